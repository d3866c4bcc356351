// The disc splat's coverage test in a fragment shader (`--splat-shape
// disc`): the sample at gl_FragCoord lies strictly inside the disc of the
// sprite's diameter around its centre (the vertex shader's v_disc:
// framebuffer centre x, y and radius). gl_SampleID's use makes the shader
// run once per sample, where gl_FragCoord is the sample's position, so the
// disc's edge is anti-aliased by the G-buffer's samples as the square's
// is. The compute rasteriser makes the same test (splat_compute.comp).

layout(location = 3) flat in vec3 v_disc;

bool inside_disc() {
    vec2 d = gl_FragCoord.xy - v_disc.xy;
    // gl_SampleID >= 0 always: its use alone asks for sample shading.
    return gl_SampleID >= 0 && dot(d, d) < v_disc.z * v_disc.z;
}
