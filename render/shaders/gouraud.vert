#version 330 core
// orthosim per-vertex (Gouraud) lighting: the same ambient + directional Lambert + faint specular
// model as mesh.frag, evaluated once per vertex instead of once per pixel.
// Why: on llvmpipe the fragment stage is the bulk of the frame at 640x480 (teeth cover a third of
// the image with overdraw), while a tooth has only ~1,000-2,000 vertices; with meshes this dense
// the interpolated shading is visually the same. The fragment shader is then a copy.
// Inputs and uniforms are the ones pyrender binds (see render/renderer.py, LeanRenderer).

layout(location = 0) in vec3 position;
#ifdef NORMAL_LOC
layout(location = NORMAL_LOC) in vec3 normal;
#endif
#ifdef COLOR_0_LOC
layout(location = COLOR_0_LOC) in vec4 color_0;
#endif
layout(location = INST_M_LOC) in mat4 inst_m;

struct Material {
    vec3 emissive_factor;
    vec4 base_color_factor;
    float metallic_factor;
    float roughness_factor;
};

struct DirectionalLight {
    vec3 direction;
    vec3 color;
    float intensity;
};

uniform mat4 M;
uniform mat4 V;
uniform mat4 P;
uniform Material material;
uniform vec3 cam_pos;
uniform vec3 ambient_light;
uniform int n_directional_lights;
uniform DirectionalLight directional_lights[MAX_DIRECTIONAL_LIGHTS + 1];

out vec4 shaded;

void main()
{
    mat4 model = M * inst_m;
    vec4 world = model * vec4(position, 1.0);
    gl_Position = P * V * world;
#ifdef COLOR_0_LOC
    vec4 base = material.base_color_factor * color_0;
#else
    vec4 base = material.base_color_factor;
#endif
#ifdef NORMAL_LOC
    // rigid (teeth) or uniformly scaled (markers) poses: the 3x3 part maps normals correctly
    vec3 n = normalize(mat3(model) * normal);
    vec3 v = normalize(cam_pos - world.xyz);
    vec3 lit = ambient_light;
    vec3 spec = vec3(0.0);
    float shininess = mix(48.0, 0.0, material.roughness_factor);
    for (int i = 0; i < n_directional_lights; i++) {
        vec3 l = -directional_lights[i].direction;
        vec3 c = directional_lights[i].color * directional_lights[i].intensity;
        float ndl = max(dot(n, l), 0.0);
        lit += c * ndl;
        if (shininess > 0.0 && ndl > 0.0) {
            spec += c * 0.12 * pow(max(dot(n, normalize(l + v)), 0.0), shininess);
        }
    }
    shaded = vec4(clamp(base.rgb * lit + spec + material.emissive_factor, 0.0, 1.0), base.a);
#else
    shaded = base;
#endif
}
