//! The thin-lens camera of DESIGN §2: pose, projection, circle of confusion,
//! lens offset, the camera file and its defaults (auto-framing, automatic
//! aperture).
//!
//! This is the only place the lens formulas live on the CPU; `glsl/lens.glsl`
//! mirrors them and the tests compare the GPU against these functions.
//!
//! Conventions (DESIGN §2): lengths in scene units; eye space has x right,
//! y up and z > 0 *in front of* the eye (not glam's −z view space); pixel
//! coordinates have their origin at the top-left corner, x right, y down, and
//! pixel centres at +0.5. The lens is the fixed-field-of-view thin lens of
//! pbrt, Mitsuba and Cycles: the projection does not breathe with focus.

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Default image size without a camera (the paper's demo resolution).
pub const DEFAULT_WIDTH: u32 = 640;
/// Default image height without a camera.
pub const DEFAULT_HEIGHT: u32 = 480;
/// Default vertical field of view in degrees.
pub const DEFAULT_FOVY_DEG: f32 = 40.0;
/// Margin that auto-framing leaves on each side of the image, as a fraction
/// of the image width (left and right) or height (top and bottom).
pub const FRAMING_MARGIN: f32 = 0.05;

/// The resolved thin-lens camera of DESIGN §2.
///
/// Built by [`resolve`] from a [`CameraSpec`], or directly. `up` need not be
/// unit length nor perpendicular to the view direction; [`Camera::basis`]
/// orthonormalises it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Centre of the lens, in world space.
    pub eye: Vec3,
    /// Point the camera looks at.
    pub target: Vec3,
    /// Approximate up direction of the image.
    pub up: Vec3,
    /// Vertical field of view θ in degrees, in (0, 180).
    pub fovy_deg: f32,
    /// Lens aperture radius R in scene units (0: a pinhole).
    pub aperture_radius: f32,
    /// Focus distance S: the eye-space depth of the plane in focus (> 0).
    pub focus_distance: f32,
}

impl Camera {
    /// The orthonormal eye basis `(right, up', forward)`:
    /// forward = normalize(target − eye); right = normalize(forward × up);
    /// up' = right × forward.
    pub fn basis(&self) -> (Vec3, Vec3, Vec3) {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        (right, up, forward)
    }

    /// Focal length in pixels: f_px = (H / 2) / tan(θ / 2).
    pub fn f_px(&self) -> f32 {
        (self.height as f32 / 2.0) / (self.fovy_deg.to_radians() / 2.0).tan()
    }

    /// Eye-space coordinates of the world point `p`:
    /// (x, y, z) = ((p − eye)·right, (p − eye)·up', (p − eye)·forward).
    /// z > 0 in front of the eye (DESIGN §2; not glam's −z view space).
    pub fn eye_from_world(&self, p: Vec3) -> Vec3 {
        let (right, up, forward) = self.basis();
        let d = p - self.eye;
        Vec3::new(d.dot(right), d.dot(up), d.dot(forward))
    }

    /// Pinhole projection of the world point `p`: its pixel position
    /// (x_px = W/2 + f_px·x/z, y_px = H/2 − f_px·y/z; origin top-left, pixel
    /// centres at +0.5) and its eye depth z. `None` when z ≤ 0 (at or behind
    /// the eye).
    pub fn project(&self, p: Vec3) -> Option<(Vec2, f32)> {
        let e = self.eye_from_world(p);
        if e.z.is_nan() || e.z <= 0.0 {
            return None;
        }
        let f = self.f_px();
        let px = Vec2::new(
            self.width as f32 / 2.0 + f * e.x / e.z,
            self.height as f32 / 2.0 - f * e.y / e.z,
        );
        Some((px, e.z))
    }

    /// Circle-of-confusion diameter in pixels of a point at eye depth `z`:
    /// c_px(z) = 2R · f_px · |z − S| / (z · S).
    ///
    /// `z = +∞` is the background (DESIGN §2): c_px(∞) = 2R · f_px / S.
    /// Defined for z > 0.
    pub fn coc_px(&self, z: f32) -> f32 {
        let (r, s) = (self.aperture_radius, self.focus_distance);
        if z == f32::INFINITY {
            return 2.0 * r * self.f_px() / s;
        }
        2.0 * r * self.f_px() * (z - s).abs() / (z * s)
    }

    /// Which way a point at depth `z` moves with the lens position:
    /// +1 behind the focus plane (z > S), −1 in front of it (z < S).
    ///
    /// At z = S this returns +1; the CoC, and with it the offset, is zero
    /// there, so the choice does not matter; `glsl/lens.glsl` makes the same one.
    pub fn lens_sign(&self, z: f32) -> f32 {
        if z >= self.focus_distance {
            1.0
        } else {
            -1.0
        }
    }

    /// THE lens-position ↔ image-offset relation of DESIGN §2, the one
    /// function the accumulation reference (sheared projection) and the ray
    /// distribution buffer (bin of a pair) are built on.
    ///
    /// A point at eye depth `z` whose pinhole projection is p is seen, through
    /// the normalised lens position `u` (|u| ≤ 1, in pixel axes: x right,
    /// y down), at p + `lens_offset_px(z, u)`, where
    /// `lens_offset_px(z, u) = sign(z) · (c_px(z) / 2) · u`.
    /// A point behind the focus plane moves with u, one in front of it against
    /// u, one on it not at all (the focus plane stays fixed).
    pub fn lens_offset_px(&self, z: f32, u: Vec2) -> Vec2 {
        self.lens_sign(z) * (self.coc_px(z) / 2.0) * u
    }

    /// The largest CoC diameter (pixels) over the eye-depth range
    /// [`z_min`, `z_max`], 0 < z_min ≤ z_max. The CoC decreases towards the
    /// focus plane from both sides, so the maximum is at one end of the
    /// range; `z_max = +∞` includes the background.
    pub fn max_coc_px(&self, z_min: f32, z_max: f32) -> f32 {
        self.coc_px(z_min).max(self.coc_px(z_max))
    }

    /// Guard band in pixels around the frame (DESIGN §3):
    /// ⌈max CoC / 2 + max splat / 2⌉, both arguments in pixels.
    pub fn guard_band_px(max_coc_px: f32, max_splat_px: f32) -> u32 {
        (max_coc_px / 2.0 + max_splat_px / 2.0).ceil() as u32
    }

    /// The camera as a complete camera file: width, height, eye, target, up,
    /// fovy_deg, aperture_radius and focus_distance.
    pub fn to_spec(&self) -> CameraSpec {
        CameraSpec {
            width: Some(self.width),
            height: Some(self.height),
            eye: Some(self.eye.to_array()),
            target: Some(self.target.to_array()),
            up: Some(self.up.to_array()),
            fovy_deg: Some(self.fovy_deg),
            aperture_radius: Some(self.aperture_radius),
            focus_distance: Some(self.focus_distance),
            ..CameraSpec::default()
        }
    }

    /// The camera as a pretty-printed camera file (`--print-camera`); reading
    /// it back with [`CameraSpec::from_json_str`] and [`resolve`] gives this
    /// camera again.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(&self.to_spec()).expect("a camera spec always serialises")
    }
}

/// Shirley–Chiu concentric map: the square [−1, 1]² onto the unit disk,
/// area-preserving (equal areas of the square map to equal areas of the
/// disk) and continuous, so stratified square samples stay stratified.
pub fn concentric_disk(a: Vec2) -> Vec2 {
    if a == Vec2::ZERO {
        return Vec2::ZERO;
    }
    let quarter = std::f32::consts::FRAC_PI_4;
    let (r, theta) = if a.x.abs() > a.y.abs() {
        (a.x, quarter * (a.y / a.x))
    } else {
        (a.y, 2.0 * quarter - quarter * (a.x / a.y))
    };
    r * Vec2::new(theta.cos(), theta.sin())
}

/// The inverse of [`concentric_disk`]: a point of the unit disk back to the
/// square [−1, 1]².
pub fn concentric_square(u: Vec2) -> Vec2 {
    let r = u.length();
    if r == 0.0 {
        return Vec2::ZERO;
    }
    let four_over_pi = 4.0 / std::f32::consts::PI;
    if u.x.abs() >= u.y.abs() {
        let s = if u.x >= 0.0 { 1.0 } else { -1.0 };
        let theta = (s * u.y).atan2(s * u.x);
        Vec2::new(s * r, s * r * theta * four_over_pi)
    } else {
        let s = if u.y >= 0.0 { 1.0 } else { -1.0 };
        let theta = (s * u.y).atan2(s * u.x);
        Vec2::new(
            s * r * (std::f32::consts::FRAC_PI_2 - theta) * four_over_pi,
            s * r,
        )
    }
}

/// The ray distribution buffer's lens bins (DESIGN §5): bin b = j·N + i is
/// cell (i, j) of an N×N grid on [−1, 1]² (half-open cells), and its lens
/// position u_b is the concentric map of the cell's centre.
pub fn rdb_lens_table(n: u32) -> Vec<Vec2> {
    (0..n * n)
        .map(|b| {
            let (i, j) = ((b % n) as f32, (b / n) as f32);
            let cell = |k: f32| -1.0 + (2.0 * k + 1.0) / n as f32;
            concentric_disk(Vec2::new(cell(i), cell(j)))
        })
        .collect()
}

/// The bin of an N×N ray distribution buffer whose lens cell holds the
/// normalised lens position `u`.
pub fn rdb_bin(u: Vec2, n: u32) -> u32 {
    let a = concentric_square(u);
    let cell = |v: f32| (((v + 1.0) * 0.5 * n as f32).floor() as i64).clamp(0, n as i64 - 1) as u32;
    cell(a.y) * n + cell(a.x)
}

/// `count` normalised lens positions stratified over the unit disk: a
/// Fibonacci lattice on the square ((i + ½)/S, frac(i/φ + ½)), mapped by
/// [`concentric_disk`]. Deterministic; one sample is the lens centre.
pub fn lens_samples(count: u32) -> Vec<Vec2> {
    let inv_phi = (5f64.sqrt() - 1.0) / 2.0;
    (0..count)
        .map(|i| {
            let x = (i as f64 + 0.5) / count as f64;
            let y = (i as f64 * inv_phi + 0.5).fract();
            concentric_disk(Vec2::new(2.0 * x as f32 - 1.0, 2.0 * y as f32 - 1.0))
        })
        .collect()
}

/// A camera file (`--camera FILE.json`, DESIGN §2) or the camera flags: every
/// field optional, named as in the JSON. Unknown JSON fields are ignored.
/// [`resolve`] fills in the defaults.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraSpec {
    /// Image width in pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<u32>,
    /// Image height in pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<u32>,
    /// Eye (lens centre) position.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eye: Option<[f32; 3]>,
    /// Point looked at.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<[f32; 3]>,
    /// Up direction (default +y).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub up: Option<[f32; 3]>,
    /// Vertical field of view in degrees; wins over the focal length.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fovy_deg: Option<f32>,
    /// Focal length in mm: with `sensor_height_mm` gives the field of view,
    /// with `units_per_mm` and `f_number` the aperture.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focal_length_mm: Option<f32>,
    /// Sensor height in mm (with `focal_length_mm`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_height_mm: Option<f32>,
    /// Aperture radius in scene units; wins over `f_number`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aperture_radius: Option<f32>,
    /// f-number N: R = f / 2N with f = focal_length_mm · units_per_mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub f_number: Option<f32>,
    /// Scene units per millimetre, to turn the focal length into scene units.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub units_per_mm: Option<f32>,
    /// Focus distance S (eye-space depth of the plane in focus).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus_distance: Option<f32>,
}

impl CameraSpec {
    /// Reads a camera file. [`Error::Io`] if it cannot be read,
    /// [`Error::Json`] (serde's message, with line and column) if it is not
    /// JSON of the camera file's shape.
    pub fn from_json_file(path: impl AsRef<Path>) -> Result<CameraSpec> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        parse_json(&text, path)
    }

    /// Parses a camera file's text; errors as [`CameraSpec::from_json_file`],
    /// with the path given as `camera JSON`.
    pub fn from_json_str(json: &str) -> Result<CameraSpec> {
        parse_json(json, Path::new("camera JSON"))
    }

    /// This spec with every field that is set in `flags` replaced by the
    /// flag's value (command-line flags override single fields of the file).
    pub fn overridden_by(self, flags: &CameraSpec) -> CameraSpec {
        CameraSpec {
            width: flags.width.or(self.width),
            height: flags.height.or(self.height),
            eye: flags.eye.or(self.eye),
            target: flags.target.or(self.target),
            up: flags.up.or(self.up),
            fovy_deg: flags.fovy_deg.or(self.fovy_deg),
            focal_length_mm: flags.focal_length_mm.or(self.focal_length_mm),
            sensor_height_mm: flags.sensor_height_mm.or(self.sensor_height_mm),
            aperture_radius: flags.aperture_radius.or(self.aperture_radius),
            f_number: flags.f_number.or(self.f_number),
            units_per_mm: flags.units_per_mm.or(self.units_per_mm),
            focus_distance: flags.focus_distance.or(self.focus_distance),
        }
    }

    /// Checks that a camera file is complete (DESIGN §2): an error naming the
    /// first missing field among width, height, eye, target, the field of
    /// view (`fovy_deg`, or `focal_length_mm` + `sensor_height_mm`), the
    /// aperture (`aperture_radius` or `f_number`) and focus_distance. `up`
    /// may be left out (+y). Values are checked by [`resolve`].
    pub fn require_complete(&self) -> Result<()> {
        let missing = |field: &'static str, msg: &str| {
            Err(Error::Camera {
                field,
                msg: msg.to_string(),
            })
        };
        if self.width.is_none() {
            return missing("width", "missing from the camera file");
        }
        if self.height.is_none() {
            return missing("height", "missing from the camera file");
        }
        if self.eye.is_none() {
            return missing("eye", "missing from the camera file");
        }
        if self.target.is_none() {
            return missing("target", "missing from the camera file");
        }
        if self.fovy_deg.is_none() {
            match (self.focal_length_mm, self.sensor_height_mm) {
                (Some(_), Some(_)) => {}
                (Some(_), None) => {
                    return missing(
                        "sensor_height_mm",
                        "missing: focal_length_mm needs sensor_height_mm to give the field of view (or give fovy_deg)",
                    )
                }
                (None, Some(_)) => {
                    return missing(
                        "focal_length_mm",
                        "missing: sensor_height_mm needs focal_length_mm to give the field of view (or give fovy_deg)",
                    )
                }
                (None, None) => {
                    return missing(
                        "fovy_deg",
                        "missing: give fovy_deg, or focal_length_mm and sensor_height_mm",
                    )
                }
            }
        }
        if self.aperture_radius.is_none() && self.f_number.is_none() {
            return missing(
                "aperture_radius",
                "missing: give aperture_radius, or f_number (with focal_length_mm and units_per_mm)",
            );
        }
        if self.focus_distance.is_none() {
            return missing("focus_distance", "missing from the camera file");
        }
        Ok(())
    }
}

fn parse_json(text: &str, path: &Path) -> Result<CameraSpec> {
    serde_json::from_str(text).map_err(|e| Error::Json {
        path: PathBuf::from(path),
        msg: e.to_string(),
    })
}

fn camera_error(field: &'static str, msg: impl Into<String>) -> Error {
    Error::Camera {
        field,
        msg: msg.into(),
    }
}

/// Errors unless `v` is finite and > 0.
fn check_positive(field: &'static str, v: Option<f32>) -> Result<()> {
    match v {
        Some(v) if !(v.is_finite() && v > 0.0) => Err(camera_error(
            field,
            format!("must be a finite number > 0, got {v}"),
        )),
        _ => Ok(()),
    }
}

/// Errors unless every component of `v` is finite.
fn check_vector(field: &'static str, v: Option<[f32; 3]>) -> Result<()> {
    match v {
        Some(v) if !v.iter().all(|c| c.is_finite()) => Err(camera_error(
            field,
            format!("must be three finite numbers, got {v:?}"),
        )),
        _ => Ok(()),
    }
}

/// Checks every value present in `spec` on its own (DESIGN §2: impossible
/// values are errors naming the field).
fn validate(spec: &CameraSpec) -> Result<()> {
    if spec.width == Some(0) {
        return Err(camera_error("width", "must be at least 1 pixel"));
    }
    if spec.height == Some(0) {
        return Err(camera_error("height", "must be at least 1 pixel"));
    }
    check_vector("eye", spec.eye)?;
    check_vector("target", spec.target)?;
    check_vector("up", spec.up)?;
    if spec.up.is_some_and(|u| Vec3::from_array(u) == Vec3::ZERO) {
        return Err(camera_error("up", "must not be the zero vector"));
    }
    if let Some(a) = spec.fovy_deg {
        if a.is_nan() || a <= 0.0 || a >= 180.0 {
            return Err(camera_error(
                "fovy_deg",
                format!("must be strictly between 0 and 180 degrees, got {a}"),
            ));
        }
    }
    check_positive("focal_length_mm", spec.focal_length_mm)?;
    check_positive("sensor_height_mm", spec.sensor_height_mm)?;
    check_positive("units_per_mm", spec.units_per_mm)?;
    check_positive("f_number", spec.f_number)?;
    if let Some(r) = spec.aperture_radius {
        if !(r.is_finite() && r >= 0.0) {
            return Err(camera_error(
                "aperture_radius",
                format!("must be a finite number >= 0, got {r}"),
            ));
        }
    }
    check_positive("focus_distance", spec.focus_distance)?;
    Ok(())
}

/// The vertical field of view in degrees: `fovy_deg`, else
/// θ = 2·atan(h / 2f) from `focal_length_mm` and `sensor_height_mm`, else 40°.
fn resolve_fovy(spec: &CameraSpec) -> Result<f32> {
    if let Some(a) = spec.fovy_deg {
        return Ok(a);
    }
    match (spec.focal_length_mm, spec.sensor_height_mm) {
        (Some(f), Some(h)) => Ok((2.0 * (h / (2.0 * f)).atan()).to_degrees()),
        (Some(_), None) => Err(camera_error(
            "sensor_height_mm",
            "missing: focal_length_mm needs sensor_height_mm to give the field of view (or give fovy_deg)",
        )),
        (None, Some(_)) => Err(camera_error(
            "focal_length_mm",
            "missing: sensor_height_mm needs focal_length_mm to give the field of view (or give fovy_deg)",
        )),
        (None, None) => Ok(DEFAULT_FOVY_DEG),
    }
}

/// Whether `up` can orient a camera looking along `forward` (not parallel).
fn up_is_usable(forward: Vec3, up: Vec3) -> bool {
    forward.normalize().cross(up.normalize()).length() > 1e-6
}

/// The points that auto-framing and the automatic aperture look at: the
/// finite ones of `points`, or the bounding-box corners when there are none.
/// Borrows `points` (a cloud may hold a hundred million of them).
fn framing_points(points: &[Vec3], lo: Vec3, hi: Vec3) -> impl Iterator<Item = Vec3> + '_ {
    let corners: Vec<Vec3> = if points.iter().any(|p| p.is_finite()) {
        Vec::new()
    } else {
        (0..8)
            .map(|i| {
                Vec3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                )
            })
            .collect()
    };
    points
        .iter()
        .copied()
        .filter(|p| p.is_finite())
        .chain(corners)
}

/// The auto-framed eye: eye = target + (0, 0, d), looking along −z, with the
/// smallest d > 0 such that every point projects inside the image with a
/// [`FRAMING_MARGIN`] on each side and lies at least `near` in front of the
/// eye. Per point q = p − target with eye-space x = q·right, y = q·up' and
/// depth z = d + q·forward, the condition f_px·|x| / z ≤ (1/2 − margin)·W
/// (and likewise for y and H) gives
/// d ≥ f_px·|x| / ((1/2 − margin)·W) − q·forward.
fn auto_frame_eye(
    target: Vec3,
    up: Vec3,
    width: u32,
    height: u32,
    fovy_deg: f32,
    points: impl Iterator<Item = Vec3>,
    near: f32,
) -> Vec3 {
    let probe = Camera {
        width,
        height,
        eye: target + Vec3::Z,
        target,
        up,
        fovy_deg,
        aperture_radius: 0.0,
        focus_distance: 1.0,
    };
    let (right, up, forward) = probe.basis();
    let f = probe.f_px();
    let half_w = (0.5 - FRAMING_MARGIN) * width as f32;
    let half_h = (0.5 - FRAMING_MARGIN) * height as f32;
    let mut d = near;
    for p in points {
        let q = p - target;
        let ahead = q.dot(forward);
        let need = (f * q.dot(right).abs() / half_w)
            .max(f * q.dot(up).abs() / half_h)
            .max(near);
        d = d.max(need - ahead);
    }
    target + Vec3::new(0.0, 0.0, d)
}

/// Resolves a camera spec into a [`Camera`], field by field: the spec's
/// value if present, else the default of DESIGN §2.
///
/// * width × height: 640 × 480.
/// * field of view: `fovy_deg`, else 2·atan(h / 2f) from `focal_length_mm` and
///   `sensor_height_mm` (one without the other is an error naming the missing
///   one), else 40°.
/// * up: +y. target: the centre of the bounding box `cloud_min`..`cloud_max`.
/// * eye: auto-framed — looking along −z at the target from the nearest
///   distance at which every point of `points` (the bounding-box corners if
///   it is empty) projects inside the image with a 5 % margin on each side
///   (and at least 0.1 % of the box diagonal in front of the eye).
/// * aperture: `aperture_radius` wins; else `f_number` N gives R = f / 2N
///   with f = `focal_length_mm` · `units_per_mm` (both required); else the
///   automatic aperture: R such that the larger CoC at the nearest and the
///   farthest eye depth of `points` in front of the eye is max(4, H/60)
///   pixels. If every point is at the focus depth (or none is in front), R
///   falls back to 1 % of the bounding-box diagonal (1 % of S if the box is a
///   single point).
/// * focus distance: the eye depth of the target, (target − eye)·forward.
///
/// Impossible values are [`Error::Camera`] naming the field. The device's
/// maximum image size is checked by the renderer, not here.
pub fn resolve(
    spec: &CameraSpec,
    cloud_min: Vec3,
    cloud_max: Vec3,
    points: &[Vec3],
) -> Result<Camera> {
    validate(spec)?;
    let width = spec.width.unwrap_or(DEFAULT_WIDTH);
    let height = spec.height.unwrap_or(DEFAULT_HEIGHT);
    let fovy_deg = resolve_fovy(spec)?;
    let up = spec.up.map_or(Vec3::Y, Vec3::from_array);

    let diagonal = (cloud_max - cloud_min).length();
    let diagonal = if diagonal.is_finite() { diagonal } else { 0.0 };
    let target = match spec.target {
        Some(t) => Vec3::from_array(t),
        None => {
            let centre = (cloud_min + cloud_max) / 2.0;
            if !centre.is_finite() {
                return Err(camera_error(
                    "target",
                    "no default: the cloud's bounding box is empty or not finite",
                ));
            }
            centre
        }
    };

    let eye = match spec.eye {
        Some(e) => Vec3::from_array(e),
        None => {
            if !up_is_usable(-Vec3::Z, up) {
                return Err(camera_error(
                    "up",
                    format!(
                        "{up} is parallel to the auto-framing view direction (−z); give another up or an eye"
                    ),
                ));
            }
            let no_points = !points.iter().any(|p| p.is_finite());
            if no_points && !(cloud_min.is_finite() && cloud_max.is_finite()) {
                return Err(camera_error(
                    "eye",
                    "cannot auto-frame: no points and the cloud's bounding box is empty or not finite",
                ));
            }
            let near = if diagonal > 0.0 { 1e-3 * diagonal } else { 1.0 };
            let pts = framing_points(points, cloud_min, cloud_max);
            auto_frame_eye(target, up, width, height, fovy_deg, pts, near)
        }
    };
    if eye == target {
        return Err(camera_error(
            "eye",
            format!("must differ from the target, both are {eye}"),
        ));
    }
    if !up_is_usable(target - eye, up) {
        return Err(camera_error(
            "up",
            format!("{up} is parallel to the view direction from eye {eye} to target {target}"),
        ));
    }

    let forward = (target - eye).normalize();
    let focus_distance = spec
        .focus_distance
        .unwrap_or_else(|| (target - eye).dot(forward));

    let mut camera = Camera {
        width,
        height,
        eye,
        target,
        up,
        fovy_deg,
        aperture_radius: 0.0,
        focus_distance,
    };
    camera.aperture_radius = match (spec.aperture_radius, spec.f_number) {
        (Some(r), _) => r,
        (None, Some(n)) => {
            let msg = "f_number needs focal_length_mm and units_per_mm";
            let f_mm = spec
                .focal_length_mm
                .ok_or_else(|| camera_error("focal_length_mm", msg))?;
            let units = spec
                .units_per_mm
                .ok_or_else(|| camera_error("units_per_mm", msg))?;
            f_mm * units / (2.0 * n)
        }
        (None, None) => auto_aperture(
            &camera,
            framing_points(points, cloud_min, cloud_max),
            diagonal,
        ),
    };
    Ok(camera)
}

/// The automatic aperture radius: R such that the larger CoC at the nearest
/// and farthest eye depth of `points` (those in front of the eye) is
/// max(4, H/60) pixels. The CoC is linear in R, so R = goal / CoC(R = 1).
/// Falls back to 1 % of the box diagonal (or of S) when there is no CoC to
/// aim for (every point at the focus depth, or none in front).
fn auto_aperture(camera: &Camera, points: impl Iterator<Item = Vec3>, diagonal: f32) -> f32 {
    let (_, _, forward) = camera.basis();
    let (mut near, mut far) = (f32::INFINITY, 0.0f32);
    for p in points {
        // The eye depth z of `Camera::eye_from_world`, with the basis hoisted.
        let z = (p - camera.eye).dot(forward);
        if z > 0.0 && z.is_finite() {
            near = near.min(z);
            far = far.max(z);
        }
    }
    let goal = (camera.height as f32 / 60.0).max(4.0);
    let unit = Camera {
        aperture_radius: 1.0,
        ..*camera
    };
    let coc_per_unit = if near <= far {
        unit.max_coc_px(near, far)
    } else {
        0.0
    };
    if coc_per_unit > 0.0 && coc_per_unit.is_finite() {
        goal / coc_per_unit
    } else if diagonal > 0.0 {
        0.01 * diagonal
    } else {
        0.01 * camera.focus_distance
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framing_points_fall_back_to_the_box_corners() {
        let (lo, hi) = (Vec3::new(-1.0, -2.0, -3.0), Vec3::new(1.0, 2.0, 3.0));
        // Finite points are used as they are, non-finite ones skipped.
        let points = [Vec3::ONE, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::ZERO];
        let used: Vec<Vec3> = framing_points(&points, lo, hi).collect();
        assert_eq!(used, vec![Vec3::ONE, Vec3::ZERO]);
        // No finite point: the 8 corners.
        let corners: Vec<Vec3> = framing_points(&[], lo, hi).collect();
        assert_eq!(corners.len(), 8);
        assert!(corners.contains(&lo) && corners.contains(&hi));
        assert!(corners.contains(&Vec3::new(1.0, -2.0, 3.0)));
    }

    #[test]
    fn up_parallel_to_the_view_is_unusable() {
        assert!(up_is_usable(-Vec3::Z, Vec3::Y));
        assert!(up_is_usable(-Vec3::Z, Vec3::new(0.0, 1.0, 1.0)));
        assert!(!up_is_usable(-Vec3::Z, Vec3::Z * 3.0));
        assert!(!up_is_usable(Vec3::new(0.0, -2.0, 0.0), Vec3::Y));
    }
}
