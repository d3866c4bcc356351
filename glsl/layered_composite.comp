#version 460
// Layered DOF, pass 4, once per depth slice, back to front (DESIGN §6):
// per row, the prefix sum of the slice's row differences gives each
// pixel's spread premultiplied color C and coverage A (and clears the
// differences for the next slice); the slice's color C / A goes over what
// lies behind with alpha min(A, 1). The farthest slice goes over the
// background; the nearest writes the result.
#include "lens.glsl"
#include "layered_push.glsl"
#include "layered_fixed.glsl"

layout(local_size_x = 64) in;

layout(binding = 0, std430) buffer Differences { uint64_t differences[]; };
layout(binding = 1, rgba32f) uniform image2D behind;             // rgb, alpha: coverage so far
layout(binding = 2, rgba16f) uniform writeonly image2D result;
// Per row, the columns the slice's differences touch (layered_spread.comp);
// elsewhere the slice adds nothing, and a slice between the farthest and
// the nearest leaves those pixels as they are. Cleared for the next slice.
layout(binding = 3, std430) buffer RowSpans { uint row_spans[]; };

void main() {
    int row = int(gl_GlobalInvocationID.x);
    int y = pc.band_y0 + row;
    if (row >= pc.band_rows || y >= pc.extent.y) {
        return;
    }
    bool farthest = pc.slice == pc.slices - 1;
    bool nearest = pc.slice == 0;
    int from = pc.extent.x - int(row_spans[2 * row]);
    int to = int(row_spans[2 * row + 1]) - 1;
    row_spans[2 * row] = 0u;
    row_spans[2 * row + 1] = 0u;
    bool every = farthest || nearest;
    uint64_t rg = 0ul, ba = 0ul;
    for (int x = every ? 0 : from; x <= (every ? pc.extent.x - 1 : to); ++x) {
        if (x >= from && x <= to) {
            uint at = 2u * uint(row * pc.extent.x + x);
            rg += differences[at];
            ba += differences[at + 1u];
            differences[at] = 0ul;
            differences[at + 1u] = 0ul;
        }
        vec4 spread = vec4(unpack(rg), unpack(ba));
        float a = max(spread.a, 0.0);
        float alpha = min(a, 1.0);
        vec3 rgb = pc.gaussian_layers != 0u ? spread.rgb : max(spread.rgb, vec3(0.0));
        vec3 color = a > 1.0 ? rgb / a : rgb;
        vec4 under = farthest ? vec4(pc.background.rgb, 0.0) : imageLoad(behind, ivec2(x, y));
        vec4 over = vec4(color + under.rgb * (1.0 - alpha), alpha + under.a * (1.0 - alpha));
        if (nearest) {
            imageStore(result, ivec2(x, y), over);
        } else {
            imageStore(behind, ivec2(x, y), over);
        }
    }
}
