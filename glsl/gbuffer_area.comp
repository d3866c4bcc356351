#version 460
// Each marked pixel's color by area (gbuffer_area.glsl): its candidates
// are the distinct splats that the samples of its window saw whose
// squares (as the raster drew them: `squares`) reach into its box; the
// nearest AREA_CANDIDATES of them by (depth, index), as the words order
// them, each weigh by the part of the box it covers and no nearer
// candidate does. The squares face the camera at one depth each and are
// aligned with the pixel grid: the box is cut into rows at the
// candidates' y edges (exact) and 64 columns (a box's x edges count to
// 1/64 of a pixel), and front to back a candidate takes the columns of
// its box, in the rows of its box, that no nearer one took. The part none
// covers is what the window's samples outside every candidate saw (the
// pixel's own, else the ring's; with none, the candidates' colors in
// proportion). The eye image keeps the samples' depth (the plain
// resolve's; the nearest candidate's where no sample saw a splat) and
// takes the color's coverage.
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_control_flow_attributes : require

layout(local_size_x = 64) in;

// One word per target pixel (splat_compute_main.glsl): the target holds
// the G-buffer rows [target_first_row, target_end_row), a band's and a
// row of its neighbours' on each side.
layout(binding = 0, std430) readonly buffer Visibility { uint64_t visibility[]; };
#define AREA_LIST_BINDING 1
#include "gbuffer_area.glsl"
#include "raster_grid.glsl"

layout(push_constant, std430) uniform AreaPush {
    ivec2 extent;          // of the G-buffer (y: the end of the band's rows)
    int first_row;         // the band's first G-buffer row
    int target_first_row;  // the G-buffer row of the target's row 0
    int target_end_row;    // the G-buffer row after the target's last
    uint target_width;     // visibility words per row
    uint scale;            // target pixels per G-buffer pixel along each axis (K)
    float color_scale;     // the linear color of a splat's code 65535 (1: white)
    vec4 background;       // linear RGB of an uncovered sample
} pc;

#include "visibility_word.glsl"

// The raster's squares by splat index: centre and edge (target pixels),
// eye depth (splat_compute_main.glsl).
layout(binding = 2, std430) readonly buffer Squares { vec4 squares[]; };
// The splats (24 bytes each: position and size, then the UNORM16 color),
// read as pairs of words: splat i's color is pair 3i + 2 (one load).
layout(binding = 3, std430) readonly buffer Splats { uvec2 splat_pairs[]; };
layout(binding = 4, rgba16f) uniform writeonly image2D gbuffer_color;
layout(binding = 5, rgba32f) uniform image2D gbuffer_eye;

// The nearest splats a pixel's color is made of, at most (mirrors
// src/passes/gbuffer_area.rs, AREA_CANDIDATES).
const int AREA_CANDIDATES = 8;
// Rows of the pixel: between its top, the boxes' 2·AREA_CANDIDATES y
// edges and its bottom. Columns: a box's x edges count to 1/64 of a pixel.
const int ROWS = 2 * AREA_CANDIDATES + 1;
const int COLUMNS = 64;

vec3 splat_color(uint i) {
    uvec2 c = splat_pairs[3u * i + 2u];
    return vec3(unpackUnorm2x16(c.x), unpackUnorm2x16(c.y).x);
}

// Puts a before b.
void order(inout float a, inout float b) {
    float lo = min(a, b);
    b = max(a, b);
    a = lo;
}

// Sorts the 16 edges ascending: Batcher's odd-even merge sort, 63
// compare-exchanges with constant places (registers, not memory indexed
// lane by lane; src/passes/gbuffer_area.rs checks that it sorts).
void sort16(inout float e[16]) {
    order(e[0], e[1]);
    order(e[2], e[3]);
    order(e[0], e[2]);
    order(e[1], e[3]);
    order(e[1], e[2]);
    order(e[4], e[5]);
    order(e[6], e[7]);
    order(e[4], e[6]);
    order(e[5], e[7]);
    order(e[5], e[6]);
    order(e[0], e[4]);
    order(e[2], e[6]);
    order(e[2], e[4]);
    order(e[1], e[5]);
    order(e[3], e[7]);
    order(e[3], e[5]);
    order(e[1], e[2]);
    order(e[3], e[4]);
    order(e[5], e[6]);
    order(e[8], e[9]);
    order(e[10], e[11]);
    order(e[8], e[10]);
    order(e[9], e[11]);
    order(e[9], e[10]);
    order(e[12], e[13]);
    order(e[14], e[15]);
    order(e[12], e[14]);
    order(e[13], e[15]);
    order(e[13], e[14]);
    order(e[8], e[12]);
    order(e[10], e[14]);
    order(e[10], e[12]);
    order(e[9], e[13]);
    order(e[11], e[15]);
    order(e[11], e[13]);
    order(e[9], e[10]);
    order(e[11], e[12]);
    order(e[13], e[14]);
    order(e[0], e[8]);
    order(e[4], e[12]);
    order(e[4], e[8]);
    order(e[2], e[10]);
    order(e[6], e[14]);
    order(e[6], e[10]);
    order(e[2], e[4]);
    order(e[6], e[8]);
    order(e[10], e[12]);
    order(e[1], e[9]);
    order(e[5], e[13]);
    order(e[5], e[9]);
    order(e[3], e[11]);
    order(e[7], e[15]);
    order(e[7], e[11]);
    order(e[3], e[5]);
    order(e[7], e[9]);
    order(e[11], e[13]);
    order(e[1], e[2]);
    order(e[3], e[4]);
    order(e[5], e[6]);
    order(e[7], e[8]);
    order(e[9], e[10]);
    order(e[11], e[12]);
    order(e[13], e[14]);
}

// The columns a box [x0, x1) covers, in COLUMNS-ths of the pixel: those
// whose centres it holds.
uint64_t columns_of(float x0, float x1, float per_target_px) {
    uint lo = uint(clamp(ceil(x0 * per_target_px - 0.5), 0.0, 64.0));
    uint hi = uint(clamp(ceil(x1 * per_target_px - 0.5), 0.0, 64.0));
    uint64_t below_hi = hi == 64u ? NOTHING : (uint64_t(1) << hi) - uint64_t(1);
    uint64_t below_lo = lo == 64u ? NOTHING : (uint64_t(1) << lo) - uint64_t(1);
    return below_hi & ~below_lo;
}

// Word's square as a box [x0, x1) × [y0, y1) in target pixels from the
// corner of the pixel whose block starts at `block`: (x0, x1, y0, y1).
vec4 box_of(uint64_t word, ivec2 block) {
    vec4 sq = squares[word_splat(word)];
    vec2 a = sq.xy - 0.5 * sq.z - vec2(block);
    vec2 b = sq.xy + 0.5 * sq.z - vec2(block);
    return vec4(a.x, b.x, a.y, b.y);
}

// Whether word's square reaches into the pixel's box [0, side)².
bool reaches_into(uint64_t word, ivec2 block, float side) {
    vec4 box = box_of(word, block);
    return min(box.y, side) > max(box.x, 0.0) && min(box.w, side) > max(box.z, 0.0);
}

void main() {
    ivec2 p;
    if (!marked_pixel(p)) {
        return;
    }
    int k = int(pc.scale);
    float side = float(k);
    ivec2 block, t_lo, t_hi;
    area_window(p, k, pc.extent.x, pc.target_first_row, pc.target_end_row, block, t_lo, t_hi);
    // The candidates, nearest first by their words. Empty places hold
    // NOTHING, beyond every splat's word. The loops over the places have a
    // constant count and are unrolled: each place is a register, not
    // memory indexed lane by lane. A word's square is loaded to test that
    // it reaches into the box, and again for the candidates kept: the list
    // moves words alone, not their boxes.
    uint64_t words[AREA_CANDIDATES];
    [[unroll]] for (int c = 0; c < AREA_CANDIDATES; ++c) {
        words[c] = NOTHING;
    }
    // No word is 0: a splat's depth is beyond the near plane.
    uint64_t last = uint64_t(0);
    for (int y = t_lo.y; y < t_hi.y; ++y) {
        for (int x = t_lo.x; x < t_hi.x; ++x) {
            uint64_t word = word_at(ivec2(x, y));
            // Background, repeats (the last word seen, one kept), and
            // beyond the farthest of a full list.
            bool skip = word == NOTHING || word == last || word > words[AREA_CANDIDATES - 1];
            [[unroll]] for (int c = 0; c < AREA_CANDIDATES; ++c) {
                skip = skip || words[c] == word;
            }
            last = word;
            if (skip || !reaches_into(word, block, side)) {
                continue;
            }
            // Into its place; the farthest falls off a full list.
            [[unroll]] for (int c = 0; c < AREA_CANDIDATES; ++c) {
                uint64_t w = words[c];
                words[c] = min(w, word);
                word = max(w, word);
            }
        }
    }
    int n = 0;
    [[unroll]] for (int c = 0; c < AREA_CANDIDATES; ++c) {
        n += words[c] != NOTHING ? 1 : 0;
    }
    if (n == 0) {
        // No splat reaches the box but by less than a float's step: the
        // plain resolve's color stays.
        return;
    }
    // Their squares (target pixels from the pixel's corner: x0, x1, y0,
    // y1; the pixel's box is [0, K]²); an empty place's is empty.
    vec4 boxes[AREA_CANDIDATES];
    [[unroll]] for (int c = 0; c < AREA_CANDIDATES; ++c) {
        boxes[c] = c < n ? box_of(words[c], block) : vec4(0.0);
    }
    // What the candidates leave uncovered is what the window's samples
    // outside every candidate saw (background, or splats past a full
    // list): the pixel's own, if any lies there, else the ring's; with
    // none, the candidates' colors fill it in proportion.
    vec4 rest_own = vec4(0.0), rest_ring = vec4(0.0);  // color sum, hits
    float own_samples = 0.0, ring_samples = 0.0;
    float inv_k = 1.0 / side;
    // Row by row: first which of the row's samples lie outside every
    // candidate (bits by column), then their words alone, in the same
    // order. llvmpipe runs a branch's body whenever any of a row of eight
    // lanes takes it, so loads under a test of each sample cost every
    // sample's; a loop over the set bits runs as often as the lane with
    // the most.
    for (int y = t_lo.y; y < t_hi.y; ++y) {
        int v = y - block.y;
        int j = v < 0 ? k - 1 : (v >= k ? 0 : v);
        uint outside = 0u;
        for (int x = t_lo.x; x < t_hi.x; ++x) {
            int u = x - block.x;
            int i = u < 0 ? k - 1 : (u >= k ? 0 : u);
            vec2 s = vec2(u - i, v - j) + block_sample(i, j, k, inv_k);
            bool inside = false;
            [[unroll]] for (int c = 0; c < AREA_CANDIDATES; ++c) {
                vec4 b = boxes[c];
                inside = inside || (s.x >= b.x && s.x < b.y && s.y >= b.z && s.y < b.w);
            }
            outside |= inside ? 0u : 1u << uint(x - t_lo.x);
        }
        while (outside != 0u) {
            int x = t_lo.x + findLSB(outside);
            outside &= outside - 1u;
            int u = x - block.x;
            uint64_t word = word_at(ivec2(x, y));
            vec4 seen = word == NOTHING
                ? vec4(pc.background.rgb, 0.0)
                : vec4(pc.color_scale * splat_color(word_splat(word)), 1.0);
            bool own = u >= 0 && u < k && v >= 0 && v < k;
            rest_own += own ? seen : vec4(0.0);
            own_samples += own ? 1.0 : 0.0;
            rest_ring += own ? vec4(0.0) : seen;
            ring_samples += own ? 0.0 : 1.0;
        }
    }
    vec4 rest_sum = own_samples > 0.0 ? rest_own : rest_ring;
    float rest_samples = own_samples > 0.0 ? own_samples : ring_samples;
    // The pixel in rows at the boxes' y edges (exact) and 64 columns: a
    // candidate takes the columns of its box, in the rows of its box,
    // that no nearer one took.
    float e[16];
    [[unroll]] for (int c = 0; c < AREA_CANDIDATES; ++c) {
        e[2 * c] = c < n ? clamp(boxes[c].z, 0.0, side) : side;
        e[2 * c + 1] = c < n ? clamp(boxes[c].w, 0.0, side) : side;
    }
    sort16(e);
    float row_lo[ROWS], row_hi[ROWS];
    uint64_t taken[ROWS];
    [[unroll]] for (int r = 0; r < ROWS; ++r) {
        row_lo[r] = r == 0 ? 0.0 : e[r - 1];
        row_hi[r] = r == ROWS - 1 ? side : e[r];
        taken[r] = uint64_t(0);
    }
    float per_target_px = float(COLUMNS) / side;
    vec3 color = vec3(0.0);
    float covered = 0.0;
    [[unroll]] for (int c = 0; c < AREA_CANDIDATES; ++c) {
        if (c < n) {
            vec4 box = boxes[c];
            uint64_t columns = columns_of(box.x, box.y, per_target_px);
            float area = 0.0;
            [[unroll]] for (int r = 0; r < ROWS; ++r) {
                if (row_lo[r] >= box.z && row_hi[r] <= box.w) {
                    uint64_t fresh = columns & ~taken[r];
                    taken[r] |= columns;
                    uvec2 halves = unpack32(fresh);
                    area += float(bitCount(halves.x) + bitCount(halves.y)) * (row_hi[r] - row_lo[r]);
                }
            }
            area /= per_target_px;
            color += area * splat_color(word_splat(words[c]));
            covered += area;
        }
    }
    color *= pc.color_scale;
    float box_area = side * side;
    vec4 result;
    if (rest_samples > 0.0) {
        float rest = max(box_area - covered, 0.0) / rest_samples;
        result = (vec4(color, covered) + rest * rest_sum) / box_area;
    } else {
        result = vec4(color / covered, 1.0);
    }
    imageStore(gbuffer_color, p, result);
    // A pixel none of whose samples saw a splat, with candidates over part
    // of it: their nearest depth (covered pixels have a depth).
    vec4 eye = imageLoad(gbuffer_eye, p);
    float z = isinf(eye.z) ? word_depth(words[0]) : eye.z;
    imageStore(gbuffer_eye, p, vec4(eye.xy, z, result.a));
}
