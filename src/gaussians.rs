//! The CPU reference of 3D Gaussian rendering (issue 31, item 4): a
//! scene's pinhole image as the reference rasterizer (graphdeco-inria's
//! diff-gaussian-rasterization) defines it, in pointlens's camera
//! (docs/ARCHITECTURE.md, "3D Gaussian scenes"). For tests, on small
//! images: one pixel at a time, every Gaussian of its 16 × 16 tile.
//!
//! Per Gaussian: its eye-space centre (culled at z ≤ [`near_z`]); the 3D
//! covariance Σ = R S Sᵀ Rᵀ; the 2D covariance J W Σ Wᵀ Jᵀ with the
//! Jacobian of the projection at the centre (its x/z and y/z clamped to
//! 1.3 × the half field of view's tangent) plus 0.3 px² on the diagonal
//! (the reference's low-pass: its anti-aliasing); the radius ⌈3√λ_max⌉ and
//! the 16-px tiles its square covers; the colour from the SH at the
//! direction camera → centre, + 0.5, clamped at 0. Per pixel, at its
//! centre, front to back by eye depth: α = min(0.99, o·e^power), skipped
//! below 1/255 or where power > 0; the Gaussian that would take the
//! transmittance below 10⁻⁴ ends the pixel without adding; the background
//! takes what transmittance is left. The values composited are those the
//! scene was trained on (sRGB-encoded).

use glam::{Mat3, Vec2, Vec3};

use crate::camera::Camera;
use crate::input::gaussians::GaussianScene;
use crate::passes::sample_plan::ssaa_jitter;

/// The reference rasterizer's tile side, pixels.
pub const TILE_PX: i32 = 16;

/// The SH basis constants of the reference code, degrees 0–3.
const SH_C0: f32 = 0.282_094_8;
const SH_C1: f32 = 0.488_602_52;
const SH_C2: [f32; 5] = [
    1.092_548_4,
    -1.092_548_4,
    0.315_391_57,
    -1.092_548_4,
    0.546_274_2,
];
const SH_C3: [f32; 7] = [
    -0.590_043_6,
    2.890_611_4,
    -0.457_045_8,
    0.373_176_33,
    -0.457_045_8,
    1.445_305_7,
    -0.590_043_6,
];

/// The colour of SH coefficients `sh` (`[k][channel]`, degree `degree`)
/// seen along the unit direction `d`: the reference's evaluation, + 0.5,
/// clamped at 0.
pub fn sh_color(sh: &[f32], degree: u32, d: Vec3) -> Vec3 {
    let c = |k: usize| Vec3::new(sh[3 * k], sh[3 * k + 1], sh[3 * k + 2]);
    let mut result = SH_C0 * c(0);
    if degree > 0 {
        let (x, y, z) = (d.x, d.y, d.z);
        result += -SH_C1 * y * c(1) + SH_C1 * z * c(2) - SH_C1 * x * c(3);
        if degree > 1 {
            let (xx, yy, zz) = (x * x, y * y, z * z);
            let (xy, yz, xz) = (x * y, y * z, x * z);
            result += SH_C2[0] * xy * c(4)
                + SH_C2[1] * yz * c(5)
                + SH_C2[2] * (2.0 * zz - xx - yy) * c(6)
                + SH_C2[3] * xz * c(7)
                + SH_C2[4] * (xx - yy) * c(8);
            if degree > 2 {
                result += SH_C3[0] * y * (3.0 * xx - yy) * c(9)
                    + SH_C3[1] * xy * z * c(10)
                    + SH_C3[2] * y * (4.0 * zz - xx - yy) * c(11)
                    + SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * c(12)
                    + SH_C3[4] * x * (4.0 * zz - xx - yy) * c(13)
                    + SH_C3[5] * z * (xx - yy) * c(14)
                    + SH_C3[6] * x * (xx - 3.0 * yy) * c(15);
            }
        }
    }
    (result + Vec3::splat(0.5)).max(Vec3::ZERO)
}

/// The 3D covariance Σ = R S Sᵀ Rᵀ of Gaussian `g` (world units²).
pub fn covariance(scene: &GaussianScene, g: usize) -> Mat3 {
    let r = Mat3::from_quat(scene.rotations[g]);
    let m = r * Mat3::from_diagonal(scene.scales[g]);
    m * m.transpose()
}

/// A Gaussian as the frame sees it.
#[derive(Debug, Clone, Copy)]
pub struct Splat2d {
    /// Centre in pixels (pointlens's: pixel centres at +0.5).
    pub centre_px: Vec2,
    /// Eye depth of the centre.
    pub depth: f32,
    /// The inverse 2D covariance (a, b, c): power = −½(a dx² + c dy²) − b dx dy.
    pub conic: Vec3,
    /// ⌈3√λ_max⌉, pixels.
    pub radius_px: i32,
    /// Tiles covered, [min, max) in x and y.
    pub tiles: [i32; 4],
    pub color: Vec3,
    pub opacity: f32,
}

/// Gaussian `g` of `scene` through `camera`'s pinhole (its lens ignored),
/// or None where the reference culls it (at the eye depth `near_z`,
/// [`near_z`] of the scene).
pub fn project(scene: &GaussianScene, g: usize, camera: &Camera, near_z: f32) -> Option<Splat2d> {
    project_through(scene, g, camera, Vec2::ZERO, near_z)
}

/// The reference code's near plane: Gaussians whose centre is at most this
/// eye depth (scene units; metres in its trained scenes) are culled.
pub const REFERENCE_NEAR_Z: f32 = 0.2;

/// A scene's near plane, eye depth: the reference code's
/// [`REFERENCE_NEAR_Z`], or 1 % of the centres' extent (the bounding box's
/// largest side) where that is nearer, so that a scene smaller than 20
/// units across is not culled by a plane fitted to rooms and streets.
pub fn near_z(centres: &[Vec3]) -> f32 {
    let (lo, hi) = centres.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let extent = (hi - lo).max_element();
    match extent.is_finite() && extent > 0.0 {
        true => REFERENCE_NEAR_Z.min(0.01 * extent),
        false => REFERENCE_NEAR_Z,
    }
}

/// Gaussian `g` of `scene` seen from the point `lens` of `camera`'s lens
/// (eye-space x and y, scene units; |lens| ≤ R) through the projection
/// sheared so that the focus plane stays in place: eye point e is drawn
/// where the pinhole draws (e.x − l.x + l.x·e.z/S, e.y − l.y + l.y·e.z/S,
/// e.z), an affine map applied to the Gaussian's centre and covariance
/// alike (so defocus enlarges it), its colour seen from the lens point.
/// None where culled: its centre at an eye depth of at most `near_z`.
pub fn project_through(
    scene: &GaussianScene,
    g: usize,
    camera: &Camera,
    lens: Vec2,
    near_z: f32,
) -> Option<Splat2d> {
    let eye_from_world = camera.eye_from_world_transform();
    let p = scene.positions[g];
    let e0 = eye_from_world.apply(p);
    if e0.z <= near_z || e0.z.is_nan() {
        return None;
    }
    let s = camera.focus_distance;
    let shear = Mat3::from_cols(Vec3::X, Vec3::Y, Vec3::new(lens.x / s, lens.y / s, 1.0));
    let e = shear * e0 - lens.extend(0.0);
    let sigma = covariance(scene, g);
    // W: the world → eye rotation (rows right, up, forward), then the
    // shear.
    let (right, up, forward) = camera.basis();
    let w = shear * Mat3::from_cols(right, up, forward).transpose();
    // The Jacobian of (W/2 + f x/z, H/2 − f y/z), at the centre with x/z and
    // y/z clamped as the reference clamps them.
    let f = camera.f_px();
    let tan_x = camera.width as f32 / (2.0 * f);
    let tan_y = camera.height as f32 / (2.0 * f);
    let (lim_x, lim_y) = (1.3 * tan_x, 1.3 * tan_y);
    let tx = (e.x / e.z).clamp(-lim_x, lim_x) * e.z;
    let ty = (e.y / e.z).clamp(-lim_y, lim_y) * e.z;
    let z = e.z;
    // Rows of J as columns of its transpose (glam is column-major).
    let jt = Mat3::from_cols(
        Vec3::new(f / z, 0.0, -f * tx / (z * z)),
        Vec3::new(0.0, -f / z, f * ty / (z * z)),
        Vec3::ZERO,
    );
    let t = jt.transpose() * w;
    let cov = t * sigma * t.transpose();
    let (a, b, c) = (cov.x_axis.x + 0.3, cov.y_axis.x, cov.y_axis.y + 0.3);
    let det = a * c - b * b;
    // Also culled: a covariance beyond floats (as the device culls it).
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let conic = Vec3::new(c / det, -b / det, a / det);
    let mid = 0.5 * (a + c);
    let lambda1 = mid + (mid * mid - det).max(0.1).sqrt();
    let lambda2 = mid - (mid * mid - det).max(0.1).sqrt();
    let radius = (3.0 * lambda1.max(lambda2).sqrt()).ceil();
    if !radius.is_finite() {
        return None;
    }
    // The tiles are taken from the radius as a float, clamped to the
    // image (as on the device); the reference's int is this below 2^31.
    let radius_px = radius.min(i32::MAX as f32) as i32;
    let centre_px = camera.pixel_of_eye(e);
    // The reference's pixel coordinates put pixel centres at integers.
    let at = centre_px - Vec2::splat(0.5);
    let grid = (
        (camera.width as i32 + TILE_PX - 1) / TILE_PX,
        (camera.height as i32 + TILE_PX - 1) / TILE_PX,
    );
    let lo = |v: f32, n: i32| ((v - radius) / TILE_PX as f32).max(0.0).min(n as f32) as i32;
    let hi = |v: f32, n: i32| {
        ((v + radius + TILE_PX as f32 - 1.0) / TILE_PX as f32)
            .max(0.0)
            .min(n as f32) as i32
    };
    let tiles = [
        lo(at.x, grid.0),
        hi(at.x, grid.0),
        lo(at.y, grid.1),
        hi(at.y, grid.1),
    ];
    if (tiles[1] - tiles[0]) * (tiles[3] - tiles[2]) == 0 {
        return None;
    }
    let lens_world = camera.eye + right * lens.x + up * lens.y;
    let direction = (p - lens_world).normalize();
    Some(Splat2d {
        centre_px,
        depth: e.z,
        conic,
        radius_px,
        tiles,
        color: sh_color(scene.sh_of(g), scene.sh_degree, direction),
        opacity: scene.opacities[g],
    })
}

/// The pinhole image of `scene` through `camera` over `background` (an
/// sRGB-encoded colour, composited as the scene was trained): RGB rows
/// from the top, as composited (sRGB-encoded values).
pub fn render_reference(scene: &GaussianScene, camera: &Camera, background: Vec3) -> Vec<Vec3> {
    render_through(scene, camera, background, Vec2::ZERO, Vec2::ZERO)
}

/// The thin-lens image of `scene` through `camera` (`accum`'s reference):
/// the mean, in linear light, of the images seen from the lens points
/// `R · u` for each `u` of `lens_samples` (points of the unit disk),
/// each image's composited values decoded from sRGB first (the scene was
/// trained on encoded values; averaging those instead moves a blurred
/// image far from the physical one), over the encoded `background`; each
/// lens point at the K × K sub-pixel positions of `ssaa` (the cell
/// centres of [`ssaa_jitter`]; 1: the pixel centre). Linear-light RGB rows
/// from the top.
pub fn render_reference_lens(
    scene: &GaussianScene,
    camera: &Camera,
    background: Vec3,
    lens_samples: &[Vec2],
    ssaa: u32,
) -> Vec<Vec3> {
    let decode = |c: Vec3| {
        Vec3::new(
            crate::image_io::srgb_to_linear(c.x),
            crate::image_io::srgb_to_linear(c.y),
            crate::image_io::srgb_to_linear(c.z),
        )
    };
    let mut sum = vec![Vec3::ZERO; (camera.width * camera.height) as usize];
    for &u in lens_samples {
        for k in 0..ssaa * ssaa {
            let jitter = ssaa_jitter(k, ssaa);
            let image = render_through(
                scene,
                camera,
                background,
                camera.aperture_radius * u,
                jitter,
            );
            for (s, c) in sum.iter_mut().zip(image) {
                *s += decode(c);
            }
        }
    }
    let n = (lens_samples.len() as u32 * ssaa * ssaa).max(1) as f32;
    sum.iter().map(|s| *s / n).collect()
}

/// The image from the lens point `lens` ([`project_through`]), each pixel
/// sampled at its centre + `jitter` (px).
fn render_through(
    scene: &GaussianScene,
    camera: &Camera,
    background: Vec3,
    lens: Vec2,
    jitter: Vec2,
) -> Vec<Vec3> {
    let near = near_z(&scene.positions);
    let mut splats: Vec<(usize, Splat2d)> = (0..scene.len())
        .filter_map(|g| project_through(scene, g, camera, lens, near).map(|s| (g, s)))
        .collect();
    // Front to back; equal depths in the scene's order.
    splats.sort_by(|a, b| a.1.depth.total_cmp(&b.1.depth).then(a.0.cmp(&b.0)));
    let (w, h) = (camera.width as i32, camera.height as i32);
    let mut image = vec![Vec3::ZERO; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let tile = (x / TILE_PX, y / TILE_PX);
            let pixel = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) + jitter;
            let mut t = 1.0f32;
            let mut color = Vec3::ZERO;
            for (_, s) in &splats {
                if tile.0 < s.tiles[0]
                    || tile.0 >= s.tiles[1]
                    || tile.1 < s.tiles[2]
                    || tile.1 >= s.tiles[3]
                {
                    continue;
                }
                let d = s.centre_px - pixel;
                let power =
                    -0.5 * (s.conic.x * d.x * d.x + s.conic.z * d.y * d.y) - s.conic.y * d.x * d.y;
                if power > 0.0 {
                    continue;
                }
                let alpha = (s.opacity * power.exp()).min(0.99);
                if alpha < 1.0 / 255.0 {
                    continue;
                }
                let next = t * (1.0 - alpha);
                if next < 1e-4 {
                    break;
                }
                color += s.color * alpha * t;
                t = next;
            }
            image[(y * w + x) as usize] = color + t * background;
        }
    }
    image
}
