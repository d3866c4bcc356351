// One pixel's G-buffer resolve, folded one raster sample at a time
// (DESIGN §3): the running color sum (alpha: 1 per covered sample, so its
// sum counts them), and the nearest sample's eye position, with in w that
// sample's index: ties in depth go to the lowest index, whatever the order
// of folding. Uncovered samples are the background surface at z = +inf.
// Shared by gbuffer_resolve.comp (one sample per raster pass) and
// gbuffer_resolve_ms.comp (multisampled passes).

struct Fold {
    vec4 sum;
    vec4 best;
};

// Starts the fold with the first sample: color c, eye position e (w > 0:
// covered), sample index `index`.
Fold fold_first(vec4 c, vec4 e, float index) {
    float inf = uintBitsToFloat(0x7f800000u);
    return Fold(c, e.w > 0.0 ? vec4(e.xyz, index) : vec4(0.0, 0.0, inf, index));
}

void fold_next(inout Fold f, vec4 c, vec4 e, float index) {
    f.sum += c;
    if (e.w > 0.0 && (e.z < f.best.z || (e.z == f.best.z && index < f.best.w))) {
        f.best = vec4(e.xyz, index);
    }
}

// The G-buffer's eye position after the last of n samples: w = coverage.
vec4 fold_eye(Fold f, float n) {
    return vec4(f.best.xyz, f.sum.a / n);
}
