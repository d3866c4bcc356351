#version 460
// Fast DOF, pass 1 (DESIGN §4): per G-buffer pixel, its CoC diameter c (px)
// from the eye depth (background: z = +inf) and its gather weight: the
// inverse of the number of pixel centres inside its disk, or its shaped
// aperture's (area weights), or 1
// (uniform weights, the paper's plain mean).
#include "lens.glsl"
#include "disk.glsl"
#include "aperture.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 1, rg32f) uniform writeonly image2D coc_weight;
// A shaped aperture's chords (pc.shaped; Aperture::shape_rows).
layout(binding = 2, std430) readonly buffer ShapeChords { vec2 shape_chords[]; };
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
    uint shaped;       // 1: the gather's taps follow the chords (fast_gather.glsl)
    int shape_rows;
    float shape_y_min; // the shape's vertical extent, lens units
    float shape_y_max;
    uint background_only; // 1: count the background's CoC into background_count
} pc;

// The pixel centres (integer offsets from a centre) inside the shape
// scaled to diameter c, by the gather's own test (fast_gather.glsl,
// shape_reaches): per row dy, the columns within the row's chord.
float shape_pixel_count(float c) {
    float r = 0.5 * c;
    if (r <= 0.0) {
        return 1.0;
    }
    float n = 0.0;
    for (int dy = int(ceil(r * pc.shape_y_min)); dy <= int(floor(r * pc.shape_y_max)); ++dy) {
        vec2 chord = shape_chords[shape_row_index(float(dy) / r, pc.shape_rows)];
        n += max(floor(r * chord.y) - ceil(r * chord.x) + 1.0, 0.0);
    }
    return max(n, 1.0);
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
