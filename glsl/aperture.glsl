// The aperture's cat's eye (docs/decisions/aperture-shape.md), mirrored
// from src/camera/aperture.rs (Aperture::cat_eye_centre,
// Aperture::cat_eye_passes, Aperture::cat_eye_blur_reach, and RDB's
// Aperture::cat_eye_lens and cat_eye_pressed_weight); tests/aperture.rs
// holds each method that follows it to the analytic image, and
// tests/shaders.rs the blur's reach, the pressed lens and its weight to
// the CPU's.

// Whether this pipeline carries the code of shaped apertures and of the
// cat's eye (a specialization constant, id 0: src/passes/mod.rs,
// Specialized::round): the round pipeline of a pass is made without it, for
// the frames of the round aperture, which never run it.
layout(constant_id = 0) const bool APERTURE_CODE = true;

// The second circle's centre, in lens positions, for pixel p of a frame of
// size `frame`: −2S·d, d = (p + ½ − frame/2) / |frame/2|.
vec2 cat_eye_centre(ivec2 p, ivec2 frame, float cat_eye) {
    vec2 half_frame = 0.5 * vec2(frame);
    vec2 d = (vec2(p) + 0.5 - half_frame) / length(half_frame);
    return -2.0 * cat_eye * d;
}

// The least part of its CoC across which a lens holding the disk of radius
// shape_reach, clipped by the cat's eye S whose circle is centred at
// `centre` (cat_eye_centre of the point's pixel; half_diag = |frame/2| px),
// blurs a point whose CoC runs over the range of coc's two ends (px) on
// one side of the focus (behind: beyond it); 0 where it may not blur at
// all (Aperture::cat_eye_blur_reach).
float cat_eye_blur_reach(float shape_reach, float cat_eye, vec2 centre, float half_diag, vec2 coc, bool behind) {
    float delta = length(centre);
    float s = behind ? cat_eye : -cat_eye;
    vec2 k = vec2(1.0) + s * coc / half_diag;
    if (k.x * k.y <= 0.0) {
        return 0.0;
    }
    vec2 t = vec2(1.0) / abs(k);
    vec2 edge = 0.5 * (vec2(shape_reach) + (1.0 - delta) * t);
    return max(min(min(shape_reach, min(t.x, t.y)), min(edge.x, edge.y)), 0.0);
}

// The unit disk pressed into the part of the lens a pixel whose cat's eye
// circle is centred at `centre` sees (Aperture::cat_eye_lens): into the
// ellipse that holds the two circles' meet, its centre δ/2 along the axis
// e = centre/δ (δ = |centre|; e = x where δ² ≤ 1e-30, where the press is
// the identity to float precision), its half-axes 1 − δ/2 along e and √(1 − δ²/4) across. A
// cell's area is scaled by their product. The terms of one centre, for
// many lens positions:
struct CatLens {
    vec2 e;
    float half_delta;
    float half_along;
    float half_across;
};

CatLens cat_lens_of(vec2 centre) {
    float delta2 = dot(centre, centre);
    float inverse = inversesqrt(max(delta2, 1.0e-30));
    float delta = delta2 * inverse;
    CatLens l;
    l.e = delta2 > 1.0e-30 ? centre * inverse : vec2(1.0, 0.0);
    l.half_delta = 0.5 * delta;
    l.half_along = max(1.0 - 0.5 * delta, 0.0);
    l.half_across = sqrt(max(1.0 - 0.25 * delta * delta, 0.0));
    return l;
}

vec2 cat_lens_at(CatLens l, vec2 u) {
    vec2 across = vec2(-l.e.y, l.e.x);
    return (l.half_delta + l.half_along * dot(u, l.e)) * l.e + (l.half_across * dot(u, across)) * across;
}

vec2 cat_eye_lens(vec2 u, vec2 centre) {
    return cat_lens_at(cat_lens_of(centre), u);
}

// The area of a pressed cell over its cell of the unit disk.
float cat_lens_area(CatLens l) {
    return l.half_along * l.half_across;
}

// Whether lens position u passes the circle of radius 1 about `centre`.
bool cat_eye_passes(vec2 u, vec2 centre) {
    vec2 v = u - centre;
    return v.x * v.x + v.y * v.y <= 1.0;
}

// The half-width of one of `count` equal cells of the lens's circle
// (area π/count): Aperture::lens_cell_half_width.
float lens_cell_half_width(float count) {
    return 0.886227 / sqrt(count);
}

// The part of a lens cell of half-width `half_cell` about u inside the
// circle of radius 1 about `centre` (Aperture::cat_eye_cell_weight): a
// ramp across the circle, 1 a half cell inside it, 0 a half cell outside.
float cat_eye_cell_weight(vec2 u, vec2 centre, float half_cell) {
    return clamp((1.0 - length(u - centre)) / (2.0 * half_cell) + 0.5, 0.0, 1.0);
}

// The weight of an RDB bin of lens position u pressed by the terms `l`
// (cat_lens_at; RDB's resolve: of the pixel's own circle) at a pixel whose
// circle is centred at `centre`: the part of its pressed cell (of
// half-width half_cell before the press, h = √area times that after it)
// inside both that circle and the lens, a ramp across each: 1 − r (r the
// distance from the circle's centre) taken as (1 − r²)/2, which it is to
// within (1 − r)²/2 where the ramp is not flat (|1 − r| < h), with no
// square root (Aperture::cat_eye_pressed_weight).
float cat_eye_pressed_weight(CatLens l, vec2 u, vec2 centre, float half_cell) {
    vec2 at = cat_lens_at(l, u);
    float quarter_h = 0.25 / max(half_cell * sqrt(cat_lens_area(l)), 1.0e-6);
    vec2 v = at - centre;
    return clamp((1.0 - dot(v, v)) * quarter_h + 0.5, 0.0, 1.0)
        * clamp((1.0 - dot(at, at)) * quarter_h + 0.5, 0.0, 1.0);
}

// The row of a shaped aperture's chord table (src/camera/aperture.rs,
// Aperture::shape_rows: `rows` rows of equal height over the lens's
// y ∈ [−1, 1]) holding lens y.
int shape_row_index(float y, int rows) {
    return clamp(int(floor((y + 1.0) * 0.5 * float(rows))), 0, rows - 1);
}
