#version 460
// The tile list of one lens point (src/gaussian_render.rs), in two stages:
//   0: one invocation per Gaussian in depth order writes an entry (tile,
//      Gaussian) for every tile it covers, from offsets[], the prefix sum
//      of the tiles covered in that order; entries past the capacity are
//      dropped (the host sees the total in counts[] and renders again);
//   1: after the entries are sorted by tile (stably, so depth order holds
//      within a tile), each tile's range [begin, end) of the list.
#include "gaussian.glsl"

layout(local_size_x = 256) in;

layout(binding = 0, std430) readonly buffer In { Projected projected[]; };
layout(binding = 1, std430) readonly buffer Order { uint order[]; };
layout(binding = 2, std430) readonly buffer Touched { uint touched[]; };
layout(binding = 3, std430) readonly buffer Offsets { uint offsets[]; };
layout(binding = 4, std430) buffer TileKeys { uint tile_keys[]; };
layout(binding = 5, std430) writeonly buffer TileValues { uint tile_values[]; };
layout(binding = 6, std430) writeonly buffer Ranges { uvec2 ranges[]; };
layout(binding = 7, std430) readonly buffer Counts { uint counts[]; };

layout(push_constant) uniform Push {
    uint stage;
    uint count;      // Gaussians
    uint capacity;   // entries the tile list holds
    uint grid_x;     // tiles per row
    uint entries_index;  // counts[entries_index]: the entries of this lens point
} pc;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (pc.stage == 0u) {
        if (i >= pc.count) {
            return;
        }
        uint g = order[i];
        if (touched[g] == 0u) {
            return;
        }
        ivec4 tiles = projected[g].tiles;
        uint at = offsets[i];
        for (int y = tiles.z; y < tiles.w; y++) {
            for (int x = tiles.x; x < tiles.y; x++) {
                if (at < pc.capacity) {
                    tile_keys[at] = uint(y) * pc.grid_x + uint(x);
                    tile_values[at] = g;
                }
                at++;
            }
        }
        return;
    }
    // Any number of entries: each invocation every stride-th one (the
    // dispatch is bounded by the device's workgroup count).
    uint n = min(counts[pc.entries_index], pc.capacity);
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (; i < n; i += stride) {
        uint tile = tile_keys[i];
        if (i == 0u || tile_keys[i - 1u] != tile) {
            ranges[tile].x = i;
        }
        if (i + 1u == n || tile_keys[i + 1u] != tile) {
            ranges[tile].y = i + 1u;
        }
    }
}
