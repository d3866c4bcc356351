// The weight of this pass's lens position in receiving pixel p's fold
// (gbuffer_fold.glsl): accum's cat's eye (docs/decisions/aperture-shape.md),
// mirrored from src/camera/aperture.rs (Aperture::cat_eye_weight).
// the part of the sample's lens cell (half-width pc.half_cell) inside the
// pixel's cat's-eye circle where there is one, else (the cell wholly
// outside) 2^(-40·r), r > 1 its distance from the circle's centre in lens radii,
// at least 2^-120 (a normal float; r passes 3 in a wide frame's guard
// band): the samples outside add less than a float's precision to a
// pixel that has one inside, and a pixel that has none (a corner's sliver
// between the lattice's points) sees through the samples nearest its
// circle.
// Without the cat's eye every weight is 1, and the fold is the plain mean.
//
// The including shader's push block `pc` has lens_u (this pass's lens
// position), window_origin (the frame pixel of G-buffer pixel (0, 0)),
// frame_size (the whole frame's), cat_eye (S; 0: off) and half_cell (a
// lens sample's cell, Aperture::lens_cell_half_width).
#include "aperture.glsl"

float lens_weight(ivec2 p) {
    if (pc.cat_eye == 0.0) {
        return 1.0;
    }
    vec2 centre = cat_eye_centre(pc.window_origin + p, pc.frame_size, pc.cat_eye);
    float w = cat_eye_cell_weight(pc.lens_u, centre, pc.half_cell);
    if (w > 0.0) {
        return w;
    }
    return exp2(max(-40.0 * length(pc.lens_u - centre), -120.0));
}
