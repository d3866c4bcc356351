// Resolves the compute rasteriser's visibility buffer (splat_compute.comp)
// into the G-buffer: a target pixel's sample is its word's splat — linear
// color as the vertex input reads the UNORM16 color, eye depth from the
// word's upper half — or (background, +inf) where no splat covers it, as
// the sprite path's cleared sample; then the fold of
// gbuffer_resolve_blocks.glsl. Included by gbuffer_resolve_vis.comp and,
// with AREA_MARKS, by gbuffer_resolve_vis_marks.comp, which also marks
// the pixels that resolve by area (gbuffer_area.glsl).
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x = 16, local_size_y = 16) in;

layout(binding = 0, std430) readonly buffer Visibility { uint64_t visibility[]; };
layout(binding = 1, rgba32f) uniform image2D color_sum;
layout(binding = 2, rgba32f) uniform image2D gbuffer_eye;   // w: nearest's index, then coverage
layout(binding = 3, rgba16f) uniform writeonly image2D gbuffer_color;
// The splats (24 bytes each: position and size, then the UNORM16 color),
// read as pairs of words: splat i's color is pair 3i + 2 (one load).
layout(binding = 4, std430) readonly buffer Splats { uvec2 splat_pairs[]; };

layout(push_constant, std430) uniform VisPush {
    ivec2 extent;        // of the G-buffer (y: the end of the band's rows)
    uint sample_index;   // of this pass's first sample
    uint sample_count;   // samples of the whole G-buffer
    uint scale;          // target pixels per output pixel along each axis
    int first_row;       // the band's first G-buffer row
    uint target_width;   // visibility words per row
    int target_first_row; // the G-buffer row of the target's row 0
    vec4 background;     // linear RGB of an uncovered sample
    vec2 lens_u;         // this pass's lens position
    ivec2 window_origin; // the frame pixel of G-buffer pixel (0, 0)
    ivec2 frame_size;    // the whole frame, pixels
    float cat_eye;       // S (0: off)
    float half_cell;     // a lens sample's cell (Aperture::lens_cell_half_width)
    float color_scale;   // the linear color of a splat's code 65535 (1: white)
    int target_end_row;  // the G-buffer row after the target's last
    // The lens that blurs the G-buffer after it: f_px, aperture radius,
    // focus distance, the CoC (px) past which no pixel is marked, and,
    // for the cat's eye, its S and the shape's least reach, by which each
    // pixel's limit grows (ResolvePass::area_blur; zeros: none).
    float area_blur[6];
} pc;

#include "visibility_word.glsl"

vec4 target_sample(ivec2 q) {
    uint64_t word = word_at(q);
    if (word == NOTHING) {
        return vec4(pc.background.rgb, 1.0 / 0.0);
    }
    uint i = word_splat(word);
    uvec2 c = splat_pairs[3u * i + 2u];
    vec3 color = vec3(unpackUnorm2x16(c.x), unpackUnorm2x16(c.y).x);
    return vec4(color, word_depth(word));
}

#define TARGET_FIRST_ROW pc.target_first_row
#include "gbuffer_resolve_blocks.glsl"

#ifdef AREA_MARKS
#define AREA_LIST_BINDING 5
#include "gbuffer_area.glsl"
// The raster's flags of the tiles its splats reach (area_tiles.glsl).
layout(binding = 6, std430) readonly buffer Touched { uint touched[]; };
#include "area_tiles.glsl"

// Whether no splat reaches pixel p's tile: its window's words are all
// background.
bool untouched(ivec2 p) {
    ivec2 t = (p - ivec2(0, pc.target_first_row)) / AREA_TILE_PX;
    return touched[t.y * area_tiles_per_row(pc.extent.x) + t.x] == 0u;
}

#include "lens.glsl"

// Whether the words of the target pixels [lo, hi) are all `first`; their
// splats' depths (min, max; +inf where none) in `zs`.
bool all_of(ivec2 lo, ivec2 hi, uint64_t first, out vec2 zs) {
    bool one = true;
    zs = vec2(1.0 / 0.0, 0.0);
    for (int y = lo.y; y < hi.y; ++y) {
        for (int x = lo.x; x < hi.x; ++x) {
            uint64_t word = word_at(ivec2(x, y));
            one = one && word == first;
            float z = word_depth(word);
            zs = vec2(min(zs.x, z), max(zs.y, z));
        }
    }
    return one;
}

// Whether every depth in [zs.x, zs.y] blurs past the limit through the
// lens after the G-buffer (pc.area_blur) at G-buffer pixel p: the CoC
// grows away from the focus on either side, so its least over the range
// is at an end, or 0 where the range holds the focus. With the cat's eye,
// the blur spans at least the part of the CoC that the pixel's clipped
// lens leaves (cat_eye_blur_reach).
bool blurred_past_limit(ivec2 p, vec2 zs) {
    float f_px = pc.area_blur[0], radius = pc.area_blur[1], focus = pc.area_blur[2];
    float limit = pc.area_blur[3];
    if (limit <= 0.0 || (zs.x <= focus && zs.y >= focus)) {
        return false;
    }
    vec2 coc = vec2(coc_px(zs.x, f_px, radius, focus), coc_px(zs.y, f_px, radius, focus));
    float least = min(coc.x, coc.y);
    float cat_eye = pc.area_blur[4];
    if (cat_eye > 0.0) {
        vec2 centre = cat_eye_centre(pc.window_origin + p, pc.frame_size, cat_eye);
        float half_diag = length(0.5 * vec2(pc.frame_size));
        float reach = cat_eye_blur_reach(pc.area_blur[5], cat_eye, centre, half_diag, coc, zs.x > focus);
        return least * reach > limit;
    }
    return least > limit;
}
#endif

void main() {
    resolve_blocks();
#ifdef AREA_MARKS
    // Marked: the pixel's samples and the ring of its neighbours' nearest
    // samples around them (within the target) do not all hold one word,
    // and not all of their depths blur past the limit. In a tile no splat
    // reaches, all are background: none is read.
    ivec2 p = ivec2(gl_GlobalInvocationID.xy) + ivec2(0, pc.first_row);
    if (any(greaterThanEqual(p, pc.extent)) || untouched(p)) {
        return;
    }
    ivec2 block, lo, hi;
    area_window(p, int(pc.scale), pc.extent.x, TARGET_FIRST_ROW, pc.target_end_row, block, lo, hi);
    vec2 zs;
    if (!all_of(lo, hi, word_at(block), zs) && !blurred_past_limit(p, zs)) {
        mark(p);
    }
#endif
}
