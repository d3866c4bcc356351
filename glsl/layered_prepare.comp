#version 460
// Layered DOF, pass 2, once per layer (DESIGN §6): each covered pixel of
// the layer as a fragment to spread: premultiplied color (the background's
// share of the mean taken out), coverage, signed CoC. Layers after the
// first go through the modified peel: an occluded pixel is kept only where
// it can be seen through the lens, i.e. near an opening of the occluders
// (a tile of the first layer that sees farther than midway between the
// pixel and its occluder) within the pixel's CoC radius plus the
// occluders' (a ray from depth z through lens point u crosses depth z'
// |c_s(z) - c_s(z')| |u| / 2 px from where it started). Counts the kept and
// discarded pixels, and appends each workgroup's tile of pixels, as
// (layer, tile), to the list of every slice its kept fragments spread in:
// the spread of a slice runs one workgroup per entry of its list
// (an indirect dispatch), not one per tile and layer.
#include "lens.glsl"
#include "layered_push.glsl"
#include "layered_slices.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba16f) uniform readonly image2D layer_color;
layout(binding = 1, rgba32f) uniform readonly image2D layer_eye;
layout(binding = 2, rgba32f) uniform readonly image2D first_eye;
layout(binding = 3, rg32f) uniform readonly image2D occluder_tiles;
layout(binding = 4, rgba32f) uniform writeonly image2DArray fragment_color; // premultiplied rgb, coverage
layout(binding = 5, rg32f) uniform writeonly image2DArray fragment_coc;     // signed CoC (px), spread radius (px; 0: no surface)
layout(binding = 6, std430) buffer Counts { uint counts[]; };             // kept, discarded per layer
// Per slice, tiles × layers entries: layer * tiles + tile.
layout(binding = 7, std430) writeonly buffer SliceLists { uint slice_lists[]; };
// The spread radius per CoC radius (src/passes/spread_disk.rs,
// radius_table_words).
layout(binding = 8, std430) readonly buffer SpreadRadius {
    uint entries;
    float entries_per_px;
    float excess;     // px², beyond the last entry
    uint pad;
    float radius[];
} spread;
// Per slice a VkDispatchIndirectCommand (x, y, z): x counts the entries of
// its list (y and z are 1, written by the host's update).
layout(binding = 9, std430) buffer SliceDispatch { uint slice_dispatch[]; };

// This workgroup's kept and discarded pixels, added to the totals once,
// and the slices of its kept fragments.
shared uint group_counts[2];
shared uint group_slices;

// Distance from pixel centre p + 0.5 to tile t's pixel rectangle.
float tile_distance(vec2 p, ivec2 t) {
    vec2 lo = vec2(t * pc.tile);
    vec2 hi = lo + vec2(pc.tile);
    vec2 d = max(max(lo - p, p - hi), vec2(0.0));
    return length(d);
}

bool visible_through_lens(ivec2 p, float z) {
    float z_occluder = imageLoad(first_eye, p).z;
    float midway = 0.5 * (z_occluder + z);
    float c = coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance);
    vec2 centre = vec2(p) + 0.5;
    // Every occluder within reach has a CoC of at most max_coc_px: scan
    // that far, and take the largest occluder CoC met.
    float scan = 0.5 * (c + pc.max_coc_px) + 1.0;
    ivec2 t_lo = max(ivec2(floor((centre - scan) / float(pc.tile))), ivec2(0));
    ivec2 t_hi = min(ivec2(floor((centre + scan) / float(pc.tile))), pc.tiles - 1);
    float c_occluders = 0.0;
    for (int ty = t_lo.y; ty <= t_hi.y; ++ty) {
        for (int tx = t_lo.x; tx <= t_hi.x; ++tx) {
            if (tile_distance(centre, ivec2(tx, ty)) <= scan) {
                c_occluders = max(c_occluders, imageLoad(occluder_tiles, ivec2(tx, ty)).y);
            }
        }
    }
    float reach = 0.5 * (c + c_occluders) + 1.0;
    for (int ty = t_lo.y; ty <= t_hi.y; ++ty) {
        for (int tx = t_lo.x; tx <= t_hi.x; ++tx) {
            ivec2 t = ivec2(tx, ty);
            if (tile_distance(centre, t) <= reach && imageLoad(occluder_tiles, t).x > midway) {
                return true;
            }
        }
    }
    return false;
}

// The radius (px) the spread draws a CoC of diameter coc_px with: the disk
// whose drawn form has the lens disk's variance (src/passes/spread_disk.rs,
// whose spread_radius_px this mirrors). At least half a pixel: above zero
// marks a surface.
float spread_radius_px(float coc_px) {
    float r = 0.5 * abs(coc_px);
    float u = r * spread.entries_per_px;
    if (u < float(spread.entries - 1u)) {
        uint i = uint(u);
        float f = u - float(i);
        return spread.radius[i] + (spread.radius[i + 1u] - spread.radius[i]) * f;
    }
    return sqrt(r * r - spread.excess);
}

void prepare(ivec2 p);

void main() {
    if (gl_LocalInvocationIndex < 2u) {
        group_counts[gl_LocalInvocationIndex] = 0u;
    }
    if (gl_LocalInvocationIndex == 0u) {
        group_slices = 0u;
    }
    barrier();
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (all(lessThan(p, pc.extent))) {
        prepare(p);
    }
    barrier();
    if (gl_LocalInvocationIndex < 2u && group_counts[gl_LocalInvocationIndex] != 0u) {
        atomicAdd(counts[2 * pc.layer + int(gl_LocalInvocationIndex)], group_counts[gl_LocalInvocationIndex]);
    }
    if (gl_LocalInvocationIndex == 0u && group_slices != 0u) {
        uint tiles = gl_NumWorkGroups.x * gl_NumWorkGroups.y;
        uint entry = uint(pc.layer) * tiles + gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
        uint capacity = tiles * uint(pc.layers);
        for (uint bits = group_slices; bits != 0u; bits &= bits - 1u) {
            uint slice = uint(findLSB(bits));
            uint at = atomicAdd(slice_dispatch[3u * slice], 1u);
            slice_lists[slice * capacity + at] = entry;
        }
    }
}

void prepare(ivec2 p) {
    vec4 eye = imageLoad(layer_eye, p);
    float z = eye.z;
    float coverage = eye.w;
    ivec3 at = ivec3(p, pc.layer);
    if (isinf(z) || coverage <= 0.0) {
        imageStore(fragment_color, at, vec4(0.0));
        imageStore(fragment_coc, at, vec4(0.0)); // y = 0: no surface
        return;
    }
    bool keep = pc.layer == 0 || pc.keep_occluded != 0u || visible_through_lens(p, z);
    atomicAdd(group_counts[keep ? 0 : 1], 1u);
    vec3 mean = imageLoad(layer_color, p).rgb;
    // The mean holds the background's color for the uncovered samples.
    vec3 premultiplied = mean - (1.0 - coverage) * pc.background.rgb;
    if (pc.gaussian_layers == 0u) {
        premultiplied = max(premultiplied, vec3(0.0));
    }
    imageStore(fragment_color, at, keep ? vec4(premultiplied, coverage) : vec4(0.0));
    // Kept or not, the pixel's surface occludes the layers behind it.
    float c = signed_coc_px(z, pc.f_px, pc.aperture_radius, pc.focus_distance);
    imageStore(fragment_coc, at, vec4(c, spread_radius_px(c), 0.0, 0.0));
    if (keep) {
        atomicOr(group_slices, slice_bits(c));
    }
}
