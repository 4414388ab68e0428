// Compare each tile of a rendered atlas (one particle's view per tile) with the observed
// image, and reduce the tile to a few numbers on the GPU (one work group per tile).
// Output per tile k: (zero-mean NCC, mean squared difference, covered fraction, robust cost)
// over the pixels where the model has geometry (depth > 0). Intensities in [0, 1].
//
// The robust cost (localization/render_likelihood.py, `robust_cost`, is the numpy twin):
// every covered pixel has a weight w = trust (the model's per-vertex trust, carried in the
// render's alpha) x 0 at occlusion boundaries (a relative depth jump to a 4-neighbour above
// u_edge_jump, or an empty neighbour). The exposure of the render is fitted to the
// observation by weighted least squares (o ~ g r + b, g clamped to u_gain). The cost is
//   1 - sum_p w_p (rho(o_p - mean_w(o)) - rho(o_p - g r_p - b)) / P,   rho(e) = min(e^2 / tau^2, 1),
// the truncated gain of the model over the null model "a flat image", per pixel of the
// view (P pixels): 1 where the model explains nothing (uncovered, untrusted, or no better
// than flat), lower the more observed pixels the model predicts.

#if defined COMPUTE_SHADER
layout(local_size_x = 256) in;
layout(binding = 0) uniform sampler2D u_render;    // atlas colour (RGBA8), alpha = trust
layout(binding = 1) uniform sampler2D u_depth;     // atlas camera-z depth (R32F), 0 = empty
layout(binding = 2) uniform sampler2D u_observed;  // observed luminance (R32F), tile-sized
uniform ivec2 u_tile;                              // tile width, height (px)
uniform int u_cols;                                // tiles per atlas row
uniform float u_tau;                               // truncation of the residual (intensity)
uniform float u_edge_jump;                         // relative depth jump of an occlusion boundary
uniform vec2 u_gain;                               // (min, max) exposure gain
layout(std430, binding = 0) writeonly buffer Scores { vec4 scores[]; };

shared float s_sum[12][256];
shared vec3 s_fit;  // gain, offset, weighted mean of the observation

float rho(float e) { return min(e * e / (u_tau * u_tau), 1.0); }

float edge_weight(ivec2 origin, ivec2 xy, float d) {
    ivec2 nb[4] = ivec2[4](ivec2(1, 0), ivec2(-1, 0), ivec2(0, 1), ivec2(0, -1));
    for (int i = 0; i < 4; ++i) {
        ivec2 q = clamp(xy + nb[i], ivec2(0), u_tile - 1);
        float dq = texelFetch(u_depth, origin + q, 0).r;
        if (dq <= 0.0 || abs(dq - d) > u_edge_jump * min(d, dq)) return 0.0;
    }
    return 1.0;
}

void reduce(uint lid, int count) {
    barrier();
    for (uint stride = 128u; stride > 0u; stride >>= 1) {
        if (lid < stride) {
            for (int j = 0; j < count; ++j) s_sum[j][lid] += s_sum[j][lid + stride];
        }
        barrier();
    }
}

void main() {
    uint k = gl_WorkGroupID.x;
    uint lid = gl_LocalInvocationID.x;
    ivec2 origin = ivec2(int(k) % u_cols, int(k) / u_cols) * u_tile;
    float acc[12] = float[12](0., 0., 0., 0., 0., 0., 0., 0., 0., 0., 0., 0.);
    int n_px = u_tile.x * u_tile.y;
    for (int p = int(lid); p < n_px; p += 256) {
        ivec2 xy = ivec2(p % u_tile.x, p / u_tile.x);
        float d = texelFetch(u_depth, origin + xy, 0).r;
        if (d <= 0.0) continue;
        vec4 c = texelFetch(u_render, origin + xy, 0);
        float r = dot(c.rgb, vec3(0.299, 0.587, 0.114));
        float o = texelFetch(u_observed, xy, 0).r;
        float w = c.a * edge_weight(origin, xy, d);
        acc[0] += r; acc[1] += o; acc[2] += r * r; acc[3] += o * o; acc[4] += r * o; acc[5] += 1.0;
        acc[6] += w; acc[7] += w * r; acc[8] += w * o; acc[9] += w * r * r; acc[10] += w * r * o;
    }
    for (int j = 0; j < 12; ++j) s_sum[j][lid] = acc[j];
    reduce(lid, 11);
    if (lid == 0u) {
        float sw = max(s_sum[6][0], 1e-6);
        float mr = s_sum[7][0] / sw, mo = s_sum[8][0] / sw;
        float var_r = s_sum[9][0] / sw - mr * mr, cov = s_sum[10][0] / sw - mr * mo;
        float g = clamp(var_r > 1e-8 ? cov / var_r : 1.0, u_gain.x, u_gain.y);
        s_fit = vec3(g, mo - g * mr, mo);
    }
    barrier();
    vec3 fit = s_fit;
    float gain = 0.0;
    for (int p = int(lid); p < n_px; p += 256) {
        ivec2 xy = ivec2(p % u_tile.x, p / u_tile.x);
        float d = texelFetch(u_depth, origin + xy, 0).r;
        if (d <= 0.0) continue;
        vec4 c = texelFetch(u_render, origin + xy, 0);
        float w = c.a * edge_weight(origin, xy, d);
        if (w <= 0.0) continue;
        float r = dot(c.rgb, vec3(0.299, 0.587, 0.114));
        float o = texelFetch(u_observed, xy, 0).r;
        gain += w * (rho(o - fit.z) - rho(o - fit.x * r - fit.y));
    }
    barrier();
    s_sum[11][lid] = gain;
    barrier();
    for (uint stride = 128u; stride > 0u; stride >>= 1) {
        if (lid < stride) s_sum[11][lid] += s_sum[11][lid + stride];
        barrier();
    }
    if (lid == 0u) {
        float n = s_sum[5][0];
        float m = max(n, 1.0);
        float mr = s_sum[0][0] / m, mo = s_sum[1][0] / m;
        float var_r = s_sum[2][0] / m - mr * mr, var_o = s_sum[3][0] / m - mo * mo;
        float cov = s_sum[4][0] / m - mr * mo;
        float ncc = n > 1.0 ? cov / sqrt(max(var_r * var_o, 1e-12)) : 0.0;
        float mse = n > 0.0 ? (s_sum[2][0] - 2.0 * s_sum[4][0] + s_sum[3][0]) / m : 1.0;
        float cost = s_sum[6][0] > 2.0 ? 1.0 - s_sum[11][0] / float(n_px) : 1.0;
        scores[k] = vec4(ncc, mse, n / float(n_px), cost);
    }
}
#endif
