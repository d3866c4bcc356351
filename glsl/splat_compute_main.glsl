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
//
// With SPLAT_PEEL (splat_compute_peel*.comp) it is the depth peel of the
// layered method's later layers, as splat_peel_frag.glsl is for the
// sprites: a target pixel keeps only the splats beyond the previous
// layer's resolved depth at its G-buffer pixel by more than their
// thickness. The target is then the whole G-buffer, a whole number of
// times its size along each axis (one band).
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

#ifdef SPLAT_PEEL
// The previous layer's G-buffer eye image: (0, 0, z, coverage), z = +inf
// where it saw nothing (so nothing lies beyond it).
layout(binding = 3, rgba32f) uniform readonly image2D previous;

// A surface is this many splat diameters thick for the peel
// (src/passes/splat_raster.rs, PEEL_THICKNESS_DIAMETERS).
const float PEEL_THICKNESS = 1.0;
#endif

// Squares of more target pixels go to the large list (mirrors
// src/passes/splat_compute.rs, LARGE_PIXELS).
const uint LARGE_PIXELS = 4096u;
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

#ifdef SPLAT_PEEL
// Target pixels per G-buffer pixel along each axis: the peel's target is
// the G-buffer's size times it (src/passes/splat_compute.rs,
// ComputeRaster::record).
int peel_scale() {
    return int(pc.extent.x) / imageSize(previous).x;
}

// Draws the splat's target pixels (xs × ys) within G-buffer pixel g, of
// k × k target pixels, where the splat lies beyond the previous layer
// there by more than its thickness, as splat_peel_frag.glsl tests it: the
// test once for the pixel's k² target pixels.
void peel_gbuffer_pixel(Projected s, uint64_t word, ivec2 xs, ivec2 ys, ivec2 g, int k) {
    if (s.z > imageLoad(previous, g).z + PEEL_THICKNESS * s.diameter) {
        uint width = uint(pc.extent.x);
        for (int y = max(ys.x, g.y * k); y <= min(ys.y, g.y * k + k - 1); ++y) {
            uint row = uint(y) * width;
            for (int x = max(xs.x, g.x * k); x <= min(xs.y, g.x * k + k - 1); ++x) {
                if (covers(s, x, y)) {
                    atomicMin(visibility[row + uint(x)], word);
                }
            }
        }
    }
}
#endif

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
#ifdef SPLAT_PEEL
        // By G-buffer pixel: the peel's test once for its scale² target
        // pixels (the same target pixels as testing each).
        int k = peel_scale();
        for (int gy = ys.x / k; gy <= ys.y / k; ++gy) {
            for (int gx = xs.x / k; gx <= xs.y / k; ++gx) {
                peel_gbuffer_pixel(s, word, xs, ys, ivec2(gx, gy), k);
            }
        }
#else
        for (int y = ys.x; y <= ys.y; ++y) {
            uint row = uint(y) * width;
            for (int x = xs.x; x <= xs.y; ++x) {
                if (covers(s, x, y)) {
                    atomicMin(visibility[row + uint(x)], word);
                }
            }
        }
#endif
    } else {
#ifdef SPLAT_PEEL
        // By G-buffer pixel, as above: each invocation tests a G-buffer
        // pixel of the square once, then takes its target pixels; a chunk
        // holds CHUNK_PIXELS / scale² G-buffer pixels (no more loop
        // iterations per invocation than a chunk of target pixels).
        int k = peel_scale();
        ivec2 g_lo = ivec2(xs.x, ys.x) / k;
        uint gw = uint(xs.y / k - g_lo.x + 1);
        uint gn = gw * uint(ys.y / k - g_lo.y + 1);
        uint chunk = CHUNK_PIXELS / uint(k * k);
        uint first = gl_WorkGroupID.y * chunk;
        uint end = min(gn, first + chunk);
        for (uint j = first + gl_LocalInvocationID.x; j < end; j += gl_WorkGroupSize.x) {
            peel_gbuffer_pixel(s, word, xs, ys, g_lo + ivec2(j % gw, j / gw), k);
        }
#else
        uint first = gl_WorkGroupID.y * CHUNK_PIXELS;
        uint end = min(n, first + CHUNK_PIXELS);
        for (uint k = first + gl_LocalInvocationID.x; k < end; k += gl_WorkGroupSize.x) {
            uint x = uint(xs.x) + k % w;
            uint y = uint(ys.x) + k / w;
            if (covers(s, int(x), int(y))) {
                atomicMin(visibility[y * width + x], word);
            }
        }
#endif
    }
}
