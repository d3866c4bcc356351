// Writes a splat's linear color and eye depth into one sample: (r, g, b, z).
// The depth test (LESS) keeps the nearest splat, and the earlier one on
// exact ties; an uncovered sample keeps the clear value (background, +inf).

// With SPLAT_DISC (splat_raster_disc.frag, `--splat-shape disc`) a splat
// is the disc inscribed in its square: samples outside it are discarded,
// per sample (splat_disc.glsl).

layout(location = 0) flat in vec3 v_color;
layout(location = 1) flat in float v_z;

layout(location = 0) out vec4 out_sample;

#ifdef SPLAT_DISC
#include "splat_disc.glsl"
#endif

void main() {
#ifdef SPLAT_DISC
    if (!inside_disc()) {
        discard;
    }
#endif
    out_sample = vec4(v_color, v_z);
}
