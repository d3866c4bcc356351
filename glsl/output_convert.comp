#version 460
// Converts a frame's result (rgba16f, inside the guard band) to the output
// file's pixels in a host-visible buffer, so that the host only copies
// them out:
//   format 0: linear RGBA f32 (EXR), one pixel per invocation (f16 → f32
//     is exact);
//   format 1: sRGB 8-bit RGB (PNG), tightly packed, 4 pixels (12 bytes,
//     3 words) per invocation. Each channel's code comes from a table of
//     all 65,536 half-float bit patterns made on the host with
//     image_io::linear_to_srgb8, so it equals the host's encoding exactly.

layout(local_size_x = 64) in;

layout(binding = 0, rgba16f) uniform readonly image2D result;
layout(binding = 1, std430) readonly buffer Srgb8Lut { uint srgb8_lut[]; }; // byte b of word i: code of half bits 4i + b
layout(binding = 2, std430) writeonly buffer Output { uint words[]; };

layout(push_constant, std430) uniform Push {
    ivec2 origin;  // result pixel of output pixel (0, 0): the guard band
    ivec2 size;    // output width, height
    uint format;   // 0: linear f32 RGBA, 1: sRGB 8-bit RGB
    uint count;    // invocations with work: pixels (format 0) or 4-pixel groups (format 1)
} pc;

vec4 pixel(uint i) {
    ivec2 p = ivec2(int(i % uint(pc.size.x)), int(i / uint(pc.size.x)));
    return imageLoad(result, pc.origin + p);
}

uint srgb8(float v) {
    uint bits = packHalf2x16(vec2(v, 0.0)) & 0xFFFFu;
    return (srgb8_lut[bits >> 2u] >> (8u * (bits & 3u))) & 0xFFu;
}

void main() {
    uint i = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * 64u + gl_LocalInvocationIndex;
    if (i >= pc.count) {
        return;
    }
    if (pc.format == 0u) {
        vec4 c = pixel(i);
        for (uint k = 0u; k < 4u; ++k) {
            words[4u * i + k] = floatBitsToUint(c[k]);
        }
        return;
    }
    uint pixels = uint(pc.size.x) * uint(pc.size.y);
    uint packed[3] = uint[3](0u, 0u, 0u);
    for (uint k = 0u; k < 4u; ++k) {
        uint p = 4u * i + k;
        if (p >= pixels) {
            break;
        }
        vec4 c = pixel(p);
        for (uint ch = 0u; ch < 3u; ++ch) {
            uint byte_index = 3u * k + ch;
            packed[byte_index / 4u] |= srgb8(c[ch]) << (8u * (byte_index % 4u));
        }
    }
    for (uint w = 0u; w < 3u; ++w) {
        words[3u * i + w] = packed[w];
    }
}
