#version 460
// The depth peel's splats (DESIGN §6, issue 28): before a peel pass, keep
// only the splats that can pass splat_peel.frag's test somewhere — beyond
// the previous layer's depth by their thickness at some pixel their sprite
// may touch — in their order (a prefix sum), so that the peel draws fewer
// splats (lavapipe pays per splat drawn, even clipped) and gets the same
// image bit for bit: every splat left out fails the test at every sample.
// Five stages of one shader, none of which waits inside a workgroup
// (lavapipe runs a workgroup barrier as a switch between its invocations):
//   0: per TILE×TILE tile of the previous layer, its nearest depth;
//   1: per splat, whether it can pass the peel (against the tiles its
//      sprite may touch: a superset of its pixels, so never fewer kept);
//   2: per run of RUN splats, how many it keeps;
//   3: one invocation: each run's first place (a running sum, in order)
//      and the draw's VkDrawIndirectCommand (vertexCount = kept splats);
//   4: per run, its kept splats copied to their places, in order.
// The projection mirrors splat_raster.vert (the sprite's centre and size);
// the footprint takes one pixel more on each side for the rasterizer's
// rounding, and a sprite wider than MAX_FOOTPRINT pixels is kept unseen.
#include "lens.glsl"

layout(local_size_x = 256) in;

// The splats as the vertex buffer holds them: per splat 6 words, position
// and world diameter as 4 floats, the UNORM16 color as 2 words.
layout(binding = 0, std430) readonly buffer Splats { uint splats[]; };
// The previous layer's G-buffer eye image: (0, 0, z, coverage).
layout(binding = 1, rgba32f) uniform readonly image2D previous;
// Per splat, 1 if kept.
layout(binding = 2, std430) buffer Flags { uint flags[]; };
// Per run of RUN splats, how many it keeps, then its first place.
layout(binding = 3, std430) buffer Runs { uint runs[]; };
layout(binding = 4, std430) writeonly buffer Kept { uint kept[]; };
// vertexCount, instanceCount, firstVertex, firstInstance.
layout(binding = 5, std430) writeonly buffer Draw { uint draw[4]; };
// Per tile of the previous layer, its nearest depth.
layout(binding = 6, std430) buffer Tiles { float tile_near[]; };

#include "splat_compute_push.glsl"

// A surface is this many splat diameters thick for the peel (mirrors
// splat_peel_frag.glsl; src/passes/splat_raster.rs, PEEL_THICKNESS_DIAMETERS).
const float PEEL_THICKNESS = 1.0;
// Sprites wider than this many pixels are kept without a look.
const float MAX_FOOTPRINT = 64.0;
// Tile edge of the nearest depths, pixels.
const int TILE = 8;
// Splats per run of stages 2–4.
const uint RUN = 256u;
// Relative slack of the comparison with the fragment shader's (f32 rounds
// at 6e-8: a few roundings apart at most).
const float SLACK = 1e-5;

bool peels(uint i) {
    vec4 ps = vec4(uintBitsToFloat(splats[6u * i]), uintBitsToFloat(splats[6u * i + 1u]),
                   uintBitsToFloat(splats[6u * i + 2u]), uintBitsToFloat(splats[6u * i + 3u]));
    vec3 d = ps.xyz - pc.eye.xyz;
    vec3 e = vec3(dot(d, pc.right.xyz), dot(d, pc.up.xyz), dot(d, pc.forward.xyz));
    if (e.z <= pc.near || e.z >= pc.far) {
        return false; // the vertex shader puts it outside the clip volume
    }
    vec2 p = vec2(pc.center.x + pc.f_px * e.x / e.z, pc.center.y - pc.f_px * e.y / e.z);
    p += lens_offset_px(e.z, pc.lens_u, pc.f_px, pc.aperture_radius, pc.focus_distance);
    float size = pc.splat_px > 0.0 ? pc.splat_px : pc.f_px * ps.w / e.z;
    float diameter = pc.splat_px > 0.0 ? pc.splat_px * e.z / pc.f_px : ps.w;
    size = clamp(size, pc.min_point_size, pc.max_point_size);
    if (!(size <= MAX_FOOTPRINT)) {
        return true;
    }
    ivec2 extent = imageSize(previous);
    ivec2 tiles = (extent + TILE - 1) / TILE;
    ivec2 lo = max(ivec2(floor(p - 0.5 * size)) - 1, ivec2(0)) / TILE;
    ivec2 hi = min(ivec2(floor(p + 0.5 * size)) + 1, extent - 1) / TILE;
    // The peel keeps it at pixel q when v_z > z(q) + thickness, in the
    // fragment shader's arithmetic (rounding is monotonic, so the nearest
    // z of a tile bounds its pixels'); this shader's e.z and diameter may
    // differ from the vertex shader's in the last bits (another
    // contraction of the same products), hence the slack.
    float z = e.z * (1.0 + SLACK);
    for (int y = lo.y; y <= hi.y; ++y) {
        for (int x = lo.x; x <= hi.x; ++x) {
            if (z > tile_near[y * tiles.x + x] + PEEL_THICKNESS * diameter * (1.0 - SLACK)) {
                return true;
            }
        }
    }
    return false;
}

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint runs_count = (pc.count + RUN - 1u) / RUN;
    if (pass_stage() == 0u) {
        ivec2 extent = imageSize(previous);
        ivec2 tiles = (extent + TILE - 1) / TILE;
        if (i >= uint(tiles.x * tiles.y)) {
            return;
        }
        ivec2 t = ivec2(int(i) % tiles.x, int(i) / tiles.x);
        ivec2 lo = t * TILE;
        ivec2 hi = min(lo + TILE, extent);
        float z_near = 1.0 / 0.0;
        for (int y = lo.y; y < hi.y; ++y) {
            for (int x = lo.x; x < hi.x; ++x) {
                z_near = min(z_near, imageLoad(previous, ivec2(x, y)).z);
            }
        }
        tile_near[i] = z_near;
    } else if (pass_stage() == 1u) {
        if (i < pc.count) {
            flags[i] = peels(i) ? 1u : 0u;
        }
    } else if (pass_stage() == 2u) {
        if (i < runs_count) {
            uint kept_in_run = 0u;
            for (uint j = i * RUN; j < min((i + 1u) * RUN, pc.count); ++j) {
                kept_in_run += flags[j];
            }
            runs[i] = kept_in_run;
        }
    } else if (pass_stage() == 3u) {
        if (i == 0u) {
            uint sum = 0u;
            for (uint r = 0u; r < runs_count; ++r) {
                uint n = runs[r];
                runs[r] = sum;
                sum += n;
            }
            draw[0] = sum;
            draw[1] = 1u;
            draw[2] = 0u;
            draw[3] = 0u;
        }
    } else if (i < runs_count) {
        uint at = runs[i];
        for (uint j = i * RUN; j < min((i + 1u) * RUN, pc.count); ++j) {
            if (flags[j] != 0u) {
                for (uint w = 0u; w < 6u; ++w) {
                    kept[6u * at + w] = splats[6u * j + w];
                }
                at += 1u;
            }
        }
    }
}
