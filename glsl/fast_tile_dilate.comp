#version 460
// Fast DOF, pass 3: each tile's gather radius (x), the largest c/2 among
// the tiles whose largest disk can reach it (distance between the tiles'
// pixel centres at most c/2): gathering that far finds every contributor.
// And (y) whether any pixel within that radius of the tile, per axis (the
// gather's square window), sees a point: y = 0 lets the gather take the
// all-background path.

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rg32f) uniform readonly image2D tile_max;
layout(binding = 1, rg32f) uniform writeonly image2D tile_radius;

layout(push_constant, std430) uniform Push {
    ivec2 tiles;
    int tile;       // tile edge, pixels
    int reach;      // tiles to search on each side: ceil(max CoC / 2 / tile) + 1
    float fixed_radius; // > 0: every tile gets this radius (the fixed-window baseline)
} pc;

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(t, pc.tiles))) {
        return;
    }
    if (pc.fixed_radius > 0.0) {
        // The fixed-window baseline gathers everything the plain way.
        imageStore(tile_radius, t, vec4(pc.fixed_radius, 1.0, 0.0, 0.0));
        return;
    }
    float radius = 0.0;
    for (int dy = -pc.reach; dy <= pc.reach; ++dy) {
        for (int dx = -pc.reach; dx <= pc.reach; ++dx) {
            ivec2 s = t + ivec2(dx, dy);
            if (any(lessThan(s, ivec2(0))) || any(greaterThanEqual(s, pc.tiles))) {
                continue;
            }
            float half_c = 0.5 * imageLoad(tile_max, s).x;
            // Gap between the two tiles' pixel-centre rectangles, per axis.
            vec2 gap = vec2(max(abs(ivec2(dx, dy)) * pc.tile - (pc.tile - 1), ivec2(0)));
            if (dot(gap, gap) <= half_c * half_c) {
                radius = max(radius, half_c);
            }
        }
    }
    // Tiles with a pixel inside the square window of radius floor(radius)
    // around some pixel of this tile: per-axis gap at most that. They are
    // within `reach`, since radius <= max CoC / 2.
    float window = floor(radius);
    bool points = false;
    for (int dy = -pc.reach; dy <= pc.reach; ++dy) {
        for (int dx = -pc.reach; dx <= pc.reach; ++dx) {
            ivec2 s = t + ivec2(dx, dy);
            if (any(lessThan(s, ivec2(0))) || any(greaterThanEqual(s, pc.tiles))) {
                continue;
            }
            vec2 gap = vec2(max(abs(ivec2(dx, dy)) * pc.tile - (pc.tile - 1), ivec2(0)));
            if (max(gap.x, gap.y) <= window && imageLoad(tile_max, s).y > 0.0) {
                points = true;
            }
        }
    }
    imageStore(tile_radius, t, vec4(radius, points ? 1.0 : 0.0, 0.0, 0.0));
}
