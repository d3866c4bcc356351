#version 460
// Layered DOF, pass 3, once per depth slice (DESIGN §6, after Kosloff, Tao
// and Barsky 2009): every kept fragment of the slice spreads its
// premultiplied color and coverage, divided by its disk's area, over a
// disk of its spread radius (layered_prepare.comp: the lens disk's blur,
// less the pixel box the G-buffer and the disk's anti-aliasing already
// add; src/passes/spread_disk.rs), by writing signed differences where
// each row span of the disk starts and ends (two at each end, for the
// pixels the end cuts; one where they meet) into a buffer of row
// differences (cost: the disk's height, not its area). The composite
// pass turns the differences into the filled disks with a prefix sum along
// each row. A fragment belongs to the slice of its signed CoC, and, in
// the first RAMP of that slice, also to the next nearer slice with a
// weight falling from 1 to 0, so that a surface crossing a slice boundary
// leaves no seam (its far slice holds it whole beneath the nearer).
// Within a slice the fragments are normalised together, as one surface:
// a fragment whose pixel has a nearer layer's surface in the same slice
// is hidden by it and left out (a surface cut by the peel into two layers
// at an occluder in another slice keeps both parts, and shows no seam).
#include "lens.glsl"
#include "aperture.glsl"
#include "layered_push.glsl"
#include "layered_fixed.glsl"
#include "layered_slices.glsl"
#include "workgroup_order.glsl"

// The workgroups the device runs at once, from as many parts of the
// slice's list (src/passes/kernel_sizes.rs, SPREAD_STREAMS_ID).
layout(constant_id = 12) const uint WORKGROUP_STREAMS = 1u;

layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(binding = 0, rgba32f) uniform readonly image2DArray fragment_color;
layout(binding = 1, rg32f) uniform readonly image2DArray fragment_coc; // signed CoC, spread radius (0: none)
layout(binding = 2, std430) buffer Differences { uint64_t differences[]; }; // 2 words per pixel
// Per slice, the (layer, tile) entries that have fragments in it
// (layered_prepare.comp): one workgroup each, dispatched indirectly.
layout(binding = 3, std430) readonly buffer SliceLists { uint slice_lists[]; };
// Per row of the band, the columns the slice's differences may touch, for
// the composite to skip the rest: max(width - first column), max(last + 1)
// (0, 0: none).
layout(binding = 4, std430) buffer RowSpans { uint row_spans[]; };
// A shaped aperture's chords (pc.shaped): per row of equal height over the
// lens's y ∈ [−1, 1], the shape's [x_lo, x_hi] (src/camera/aperture.rs,
// Aperture::shape_rows).
layout(binding = 5, std430) readonly buffer ShapeChords { vec2 shape_chords[]; };
// An aperture image's rows of spans (pc.shaped == 2; Aperture::shape_spans):
// row k's spans are span_list[span_offsets[k] .. span_offsets[k + 1]], each
// (x_lo, x_hi, transmission) in lens units.
layout(binding = 6, std430) readonly buffer SpanOffsets { uint span_offsets[]; };
layout(binding = 7, std430) readonly buffer SpanList { float span_list[]; };

// The box of G-buffer pixels this workgroup's fragments wrote differences
// at: x from, x to, y from, y to.
shared int group_box[4];

// Adds fixed-point v at G-buffer pixel (x, y) of the band; a difference
// left of the image adds at x = 0 (the prefix sums right of it are the
// same), one right of it or of zero is dropped.
void add(int x, int y, ivec4 v) {
    if (x >= pc.extent.x || v == ivec4(0)) {
        return;
    }
    uint at = 2u * uint((y - pc.band_y0) * pc.extent.x + max(x, 0));
    atomicAdd(differences[at], pack(v.r, v.g));
    atomicAdd(differences[at + 1u], pack(v.b, v.a));
}

// Row dy (vertical offset from the disk's centre, px) of a disk of radius
// r: the part of the row's height inside the disk's vertical extent, and
// the half-width of the disk there (its chord halfway through that part),
// at least half a pixel, so that a disk under a pixel wide is one pixel.
// Mirrors disk_row in src/passes/spread_disk.rs.
vec2 disk_row(float r, int dy) {
    float ady = abs(float(dy));
    float height = clamp(r + 0.5 - ady, 0.0, 1.0);
    float y = height < 1.0 ? 0.5 * (ady - 0.5 + r) : ady;
    return vec2(height, max(sqrt(max(r * r - y * y, 0.0)), 0.5));
}

// Adds v, spread over the span [a, b] of row y (px), to the row's
// differences: each pixel takes its overlap with the span.
void spread_span(int y, float a, float b, vec4 v) {
    int x0 = int(floor(a)), x1 = int(floor(b));
    if (x1 < 0 || x0 >= pc.extent.x) {
        return;
    }
    if (x0 == x1) {
        ivec4 part = to_fixed(v * (b - a));
        add(x0, y, part);
        add(x0 + 1, y, -part);
        return;
    }
    // Pixel x0 takes x0 + 1 - a of it, x1 takes b - x1, those between
    // all of it; the differences sum to exactly zero. Where x1 is x0 + 1
    // its two differences are added as one (the same integer sum).
    ivec4 first = to_fixed(v * (float(x0 + 1) - a));
    ivec4 last = to_fixed(v * (b - float(x1)));
    ivec4 whole = to_fixed(v);
    add(x0, y, first);
    if (x1 == x0 + 1) {
        add(x1, y, last - first);
    } else {
        add(x0 + 1, y, whole - first);
        add(x1, y, last - whole);
    }
    add(x1 + 1, y, -last);
}

// The chord of the cat's eye's circle (cat.xy, radius cat.z; lens units)
// across lens row yn (its centre alone where the row misses it).
vec2 cat_chord(vec3 cat, float yn) {
    float dc = yn - cat.y;
    float h = sqrt(max(cat.z * cat.z - dc * dc, 0.0));
    return vec2(cat.x - h, cat.x + h);
}

// Row dy (from the fragment's centre, px) of the shaped aperture scaled to
// radius r, turned by 180° in front of the focus plane (front), clipped by
// the cat's eye where pc.cat_eye > 0: the circle about cat.xy of radius
// cat.z (lens units; cat_circle):
// the part of the row's height inside the shape's vertical extent, and the
// shape's span there relative to the centre (its chord halfway through
// that part), at least a pixel wide; height 0: the row misses the shape.
// A shape the cat's eye clips away entirely is the lens point −S·d,
// halfway between the circles' centres.
vec3 shape_row(float r, int dy, bool front, vec3 cat) {
    float top = pc.shape_y_min, bottom = pc.shape_y_max;
    bool clip = pc.cat_eye > 0.0;
    if (clip) {
        top = max(top, cat.y - cat.z);
        bottom = min(bottom, cat.y + cat.z);
        if (bottom < top) {
            top = 0.5 * cat.y;
            bottom = top;
        }
    }
    float y_lo = r * (front ? -bottom : top);
    float y_hi = r * (front ? -top : bottom);
    if (y_hi - y_lo < 1.0) {
        // At least a pixel high, as the disk (the row of the centre then
        // holds it, for any radius under half a pixel).
        float m = 0.5 * (y_lo + y_hi);
        y_lo = m - 0.5;
        y_hi = m + 0.5;
    }
    float lo = max(float(dy) - 0.5, y_lo);
    float hi = min(float(dy) + 0.5, y_hi);
    if (hi <= lo) {
        return vec3(0.0);
    }
    float y = r > 0.0 ? 0.5 * (lo + hi) / r : 0.0;
    float yn = front ? -y : y;
    int k = clamp(int(floor((yn + 1.0) * 0.5 * float(pc.shape_rows))), 0, pc.shape_rows - 1);
    vec2 chord = shape_chords[k];
    if (clip) {
        vec2 cut = cat_chord(cat, yn);
        chord = vec2(max(chord.x, cut.x), min(chord.y, cut.y));
    }
    if (chord.x > chord.y) {
        // The row's centre is past the shape's last chord: its middle.
        chord = vec2(0.5 * (chord.x + chord.y));
    }
    vec2 span = front ? -chord.yx * r : chord * r;
    if (span.y - span.x < 1.0) {
        float m = 0.5 * (span.x + span.y);
        span = vec2(m - 0.5, m + 0.5);
    }
    return vec3(hi - lo, span);
}

// Row dy of an aperture image scaled to radius r (turned by 180° in front
// of the focus plane, clipped by the cat's eye as shape_row): the part of
// the row's height inside the image's vertical extent times each span's
// length and transmission, summed and returned; where `spread`, each span
// also spread over G-buffer row p.y + dy, `unit` per unit of that area.
float image_row(float r, ivec2 p, int dy, bool front, vec3 cat, bool spread, vec4 unit) {
    float top = pc.shape_y_min, bottom = pc.shape_y_max;
    bool clip = pc.cat_eye > 0.0;
    if (clip) {
        top = max(top, cat.y - cat.z);
        bottom = min(bottom, cat.y + cat.z);
    }
    float lo = max(float(dy) - 0.5, r * (front ? -bottom : top));
    float hi = min(float(dy) + 0.5, r * (front ? -top : bottom));
    if (hi <= lo) {
        return 0.0;
    }
    float yn = (front ? -1.0 : 1.0) * 0.5 * (lo + hi) / r;
    vec2 cut = vec2(-1.0, 1.0);
    if (clip) {
        cut = cat_chord(cat, yn);
    }
    int k = shape_row_index(yn, pc.shape_rows);
    float centre = float(p.x) + 0.5;
    float area = 0.0;
    for (uint i = span_offsets[k]; i < span_offsets[k + 1]; ++i) {
        vec2 span = vec2(max(span_list[3u * i], cut.x), min(span_list[3u * i + 1u], cut.y));
        if (span.y <= span.x) {
            continue;
        }
        span = front ? -span.yx * r : span * r;
        float part = (hi - lo) * span_list[3u * i + 2u];
        area += part * (span.y - span.x);
        if (spread) {
            spread_span(p.y + dy, centre + span.x, centre + span.y, unit * part);
        }
    }
    return area;
}

// The cat's eye of the pixels a fragment at G-buffer pixel p reaches, in
// its lens positions u: a receiving pixel p + (±r)·u sees u where
// |u + 2S·d(p + (±r)·u)| ≤ 1, and d is affine in the pixel, so those u
// form one circle for all of them: centre −2S·d(p)/k, radius 1/|k|, with
// k = 1 + S·(±2r)/|frame/2| (− in front of the focus plane). Returns
// (centre, radius).
vec3 cat_circle(ivec2 p, float r, bool front) {
    vec2 centre = cat_eye_centre(p + pc.frame_offset, pc.frame_size, pc.cat_eye);
    float k = 1.0 + pc.cat_eye * (front ? -2.0 * r : 2.0 * r) / length(0.5 * vec2(pc.frame_size));
    return vec3(centre / k, 1.0 / abs(k));
}

// Spreads this invocation's fragment, if it has one in the slice; returns
// whether it did, with the box it wrote differences in.
bool spread_fragment(out ivec4 box) {
    // This workgroup's tile of 8×8 pixels and layer: entry
    // layer * tiles + tile of the slice's list (as prepare's workgroups),
    // in the order of the device's streams.
    uvec2 grid = (uvec2(pc.extent) + 7u) / 8u;
    uint tiles = grid.x * grid.y;
    uint listed = streamed_entry(gl_WorkGroupID.x, gl_NumWorkGroups.x, WORKGROUP_STREAMS);
    uint entry = slice_lists[uint(pc.slice) * tiles * uint(pc.layers) + listed];
    uint tile = entry % tiles;
    ivec3 at = ivec3(ivec2(tile % grid.x, tile / grid.x) * 8 + ivec2(gl_LocalInvocationID.xy), entry / tiles);
    if (any(greaterThanEqual(at.xy, pc.extent))) {
        return false;
    }
    vec4 v = imageLoad(fragment_color, at);
    if (v.a <= 0.0) {
        return false;
    }
    vec2 coc = imageLoad(fragment_coc, at).xy; // signed CoC, spread radius
    float c_signed = coc.x;
    float weight = slice_weight(c_signed, pc.slice);
    if (weight <= 0.0) {
        return false;
    }
    for (int l = 0; l < at.z; ++l) {
        vec2 nearer = imageLoad(fragment_coc, ivec3(at.xy, l)).xy;
        if (nearer.y > 0.0 && slice_weight(nearer.x, pc.slice) > 0.0) {
            return false;
        }
    }
    float r = coc.y;
    // The rows of a height above zero (mirrors disk_rows).
    int rows = max(int(ceil(r - 0.5)), 0);
    ivec2 p = at.xy;
    int y_lo = max(p.y - rows, pc.band_y0);
    int y_hi = min(p.y + rows, min(pc.band_y0 + pc.band_rows, pc.extent.y) - 1);
    if (y_lo > y_hi) {
        return false;
    }
    float centre = float(p.x) + 0.5;
    // No row is wider than max(r, 0.5) each side; the last difference is
    // one past the last pixel.
    float reach = max(r, 0.5);
    box = ivec4(max(int(floor(centre - reach)), 0),
                min(int(floor(centre + reach)) + 1, pc.extent.x - 1), y_lo, y_hi);
    if (APERTURE_CODE && pc.shaped != 0u) {
        // A shaped aperture: its chords instead of the disk's rows.
        bool front = c_signed < 0.0;
        vec3 cat = cat_circle(p, r, front);
        if (pc.shaped == 2u) {
            // An aperture image. Under a pixel across: the fragment's pixel.
            if (r < 0.5) {
                if (p.y >= y_lo && p.y <= y_hi) {
                    spread_span(p.y, centre - 0.5, centre + 0.5, v * weight);
                }
                return true;
            }
            float image_area = 0.0;
            for (int dy = -rows; dy <= rows; ++dy) {
                image_area += image_row(r, p, dy, front, cat, false, vec4(0.0));
            }
            if (image_area <= 0.0) {
                return false;
            }
            vec4 image_unit = v * (weight / image_area);
            for (int y = y_lo; y <= y_hi; ++y) {
                image_row(r, p, y - p.y, front, cat, true, image_unit);
            }
            return true;
        }
        float shape_area = 0.0;
        for (int dy = -rows; dy <= rows; ++dy) {
            vec3 row = shape_row(r, dy, front, cat);
            shape_area += row.x * (row.z - row.y);
        }
        vec4 shape_unit = v * (weight / shape_area);
        for (int y = y_lo; y <= y_hi; ++y) {
            vec3 row = shape_row(r, y - p.y, front, cat);
            if (row.x > 0.0) {
                spread_span(y, centre + row.y, centre + row.z, shape_unit * row.x);
            }
        }
        return true;
    }
    // The disk: per row, the interval [x - h, x + h] around the pixel's
    // centre x, each pixel covered by its overlap with it, times the part
    // of the row's height inside the disk (anti-aliased both ways); its
    // area normalises the spread. (After the shape's code: a shaped frame
    // does not sum it.)
    float area = 0.0;
    for (int dy = -rows; dy <= rows; ++dy) {
        vec2 row = disk_row(r, dy);
        area += 2.0 * row.y * row.x;
    }
    vec4 unit = v * (weight / area);
    for (int y = y_lo; y <= y_hi; ++y) {
        vec2 row = disk_row(r, y - p.y);
        float h = row.y;
        spread_span(y, centre - h, centre + h, unit * row.x);
    }
    return true;
}

void main() {
    if (gl_LocalInvocationIndex == 0u) {
        group_box = int[](pc.extent.x, -1, pc.extent.y, -1);
    }
    barrier();
    ivec4 box;
    if (spread_fragment(box)) {
        atomicMin(group_box[0], box.x);
        atomicMax(group_box[1], box.y);
        atomicMin(group_box[2], box.z);
        atomicMax(group_box[3], box.w);
    }
    barrier();
    // The workgroup's rows, spread over its invocations.
    for (int y = group_box[2] + int(gl_LocalInvocationIndex); y <= group_box[3]; y += 64) {
        uint row = uint(y - pc.band_y0);
        atomicMax(row_spans[2u * row], uint(pc.extent.x - group_box[0]));
        atomicMax(row_spans[2u * row + 1u], uint(group_box[1] + 1));
    }
}
