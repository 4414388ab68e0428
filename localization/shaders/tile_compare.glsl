// Compare each tile of a rendered atlas (one particle's view per tile) with the observed
// image, and reduce the tile to a few numbers on the GPU (one work group per tile).
// Output per tile k: (zero-mean NCC, mean squared difference, covered fraction, 0),
// over the pixels where the model has geometry (depth > 0). Intensities in [0, 1].

#if defined COMPUTE_SHADER
layout(local_size_x = 256) in;
layout(binding = 0) uniform sampler2D u_render;    // atlas colour (RGBA8)
layout(binding = 1) uniform sampler2D u_depth;     // atlas camera-z depth (R32F), 0 = empty
layout(binding = 2) uniform sampler2D u_observed;  // observed luminance (R32F), tile-sized
uniform ivec2 u_tile;                              // tile width, height (px)
uniform int u_cols;                                // tiles per atlas row
layout(std430, binding = 0) writeonly buffer Scores { vec4 scores[]; };

shared float s_sum[6][256];

void main() {
    uint k = gl_WorkGroupID.x;
    uint lid = gl_LocalInvocationID.x;
    ivec2 origin = ivec2(int(k) % u_cols, int(k) / u_cols) * u_tile;
    float sr = 0.0, so = 0.0, srr = 0.0, soo = 0.0, sro = 0.0, n = 0.0;
    int n_px = u_tile.x * u_tile.y;
    for (int p = int(lid); p < n_px; p += 256) {
        ivec2 xy = ivec2(p % u_tile.x, p / u_tile.x);
        if (texelFetch(u_depth, origin + xy, 0).r <= 0.0) continue;
        float r = dot(texelFetch(u_render, origin + xy, 0).rgb, vec3(0.299, 0.587, 0.114));
        float o = texelFetch(u_observed, xy, 0).r;
        sr += r; so += o; srr += r * r; soo += o * o; sro += r * o; n += 1.0;
    }
    s_sum[0][lid] = sr; s_sum[1][lid] = so; s_sum[2][lid] = srr;
    s_sum[3][lid] = soo; s_sum[4][lid] = sro; s_sum[5][lid] = n;
    barrier();
    for (uint stride = 128u; stride > 0u; stride >>= 1) {
        if (lid < stride) {
            for (int j = 0; j < 6; ++j) s_sum[j][lid] += s_sum[j][lid + stride];
        }
        barrier();
    }
    if (lid == 0u) {
        n = s_sum[5][0];
        float m = max(n, 1.0);
        float mr = s_sum[0][0] / m, mo = s_sum[1][0] / m;
        float var_r = s_sum[2][0] / m - mr * mr, var_o = s_sum[3][0] / m - mo * mo;
        float cov = s_sum[4][0] / m - mr * mo;
        float ncc = n > 1.0 ? cov / sqrt(max(var_r * var_o, 1e-12)) : 0.0;
        float mse = n > 0.0 ? (s_sum[2][0] - 2.0 * s_sum[4][0] + s_sum[3][0]) / m : 1.0;
        scores[k] = vec4(ncc, mse, n / float(n_px), 0.0);
    }
}
#endif
