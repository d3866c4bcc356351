#version 460
// Resolves one-sample rasters into the G-buffer as they are drawn
// (DESIGN §3): folds samples sample_index, sample_index + 1, … into the
// running color sum and nearest eye position (gbuffer_fold.glsl). A pass
// of scale 1 (the one-sample form, one pass per sample) holds one sample of
// each pixel, in place; a pass of scale K (the upscaled plan, every sample
// in one pass) holds output pixel p's K² samples in the target's K×K block
// at K·p, sample s (the one-sample form's index) in cell K² − 1 − s
// (src/passes/sample_plan.rs); an upscaled plan drawn in bands holds only
// the band's rows, from first_row. After the last sample, writes the mean
// color and the coverage fraction.
#include "gbuffer_fold.glsl"

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
} pc;

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy) + ivec2(0, pc.first_row);
    if (any(greaterThanEqual(p, pc.extent))) {
        return;
    }
    ivec2 block = (p - ivec2(0, pc.first_row)) * int(pc.scale);
    uint n = pc.scale * pc.scale;
    Fold f;
    if (pc.sample_index != 0u) {
        f = Fold(imageLoad(color_sum, p), imageLoad(gbuffer_eye, p));
    }
    for (uint s = 0u; s < n; s++) {
        uint cell = n - 1u - s;
        ivec2 q = block + ivec2(cell % pc.scale, cell / pc.scale);
        vec4 t = imageLoad(sample_target, q);
        float index = float(pc.sample_index + s);
        if (pc.sample_index == 0u && s == 0u) {
            f = fold_first(t, index);
        } else {
            fold_next(f, t, index);
        }
    }
    if (pc.sample_index + n == pc.sample_count) {
        float count = float(pc.sample_count);
        imageStore(gbuffer_color, p, f.sum / count);
        imageStore(gbuffer_eye, p, fold_eye(f, count));
    } else {
        imageStore(color_sum, p, f.sum);
        imageStore(gbuffer_eye, p, f.best);
    }
}
