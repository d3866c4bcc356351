#version 460
// The two-field gather, pass 2: each band texel's sources
// (fields::bands). Texel (x, y) of level l = pc.level + z (2^l px) sums the
// surfaces among its pixels whose CoC radius lies in the level's band, for
// two sets (0: the near field, 1: all surfaces): colour, count, r², and
// sub-texel position; writes per set the mean colour and count over its
// t² pixels divided by the texel's spread (the sum of its weights over
// every receiver texel), then (rho, centroid): 4 vec4 per texel.
//
// Two cuts (src/passes/kernel_sizes.rs): an invocation per texel, 8×8 a
// workgroup (BANDS_SHARED false: every level on a CPU device, the fine
// ones on a GPU), or a workgroup of 64 per texel (true: a GPU's coarse
// levels, whose few texels of up to 64×64 pixels would each keep one
// invocation busy while the rest of the device idles): its invocations sum
// every 64th pixel and reduce their sums in shared memory in a fixed
// order. The two orders of the float sums differ in their last bits.
#include "lens.glsl"
#include "fields.glsl"

layout(local_size_x = 8, local_size_y = 8, local_size_x_id = 8, local_size_y_id = 9) in;
layout(constant_id = 7) const bool BANDS_SHARED = false;
const uint GROUP = gl_WorkGroupSize.x * gl_WorkGroupSize.y;

layout(binding = 0, rgba16f) uniform readonly image2D gbuffer_color;
layout(binding = 1, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 2, std430) writeonly buffer BandSources { vec4 band_sources[]; };

// A shared texel's invocations' sums: per set, colour and (count, r²,
// centroid).
shared vec4 shared_sum[2][GROUP];
shared vec4 shared_rest[2][GROUP];

// Adds pixel (ix, iy) of `texel` (of level `level`, t px a side) to the
// sums (vec4 sum[2], float n[2], float r2[2], vec2 cen[2], in scope) of
// the sets it belongs to. A macro rather than a function: llvmpipe copied
// a function's inout arrays per pixel (the pass 1.4× slower).
#define ADD_PIXEL(texel, level, t, ix, iy)                                                    \
    {                                                                                         \
        ivec2 p = (texel) * (t) + ivec2((ix), (iy)) - pc.anchor;                              \
        if (all(greaterThanEqual(p, ivec2(0))) && all(lessThan(p, pc.extent))) {              \
            float z = imageLoad(gbuffer_eye, p).z;                                            \
            float r = fields_radius(z);                                                       \
            if (!isinf(z) && fields_band_level(r) == (level)) {                               \
                vec4 c = imageLoad(gbuffer_color, p);                                         \
                vec2 sub = (vec2((ix), (iy)) + 0.5) / float(t) - 0.5;                         \
                for (int s = z < pc.focus_distance ? 0 : 1; s < 2; ++s) {                     \
                    sum[s] += c;                                                              \
                    n[s] += 1.0;                                                              \
                    r2[s] += r * r;                                                           \
                    cen[s] += sub;                                                            \
                }                                                                             \
            }                                                                                 \
        }                                                                                     \
    }

// Writes `texel`'s sources from its sums.
void write_texel(ivec2 texel, int level, int t, ivec2 size,
                 vec4 sum[2], float n[2], float r2[2], vec2 cen[2]) {
    uint at = 4u * (fields_band_offset(level) + uint(texel.y * size.x + texel.x));
    float cells = float(t * t);
    int reach = FIELDS_BAND_REACH;
    float reach2 = (FIELDS_BAND + 0.5 + FIELDS_HALF_DIAGONAL) * (FIELDS_BAND + 0.5 + FIELDS_HALF_DIAGONAL);
    for (int s = 0; s < 2; ++s) {
        if (n[s] == 0.0) {
            band_sources[at + 2u * uint(s)] = vec4(0.0);
            band_sources[at + 2u * uint(s) + 1u] = vec4(0.0);
            continue;
        }
        float rho = sqrt(r2[s] / n[s]) / float(t);
        vec2 c = cen[s] / n[s];
        float spread = 0.0;
        for (int dy = -reach; dy <= reach; ++dy) {
            int h = fields_row_half(reach2, dy);
            for (int dx = -h; dx <= h; ++dx) {
                spread += fields_band_weight(rho, ivec2(dx, dy), c);
            }
        }
        band_sources[at + 2u * uint(s)] = sum[s] / cells / spread;
        band_sources[at + 2u * uint(s) + 1u] = vec4(n[s] / cells / spread, rho, c);
    }
}

// An invocation per texel: its pixels row by row.
void texel_alone() {
    int level = pc.level + int(gl_GlobalInvocationID.z);
    ivec2 texel = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = fields_level_size(level);
    if (any(greaterThanEqual(texel, size))) {
        return;
    }
    int t = 1 << level;
    vec4 sum[2] = vec4[2](vec4(0.0), vec4(0.0));
    float n[2] = float[2](0.0, 0.0);
    float r2[2] = float[2](0.0, 0.0);
    vec2 cen[2] = vec2[2](vec2(0.0), vec2(0.0));
    for (int iy = 0; iy < t; ++iy) {
        for (int ix = 0; ix < t; ++ix) {
            ADD_PIXEL(texel, level, t, ix, iy)
        }
    }
    write_texel(texel, level, t, size, sum, n, r2, cen);
}

// A workgroup per texel (GROUP a power of two). Every branch before a
// barrier is the same for the whole workgroup.
void texel_shared() {
    int level = pc.level + int(gl_WorkGroupID.z);
    ivec2 texel = ivec2(gl_WorkGroupID.xy);
    ivec2 size = fields_level_size(level);
    if (any(greaterThanEqual(texel, size))) {
        return;
    }
    int t = 1 << level;
    uint i = gl_LocalInvocationIndex;
    vec4 sum[2] = vec4[2](vec4(0.0), vec4(0.0));
    float n[2] = float[2](0.0, 0.0);
    float r2[2] = float[2](0.0, 0.0);
    vec2 cen[2] = vec2[2](vec2(0.0), vec2(0.0));
    for (int k = int(i); k < t * t; k += int(GROUP)) {
        ADD_PIXEL(texel, level, t, k % t, k / t)
    }
    for (int s = 0; s < 2; ++s) {
        shared_sum[s][i] = sum[s];
        shared_rest[s][i] = vec4(n[s], r2[s], cen[s]);
    }
    barrier();
    for (uint half_group = GROUP / 2u; half_group > 0u; half_group /= 2u) {
        if (i < half_group) {
            for (int s = 0; s < 2; ++s) {
                shared_sum[s][i] += shared_sum[s][i + half_group];
                shared_rest[s][i] += shared_rest[s][i + half_group];
            }
        }
        barrier();
    }
    if (i == 0u) {
        for (int s = 0; s < 2; ++s) {
            sum[s] = shared_sum[s][0];
            n[s] = shared_rest[s][0].x;
            r2[s] = shared_rest[s][0].y;
            cen[s] = shared_rest[s][0].zw;
        }
        write_texel(texel, level, t, size, sum, n, r2, cen);
    }
}

void main() {
    if (BANDS_SHARED) {
        texel_shared();
    } else {
        texel_alone();
    }
}
