// Plane-sweep stereo (Collins 1996; Gallup et al. 2007) for one reference view: for each
// fronto-parallel plane of the reference camera, every window pixel is mapped into each
// neighbour through the plane (a homography), the window's NCC with the reference is
// computed per neighbour, and the mean of the best neighbours' NCC is maximised per pixel; the best depth is
// refined by a parabola through the scores of the neighbouring planes.

#if defined VERTEX_SHADER
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}
#endif

#if defined FRAGMENT_SHADER
uniform sampler2DArray u_images;   // all source photos, RGB
uniform int u_reference;           // layer of the reference photo
uniform int u_n_neighbours;
uniform ivec4 u_neighbours;        // layers of up to 4 neighbours
uniform mat4 u_neighbour_from_ref[4];  // pix_from_world(neighbour) * world_from_cam(reference)
uniform mat3 u_K_inv;              // reference camera
uniform vec2 u_size;               // (width, height) of the photos
uniform float u_inv_depth_near;    // 1 / nearest plane depth
uniform float u_inv_depth_far;     // 1 / farthest plane depth
layout(location = 0) out vec4 f_result;  // (depth, score, 0, 1)

float luma(vec2 pix, int layer) {
    return dot(texture(u_images, vec3((pix + 0.5) / u_size, float(layer))).rgb, vec3(0.299, 0.587, 0.114));
}

float plane_depth(float k) {  // planes uniform in inverse depth
    return 1.0 / mix(u_inv_depth_near, u_inv_depth_far, k / float(PLANES - 1));
}

float plane_score(vec2 p, float depth) {  // mean NCC of the best BEST_OF neighbours
    float top[4] = float[4](-1.0, -1.0, -1.0, -1.0);
    for (int n = 0; n < u_n_neighbours; ++n) {
        float sr = 0.0, sn = 0.0, srr = 0.0, snn = 0.0, srn = 0.0;
        bool inside = true;
        for (int dy = -RADIUS; dy <= RADIUS; ++dy) {
            for (int dx = -RADIUS; dx <= RADIUS; ++dx) {
                vec2 q = p + vec2(dx, dy);
                vec4 h = u_neighbour_from_ref[n] * vec4(depth * (u_K_inv * vec3(q, 1.0)), 1.0);
                vec2 s = h.xy / h.z;
                inside = inside && h.z > 0.0 && all(greaterThanEqual(s, vec2(0.0))) && all(lessThan(s, u_size - 1.0));
                float a = luma(q, u_reference) - 0.5;  // centred: less cancellation in float
                float b = luma(s, u_neighbours[n]) - 0.5;
                sr += a; sn += b; srr += a * a; snn += b * b; srn += a * b;
            }
        }
        float m = float((2 * RADIUS + 1) * (2 * RADIUS + 1));
        float var_r = (srr - sr * sr / m) / m, var_n = (snn - sn * sn / m) / m;
        float ncc = clamp((srn - sr * sn / m) / m / sqrt(max(var_r * var_n, 1e-12)), -1.0, 1.0);
        float score = inside && var_r > MIN_VARIANCE && var_n > MIN_VARIANCE ? ncc : -1.0;
        for (int j = 0; j < 4; ++j) {  // insert into the sorted top list
            if (score > top[j]) { float t = top[j]; top[j] = score; score = t; }
        }
    }
    float total = 0.0;
    int used = min(BEST_OF, max(u_n_neighbours, 1));
    for (int j = 0; j < used; ++j) total += top[j];
    return total / float(used);
}

void main() {
    vec2 p = gl_FragCoord.xy - 0.5;
    float best = -2.0, before = -2.0, after = -2.0, previous = -2.0;
    int best_k = 0;
    for (int k = 0; k < PLANES; ++k) {
        float s = plane_score(p, plane_depth(float(k)));
        if (k == best_k + 1) after = s;
        if (s > best) { best = s; best_k = k; before = previous; after = -2.0; }
        previous = s;
    }
    float k = float(best_k);
    if (best_k > 0 && best_k < PLANES - 1) {  // parabola through the neighbouring planes' scores
        float denom = before - 2.0 * best + after;
        if (denom < -1e-6) k += clamp(0.5 * (before - after) / denom, -0.5, 0.5);
    }
    f_result = vec4(plane_depth(k), best, 0.0, 1.0);
}
#endif
