// Fast DOF, pass 4 (Zhao §3.3, DESIGN §4): each output pixel Q averages the
// colors (and, as alpha, the coverage) of the pixels P with |p − q| <= c_P / 2 and z_P <= z_Q, weighted
// by P's weight, gathering only as far as its tile's dilated radius. Where
// that window holds only background (the tile's flag), every P has Q's own
// CoC, weight and color: the same sums are formed from those, in the same
// order, without loading each P — bitwise the plain gather's result; for a
// black background (coverage 0) every product and sum is +0 and the mean
// is +0, so there is no loop at all.
//
// Two ways to form the sums over the window (fast_gather.comp and
// fast_gather_tree.comp include this file): pixel by pixel, or (TREE) by
// the blocks of fast_tree.glsl, taking a block's sums whole where its
// bounds show that every one of its pixels passes both tests, leaving it
// where none can, and opening it into its four children otherwise. The
// same pixels contribute either way; only the order of the additions
// differs (the float sums round differently). The cost follows where the
// tests change within the disk (its rim, and the line where z_P crosses
// z_Q), not its area.

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba16f) uniform readonly image2D gbuffer_color;
layout(binding = 1, rgba32f) uniform readonly image2D gbuffer_eye;
layout(binding = 2, rg32f) uniform readonly image2D coc_weight;
layout(binding = 3, rg32f) uniform readonly image2D tile_radius;
layout(binding = 4, rgba16f) uniform writeonly image2D result;
#ifdef TREE
#include "fast_tree.glsl"
layout(binding = 5, std430) readonly buffer Sums { vec4 sums[]; };
layout(binding = 6, std430) readonly buffer Weights { float weights[]; };
layout(binding = 7, std430) readonly buffer Bounds { vec4 bounds[]; };
#endif
#include "aperture.glsl"

layout(push_constant, std430) uniform Push {
    ivec2 extent;   // G-buffer size
    ivec2 origin;   // first output pixel (the guard band)
    ivec2 size;     // output size
    int tile;
    int levels;     // levels of the block tree (TREE; 0: none)
    ivec2 padded;   // the tree's padded extent (fast_tree.glsl)
    // A shaped aperture: a tap reaches Q where its lens position passes
    // the shape (shape_reaches) instead of the disk; the tree takes a block
    // whole where its pixels lie within its blades' polygon or its
    // ellipse, or, for curved blades, the disk of radius shape_inner
    // (ShapeRows::inner_radius) or the box (ShapeRows::inner_box) that
    // the shape holds, and
    // leaves it where they lie outside the shape's bounding box, scaled by
    // the block's largest c and turned for the pixels in front of the
    // focus, or beyond one of its blades' lines or its ellipse.
    uint shaped;
    float focus_distance;
    vec2 shape_inner_box; // ShapeRows::inner_box: half-width, half-height
    float shape_inner;
    float blade_cos;      // cos(π/N) of N blades
    vec4 shape_box;       // Aperture::lens_bounding_box: x min, x max, y min, y max
    vec4 base_from_lens;  // Aperture::base_from_lens, row by row
    float curvature;      // of the blades
} pc;

// The blade count of the frame's shaped aperture (0: none, the squeezed
// circle): the pipeline of a shaped frame is made for its count (a
// specialization constant, id 1; src/passes/fast.rs, Fast::gather_for).
layout(constant_id = 1) const int BLADES = 0;

// M·x of Aperture::base_from_lens (Aperture::base_by_matrix mirrors it):
// an offset or lens position, its squeeze undone, then turned.
vec2 base_by_matrix(vec2 x) {
    vec4 m = pc.base_from_lens;
    return vec2(m.x * x.x + m.y * x.y, m.z * x.x + m.w * x.y);
}

// Mᵀ·x: a direction of M's image turned back to offsets or lens
// positions (u·(Mᵀ·x) = (M·u)·x).
vec2 base_by_matrix_transposed(vec2 x) {
    vec4 m = pc.base_from_lens;
    return vec2(m.x * x.x + m.z * x.y, m.y * x.x + m.w * x.y);
}

// The blades' middle directions turned back to lens positions: u·n_k is
// (M·u)·d_k (Aperture::blade_middle; set once per invocation in main).
vec2 blade_normals[BLADES > 0 ? BLADES : 1];

void set_blade_normals() {
    for (int k = 0; k < BLADES; ++k) {
        float phi = 1.5707964 + (float(k) + 0.5) * (6.2831855 / float(BLADES));
        blade_normals[k] = base_by_matrix_transposed(vec2(cos(phi), -sin(phi)));
    }
}

// The union of the shape's bounding box and its mirror through the lens
// centre (x min, x max, y min, y max; set once per invocation in main):
// the box of a shape symmetric about the centre on both sides of the
// focus (shape_box_meets).
vec4 shape_union_box;

void set_shape_union_box() {
    vec4 b = pc.shape_box;
    shape_union_box = vec4(min(b.x, -b.y), max(b.y, -b.x), min(b.z, -b.w), max(b.w, -b.z));
}

// Whether the frame's blades are straight (id 11; Aperture::has_straight_blades,
// set with BLADES): their polygon lies within the circle |M·v| <= h, and
// |v| <= |M·v|, so shape_reaches tests the blades alone.
layout(constant_id = 11) const bool STRAIGHT = false;

// Whether every frame of the pipeline is shaped (id 10): a pipeline made
// for shaped frames alone (Fast::gather_for), whose disk code is compiled
// away. llvmpipe runs both sides of a branch it cannot prove uniform, so
// a shaped frame through the general pipeline also paid for every tap's
// disk test and its depth load.
layout(constant_id = 10) const bool SHAPED_ONLY = false;

// Whether the frame's aperture is shaped: never in the round pipeline
// (APERTURE_CODE, aperture.glsl), whose shape code is compiled away;
// always in one made for shaped frames (SHAPED_ONLY).
bool shaped() {
    return APERTURE_CODE && (SHAPED_ONLY || pc.shaped != 0u);
}

// Whether a block of offsets [v0, v1] from Q, of diameters up to c and
// depths zs (min, max), can reach Q through the shape at all: its box
// meets the shape's bounding box scaled to c/2 (v = −(s·c/2)·u, s the
// side of the focus; the shape holds the lens centre, so a smaller c
// reaches within the larger's box).
bool shape_box_meets(ivec2 v0, ivec2 v1, float c, vec2 zs) {
    // A hundredth of a percent wider: no rounding leaves out a pixel that
    // shape_reaches takes (the box holds the lens centre: it grows).
    float scale = 0.5001 * c;
    if (BLADES % 2 == 0) {
        // A shape symmetric about the lens centre (an even count of
        // blades, or none): both sides' boxes are one, taken as their
        // union for the rounding of the shape's bounds (shape_union_box,
        // scaled here: the bits of the scaled boxes' union, scale >= 0).
        vec4 u = scale * shape_union_box;
        return float(v0.x) <= u.y && float(v1.x) >= u.x && float(v0.y) <= u.w && float(v1.y) >= u.z;
    }
    vec4 b = scale * pc.shape_box;
    // Behind the focus (s = +1): v in −(c/2)·box; in front: (c/2)·box.
    vec4 behind = vec4(-b.y, -b.x, -b.w, -b.z);
    bool meets = false;
    if (zs.y >= pc.focus_distance) {
        meets = meets || (float(v0.x) <= behind.y && float(v1.x) >= behind.x
                          && float(v0.y) <= behind.w && float(v1.y) >= behind.z);
    }
    if (zs.x < pc.focus_distance) {
        meets = meets || (float(v0.x) <= b.y && float(v1.x) >= b.x
                          && float(v0.y) <= b.w && float(v1.y) >= b.z);
    }
    return meets;
}

// Whether a pixel at offset v = P − Q from Q, of diameter c and depth z,
// reaches Q through a lens position u of the shape: Q = P + sign(z)·c/2·u
// (Aperture::reaches mirrors it). Tested in v's pixels, without a
// division: with h = c/2 and s = sign(z), u = −v/(s·h), so |u| ≤ 1 is
// |v| ≤ h and, with R = |M·v| = h·|w| and m = max_k −s·(v·n_k) = h·(w·d_k)'s
// largest, the blades' test m·(|w| − C) ≤ (1 − C)·cos(π/N)·|w| times h² is
// m·(R − C·h) ≤ (1 − C)·cos(π/N)·R·h. An even count's blades come in
// opposite pairs, so m is the largest |v·n_k| of the first half, whatever
// s (REACHES_EITHER_SIDE: the depth need not be read first). Straight
// blades (STRAIGHT) are m ≤ cos(π/N)·h alone.
bool shape_reaches(ivec2 v, float c, float z) {
    if (c <= 0.0) {
        return v == ivec2(0);
    }
    float h = 0.5 * c;
    vec2 x = vec2(v);
    if (!STRAIGHT && dot(x, x) > h * h) {
        return false;
    }
    vec2 mv = base_by_matrix(x);
    float r2 = dot(mv, mv);
    if (BLADES == 0) {
        return r2 <= h * h;
    }
    float most = 0.0;
    if (BLADES % 2 == 0) {
        for (int k = 0; k < BLADES / 2; ++k) {
            most = max(most, abs(dot(x, blade_normals[k])));
        }
    } else {
        float s = z >= pc.focus_distance ? -1.0 : 1.0;
        for (int k = 0; k < BLADES; ++k) {
            most = max(most, s * dot(x, blade_normals[k]));
        }
    }
    if (STRAIGHT) {
        return most <= pc.blade_cos * h;
    }
    float r = sqrt(r2);
    return r2 <= h * h && most * (r - pc.curvature * h) <= (1.0 - pc.curvature) * pc.blade_cos * r * h;
}

// Whether no offset of the box [v0, v1] reaches Q through the squeezed
// circle (no blades) for any diameter up to c (a smaller one's ellipse
// lies in the larger's), on either side of the focus alike (it is
// symmetric about the lens centre), h a ten-thousandth past c/2 for the
// rounding: across the axis g = Mᵀ·M·mid (the ellipse's normal where the
// ray through the box's centre meets it), the ellipse reaches
// h·|M⁻ᵀ·g| = h·|M·mid| along g, the box no less than
// g·mid − |half_size.x·g.x| − |half_size.y·g.y|, and g·mid = |M·mid|².
// The shape's bounding box (shape_box_meets) alone left the corners
// between the two to be opened down to the leaves.
bool box_outside_ellipse(ivec2 v0, ivec2 v1, float c) {
    float h = 0.50005 * c;
    vec2 mid = 0.5 * vec2(v0 + v1), half_size = 0.5 * vec2(v1 - v0);
    vec2 mm = base_by_matrix(mid);
    vec2 g = base_by_matrix_transposed(mm);
    return dot(mm, mm) - dot(half_size, abs(g)) > h * length(mm);
}

// Whether every offset of the box [v0, v1] reaches Q through the
// squeezed circle (no blades) for every diameter of c and more (a larger
// one's ellipse holds the smaller's), whatever the side of the focus: its
// corners lie within the ellipse |M·v| <= h, h a ten-thousandth short of
// c/2 (it is convex: the corners decide; |v| <= |M·v| too).
bool box_inside_ellipse(ivec2 v0, ivec2 v1, float c) {
    float h = 0.49995 * c;
    vec2 corners[4] = vec2[4](vec2(v0), vec2(v1.x, v0.y), vec2(v0.x, v1.y), vec2(v1));
    bool inside = true;
    for (int i = 0; i < 4; ++i) {
        vec2 mv = base_by_matrix(corners[i]);
        inside = inside && dot(mv, mv) <= h * h;
    }
    return inside;
}

// Of the box [v0, v1] of offsets from Q, of depths bound.xy (min, max)
// and diameters bound.zw (min, max), on each side of the focus its depths
// take: x, whether no offset reaches Q through the blades for any
// diameter up to bound.w (a smaller one's shape lies in the larger's):
// the box lies beyond one of their lines, which lie ((1 − C)·cos(π/N) + C)·h
// from the lens centre along d_k (a curved blade bulges out to
// C·cos δ ≤ C beyond its line), h a ten-thousandth past c/2; y, whether
// every offset reaches Q for every diameter of bound.z and more: the box
// lies within the blades' polygon, whose lines lie cos(π/N)·h out, h a
// ten-thousandth short of c/2 (the polygon lies within the shape whatever
// the curvature: a curved blade bulges past its line between the same
// corners, on the circle). Over the box, s·(v·n_k) runs s·(mid·n_k) ±
// (|half_size.x·n_k.x| + |half_size.y·n_k.y|), worked out once a blade for
// both. An even count's blades come in opposite pairs: half of them, on
// either side alike.
bvec2 blade_box(ivec2 v0, ivec2 v1, vec4 bound) {
    float reach_out = ((1.0 - pc.curvature) * pc.blade_cos + pc.curvature) * 0.50005 * bound.w;
    float reach_in = pc.blade_cos * 0.49995 * bound.z;
    vec2 mid = 0.5 * vec2(v0 + v1), half_size = 0.5 * vec2(v1 - v0);
    bool outside = false, inside = true;
    if (BLADES % 2 == 0) {
        for (int k = 0; k < BLADES / 2; ++k) {
            vec2 n = blade_normals[k];
            float along = abs(dot(mid, n)), across = dot(half_size, abs(n));
            outside = outside || along - across > reach_out;
            inside = inside && along + across <= reach_in;
        }
        return bvec2(outside, inside);
    }
    bool behind = bound.y >= pc.focus_distance, front = bound.x < pc.focus_distance;
    bool out_behind = false, out_front = false;
    for (int k = 0; k < BLADES; ++k) {
        vec2 n = blade_normals[k];
        float along = dot(mid, n), across = dot(half_size, abs(n));
        out_behind = out_behind || -along - across > reach_out;
        out_front = out_front || along - across > reach_out;
        inside = inside && (!behind || -along + across <= reach_in) && (!front || along + across <= reach_in);
    }
    return bvec2((!behind || out_behind) && (!front || out_front), inside);
}

// Whether shape_reaches does not depend on the depth: an even count of
// blades or none (a shape symmetric about the lens centre).
const bool REACHES_EITHER_SIDE = BLADES % 2 == 0;

// Whether the pixel loops clip each row of the window to row_span: in the
// pipelines made for their frames (the round pipeline, APERTURE_CODE off,
// and those for shaped frames alone). The general pipeline keeps the
// whole window, the reference tests/aperture.rs holds the clipped loops
// to, byte for byte: a tap outside the span fails the test it skips.
const bool ROW_SPANS = !APERTURE_CODE || SHAPED_ONLY;

// The columns [x0, x1] of row dy of the window (offsets from Q) outside
// which no tap of a CoC diameter up to 2t reaches Q, on either side of
// the focus (Aperture::row_span mirrors it, and its test holds every tap
// that reaches within): the disk |v| <= t; for a shape, the ellipse
// |M·v| <= t and every blade's half-plane s·(v·n_k) <= ((1 − C)·cos(π/N)
// + C)·t (an even count's in slabs, an odd count's two sides joined),
// the scale widened by a thousandth of t and of a pixel for the rounding.
ivec2 row_span(int dy, float t) {
    const ivec2 EMPTY = ivec2(1, 0);
    t = 1.001 * t + 0.001;
    float y = float(dy);
    float room = t * t - y * y;
    if (room < 0.0) {
        return EMPTY;
    }
    vec2 span = vec2(-sqrt(room), sqrt(room));
    if (shaped()) {
        vec4 m = pc.base_from_lens;
        float a = m.x * m.x + m.z * m.z;
        float b = 2.0 * (m.x * m.y + m.z * m.w) * y;
        float c = (m.y * m.y + m.w * m.w) * y * y - t * t;
        float disc = b * b - 4.0 * a * c;
        if (disc < 0.0) {
            return EMPTY;
        }
        span = vec2(max(span.x, (-b - sqrt(disc)) / (2.0 * a)),
                    min(span.y, (-b + sqrt(disc)) / (2.0 * a)));
    }
    if (shaped() && BLADES > 0) {
        float reach = ((1.0 - pc.curvature) * pc.blade_cos + pc.curvature) * t;
        if (BLADES % 2 == 0) {
            // Blade k + N/2 faces −n_k: a slab for each of the first half.
            for (int k = 0; k < BLADES / 2; ++k) {
                vec2 n = blade_normals[k];
                if (abs(n.x) > 1e-4) {
                    float x0 = (reach - y * n.y) / n.x, x1 = (-reach - y * n.y) / n.x;
                    span = vec2(max(span.x, min(x0, x1)), min(span.y, max(x0, x1)));
                }
            }
        } else {
            vec2 sides[2] = vec2[2](span, span);
            for (int i = 0; i < 2; ++i) {
                float s = i == 0 ? 1.0 : -1.0;
                for (int k = 0; k < BLADES; ++k) {
                    vec2 n = s * blade_normals[k];
                    if (abs(n.x) > 1e-4) {
                        float x = (reach - y * n.y) / n.x;
                        sides[i] = n.x > 0.0 ? vec2(sides[i].x, min(sides[i].y, x))
                                             : vec2(max(sides[i].x, x), sides[i].y);
                    }
                }
            }
            bool front = sides[0].x <= sides[0].y, behind = sides[1].x <= sides[1].y;
            span = front && behind ? vec2(min(sides[0].x, sides[1].x), max(sides[0].y, sides[1].y))
                 : front ? sides[0] : sides[1];
        }
    }
    if (span.x > span.y) {
        return EMPTY;
    }
    // Bounded before the conversion: a span wider than any window.
    return ivec2(ceil(max(span.x, -1.0e6)), floor(min(span.y, 1.0e6)));
}

// The block after block b of level l in depth-first order under a top
// block of level `top`, when b is not opened: up past last children (odd
// x and y: as many levels as b.x & b.y has trailing ones), then on to the
// next sibling: (1, y) after (0, y), (0, y + 1) after (1, y). `done` once
// the way up comes back to the top block. The way up is computed, not
// looped: each loop turn counts against llvmpipe's limit of 65,535 per
// invocation.
void next_block(inout int l, inout ivec2 b, int top, out bool done) {
    int up = min(findLSB(~(b.x & b.y)), top - l);
    l += up;
    b >>= up;
    done = l == top;
    b = (b.x & 1) == 0 ? b + ivec2(1, 0) : b + ivec2(-1, 1);
}

void main() {
    set_blade_normals();
    set_shape_union_box();
    ivec2 q = pc.origin + ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(gl_GlobalInvocationID.xy, uvec2(pc.size)))) {
        return;
    }
    float zq = imageLoad(gbuffer_eye, q).z;
    vec2 tile = imageLoad(tile_radius, q / pc.tile).xy;
    int r = int(min(floor(tile.x), float(max(pc.extent.x, pc.extent.y))));
    // precise: no contraction into fused multiply-adds and no hoisting of
    // the products, so that both paths round alike on every compiler.
    precise vec4 sum = vec4(0.0);
    precise float weight = 0.0;
    if (tile.y == 0.0) {
        // Only background around: z_P = z_Q = +inf passes the z test, and
        // c_P, w_P and the color are Q's.
        vec2 cw = imageLoad(coc_weight, q).xy;
        vec4 color = imageLoad(gbuffer_color, q);
        if (all(equal(color, vec4(0.0)))) {
            imageStore(result, q, vec4(0.0));
            return;
        }
        for (int dy = max(-r, -q.y); dy <= min(r, pc.extent.y - 1 - q.y); ++dy) {
            ivec2 row = ivec2(max(-r, -q.x), min(r, pc.extent.x - 1 - q.x));
            if (ROW_SPANS) {
                ivec2 span = row_span(dy, tile.x);
                row = ivec2(max(row.x, span.x), min(row.y, span.y));
            }
            for (int dx = row.x; dx <= row.y; ++dx) {
                if (shaped()) {
                    if (!shape_reaches(ivec2(dx, dy), cw.x, 1.0 / 0.0)) {
                        continue;
                    }
                } else if (float(dx * dx + dy * dy) > 0.25 * cw.x * cw.x) {
                    continue;
                }
                sum += cw.y * color;
                weight += cw.y;
            }
        }
        imageStore(result, q, sum / weight);
        return;
    }
    // The window clipped to the G-buffer (a radius may exceed it: the
    // guard band is bounded, docs/ARCHITECTURE.md).
    ivec2 lo = max(q - r, ivec2(0));
    ivec2 hi = min(q + r, pc.extent - 1);
#ifdef TREE
    // The largest blocks no wider than the radius: at most 6 per axis
    // cover the window.
    int top = r >= TREE_MIN_RADIUS ? min(findMSB(r), pc.levels) : 0;
    float inner2 = shaped() ? pc.shape_inner * pc.shape_inner : 1.0;
    // Whether a shape's own test of the blocks it holds (straight blades'
    // polygon, the squeezed circle's ellipse) takes all its inner disk and
    // inner box do (they lie within it), so that those two are left out:
    // in the pipelines made for shaped frames they are compiled away,
    // where llvmpipe ran both at every visit. Curved blades bulge past
    // their polygon, and their inner disk and box take blocks it does not.
    bool exact_inside = shaped() && (STRAIGHT || BLADES == 0);
    if (top > 0) {
        ivec2 b_lo = lo >> top, b_hi = hi >> top;
        for (int by = b_lo.y; by <= b_hi.y; ++by) {
            for (int bx = b_lo.x; bx <= b_hi.x; ++bx) {
                // Depth first through the quadtree under this top block,
                // without a stack: from a block either down to its first
                // child, or on to the next block in depth-first order (up
                // past the last children, then to the next sibling). The
                // way up is computed, not looped: each loop turn counts
                // against llvmpipe's limit of 65,535 per invocation.
                int l = top;
                ivec2 b = ivec2(bx, by);
                bool done = false;
                while (!done) {
                    // The blocks up to the next leaf that is neither taken
                    // nor left whole, or the last: llvmpipe runs every
                    // branch that any of a row of eight lanes takes, and
                    // a leaf's pixels in the loop of the visits would run
                    // (masked) at every visit of every lane; here they run
                    // once all lanes have come to a leaf or the end. Each
                    // lane's sums are added in the same order as with the
                    // leaf in the visits' loop: the same bits.
                    bool leaf = false;
                    ivec2 x0, x1; // the block's first and last pixels: at the end, the leaf's
                    while (!done && !leaf) {
                        bool open = false;
                        x0 = b << l;
                        x1 = min(x0 + (1 << l) - 1, pc.extent - 1);
                        if (any(greaterThan(x0, hi)) || any(lessThan(x1, lo))) {
                            // Outside the window (or the padding beyond the
                            // extent): nothing.
                        } else {
                            uint at = tree_index(pc.padded, l, b);
                            vec4 bound = bounds[at]; // z min, z max, c min, c max
                            // The nearest and farthest of the block's pixels
                            // from Q, per axis (integers: the squares are exact).
                            ivec2 near = max(max(x0 - q, q - x1), ivec2(0));
                            ivec2 far = max(abs(x0 - q), abs(x1 - q));
                            float near2 = float(near.x * near.x + near.y * near.y);
                            float far2 = float(far.x * far.x + far.y * far.y);
                            bvec2 blades = shaped() && BLADES > 0 ? blade_box(x0 - q, x1 - q, bound) : bvec2(false);
                            if (bound.x > zq || near2 > 0.25 * bound.w * bound.w
                                    || (shaped() && (!shape_box_meets(x0 - q, x1 - q, bound.w, bound.xy)
                                                     || (BLADES > 0 ? blades.x : box_outside_ellipse(x0 - q, x1 - q, bound.w))))) {
                                // No pixel passes: every one is behind Q, or out
                                // of its own disk's reach (0.25 c² grows with c,
                                // so the largest c bounds every pixel's test),
                                // or of the shape's box, or beyond one of its
                                // blades or its squeezed circle.
                            } else if (all(greaterThanEqual(x0, lo)) && all(lessThanEqual(x1, hi))
                                    && bound.y <= zq
                                    && ((!exact_inside
                                         && (!(far2 > 0.25 * bound.z * bound.z * inner2)
                                             || (shaped() && all(lessThanEqual(vec2(far), 0.5 * bound.z * pc.shape_inner_box)))))
                                        || (shaped()
                                            && ((BLADES == 0 && box_inside_ellipse(x0 - q, x1 - q, bound.z))
                                                || (BLADES > 0 && blades.y))))) {
                                // Every pixel passes: inside the window, none
                                // behind Q, the farthest within the smallest
                                // disk's reach (a shape's: its inner disk's or
                                // inner box's, inside every chord, turned or
                                // not; the blades' polygon; the squeezed
                                // circle's ellipse).
                                sum += sums[at];
                                weight += weights[at];
                            } else if (l > TREE_LEAF_LEVEL) {
                                open = true;
                            } else {
                                leaf = true;
                            }
                        }
                        if (open) {
                            l -= 1;
                            b *= 2;
                        } else if (!leaf) {
                            next_block(l, b, top, done);
                        }
                    }
                    if (leaf) {
                        // A leaf: its pixels in the window one by one,
                        // with the two tests of the pixel loop below
                        // (written out in both: a shared function made
                        // the pixel loop 10-30 % slower on llvmpipe), as
                        // a loop over its rows with the columns of a
                        // fixed count (unrolled), so that leaves add few
                        // turns to llvmpipe's loop limit.
                        ivec2 p0 = max(x0, lo), p1 = min(x1, hi);
                        for (int y = p0.y; y <= p1.y; ++y) {
                            for (int i = 0; i < (1 << TREE_LEAF_LEVEL); ++i) {
                                ivec2 p = ivec2(x0.x + i, y);
                                if (p.x < p0.x || p.x > p1.x) {
                                    continue;
                                }
                                ivec2 d = p - q;
                                vec2 cw = imageLoad(coc_weight, p).xy;
                                float zp = imageLoad(gbuffer_eye, p).z;
                                bool reaches = shaped()
                                    ? shape_reaches(d, cw.x, zp)
                                    : !(float(d.x * d.x + d.y * d.y) > 0.25 * cw.x * cw.x);
                                if (reaches && !(zp > zq)) {
                                    sum += cw.y * imageLoad(gbuffer_color, p);
                                    weight += cw.y;
                                }
                            }
                        }
                        next_block(l, b, top, done);
                    }
                }
            }
        }
        imageStore(result, q, sum / weight);
        return;
    }
#endif
    for (int dy = lo.y - q.y; dy <= hi.y - q.y; ++dy) {
        ivec2 row = ivec2(lo.x - q.x, hi.x - q.x);
        if (ROW_SPANS) {
            ivec2 span = row_span(dy, tile.x);
            row = ivec2(max(row.x, span.x), min(row.y, span.y));
        }
        for (int dx = row.x; dx <= row.y; ++dx) {
            ivec2 p = q + ivec2(dx, dy);
            vec2 cw = imageLoad(coc_weight, p).xy;
            if (shaped() && REACHES_EITHER_SIDE) {
                // As the disk's test: the shape's first, the depth's after.
                if (!shape_reaches(ivec2(dx, dy), cw.x, 0.0)) {
                    continue;
                }
                if (imageLoad(gbuffer_eye, p).z > zq) {
                    continue;
                }
            } else if (shaped()) {
                float zp = imageLoad(gbuffer_eye, p).z;
                if (!shape_reaches(ivec2(dx, dy), cw.x, zp) || zp > zq) {
                    continue;
                }
            } else {
                float d2 = float(dx * dx + dy * dy);
                if (d2 > 0.25 * cw.x * cw.x) {
                    continue;
                }
                if (imageLoad(gbuffer_eye, p).z > zq) {
                    continue;
                }
            }
            sum += cw.y * imageLoad(gbuffer_color, p);
            weight += cw.y;
        }
    }
    // Q itself always takes part (distance 0, same depth): weight > 0.
    // Alpha: the contributors' coverage, weighted as their color.
    imageStore(result, q, sum / weight);
}
