#version 460
// Resolves one-sample rasters into the G-buffer as they are drawn
// (DESIGN §3): folds samples sample_index, sample_index + 1, … into the
// running color sum and nearest eye position (gbuffer_fold.glsl), from the
// sample target the sprites drew (gbuffer_resolve_blocks.glsl).

layout(local_size_x = 16, local_size_y = 16) in;

layout(binding = 0, rgba32f) uniform readonly image2D sample_target; // (r, g, b, z)
layout(binding = 1, rgba32f) uniform image2D color_sum;
layout(binding = 2, rgba32f) uniform image2D gbuffer_eye;   // w: nearest's index, then coverage
layout(binding = 3, rgba16f) uniform writeonly image2D gbuffer_color;

layout(push_constant, std430) uniform Push {
    ivec2 extent;        // of the G-buffer (y: the end of the band's rows)
    uint sample_index;   // of this pass's first sample
    uint sample_count;   // samples of the whole G-buffer
    uint scale;          // target pixels per output pixel along each axis
    int first_row;       // the band's first G-buffer row (the target's row 0)
    vec2 lens_u;         // this pass's lens position
    ivec2 window_origin; // the frame pixel of G-buffer pixel (0, 0)
    ivec2 frame_size;    // the whole frame, pixels
    float cat_eye;       // S (0: off)
    float half_cell;     // a lens sample's cell (Aperture::lens_cell_half_width)
    float color_scale;   // the linear color of a splat's code 65535 (1: white)
} pc;

vec4 target_sample(ivec2 q) {
    return imageLoad(sample_target, q);
}

#include "gbuffer_resolve_blocks.glsl"

void main() {
    resolve_blocks();
}
