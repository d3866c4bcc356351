#version 460
// The layered method's input from Gaussians (src/gaussian_render.rs,
// `render_layered`): the pinhole blend of gaussian_blend.comp, a workgroup
// per 16 x 16 tile, but each pixel composites the Gaussians of each depth
// layer apart (layers of equal signed-CoC width, nearest first; the tile
// list is in depth order, so a pixel meets them layer after layer). Per
// layer and pixel it writes what a depth-peeled G-buffer layer holds: its
// light over the background, coverage = 1 - transmittance, and the eye
// depth of its contributions (weighted as they were composited), +inf
// where none. A layer's light is the linear-light difference it makes
// over what lies behind it in the pinhole view, so that the layers laid
// over one another without blur give the pinhole image exactly.
#include "gaussian.glsl"
#include "lens.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

const uint GROUP = 256u;

layout(binding = 0, std430) readonly buffer In { Projected projected[]; };
layout(binding = 1, std430) readonly buffer TileValues { uint tile_values[]; };
layout(binding = 2, std430) readonly buffer Ranges { uvec2 ranges[]; };
layout(binding = 3, std430) readonly buffer Counts { uint counts[]; };
// Per layer, the images of a G-buffer layer: colour over the background
// with coverage (rgba16f), and (0, 0, z, coverage) (rgba32f). Layers past
// pc.layers are bound to layer 0's images and never written.
layout(binding = 4, rgba16f) uniform writeonly image2D color0;
layout(binding = 5, rgba16f) uniform writeonly image2D color1;
layout(binding = 6, rgba16f) uniform writeonly image2D color2;
layout(binding = 7, rgba16f) uniform writeonly image2D color3;
layout(binding = 8, rgba16f) uniform writeonly image2D color4;
layout(binding = 9, rgba16f) uniform writeonly image2D color5;
layout(binding = 10, rgba16f) uniform writeonly image2D color6;
layout(binding = 11, rgba16f) uniform writeonly image2D color7;
layout(binding = 12, rgba32f) uniform writeonly image2D eye0;
layout(binding = 13, rgba32f) uniform writeonly image2D eye1;
layout(binding = 14, rgba32f) uniform writeonly image2D eye2;
layout(binding = 15, rgba32f) uniform writeonly image2D eye3;
layout(binding = 16, rgba32f) uniform writeonly image2D eye4;
layout(binding = 17, rgba32f) uniform writeonly image2D eye5;
layout(binding = 18, rgba32f) uniform writeonly image2D eye6;
layout(binding = 19, rgba32f) uniform writeonly image2D eye7;

void store(int layer, ivec2 p, vec4 color, vec4 eye) {
    switch (layer) {
    case 0: imageStore(color0, p, color); imageStore(eye0, p, eye); break;
    case 1: imageStore(color1, p, color); imageStore(eye1, p, eye); break;
    case 2: imageStore(color2, p, color); imageStore(eye2, p, eye); break;
    case 3: imageStore(color3, p, color); imageStore(eye3, p, eye); break;
    case 4: imageStore(color4, p, color); imageStore(eye4, p, eye); break;
    case 5: imageStore(color5, p, color); imageStore(eye5, p, eye); break;
    case 6: imageStore(color6, p, color); imageStore(eye6, p, eye); break;
    case 7: imageStore(color7, p, color); imageStore(eye7, p, eye); break;
    }
}

layout(push_constant) uniform Push {
    vec4 background;           // linear
    vec4 background_encoded;   // sRGB-encoded
    uint width;
    uint height;
    uint capacity;
    uint entries_index;
    uint layers;
    float layer_lo;      // signed CoC (px) of layer 0's near edge
    float layer_width;   // signed CoC (px) per layer
    float f_px;
    float aperture_radius;
    float focus_distance;
} pc;

shared vec2 s_centre[GROUP];
shared vec4 s_conic_opacity[GROUP];
shared vec4 s_color_depth[GROUP];

uint layer_of(float z) {
    float c = signed_coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance);
    return uint(clamp(floor((c - pc.layer_lo) / pc.layer_width), 0.0, float(pc.layers - 1u)));
}

// The most layers (crate::gaussian_render::MAX_LAYERS).
const uint MAX_LAYERS = 8u;

vec3 decode(vec3 c) {
    return vec3(srgb_to_linear(c.r), srgb_to_linear(c.g), srgb_to_linear(c.b));
}

// Entries of a batch per turn of the layers' loop (gaussian_blend.comp).
const uint PER_TURN = 4u;

// Entry j of the batch into its layer's composite: nothing past the
// batch, for a layer that met the transmittance limit, or below the
// cut-off (alpha 0). A macro, not a function: it writes main's arrays.
#define LAYER_ENTRY(J) { \
    uint j = (J); \
    if (j < batch) { \
        float z = s_color_depth[j].w; \
        uint l = layer_of(z); \
        float alpha = (stopped & (1u << l)) != 0u ? 0.0 \
            : gaussian_alpha(s_centre[j] - at, s_conic_opacity[j]); \
        if (alpha != 0.0) { \
            float transmittance = transmittances[l]; \
            float next = transmittance * (1.0 - alpha); \
            if (next < 0.0001) { \
                stopped |= 1u << l; \
            } else { \
                float weight = alpha * transmittance; \
                colors[l] += s_color_depth[j].rgb * weight; \
                wz[l] += weight * z; \
                w[l] += weight; \
                transmittances[l] = next; \
            } \
        } \
    } \
}

void main() {
    bool overflow = counts[pc.entries_index] > pc.capacity;
    uvec2 pixel = gl_GlobalInvocationID.xy;
    uint grid_x = (pc.width + uint(TILE_PX) - 1u) / uint(TILE_PX);
    uint tile = gl_WorkGroupID.y * grid_x + gl_WorkGroupID.x;
    uint t = gl_LocalInvocationIndex;
    bool inside = pixel.x < pc.width && pixel.y < pc.height;
    uint i = pixel.y * pc.width + pixel.x;
    vec2 at = vec2(pixel) + vec2(0.5);
    uvec2 range = overflow ? uvec2(0u) : ranges[tile];
    // Per layer, front to back: the composite (encoded), transmittance,
    // and the weights of the depths.
    vec3 colors[MAX_LAYERS];
    float transmittances[MAX_LAYERS];
    float wz[MAX_LAYERS];
    float w[MAX_LAYERS];
    for (uint l = 0u; l < MAX_LAYERS; l++) {
        colors[l] = vec3(0.0);
        transmittances[l] = 1.0;
        wz[l] = 0.0;
        w[l] = 0.0;
    }
    uint stopped = 0u;
    for (uint first = range.x; first < range.y; first += GROUP) {
        barrier(); // the previous batch is read
        uint k = first + t;
        if (k < range.y) {
            Projected p = projected[tile_values[k]];
            s_centre[t] = p.centre_depth.xy;
            s_conic_opacity[t] = p.conic_opacity;
            s_color_depth[t] = vec4(p.color.rgb, p.centre_depth.z);
        }
        barrier();
        uint batch = min(GROUP, range.y - first);
        // PER_TURN entries per turn of the loop, written out (LAYER_ENTRY):
        // llvmpipe ends an invocation's loops after 65,535 turns in all
        // (LP_MAX_TGSI_LOOP_ITERATIONS), and a tile's list may be longer.
        for (uint j0 = 0u; j0 < batch && inside; j0 += PER_TURN) {
            LAYER_ENTRY(j0 + 0u)
            LAYER_ENTRY(j0 + 1u)
            LAYER_ENTRY(j0 + 2u)
            LAYER_ENTRY(j0 + 3u)
        }
    }
    if (!inside) {
        return;
    }
    // Back to front: what lies behind layer l in the pinhole view
    // (encoded), and layer l's share of the light over it, so that laid
    // over one another in linear light without blur the layers give the
    // pinhole image: decode(C_l + T_l B) - T_l decode(B).
    vec3 behind = pc.background_encoded.rgb;
    for (int l = int(pc.layers) - 1; l >= 0; l--) {
        float t = transmittances[l];
        vec3 over = colors[l] + t * behind;
        // Signed: a layer darker than what it covers takes light away.
        vec3 share = decode(over) - t * decode(behind);
        behind = over;
        float coverage = 1.0 - t;
        float z = w[l] > 0.0 ? wz[l] / w[l] : 1.0 / 0.0;
        // As a G-buffer layer holds it: the colour over the background.
        vec3 color = share + t * pc.background.rgb;
        store(l, ivec2(pixel), vec4(color, coverage), vec4(0.0, 0.0, z, coverage));
    }
}
