// Light-field rendering through plane homographies (Heigl et al.), see ibr/lightfield.py.
// Each triangle of the net of projected source centres is drawn once; its three corner
// sources are mapped through the triangle's scene plane (H_i = B_i B_V^-1, evaluated per
// pixel as ray-plane intersection + projection) and blended with Gouraud-ramped weights.

#if defined VERTEX_SHADER
in vec2 in_pixel;        // (u, v) of the net vertex in the virtual image
in vec3 in_weight;       // Gouraud weights of the triangle's three corner sources
in vec3 in_sources;      // the triangle's three corner sources (indices, as floats)
in vec4 in_plane;        // the triangle's scene plane: n . X = w (world, metres)
uniform vec2 u_size;     // virtual image (width, height)
noperspective out vec3 v_weight;
flat out ivec3 v_sources;
flat out vec4 v_plane;
void main() {
    v_weight = in_weight;
    v_sources = ivec3(round(in_sources));
    v_plane = in_plane;
    gl_Position = vec4(2.0 * (in_pixel + 0.5) / u_size - 1.0, 0.0, 1.0);
}
#endif

#if defined FRAGMENT_SHADER
noperspective in vec3 v_weight;
flat in ivec3 v_sources;
flat in vec4 v_plane;
uniform sampler2DArray u_images;
uniform mat3 u_world_from_pixel;  // R_V^T K_V^-1: pixel (u, v, 1) -> world ray direction
uniform vec3 u_eye;               // virtual camera centre
uniform vec2 u_source_size;
layout(std430, binding = 0) readonly buffer PixFromWorld { mat4 pix_from_world[]; };
layout(location = 0) out vec4 f_color;

void main() {
    vec3 dir = u_world_from_pixel * vec3(gl_FragCoord.xy - 0.5, 1.0);
    float denom = dot(v_plane.xyz, dir);
    float t = (v_plane.w - dot(v_plane.xyz, u_eye)) / denom;
    if (abs(denom) < 1e-12 || t <= 0.0) discard;
    vec3 P = u_eye + t * dir;
    vec3 rgb = vec3(0.0);
    float wsum = 0.0;
    for (int k = 0; k < 3; ++k) {
        vec4 q = pix_from_world[v_sources[k]] * vec4(P, 1.0);
        if (q.z <= 0.0) continue;
        vec2 s = q.xy / q.z;
        if (any(lessThan(s, vec2(-0.5))) || any(greaterThanEqual(s, u_source_size - 0.5))) continue;
        float w = v_weight[k];
        rgb += w * texture(u_images, vec3((s + 0.5) / u_source_size, float(v_sources[k]))).rgb;
        wsum += w;
    }
    if (wsum <= 1e-6) discard;
    f_color = vec4(rgb / wsum, 1.0);
}
#endif
