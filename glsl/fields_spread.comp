#version 460
// The two-field gather, pass 3: each band texel of level l = z + 1 takes
// from the texels whose disks reach it (fields::bands), for both sets:
// (near colour, all colour, (near weight, all weight, 0, 0)). A workgroup
// first loads the source texels its 8×8 receivers can reach into shared
// memory, and writes zeros at once where none of them holds a source
// (most of a level's texels: llvmpipe's cost is per invocation and loop
// turn, so the empty regions must cost one load each, not 89).
#include "lens.glsl"
#include "fields.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, std430) readonly buffer BandSources { vec4 band_sources[]; };
layout(binding = 1, std430) writeonly buffer Bands { vec4 bands[]; };

const int REACH = FIELDS_BAND_REACH;
const int SIDE = 8 + 2 * REACH;  // the region's side, texels
shared vec4 region[SIDE * SIDE * 4];
shared uint any_source;

void main() {
    int level = int(gl_GlobalInvocationID.z) + 1;
    ivec2 size = fields_level_size(level);
    ivec2 first = ivec2(gl_WorkGroupID.xy) * 8;
    if (any(greaterThanEqual(first, size))) {
        return; // the whole workgroup: past this level's texels
    }
    uint base = fields_band_offset(level);
    ivec2 origin = first - REACH;
    if (gl_LocalInvocationIndex == 0u) {
        any_source = 0u;
    }
    barrier();
    for (int i = int(gl_LocalInvocationIndex); i < SIDE * SIDE; i += 64) {
        ivec2 s = origin + ivec2(i % SIDE, i / SIDE);
        vec4 v[4] = vec4[4](vec4(0.0), vec4(0.0), vec4(0.0), vec4(0.0));
        if (all(greaterThanEqual(s, ivec2(0))) && all(lessThan(s, size))) {
            uint at = 4u * (base + uint(s.y * size.x + s.x));
            for (int k = 0; k < 4; ++k) {
                v[k] = band_sources[at + uint(k)];
            }
            if (v[1].x != 0.0 || v[3].x != 0.0) {
                atomicOr(any_source, 1u);
            }
        }
        for (int k = 0; k < 4; ++k) {
            region[4 * i + k] = v[k];
        }
    }
    barrier();
    ivec2 texel = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(texel, size))) {
        return;
    }
    uint out_at = 3u * (base + uint(texel.y * size.x + texel.x));
    if (any_source == 0u) {
        bands[out_at] = vec4(0.0);
        bands[out_at + 1u] = vec4(0.0);
        bands[out_at + 2u] = vec4(0.0);
        return;
    }
    vec4 color[2] = vec4[2](vec4(0.0), vec4(0.0));
    float weight[2] = float[2](0.0, 0.0);
    float reach2 = (FIELDS_BAND + 0.5 + FIELDS_HALF_DIAGONAL) * (FIELDS_BAND + 0.5 + FIELDS_HALF_DIAGONAL);
    ivec2 local = texel - origin;
    for (int dy = -REACH; dy <= REACH; ++dy) {
        int h = fields_row_half(reach2, dy);
        for (int dx = -h; dx <= h; ++dx) {
            ivec2 d = ivec2(dx, dy);
            int i = 4 * ((local.y + dy) * SIDE + local.x + dx);
            for (int set = 0; set < 2; ++set) {
                vec4 shape = region[i + 2 * set + 1];
                if (shape.x == 0.0) {
                    continue;
                }
                float w = fields_band_weight(shape.y, d, shape.zw);
                color[set] += region[i + 2 * set] * w;
                weight[set] += shape.x * w;
            }
        }
    }
    bands[out_at] = color[0];
    bands[out_at + 1u] = color[1];
    bands[out_at + 2u] = vec4(weight[0], weight[1], 0.0, 0.0);
}
