#version 460
// Fast DOF, pass 2: per TILE×TILE tile, the largest CoC (x) and whether
// any of its pixels sees a point (y = 1) rather than only background.

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rg32f) uniform readonly image2D coc_weight;
layout(binding = 1, rg32f) uniform writeonly image2D tile_max;
layout(binding = 2, rgba32f) uniform readonly image2D gbuffer_eye;

layout(push_constant, std430) uniform Push {
    ivec2 extent;   // G-buffer size
    ivec2 tiles;    // tile grid size
    int tile;       // tile edge, pixels
} pc;

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(t, pc.tiles))) {
        return;
    }
    ivec2 lo = t * pc.tile;
    ivec2 hi = min(lo + pc.tile, pc.extent);
    float m = 0.0;
    bool points = false;
    for (int y = lo.y; y < hi.y; ++y) {
        for (int x = lo.x; x < hi.x; ++x) {
            m = max(m, imageLoad(coc_weight, ivec2(x, y)).x);
            // Background pixels are the surface at z = +inf.
            points = points || !isinf(imageLoad(gbuffer_eye, ivec2(x, y)).z);
        }
    }
    imageStore(tile_max, t, vec4(m, points ? 1.0 : 0.0, 0.0, 0.0));
}
