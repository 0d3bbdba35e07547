#version 300 es
// The id pass (picking and the browser test): the same transform as tooth.vert, no lighting.
precision highp float;

layout(location = 0) in vec3 position;

uniform mat4 M;
uniform mat4 V;
uniform mat4 P;

void main()
{
    gl_Position = P * V * M * vec4(position, 1.0);
}
