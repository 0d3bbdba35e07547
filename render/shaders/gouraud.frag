#version 330 core
// Companion of gouraud.vert: the colour was computed per vertex, the rasteriser interpolated it.
in vec4 shaded;
#ifdef LABEL_TARGET
// The label pass rides on the colour pass (orthosim_render.labels): a second target gets the
// node's label id as two exact 8-bit channels (red the low byte, green the high byte).
layout(location = 0) out vec4 frag_color;
layout(location = 1) out vec4 label_color;
uniform vec2 label_rg;  // (id % 256, id / 256) / 255
#else
out vec4 frag_color;
#endif
void main()
{
    frag_color = shaded;
#ifdef LABEL_TARGET
    label_color = vec4(label_rg, 0.0, 1.0);
#endif
}
