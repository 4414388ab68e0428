// Foster, Wang & Grupen's rendering-quality heuristic (Sec. IV-B, "Choosing a goal"),
// one work group per candidate view. The candidate views were rasterised into the tiles of
// an atlas whose world attachment holds the proxy's world point P per pixel (w = 1 where
// the proxy was hit). Per pixel: the smallest angle between the desired ray P -> candidate
// centre and the rays P -> source centre over the sources that see P (inside the source
// image and not occluded per the source's depth map); a pixel no source sees scores
// u_unseen_score. The tile is reduced on the GPU to (sum of pixel scores, proxy pixels,
// proxy pixels seen by some source, 0); explore/view_quality.py turns that into the mean.
// SHARED_SOURCES (up to MAX_SHARED sources): each work group first bounds its tile's proxy
// points with a box and copies into shared memory only the sources that may see some of it
// (conservative: a source is dropped only when all 8 box corners are behind it, or all in
// front and off the same side of its image; a projective map keeps the box's points in the
// corners' hull). Without it, every source is read from the storage buffer per pixel.

#if defined COMPUTE_SHADER
#ifndef LOCAL_SIZE
#define LOCAL_SIZE 256
#endif
layout(local_size_x = LOCAL_SIZE) in;
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

shared vec4 s_a[LOCAL_SIZE];  // reductions: box lows, then (score sum, pixels, seen pixels)
shared vec4 s_b[LOCAL_SIZE];  // box highs
#if SHARED_SOURCES
shared vec4 s_rows[MAX_SHARED][3];
shared vec3 s_c[MAX_SHARED];
shared int s_layer[MAX_SHARED];
shared uint s_count;
#define SRC_ROW(i, r) s_rows[i][r]
#define SRC_C(i) s_c[i]
#define SRC_LAYER(i) s_layer[i]
#else
#define SRC_ROW(i, r) sources[i].rows[r]
#define SRC_C(i) sources[i].centre.xyz
#define SRC_LAYER(i) (i)
#endif

float pixel_score(vec3 P, vec3 eye, int n_active, out bool seen) {
    vec3 r = normalize(eye - P);
    float best = -2.0;
    vec3 best_ray = r;
    vec4 P1 = vec4(P, 1.0);
    for (int i = 0; i < n_active; ++i) {
        float z = dot(SRC_ROW(i, 2), P1);
        if (z <= u_near) continue;
        ivec2 px = ivec2(floor(vec2(dot(SRC_ROW(i, 0), P1), dot(SRC_ROW(i, 1), P1)) / z + 0.5));
        if (any(lessThan(px, ivec2(0))) || any(greaterThanEqual(px, u_depth_size))) continue;
        float d = texelFetch(u_depths, ivec3(px, SRC_LAYER(i)), 0).r;
        if (d <= 0.0 || z > d * (1.0 + u_tol_rel) + u_tol_abs) continue;
        vec3 ri = normalize(SRC_C(i) - P);
        float c = dot(r, ri);
        if (c > best) { best = c; best_ray = ri; }
    }
    seen = best > -1.5;
    // atan2(|r x ri|, r . ri): accurate near 0, unlike acos
    return seen ? atan(length(cross(r, best_ray)), dot(r, best_ray)) : u_unseen_score;
}

void reduce(uint lid, bool minmax) {  // s_a[0], s_b[0] = min/max (or sum) over the group
    for (uint stride = uint(LOCAL_SIZE) / 2u; stride > 0u; stride >>= 1) {
        if (lid < stride) {
            if (minmax) {
                s_a[lid] = min(s_a[lid], s_a[lid + stride]);
                s_b[lid] = max(s_b[lid], s_b[lid + stride]);
            } else {
                s_a[lid] += s_a[lid + stride];
            }
        }
        barrier();
    }
}

#if SHARED_SOURCES
bool may_see(vec4 rows[3], vec3 lo, vec3 hi) {
    bool all_behind = true, all_front = true;
    bvec4 off = bvec4(true);  // all corners left, right, above, below the image
    for (int c = 0; c < 8; ++c) {
        vec4 X = vec4(mix(lo, hi, vec3(c & 1, (c >> 1) & 1, (c >> 2) & 1)), 1.0);
        float z = dot(rows[2], X);
        all_behind = all_behind && z <= u_near;
        all_front = all_front && z > u_near;
        vec2 uv = vec2(dot(rows[0], X), dot(rows[1], X)) / max(z, 1e-9);
        off = bvec4(off.x && uv.x < -0.5, off.y && uv.x >= float(u_depth_size.x) - 0.5,
                    off.z && uv.y < -0.5, off.w && uv.y >= float(u_depth_size.y) - 0.5);
    }
    return !all_behind && !(all_front && any(off));
}
#endif

void main() {
    uint k = gl_WorkGroupID.x;
    uint lid = gl_LocalInvocationID.x;
    ivec2 origin = ivec2(int(k) % u_cols, int(k) / u_cols) * u_tile;
    vec3 eye = eyes[u_first + int(k)].xyz;
    int n_px = u_tile.x * u_tile.y;
    int n_active = u_n_sources;
#if SHARED_SOURCES
    vec3 lo = vec3(1e30), hi = vec3(-1e30);
    for (int p = int(lid); p < n_px; p += LOCAL_SIZE) {
        vec4 w = texelFetch(u_world, origin + ivec2(p % u_tile.x, p / u_tile.x), 0);
        if (w.w >= 0.5) { lo = min(lo, w.xyz); hi = max(hi, w.xyz); }
    }
    s_a[lid] = vec4(lo, 0.0); s_b[lid] = vec4(hi, 0.0);
    if (lid == 0u) s_count = 0u;
    barrier();
    reduce(lid, true);
    lo = s_a[0].xyz; hi = s_b[0].xyz;
    barrier();
    for (int i = int(lid); i < u_n_sources; i += LOCAL_SIZE) {
        vec4 rows[3] = sources[i].rows;
        if (!may_see(rows, lo, hi)) continue;
        uint slot = atomicAdd(s_count, 1u);
        for (int r = 0; r < 3; ++r) s_rows[slot][r] = rows[r];
        s_c[slot] = sources[i].centre.xyz;
        s_layer[slot] = i;
    }
    barrier();
    n_active = int(s_count);
#endif
    float sum = 0.0, n = 0.0, n_seen = 0.0;
    for (int p = int(lid); p < n_px; p += LOCAL_SIZE) {
        vec4 w = texelFetch(u_world, origin + ivec2(p % u_tile.x, p / u_tile.x), 0);
        if (w.w < 0.5) continue;
        bool seen;
        sum += pixel_score(w.xyz, eye, n_active, seen);
        n += 1.0;
        n_seen += seen ? 1.0 : 0.0;
    }
    s_a[lid] = vec4(sum, n, n_seen, 0.0);
    barrier();
    reduce(lid, false);
    if (lid == 0u) scores[u_first + int(k)] = s_a[0];
}
#endif
