// Push constants of the compute passes over the splats (splat_compute.comp,
// peel_cull.comp; src/passes/splat_raster.rs, SplatComputePush): the
// sprite path's projection (splat_raster.glsl) with its jitter added to
// the centre (SplatPush::for_compute), with
// the splat count and the pass's stage (with the compute rasteriser's
// cells per pixel). 128 bytes, lavapipe's limit.
layout(push_constant, std430) uniform SplatComputePush {
    vec4 eye;
    vec4 right;
    vec4 up;
    vec4 forward;
    vec2 center;
    vec2 extent;   // the target's size, pixels
    vec2 lens_u;
    float f_px;
    float near;
    float far;
    float splat_px;
    float aperture_radius;
    float focus_distance;
    float max_point_size;
    float min_point_size;
    uint count;    // splats
    // Bits 0–14: the pass's stage; bit 15: the compute rasteriser writes
    // each splat's square (for the area resolve); bits 16–31: its target
    // pixels per G-buffer pixel along each axis, the cells of its rotated
    // sample grid (splat_compute_main.glsl; 0 in the peel's cull).
    uint stage_cells;
} pc;

uint pass_stage() {
    return pc.stage_cells & 0x7fffu;
}

bool writes_squares() {
    return (pc.stage_cells & 0x8000u) != 0u;
}
