// VuePlan Phase II visibility counts (Blaer & Allen 2009, Sec. 3.2.2-3.2.4) on the GPU,
// every (boundary-unseen voxel u, potential view p) pair in one pass. The pair counts for p
// when the segment from u's centre to p is within the scanner's range, meets the normal of
// one of u's exposed faces within the grazing angle, and crosses no blocked (seen-occupied
// or unseen) voxel besides u. The segment is walked voxel by voxel (Amanatides & Woo), and
// from a voxel whose nearest blocked voxel is D >= 3 voxels away it jumps D - sqrt(3)
// voxels at once (no point that close lies in a blocked voxel), as the numpy walk
// (explore/vueplan/voxel_grid.py, segments_clear) does. Where the segment passes through a
// voxel edge or corner, the voxels beside it block too (Embree's watertight convention).
// See explore/vueplan/voxel_visibility.py.
// Units: voxel coordinates (world minus the grid origin, over the voxel edge).

#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;  // views

layout(std430, binding = 0) readonly buffer Distance { float dist[]; };  // C order (nx, ny, nz); 0 = blocked
layout(std430, binding = 1) readonly buffer Voxels { ivec4 voxels[]; };   // (i, j, k, exposed-face bits)
layout(std430, binding = 2) readonly buffer Views { vec4 views[]; };      // voxel coordinates
layout(std430, binding = 3) buffer Counts { uint counts[]; };   // per view, then the rays walked

uniform ivec3 u_shape;
uniform int u_n_voxels;
uniform int u_n_views;
uniform int u_voxel_offset;     // first voxel block of this dispatch
uniform float u_voxel_m;        // voxel edge (metres)
uniform float u_min_range_m;
uniform float u_max_range_m;
uniform float u_cos_max;        // cosine of the largest grazing angle

const vec3 FACE_NORMALS[6] = vec3[6](vec3(-1, 0, 0), vec3(1, 0, 0), vec3(0, -1, 0), vec3(0, 1, 0),
                                     vec3(0, 0, -1), vec3(0, 0, 1));
const float BIG = 1e30;
const float TIE_EPS = 1e-5;  // segment parameter: crossings closer than this are one (a tie)

float distance_at(ivec3 c) { return dist[(c.x * u_shape.y + c.y) * u_shape.z + c.z]; }

// True if the segment a -> b crosses no blocked voxel besides the one holding a.
bool segment_clear(vec3 a, vec3 b) {
    vec3 d = b - a;
    float len = length(d);
    ivec3 step = ivec3(greaterThan(d, vec3(0.0))) * 2 - 1;
    vec3 inv = vec3(d.x != 0.0 ? 1.0 / d.x : BIG, d.y != 0.0 ? 1.0 / d.y : BIG, d.z != 0.0 ? 1.0 / d.z : BIG);
    vec3 t_delta = abs(inv);
    ivec3 idx = ivec3(floor(a));
    vec3 t_max = mix(vec3(BIG), (vec3(idx + ivec3(greaterThan(step, ivec3(0)))) - a) * inv, notEqual(d, vec3(0.0)));
    int guard = 4 * (u_shape.x + u_shape.y + u_shape.z);
    for (int it = 0; it < guard; ++it) {
        float t = min(t_max.x, min(t_max.y, t_max.z));
        if (t >= 1.0) return true;
        // a ray through a voxel edge or corner (a tie, up to float32) touches the voxels on
        // both sides of it: either one blocked blocks it, as for Embree's watertight test
        bvec3 tie = lessThanEqual(t_max, vec3(t + TIE_EPS));
        ivec3 prev = idx;
        int n_tie = int(tie.x) + int(tie.y) + int(tie.z);
        if (n_tie > 1) {
            for (int k = 0; k < 3; ++k) {
                if (!tie[k]) continue;
                ivec3 side = prev;
                side[k] += step[k];
                if (all(greaterThanEqual(side, ivec3(0))) && all(lessThan(side, u_shape)) && distance_at(side) == 0.0)
                    return false;
            }
        }
        for (int k = 0; k < 3; ++k)
            if (tie[k]) { idx[k] += step[k]; t_max[k] += t_delta[k]; }
        if (any(lessThan(idx, ivec3(0))) || any(greaterThanEqual(idx, u_shape))) return true;  // left the box
        float D = distance_at(idx);
        if (D == 0.0) return false;
        if (D >= 3.0) {  // jump across open space and re-enter the walk there
            float tj = t + (D - sqrt(3.0)) / len;
            if (tj >= 1.0) return true;
            vec3 p = a + tj * d;
            idx = ivec3(floor(p + 1e-6 * sign(d)));
            t_max = mix(vec3(BIG), (vec3(idx + ivec3(greaterThan(step, ivec3(0)))) - a) * inv, notEqual(d, vec3(0.0)));
        }
    }
    return true;
}

// One invocation per (view, block of VOXELS_PER_INVOCATION boundary voxels): the lanes of
// a SIMD group are neighbouring views looking at the same voxel, whose walks are alike.
void main() {
    int v = int(gl_GlobalInvocationID.x);
    int u0 = (u_voxel_offset + int(gl_GlobalInvocationID.y)) * VOXELS_PER_INVOCATION;
    if (v >= u_n_views || u0 >= u_n_voxels) return;
    vec3 b = views[v].xyz;
    uint seen = 0u, walked = 0u;
    for (int u = u0; u < min(u0 + VOXELS_PER_INVOCATION, u_n_voxels); ++u) {
        ivec4 vox = voxels[u];
        vec3 a = vec3(vox.xyz) + 0.5;
        vec3 d = b - a;
        float r = length(d) * u_voxel_m;
        if (r < u_min_range_m || r > u_max_range_m) continue;
        float best = -BIG;
        for (int f = 0; f < 6; ++f)
            if ((vox.w & (1 << f)) != 0) best = max(best, dot(FACE_NORMALS[f], d));
        if (best < u_cos_max * length(d)) continue;
        walked += 1u;
        if (segment_clear(a, b)) seen += 1u;
    }
    if (seen > 0u) atomicAdd(counts[v], seen);
    atomicAdd(counts[u_n_views], walked);
}
#endif
