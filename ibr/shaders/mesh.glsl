// Mesh renderer: colour (optionally lit), world position, normal and camera-z depth.
// BATCHED: one instance per view, each drawn into its own tile of an atlas framebuffer;
// gl_ClipDistance keeps every view inside its tile (see ibr/mesh_renderer.py).

#if defined VERTEX_SHADER
in vec3 in_position;
in vec3 in_normal;
in vec2 in_uv;
in vec4 in_color;
in float in_specular;
#if BATCHED
in mat4 in_clip_from_world;  // per instance
in vec2 in_tile;             // per instance: (column, row) of the view's tile
in vec3 in_eye;              // per instance: camera centre, world
uniform vec2 u_tiles;        // (columns, rows) of the atlas
out float gl_ClipDistance[4];
#else
uniform mat4 u_clip_from_world;
uniform vec3 u_eye;          // camera centre, world
#endif
out vec3 v_world;
flat out vec3 v_eye;
out vec3 v_normal;
out vec2 v_uv;
out vec4 v_color;
out float v_specular;
out float v_depth;

void main() {
#if BATCHED
    vec4 clip = in_clip_from_world * vec4(in_position, 1.0);
    gl_ClipDistance[0] = clip.w - clip.x;
    gl_ClipDistance[1] = clip.w + clip.x;
    gl_ClipDistance[2] = clip.w - clip.y;
    gl_ClipDistance[3] = clip.w + clip.y;
    // ndc_atlas = (ndc + 1) / tiles + 2 tile / tiles - 1, written in clip space
    clip.xy = (clip.xy + clip.w) / u_tiles + clip.w * (2.0 * in_tile / u_tiles - 1.0);
    v_eye = in_eye;
#else
    vec4 clip = u_clip_from_world * vec4(in_position, 1.0);
    v_eye = u_eye;
#endif
    v_world = in_position;
    v_normal = in_normal;
    v_uv = in_uv;
    v_color = in_color;
    v_specular = in_specular;
    v_depth = clip.w;  // Camera.gl_projection puts camera z in w
    gl_Position = clip;
}
#endif

#if defined FRAGMENT_SHADER
in vec3 v_world;
in vec3 v_normal;
in vec2 v_uv;
in vec4 v_color;
in float v_specular;
in float v_depth;
flat in vec3 v_eye;
uniform sampler2D u_texture;
uniform bool u_lit;
uniform vec4 u_light;        // xyz: position (w = 1) or direction towards the light (w = 0)
uniform vec3 u_light_terms;  // ambient, diffuse, specular strength
uniform float u_shininess;
uniform float u_max_aniso;   // most taps of the anisotropic filter (1: trilinear)
layout(location = 0) out vec4 f_color;
layout(location = 1) out vec4 f_world;
layout(location = 2) out vec4 f_normal;
layout(location = 3) out float f_depth;

// Anisotropic filtering by hand: up to u_max_aniso trilinear taps along the pixel's
// footprint's major axis, at the mip level of its minor axis (the footprint's shape from
// the uv derivatives). GL's own anisotropic sampler is not used: on llvmpipe it ran for
// over 10 minutes on one 320x240 view (Mesa 22.3.6; see MeshRenderer.anisotropy). The
// loop is bounded by a constant, whatever the derivatives are.
vec3 albedo_at(vec2 uv) {
    vec2 size = vec2(textureSize(u_texture, 0));
    vec2 dx = dFdx(uv) * size, dy = dFdy(uv) * size;  // texels per pixel
    float lx = length(dx), ly = length(dy);
    float major = max(lx, ly), minor = min(lx, ly);
    float n = ceil(major / max(minor, 1e-6));
    if (u_max_aniso <= 1.0 || !(n > 1.0) || isinf(major)) return texture(u_texture, uv).rgb;
    n = min(n, min(u_max_aniso, 16.0));  // the loop's bound
    float lod = log2(max(max(major / n, minor), 1.0));  // never sharper than the minor axis
    vec2 step = (lx > ly ? dx : dy) / size / n;
    vec3 sum = vec3(0.0);
    for (int i = 0; i < 16; ++i) {
        if (float(i) >= n) break;
        sum += textureLod(u_texture, uv + step * (float(i) + 0.5 - 0.5 * n), lod).rgb;
    }
    return sum / n;
}

void main() {
    vec3 albedo = albedo_at(v_uv) * v_color.rgb;
    vec3 n = normalize(v_normal);
    vec3 rgb = albedo;
    if (u_lit) {
        vec3 V = normalize(v_eye - v_world);
        if (dot(n, V) < 0.0) n = -n;  // two-sided
        vec3 L = normalize(u_light.w > 0.5 ? u_light.xyz - v_world : u_light.xyz);
        vec3 H = normalize(L + V);
        float diffuse = max(dot(n, L), 0.0);
        float specular = v_specular * u_light_terms.z * pow(max(dot(n, H), 0.0), u_shininess);
        rgb = albedo * (u_light_terms.x + u_light_terms.y * diffuse) + vec3(specular);
    }
    f_color = vec4(clamp(rgb, 0.0, 1.0), v_color.a);  // alpha: the vertex trust (1 unless set)
    f_world = vec4(v_world, 1.0);
    f_normal = vec4(n, 1.0);
    f_depth = v_depth;
}
#endif
