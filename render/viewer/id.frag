#version 300 es
// The id pass: each node in one flat colour that encodes what it is (red: the FDI number of a
// tooth, blue: 1 for a tooth), read back by viewer.js for hover and by the browser test.
precision mediump float;

uniform vec4 id_color;
out vec4 frag_color;

void main()
{
    frag_color = id_color;
}
