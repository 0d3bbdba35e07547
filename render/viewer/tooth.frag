#version 300 es
// Companion of tooth.vert (render/shaders/gouraud.frag in GLSL ES 3.00): the colour was computed
// per vertex and interpolated by the rasteriser.
precision mediump float;

in vec4 shaded;
out vec4 frag_color;

void main()
{
    frag_color = shaded;
}
