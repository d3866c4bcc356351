// One pixel's G-buffer resolve, folded one raster sample at a time
// (DESIGN §3). A sample is (r, g, b, z): the nearest splat's linear color
// and eye depth, or the background color and z = +inf where no splat
// covers it. The fold keeps the color sum (alpha: 1 per covered sample, so
// its sum counts them), and the nearest sample's depth with in w that
// sample's index: ties in depth go to the lowest index, whatever the order
// of folding. Shared by gbuffer_resolve.comp (one sample per raster pass)
// and gbuffer_resolve_ms.comp (multisampled passes).

struct Fold {
    vec4 sum;
    vec4 best; // (0, 0, z, index)
};

float covered(vec4 s) {
    return isinf(s.w) ? 0.0 : 1.0;
}

// Starts the fold with the first sample, of index `index`.
Fold fold_first(vec4 s, float index) {
    return Fold(vec4(s.rgb, covered(s)), vec4(0.0, 0.0, s.w, index));
}

void fold_next(inout Fold f, vec4 s, float index) {
    f.sum += vec4(s.rgb, covered(s));
    if (s.w < f.best.z || (s.w == f.best.z && index < f.best.w)) {
        f.best = vec4(0.0, 0.0, s.w, index);
    }
}

// The G-buffer's eye image after the last of n samples: (0, 0, z of the
// nearest sample, coverage).
vec4 fold_eye(Fold f, float n) {
    return vec4(0.0, 0.0, f.best.z, f.sum.a / n);
}
