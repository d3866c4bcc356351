#version 460
// Writes a splat's linear color and eye position; the depth test (LESS)
// keeps the nearest splat, and the earlier one on exact ties.

layout(location = 0) flat in vec3 v_color;
layout(location = 1) flat in vec3 v_eye;

layout(location = 0) out vec4 out_color;
layout(location = 1) out vec4 out_eye;

void main() {
    out_color = vec4(v_color, 1.0);
    out_eye = vec4(v_eye, 1.0);
}
