#version 460
// Resolves one multisampled raster pass into the G-buffer (DESIGN §3):
// folds its S samples, in sample order, into the running color sum and
// nearest eye position (gbuffer_fold.glsl). Sample s of output pixel p is
// read at p + its read offset (src/passes/sample_plan.rs: the pass's jitter
// can move a sample's position into the next pixel). After the last pass,
// writes the (weighted) mean color and the coverage fraction.
#include "gbuffer_fold.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(binding = 0, rgba32f) uniform readonly image2DMS sample_target; // (r, g, b, z)
layout(binding = 1, rgba32f) uniform image2D color_sum;
layout(binding = 2, rgba32f) uniform image2D gbuffer_eye;   // w: nearest's index, then coverage
layout(binding = 3, rgba16f) uniform writeonly image2D gbuffer_color;

layout(push_constant, std430) uniform Push {
    ivec2 extent;        // of the G-buffer
    uint sample_base;    // samples folded before this pass
    uint sample_count;   // samples of the whole G-buffer
    uint samples;        // S, samples of this pass
    uint read_offsets;   // bit 2s: sample s one pixel right; bit 2s + 1: one down
    uint index_base;     // index of this lens position's first sample
    uint indices[2];     // byte s: index of sample s in the one-sample form
    uint pad;
    vec2 lens_u;         // this pass's lens position
    ivec2 window_origin; // the frame pixel of G-buffer pixel (0, 0)
    ivec2 frame_size;    // the whole frame, pixels
    float cat_eye;       // S (0: off)
    float half_cell;     // a lens sample's cell (Aperture::lens_cell_half_width)
    float color_scale;   // the linear color of a splat's code 65535 (1: white)
} pc;

#include "gbuffer_lens_weight.glsl"

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, pc.extent))) {
        return;
    }
    float w = lens_weight(p);
    Fold f;
    if (pc.sample_base != 0u) {
        f = Fold(imageLoad(color_sum, p), imageLoad(gbuffer_eye, p));
    }
    for (uint s = 0u; s < pc.samples; s++) {
        ivec2 q = p + (ivec2(pc.read_offsets >> (2u * s), pc.read_offsets >> (2u * s + 1u)) & 1);
        vec4 t = scaled(imageLoad(sample_target, q, int(s)), pc.color_scale);
        float index = float(pc.index_base + ((pc.indices[s / 4u] >> (8u * (s % 4u))) & 0xFFu));
        if (pc.sample_base == 0u && s == 0u) {
            f = fold_first(t, index, w);
        } else {
            fold_next(f, t, index, w);
        }
    }
    if (pc.sample_base + pc.samples == pc.sample_count) {
        imageStore(gbuffer_color, p, fold_color(f));
        imageStore(gbuffer_eye, p, fold_eye(f));
    } else {
        imageStore(color_sum, p, f.sum);
        imageStore(gbuffer_eye, p, f.best);
    }
}
