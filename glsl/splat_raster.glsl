// Push constants of the splat raster pass (src/passes/splat_raster.rs, SplatPush).
layout(push_constant, std430) uniform SplatPush {
    vec4 eye;        // world position of the lens centre
    vec4 right;      // camera basis, world space (DESIGN §2)
    vec4 up;
    vec4 forward;
    vec2 center;     // framebuffer position of the optical axis (W/2 + guard, H/2 + guard)
    vec2 extent;     // framebuffer size in pixels (W + 2 guard, H + 2 guard)
    vec2 jitter;     // sub-pixel sample offset, pixels
    vec2 lens_u;     // normalised lens position (0 for a pinhole)
    float f_px;
    float near;      // depth range mapped to [0, 1]; points outside are clipped
    float far;
    float splat_px;  // > 0: every splat this many pixels wide
    float aperture_radius;
    float focus_distance;
    float max_point_size;
    float min_point_size; // 1, or K in the upscaled plan's target (one output pixel)
} pc;
