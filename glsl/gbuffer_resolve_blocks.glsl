// The body of the one-sample-target resolves (gbuffer_resolve.comp: a
// sample image; gbuffer_resolve_vis.comp: the compute rasteriser's
// visibility buffer): folds output pixel p's samples in the one-sample
// form's index order. A pass of scale 1 holds one sample of each pixel, in
// place; a pass of scale K (the upscaled plan, every sample in one pass)
// holds output pixel p's K² samples in the target's K×K block at K·p,
// sample s in cell K² − 1 − s (src/passes/sample_plan.rs); a plan drawn
// in bands holds only the band's rows, from first_row. After the last
// sample, writes the (weighted) mean color and the coverage fraction.
//
// The including shader declares the push block `pc` (extent,
// sample_index, sample_count, scale, first_row, color_scale and the
// fields of gbuffer_lens_weight.glsl), the images color_sum,
// gbuffer_eye and gbuffer_color, and `vec4 target_sample(ivec2 q)`: the
// (r, g, b, z) of target pixel q.
#include "gbuffer_fold.glsl"
#include "gbuffer_lens_weight.glsl"

// Whether the pass holds every sample of its pixels (sample_index 0,
// sample_count K²) and weighs them alike (no cat's eye): a specialization
// constant, id 3 (src/passes/gbuffer_resolve.rs, resolve_pair), for
// the pipeline of such passes (every compute raster's but accum's), made
// without the code of the others.
layout(constant_id = 3) const bool WHOLE_PASS = false;

// The G-buffer row of the target's row 0: the band's first row, unless
// the including shader's target starts elsewhere (a compute raster's
// band with a row of its neighbours above it).
#ifndef TARGET_FIRST_ROW
#define TARGET_FIRST_ROW pc.first_row
#endif

void resolve_blocks() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy) + ivec2(0, pc.first_row);
    if (any(greaterThanEqual(p, pc.extent))) {
        return;
    }
    ivec2 block = (p - ivec2(0, TARGET_FIRST_ROW)) * int(pc.scale);
    uint n = pc.scale * pc.scale;
    float w = WHOLE_PASS ? 1.0 : lens_weight(p);
    Fold f;
    if (!WHOLE_PASS && pc.sample_index != 0u) {
        f = Fold(imageLoad(color_sum, p), imageLoad(gbuffer_eye, p));
    }
    for (uint s = 0u; s < n; s++) {
        uint cell = n - 1u - s;
        ivec2 q = block + ivec2(cell % pc.scale, cell / pc.scale);
        vec4 t = scaled(target_sample(q), pc.color_scale);
        float index = float(pc.sample_index + s);
        if ((WHOLE_PASS || pc.sample_index == 0u) && s == 0u) {
            f = fold_first(t, index, w);
        } else {
            fold_next(f, t, index, w);
        }
    }
    if (WHOLE_PASS || pc.sample_index + n == pc.sample_count) {
        imageStore(gbuffer_color, p, fold_color(f));
        imageStore(gbuffer_eye, p, fold_eye(f));
    } else {
        imageStore(color_sum, p, f.sum);
        imageStore(gbuffer_eye, p, f.best);
    }
}
