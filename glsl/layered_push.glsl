// Push constants of the layered method's passes (src/passes/layered.rs,
// LayeredPush): one block for all of them.
layout(push_constant, std430) uniform LayeredPush {
    vec4 background;      // linear RGB of the background, w unused
    ivec2 extent;         // G-buffer size (guard band included)
    ivec2 tiles;          // tile grid of the occluder tiles
    int tile;             // tile edge, pixels
    int layer;            // the peeled layer a prepare pass reads
    int layers;           // K
    int slice;            // the depth slice a spread or composite pass takes
    int slices;           // M
    int band_y0;          // first G-buffer row of the band the differences hold
    int band_rows;        // rows of the band
    uint keep_occluded;   // 1: the plain peel (every occluded pixel kept)
    float f_px;
    float aperture_radius;
    float focus_distance;
    float max_coc_px;     // the largest CoC of a point in the view
    float slice_lo;       // signed CoC of the near edge of slice 0
    float slice_width;    // signed CoC per slice
    // 1: the layers are 3D Gaussians' depth layers (src/gaussian_render.rs):
    // one slice each, no ramp between slices, and their light signed (a
    // layer darker than what it covers takes light away).
    uint gaussian_layers;
    // 1: a shaped aperture or a cat's eye (src/camera/aperture.rs,
    // ShapeRows): fragments
    // spread over its chords (binding 5 of the spread) instead of the disk.
    uint shaped;
    float shape_y_min;    // the shape's vertical extent, lens units
    float shape_y_max;
    int shape_rows;       // rows of the chord table
    float cat_eye;        // S (0: off): each fragment's shape clipped by the
                          // cat's eye of its own pixel (glsl/aperture.glsl)
    ivec2 frame_offset;   // frame pixel of G-buffer pixel (0, 0)
    ivec2 frame_size;     // the whole frame, pixels
} pc;
