// The compute rasteriser's rotated sample grid (splat_compute_main.glsl),
// shared with the area resolve (gbuffer_area.comp), which asks where a
// G-buffer pixel's samples lie.

// How far past its corner, along one axis, the sample of a target pixel
// lies, in target pixels, for cell c of k (inv_k = 1/k): along y the
// pixel's cell column, along x k − 1 − its cell row (the grid rotated
// by atan(1/k): splat_compute_main.glsl). The cells of target pixel
// (x, y) are (x mod k, y mod k): the target starts at a G-buffer pixel's
// corner, a band at a G-buffer row.
// The callers keep cells and 1/k out of their loops over pixels (lavapipe
// divides lane by lane, and reloads the push block after each atomic).
float cell_offset(int c, float inv_k) {
    return (float(c) + 0.5) * inv_k;
}

// Where the sample of the target pixel in cell column i and row j of a
// G-buffer pixel's k × k block lies, in target pixels from the block's
// corner.
vec2 block_sample(int i, int j, int k, float inv_k) {
    return vec2(float(i) + cell_offset(k - 1 - j, inv_k), float(j) + cell_offset(i, inv_k));
}
