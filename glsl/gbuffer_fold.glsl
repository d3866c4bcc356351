// One pixel's G-buffer resolve, folded one raster sample at a time
// (DESIGN §3). A sample is (r, g, b, z): the nearest splat's linear color
// (in codes of the color scale: see `scaled`) and eye depth, or the
// background color and z = +inf where no splat covers it. Each sample
// comes with a weight w (its lens position's in this pixel: 1, but for
// accum's cat's eye, gbuffer_lens_weight.glsl). The fold keeps the
// weighted color sum (alpha: w per covered sample), the sum of the
// weights, and the nearest sample's depth with (in its .w) that sample's index:
// ties in depth go to the lowest index, whatever the order of folding.
// Shared by gbuffer_resolve.comp (one sample per raster pass) and
// gbuffer_resolve_ms.comp (multisampled passes).

struct Fold {
    vec4 sum;
    vec4 best; // (weight sum, 0, z, index)
};

float covered(vec4 s) {
    return isinf(s.w) ? 0.0 : 1.0;
}

// The sample in linear light: a covered sample's color times
// `color_scale`, the linear color of a splat's code 65535 (1 for a cloud
// within white: exact; above for a brighter one, SplatTree::color_scale).
vec4 scaled(vec4 s, float color_scale) {
    return isinf(s.w) ? s : vec4(s.rgb * color_scale, s.w);
}

// Starts the fold with the first sample, of index `index` and weight `w`.
Fold fold_first(vec4 s, float index, float w) {
    return Fold(w * vec4(s.rgb, covered(s)), vec4(w, 0.0, s.w, index));
}

void fold_next(inout Fold f, vec4 s, float index, float w) {
    f.sum += w * vec4(s.rgb, covered(s));
    f.best.x += w;
    if (s.w < f.best.z || (s.w == f.best.z && index < f.best.w)) {
        f.best.zw = vec2(s.w, index);
    }
}

// The G-buffer's color after the last sample: the weighted mean (with
// every weight 1, the sum over the count: the weights' sum is the count
// exactly, below 2^24 samples).
vec4 fold_color(Fold f) {
    return f.sum / f.best.x;
}

// The G-buffer's eye image after the last sample: (0, 0, z of the nearest
// sample, coverage).
vec4 fold_eye(Fold f) {
    return vec4(0.0, 0.0, f.best.z, f.sum.a / f.best.x);
}
