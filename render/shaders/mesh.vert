#version 330 core
// orthosim Lambert vertex shader, loaded by pyrender's ShaderProgramCache(shader_dir=render/shaders).
// pyrender compiles it with NORMAL_LOC / COLOR_0_LOC / INST_M_LOC defines matching the mesh buffers.
// Why not pyrender's own mesh.vert: it inverts a 4x4 matrix per vertex to get the normal matrix;
// every pose we draw is rigid (teeth) or rigid with a uniform scale (contact markers), for which
// the model matrix's upper 3x3 followed by a normalisation gives the same normal much cheaper.

layout(location = 0) in vec3 position;
#ifdef NORMAL_LOC
layout(location = NORMAL_LOC) in vec3 normal;
#endif
#ifdef COLOR_0_LOC
layout(location = COLOR_0_LOC) in vec4 color_0;
#endif
layout(location = INST_M_LOC) in mat4 inst_m;

uniform mat4 M;
uniform mat4 V;
uniform mat4 P;

out vec3 frag_position;
out vec3 frag_normal;
out vec4 vertex_color;

void main()
{
    mat4 model = M * inst_m;
    vec4 world = model * vec4(position, 1.0);
    gl_Position = P * V * world;
    frag_position = world.xyz;
#ifdef NORMAL_LOC
    frag_normal = mat3(model) * normal;
#else
    frag_normal = vec3(0.0, 0.0, 0.0);
#endif
#ifdef COLOR_0_LOC
    vertex_color = color_0;
#else
    vertex_color = vec4(1.0);
#endif
}
