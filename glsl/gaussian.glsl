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
