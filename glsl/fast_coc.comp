#version 460
// Fast DOF, pass 1 (DESIGN §4): per G-buffer pixel, its CoC diameter c (px)
// from the eye depth (background: z = +inf) and its gather weight: the
// inverse of the number of pixel centres inside its disk, or its shaped
// aperture's (area weights), or 1
// (uniform weights, the paper's plain mean).
#include "lens.glsl"
#include "disk.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 1, rg32f) uniform writeonly image2D coc_weight;
// A shaped aperture's reach thresholds, ascending (pc.shaped;
// Aperture::tap_thresholds): the least half-CoC at which each pixel
// offset reaches through the shape, those up to pc.reach_max.
layout(binding = 2, std430) readonly buffer TapThresholds { float tap_thresholds[]; };
// The background's pixel count: every pixel no splat covers has the CoC of
// z = +inf, so the dispatch before the pass's own (pc.background_only)
// counts it once, and those pixels skip the count's loop.
layout(binding = 3, std430) buffer Background { float background_count; };

layout(push_constant, std430) uniform Push {
    ivec2 extent;
    float f_px;
    float aperture_radius;
    float focus_distance;
    uint area_weights;
    uint shaped;       // 1: the gather's taps follow the shape (fast_gather.glsl)
    int tap_count;     // thresholds in tap_thresholds
    float reach_max;   // the half-CoC they reach to (px)
    uint background_only; // 1: count the background's CoC into background_count
} pc;

// The pixel centres (integer offsets from a centre) inside the shape
// scaled to diameter c, by the gather's own test (fast_gather.glsl,
// shape_reaches; Aperture::reaches): how many reach thresholds lie at or
// below c/2, found by halving. Past the table (CoCs wider than the
// frame's), its count grown with the area, (c/2 / reach_max)².
float shape_pixel_count(float c) {
    float h = 0.5 * c;
    if (h <= 0.0) {
        return 1.0;
    }
    if (h > pc.reach_max) {
        return float(pc.tap_count) * (h / pc.reach_max) * (h / pc.reach_max);
    }
    int lo = 0, hi = pc.tap_count;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (tap_thresholds[mid] <= h) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    return max(float(lo), 1.0);
}

// The pixel centres a pixel of CoC diameter c spreads over: the shape's or
// the disk's.
float pixel_count(float c) {
    return pc.shaped != 0u ? shape_pixel_count(c) : disk_pixel_count(c);
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (pc.background_only != 0u) {
        if (p == ivec2(0)) {
            background_count = pixel_count(coc_px(1.0 / 0.0, pc.f_px, pc.aperture_radius, pc.focus_distance));
        }
        return;
    }
    if (any(greaterThanEqual(p, pc.extent))) {
        return;
    }
    float z = imageLoad(gbuffer_eye, p).z;
    float c = coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance);
    // A background pixel's count is the one counted before, and its loop
    // runs for c = 0 (a group of such pixels runs none).
    bool background = isinf(z);
    float count = pixel_count(background ? 0.0 : c);
    float area = background ? background_count : count;
    float w = pc.area_weights != 0u ? 1.0 / area : 1.0;
    imageStore(coc_weight, p, vec4(c, w, 0.0, 0.0));
}
