// A splat's place in the raster target (DESIGN §2, §3), shared by the
// sprite path (splat_raster.vert) and the compute rasteriser
// (splat_compute.comp) so that both place and size a splat with the same
// arithmetic. Reads the push block `pc` (eye, right, up, forward, center,
// lens_u, f_px, near, far, splat_px, aperture_radius, focus_distance,
// min_point_size, max_point_size). Needs lens.glsl.

struct Projected {
    vec2 p;          // target position of the centre, pixels
    float size_px;   // edge of the square, target pixels (clamped)
    float z;         // eye depth
    float diameter;  // world diameter, for the depth peel
};

// False when the splat is behind the eye or outside (near, far).
bool project_splat(vec4 position_size, vec2 jitter, out Projected s) {
    vec3 d = position_size.xyz - pc.eye.xyz;
    vec3 e = vec3(dot(d, pc.right.xyz), dot(d, pc.up.xyz), dot(d, pc.forward.xyz));
    s.z = e.z;
    s.diameter = 0.0;
    s.p = vec2(0.0);
    s.size_px = 1.0;
    if (e.z <= pc.near || e.z >= pc.far) {
        return false;
    }
    vec2 p = vec2(pc.center.x + pc.f_px * e.x / e.z, pc.center.y - pc.f_px * e.y / e.z);
    s.p = p + jitter + lens_offset_px(e.z, pc.lens_u, pc.f_px, pc.aperture_radius, pc.focus_distance);
    float size = pc.splat_px > 0.0 ? pc.splat_px : pc.f_px * position_size.w / e.z;
    s.diameter = pc.splat_px > 0.0 ? pc.splat_px * e.z / pc.f_px : position_size.w;
    s.size_px = clamp(size, pc.min_point_size, pc.max_point_size);
    return true;
}
