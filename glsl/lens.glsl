// The thin lens of DESIGN §2, mirrored from src/camera/lens.rs (the CPU code
// is the reference; tests/shaders.rs checks that both sides agree).

// Circle-of-confusion diameter in pixels at eye depth z (z = +inf: background).
float coc_px(float z, float f_px, float aperture_radius, float focus_distance) {
    if (isinf(z)) {
        return 2.0 * aperture_radius * f_px / focus_distance;
    }
    return 2.0 * aperture_radius * f_px * abs(z - focus_distance) / (z * focus_distance);
}

// Signed CoC diameter (px): sign(z) * c(z), negative in front of the focus
// plane (Camera::signed_coc_px).
float signed_coc_px(float z, float f_px, float aperture_radius, float focus_distance) {
    float s = z >= focus_distance ? 1.0 : -1.0;
    return s * coc_px(z, f_px, aperture_radius, focus_distance);
}

// Image offset at which a point at depth z is seen through the normalised
// lens position u (pixel axes, x right, y down): sign(z) * c(z)/2 * u.
vec2 lens_offset_px(float z, vec2 u, float f_px, float aperture_radius, float focus_distance) {
    return 0.5 * signed_coc_px(z, f_px, aperture_radius, focus_distance) * u;
}
