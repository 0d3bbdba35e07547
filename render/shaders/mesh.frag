#version 330 core
// orthosim Lambert fragment shader: ambient plus up to MAX_DIRECTIONAL_LIGHTS directional lights
// (the fixed rig of render/scene.py) and a faint specular highlight so that enamel reads as enamel.
// Why not pyrender's mesh.frag: its physically based model (image-based terms, per-light Fresnel
// and geometry terms) dominates the frame time on llvmpipe, and clinicians need shape, not PBR.
// Colour = material base colour factor (the per-tooth tint) x vertex colour (crown, root, contact).
// Back faces (seen through a clipped or open mesh) are lit with the flipped normal.

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

uniform Material material;
uniform vec3 cam_pos;
uniform vec3 ambient_light;
uniform int n_directional_lights;
uniform DirectionalLight directional_lights[MAX_DIRECTIONAL_LIGHTS + 1];

in vec3 frag_position;
in vec3 frag_normal;
in vec4 vertex_color;

out vec4 frag_color;

void main()
{
    vec4 base = material.base_color_factor * vertex_color;
    vec3 n = frag_normal;
    float len_n = length(n);
    vec3 rgb;
    if (len_n < 1e-6) {
        rgb = base.rgb;  // no normals: unlit marker colour
    } else {
        n /= len_n;
        vec3 v = normalize(cam_pos - frag_position);
        if (dot(n, v) < 0.0) {
            n = -n;
        }
        vec3 lit = ambient_light;
        vec3 spec = vec3(0.0);
        for (int i = 0; i < n_directional_lights; i++) {
            vec3 l = -directional_lights[i].direction;
            vec3 c = directional_lights[i].color * directional_lights[i].intensity;
            float ndl = max(dot(n, l), 0.0);
            lit += c * ndl;
            vec3 h = normalize(l + v);
            // Roughness 1 (markers) switches the highlight off; enamel uses ~0.5.
            float shininess = mix(48.0, 0.0, material.roughness_factor);
            if (shininess > 0.0 && ndl > 0.0) {
                spec += c * 0.12 * pow(max(dot(n, h), 0.0), shininess);
            }
        }
        rgb = base.rgb * lit + spec + material.emissive_factor;
    }
    frag_color = vec4(clamp(rgb, 0.0, 1.0), base.a);
}
