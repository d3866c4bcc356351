// The depth peel of the layered method (DESIGN §6, Everitt 2001): a layer
// after the first keeps, per sample, the nearest splat lying beyond the
// previous layer's surface at this pixel — its resolved G-buffer depth,
// the nearest of its samples — by more than the splat's own thickness, so
// that the overlapping splats of one surface stay in one layer. Shaded
// once per pixel; the depth test picks the nearest kept splat per sample.

layout(location = 0) flat in vec3 v_color;
layout(location = 1) flat in float v_z;
layout(location = 2) flat in float v_diameter;

// The previous layer's G-buffer eye image: (0, 0, z, coverage), z = +inf
// where it saw nothing (so nothing lies beyond it).
layout(binding = 0, rgba32f) uniform readonly image2D previous;

layout(location = 0) out vec4 out_sample;

// A surface is this many splat diameters thick for the peel
// (src/passes/splat_raster.rs, PEEL_THICKNESS_DIAMETERS).
const float PEEL_THICKNESS = 1.0;

#ifdef SPLAT_DISC
#include "splat_disc.glsl"
#endif

void main() {
#ifdef SPLAT_DISC
    if (!inside_disc()) {
        discard;
    }
#endif
    ivec2 p = ivec2(gl_FragCoord.xy);
    // The sample target may be a pixel wider than the G-buffer.
    if (any(greaterThanEqual(p, imageSize(previous)))) {
        discard;
    }
    if (!(v_z > imageLoad(previous, p).z + PEEL_THICKNESS * v_diameter)) {
        discard;
    }
    out_sample = vec4(v_color, v_z);
}
