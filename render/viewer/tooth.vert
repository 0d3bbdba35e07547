#version 300 es
// orthosim's per-vertex (Gouraud) lighting of render/shaders/gouraud.vert, ported to GLSL ES 3.00
// for the page (viewer.js): ambient + the camera-fixed directional rig of render/scene.py + a faint
// specular highlight, so the page shades teeth as the frames do. Colours are the frames' own
// (sRGB values used as they are, as the offscreen renderer does).
precision highp float;

layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;

uniform mat4 M;
uniform mat4 V;
uniform mat4 P;
uniform vec4 base_color;
uniform vec3 emissive;
uniform float shininess;  // 0: no highlight (markers, gum)
uniform vec3 cam_pos;
uniform vec3 ambient_light;
uniform vec3 light_direction[3];  // world frame, the way each light travels
uniform vec3 light_color[3];  // colour x intensity

out vec4 shaded;

void main()
{
    vec4 world = M * vec4(position, 1.0);
    gl_Position = P * V * world;
    // rigid poses, or rigid with a uniform scale (markers): the 3x3 part maps normals correctly
    vec3 n = normalize(mat3(M) * normal);
    vec3 v = normalize(cam_pos - world.xyz);
    vec3 lit = ambient_light;
    vec3 spec = vec3(0.0);
    for (int i = 0; i < 3; i++) {
        vec3 l = -light_direction[i];
        float ndl = max(dot(n, l), 0.0);
        lit += light_color[i] * ndl;
        if (shininess > 0.0 && ndl > 0.0) {
            spec += light_color[i] * 0.12 * pow(max(dot(n, normalize(l + v)), 0.0), shininess);
        }
    }
    shaded = vec4(clamp(base_color.rgb * lit + spec + emissive, 0.0, 1.0), base_color.a);
}
