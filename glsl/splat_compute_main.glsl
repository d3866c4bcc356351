// The compute rasteriser (issue 28, item 2; Schütz et al. 2021): splats
// drawn by compute shaders into a 64-bit visibility buffer, one word per
// target pixel, (eye depth bits << 32) | splat index, kept by atomicMin:
// the nearest splat, and on exact depth ties the earlier one, as the
// sprite path's depth test keeps it. The G-buffer resolve
// (gbuffer_resolve_vis.comp) reads each word's splat color.
//
// A splat covers the target pixels whose centre lies in its square,
// [p − size/2, p + size/2) along each axis (the sprite rule of the
// Vulkan specification, without the sprite path's rounding of the
// position to sub-pixel steps and of the size to the point-size
// granularity). Positions and sizes are those of splat_raster.vert
// (splat_project.glsl).
//
// Two stages of one shader:
//   0: one invocation per splat; a square of at most LARGE_PIXELS target
//      pixels is drawn there, a larger one is appended to the large list,
//      whose first word is the x count of the next stage's dispatch;
//   1: per large splat, workgroups (y) of CHUNK_PIXELS of its pixels
//      each, shared out over the workgroup's invocations (a lavapipe
//      invocation runs its loop alone: one big square would hold up its
//      whole SIMD group). Chunks keep an invocation's loop at 16,384
//      iterations at most: llvmpipe ends an invocation's loops after
//      65,535 iterations in all (LP_MAX_TGSI_LOOP_ITERATIONS), and a
//      255 px splat at SSAA 16 covers 16.6 M target pixels, 260,000 each
//      for 64 invocations (drawn in bands with gaps before the chunks).
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#include "lens.glsl"

layout(local_size_x = 64) in;

// The splats as the vertex buffer holds them: per splat 6 words, position
// and world diameter as 4 floats, the UNORM16 color as 2 words.
layout(binding = 0, std430) readonly buffer Splats { uint splats[]; };
// One word per target pixel, row by row; cleared to all ones (nothing).
layout(binding = 1, std430) buffer Visibility { uint64_t visibility[]; };
// A VkDispatchIndirectCommand (x: large splats, then 1, 1), a pad word,
// then the large splats' indices.
layout(binding = 2, std430) buffer Large { uint large_dispatch[4]; uint large[]; };

#include "splat_compute_push.glsl"

#include "splat_project.glsl"

// Squares of more target pixels go to the large list (mirrors
// src/passes/splat_compute.rs, LARGE_PIXELS).
const uint LARGE_PIXELS = 256u;
// Target pixels of a large splat per workgroup of stage 1 (mirrors
// src/passes/splat_compute.rs, CHUNK_PIXELS).
const uint CHUNK_PIXELS = 1048576u;

vec4 position_size(uint i) {
    return vec4(uintBitsToFloat(splats[6u * i]), uintBitsToFloat(splats[6u * i + 1u]),
                uintBitsToFloat(splats[6u * i + 2u]), uintBitsToFloat(splats[6u * i + 3u]));
}

// The first and last target pixel (inclusive) whose centre x + 0.5 lies
// in [centre − size/2, centre + size/2), clamped to the target; empty
// when last < first.
ivec2 covered(float centre, float size, float extent) {
    float lo = ceil(centre - 0.5 * size - 0.5);
    float hi = ceil(centre + 0.5 * size - 0.5) - 1.0;
    return ivec2(clamp(lo, 0.0, extent), clamp(hi, -1.0, extent - 1.0));
}

// Whether target pixel (x, y) of the splat's square is the splat's: every
// one for a square; for a disc (SPLAT_DISC, `--splat-shape disc`) those
// whose centre lies strictly inside the disc of the square's diameter, as
// the sprites' disc test (splat_disc.glsl).
bool covers(Projected s, int x, int y) {
#ifdef SPLAT_DISC
    vec2 d = vec2(x, y) + 0.5 - s.p;
    float r = 0.5 * s.size_px;
    return dot(d, d) < r * r;
#else
    return true;
#endif
}

void main() {
    uint i;
    if (pc.stage == 0u) {
        i = gl_GlobalInvocationID.x;
        if (i >= pc.count) {
            return;
        }
    } else {
        i = large[gl_WorkGroupID.x];
    }
    Projected s;
    if (!project_splat(position_size(i), vec2(0.0), s)) {
        return;
    }
    ivec2 xs = covered(s.p.x, s.size_px, pc.extent.x);
    ivec2 ys = covered(s.p.y, s.size_px, pc.extent.y);
    if (xs.y < xs.x || ys.y < ys.x) {
        return;
    }
    uint w = uint(xs.y - xs.x + 1);
    uint n = w * uint(ys.y - ys.x + 1);
    uint width = uint(pc.extent.x);
    uint64_t word = (uint64_t(floatBitsToUint(s.z)) << 32) | uint64_t(i);
    if (pc.stage == 0u) {
        if (n > LARGE_PIXELS) {
            large[atomicAdd(large_dispatch[0], 1u)] = i;
            return;
        }
        for (int y = ys.x; y <= ys.y; ++y) {
            uint row = uint(y) * width;
            for (int x = xs.x; x <= xs.y; ++x) {
                if (covers(s, x, y)) {
                    atomicMin(visibility[row + uint(x)], word);
                }
            }
        }
    } else {
        uint first = gl_WorkGroupID.y * CHUNK_PIXELS;
        uint end = min(n, first + CHUNK_PIXELS);
        for (uint k = first + gl_LocalInvocationID.x; k < end; k += gl_WorkGroupSize.x) {
            uint x = uint(xs.x) + k % w;
            uint y = uint(ys.x) + k / w;
            if (covers(s, int(x), int(y))) {
                atomicMin(visibility[y * width + x], word);
            }
        }
    }
}
