// Unstructured lumigraph rendering (Buehler et al. 2001), per pixel over a texture array of
// source images (as SIBR's ulr_v3). See ibr/ulr.py for the algorithm in words and in numpy.
// PASS 0: camera-z depth of the proxy mesh seen by the virtual camera.
// PASS 1: full-screen blend: world point from the (hole-filled) depth, k-best sources by
//         angle + resolution penalty, field-of-view and shadow-map visibility tests,
//         smooth k-nearest weights (the per-pixel reference).
// PASS 2: the blending field (Buehler et al. Sec. 5, ibr/render/blending_field.py): the
//         triangulated field samples are rasterised; each triangle carries SLOTS (weight at
//         its 3 vertices, source) entries, interpolated with the barycentrics; per pixel
//         the sources failing the field-of-view or visibility test are dropped and the rest
//         renormalised. A pixel none of whose field sources sees it is left unblended (alpha
//         0) for hole filling, as Buehler et al.'s real-time renderer has no per-pixel pass.

#if PASS == 0

#if defined VERTEX_SHADER
in vec3 in_position;
uniform mat4 u_clip_from_world;
out float v_depth;
void main() {
    vec4 clip = u_clip_from_world * vec4(in_position, 1.0);
    v_depth = clip.w;  // camera z (Camera.gl_projection)
    gl_Position = clip;
}
#endif

#if defined FRAGMENT_SHADER
in float v_depth;
layout(location = 0) out float f_depth;
void main() { f_depth = v_depth; }
#endif

#else  // PASS 1, 2

#if defined VERTEX_SHADER
#if PASS == 1
void main() {  // one triangle covering the viewport
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}
#else
in vec2 in_uv;           // field sample, virtual-view pixels (centres at integers)
uniform vec2 u_view_size;  // (width, height) of the virtual view
out vec3 v_bary;
void main() {  // non-indexed triangles: vertex 3t + j is corner j of triangle t
    int j = gl_VertexID % 3;
    v_bary = vec3(j == 0, j == 1, j == 2);
    gl_Position = vec4(2.0 * (in_uv + 0.5) / u_view_size - 1.0, 0.0, 1.0);
}
#endif
#endif

#if defined FRAGMENT_SHADER
uniform sampler2DArray u_images;   // source photos, RGB, linear filtering
uniform sampler2DArray u_depths;   // source camera-z depth of the proxy (0 = empty), nearest
uniform sampler2D u_view_depth;    // virtual camera-z; < 0: hole-filled (no visibility test)
uniform mat4 u_world_from_cam;     // virtual camera
uniform mat3 u_K_inv;              // virtual camera
uniform vec3 u_eye;                // virtual camera centre, world
uniform int u_n_sources;
uniform int u_only_source;         // -1: all sources compete; else only this one
uniform vec2 u_source_size;        // (width, height) of the source images, pixels
uniform float u_alpha;             // weight of the angle penalty (per radian)
uniform float u_beta;              // weight of the relative resolution penalty
uniform float u_visibility_tolerance;  // relative camera-z slack of the shadow-map test
layout(std430, binding = 0) readonly buffer PixFromWorld { mat4 pix_from_world[]; };
layout(std430, binding = 1) readonly buffer Centres { vec4 centres[]; };
layout(location = 0) out vec4 f_color;

#if PASS == 1
// The per-pixel blend of surface point P; false if no source sees P.
bool pixel_blend(vec3 P, bool filled, out vec3 color) {
    vec3 to_eye = normalize(u_eye - P);
    float d_eye = distance(u_eye, P);

    float best_p[K + 1];
    int best_i[K + 1];
    for (int j = 0; j <= K; ++j) { best_p[j] = 1e30; best_i[j] = -1; }
    int found = 0;
    for (int i = 0; i < u_n_sources; ++i) {
        if (u_only_source >= 0 && i != u_only_source) continue;
        vec4 q = pix_from_world[i] * vec4(P, 1.0);
        if (q.z <= 0.0) continue;
        vec2 s = q.xy / q.z;
        // field-of-view penalty: infinite outside the source image
        if (any(lessThan(s, vec2(-0.5))) || any(greaterThanEqual(s, u_source_size - 0.5))) continue;
        if (!filled) {  // visibility: shadow-map test against the source's proxy depth
            float d = texelFetch(u_depths, ivec3(ivec2(floor(s + 0.5)), i), 0).r;
            if (d <= 0.0 || q.z > d * (1.0 + u_visibility_tolerance)) continue;
        }
        vec3 to_src = centres[i].xyz - P;
        float ang = acos(clamp(dot(normalize(to_src), to_eye), -1.0, 1.0));
        float res = max(0.0, (length(to_src) - d_eye) / d_eye);
        float pen = u_alpha * ang + u_beta * res;
        found += 1;
        // insert into the sorted list of the K + 1 smallest penalties
        for (int j = K; j >= 0; --j) {
            if (j > 0 && pen < best_p[j - 1]) {
                best_p[j] = best_p[j - 1]; best_i[j] = best_i[j - 1];
            } else {
                if (pen < best_p[j]) { best_p[j] = pen; best_i[j] = i; }
                break;
            }
        }
    }
    if (found == 0) return false;
    int n = min(found, K);
    float thresh = found > K ? best_p[K] : best_p[n - 1] * 1.5 + 1e-3;
    vec3 rgb = vec3(0.0);
    float wsum = 0.0;
    for (int j = 0; j < n; ++j) {
        int i = best_i[j];
        float w = (1.0 - best_p[j] / thresh) / (best_p[j] + EPS);
        vec4 q = pix_from_world[i] * vec4(P, 1.0);
        vec2 s = q.xy / q.z;
        rgb += w * texture(u_images, vec3((s + 0.5) / u_source_size, float(i))).rgb;
        wsum += w;
    }
    color = rgb / wsum;
    return wsum > 0.0;
}
#endif

#if PASS == 2
layout(std430, binding = 2) readonly buffer Field { vec4 field[]; };  // (w0, w1, w2, source)
in vec3 v_bary;

// The interpolated blending field at P; false if every source it names fails the tests.
bool field_blend(vec3 P, bool filled, out vec3 color) {
    vec3 rgb = vec3(0.0);
    float wsum = 0.0;
    int base = gl_PrimitiveID * SLOTS;
    for (int j = 0; j < SLOTS; ++j) {
        vec4 e = field[base + j];
        int i = int(e.w);
        if (i < 0) break;
        float w = dot(e.xyz, v_bary);
        if (w <= 0.0) continue;
        vec4 q = pix_from_world[i] * vec4(P, 1.0);
        if (q.z <= 0.0) continue;
        vec2 s = q.xy / q.z;
        if (any(lessThan(s, vec2(-0.5))) || any(greaterThanEqual(s, u_source_size - 0.5))) continue;
        if (!filled) {
            float d = texelFetch(u_depths, ivec3(ivec2(floor(s + 0.5)), i), 0).r;
            if (d <= 0.0 || q.z > d * (1.0 + u_visibility_tolerance)) continue;
        }
        rgb += w * texture(u_images, vec3((s + 0.5) / u_source_size, float(i))).rgb;
        wsum += w;
    }
    color = rgb / wsum;
    return wsum > 0.0;
}
#endif

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    float z = texelFetch(u_view_depth, px, 0).r;
    if (z == 0.0) { f_color = vec4(0.0); return; }
    bool filled = z < 0.0;
    z = abs(z);
    vec3 pc = z * (u_K_inv * vec3(gl_FragCoord.xy - 0.5, 1.0));
    vec3 P = (u_world_from_cam * vec4(pc, 1.0)).xyz;
    vec3 rgb;
#if PASS == 2
    f_color = field_blend(P, filled, rgb) ? vec4(rgb, 1.0) : vec4(0.0);
#else
    f_color = pixel_blend(P, filled, rgb) ? vec4(rgb, 1.0) : vec4(0.0);
#endif
}
#endif

#endif
