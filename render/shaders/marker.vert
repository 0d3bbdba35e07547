#version 330 core
// Contact markers as point sprites: one vertex per overlapping leaf sphere (centre, radius),
// expanded by the rasteriser into a square that marker.frag turns into a shaded sphere.
// Why not instanced sphere meshes: 2,000 icospheres are 160,000 triangles whose vertices llvmpipe
// transforms on the application thread; 2,000 points cost almost nothing and look the same.
// TEXCOORD_0_LOC carries (radius mm, label id: read by the label pass only). Inputs follow pyrender's buffer layout.

layout(location = 0) in vec3 position;
layout(location = TEXCOORD_0_LOC) in vec2 texcoord_0;
layout(location = INST_M_LOC) in mat4 inst_m;

uniform mat4 M;
uniform mat4 V;
uniform mat4 P;
uniform float viewport_height;  // pixels

out vec3 center_view;  // sphere centre in the camera frame, mm
out float radius;  // mm
#ifdef LABEL_TARGET
flat out float label_id;  // texcoord_0.y: the sphere's label id (orthosim_render.labels)
#endif

void main()
{
    vec4 c = V * M * inst_m * vec4(position, 1.0);
    center_view = c.xyz;
    radius = texcoord_0.x;
#ifdef LABEL_TARGET
    label_id = texcoord_0.y;
#endif
    gl_Position = P * c;
    // projected diameter in pixels (perspective: |P[1][1]| = cot(yfov / 2); the renderer mirrors
    // y, hence abs); at least 3 px so that a tiny contact never disappears
    float d = 2.0 * radius * abs(P[1][1]) / max(-c.z, 1e-3) * 0.5 * viewport_height;
    gl_PointSize = max(d, 3.0);
}
