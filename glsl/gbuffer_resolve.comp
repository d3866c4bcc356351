#version 460
// Resolves the one-sample rasters into the G-buffer as they are drawn
// (DESIGN §3): folds sample s into the running color sum and nearest eye
// position (gbuffer_fold.glsl). After the last sample, writes the mean
// color and the coverage fraction.
#include "gbuffer_fold.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(binding = 0, rgba32f) uniform readonly image2D sample_target; // (r, g, b, z)
layout(binding = 1, rgba32f) uniform image2D color_sum;
layout(binding = 2, rgba32f) uniform image2D gbuffer_eye;   // w: nearest's index, then coverage
layout(binding = 3, rgba16f) uniform writeonly image2D gbuffer_color;

layout(push_constant, std430) uniform Push {
    ivec2 extent;
    uint sample_index;
    uint sample_count;
} pc;

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, pc.extent))) {
        return;
    }
    vec4 s = imageLoad(sample_target, p);
    float index = float(pc.sample_index);
    Fold f;
    if (pc.sample_index == 0u) {
        f = fold_first(s, index);
    } else {
        f = Fold(imageLoad(color_sum, p), imageLoad(gbuffer_eye, p));
        fold_next(f, s, index);
    }
    if (pc.sample_index + 1u == pc.sample_count) {
        float n = float(pc.sample_count);
        imageStore(gbuffer_color, p, f.sum / n);
        imageStore(gbuffer_eye, p, fold_eye(f, n));
    } else {
        imageStore(color_sum, p, f.sum);
        imageStore(gbuffer_eye, p, f.best);
    }
}
