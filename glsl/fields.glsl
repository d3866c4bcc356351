// The bounded two-field gather (issue 28, item 5): constants, layouts and
// helpers of its passes, mirrored from src/fields.rs (the CPU reference;
// tests/fields.rs holds the passes to it).

const float FIELDS_B0 = 3.0;             // fields::B0
const float FIELDS_BAND = 4.0;           // fields::BAND
const int FIELDS_RINGS = 3;              // fields::RINGS
const int FIELDS_LEVELS = 6;             // fields::LEVELS
const int FIELDS_STEPS = 512;            // fields::TABLE_STEPS
const float FIELDS_HALF_DIAGONAL = 0.7072; // fields::HALF_DIAGONAL
const int FIELDS_COUNT_MAX = 65535;      // fields::DISK_COUNT_MAX
const int FIELDS_TAPS = 1 + 4 * FIELDS_RINGS * (FIELDS_RINGS + 1); // fields::ring_taps
const float FIELDS_PI = 3.14159265358979;

// The tables buffer (fields::tables()): the full-resolution band's overlap
// table (45 rows), the rings' (57 rows), N(r) by floor(r²), the ring taps.
const int FIELDS_T0_ROWS = 45;           // OverlapTable::new(B0).offsets.len()
const int FIELDS_T1_ROWS = 57;           // OverlapTable::new(small_radius()).offsets.len()
// The band spread's reach in whole texels: ceil(BAND + 1/2 + HALF_DIAGONAL)
// (fields::band_offsets).
const int FIELDS_BAND_REACH = 6;
const int FIELDS_T0_BASE = 0;
const int FIELDS_T1_BASE = FIELDS_T0_BASE + FIELDS_T0_ROWS * (FIELDS_STEPS + 1);
const int FIELDS_COUNT_BASE = FIELDS_T1_BASE + FIELDS_T1_ROWS * (FIELDS_STEPS + 1);
const int FIELDS_TAPS_BASE = FIELDS_COUNT_BASE + FIELDS_COUNT_MAX + 1;

layout(push_constant, std430) uniform Push {
    ivec2 extent;   // G-buffer size
    ivec2 origin;   // first output pixel (the guard band)
    ivec2 size;     // output size
    ivec2 anchor;   // G-buffer pixel g is texel (g + anchor) >> l of level l
    float f_px;
    float aperture_radius;
    float focus_distance;
    int level;      // fields_far: the level written
} pc;

float fields_radius(float z) {
    return 0.5 * coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance);
}

// Texels of level l (2^l px) over the G-buffer, whose pixel g lies in
// texel (g + anchor) >> l: the texels of a tile are the whole frame's
// (passes::fields::anchor; 0 for a whole frame, as fields::reference
// has it).
ivec2 fields_level_size(int l) {
    return (pc.extent + pc.anchor + (1 << l) - 1) >> l;
}

// Texels of the far mip's levels before l (level 0 first).
uint fields_far_offset(int l) {
    uint n = 0u;
    for (int i = 0; i < l; ++i) {
        ivec2 s = fields_level_size(i);
        n += uint(s.x * s.y);
    }
    return n;
}

// Texels of the band levels before l (level 1 first).
uint fields_band_offset(int l) {
    ivec2 s = fields_level_size(0);
    return fields_far_offset(l) - uint(s.x * s.y);
}

// The band level (1..FIELDS_LEVELS) of CoC radius r, 0 under FIELDS_B0.
int fields_band_level(float r) {
    if (r < FIELDS_B0) {
        return 0;
    }
    for (int l = 1; l < FIELDS_LEVELS; ++l) {
        if (r < FIELDS_BAND * float(1 << l)) {
            return l;
        }
    }
    return FIELDS_LEVELS;
}

// fields::band_weight: d and cen as (x, y).
float fields_band_weight(float rho, ivec2 d, vec2 cen) {
    vec2 v = vec2(d) + cen;
    return clamp(rho - sqrt(v.x * v.x + v.y * v.y) + 0.5, 0.0, 1.0);
}

// fields::OverlapTable::step.
int fields_step(float r, float r_max) {
    return int(clamp(roundEven(r * float(FIELDS_STEPS) / r_max), 0.0, float(FIELDS_STEPS)));
}

// The largest |dx| with dx² + dy² < reach2 (-1: none): a disk's row, so
// that loops over the integer offsets of a disk (fields::disk_offsets,
// row by row) take only its offsets.
int fields_row_half(float reach2, int dy) {
    float rest = reach2 - float(dy * dy);
    if (rest <= 0.0) {
        return -1;
    }
    int h = int(floor(sqrt(rest)));
    while (h >= 0 && float(h * h + dy * dy) >= reach2) {
        --h;
    }
    while (float((h + 1) * (h + 1) + dy * dy) < reach2) {
        ++h;
    }
    return h;
}
