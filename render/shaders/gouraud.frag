#version 330 core
// Companion of gouraud.vert: the colour was computed per vertex, the rasteriser interpolated it.
in vec4 shaded;
out vec4 frag_color;
void main()
{
    frag_color = shaded;
}
