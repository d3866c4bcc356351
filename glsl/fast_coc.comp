#version 460
// Fast DOF, pass 1 (DESIGN §4): per G-buffer pixel, its CoC diameter c (px)
// from the eye depth (background: z = +inf) and its gather weight: the
// inverse of the number of pixel centres inside its disk (area weights) or 1
// (uniform weights, the paper's plain mean).
#include "lens.glsl"
#include "disk.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 1, rg32f) uniform writeonly image2D coc_weight;

layout(push_constant, std430) uniform Push {
    ivec2 extent;
    float f_px;
    float aperture_radius;
    float focus_distance;
    uint area_weights;
} pc;

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, pc.extent))) {
        return;
    }
    float z = imageLoad(gbuffer_eye, p).z;
    float c = coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance);
    float w = pc.area_weights != 0u ? 1.0 / disk_pixel_count(c) : 1.0;
    imageStore(coc_weight, p, vec4(c, w, 0.0, 0.0));
}
