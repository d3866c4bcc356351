// The compute rasteriser (issue 28, item 2; Schütz et al. 2021): splats
// drawn by compute shaders into a 64-bit visibility buffer, one word per
// target pixel, (eye depth bits << 32) | splat index, kept by atomicMin:
// the nearest splat, and on exact depth ties the earlier one, as the
// sprite path's depth test keeps it. The G-buffer resolve
// (gbuffer_resolve_vis.comp) reads each word's splat color.
//
// A splat covers the target pixels whose sample lies in its square,
// [p − size/2, p + size/2) along each axis (the sprite rule of the
// Vulkan specification, without the sprite path's rounding of the
// position to sub-pixel steps and of the size to the point-size
// granularity). Positions and sizes are those of splat_raster.vert
// (splat_project.glsl).
//
// The samples: a G-buffer pixel is a block of k × k target pixels (k the
// push block's cells), and the target pixel in the block's column i and
// row j samples at (i + 1 − (j + ½)/k, j + (i + ½)/k) target pixels from
// the block's corner: a grid rotated by atan(1/k), so that the k² samples
// of a pixel fall in k² different columns and rows of 1/k² pixel each
// (at k = 2 the standard 4-sample locations; at k = 1 the pixel centre).
// A splat is an axis-aligned square: a k × k grid of cell centres sees
// its edges in steps of 1/k pixel, the rotated grid in steps of 1/k²
// (docs/ARCHITECTURE.md, the compute rasteriser, *The rotated grid*).
//
// Two stages of one shader:
//   0: one invocation per splat; a square of at most LARGE_PIXELS target
//      pixels is drawn there, a larger one is appended to the large list,
//      whose first word is the x count of the next stage's dispatch;
//   1: per large splat, workgroups (y) of CHUNK_PIXELS of its pixels
//      each, shared out over the workgroup's invocations (a lavapipe
//      invocation runs its loop alone: one big square would hold up its
//      whole SIMD group). Chunks keep an invocation's loop at 16,384
//      iterations at most: llvmpipe ends an invocation's loops after
//      65,535 iterations in all (LP_MAX_TGSI_LOOP_ITERATIONS), and a
//      255 px splat at SSAA 16 covers 16.6 M target pixels, 260,000 each
//      for 64 invocations (drawn in bands with gaps before the chunks).
//
// With SPLAT_PEEL (splat_compute_peel*.comp) it is the depth peel of the
// layered method's later layers, as splat_peel_frag.glsl is for the
// sprites: a target pixel keeps only the splats beyond the previous
// layer's resolved depth at its G-buffer pixel by more than their
// thickness. The target is then the whole G-buffer, a whole number of
// times its size along each axis (one band).
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#include "lens.glsl"

layout(local_size_x = 64) in;

// The splats as the vertex buffer holds them: per splat 6 words, position
// and world diameter as 4 floats, the UNORM16 color as 2 words.
layout(binding = 0, std430) readonly buffer Splats { uint splats[]; };
// One word per target pixel, row by row; cleared to all ones (nothing).
layout(binding = 1, std430) buffer Visibility { uint64_t visibility[]; };
// A VkDispatchIndirectCommand (x: large splats, then 1, 1), a pad word,
// then the large splats' indices.
layout(binding = 2, std430) buffer Large { uint large_dispatch[4]; uint large[]; };

#include "splat_compute_push.glsl"

#include "splat_project.glsl"

#ifdef SPLAT_PEEL
// The previous layer's G-buffer eye image: (0, 0, z, coverage), z = +inf
// where it saw nothing (so nothing lies beyond it).
layout(binding = 3, rgba32f) uniform readonly image2D previous;

// A surface is this many splat diameters thick for the peel
// (src/passes/splat_raster.rs, PEEL_THICKNESS_DIAMETERS).
const float PEEL_THICKNESS = 1.0;
#else
// Per splat index, the square as this pass drew it: centre (target
// pixels), edge (target pixels), eye depth; written by the first stage
// for every splat with target pixels in its box, read by the area pass
// (gbuffer_area.comp) for the splats its words name.
layout(binding = 3, std430) writeonly buffer Squares { vec4 squares[]; };
// Per tile of the marking (area_tiles.glsl), 1 where a drawn splat's box
// reaches it; cleared before the pass. Written with the squares.
layout(binding = 4, std430) buffer Touched { uint touched[]; };
#include "area_tiles.glsl"

// Flags the tiles that the target pixels [lo, hi] (inclusive, a splat's
// box), one target pixel past them, reach: a pixel whose window holds one
// of them lies in one of those tiles. An atomic, as other splats flag the
// same tiles at once.
void touch_tiles(ivec2 lo, ivec2 hi, int k) {
    int tile = AREA_TILE_PX * k;
    int width_px = int(pc.extent.x) / k;
    ivec2 last = (ivec2(width_px, int(pc.extent.y) / k) - 1) / AREA_TILE_PX;
    ivec2 first_tile = max(lo - 1, ivec2(0)) / tile;
    ivec2 last_tile = min((hi + 1) / tile, last);
    int per_row = area_tiles_per_row(width_px);
    for (int y = first_tile.y; y <= last_tile.y; ++y) {
        for (int x = first_tile.x; x <= last_tile.x; ++x) {
            atomicOr(touched[y * per_row + x], 1u);
        }
    }
}
#endif

// Squares of more target pixels go to the large list (mirrors
// src/passes/splat_compute.rs, LARGE_PIXELS).
const uint LARGE_PIXELS = 4096u;
// Target pixels of a large splat per workgroup of stage 1 (mirrors
// src/passes/splat_compute.rs, CHUNK_PIXELS).
const uint CHUNK_PIXELS = 1048576u;

vec4 position_size(uint i) {
    return vec4(uintBitsToFloat(splats[6u * i]), uintBitsToFloat(splats[6u * i + 1u]),
                uintBitsToFloat(splats[6u * i + 2u]), uintBitsToFloat(splats[6u * i + 3u]));
}

// Target pixels per G-buffer pixel along each axis: the cells of the
// rotated sample grid (src/passes/splat_compute.rs, ComputeRaster::record).
int cells() {
    return int(pc.stage_cells >> 16u);
}

#include "raster_grid.glsl"

// The target pixels t along an axis (first, last; empty when last <
// first) whose sample, `offset` past t, lies in
// [centre − size/2, centre + size/2).
ivec2 span(float centre, float size, float offset) {
    return ivec2(ceil(centre - 0.5 * size - offset), ceil(centre + 0.5 * size - offset) - 1.0);
}

bool in_span(int t, ivec2 span) {
    return t >= span.x && t <= span.y;
}

// The splat's box along an axis: the target pixels with a sample in
// [centre − size/2, centre + size/2) at some cell, from the largest
// offset's first to the smallest's last; clamped to the target.
ivec2 covered(float centre, float size, float extent, int k, float inv_k) {
    float lo = float(span(centre, size, cell_offset(k - 1, inv_k)).x);
    float hi = float(span(centre, size, cell_offset(0, inv_k)).y);
    return ivec2(clamp(lo, 0.0, extent), clamp(hi, -1.0, extent - 1.0));
}

// Whether target pixel (x, y), at cells (i, j), is the splat's: its
// sample lies in the square; for a disc (SPLAT_DISC, `--splat-shape
// disc`) strictly inside the disc of the square's diameter, as the
// sprites' disc test (splat_disc.glsl).
bool covers(Projected s, int x, int y, int i, int j, int k, float inv_k) {
    float ox = cell_offset(k - 1 - j, inv_k);
    float oy = cell_offset(i, inv_k);
#ifdef SPLAT_DISC
    vec2 d = vec2(float(x) + ox, float(y) + oy) - s.p;
    float r = 0.5 * s.size_px;
    return dot(d, d) < r * r;
#else
    return in_span(x, span(s.p.x, s.size_px, ox)) && in_span(y, span(s.p.y, s.size_px, oy));
#endif
}

// Draws the splat's target pixels of row y (cell row j) from column x0
// (cell column i0) to x1, all within its box: those `covers` keeps. For a
// square, the same test by the row: the columns of the row's span, and of
// them those whose cell column's span holds y (every one in a row inside
// the smallest and the largest offset's spans: the spans move with the
// offset).
void draw_row(Projected s, uint64_t word, int y, int j, int x0, int x1, int i0, int k,
              float inv_k) {
    uint row = uint(y) * uint(pc.extent.x);
#ifdef SPLAT_DISC
    for (int x = x0, i = i0; x <= x1; ++x, i = i + 1 == k ? 0 : i + 1) {
        if (covers(s, x, y, i, j, k, inv_k)) {
            atomicMin(visibility[row + uint(x)], word);
        }
    }
#else
    ivec2 xr = span(s.p.x, s.size_px, cell_offset(k - 1 - j, inv_k));
    uint columns = 0xffffffffu;
    if (!in_span(y, span(s.p.y, s.size_px, cell_offset(0, inv_k)))
        || !in_span(y, span(s.p.y, s.size_px, cell_offset(k - 1, inv_k)))) {
        columns = 0u;
        for (int c = 0; c < k; ++c) {
            columns |= uint(in_span(y, span(s.p.y, s.size_px, cell_offset(c, inv_k)))) << uint(c);
        }
    }
    // The row's span starts at most a pixel after the box (the offsets
    // differ by less than a pixel).
    int first = max(x0, xr.x);
    int i = i0 + (first - x0);
    i = i >= k ? i - k : i;
    for (int x = first; x <= min(x1, xr.y); ++x, i = i + 1 == k ? 0 : i + 1) {
        if (((columns >> uint(i)) & 1u) != 0u) {
            atomicMin(visibility[row + uint(x)], word);
        }
    }
#endif
}

#ifdef SPLAT_PEEL
// Draws the splat's target pixels (xs × ys) within G-buffer pixel g, of
// k × k target pixels, where the splat lies beyond the previous layer
// there by more than its thickness, as splat_peel_frag.glsl tests it: the
// test once for the pixel's k² target pixels.
void peel_gbuffer_pixel(Projected s, uint64_t word, ivec2 xs, ivec2 ys, ivec2 g, int k,
                        float inv_k) {
    if (s.z > imageLoad(previous, g).z + PEEL_THICKNESS * s.diameter) {
        int x0 = max(xs.x, g.x * k);
        int x1 = min(xs.y, g.x * k + k - 1);
        for (int y = max(ys.x, g.y * k); y <= min(ys.y, g.y * k + k - 1); ++y) {
            draw_row(s, word, y, y - g.y * k, x0, x1, x0 - g.x * k, k, inv_k);
        }
    }
}
#endif

void main() {
    uint i;
    if (pass_stage() == 0u) {
        i = gl_GlobalInvocationID.x;
        if (i >= pc.count) {
            return;
        }
    } else {
        i = large[gl_WorkGroupID.x];
    }
    Projected s;
    if (!project_splat(position_size(i), vec2(0.0), s)) {
        return;
    }
    int k = cells();
    float inv_k = 1.0 / float(k);
    ivec2 xs = covered(s.p.x, s.size_px, pc.extent.x, k, inv_k);
    ivec2 ys = covered(s.p.y, s.size_px, pc.extent.y, k, inv_k);
    if (xs.y < xs.x || ys.y < ys.x) {
        return;
    }
    uint w = uint(xs.y - xs.x + 1);
    uint n = w * uint(ys.y - ys.x + 1);
    uint width = uint(pc.extent.x);
    uint64_t word = (uint64_t(floatBitsToUint(s.z)) << 32) | uint64_t(i);
    if (pass_stage() == 0u) {
#ifndef SPLAT_PEEL
        if (writes_squares()) {
            squares[i] = vec4(s.p, s.size_px, s.z);
            touch_tiles(ivec2(xs.x, ys.x), ivec2(xs.y, ys.y), k);
        }
#endif
        if (n > LARGE_PIXELS) {
            large[atomicAdd(large_dispatch[0], 1u)] = i;
            return;
        }
#ifdef SPLAT_PEEL
        // By G-buffer pixel: the peel's test once for its scale² target
        // pixels (the same target pixels as testing each).
        for (int gy = ys.x / k; gy <= ys.y / k; ++gy) {
            for (int gx = xs.x / k; gx <= xs.y / k; ++gx) {
                peel_gbuffer_pixel(s, word, xs, ys, ivec2(gx, gy), k, inv_k);
            }
        }
#else
        int i0 = xs.x % k;
        for (int y = ys.x, j = ys.x % k; y <= ys.y; ++y, j = j + 1 == k ? 0 : j + 1) {
            draw_row(s, word, y, j, xs.x, xs.y, i0, k, inv_k);
        }
#endif
    } else {
#ifdef SPLAT_PEEL
        // By G-buffer pixel, as above: each invocation tests a G-buffer
        // pixel of the square once, then takes its target pixels; a chunk
        // holds CHUNK_PIXELS / scale² G-buffer pixels (no more loop
        // iterations per invocation than a chunk of target pixels).
        ivec2 g_lo = ivec2(xs.x, ys.x) / k;
        uint gw = uint(xs.y / k - g_lo.x + 1);
        uint gn = gw * uint(ys.y / k - g_lo.y + 1);
        uint chunk = CHUNK_PIXELS / uint(k * k);
        uint first = gl_WorkGroupID.y * chunk;
        uint end = min(gn, first + chunk);
        for (uint j = first + gl_LocalInvocationID.x; j < end; j += gl_WorkGroupSize.x) {
            peel_gbuffer_pixel(s, word, xs, ys, g_lo + ivec2(j % gw, j / gw), k, inv_k);
        }
#else
        uint first = gl_WorkGroupID.y * CHUNK_PIXELS;
        uint end = min(n, first + CHUNK_PIXELS);
        for (uint m = first + gl_LocalInvocationID.x; m < end; m += gl_WorkGroupSize.x) {
            int x = xs.x + int(m % w);
            int y = ys.x + int(m / w);
            if (covers(s, x, y, x % k, y % k, k, inv_k)) {
                atomicMin(visibility[uint(y) * width + uint(x)], word);
            }
        }
#endif
    }
}
