#version 460
// Ray distribution buffer, resolve from the 64-bit bins (rdb_bins64.glsl):
// as rdb_resolve.comp, each output pixel is the mean, in linear light, of
// the colors of the sources its filled bins kept; a pixel with no filled bin
// keeps its G-buffer color.
#include "rdb_bins64.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba16f) uniform readonly image2D gbuffer_color;
layout(binding = 1, std430) readonly buffer Bins { uint64_t bins64[]; };
layout(binding = 2, rgba16f) uniform writeonly image2D result;
layout(binding = 3, std430) readonly buffer LensTable { vec2 lens_u[]; };

#include "rdb_push.glsl"
#include "aperture.glsl"

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(t, pc.tile_size))) {
        return;
    }
    ivec2 q = pc.tile_origin + t;
    int n2 = pc.bins * pc.bins;
    vec4 sum = vec4(0.0);
    float n = 0.0;
    vec2 cat = cat_eye_centre(pc.window_origin + q, pc.frame_size, pc.cat_eye);
    // Its bins pressed into its cat's eye (rdb_offers.glsl), or not.
    CatLens pressed = cat_lens_of(cat);
    // A bin stands for one of N² cells of the lens.
    float half_cell = lens_cell_half_width(float(pc.bins * pc.bins));
    for (int b = 0; b < n2; ++b) {
        uint64_t word = bins64[bin_index(b, n2, t, pc.tile_size)];
        float w = !APERTURE_CODE || pc.cat_eye == 0.0 ? 1.0
            : pc.cat_lens != 0u ? cat_eye_pressed_weight(pressed, lens_u[b], cat, half_cell)
            : cat_eye_cell_weight(lens_u[b], cat, half_cell);
        if (bin_filled(word, pc.step) && w > 0.0) {
            uint source = bin_source(word);
            ivec2 p = ivec2(int(source % uint(pc.extent.x)), int(source / uint(pc.extent.x)));
            sum += w * imageLoad(gbuffer_color, p);
            n += w;
        }
    }
    // Alpha: the mean coverage of the sources, as the color.
    vec4 color = n > 0.0 ? sum / n : imageLoad(gbuffer_color, q + pc.origin);
    imageStore(result, q + pc.origin, color);
}
