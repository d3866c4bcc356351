#version 460
// Ray distribution buffer, scatter (rdb_offers.glsl) into two R32_UINT
// array images, a layer per bin, in two passes: pass 0 keeps, per (Q, bin),
// the smallest depth (atomicMin); pass 1, among the sources at that depth,
// the smallest index.

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 1, r32ui) uniform uimage2DArray rdb_depth;
layout(binding = 2, r32ui) uniform uimage2DArray rdb_source;
layout(binding = 3, std430) readonly buffer LensTable { vec2 lens_u[]; };

#define RDB_SCATTER
#include "rdb_push.glsl"

// Offers source `source` at depth `depth_bits` to bin `bin` of output pixel
// q; pixels outside the tile are left to the tile that holds them.
void offer(ivec2 q, int bin, uint depth_bits, uint source) {
    ivec2 t = q - pc.tile_origin;
    if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, pc.tile_size))) {
        return;
    }
    ivec3 at = ivec3(t, bin);
    if (pc.step == 0u) {
        imageAtomicMin(rdb_depth, at, depth_bits);
    } else if (imageLoad(rdb_depth, at).x == depth_bits) {
        imageAtomicMin(rdb_source, at, source);
    }
}

#include "rdb_offers.glsl"
