#version 460
// The two-field gather, pass 2: each band texel's sources
// (fields::bands). Texel (x, y) of level l = z + 1 (2^l px) sums the
// surfaces among its pixels whose CoC radius lies in the level's band, for
// two sets (0: the near field, 1: all surfaces): colour, count, r², and
// sub-texel position; writes per set the mean colour and count over its
// t² pixels divided by the texel's spread (the sum of its weights over
// every receiver texel), then (rho, centroid): 4 vec4 per texel.
#include "lens.glsl"
#include "fields.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba16f) uniform readonly image2D gbuffer_color;
layout(binding = 1, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 2, std430) writeonly buffer BandSources { vec4 band_sources[]; };

void main() {
    int level = int(gl_GlobalInvocationID.z) + 1;
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
            ivec2 p = texel * t + ivec2(ix, iy) - pc.anchor;
            if (any(lessThan(p, ivec2(0))) || any(greaterThanEqual(p, pc.extent))) {
                continue;
            }
            float z = imageLoad(gbuffer_eye, p).z;
            if (isinf(z)) {
                continue;
            }
            float r = fields_radius(z);
            if (fields_band_level(r) != level) {
                continue;
            }
            vec4 c = imageLoad(gbuffer_color, p);
            vec2 sub = (vec2(ix, iy) + 0.5) / float(t) - 0.5;
            for (int s = z < pc.focus_distance ? 0 : 1; s < 2; ++s) {
                sum[s] += c;
                n[s] += 1.0;
                r2[s] += r * r;
                cen[s] += sub;
            }
        }
    }
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
