// The layouts the Gaussian passes share (src/gaussian_render.rs mirrors
// them: GpuGaussian, GpuProjected; a test checks the sizes).

// A Gaussian as uploaded: centre and activated opacity; the 3D covariance
// R S S^T R^T computed on the host (row-major upper triangle).
struct Gaussian {
    vec4 position_opacity;
    vec4 cov_a;   // xx, xy, xz, yy
    vec4 cov_b;   // yz, zz, -, -
};

// A Gaussian as one lens point sees it (crate::gaussians::Splat2d).
struct Projected {
    vec4 centre_depth;    // centre in pixels (pixel centres at +0.5), eye depth, -
    vec4 conic_opacity;   // inverse 2D covariance (a, b, c), opacity
    vec4 color;           // rgb as trained (sRGB-encoded), -
    ivec4 tiles;          // tiles covered: x0, x1, y0, y1 ([min, max))
};

// The reference rasterizer's tile side, pixels (crate::gaussians::TILE_PX).
const int TILE_PX = 16;

// sRGB-encoded value -> linear light (image_io::srgb_to_linear, the power
// curve continued above 1).
float srgb_to_linear(float c) {
    return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}

// The opacity a Gaussian adds at a sample d = centre - sample (px): the
// reference's alpha = min(0.99, o e^power), 0 where power > 0 or alpha is
// below 1/255 (the Gaussian is skipped there).
float gaussian_alpha(vec2 d, vec4 conic_opacity) {
    vec4 co = conic_opacity;
    float power = -0.5 * (co.x * d.x * d.x + co.z * d.y * d.y) - co.y * d.x * d.y;
    if (power > 0.0) {
        return 0.0;
    }
    float alpha = min(0.99, co.w * exp(power));
    return alpha < 1.0 / 255.0 ? 0.0 : alpha;
}
