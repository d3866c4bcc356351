#version 460
// The two-field gather, pass 1: the far field's mip (fields::far_mip). Level
// 0 per G-buffer pixel (and zero for the anchor's texels before it): (c · far) and (far, r · far, (1/z) · far, 0), far
// = not in front of the focus plane (the background included); each level
// after it the mean of the 2×2 texels below (zero past the edge). One
// dispatch per level.
#include "lens.glsl"
#include "fields.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba16f) uniform readonly image2D gbuffer_color;
layout(binding = 1, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 2, std430) buffer FarColor { vec4 far_color[]; };
layout(binding = 3, std430) buffer FarRest { vec4 far_rest[]; };

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = fields_level_size(pc.level);
    if (any(greaterThanEqual(p, size))) {
        return;
    }
    uint at = fields_far_offset(pc.level) + uint(p.y * size.x + p.x);
    if (pc.level == 0) {
        ivec2 g = p - pc.anchor;
        if (any(lessThan(g, ivec2(0)))) {
            far_color[at] = vec4(0.0); // before the G-buffer's first pixel
            far_rest[at] = vec4(0.0);
            return;
        }
        float z = imageLoad(gbuffer_eye, g).z;
        bool near = !isinf(z) && z < pc.focus_distance;
        if (near) {
            far_color[at] = vec4(0.0);
            far_rest[at] = vec4(0.0);
            return;
        }
        far_color[at] = imageLoad(gbuffer_color, g);
        far_rest[at] = vec4(1.0, fields_radius(z), isinf(z) ? 0.0 : 1.0 / z, 0.0);
        return;
    }
    ivec2 below = fields_level_size(pc.level - 1);
    uint base = fields_far_offset(pc.level - 1);
    vec4 c = vec4(0.0);
    vec4 rest = vec4(0.0);
    const ivec2 children[4] = ivec2[4](ivec2(0, 0), ivec2(1, 0), ivec2(0, 1), ivec2(1, 1));
    for (int i = 0; i < 4; ++i) {
        ivec2 q = 2 * p + children[i];
        if (all(lessThan(q, below))) {
            uint b = base + uint(q.y * below.x + q.x);
            c += far_color[b];
            rest += far_rest[b];
        }
    }
    far_color[at] = 0.25 * c;
    far_rest[at] = 0.25 * rest;
}
