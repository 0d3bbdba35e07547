#version 330 core
// Turns a point sprite into a lit sphere: discards the corners, writes the sphere's true depth so
// that a marker half inside a tooth shows only its outer half, exactly where the contact is.

uniform mat4 P;
uniform vec4 marker_color;
uniform vec3 marker_emissive;

in vec3 center_view;
in float radius;

#ifdef LABEL_TARGET
flat in float label_id;
layout(location = 0) out vec4 frag_color;
layout(location = 1) out vec4 label_color;  // as in gouraud.frag
#else
out vec4 frag_color;
#endif

void main()
{
    // gl_PointCoord's t runs toward window -y, which is camera +y: the renderer draws the image
    // mirrored vertically (see render/renderer.py, _frame_constants)
    vec2 q = gl_PointCoord * 2.0 - 1.0;
    float rr = dot(q, q);
    if (rr > 1.0) {
        discard;
    }
    vec3 n = vec3(q, sqrt(1.0 - rr));  // camera frame, toward the viewer
    vec3 p = center_view + radius * n;
    vec4 clip = P * vec4(p, 1.0);
    gl_FragDepth = clamp(0.5 * clip.z / clip.w + 0.5, 0.0, 1.0);
    // fixed key light from the upper left of the viewer, as the tooth light rig
    float ndl = max(dot(n, normalize(vec3(-0.45, 0.55, 0.70))), 0.0);
    vec3 rgb = marker_color.rgb * (0.35 + 0.75 * ndl) + marker_emissive;
    frag_color = vec4(clamp(rgb, 0.0, 1.0), marker_color.a);
#ifdef LABEL_TARGET
    float id = floor(label_id + 0.5);
    float high = floor(id / 256.0);
    label_color = vec4((id - 256.0 * high) / 255.0, high / 255.0, 0.0, 1.0);
#endif
}
