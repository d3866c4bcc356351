#version 460
// Front-to-back compositing of one lens point's Gaussians, a workgroup per
// 16 x 16 tile (src/gaussian_render.rs; crate::gaussians::render_through
// is the reference): at each pixel centre (moved by the sample's jitter
// where --ssaa takes several), alpha = min(0.99, o e^power),
// skipped below 1/255 or where power > 0; the Gaussian that would take the
// transmittance below 1e-4 ends the pixel; the background (encoded) takes
// what is left. The composite, sRGB-encoded as trained, is decoded and
// added to the pixel's sum in linear light, weighted by the lens point's
// weight in the pixel (1, but for accum's cat's eye: the resolve's rule,
// gbuffer_lens_weight.glsl), and the weight to the sum's alpha. Nothing is
// added when the tile list overflowed (the host renders the frame again).
#include "gaussian.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

const uint GROUP = 256u;

layout(binding = 0, std430) readonly buffer In { Projected projected[]; };
layout(binding = 1, std430) readonly buffer TileValues { uint tile_values[]; };
layout(binding = 2, std430) readonly buffer Ranges { uvec2 ranges[]; };
layout(binding = 3, std430) readonly buffer Counts { uint counts[]; };
layout(binding = 4, std430) buffer Sum { vec4 sum[]; };

layout(push_constant) uniform Push {
    vec4 background;     // sRGB-encoded
    vec2 jitter;         // the sample's offset from the pixel centre, px
    uint width;
    uint height;
    uint capacity;
    uint entries_index;
    vec2 lens_u;         // the lens point in pixel axes (y down)
    ivec2 window_origin; // the frame pixel of pixel (0, 0): none, a whole frame
    ivec2 frame_size;    // the whole frame, pixels
    float cat_eye;       // S (0: off)
    float half_cell;     // a lens sample's cell (Aperture::lens_cell_half_width)
} pc;

#include "gbuffer_lens_weight.glsl"

shared vec2 s_centre[GROUP];
shared vec4 s_conic_opacity[GROUP];
shared vec3 s_color[GROUP];
shared uint s_done;

// Entries of a batch per turn of the blend's loop, written out (below):
// llvmpipe ends an invocation's loops after 65,535 turns in all
// (LP_MAX_TGSI_LOOP_ITERATIONS), and a tile's list may be longer than that
// (tests/gaussian_gpu.rs); 4 per turn reach about 260,000 entries, at the
// speed of one (16 per turn were 10-25 % slower on lavapipe).
const uint PER_TURN = 4u;

// Blends entry j of the batch into the pixel's composite: nothing past the
// batch, once the pixel is done, or below the cut-off (alpha 0).
void blend(uint j, uint batch, vec2 at, inout bool done, inout float transmittance,
           inout vec3 color) {
    if (j >= batch || done) {
        return;
    }
    float alpha = gaussian_alpha(s_centre[j] - at, s_conic_opacity[j]);
    if (alpha == 0.0) {
        return;
    }
    float next = transmittance * (1.0 - alpha);
    if (next < 0.0001) {
        done = true;
        return;
    }
    color += s_color[j] * alpha * transmittance;
    transmittance = next;
}

void main() {
    if (counts[pc.entries_index] > pc.capacity) {
        return; // the whole dispatch: the list overflowed
    }
    uvec2 pixel = gl_GlobalInvocationID.xy;
    uint grid_x = (pc.width + uint(TILE_PX) - 1u) / uint(TILE_PX);
    uint tile = gl_WorkGroupID.y * grid_x + gl_WorkGroupID.x;
    uint t = gl_LocalInvocationIndex;
    bool inside = pixel.x < pc.width && pixel.y < pc.height;
    bool done = !inside;
    vec2 at = vec2(pixel) + vec2(0.5) + pc.jitter;
    uvec2 range = ranges[tile];
    float transmittance = 1.0;
    vec3 color = vec3(0.0);
    for (uint first = range.x; first < range.y; first += GROUP) {
        barrier(); // the previous batch is read
        if (t == 0u) {
            s_done = 0u;
        }
        barrier();
        if (done) {
            atomicAdd(s_done, 1u);
        }
        uint k = first + t;
        if (k < range.y) {
            Projected p = projected[tile_values[k]];
            s_centre[t] = p.centre_depth.xy;
            s_conic_opacity[t] = p.conic_opacity;
            s_color[t] = p.color.rgb;
        }
        barrier();
        if (s_done == GROUP) {
            break;
        }
        uint batch = min(GROUP, range.y - first);
        for (uint j = 0u; j < batch && !done; j += PER_TURN) {
            blend(j + 0u, batch, at, done, transmittance, color);
            blend(j + 1u, batch, at, done, transmittance, color);
            blend(j + 2u, batch, at, done, transmittance, color);
            blend(j + 3u, batch, at, done, transmittance, color);
        }
    }
    if (inside) {
        vec3 c = color + transmittance * pc.background.rgb;
        uint i = pixel.y * pc.width + pixel.x;
        float w = lens_weight(ivec2(pixel));
        sum[i] += w * vec4(srgb_to_linear(c.r), srgb_to_linear(c.g), srgb_to_linear(c.b), 1.0);
    }
}
