#version 460
// Fast DOF, pass 1 (DESIGN §4): per G-buffer pixel, its CoC diameter c (px)
// from the eye depth (background: z = +inf) and its gather weight: the
// inverse of the number of pixel centres inside its disk (area weights) or 1
// (uniform weights, the paper's plain mean).
#include "lens.glsl"

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

// Pixel centres (integer offsets) within distance c/2 of a pixel centre.
float disk_pixel_count(float c) {
    float r2 = 0.25 * c * c;
    int r = int(floor(0.5 * c));
    float n = 0.0;
    for (int dy = -r; dy <= r; ++dy) {
        // Largest dx with dx² + dy² <= r², found exactly in integers.
        int dx = int(floor(sqrt(max(r2 - float(dy * dy), 0.0))));
        while (float(dx * dx + dy * dy) > r2) { --dx; }
        while (float((dx + 1) * (dx + 1) + dy * dy) <= r2) { ++dx; }
        n += float(2 * dx + 1);
    }
    return max(n, 1.0);
}

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
