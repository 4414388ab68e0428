// Foster, Wang & Grupen's rendering-quality heuristic (Sec. IV-B, "Choosing a goal"),
// one work group per candidate view. The candidate views were rasterised into the tiles of
// an atlas whose world attachment holds the proxy's world point P per pixel (w = 1 where
// the proxy was hit). Per pixel: the smallest angle between the desired ray P -> candidate
// centre and the rays P -> source centre over the sources that see P (inside the source
// image and not occluded per the source's depth map); a pixel no source sees scores
// u_unseen_score. The tile is reduced on the GPU to (sum of pixel scores, proxy pixels,
// proxy pixels seen by some source, 0); explore/view_quality.py turns that into the mean.
// SHARED_SOURCES (up to MAX_SHARED sources): each work group first copies the sources into
// shared memory (about 20% faster on llvmpipe than reading the storage buffer per pixel).

#if defined COMPUTE_SHADER
layout(local_size_x = 256) in;
layout(binding = 0) uniform sampler2D u_world;         // atlas world points (RGBA32F)
layout(binding = 1) uniform sampler2DArray u_depths;   // source camera-z depth maps (R32F), 0 = empty
struct Source {
    vec4 rows[3];  // rows of pixel_from_world = K' [R | t] (depth-map pixels); rows[2]: camera z
    vec4 centre;   // xyz: source centre, world
};
layout(std430, binding = 0) readonly buffer Sources { Source sources[]; };
layout(std430, binding = 1) readonly buffer Eyes { vec4 eyes[]; };  // candidate centres
layout(std430, binding = 2) writeonly buffer Scores { vec4 scores[]; };
uniform ivec2 u_tile;          // tile width, height (px)
uniform int u_cols;            // tiles per atlas row
uniform int u_first;           // index of this pass's first view in Eyes / Scores
uniform int u_n_sources;
uniform ivec2 u_depth_size;    // depth map width, height (px)
uniform float u_near;          // camera z below which a source does not see P (m)
uniform float u_tol_rel;       // visibility: z <= d (1 + tol_rel) + tol_abs
uniform float u_tol_abs;
uniform float u_unseen_score;  // score of a proxy pixel no source sees (rad)

shared float s_sum[3][256];
#if SHARED_SOURCES
shared vec4 s_rows[MAX_SHARED][3];
shared vec3 s_c[MAX_SHARED];
#define SRC_ROW(i, r) s_rows[i][r]
#define SRC_C(i) s_c[i]
#else
#define SRC_ROW(i, r) sources[i].rows[r]
#define SRC_C(i) sources[i].centre.xyz
#endif

float pixel_score(vec3 P, vec3 eye, out bool seen) {
    vec3 r = normalize(eye - P);
    float best = -2.0;
    vec3 best_ray = r;
    for (int i = 0; i < u_n_sources; ++i) {
        vec4 P1 = vec4(P, 1.0);
        float z = dot(SRC_ROW(i, 2), P1);
        if (z <= u_near) continue;
        ivec2 px = ivec2(floor(vec2(dot(SRC_ROW(i, 0), P1), dot(SRC_ROW(i, 1), P1)) / z + 0.5));
        if (any(lessThan(px, ivec2(0))) || any(greaterThanEqual(px, u_depth_size))) continue;
        float d = texelFetch(u_depths, ivec3(px, i), 0).r;
        if (d <= 0.0 || z > d * (1.0 + u_tol_rel) + u_tol_abs) continue;
        vec3 ri = normalize(SRC_C(i) - P);
        float c = dot(r, ri);
        if (c > best) { best = c; best_ray = ri; }
    }
    seen = best > -1.5;
    // atan2(|r x ri|, r . ri): accurate near 0, unlike acos
    return seen ? atan(length(cross(r, best_ray)), dot(r, best_ray)) : u_unseen_score;
}

void main() {
    uint k = gl_WorkGroupID.x;
    uint lid = gl_LocalInvocationID.x;
    ivec2 origin = ivec2(int(k) % u_cols, int(k) / u_cols) * u_tile;
    vec3 eye = eyes[u_first + int(k)].xyz;
    float sum = 0.0, n = 0.0, n_seen = 0.0;
#if SHARED_SOURCES
    for (int i = int(lid); i < u_n_sources; i += 256) {
        for (int r = 0; r < 3; ++r) s_rows[i][r] = sources[i].rows[r];
        s_c[i] = sources[i].centre.xyz;
    }
    barrier();
#endif
    int n_px = u_tile.x * u_tile.y;
    for (int p = int(lid); p < n_px; p += 256) {
        vec4 w = texelFetch(u_world, origin + ivec2(p % u_tile.x, p / u_tile.x), 0);
        if (w.w < 0.5) continue;
        bool seen;
        sum += pixel_score(w.xyz, eye, seen);
        n += 1.0;
        n_seen += seen ? 1.0 : 0.0;
    }
    s_sum[0][lid] = sum; s_sum[1][lid] = n; s_sum[2][lid] = n_seen;
    barrier();
    for (uint stride = 128u; stride > 0u; stride >>= 1) {
        if (lid < stride) {
            for (int j = 0; j < 3; ++j) s_sum[j][lid] += s_sum[j][lid + stride];
        }
        barrier();
    }
    if (lid == 0u) scores[u_first + int(k)] = vec4(s_sum[0][0], s_sum[1][0], s_sum[2][0], 0.0);
}
#endif
