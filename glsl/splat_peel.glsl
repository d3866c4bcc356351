// The depth peel of the layered method (DESIGN §6, Everitt 2001): a layer
// after the first keeps, per sample, the nearest splat lying beyond the
// previous layer's surface at that sample by more than the splat's own
// thickness, so that the overlapping splats of one surface stay in one
// layer. Included by splat_peel.frag (one sample per pass) and
// splat_peel_ms.frag (multisampled passes), which define PREVIOUS_Z.

layout(location = 0) flat in vec3 v_color;
layout(location = 1) flat in float v_z;
layout(location = 2) flat in float v_diameter;

layout(location = 0) out vec4 out_sample;

// A surface is this many splat diameters thick for the peel
// (src/passes/layered.rs, PEEL_THICKNESS_DIAMETERS).
const float PEEL_THICKNESS = 1.0;

void main() {
    // The previous layer's (r, g, b, z) at this sample; z = +inf where it
    // saw nothing, so nothing lies beyond it.
    if (!(v_z > PREVIOUS_Z + PEEL_THICKNESS * v_diameter)) {
        discard;
    }
    out_sample = vec4(v_color, v_z);
}
