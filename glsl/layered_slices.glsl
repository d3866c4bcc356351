// The depth slices of the layered method (DESIGN §6, src/passes/layered.rs
// `Slices`): pc.slices slices of pc.slice_width px of signed CoC from
// pc.slice_lo, nearest first. A fragment belongs to the slice of its signed
// CoC and, in the first RAMP of that slice, also to the next nearer slice
// with a weight falling from 1 to 0. Needs layered_push.glsl.

// Mirrors RAMP in src/passes/layered.rs.
const float RAMP = 0.5;

// The slice of signed CoC c, and in `within` where in it c lies (0: its
// near edge, 1: its far edge).
int slice_of(float c, out float within) {
    float t = (c - pc.slice_lo) / pc.slice_width;
    int slice = clamp(int(floor(t)), 0, pc.slices - 1);
    within = clamp(t - float(slice), 0.0, 1.0);
    return slice;
}

// The weight of a fragment of signed CoC c in slice `slice`: 1 in its own
// slice, falling from 1 to 0 over the first RAMP of it in the next nearer
// one, 0 elsewhere.
float slice_weight(float c, int slice) {
    float within;
    int own = slice_of(c, within);
    if (own == slice) {
        return 1.0;
    }
    if (pc.gaussian_layers != 0u) {
        return 0.0;
    }
    if (own == slice + 1 && within < RAMP) {
        return 1.0 - within / RAMP;
    }
    return 0.0;
}

// The slices of signed CoC c with a weight above zero, as bits.
uint slice_bits(float c) {
    float within;
    int own = slice_of(c, within);
    uint bits = 1u << uint(own);
    if (own > 0 && within < RAMP && pc.gaussian_layers == 0u) {
        bits |= 1u << uint(own - 1);
    }
    return bits;
}
