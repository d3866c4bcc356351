#version 460
// Converts a frame's result (rgba16f, inside the guard band), under the
// frame's veil (crate::veil) when it has one, to the output file's pixels
// in a host-visible buffer, so that the host only copies them out:
//   format 0: linear RGBA f32 (EXR), one pixel per invocation (f16 → f32
//     is exact);
//   format 1: sRGB 8-bit RGB (PNG), tightly packed, also one pixel per
//     invocation: a workgroup's 64 pixels (192 bytes) meet in shared
//     memory and 48 of its invocations write their 48 words. Each
//     channel's code comes from a table of all 65,536 half-float bit
//     patterns made on the host with image_io::linear_to_srgb8, so it
//     equals the host's encoding exactly.
// One pixel per invocation in both: the veil loops over every veil splat
// per pixel, and llvmpipe ends an invocation's loops, all together, after
// 65,535 iterations without a word (docs/ARCHITECTURE.md, "llvmpipe's
// loop limit"); an invocation that veiled 4 pixels ran out of them on
// veils of some thousand splats and left the last pixels black.

layout(local_size_x = 64) in;

layout(binding = 0, rgba16f) uniform readonly image2D result;
layout(binding = 1, std430) readonly buffer Srgb8Lut { uint srgb8_lut[]; }; // byte b of word i: code of half bits 4i + b
layout(binding = 2, std430) writeonly buffer Output { uint words[]; };

// Mirrors crate::veil::VeilSplat: the splats too near the lens for the
// G-buffer, nearest first.
struct VeilSplat {
    vec2 centre_px;     // pinhole position p, output pixels
    float lens_per_px;  // sign · 2 / c: u_q = lens_per_px · (q − p)
    float half_side;    // s / c: half the side of its lens square
    vec4 color;         // linear rgb, coverage 1
};
layout(binding = 3, std430) readonly buffer Veil { VeilSplat veil[]; };

// Whether this pipeline carries the veil's code (a specialization
// constant, id 2; src/passes/output.rs): the pipeline of the frames
// without a veil is made without it, which llvmpipe runs in 0.6 of the
// time (a 1080p frame's pass 63 -> 37 ms).
layout(constant_id = 2) const bool VEIL_CODE = true;

layout(push_constant, std430) uniform Push {
    ivec2 origin;  // result pixel of output pixel (0, 0): the guard band
    ivec2 size;    // output width, height (the window's)
    ivec2 window;  // the frame's pixel of output pixel (0, 0): a tile's origin
    uint format;   // 0: linear f32 RGBA, 1: sRGB 8-bit RGB
    uint count;    // pixels (invocations with work)
    uint veil_count; // disks of the veil (0: the result as it is)
} pc;

// Mirrors crate::veil::VEIL_CELLS: lens cells per axis.
const int CELLS = 16;

// The cells whose centre lies in the unit disk, a bit per cell, a word per
// row (crate::veil::VeilGrid; a test checks they agree), and their count.
const uint DISK[CELLS] = uint[](
    0x07E0u, 0x1FF8u, 0x3FFCu, 0x7FFEu, 0x7FFEu, 0xFFFFu, 0xFFFFu, 0xFFFFu,
    0xFFFFu, 0xFFFFu, 0xFFFFu, 0x7FFEu, 0x7FFEu, 0x3FFCu, 0x1FF8u, 0x07E0u);
const uint DISK_CELLS = 208u;

// The cells [lo, hi] of one axis whose centres lie in [a − h, a + h]
// (crate::veil::cell_range).
// precise: no fused multiply-adds, so that the GPU rounds as the CPU
// mirror does and a cell centre on a square's edge falls alike.
ivec2 cell_range(float a, float h) {
    float n = float(CELLS);
    precise float lo = max(ceil((a - h + 1.0) * n / 2.0 - 0.5), 0.0);
    precise float hi = min(floor((a + h + 1.0) * n / 2.0 - 0.5), n - 1.0);
    return ivec2(lo, hi);
}

// The veil over `under` at output pixel p of the window (crate::veil::Veil::apply): each
// lens cell in the disk takes the nearest veil point whose lens square
// holds its centre, else `under`; the pixel is their mean.
vec4 veiled(ivec2 p, vec4 under) {
    uint marked[CELLS];
    for (int j = 0; j < CELLS; ++j) {
        marked[j] = 0u;
    }
    vec2 q = vec2(p + pc.window) + 0.5;
    vec4 over = vec4(0.0);
    uint count = 0u;
    for (uint k = 0u; k < pc.veil_count && count < DISK_CELLS; ++k) {
        precise vec2 u = veil[k].lens_per_px * (q - veil[k].centre_px);
        ivec2 ci = cell_range(u.x, veil[k].half_side);
        ivec2 cj = cell_range(u.y, veil[k].half_side);
        if (ci.x > ci.y || cj.x > cj.y) {
            continue;
        }
        uint span = (0xFFFFFFFFu >> uint(31 - (ci.y - ci.x))) << uint(ci.x);
        for (int j = cj.x; j <= cj.y; ++j) {
            uint fresh = span & DISK[j] & ~marked[j];
            marked[j] |= fresh;
            uint n = uint(bitCount(fresh));
            count += n;
            over += float(n) * veil[k].color;
        }
    }
    float total = float(DISK_CELLS);
    return over / total + (float(DISK_CELLS - count) / total) * under;
}

vec4 pixel(uint i) {
    ivec2 p = ivec2(int(i % uint(pc.size.x)), int(i / uint(pc.size.x)));
    vec4 c = imageLoad(result, pc.origin + p);
    return !VEIL_CODE || pc.veil_count == 0u ? c : veiled(p, c);
}

uint srgb8(float v) {
    uint bits = packHalf2x16(vec2(v, 0.0)) & 0xFFFFu;
    return (srgb8_lut[bits >> 2u] >> (8u * (bits & 3u))) & 0xFFu;
}

// The sRGB codes of a workgroup's pixels, byte ch of entry l: channel ch
// of its pixel l.
shared uint group_codes[64];

void main() {
    uint group = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    uint l = gl_LocalInvocationIndex;
    uint i = group * 64u + l;
    if (pc.format == 0u) {
        if (i < pc.count) {
            vec4 c = pixel(i);
            for (uint k = 0u; k < 4u; ++k) {
                words[4u * i + k] = floatBitsToUint(c[k]);
            }
        }
        return;
    }
    // Every invocation of the workgroup reaches the barrier (the format
    // is the same for all): one past the last pixel gives zero bytes.
    uint codes = 0u;
    if (i < pc.count) {
        vec4 c = pixel(i);
        codes = srgb8(c.r) | (srgb8(c.g) << 8u) | (srgb8(c.b) << 16u);
    }
    group_codes[l] = codes;
    barrier();
    // Word w of the group holds its bytes 4w .. 4w + 3: byte b is channel
    // b % 3 of pixel b / 3. The last group's words stop at the last
    // 4-pixel group's (OutputFormat::buffer_bytes).
    uint words_used = 3u * ((pc.count + 3u) / 4u);
    uint w = group * 48u + l;
    if (l < 48u && w < words_used) {
        uint word = 0u;
        for (uint k = 0u; k < 4u; ++k) {
            uint b = 4u * l + k;
            word |= ((group_codes[b / 3u] >> (8u * (b % 3u))) & 0xFFu) << (8u * k);
        }
        words[w] = word;
    }
}
