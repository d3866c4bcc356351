#version 460
// Writes a splat's linear color and eye depth into one sample: (r, g, b, z).
// The depth test (LESS) keeps the nearest splat, and the earlier one on
// exact ties; an uncovered sample keeps the clear value (background, +inf).

layout(location = 0) flat in vec3 v_color;
layout(location = 1) flat in float v_z;

layout(location = 0) out vec4 out_sample;

void main() {
    out_sample = vec4(v_color, v_z);
}
