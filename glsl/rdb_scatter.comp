#version 460
// Ray distribution buffer (Zhao §3.2, DESIGN §5), scatter: every G-buffer
// pixel P offers itself to the lens bins of the output pixels its rays
// reach. Pass 0 keeps, per (Q, bin), the smallest depth (atomicMin of the
// float bits; z > 0, so bit order is numeric order); pass 1 keeps, among
// the sources at that depth, the smallest index: deterministic.
//   centre mode: bin b of Q receives P when P moved by its lens offset for
//     the bin's centre u_b lands on Q (q = p + floor(offset + 0.5)).
//   pairs mode: for every Q inside P's CoC, only the bin holding
//     u = sign · 2 (q − p) / c receives P; c < 2 fills every bin of P itself.
#include "lens.glsl"
#include "concentric.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 1, r32ui) uniform uimage2DArray rdb_depth;
layout(binding = 2, r32ui) uniform uimage2DArray rdb_source;
layout(binding = 3, std430) readonly buffer LensTable { vec2 lens_u[]; };

layout(push_constant, std430) uniform Push {
    ivec2 extent;      // G-buffer size
    ivec2 origin;      // G-buffer pixel of output pixel (0, 0): the guard band
    ivec2 scan_origin; // G-buffer pixel of invocation (0, 0)
    ivec2 tile_origin; // output pixel of RDB texel (0, 0)
    ivec2 tile_size;   // output pixels the RDB holds (a tile or the frame)
    int bins;       // N: N×N bins
    uint pairs;     // 0: centre mode, 1: pairs mode
    uint pass_index; // 0: depth, 1: source index
    float f_px;
    float aperture_radius;
    float focus_distance;
} pc;

// Offers source `source` at depth `depth_bits` to bin `bin` of output pixel
// q; pixels outside the tile are left to the tile that holds them.
void offer(ivec2 q, int bin, uint depth_bits, uint source) {
    ivec2 t = q - pc.tile_origin;
    if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, pc.tile_size))) {
        return;
    }
    ivec3 at = ivec3(t, bin);
    if (pc.pass_index == 0u) {
        imageAtomicMin(rdb_depth, at, depth_bits);
    } else if (imageLoad(rdb_depth, at).x == depth_bits) {
        imageAtomicMin(rdb_source, at, source);
    }
}

void main() {
    ivec2 p = pc.scan_origin + ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, pc.extent))) {
        return;
    }
    float z = imageLoad(gbuffer_eye, p).z;
    uint depth_bits = floatBitsToUint(z);
    uint source = uint(p.y * pc.extent.x + p.x);
    ivec2 po = p - pc.origin; // P in output pixel coordinates
    int n2 = pc.bins * pc.bins;
    float c = coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance);
    if (pc.pairs == 0u) {
        for (int b = 0; b < n2; ++b) {
            vec2 offset = lens_offset_px(z, lens_u[b], pc.f_px, pc.aperture_radius, pc.focus_distance);
            offer(po + ivec2(floor(offset + 0.5)), b, depth_bits, source);
        }
        return;
    }
    if (c < 2.0) {
        for (int b = 0; b < n2; ++b) {
            offer(po, b, depth_bits, source);
        }
        return;
    }
    float sign_z = z >= pc.focus_distance ? 1.0 : -1.0;
    float r2 = 0.25 * c * c;
    int r = int(floor(0.5 * c));
    for (int dy = -r; dy <= r; ++dy) {
        for (int dx = -r; dx <= r; ++dx) {
            if (float(dx * dx + dy * dy) > r2) {
                continue;
            }
            vec2 u = sign_z * 2.0 * vec2(dx, dy) / c;
            vec2 a = concentric_square(u);
            ivec2 cell = clamp(ivec2(floor((a + 1.0) * 0.5 * float(pc.bins))), ivec2(0), ivec2(pc.bins - 1));
            offer(po + ivec2(dx, dy), cell.y * pc.bins + cell.x, depth_bits, source);
        }
    }
}
