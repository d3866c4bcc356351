#version 460
// Fast DOF, pass 4 (Zhao §3.3, DESIGN §4): each output pixel Q averages the
// colors (and, as alpha, the coverage) of the pixels P with |p − q| <= c_P / 2 and z_P <= z_Q, weighted
// by P's weight, gathering only as far as its tile's dilated radius. Where
// that window holds only background (the tile's flag), every P has Q's own
// CoC, weight and color: the same sums are formed from those, in the same
// order, without loading each P — bitwise the plain gather's result; for a
// black background (coverage 0) every product and sum is +0 and the mean
// is +0, so there is no loop at all.

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba16f) uniform readonly image2D gbuffer_color;
layout(binding = 1, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 2, rg32f) uniform readonly image2D coc_weight;
layout(binding = 3, rg32f) uniform readonly image2D tile_radius;
layout(binding = 4, rgba16f) uniform writeonly image2D result;

layout(push_constant, std430) uniform Push {
    ivec2 extent;   // G-buffer size
    ivec2 origin;   // first output pixel (the guard band)
    ivec2 size;     // output size
    int tile;
} pc;

void main() {
    ivec2 q = pc.origin + ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(gl_GlobalInvocationID.xy, uvec2(pc.size)))) {
        return;
    }
    float zq = imageLoad(gbuffer_eye, q).z;
    vec2 tile = imageLoad(tile_radius, q / pc.tile).xy;
    int r = int(min(floor(tile.x), float(max(pc.extent.x, pc.extent.y))));
    // precise: no contraction into fused multiply-adds and no hoisting of
    // the products, so that both paths round alike on every compiler.
    precise vec4 sum = vec4(0.0);
    precise float weight = 0.0;
    if (tile.y == 0.0) {
        // Only background around: z_P = z_Q = +inf passes the z test, and
        // c_P, w_P and the color are Q's.
        vec2 cw = imageLoad(coc_weight, q).xy;
        vec4 color = imageLoad(gbuffer_color, q);
        if (all(equal(color, vec4(0.0)))) {
            imageStore(result, q, vec4(0.0));
            return;
        }
        for (int dy = max(-r, -q.y); dy <= min(r, pc.extent.y - 1 - q.y); ++dy) {
            for (int dx = max(-r, -q.x); dx <= min(r, pc.extent.x - 1 - q.x); ++dx) {
                float d2 = float(dx * dx + dy * dy);
                if (d2 > 0.25 * cw.x * cw.x) {
                    continue;
                }
                sum += cw.y * color;
                weight += cw.y;
            }
        }
        imageStore(result, q, sum / weight);
        return;
    }
    // The window clipped to the G-buffer (a radius may exceed it: the
    // guard band is bounded, docs/ARCHITECTURE.md).
    for (int dy = max(-r, -q.y); dy <= min(r, pc.extent.y - 1 - q.y); ++dy) {
        for (int dx = max(-r, -q.x); dx <= min(r, pc.extent.x - 1 - q.x); ++dx) {
            ivec2 p = q + ivec2(dx, dy);
            vec2 cw = imageLoad(coc_weight, p).xy;
            float d2 = float(dx * dx + dy * dy);
            if (d2 > 0.25 * cw.x * cw.x) {
                continue;
            }
            if (imageLoad(gbuffer_eye, p).z > zq) {
                continue;
            }
            sum += cw.y * imageLoad(gbuffer_color, p);
            weight += cw.y;
        }
    }
    // Q itself always takes part (distance 0, same depth): weight > 0.
    // Alpha: the contributors' coverage, weighted as their color.
    imageStore(result, q, sum / weight);
}
