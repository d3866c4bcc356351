#version 460
// The two-field gather, pass 4 (fields::reference): per output pixel Q,
// its front and back, composited. A surface receiver's front is the
// near-field bands (full resolution by the overlap table, then every band
// level bilinearly) and the far-field taps in front of it; its back the
// far-field taps behind it: rings of its own CoC over the far mip, or for
// radii under K + 1/2 the full-resolution offsets by the rings' overlap
// table. A background receiver's front is the bands of all surfaces, its
// back its own colour.
#include "lens.glsl"
#include "fields.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba16f) uniform readonly image2D gbuffer_color;
layout(binding = 1, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 2, std430) readonly buffer FarColor { vec4 far_color[]; };
layout(binding = 3, std430) readonly buffer FarRest { vec4 far_rest[]; };
layout(binding = 4, std430) readonly buffer Bands { vec4 bands[]; };
layout(binding = 5, std430) readonly buffer Tables { float tables[]; };
layout(binding = 6, rgba16f) uniform writeonly image2D result;

float share(int base, int row, float r, float r_max) {
    return tables[base + row * (FIELDS_STEPS + 1) + fields_step(r, r_max)];
}

// N(r): the pixel centres within r of a pixel centre (fields::disk_count).
float disk_count(float r) {
    float m = floor(r * r);
    if (m <= float(FIELDS_COUNT_MAX)) {
        return tables[FIELDS_COUNT_BASE + int(m)];
    }
    return FIELDS_PI * r * r;
}

// The four texels around texel coordinates xy (texel centres at integers)
// of a level of `size` texels starting at texel `base`, indices clamped to
// the level, in the order (x0, y0), (x1, y0), (x0, y1), (x1, y1), and the
// fractions between them (fields::Plane::bilinear).
void corners(ivec2 size, uint base, vec2 xy, out uvec4 at, out vec2 fr) {
    vec2 f0 = floor(xy);
    fr = xy - f0;
    ivec2 a = clamp(ivec2(f0), ivec2(0), size - 1);
    ivec2 b = clamp(ivec2(f0) + 1, ivec2(0), size - 1);
    at = base + uvec4(a.y * size.x + a.x, a.y * size.x + b.x, b.y * size.x + a.x, b.y * size.x + b.x);
}

vec4 bilinear(vec4 v00, vec4 v10, vec4 v01, vec4 v11, vec2 fr) {
    vec4 top = v00 + (v10 - v00) * fr.x;
    vec4 bottom = v01 + (v11 - v01) * fr.x;
    return top + (bottom - top) * fr.y;
}

float bilinear(float v00, float v10, float v01, float v11, vec2 fr) {
    float top = v00 + (v10 - v00) * fr.x;
    float bottom = v01 + (v11 - v01) * fr.x;
    return top + (bottom - top) * fr.y;
}

// The far mip's level of `size` texels from texel `base`, at xy.
void far_fetch(ivec2 size, uint base, vec2 xy, out vec4 color, out vec4 rest) {
    uvec4 at;
    vec2 fr;
    corners(size, base, xy, at, fr);
    color = bilinear(far_color[at.x], far_color[at.y], far_color[at.z], far_color[at.w], fr);
    rest = bilinear(far_rest[at.x], far_rest[at.y], far_rest[at.z], far_rest[at.w], fr);
}

// A band level's set (of `size` texels from band texel `base`) at xy:
// colour and weight.
vec4 band_fetch(ivec2 size, uint base, int set, vec2 xy, out float weight) {
    uvec4 at;
    vec2 fr;
    corners(size, base, xy, at, fr);
    at *= 3u;
    uint c = uint(set);
    weight = bilinear(bands[at.x + 2u][set], bands[at.y + 2u][set], bands[at.z + 2u][set],
                      bands[at.w + 2u][set], fr);
    return bilinear(bands[at.x + c], bands[at.y + c], bands[at.z + c], bands[at.w + c], fr);
}

void main() {
    if (any(greaterThanEqual(gl_GlobalInvocationID.xy, uvec2(pc.size)))) {
        return;
    }
    ivec2 q = pc.origin + ivec2(gl_GlobalInvocationID.xy);
    vec4 cq = imageLoad(gbuffer_color, q);
    float zq = imageLoad(gbuffer_eye, q).z;
    bool surface = !isinf(zq);
    float rq = fields_radius(zq);
    float izq = surface ? 1.0 / zq : 0.0;
    int set = surface ? 0 : 1;

    // The bands of the receiver's set: full resolution first.
    vec4 front = vec4(0.0);
    float front_w = 0.0;
    {
        float reach = FIELDS_B0 + FIELDS_HALF_DIAGONAL;
        int n = int(ceil(reach));
        int row = 0;
        for (int dy = -n; dy <= n; ++dy) {
            int h = fields_row_half(reach * reach, dy);
            // Row by row: first the offsets whose pixel takes part (bits
            // by column, its depth alone loaded), then those alone, in the
            // same order: llvmpipe runs a branch's body, its loads too,
            // whenever any of a row of eight lanes takes it, and a loop over
            // the bits as often as the lane with the most.
            uint taking = 0u;
            for (int dx = -h; dx <= h; ++dx) {
                ivec2 p = q + ivec2(dx, dy);
                if (all(greaterThanEqual(p, ivec2(0))) && all(lessThan(p, pc.extent))) {
                    float z = imageLoad(gbuffer_eye, p).z;
                    bool takes = !isinf(z) && (set == 1 || z < pc.focus_distance) && fields_radius(z) < FIELDS_B0;
                    taking |= takes ? 1u << uint(dx + h) : 0u;
                }
            }
            while (taking != 0u) {
                int i = findLSB(taking);
                taking &= taking - 1u;
                ivec2 p = q + ivec2(i - h, dy);
                float r = fields_radius(imageLoad(gbuffer_eye, p).z);
                float s = share(FIELDS_T0_BASE, row + i, r, FIELDS_B0);
                front += imageLoad(gbuffer_color, p) * s;
                front_w += s;
            }
            row += max(2 * h + 1, 0);
        }
    }
    uint band_base = 0u;
    for (int l = 1; l <= FIELDS_LEVELS; ++l) {
        float t = float(1 << l);
        ivec2 size = fields_level_size(l);
        float w;
        front += band_fetch(size, band_base, set, (vec2(q + pc.anchor) + 0.5) / t - 0.5, w);
        front_w += w;
        band_base += uint(size.x * size.y);
    }

    vec4 back = cq;
    float back_w = 1.0;
    if (surface) {
        // The far field's taps, in front of Q and behind it.
        vec4 ring = vec4(0.0);
        float ring_w = 0.0;
        back = vec4(0.0);
        back_w = 0.0;
        float small = float(FIELDS_RINGS) + 0.5;
        if (rq < small) {
            float reach = small + FIELDS_HALF_DIAGONAL;
            int n = int(ceil(reach));
            int row = 0;
            int stride = fields_level_size(0).x;
            for (int dy = -n; dy <= n; ++dy) {
                int h = fields_row_half(reach * reach, dy);
                // As the bands' offsets above: first the offsets that hold
                // a surface, then those alone.
                uint holding = 0u;
                for (int dx = -h; dx <= h; ++dx) {
                    ivec2 p = q + ivec2(dx, dy);
                    if (all(greaterThanEqual(p, ivec2(0))) && all(lessThan(p, pc.extent))) {
                        ivec2 a = p + pc.anchor;
                        holding |= far_rest[uint(a.y * stride + a.x)].x != 0.0 ? 1u << uint(dx + h) : 0u;
                    }
                }
                while (holding != 0u) {
                    int i = findLSB(holding);
                    holding &= holding - 1u;
                    ivec2 a = q + ivec2(i - h, dy) + pc.anchor;
                    uint at = uint(a.y * stride + a.x);
                    vec4 rest = far_rest[at];
                    vec4 c = far_color[at];
                    // In front of Q: its own radius; behind: at most Q's.
                    bool in_front = rest.z > izq;
                    float s = share(FIELDS_T1_BASE, row + i, in_front ? rest.y : min(rest.y, rq), small);
                    if (in_front) {
                        ring += c * s;
                        ring_w += s;
                    } else {
                        back += c * s;
                        back_w += s;
                    }
                }
                row += max(2 * h + 1, 0);
            }
        } else {
            float spacing = rq / small;
            float area = FIELDS_PI * rq * rq / float(FIELDS_TAPS);
            int l = int(clamp(roundEven(log2(max(spacing, 1.0))), 0.0, float(FIELDS_LEVELS)));
            float t = float(1 << l);
            ivec2 size = fields_level_size(l);
            uint base = fields_far_offset(l);
            for (int i = 0; i < FIELDS_TAPS; ++i) {
                int b = FIELDS_TAPS_BASE + 4 * i;
                vec3 tap = vec3(tables[b], tables[b + 1], tables[b + 2]); // (dy, dx, |d|)
                vec2 pxy = vec2(q + pc.anchor) + tap.yx * spacing;
                vec4 c, rest;
                far_fetch(size, base, (pxy + 0.5) / t - 0.5, c, rest);
                float n = rest.x;
                if (n <= 1e-6) {
                    continue;
                }
                c /= n;
                float r = rest.y / n;
                float iz = rest.z / n;
                float rb = min(r, rq);
                float dist = tap.z * spacing;
                float cover, cover_back;
                if (tap.z == 0.0) {
                    float half_spacing = 0.5 * spacing;
                    cover = FIELDS_PI * min(r, half_spacing) * min(r, half_spacing) / area;
                    cover_back = FIELDS_PI * min(rb, half_spacing) * min(rb, half_spacing) / area;
                } else {
                    cover = clamp((r - dist) / spacing + 0.5, 0.0, 1.0);
                    cover_back = clamp((rb - dist) / spacing + 0.5, 0.0, 1.0);
                }
                if (iz > izq) {
                    float w = area * n * cover / disk_count(r);
                    ring += c * w;
                    ring_w += w;
                } else {
                    float w = area * n * cover_back / disk_count(rb);
                    back += c * w;
                    back_w += w;
                }
            }
        }
        front += ring;
        front_w += ring_w;
    }
    float alpha = back_w > 1e-9 ? clamp(front_w, 0.0, 1.0) : 1.0;
    vec4 out_color = front / max(front_w, 1e-12) * alpha + back / max(back_w, 1e-12) * (1.0 - alpha);
    imageStore(result, q, out_color);
}
