// Push-pull hole filling (Gortler et al. 1996) on the GPU; see ibr/render/hole_filling.py for
// the algorithm and its numpy reference (`push_pull`), which this reproduces in float32.
// MODE 0 (pull): level l -> l+1, 2x2 weighted means; rgba32f levels hold (mean value, weight).
// MODE 1 (push): level l (l >= 1) in place: w * value + (1 - w) * filled(l + 1) at p / 2.
// MODE 2 (out):  level 0: known pixels keep the source, the others take filled(1) at p / 2.
// DEPTH 1: the source is a camera-z texture (known where > 0; filled pixels come out negative);
// DEPTH 0: an RGBA colour (known where alpha > 0.5; alpha is passed through).

layout(local_size_x = 8, local_size_y = 8) in;

uniform sampler2D u_source;   // level 0 (MODE 0 with u_first, MODE 2)
uniform sampler2D u_coarse;   // level l + 1 (MODE 1, MODE 2)
uniform sampler2D u_fine;     // level l (MODE 0, not first)
uniform bool u_first;

float known_weight(vec4 t) {
#if DEPTH
    return t.r > 0.0 ? 1.0 : 0.0;
#else
    return t.a > 0.5 ? 1.0 : 0.0;
#endif
}

#if MODE == 0
layout(rgba32f, binding = 0) writeonly uniform image2D u_out;
void main() {
    ivec2 c = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(c, imageSize(u_out)))) return;
    ivec2 fs = u_first ? textureSize(u_source, 0) : textureSize(u_fine, 0);
    vec3 s = vec3(0.0);
    float w = 0.0;
    for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
            ivec2 p = 2 * c + ivec2(dx, dy);
            if (any(greaterThanEqual(p, fs))) continue;
            vec4 t = u_first ? texelFetch(u_source, p, 0) : texelFetch(u_fine, p, 0);
            float wt = u_first ? known_weight(t) : t.a;
            s += wt * t.rgb;
            w += wt;
        }
    imageStore(u_out, c, vec4(w > 0.0 ? s / w : vec3(0.0), min(w, 1.0)));
}
#elif MODE == 1
layout(rgba32f, binding = 0) uniform image2D u_level;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(u_level)))) return;
    vec4 v = imageLoad(u_level, p);
    vec3 up = texelFetch(u_coarse, p / 2, 0).rgb;
    imageStore(u_level, p, vec4(v.a * v.rgb + (1.0 - v.a) * up, v.a));
}
#else
#if DEPTH
layout(r32f, binding = 0) writeonly uniform image2D u_out;
#else
layout(rgba8, binding = 0) writeonly uniform image2D u_out;
#endif
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(u_out)))) return;
    vec4 t = texelFetch(u_source, p, 0);
    vec3 up = texelFetch(u_coarse, p / 2, 0).rgb;
#if DEPTH
    imageStore(u_out, p, vec4(t.r > 0.0 ? t.r : -abs(up.r), 0.0, 0.0, 0.0));
#else
    imageStore(u_out, p, t.a > 0.5 ? t : vec4(up, t.a));
#endif
}
#endif
