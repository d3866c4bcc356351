//! The aperture's shape (docs/decisions/aperture-shape.md): the one
//! definition of the lens's transmission T(u) over the normalised lens
//! position u (pixel axes, |u| ≤ 1) and of the cat's eye C(u; p), the
//! stratified lens samples that follow T (the accumulation reference), and
//! the camera flags and camera-file fields that set it. `glsl/aperture.glsl`
//! mirrors [`Aperture::transmission`]; tests/aperture.rs checks that both
//! sides agree and that a far highlight images to the shape.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use glam::{DVec2, Vec2};
use serde::{Deserialize, Serialize};

use super::file::camera_error;
use super::tables::{concentric_disk, lens_samples, rdb_lens_table, square_cell};
use crate::error::{Error, Result};
use crate::options::MethodKind;

/// The most blades of a shaped aperture (Blender's range, 3–16).
pub const MAX_BLADES: u32 = 16;

/// The aperture fields of a camera file and their flags (every field
/// optional; absent: a round aperture). Flattened into
/// [`super::CameraSpec`] and into `render`'s flags.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct ApertureSpec {
    /// Aperture blades: 0 = round (the default), 3 to 16 = a regular
    /// polygon inscribed in the lens's circle, a corner at the top.
    #[arg(long, value_name = "N")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aperture_blades: Option<u32>,
    /// The aperture's rotation, degrees counter-clockwise on screen (of
    /// the blades or the aperture image).
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aperture_rotation_deg: Option<f32>,
    /// Blade curvature, 0 (straight blades, the default) to 1 (round).
    #[arg(long, value_name = "C")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blade_curvature: Option<f32>,
    /// Anamorphic ratio: the aperture's height over its width (default 1;
    /// Blender's aperture_ratio). The longer axis keeps the lens radius.
    #[arg(long, value_name = "R")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anamorphic_ratio: Option<f32>,
    /// An aperture image: a grayscale PNG (8 or 16 bits) or a grey EXR,
    /// the lens's transmission over the square around its circle (row 0
    /// at the top). In a camera file, relative to the file's directory.
    #[arg(long, value_name = "FILE")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aperture_image: Option<PathBuf>,
    /// Cat's-eye vignetting, 0 (off, the default) to 1 (at the frame's
    /// corner the lens is seen through two touching circles).
    #[arg(long, value_name = "S")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cat_eye: Option<f32>,
}

impl ApertureSpec {
    /// This spec with every field set in `flags` replaced by the flag's.
    pub fn overridden_by(self, flags: &ApertureSpec) -> ApertureSpec {
        ApertureSpec {
            aperture_blades: flags.aperture_blades.or(self.aperture_blades),
            aperture_rotation_deg: flags.aperture_rotation_deg.or(self.aperture_rotation_deg),
            blade_curvature: flags.blade_curvature.or(self.blade_curvature),
            anamorphic_ratio: flags.anamorphic_ratio.or(self.anamorphic_ratio),
            aperture_image: flags.aperture_image.clone().or(self.aperture_image),
            cat_eye: flags.cat_eye.or(self.cat_eye),
        }
    }

    /// A relative `aperture_image` taken as relative to `dir` (a camera
    /// file's directory).
    pub fn relative_to(mut self, dir: &Path) -> ApertureSpec {
        if let Some(p) = &self.aperture_image {
            if p.is_relative() {
                self.aperture_image = Some(dir.join(p));
            }
        }
        self
    }

    /// Checks every value present on its own and together (one line
    /// naming the field).
    pub fn validate(&self) -> Result<()> {
        if let Some(n) = self.aperture_blades {
            if n != 0 && !(3..=MAX_BLADES).contains(&n) {
                return Err(camera_error(
                    "aperture_blades",
                    format!("must be 0 (round) or 3 to {MAX_BLADES}, got {n}"),
                ));
            }
        }
        let blades = self.aperture_blades.unwrap_or(0) > 0;
        if let Some(d) = self.aperture_rotation_deg {
            if !d.is_finite() {
                return Err(camera_error(
                    "aperture_rotation_deg",
                    format!("must be a finite number of degrees, got {d}"),
                ));
            }
            if !blades && self.aperture_image.is_none() {
                return Err(camera_error(
                    "aperture_rotation_deg",
                    "turns the blades or the aperture image: give aperture_blades (3 to 16) or aperture_image (a round aperture has no rotation)",
                ));
            }
        }
        if let Some(c) = self.blade_curvature {
            if !(0.0..=1.0).contains(&c) {
                return Err(camera_error(
                    "blade_curvature",
                    format!("must be between 0 (straight) and 1 (round), got {c}"),
                ));
            }
            if !blades {
                return Err(camera_error(
                    "blade_curvature",
                    "bends the blades: give aperture_blades (3 to 16)",
                ));
            }
        }
        if let Some(r) = self.anamorphic_ratio {
            if !(r.is_finite() && r > 0.0) {
                return Err(camera_error(
                    "anamorphic_ratio",
                    format!("must be a finite number > 0, got {r}"),
                ));
            }
        }
        if let Some(s) = self.cat_eye {
            if !(0.0..=1.0).contains(&s) {
                return Err(camera_error(
                    "cat_eye",
                    format!("must be between 0 (off) and 1, got {s}"),
                ));
            }
        }
        if blades && self.aperture_image.is_some() {
            return Err(camera_error(
                "aperture_image",
                "the image is the aperture's whole shape: give aperture_blades or aperture_image, not both",
            ));
        }
        Ok(())
    }

    /// The aperture it describes, reading the aperture image.
    pub fn resolve(&self) -> Result<Aperture> {
        self.validate()?;
        let image = match &self.aperture_image {
            Some(path) => Some(ApertureImage::read(path)?.intern()),
            None => None,
        };
        Ok(Aperture {
            blades: self.aperture_blades.unwrap_or(0),
            rotation_deg: self.aperture_rotation_deg.unwrap_or(0.0),
            curvature: self.blade_curvature.unwrap_or(0.0),
            ratio: self.anamorphic_ratio.unwrap_or(1.0),
            cat_eye: self.cat_eye.unwrap_or(0.0),
            image,
        })
    }
}

/// A part of the aperture's shape and the methods that render it: the one
/// table [`Aperture::check_method`] refuses by.
pub struct ApertureFeature {
    /// The camera-file field (the flag is `--` and the field with `-`).
    pub field: &'static str,
    /// Whether the aperture uses it.
    pub used: fn(&Aperture) -> bool,
    /// The methods that follow it on a point cloud.
    pub kinds: &'static [MethodKind],
    /// The methods that follow it on a scene of 3D Gaussians.
    pub gaussian_kinds: &'static [MethodKind],
}

/// Every part of the shape, the methods that follow it.
pub const APERTURE_FEATURES: &[ApertureFeature] = &[
    ApertureFeature {
        field: "aperture_image",
        used: |a| a.image.is_some(),
        kinds: &[MethodKind::Accum, MethodKind::Rdb, MethodKind::Layered],
        gaussian_kinds: &[MethodKind::Accum, MethodKind::Layered],
    },
    ApertureFeature {
        field: "aperture_blades",
        used: |a| a.blades != 0,
        kinds: &[
            MethodKind::Accum,
            MethodKind::Layered,
            MethodKind::Rdb,
            MethodKind::Fast,
        ],
        gaussian_kinds: &[MethodKind::Accum, MethodKind::Layered],
    },
    ApertureFeature {
        field: "anamorphic_ratio",
        used: |a| a.ratio != 1.0,
        kinds: &[
            MethodKind::Accum,
            MethodKind::Layered,
            MethodKind::Rdb,
            MethodKind::Fast,
        ],
        gaussian_kinds: &[MethodKind::Accum, MethodKind::Layered],
    },
    ApertureFeature {
        field: "cat_eye",
        used: |a| a.cat_eye > 0.0,
        kinds: &[MethodKind::Accum, MethodKind::Layered, MethodKind::Rdb],
        gaussian_kinds: &[MethodKind::Accum, MethodKind::Layered],
    },
];

/// An aperture image: linear transmission in [0, 1], row-major, row 0 at
/// the top, over the square [−1, 1]² of the lens's circle. Made by
/// [`ApertureImage::new`], which finds each pixel's share of the circle
/// once (the lens samples of every frame weigh the pixels by it).
#[derive(Clone, PartialEq)]
pub struct ApertureImage {
    /// The file it was read from (for the camera file written back).
    pub path: PathBuf,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Transmission per pixel.
    pub transmission: Vec<f32>,
    /// Per pixel, the share of it inside the lens's circle (of 8×8 points).
    in_circle: Vec<f64>,
}

impl std::fmt::Debug for ApertureImage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "ApertureImage({}, {}x{})",
            self.path.display(),
            self.width,
            self.height
        )
    }
}

/// The aperture images of this process, each kept once for the process's
/// life so that [`Aperture`] stays `Copy` (a handful of small images at
/// most: one per distinct file a process renders with).
static IMAGES: Mutex<Vec<&'static ApertureImage>> = Mutex::new(Vec::new());

/// The largest aperture image side, pixels (a transmission table, not a
/// photograph: 4096 resolves far below any CoC).
pub const MAX_APERTURE_IMAGE_SIDE: u32 = 4096;

impl ApertureImage {
    /// Reads a grayscale PNG (8 or 16 bits, no alpha) or an EXR whose
    /// pixels are grey (R = G = B); errors in one line naming the file.
    pub fn read(path: &Path) -> Result<ApertureImage> {
        let bad =
            |msg: String| camera_error("aperture_image", format!("{}: {msg}", path.display()));
        let bytes = std::fs::read(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let img = image::load_from_memory(&bytes)
            .map_err(|e| bad(format!("cannot be read as PNG or EXR ({e})")))?;
        let (width, height) = (img.width(), img.height());
        if width == 0 || height == 0 {
            return Err(bad("is empty".into()));
        }
        if width.max(height) > MAX_APERTURE_IMAGE_SIDE {
            return Err(bad(format!(
                "is {width}x{height}, larger than {MAX_APERTURE_IMAGE_SIDE} pixels on a side"
            )));
        }
        let transmission: Vec<f32> = match img {
            image::DynamicImage::ImageLuma8(g) => {
                g.pixels().map(|p| f32::from(p.0[0]) / 255.0).collect()
            }
            image::DynamicImage::ImageLuma16(g) => {
                g.pixels().map(|p| f32::from(p.0[0]) / 65535.0).collect()
            }
            image::DynamicImage::ImageRgb32F(_) | image::DynamicImage::ImageRgba32F(_) => {
                let rgba = img.to_rgba32f();
                let mut out = Vec::with_capacity(rgba.len() / 4);
                for p in rgba.pixels() {
                    let [r, g, b, _] = p.0;
                    if r != g || g != b {
                        return Err(bad(format!(
                            "is not grey (a pixel has R, G, B = {r}, {g}, {b}); an aperture image is one transmission per pixel"
                        )));
                    }
                    if r.is_nan() {
                        return Err(bad("has a NaN pixel".into()));
                    }
                    out.push(r.clamp(0.0, 1.0));
                }
                out
            }
            other => {
                return Err(bad(format!(
                    "is {:?}, not a grayscale image without alpha (an aperture image is one transmission per pixel)",
                    other.color()
                )))
            }
        };
        let image = ApertureImage::new(path.to_path_buf(), width, height, transmission);
        if image.mean_in_circle() <= 0.0 {
            return Err(bad("lets no light through the lens's circle".into()));
        }
        Ok(image)
    }

    /// This image, kept for the process's life (one copy per distinct
    /// image).
    pub fn intern(self) -> &'static ApertureImage {
        let mut images = IMAGES.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(found) = images.iter().find(|i| ***i == self) {
            return found;
        }
        let kept: &'static ApertureImage = Box::leak(Box::new(self));
        images.push(kept);
        kept
    }

    /// The pixel holding base point w ∈ [−1, 1]² (clamped to the image).
    pub fn pixel_of(&self, w: Vec2) -> (u32, u32) {
        (square_cell(w.x, self.width), square_cell(w.y, self.height))
    }

    /// The transmission at base point w (no circle test).
    pub fn at(&self, w: Vec2) -> f32 {
        let (i, j) = self.pixel_of(w);
        self.transmission[(j * self.width + i) as usize]
    }

    /// The mean transmission over the lens's circle (8×8 points per pixel).
    pub fn mean_in_circle(&self) -> f64 {
        let (sum, area) = self
            .weights_in_circle()
            .fold((0.0, 0.0), |(s, a), (t, f)| (s + t * f, a + f));
        if area > 0.0 {
            sum / area
        } else {
            0.0
        }
    }

    /// Per pixel, (transmission, share of the pixel inside the circle).
    fn weights_in_circle(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.transmission
            .iter()
            .zip(&self.in_circle)
            .map(|(&t, &f)| (f64::from(t), f))
    }
}

impl ApertureImage {
    /// An image of `transmission` (row-major, `width` × `height`, each in
    /// [0, 1]) read from `path`, with each pixel's share of the lens's
    /// circle: the share of 8×8 points of it inside, found without the
    /// points where the pixel lies wholly inside or outside.
    pub fn new(path: PathBuf, width: u32, height: u32, transmission: Vec<f32>) -> ApertureImage {
        assert_eq!(
            transmission.len() as u64,
            u64::from(width) * u64::from(height),
            "one transmission per pixel"
        );
        let (w, h) = (f64::from(width), f64::from(height));
        let in_circle = (0..height)
            .flat_map(|j| (0..width).map(move |i| (i, j)))
            .map(|(i, j)| {
                let (x0, x1) = (
                    -1.0 + 2.0 * f64::from(i) / w,
                    -1.0 + 2.0 * f64::from(i + 1) / w,
                );
                let (y0, y1) = (
                    -1.0 + 2.0 * f64::from(j) / h,
                    -1.0 + 2.0 * f64::from(j + 1) / h,
                );
                let far = |a: f64, b: f64| a.abs().max(b.abs());
                let near = |a: f64, b: f64| {
                    if a <= 0.0 && b >= 0.0 {
                        0.0
                    } else {
                        a.abs().min(b.abs())
                    }
                };
                // A margin keeps the rim's pixels with the points, whose
                // coordinates round.
                if far(x0, x1).powi(2) + far(y0, y1).powi(2) < 1.0 - 1e-9 {
                    return 1.0;
                }
                if near(x0, x1).powi(2) + near(y0, y1).powi(2) > 1.0 + 1e-9 {
                    return 0.0;
                }
                let mut inside = 0;
                for sy in 0..8 {
                    for sx in 0..8 {
                        let x = -1.0 + 2.0 * (f64::from(i) + (f64::from(sx) + 0.5) / 8.0) / w;
                        let y = -1.0 + 2.0 * (f64::from(j) + (f64::from(sy) + 0.5) / 8.0) / h;
                        inside += u32::from(x * x + y * y <= 1.0);
                    }
                }
                f64::from(inside) / 64.0
            })
            .collect();
        ApertureImage {
            path,
            width,
            height,
            transmission,
            in_circle,
        }
    }
}

/// The aperture's shape (docs/decisions/aperture-shape.md). `Copy`: an
/// aperture image is held by reference (see [`ApertureImage::intern`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aperture {
    /// 0 = round, 3 to [`MAX_BLADES`] = a regular polygon.
    pub blades: u32,
    /// Rotation, degrees counter-clockwise on screen.
    pub rotation_deg: f32,
    /// Blade curvature C ∈ [0, 1].
    pub curvature: f32,
    /// Anamorphic ratio A > 0: height over width.
    pub ratio: f32,
    /// Cat's eye S ∈ [0, 1] (0: off).
    pub cat_eye: f32,
    /// The aperture image, if the shape is one.
    pub image: Option<&'static ApertureImage>,
}

impl Default for Aperture {
    fn default() -> Self {
        Aperture::ROUND
    }
}

impl Aperture {
    /// The round aperture of DESIGN §2.
    pub const ROUND: Aperture = Aperture {
        blades: 0,
        rotation_deg: 0.0,
        curvature: 0.0,
        ratio: 1.0,
        cat_eye: 0.0,
        image: None,
    };

    /// Whether this is the round aperture (every method's images as
    /// without a shape, byte for byte).
    pub fn is_round(&self) -> bool {
        *self == Aperture::ROUND
    }

    /// Whether T(u) differs from the round aperture's (blades, squeeze or
    /// image; the cat's eye apart).
    pub fn is_shaped(&self) -> bool {
        Aperture {
            cat_eye: 0.0,
            ..*self
        } != Aperture::ROUND
    }

    /// Refuses, in one line, a shape the method does not render (on a
    /// scene of 3D Gaussians when `gaussians`): [`APERTURE_FEATURES`].
    pub fn check_method(&self, method: MethodKind, gaussians: bool) -> Result<()> {
        for f in APERTURE_FEATURES.iter().filter(|f| (f.used)(self)) {
            let kinds = if gaussians { f.gaussian_kinds } else { f.kinds };
            if !kinds.contains(&method) {
                let names: Vec<&str> = kinds.iter().map(|k| k.name()).collect();
                let scene = if gaussians { " on 3D Gaussians" } else { "" };
                return Err(Error::InvalidArgument(format!(
                    "--{} ({}) is rendered by --method {} only{scene}, not {}",
                    f.field.replace('_', "-"),
                    f.field,
                    names.join(" or "),
                    method.name()
                )));
            }
        }
        Ok(())
    }

    /// The camera-file fields of this aperture: only those that differ
    /// from the round aperture's (a round camera file prints as before).
    pub fn to_spec(&self) -> ApertureSpec {
        let set = |v: f32, default: f32| (v != default).then_some(v);
        ApertureSpec {
            aperture_blades: (self.blades != 0).then_some(self.blades),
            aperture_rotation_deg: set(self.rotation_deg, 0.0),
            blade_curvature: set(self.curvature, 0.0),
            anamorphic_ratio: set(self.ratio, 1.0),
            aperture_image: self.image.map(|i| i.path.clone()),
            cat_eye: set(self.cat_eye, 0.0),
        }
    }

    /// The base point w of lens position u: the squeeze undone, then the
    /// rotation (step 1 and 2 of the definition).
    pub fn base_of(&self, u: Vec2) -> Vec2 {
        let s = if self.ratio >= 1.0 {
            Vec2::new(self.ratio * u.x, u.y)
        } else {
            Vec2::new(u.x, u.y / self.ratio)
        };
        let (sin, cos) = self.rotation_deg.to_radians().sin_cos();
        Vec2::new(cos * s.x - sin * s.y, sin * s.x + cos * s.y)
    }

    /// The lens position u of base point w (the inverse of
    /// [`Aperture::base_of`]).
    pub fn lens_of(&self, w: Vec2) -> Vec2 {
        let (sin, cos) = self.rotation_deg.to_radians().sin_cos();
        let s = Vec2::new(cos * w.x + sin * w.y, -sin * w.x + cos * w.y);
        if self.ratio >= 1.0 {
            Vec2::new(s.x / self.ratio, s.y)
        } else {
            Vec2::new(s.x, s.y * self.ratio)
        }
    }

    /// [`Aperture::base_of`] as a matrix M, row by row (m00, m01, m10,
    /// m11): w = M·u, the squeeze undone, then the turn (to float
    /// rounding; tested). For `fast`'s tap test in GLSL.
    pub fn base_from_lens(&self) -> [f32; 4] {
        let (sx, sy) = if self.ratio >= 1.0 {
            (self.ratio, 1.0)
        } else {
            (1.0, 1.0 / self.ratio)
        };
        let (sin, cos) = self.rotation_deg.to_radians().sin_cos();
        [cos * sx, -sin * sy, sin * sx, cos * sy]
    }

    /// Whether lens position u passes a shape of blades, curvature,
    /// squeeze and turn (not an image; the cat's eye apart): T(u) > 0 of
    /// [`Aperture::transmission`] written without angles, as the tap test
    /// of `fast`'s gathers makes it in pixels ([`Aperture::reaches`]).
    /// With w = M·u, |w| ≤ 1 and, with
    /// blades, |w| ≤ ρ(φ): as m = max over the blades' middle directions
    /// d_k of w·d_k is |w|·cos δ, that is m·(|w| − C) ≤ (1 − C)·cos(π/N)·|w|.
    pub fn blades_pass(&self, u: Vec2) -> bool {
        let w = self.base_by_matrix(u);
        let r2 = w.length_squared();
        if self.blades == 0 || r2 > 1.0 {
            return r2 <= 1.0;
        }
        let most = (0..self.blades)
            .map(|k| w.dot(self.blade_middle(k)))
            .fold(-1.0f32, f32::max);
        let r = r2.sqrt();
        let c = self.curvature;
        most * (r - c) <= (1.0 - c) * self.blade_cos() * r
    }

    /// Whether a pixel at offset v from Q (pixels), of CoC diameter 2·`h`
    /// pixels, behind the focus (`behind`) or in front, reaches Q through
    /// the shape: [`Aperture::blades_pass`] of u = −v/(s·h), s = ±1 the
    /// side, in v's pixels without a division, as `fast`'s gathers test
    /// their taps (`glsl/fast_gather.glsl`, `shape_reaches`, mirrors it).
    /// With R = |M·v| = h·|w| and m = max_k −s·(v·M'd_k) = h·max_k w·d_k,
    /// the blades' test times h² is m·(R − C·h) ≤ (1 − C)·cos(π/N)·R·h; an
    /// even count's blades come in opposite pairs, so m is the largest
    /// |v·M'd_k| of the first half and the side does not matter.
    ///
    /// Straight blades ([`Aperture::has_straight_blades`]) are the test
    /// m ≤ cos(π/N)·h alone: their polygon lies within the circle |w| ≤
    /// 1, and |v| ≤ |M·v| (M turns and stretches, never shrinks).
    pub fn reaches(&self, v: Vec2, h: f32, behind: bool) -> bool {
        if h <= 0.0 {
            return v == Vec2::ZERO;
        }
        let straight = self.has_straight_blades();
        if !straight && v.length_squared() > h * h {
            return false;
        }
        let r2 = self.base_by_matrix(v).length_squared();
        if self.blades == 0 {
            return r2 <= h * h;
        }
        let most = self.blades_most(v, behind);
        if straight {
            return most <= self.blade_cos() * h;
        }
        let r = r2.sqrt();
        let c = self.curvature;
        r2 <= h * h && most * (r - c * h) <= (1.0 - c) * self.blade_cos() * r * h
    }

    /// m of [`Aperture::reaches`]: the largest s·(v·n_k) over the blades'
    /// normals (s = −1 behind the focus), at least 0; an even count's
    /// blades come in opposite pairs, so the largest |v·n_k| of the first
    /// half, whatever the side.
    fn blades_most(&self, v: Vec2, behind: bool) -> f32 {
        let normal = |k: u32| self.blade_normal(k);
        if self.blades.is_multiple_of(2) {
            return (0..self.blades / 2)
                .map(|k| v.dot(normal(k)).abs())
                .fold(0.0f32, f32::max);
        }
        let s = if behind { -1.0 } else { 1.0 };
        (0..self.blades)
            .map(|k| s * v.dot(normal(k)))
            .fold(0.0f32, f32::max)
    }

    /// The least half-CoC h (pixels) at which a pixel at offset v reaches
    /// Q through the shape ([`Aperture::reaches`] from behind the focus;
    /// the lattice of offsets is symmetric, so the count on either side is
    /// the same): the shape grows with h, so v reaches from here on. The
    /// squeezed circle's |M·v|; straight blades' m/cos(π/N); curved
    /// blades', where m·(R − C·h) ≤ (1 − C)·cos(π/N)·R·h begins,
    /// m·R/(C·m + (1 − C)·cos(π/N)·R), past |v| and R = |M·v|.
    pub fn reach_threshold(&self, v: Vec2) -> f32 {
        let r = self.base_by_matrix(v).length();
        if self.blades == 0 {
            return r.max(v.length());
        }
        let most = self.blades_most(v, true);
        if self.has_straight_blades() {
            return most / self.blade_cos();
        }
        let c = self.curvature;
        let curved = match most * r {
            0.0 => 0.0,
            mr => mr / (c * most + (1.0 - c) * self.blade_cos() * r),
        };
        curved.max(r).max(v.length())
    }

    /// The reach thresholds ([`Aperture::reach_threshold`]) of every pixel
    /// offset at or below half-CoC `max_h`, ascending: the count of pixels a
    /// point of half-CoC h ≤ max_h spreads over is how many lie at or
    /// below h (`fast_coc.comp` searches them; its gathers' taps take the
    /// same test).
    pub fn tap_thresholds(&self, max_h: f32) -> Vec<f32> {
        let m = max_h.max(0.0).ceil() as i32 + 1;
        let mut thresholds: Vec<f32> = (-m..=m)
            .flat_map(|dy| (-m..=m).map(move |dx| Vec2::new(dx as f32, dy as f32)))
            .map(|v| self.reach_threshold(v))
            .filter(|&t| t <= max_h)
            .collect();
        thresholds.sort_by(f32::total_cmp);
        thresholds
    }

    /// The least distance from the lens centre to the edge of the shape,
    /// in lens radii (blades, curvature, squeeze, turn; the cat's eye
    /// apart: [`Aperture::cat_eye_blur_reach`]; None: an aperture image,
    /// which may pass less anywhere): a blade's middle lies
    /// (1 − C)·cos(π/N) + C ≥ cos(π/N) out, and the squeeze narrows the
    /// shape by its ratio. The shape holds the disk of this radius, so a
    /// point's blur through it spans at least this part of its CoC
    /// across, in every direction.
    pub fn least_reach(&self) -> Option<f32> {
        if self.image.is_some() {
            return None;
        }
        let squeeze = self.ratio.max(1.0 / self.ratio);
        Some(self.blade_cos() / squeeze)
    }

    /// The least part of its CoC across which a lens holding the disk of
    /// radius `shape_reach` ([`Aperture::least_reach`]), clipped by the
    /// cat's eye S = `cat_eye` whose circle is centred at `centre`
    /// ([`Aperture::cat_eye_centre`] of the point's pixel, −2S·d;
    /// `half_diag` = |frame/2| px), blurs a point whose CoC runs over the
    /// range of `coc`'s two ends (px) on one side of the focus (`behind`:
    /// beyond it); 0 where it may not blur at all. Mirrored by
    /// `cat_eye_blur_reach` in `glsl/aperture.glsl`.
    ///
    /// The pixels the point reaches see, in its lens positions, one circle
    /// (`cat_circle` of `glsl/layered_spread.comp`): radius t = 1/|k| about
    /// a centre δ·t from the lens's, δ = |centre| = 2S·|d|, k = 1 ± S·CoC/|frame/2|
    /// (+ behind the focus). Its meet with the disk of radius a is at
    /// least min(2a, 2t, a + t − δt) across (along the line of the
    /// centres), so the blur spans min(a, t, (a + (1 − δ)·t)/2) of the
    /// CoC; each term is monotonic in t, which is monotonic in the CoC
    /// where k keeps its sign, so the least over the range is at an end.
    pub fn cat_eye_blur_reach(
        shape_reach: f32,
        cat_eye: f32,
        centre: Vec2,
        half_diag: f32,
        coc: Vec2,
        behind: bool,
    ) -> f32 {
        let delta = centre.length();
        let s = if behind { cat_eye } else { -cat_eye };
        let k = Vec2::ONE + s * coc / half_diag;
        if k.x * k.y <= 0.0 {
            // The circle of some CoC in the range passes through infinity.
            return 0.0;
        }
        let t = Vec2::ONE / k.abs();
        let edge = 0.5 * (Vec2::splat(shape_reach) + (1.0 - delta) * t);
        shape_reach
            .min(t.min_element())
            .min(edge.min_element())
            .max(0.0)
    }

    /// Whether the shape is a polygon of straight blades (N ≥ 3, C = 0).
    pub fn has_straight_blades(&self) -> bool {
        self.blades > 0 && self.curvature == 0.0
    }

    /// The columns [x0, x1] of row `dy` of a gather's window (offsets from
    /// Q) outside which no tap of a CoC diameter up to 2·`t` pixels
    /// reaches Q, on either side of the focus ([`Aperture::reaches`]; for
    /// the round aperture the disk's test): x0 > x1 where none does.
    /// `fast`'s gathers clip their rows to it (`row_span` of
    /// `glsl/fast_gather.glsl` mirrors it). Each bound is a convex set that
    /// holds the lens centre and grows with h, so the span of t holds the
    /// taps of every h ≤ t: the disk |v| ≤ t; for a shape, the ellipse
    /// |M·v| ≤ t and, with blades, every blade's half-plane s·(v·M'd_k) ≤
    /// ((1 − C)·cos(π/N) + C)·t on side s (a curved blade bulges past its
    /// line by at most C); an even count's blades pair into slabs, and an
    /// odd count's two sides (the shape and its turn by π) are joined. The
    /// scale is widened by a thousandth of t and of a pixel, far beyond the
    /// tests' rounding, so that no rounding leaves out a tap that passes.
    pub fn row_span(&self, dy: i32, t: f32) -> (i32, i32) {
        const EMPTY: (i32, i32) = (1, 0);
        let t = 1.001 * t + 0.001;
        let y = dy as f32;
        let room = t * t - y * y;
        if room < 0.0 {
            return EMPTY;
        }
        let (mut lo, mut hi) = (-room.sqrt(), room.sqrt());
        if self.is_shaped() {
            // |M·v|² = a·x² + b·x + c over the row: ≤ t² between the roots.
            let m = self.base_from_lens();
            let a = m[0] * m[0] + m[2] * m[2];
            let b = 2.0 * (m[0] * m[1] + m[2] * m[3]) * y;
            let c = (m[1] * m[1] + m[3] * m[3]) * y * y - t * t;
            let disc = b * b - 4.0 * a * c;
            if disc < 0.0 {
                return EMPTY;
            }
            lo = lo.max((-b - disc.sqrt()) / (2.0 * a));
            hi = hi.min((-b + disc.sqrt()) / (2.0 * a));
        }
        if self.is_shaped() && self.blades > 0 {
            let reach = ((1.0 - self.curvature) * self.blade_cos() + self.curvature) * t;
            // x within s·(x·n.x + y·n.y) ≤ reach for every blade k listed.
            let side = |s: f32, blades: u32, (mut lo, mut hi): (f32, f32)| {
                for k in 0..blades {
                    let n = self.blade_normal(k) * s;
                    if n.x.abs() > 1e-4 {
                        let x = (reach - y * n.y) / n.x;
                        if n.x > 0.0 {
                            hi = hi.min(x);
                        } else {
                            lo = lo.max(x);
                        }
                    }
                }
                (lo, hi)
            };
            if self.blades.is_multiple_of(2) {
                // Blade k + N/2 faces −M'd_k: a slab for each of the first half.
                let plus = side(1.0, self.blades / 2, (lo, hi));
                (lo, hi) = side(-1.0, self.blades / 2, plus);
            } else {
                let (front, behind) = (
                    side(1.0, self.blades, (lo, hi)),
                    side(-1.0, self.blades, (lo, hi)),
                );
                (lo, hi) = match (front.0 <= front.1, behind.0 <= behind.1) {
                    (true, true) => (front.0.min(behind.0), front.1.max(behind.1)),
                    (true, false) => front,
                    (false, true) => behind,
                    (false, false) => return EMPTY,
                };
            }
        }
        if lo > hi {
            return EMPTY;
        }
        // Bounded before the conversion: a span wider than any window.
        let bound = 1.0e6;
        (lo.max(-bound).ceil() as i32, hi.min(bound).floor() as i32)
    }

    /// Blade k's middle direction turned back to lens positions, M'·d_k:
    /// u·(M'·d_k) = (M·u)·d_k (`blade_normals` of `glsl/fast_gather.glsl`).
    fn blade_normal(&self, k: u32) -> Vec2 {
        let (m, d) = (self.base_from_lens(), self.blade_middle(k));
        Vec2::new(m[0] * d.x + m[2] * d.y, m[1] * d.x + m[3] * d.y)
    }

    /// The bounding box of the lens positions the shape passes
    /// ([`Aperture::blades_pass`]), in lens units: [x min, x max, y min,
    /// y max]. Straight blades: their polygon's corners, which lie on the
    /// unit circle between the blades' middle directions. Curved blades
    /// and the squeezed circle: the ellipse |M·u| ≤ 1, which holds them
    /// (its half-extent along an axis is the norm of that row of M⁻¹).
    /// `fast`'s tree leaves a block of offsets outside it, scaled.
    pub fn lens_bounding_box(&self) -> [f32; 4] {
        if self.has_straight_blades() {
            let sector = std::f32::consts::TAU / self.blades as f32;
            return (0..self.blades)
                .map(|k| {
                    let phi = std::f32::consts::FRAC_PI_2 + k as f32 * sector;
                    self.lens_of(Vec2::new(phi.cos(), -phi.sin()))
                })
                .fold(
                    [
                        f32::INFINITY,
                        f32::NEG_INFINITY,
                        f32::INFINITY,
                        f32::NEG_INFINITY,
                    ],
                    |b, u| [b[0].min(u.x), b[1].max(u.x), b[2].min(u.y), b[3].max(u.y)],
                );
        }
        let (cx, cy) = (self.lens_of(Vec2::X), self.lens_of(Vec2::Y));
        let (half_x, half_y) = (
            Vec2::new(cx.x, cy.x).length(),
            Vec2::new(cx.y, cy.y).length(),
        );
        [-half_x, half_x, -half_y, half_y]
    }

    /// M·u of [`Aperture::base_from_lens`], as the GLSL tap test forms it.
    fn base_by_matrix(&self, u: Vec2) -> Vec2 {
        let m = self.base_from_lens();
        Vec2::new(m[0] * u.x + m[1] * u.y, m[2] * u.x + m[3] * u.y)
    }

    /// cos(π/N) of N blades: the blades' inner radius without curvature
    /// (1 without blades).
    pub fn blade_cos(&self) -> f32 {
        match self.blades {
            0 => 1.0,
            n => (std::f32::consts::PI / n as f32).cos(),
        }
    }

    /// The middle direction of blade k in the base shape: screen angle
    /// π/2 + (k + ½)·2π/N, where δ of [`Aperture::blade_radius`] is 0.
    pub fn blade_middle(&self, k: u32) -> Vec2 {
        let sector = std::f32::consts::TAU / self.blades as f32;
        let phi = std::f32::consts::FRAC_PI_2 + (k as f32 + 0.5) * sector;
        Vec2::new(phi.cos(), -phi.sin())
    }

    /// The blades' boundary radius ρ at screen angle φ (radians) of the
    /// base shape: (1 − C)·cos(π/N)/cos δ + C.
    pub fn blade_radius(&self, phi: f32) -> f32 {
        let n = self.blades as f32;
        let sector = std::f32::consts::TAU / n;
        let delta = (phi - std::f32::consts::FRAC_PI_2).rem_euclid(sector) - sector / 2.0;
        (1.0 - self.curvature) * self.blade_cos() / delta.cos() + self.curvature
    }

    /// The transmission T(u) ∈ [0, 1] at lens position u (pixel axes).
    pub fn transmission(&self, u: Vec2) -> f32 {
        let w = self.base_of(u);
        let r2 = w.length_squared();
        if r2 > 1.0 {
            return 0.0;
        }
        if let Some(image) = self.image {
            return image.at(w);
        }
        if self.blades == 0 {
            return 1.0;
        }
        let rho = self.blade_radius((-w.y).atan2(w.x));
        if r2 <= rho * rho {
            1.0
        } else {
            0.0
        }
    }

    /// The cat's eye's centre for the frame's pixel (x, y) of a
    /// `width` × `height` frame: −2S·d (the second circle's centre in lens
    /// positions).
    pub fn cat_eye_centre(&self, x: u32, y: u32, width: u32, height: u32) -> Vec2 {
        let half = Vec2::new(width as f32, height as f32) * 0.5;
        let d = (Vec2::new(x as f32 + 0.5, y as f32 + 0.5) - half) / half.length();
        -2.0 * self.cat_eye * d
    }

    /// C(u; p): whether lens position u passes the cat's eye of the pixel
    /// whose second circle is centred at `centre`.
    pub fn cat_eye_passes(u: Vec2, centre: Vec2) -> bool {
        (u - centre).length_squared() <= 1.0
    }

    /// The half-width of one of `count` equal cells of the lens's circle
    /// (area π/count): what a lens sample of `count` (accum) or a bin of
    /// N² (RDB) stands for.
    pub fn lens_cell_half_width(count: u32) -> f32 {
        0.886_227 / (count as f32).sqrt()
    }

    /// Whether RDB presses its bins' lens positions into each pixel's
    /// cat's eye ([`Aperture::cat_eye_lens`]): with the cat's eye on a
    /// round aperture (a shape's bins lie in the shape, which the pressed
    /// ellipse would not follow).
    pub fn presses_cat_eye_lens(&self) -> bool {
        self.cat_eye > 0.0 && self.is_unit_disk()
    }

    /// The lens position that lens position u of the unit disk stands for
    /// at a pixel whose cat's eye circle is centred at `centre`: the disk
    /// pressed into the ellipse that holds the two circles' meet, centred
    /// δ/2 along e = centre/δ, half-axes 1 − δ/2 along e and √(1 − δ²/4)
    /// across (`cat_eye_lens` of `glsl/aperture.glsl`); u itself where
    /// δ² ≤ 1e-30. The ellipse holds the meet and bulges past the lens's
    /// circle by up to √(9/8) − 1 of its radius (at δ = 1).
    pub fn cat_eye_lens(u: Vec2, centre: Vec2) -> Vec2 {
        if centre.length_squared() <= 1.0e-30 {
            return u;
        }
        let delta = centre.length();
        let e = centre / delta;
        let across = Vec2::new(-e.y, e.x);
        let half_along = (1.0 - 0.5 * delta).max(0.0);
        let half_across = (1.0 - 0.25 * delta * delta).max(0.0).sqrt();
        (0.5 * delta + half_along * u.dot(e)) * e + (half_across * u.dot(across)) * across
    }

    /// The part of the lens cell of half-width `half_cell` about u inside
    /// the circle of the pixel's cat's eye centred at `centre`: a ramp
    /// across the circle, 1 a half cell inside, 0 a half cell outside
    /// (RDB's bins and accum's samples weigh so, `glsl/aperture.glsl`).
    pub fn cat_eye_cell_weight(u: Vec2, centre: Vec2, half_cell: f32) -> f32 {
        ((1.0 - (u - centre).length()) / (2.0 * half_cell) + 0.5).clamp(0.0, 1.0)
    }

    /// The area of a cell of [`Aperture::cat_eye_lens`] over its cell of
    /// the unit disk: the pressed ellipse's half-axes' product.
    pub fn cat_eye_lens_area(centre: Vec2) -> f32 {
        let delta = centre.length();
        (1.0 - 0.5 * delta).max(0.0) * (1.0 - 0.25 * delta * delta).max(0.0).sqrt()
    }

    /// The weight of an RDB bin of lens position u (the disk's, of cell
    /// half-width `half_cell`) pressed ([`Aperture::cat_eye_lens`]) into
    /// the cat's eye centred at `pressed_into`, at a pixel whose circle is
    /// centred at `centre`: the part of the pressed cell (half-width h =
    /// `half_cell` times √[`Aperture::cat_eye_lens_area`]) inside both that
    /// circle and the lens, a ramp across each, 1 − r (r the distance from
    /// the circle's centre) taken as (1 − r²)/2, which it is to within
    /// (1 − r)²/2 where the ramp is not flat (`cat_eye_pressed_weight` of
    /// `glsl/aperture.glsl`).
    pub fn cat_eye_pressed_weight(
        u: Vec2,
        pressed_into: Vec2,
        centre: Vec2,
        half_cell: f32,
    ) -> f32 {
        let at = Self::cat_eye_lens(u, pressed_into);
        let h = (half_cell * Self::cat_eye_lens_area(pressed_into).sqrt()).max(1.0e-6);
        let ramp = |r2: f32| ((1.0 - r2) * (0.25 / h) + 0.5).clamp(0.0, 1.0);
        ramp((at - centre).length_squared()) * ramp(at.length_squared())
    }

    /// The weight of lens sample u (of cell half-width `half_cell`) in the
    /// mean of the pixel whose second circle is centred at `centre`
    /// (accum's resolve, `glsl/gbuffer_lens_weight.glsl`): the part of its
    /// cell inside the circle where that is above 0, else 2^(−40·r) at r
    /// lens radii from the centre, at least 2^−120 (a normal float): the
    /// samples outside add less than a float's precision to a pixel that
    /// has one inside, and a pixel with none sees through those nearest
    /// its circle.
    pub fn cat_eye_weight(u: Vec2, centre: Vec2, half_cell: f32) -> f32 {
        match Self::cat_eye_cell_weight(u, centre, half_cell) {
            w if w > 0.0 => w,
            _ => (-40.0 * (u - centre).length()).max(-120.0).exp2(),
        }
    }

    /// The area of the aperture in lens units, ∫T du (π for the round
    /// aperture), by `n`×`n` points over the square.
    pub fn area(&self, n: u32) -> f64 {
        let cell = 2.0 / f64::from(n);
        let mut sum = 0.0;
        for j in 0..n {
            for i in 0..n {
                let u = DVec2::new(
                    -1.0 + (f64::from(i) + 0.5) * cell,
                    -1.0 + (f64::from(j) + 0.5) * cell,
                );
                sum += f64::from(self.transmission(u.as_vec2()));
            }
        }
        sum * cell * cell
    }

    /// `count` lens positions distributed as T(u) with equal weights and
    /// stratified: the Fibonacci lattice of [`lens_samples`] taken to the
    /// shape by [`Aperture::from_square`] (the round aperture's are exactly
    /// [`lens_samples`]'s). Deterministic.
    pub fn lens_samples(&self, count: u32) -> Vec<Vec2> {
        if self.is_unit_disk() {
            return lens_samples(count);
        }
        let inv_phi = (5f64.sqrt() - 1.0) / 2.0;
        let square: Vec<[f64; 2]> = (0..count)
            .map(|i| {
                let x = (f64::from(i) + 0.5) / f64::from(count);
                [x, (f64::from(i) * inv_phi + 0.5).fract()]
            })
            .collect();
        self.from_square(&square)
    }

    /// Whether T is the unit disk's (no blades, image or squeeze): its
    /// samples and bins are the round lens's tables, unchanged.
    fn is_unit_disk(&self) -> bool {
        self.blades == 0 && self.image.is_none() && self.ratio == 1.0
    }

    /// The ray distribution buffer's N×N lens bins for this shape: bin
    /// b = j·N + i is cell (i, j) of the square, its lens position the
    /// cell's centre taken to the shape by [`Aperture::from_square`], so
    /// that every bin holds an equal share of T (the round aperture's are
    /// exactly [`rdb_lens_table`]'s).
    pub fn rdb_lens_table(&self, n: u32) -> Vec<Vec2> {
        if self.is_unit_disk() {
            return rdb_lens_table(n);
        }
        let square: Vec<[f64; 2]> = (0..n * n)
            .map(|b| {
                let cell = |k: u32| (f64::from(k) + 0.5) / f64::from(n);
                [cell(b % n), cell(b / n)]
            })
            .collect();
        self.from_square(&square)
    }

    /// Points of the unit square [0, 1)² taken to the shape, preserving
    /// area (so stratified points stay stratified): through the concentric
    /// map to the disk, the blades' angular warp and the squeeze and
    /// rotation; or, for an image, its inverse cumulative distribution.
    pub fn from_square(&self, square: &[[f64; 2]]) -> Vec<Vec2> {
        if let Some(image) = self.image {
            return image_samples(image, square)
                .into_iter()
                .map(|w| self.lens_of(w))
                .collect();
        }
        let disk = square
            .iter()
            .map(|&[x, y]| concentric_disk(Vec2::new(2.0 * x as f32 - 1.0, 2.0 * y as f32 - 1.0)));
        if self.blades == 0 {
            return disk.map(|v| self.lens_of(v)).collect();
        }
        let warp = BladeWarp::new(self);
        disk.map(|v| self.lens_of(warp.apply(v))).collect()
    }
}

/// A convex shape as horizontal chords (the layered method's spreading,
/// `glsl/layered_spread.comp`): its vertical extent in lens units and,
/// for each of `chords.len()` rows of equal height over y ∈ [−1, 1], the
/// chord [x_lo, x_hi] through the row's centre (x_lo > x_hi: the row
/// misses the shape).
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeRows {
    /// The shape's least y (lens units, pixel axes: its top).
    pub y_min: f32,
    /// The shape's greatest y.
    pub y_max: f32,
    /// Per row, [x_lo, x_hi].
    pub chords: Vec<[f32; 2]>,
}

impl ShapeRows {
    /// Row k's chord with its y extent, (y0, y1, [x_lo, x_hi]): the rows
    /// split [−1, 1] evenly (`shape_row_index` of `glsl/aperture.glsl`).
    fn rows(&self) -> impl Iterator<Item = (f32, f32, [f32; 2])> + '_ {
        let height = 2.0 / self.chords.len() as f32;
        self.chords.iter().enumerate().map(move |(k, &chord)| {
            let y0 = -1.0 + k as f32 * height;
            (y0, -1.0 + (k + 1) as f32 * height, chord)
        })
    }

    /// The radius of the largest disk about the lens centre that every
    /// lens position inside passes by these chords (the rows' own test,
    /// `shape_row_index` of `glsl/aperture.glsl`: the row of u.y, u.x
    /// within its chord), less a float's rounding: the tree gather takes a
    /// block whole where all its pixels lie within it.
    pub fn inner_radius(&self) -> f32 {
        let mut inner = f32::INFINITY;
        for (y0, y1, [lo, hi]) in self.rows() {
            let (dx, dy) = (row_half_width(lo, hi), row_distance(y0, y1));
            inner = inner.min((dx * dx + dy * dy).sqrt());
        }
        (inner * (1.0 - 1e-5)).max(0.0)
    }

    /// The half-width and half-height of the largest-area rectangle about
    /// the lens centre that every lens position inside, and its mirror
    /// through the centre, passes by these chords (the rows' own test, as
    /// [`ShapeRows::inner_radius`]) and within the unit circle, less a
    /// float's rounding: the tree gather also takes a block whole where
    /// all its pixels lie within it ([0, 0] where none has area).
    pub fn inner_box(&self) -> [f32; 2] {
        let mut rows: Vec<(f32, f32)> = self
            .rows()
            .map(|(y0, y1, [lo, hi])| (row_distance(y0, y1), row_half_width(lo, hi)))
            .collect();
        rows.sort_by(|a, b| a.0.total_cmp(&b.0));
        // A half-height b reaches the rows nearer than b: for each next
        // distance, the rows before it and the widest x they all hold.
        // A chord is the shape's at its row's centre, and the shape
        // narrows within a row past it: the rows at distance b, whose
        // centres lie beyond b, bound it too (the shape's half-width
        // about x = 0 is concave in y, at least the lesser of two chords
        // between their centres). A quarter of a row's height groups the
        // two sides' rows at one distance whatever their rounding.
        let quarter = 0.5 / self.chords.len() as f32;
        let (mut best, mut best_area) = ([0.0f32; 2], 0.0f32);
        let mut a = f32::INFINITY;
        for i in 0..rows.len() {
            a = a.min(rows[i].1);
            let b = rows.get(i + 1).map_or(1.0, |next| next.0);
            if i + 1 < rows.len() && rows[i + 1].0 <= rows[i].0 + quarter {
                continue;
            }
            let at_b = rows[i + 1..]
                .iter()
                .take_while(|row| row.0 <= b + quarter)
                .fold(a, |a, row| a.min(row.1));
            // Within the circle too: the pixel test's |u| ≤ 1.
            let a_in = at_b.min((1.0 - b * b).max(0.0).sqrt());
            let [a_in, b] = [a_in, b].map(|v| (v * (1.0 - 1e-5)).max(0.0));
            if a_in * b > best_area {
                best_area = a_in * b;
                best = [a_in, b];
            }
        }
        best
    }
}

/// The half-width of the chord [lo, hi] about x = 0: how far from the
/// centre's column a row's test holds both ways (0 where the chord is
/// empty, lo > hi, or does not hold x = 0).
fn row_half_width(lo: f32, hi: f32) -> f32 {
    if lo > hi || lo > 0.0 || hi < 0.0 {
        0.0
    } else {
        (-lo).min(hi)
    }
}

/// The distance from the lens centre's row (y = 0) to the nearest point
/// of the row [y0, y1] (0 for the row that holds it).
fn row_distance(y0: f32, y1: f32) -> f32 {
    if y0 <= 0.0 && y1 >= 0.0 {
        0.0
    } else {
        y0.abs().min(y1.abs())
    }
}

/// A shape of any transmission (an aperture image) as spans of constant
/// transmission along rows (the layered method's spreading): per row of
/// equal height over y ∈ [−1, 1], `spans[offsets[k]..offsets[k + 1]]`,
/// each [x_lo, x_hi, T] in lens units.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeSpans {
    /// The least y of a row with a span (its edge).
    pub y_min: f32,
    /// The greatest.
    pub y_max: f32,
    /// Row k's spans start at `offsets[k]`; `rows + 1` entries.
    pub offsets: Vec<u32>,
    /// [x_lo, x_hi, transmission].
    pub spans: Vec<[f32; 3]>,
}

/// Points per row of [`Aperture::shape_spans`].
const SPAN_POINTS: u32 = 1024;

impl Aperture {
    /// The shape as `rows` rows of spans: T at 1024 points across each
    /// row's centre line, runs of equal T (above 0) joined into spans.
    pub fn shape_spans(&self, rows: u32) -> ShapeSpans {
        let (mut offsets, mut spans) = (vec![0u32], Vec::new());
        let (mut y_min, mut y_max) = (f32::INFINITY, f32::NEG_INFINITY);
        let step = 2.0 / SPAN_POINTS as f32;
        for k in 0..rows {
            let y = -1.0 + (k as f32 + 0.5) * 2.0 / rows as f32;
            let mut run: Option<[f32; 3]> = None;
            for i in 0..SPAN_POINTS {
                let x0 = -1.0 + i as f32 * step;
                let t = self.transmission(Vec2::new(x0 + 0.5 * step, y));
                match &mut run {
                    Some(r) if r[2] == t => r[1] = x0 + step,
                    _ => {
                        if let Some(r) = run.take() {
                            spans.push(r);
                        }
                        if t > 0.0 {
                            run = Some([x0, x0 + step, t]);
                        }
                    }
                }
            }
            spans.extend(run);
            if spans.len() as u32 > *offsets.last().unwrap_or(&0) {
                y_min = y_min.min(y - 1.0 / rows as f32);
                y_max = y_max.max(y + 1.0 / rows as f32);
            }
            offsets.push(spans.len() as u32);
        }
        ShapeSpans {
            y_min,
            y_max,
            offsets,
            spans,
        }
    }
}

/// Boundary points of [`Aperture::shape_rows`]'s polygon.
const BOUNDARY_POINTS: usize = 2048;

impl Aperture {
    /// The shape (blades, curvature, squeeze and rotation; not an image)
    /// as `rows` chords: the boundary found along 2048 rays from the
    /// centre (every such shape is star-shaped about it) by bisection,
    /// each row cut with that polygon.
    pub fn shape_rows(&self, rows: u32) -> ShapeRows {
        let boundary: Vec<Vec2> = (0..BOUNDARY_POINTS)
            .map(|i| {
                let angle = std::f32::consts::TAU * i as f32 / BOUNDARY_POINTS as f32;
                let dir = Vec2::new(angle.cos(), angle.sin());
                let (mut inside, mut outside) = (0.0f32, 1.0001f32);
                for _ in 0..30 {
                    let mid = 0.5 * (inside + outside);
                    if self.transmission(dir * mid) > 0.0 {
                        inside = mid;
                    } else {
                        outside = mid;
                    }
                }
                dir * inside
            })
            .collect();
        let y_min = boundary.iter().map(|b| b.y).fold(f32::INFINITY, f32::min);
        let y_max = boundary
            .iter()
            .map(|b| b.y)
            .fold(f32::NEG_INFINITY, f32::max);
        let chords = (0..rows)
            .map(|k| {
                let y = -1.0 + (k as f32 + 0.5) * 2.0 / rows as f32;
                let mut chord = [1.0f32, -1.0f32];
                for (i, a) in boundary.iter().enumerate() {
                    let b = boundary[(i + 1) % BOUNDARY_POINTS];
                    if (a.y <= y) != (b.y <= y) {
                        let x = a.x + (y - a.y) / (b.y - a.y) * (b.x - a.x);
                        chord = [chord[0].min(x), chord[1].max(x)];
                    }
                }
                chord
            })
            .collect();
        ShapeRows {
            y_min,
            y_max,
            chords,
        }
    }
}

/// The area-preserving map from the unit disk onto the blades' base shape:
/// a disk point at radius r and screen angle α goes to radius r·ρ(β) at
/// angle β, where β's share of the shape's area, ∫₀^β ρ² dφ over ∫₀^{2π},
/// equals α's share of the disk's, α / 2π (tabulated in 4096 steps).
struct BladeWarp<'a> {
    aperture: &'a Aperture,
    /// Cumulative ∫ρ² at the table's angles, normalised to end at 1.
    cumulative: Vec<f64>,
}

impl<'a> BladeWarp<'a> {
    const STEPS: usize = 4096;

    fn new(aperture: &'a Aperture) -> Self {
        let step = std::f64::consts::TAU / Self::STEPS as f64;
        let mut cumulative = Vec::with_capacity(Self::STEPS + 1);
        let mut sum = 0.0;
        cumulative.push(0.0);
        for k in 0..Self::STEPS {
            let mid = ((k as f64 + 0.5) * step) as f32;
            let rho = f64::from(aperture.blade_radius(mid));
            sum += rho * rho * step;
            cumulative.push(sum);
        }
        for c in &mut cumulative {
            *c /= sum;
        }
        BladeWarp {
            aperture,
            cumulative,
        }
    }

    /// The base point of disk point v.
    fn apply(&self, v: Vec2) -> Vec2 {
        let r = v.length();
        if r == 0.0 {
            return Vec2::ZERO;
        }
        let tau = std::f64::consts::TAU;
        let alpha = f64::from((-v.y).atan2(v.x)).rem_euclid(tau);
        let share = alpha / tau;
        let k = self
            .cumulative
            .partition_point(|&c| c <= share)
            .clamp(1, Self::STEPS);
        let (c0, c1) = (self.cumulative[k - 1], self.cumulative[k]);
        let t = if c1 > c0 {
            (share - c0) / (c1 - c0)
        } else {
            0.0
        };
        let beta = ((k as f64 - 1.0 + t) * tau / Self::STEPS as f64) as f32;
        let rho = self.aperture.blade_radius(beta);
        r * rho * Vec2::new(beta.cos(), -beta.sin())
    }
}

/// Base points distributed as an aperture image inside the lens's circle:
/// points of the unit square through the inverse
/// of the image's cumulative distribution (rows, then the columns of the
/// row), each pixel weighted by its transmission times its share inside
/// the circle; a point that falls outside the circle at the rim is moved
/// onto it.
fn image_samples(image: &ApertureImage, square: &[[f64; 2]]) -> Vec<Vec2> {
    let weights: Vec<f64> = image.weights_in_circle().map(|(t, f)| t * f).collect();
    let (w, h) = (image.width as usize, image.height as usize);
    let row_sums: Vec<f64> = (0..h)
        .map(|j| weights[j * w..(j + 1) * w].iter().sum())
        .collect();
    let rows = Cdf::new(&row_sums);
    square
        .iter()
        .map(|&[x, y]| {
            let (j, fy) = rows.sample(y);
            let (i, fx) = Cdf::new(&weights[j * w..(j + 1) * w]).sample(x);
            let p = Vec2::new(
                (-1.0 + 2.0 * (i as f64 + fx) / w as f64) as f32,
                (-1.0 + 2.0 * (j as f64 + fy) / h as f64) as f32,
            );
            if p.length_squared() > 1.0 {
                p.normalize()
            } else {
                p
            }
        })
        .collect()
}

/// A discrete cumulative distribution over cells of given weights.
struct Cdf(Vec<f64>);

impl Cdf {
    fn new(weights: &[f64]) -> Cdf {
        let mut c = Vec::with_capacity(weights.len() + 1);
        let mut sum = 0.0;
        c.push(0.0);
        for w in weights {
            sum += w;
            c.push(sum);
        }
        Cdf(c)
    }

    /// The cell of x ∈ [0, 1) and x's place within it, in [0, 1).
    fn sample(&self, x: f64) -> (usize, f64) {
        let total = *self.0.last().unwrap_or(&0.0);
        let n = self.0.len() - 1;
        if total <= 0.0 {
            return (n / 2, 0.5);
        }
        let target = x * total;
        let k = self.0.partition_point(|&c| c <= target).clamp(1, n);
        let (c0, c1) = (self.0[k - 1], self.0[k]);
        let f = if c1 > c0 {
            (target - c0) / (c1 - c0)
        } else {
            0.5
        };
        (k - 1, f.clamp(0.0, 1.0 - 1e-9))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blades(n: u32, rotation_deg: f32) -> Aperture {
        Aperture {
            blades: n,
            rotation_deg,
            ..Aperture::ROUND
        }
    }

    /// Blades odd and even, straight and curved, turned and squeezed, and
    /// the squeezed circle: what the tap tests are tested on.
    fn tested_shapes() -> [Aperture; 6] {
        [
            blades(3, 0.0),
            blades(5, 36.0),
            Aperture {
                curvature: 0.4,
                ..blades(6, 15.0)
            },
            Aperture {
                ratio: 2.0,
                ..blades(7, 10.0)
            },
            Aperture {
                ratio: 0.5,
                curvature: 1.0,
                ..blades(16, 0.0)
            },
            Aperture {
                ratio: 1.7,
                ..Aperture::ROUND
            },
        ]
    }

    /// The tap test without angles agrees with T(u) > 0 away from the
    /// boundary (where their roundings may differ), and the matrix with
    /// `base_of`, for blades straight and curved, turned and squeezed.
    #[test]
    fn blades_pass_where_the_transmission_is() {
        let (mut checked, mut inside) = (0, 0);
        for a in tested_shapes() {
            for i in 0..201 {
                for j in 0..201 {
                    let u = Vec2::new(i as f32 / 100.0 - 1.0, j as f32 / 100.0 - 1.0);
                    let w = a.base_by_matrix(u);
                    assert!((w - a.base_of(u)).length() < 1e-6, "{a:?} at {u}");
                    let r = w.length();
                    let rho = if a.blades == 0 {
                        1.0
                    } else {
                        a.blade_radius((-w.y).atan2(w.x)).min(1.0)
                    };
                    if (r - rho).abs() < 1e-4 {
                        continue;
                    }
                    let passes = a.transmission(u) > 0.0;
                    assert_eq!(a.blades_pass(u), passes, "{a:?} at {u}");
                    checked += 1;
                    inside += usize::from(passes);
                }
            }
        }
        assert!(
            inside > checked / 4 && inside < checked,
            "{inside} of {checked} inside"
        );
    }

    /// The tap test in pixels agrees with the test of its lens position
    /// away from the boundary, on either side of the focus, for blades
    /// even and odd, straight and curved, turned and squeezed.
    #[test]
    fn reaches_is_blades_pass_of_the_lens_position() {
        let (mut checked, mut inside) = (0, 0);
        for a in tested_shapes() {
            for h in [0.5f32, 3.0, 17.5] {
                for behind in [false, true] {
                    let s = if behind { 1.0 } else { -1.0 };
                    let reach = h.ceil() as i32 + 1;
                    for y in -reach..=reach {
                        for x in -reach..=reach {
                            let v = Vec2::new(x as f32, y as f32);
                            let u = -v / (s * h);
                            let w = a.base_of(u);
                            let rho = if a.blades == 0 {
                                1.0
                            } else {
                                a.blade_radius((-w.y).atan2(w.x)).min(1.0)
                            };
                            if (w.length() - rho).abs() < 1e-4 || (u.length() - 1.0).abs() < 1e-4 {
                                continue;
                            }
                            let passes = a.blades_pass(u);
                            assert_eq!(
                                a.reaches(v, h, behind),
                                passes,
                                "{a:?} at {v}, h {h}, behind {behind}"
                            );
                            checked += 1;
                            inside += usize::from(passes);
                        }
                    }
                }
            }
        }
        assert!(
            inside > checked / 4 && inside < checked,
            "{inside} of {checked} inside"
        );
        // No reach without a CoC but to Q itself.
        assert!(blades(6, 0.0).reaches(Vec2::ZERO, 0.0, true));
        assert!(!blades(6, 0.0).reaches(Vec2::X, 0.0, true));
    }

    /// Every tap that reaches Q with a CoC up to 2t lies within its row's
    /// span of t, on either side of the focus, for the round aperture and
    /// blades even and odd, straight and curved, turned and squeezed, at
    /// scales from under a pixel to a wide window; and the spans are not
    /// the whole window (they leave out the square's corners).
    #[test]
    fn row_spans_hold_every_tap_that_reaches() {
        let mut shapes = tested_shapes().to_vec();
        shapes.push(Aperture::ROUND);
        for a in shapes {
            for t in [0.4f32, 1.0, 3.0, 7.5, 17.5, 40.25] {
                let reach = t.ceil() as i32 + 2;
                let (mut in_spans, mut reaching) = (0usize, 0usize);
                for y in -reach..=reach {
                    let (x0, x1) = a.row_span(y, t);
                    in_spans += usize::try_from(x1 - x0 + 1).unwrap_or(0);
                    for x in -reach..=reach {
                        let v = Vec2::new(x as f32, y as f32);
                        for h in [t, t * 0.999_99, t * 0.71, t * 0.3, 0.2] {
                            for behind in [false, true] {
                                if a.reaches(v, h, behind) {
                                    reaching += 1;
                                    assert!(
                                        x0 <= x && x <= x1,
                                        "{a:?}, t {t}: {v} (h {h}, behind {behind}) outside [{x0}, {x1}]"
                                    );
                                }
                            }
                        }
                    }
                }
                assert!(reaching > 0, "{a:?}, t {t}: no tap reaches");
                let window = (2 * t.floor() as usize + 1).pow(2);
                if t > 7.0 {
                    assert!(
                        in_spans < window * 9 / 10,
                        "{a:?}, t {t}: spans of {in_spans} taps in a window of {window}"
                    );
                }
            }
        }
    }

    #[test]
    fn polygon_area_is_the_inscribed_polygons() {
        for n in [3, 5, 6, 9, 16] {
            let exact = 0.5 * f64::from(n) * (std::f64::consts::TAU / f64::from(n)).sin();
            let area = blades(n, 17.0).area(1024);
            assert!(
                (area - exact).abs() < 2e-3 * exact,
                "{n} blades: {area} against {exact}"
            );
        }
        let round = Aperture::ROUND.area(1024);
        assert!((round - std::f64::consts::PI).abs() < 1e-3);
    }

    #[test]
    fn a_corner_points_up_and_rotation_turns_counter_clockwise() {
        let five = blades(5, 0.0);
        // Up on screen is −y in pixel axes.
        assert_eq!(five.transmission(Vec2::new(0.0, -0.99)), 1.0);
        assert_eq!(five.transmission(Vec2::new(0.0, 0.99)), 0.0);
        // Turned 90° counter-clockwise the corner points left (−x).
        let turned = blades(5, 90.0);
        assert_eq!(turned.transmission(Vec2::new(-0.99, 0.0)), 1.0);
        assert_eq!(turned.transmission(Vec2::new(0.99, 0.0)), 0.0);
    }

    #[test]
    fn samples_lie_in_the_shape_and_round_is_unchanged() {
        assert_eq!(Aperture::ROUND.lens_samples(64), lens_samples(64));
        for a in [
            blades(5, 10.0),
            Aperture {
                blades: 7,
                curvature: 0.4,
                ratio: 2.0,
                ..Aperture::ROUND
            },
            Aperture {
                ratio: 0.5,
                ..Aperture::ROUND
            },
        ] {
            let s = a.lens_samples(256);
            for u in &s {
                // On or inside the shape (the rim within f32 rounding).
                assert!(a.transmission(*u * 0.999) > 0.0, "{a:?}: {u}");
            }
            // Equal areas: the mean of the samples is the shape's centroid
            // (0 for a shape symmetric under a half turn, and near 0 for
            // odd blades: their centroid is at the centre too).
            let mean = s.iter().copied().sum::<Vec2>() / s.len() as f32;
            assert!(mean.length() < 0.02, "{a:?}: mean {mean}");
        }
    }

    /// Lens position u passes the rows' own test (glsl/aperture.glsl's
    /// `shape_row_index`: the row of u.y, u.x within its chord).
    fn assert_rows_pass(rows: &ShapeRows, u: Vec2) {
        let n = rows.chords.len() as i64;
        let k = (((u.y + 1.0) * 0.5 * n as f32).floor() as i64).clamp(0, n - 1);
        let [lo, hi] = rows.chords[k as usize];
        assert!(u.x >= lo && u.x <= hi, "{u} outside row {k}: {lo}..{hi}");
    }

    /// The inner radius is the shapes' (the regular polygons' cos(π/N); a
    /// hexagon squeezed to half its height, its slanted sides from
    /// (cos 30°, ¼) to (0, ½): cos 30° / 2 over |(¼, cos 30°)|), and every
    /// lens position within it passes the rows' own test
    /// (glsl/aperture.glsl's `shape_row_index`).
    #[test]
    fn the_inner_radius_is_inside_every_chord() {
        let squeezed = Aperture {
            ratio: 0.5,
            ..blades(6, 0.0)
        };
        for (aperture, expected) in [
            (blades(6, 0.0), 30f32.to_radians().cos()),
            (blades(5, 17.0), 36f32.to_radians().cos()),
            (squeezed, {
                let c = 30f32.to_radians().cos();
                0.5 * c / Vec2::new(0.25, c).length()
            }),
        ] {
            let rows = aperture.shape_rows(512);
            let inner = rows.inner_radius();
            assert!(
                inner <= expected && inner > expected - 0.01,
                "{inner} against {expected}"
            );
            for i in 0..20_000 {
                let (a, r) = (
                    i as f32 * 2.399_963,
                    inner * ((i % 997) as f32 / 996.0).sqrt(),
                );
                assert_rows_pass(&rows, r * Vec2::new(a.cos(), a.sin()));
            }
        }
    }

    /// What `fast`'s tree takes of the rows holds the shape itself, by the
    /// test its pixels take (`blades_pass`, `shape_reaches` in GLSL): the
    /// lens positions the shape passes lie within the bounding box (the
    /// tree leaves a block outside it, a hundredth of a percent wider),
    /// and the inner disk and the corners of the inner box and its mirror
    /// (the shape is convex: the box within it) pass, for blades odd and
    /// even, straight and curved, turned and squeezed.
    #[test]
    fn the_rows_bounds_hold_the_shape() {
        let mut shapes = tested_shapes().to_vec();
        shapes.push(blades(6, 15.0));
        shapes.push(Aperture {
            curvature: 0.5,
            ..blades(6, 15.0)
        });
        for a in shapes {
            let rows = a.shape_rows(512);
            let [x_min, x_max, y_min, y_max] = a.lens_bounding_box().map(|v| v * 1.0002);
            let inner = rows.inner_radius();
            let [half_w, half_h] = rows.inner_box();
            for i in 0..20_000 {
                let angle = std::f32::consts::TAU * i as f32 / 20_000.0;
                let dir = Vec2::new(angle.cos(), angle.sin());
                assert!(
                    a.blades_pass(inner * dir),
                    "{a:?}: the inner disk {inner} at {angle}"
                );
                let (mut inside, mut outside) = (0.0f32, 1.5f32);
                for _ in 0..40 {
                    let mid = 0.5 * (inside + outside);
                    match a.blades_pass(mid * dir) {
                        true => inside = mid,
                        false => outside = mid,
                    }
                }
                let u = inside * dir;
                assert!(
                    u.x >= x_min && u.x <= x_max && u.y >= y_min && u.y <= y_max,
                    "{a:?}: {u} outside the bounding box {:?}",
                    a.lens_bounding_box()
                );
            }
            for corner in [[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]] {
                let u = Vec2::new(corner[0] * half_w, corner[1] * half_h);
                assert!(a.blades_pass(u), "{a:?}: the inner box's corner {u}");
            }
        }
    }

    /// A pixel of half-CoC h spreads over as many offsets as reach by
    /// the taps' own test ([`Aperture::reaches`]) as there are reach
    /// thresholds at or below h, on either side of the focus, for blades
    /// odd and even, straight and curved, turned and squeezed (the counts
    /// `fast`'s weights divide by).
    #[test]
    fn the_thresholds_count_the_taps_that_reach() {
        let mut next = {
            let mut state = 0x2545_f491_4f6c_dd1du64;
            move || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 40) as f32 / (1u64 << 24) as f32
            }
        };
        for a in tested_shapes() {
            let thresholds = a.tap_thresholds(40.0);
            assert!(thresholds.windows(2).all(|w| w[0] <= w[1]));
            for _ in 0..60 {
                let h = 0.3 + 39.5 * next();
                let counted = thresholds.partition_point(|&t| t <= h);
                let m = h.ceil() as i32 + 1;
                for behind in [true, false] {
                    let reached = (-m..=m)
                        .flat_map(|dy| (-m..=m).map(move |dx| Vec2::new(dx as f32, dy as f32)))
                        .filter(|&v| a.reaches(v, h, behind))
                        .count();
                    assert_eq!(counted, reached, "{a:?} at h = {h}, behind: {behind}");
                }
            }
        }
    }

    /// The unit disk pressed into a pixel's cat's eye holds the part of
    /// the lens that pixel sees (the lens's circle and the cat's eye's
    /// meet), for circles from concentric to touching, and fills most of
    /// it: its area over the meet's, 1 at the centre, 1.11 where the
    /// centres lie a radius apart; each cell's area scales by
    /// `cat_eye_lens_area`.
    #[test]
    fn the_pressed_lens_holds_what_a_pixel_sees() {
        for (k, delta) in [0.0f32, 0.3, 1.0, 1.5, 1.9].into_iter().enumerate() {
            let angle = 0.7 + k as f32;
            let centre = delta * Vec2::new(angle.cos(), angle.sin());
            let area = Aperture::cat_eye_lens_area(centre);
            // The meet's boundary (both circles' arcs) within the pressed
            // ellipse: its preimage within the unit disk.
            let (mut meet, mut inside) = (0u32, 0u32);
            for i in 0..400 {
                for j in 0..400 {
                    let u = Vec2::new(i as f32 / 199.5 - 1.0, j as f32 / 199.5 - 1.0);
                    if u.length() > 1.0 || !Aperture::cat_eye_passes(u, centre) {
                        continue;
                    }
                    meet += 1;
                    // Invert the press: along e and across it.
                    let back = match delta {
                        0.0 => u,
                        _ => {
                            let e = centre / delta;
                            let across = Vec2::new(-e.y, e.x);
                            let a = (u.dot(e) - 0.5 * delta) / (1.0 - 0.5 * delta);
                            let b = u.dot(across) / (1.0 - 0.25 * delta * delta).sqrt();
                            a * e + b * across
                        }
                    };
                    assert!(
                        back.length() <= 1.0 + 1e-4,
                        "δ = {delta}: {u} pressed from {back}"
                    );
                    inside += 1;
                    let there = Aperture::cat_eye_lens(back, centre);
                    assert!(
                        (there - u).length() < 1e-4,
                        "δ = {delta}: {there} against {u}"
                    );
                }
            }
            assert_eq!(meet, inside);
            let ratio = area * std::f32::consts::PI / (meet as f32 * (2.0 / 399.0f32).powi(2));
            assert!(
                (1.0..1.2).contains(&ratio),
                "δ = {delta}: the ellipse over the meet {ratio}"
            );
        }
    }

    /// The inner box holds every lens position inside it and its mirror
    /// by the rows' own test, reaches beyond the inner disk, and lies
    /// within the unit circle.
    #[test]
    fn the_inner_box_is_inside_every_chord() {
        let squeezed = Aperture {
            ratio: 0.5,
            ..blades(6, 0.0)
        };
        for aperture in [blades(6, 15.0), blades(5, 17.0), squeezed] {
            let rows = aperture.shape_rows(512);
            let [a, b] = rows.inner_box();
            let inner = rows.inner_radius();
            assert!(a * a + b * b > inner * inner, "{a}, {b} within {inner}");
            assert!(a * a + b * b <= 1.0);
            for i in 0..=200 {
                for j in 0..=200 {
                    let u = Vec2::new(a * (i as f32 / 100.0 - 1.0), b * (j as f32 / 100.0 - 1.0));
                    assert_rows_pass(&rows, u);
                }
            }
        }
    }

    #[test]
    fn shape_rows_cut_the_shape() {
        // A hexagon with a corner up: extent ±1 vertically, the middle
        // row as wide as the flat sides' distance, cos 30°.
        let rows = blades(6, 0.0).shape_rows(512);
        assert!((rows.y_min + 1.0).abs() < 1e-3 && (rows.y_max - 1.0).abs() < 1e-3);
        let mid = rows.chords[256];
        let half = 3f32.sqrt() / 2.0;
        assert!(
            (mid[0] + half).abs() < 2e-3 && (mid[1] - half).abs() < 2e-3,
            "{mid:?}"
        );
        // The pentagon's bottom is its flat side at cos 36°.
        let five = blades(5, 0.0).shape_rows(512);
        assert!(
            (five.y_max - 36f32.to_radians().cos()).abs() < 1e-3,
            "{}",
            five.y_max
        );
        assert!(
            five.chords[511][0] > five.chords[511][1],
            "the last row misses"
        );
    }

    #[test]
    fn the_circle_shares_are_the_8x8_counts() {
        for (w, h) in [(1, 1), (7, 5), (64, 64), (33, 90)] {
            let image = ApertureImage::new(PathBuf::new(), w, h, vec![1.0; (w * h) as usize]);
            for j in 0..h {
                for i in 0..w {
                    let mut inside = 0;
                    for sy in 0..8 {
                        for sx in 0..8 {
                            let x = -1.0
                                + 2.0 * (f64::from(i) + (f64::from(sx) + 0.5) / 8.0) / f64::from(w);
                            let y = -1.0
                                + 2.0 * (f64::from(j) + (f64::from(sy) + 0.5) / 8.0) / f64::from(h);
                            inside += u32::from(x * x + y * y <= 1.0);
                        }
                    }
                    let share = image.in_circle[(j * w + i) as usize];
                    assert_eq!(share, f64::from(inside) / 64.0, "{w}x{h} pixel {i},{j}");
                }
            }
        }
    }

    #[test]
    fn base_and_lens_are_inverse() {
        let a = Aperture {
            blades: 6,
            rotation_deg: 33.0,
            ratio: 0.6,
            ..Aperture::ROUND
        };
        for u in [Vec2::new(0.3, -0.2), Vec2::new(-0.5, 0.1)] {
            assert!((a.lens_of(a.base_of(u)) - u).length() < 1e-6);
        }
    }

    #[test]
    fn validation_refuses_what_cannot_be() {
        let bad = [
            ApertureSpec {
                aperture_blades: Some(1),
                ..Default::default()
            },
            ApertureSpec {
                aperture_blades: Some(2),
                ..Default::default()
            },
            ApertureSpec {
                aperture_blades: Some(17),
                ..Default::default()
            },
            ApertureSpec {
                anamorphic_ratio: Some(0.0),
                ..Default::default()
            },
            ApertureSpec {
                anamorphic_ratio: Some(f32::NAN),
                ..Default::default()
            },
            ApertureSpec {
                blade_curvature: Some(0.5),
                ..Default::default()
            },
            ApertureSpec {
                aperture_rotation_deg: Some(10.0),
                ..Default::default()
            },
            ApertureSpec {
                cat_eye: Some(1.5),
                ..Default::default()
            },
        ];
        for spec in bad {
            assert!(spec.validate().is_err(), "{spec:?}");
        }
        let good = ApertureSpec {
            aperture_blades: Some(6),
            aperture_rotation_deg: Some(-15.0),
            blade_curvature: Some(0.3),
            anamorphic_ratio: Some(1.5),
            cat_eye: Some(0.5),
            aperture_image: None,
        };
        assert!(good.validate().is_ok());
    }
}
