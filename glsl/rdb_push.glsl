// Push constants of the RDB's passes, both forms (src/passes/rdb.rs,
// ScatterPush and ResolvePush).
#ifdef RDB_SCATTER
layout(push_constant, std430) uniform Push {
    ivec2 extent;      // G-buffer size
    ivec2 origin;      // G-buffer pixel of output pixel (0, 0): the guard band
    ivec2 scan_origin; // G-buffer pixel of invocation (0, 0)
    ivec2 tile_origin; // output pixel of the bins' pixel (0, 0)
    ivec2 tile_size;   // output pixels the bins hold (a tile or the frame)
    int bins;          // N: N×N bins
    uint pairs;        // 0: centre mode, 1: pairs mode
    uint step;         // 32-bit form: pass (0 depth, 1 source); 64-bit form: the use's tag
    float f_px;
    float aperture_radius;
    float focus_distance;
    ivec2 window_origin; // frame pixel of output pixel (0, 0) (a poster's tile)
    ivec2 frame_size;  // the whole frame, pixels
    float cat_eye;     // S (0: off)
    uint cat_lens;     // 1: the bins' lens positions pressed into each
                       // pixel's cat's eye (cat_eye_lens; a round aperture)
} pc;
#else
layout(push_constant, std430) uniform Push {
    ivec2 extent;      // G-buffer size
    ivec2 origin;      // the guard band
    ivec2 tile_origin; // output pixel of the bins' pixel (0, 0)
    ivec2 tile_size;   // output pixels the bins hold
    int bins;
    uint step;         // 64-bit form: the use's tag (unused by the 32-bit one)
    ivec2 window_origin; // frame pixel of output pixel (0, 0) (a poster's tile)
    ivec2 frame_size;  // the whole frame, pixels
    float cat_eye;     // S (0: off): a bin whose lens position the pixel's
                       // cat's eye clips is left out (glsl/aperture.glsl)
    uint cat_lens;     // as the scatter's
} pc;
#endif
