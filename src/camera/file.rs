//! The camera file (`--camera FILE.json`, DESIGN §2): the [`CameraSpec`]
//! schema, parsing, command-line overrides, the completeness check, the
//! per-field validation and the defaults that need no cloud (image size,
//! field of view); and [`Camera`]'s conversion back to a camera file.

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

use super::{ApertureSpec, Camera};
use crate::error::{Error, Result};

/// Default image size without a camera (the paper's demo resolution).
pub const DEFAULT_WIDTH: u32 = 640;
/// Default image height without a camera.
pub const DEFAULT_HEIGHT: u32 = 480;
/// Default vertical field of view in degrees.
pub const DEFAULT_FOVY_DEG: f32 = 40.0;
/// The widest and highest image, pixels: frames beyond the device's images
/// render in tiles (docs/ARCHITECTURE.md, "Posters in tiles"); a float
/// pixel position still resolves 1/128 px at this size.
pub const MAX_SIDE_PX: u32 = 65536;
/// The most pixels of an image (2^30: 3 GiB of 8-bit RGB, 16 GiB of EXR
/// RGBA on the host).
pub const MAX_PIXELS: u64 = 1 << 30;

/// Which coordinates a camera's `eye` and `target` are in: those of the
/// file the cloud came from (e.g. UTM metres of a LAS tile), or the scene's,
/// re-centred on the cloud's origin (`PointCloud::origin`; the default).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Coordinates {
    /// The input file's coordinates.
    File,
    /// The scene's: the file's minus the cloud's origin.
    #[default]
    Recentred,
}

/// A camera file (`--camera FILE.json`, DESIGN §2) or the camera flags: every
/// field optional, named as in the JSON. Unknown JSON fields are ignored.
/// [`resolve`] fills in the defaults. `eye` and `target` are in the
/// coordinates `coordinates` names; [`CameraSpec::in_scene`] takes them to
/// the scene's before [`resolve`].
///
/// [`resolve`]: super::resolve
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraSpec {
    /// Which coordinates `eye` and `target` are in (default: recentred).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coordinates: Option<Coordinates>,
    /// With `"coordinates": "recentred"`: the origin (file coordinates) the
    /// camera was re-centred on, written by `--print-camera`; a cloud
    /// re-centred elsewhere moves the camera by the difference.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub origin: Option<[f64; 3]>,
    /// Image width in pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<u32>,
    /// Image height in pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<u32>,
    /// Eye (lens centre) position (double precision: file coordinates may
    /// be millions of metres).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eye: Option<[f64; 3]>,
    /// Point looked at.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<[f64; 3]>,
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
    /// Sensor height in mm (with `focal_length_mm`): the sensor fitted to
    /// the image's height (Blender's vertical sensor fit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_height_mm: Option<f32>,
    /// Sensor width in mm (with `focal_length_mm`), instead of the height:
    /// the sensor fitted to the image's width (Blender's horizontal fit),
    /// θ = 2·atan(w·H / (2f·W)).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_width_mm: Option<f32>,
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
    /// The aperture's shape (absent fields: round).
    #[serde(flatten)]
    pub aperture: ApertureSpec,
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
        let spec = parse_json(&text, path)?;
        let dir = path.parent().unwrap_or(Path::new(""));
        Ok(CameraSpec {
            aperture: spec.aperture.clone().relative_to(dir),
            ..spec
        })
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
            coordinates: flags.coordinates.or(self.coordinates),
            origin: flags.origin.or(self.origin),
            width: flags.width.or(self.width),
            height: flags.height.or(self.height),
            eye: flags.eye.or(self.eye),
            target: flags.target.or(self.target),
            up: flags.up.or(self.up),
            fovy_deg: flags.fovy_deg.or(self.fovy_deg),
            focal_length_mm: flags.focal_length_mm.or(self.focal_length_mm),
            sensor_height_mm: flags.sensor_height_mm.or(self.sensor_height_mm),
            sensor_width_mm: flags.sensor_width_mm.or(self.sensor_width_mm),
            aperture_radius: flags.aperture_radius.or(self.aperture_radius),
            f_number: flags.f_number.or(self.f_number),
            units_per_mm: flags.units_per_mm.or(self.units_per_mm),
            focus_distance: flags.focus_distance.or(self.focus_distance),
            aperture: self.aperture.overridden_by(&flags.aperture),
        }
    }

    /// The spec as a pretty-printed camera file (unset fields left out).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a camera spec always serialises")
    }

    /// This spec with `eye` and `target` in the scene's coordinates, for a
    /// cloud whose origin is `cloud_origin` (file coordinates): the file's
    /// coordinates less the origin, or re-centred ones moved by the
    /// difference between the spec's `origin` and the cloud's, in double
    /// precision. The result has no `coordinates` or `origin`. Errors:
    /// an `origin` given with file coordinates, a non-finite origin.
    pub fn in_scene(&self, cloud_origin: DVec3) -> Result<CameraSpec> {
        let shift =
            match (self.coordinates.unwrap_or_default(), self.origin) {
                (Coordinates::File, Some(_)) => return Err(camera_error(
                    "origin",
                    "only with \"coordinates\": \"recentred\" (file coordinates need no origin)",
                )),
                (Coordinates::File, None) => -cloud_origin,
                (Coordinates::Recentred, Some(o)) => {
                    let o = DVec3::from_array(o);
                    if !o.is_finite() {
                        return Err(camera_error(
                            "origin",
                            format!("must be three finite numbers, got {o}"),
                        ));
                    }
                    o - cloud_origin
                }
                (Coordinates::Recentred, None) => DVec3::ZERO,
            };
        let moved = |v: Option<[f64; 3]>| v.map(|v| (DVec3::from_array(v) + shift).to_array());
        Ok(CameraSpec {
            coordinates: None,
            origin: None,
            eye: moved(self.eye),
            target: moved(self.target),
            ..self.clone()
        })
    }

    /// Checks that a camera file is complete (DESIGN §2): an error naming the
    /// first missing field among width, height, eye, target, the field of
    /// view (`fovy_deg`, or `focal_length_mm` + `sensor_height_mm`), the
    /// aperture (`aperture_radius` or `f_number`) and focus_distance. `up`
    /// may be left out (+y). Values are checked by [`resolve`].
    ///
    /// [`resolve`]: super::resolve
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
            match (
                self.focal_length_mm,
                self.sensor_height_mm.or(self.sensor_width_mm),
            ) {
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

pub(super) fn camera_error(field: &'static str, msg: impl Into<String>) -> Error {
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
fn check_vector<T: Copy + Into<f64> + std::fmt::Debug>(
    field: &'static str,
    v: Option<[T; 3]>,
) -> Result<()> {
    match v {
        Some(v) if !v.iter().all(|&c| c.into().is_finite()) => Err(camera_error(
            field,
            format!("must be three finite numbers, got {v:?}"),
        )),
        _ => Ok(()),
    }
}

/// Checks every value present in `spec` on its own (DESIGN §2: impossible
/// values are errors naming the field).
pub(super) fn validate(spec: &CameraSpec) -> Result<()> {
    for (name, side) in [("width", spec.width), ("height", spec.height)] {
        match side {
            Some(0) => return Err(camera_error(name, "must be at least 1 pixel")),
            Some(n) if n > MAX_SIDE_PX => {
                return Err(camera_error(
                    name,
                    format!("{n} pixels is more than the {MAX_SIDE_PX} pointlens renders"),
                ))
            }
            _ => {}
        }
    }
    if let (Some(w), Some(h)) = (spec.width, spec.height) {
        if w as u64 * h as u64 > MAX_PIXELS {
            return Err(camera_error(
                "width",
                format!(
                    "{w}x{h} is {} pixels, more than the {MAX_PIXELS} (2^30) pointlens renders",
                    w as u64 * h as u64
                ),
            ));
        }
    }
    check_vector("eye", spec.eye)?;
    check_vector("target", spec.target)?;
    check_vector("up", spec.up)?;
    check_vector("origin", spec.origin)?;
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
    check_positive("sensor_width_mm", spec.sensor_width_mm)?;
    if spec.sensor_height_mm.is_some() && spec.sensor_width_mm.is_some() {
        return Err(camera_error(
            "sensor_width_mm",
            "give sensor_height_mm or sensor_width_mm, not both: the one given is fitted to the image's height or width",
        ));
    }
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
    spec.aperture.validate()
}

/// The vertical field of view in degrees for a `width` × `height` image:
/// `fovy_deg`, else θ = 2·atan(h / 2f) from `focal_length_mm` and
/// `sensor_height_mm`, or θ = 2·atan(w·H / (2f·W)) from `sensor_width_mm`
/// (the sensor's width fitted to the image's), else 40°.
pub(super) fn resolve_fovy(spec: &CameraSpec, width: u32, height: u32) -> Result<f32> {
    if let Some(a) = spec.fovy_deg {
        return Ok(a);
    }
    let sensor_h = match (spec.sensor_height_mm, spec.sensor_width_mm) {
        (Some(h), _) => Some(f64::from(h)),
        (None, Some(w)) => Some(f64::from(w) * f64::from(height) / f64::from(width)),
        (None, None) => None,
    };
    match (spec.focal_length_mm, sensor_h) {
        (Some(f), Some(h)) => Ok((2.0 * (h / (2.0 * f64::from(f))).atan()).to_degrees() as f32),
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

/// An f32 as the f64 with the same shortest decimal form (0.1f32 → 0.1,
/// not 0.10000000149011612), so that camera files print as typed; it reads
/// back as the same f32.
fn shortest_f64(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(f64::from(v))
}

impl Camera {
    /// The camera as a complete camera file: width, height, eye, target, up,
    /// fovy_deg, aperture_radius and focus_distance, in the scene's
    /// coordinates (no `coordinates` field).
    pub fn to_spec(&self) -> CameraSpec {
        CameraSpec {
            width: Some(self.width),
            height: Some(self.height),
            eye: Some(self.eye.to_array().map(shortest_f64)),
            target: Some(self.target.to_array().map(shortest_f64)),
            up: Some(self.up.to_array()),
            fovy_deg: Some(self.fovy_deg),
            aperture_radius: Some(self.aperture_radius),
            focus_distance: Some(self.focus_distance),
            aperture: self.aperture.to_spec(),
            ..CameraSpec::default()
        }
    }

    /// The camera as a pretty-printed camera file (`--print-camera`); reading
    /// it back with [`CameraSpec::from_json_str`] and [`resolve`] gives this
    /// camera again.
    ///
    /// [`resolve`]: super::resolve
    pub fn to_json(&self) -> String {
        self.to_spec().to_json()
    }

    /// The camera as a complete camera file in the given coordinates, for a
    /// cloud whose origin is `cloud_origin` (file coordinates): file
    /// coordinates add the origin to `eye` and `target` (double precision);
    /// recentred ones record the origin (when not zero) so that the file
    /// stays right for a cloud re-centred elsewhere. Reading it back with
    /// [`CameraSpec::in_scene`] and [`resolve`] gives this camera again.
    ///
    /// [`resolve`]: super::resolve
    pub fn to_spec_in(&self, coordinates: Coordinates, cloud_origin: DVec3) -> CameraSpec {
        let spec = self.to_spec();
        match coordinates {
            Coordinates::Recentred => CameraSpec {
                coordinates: Some(Coordinates::Recentred),
                origin: (cloud_origin != DVec3::ZERO).then_some(cloud_origin.to_array()),
                ..spec
            },
            Coordinates::File => {
                let file = |v: Option<[f64; 3]>| {
                    v.map(|v| (DVec3::from_array(v) + cloud_origin).to_array())
                };
                CameraSpec {
                    coordinates: Some(Coordinates::File),
                    eye: file(spec.eye),
                    target: file(spec.target),
                    ..spec
                }
            }
        }
    }
}
