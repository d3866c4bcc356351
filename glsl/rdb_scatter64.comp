#version 460
// Ray distribution buffer, scatter (rdb_offers.glsl) in one pass: an
// atomicMin of (tag, depth, source) per (Q, bin) into the 64-bit bins of
// rdb_bins64.glsl.
#include "rdb_bins64.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 1, std430) buffer Bins { uint64_t bins64[]; };
layout(binding = 2, std430) readonly buffer LensTable { vec2 lens_u[]; };

#define RDB_SCATTER
#include "rdb_push.glsl"

// Offers source `source` at depth `depth_bits` to bin `bin` of output pixel
// q; pixels outside the tile are left to the tile that holds them.
void offer(ivec2 q, int bin, uint depth_bits, uint source) {
    ivec2 t = q - pc.tile_origin;
    if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, pc.tile_size))) {
        return;
    }
    uint at = bin_index(bin, pc.bins * pc.bins, t, pc.tile_size);
    atomicMin(bins64[at], bin_word(pc.step, depth_bits, source));
}

#include "rdb_offers.glsl"
