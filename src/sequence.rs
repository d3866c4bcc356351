//! Sequences (DESIGN §8's `--frames`, `--path`, `--frame-range`): the
//! camera of every frame of a shot — a turntable orbit, a focus pull, an
//! aperture pull, or a camera path of keyframes — and the numbered output
//! files. A frame's camera is a function of its number alone, so that any
//! range of a sequence rendered apart equals the same frames of the whole.
//! `docs/SEQUENCES.md` gives the rules for users.

use std::path::{Path, PathBuf};

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};

use crate::camera::{Camera, CameraSpec};
use crate::error::{Error, Result};

/// The largest frame number a sequence may have (Blender's, 1,048,574):
/// every frame's camera is resolved before the first is rendered, so a
/// mistyped count fails here instead of filling the memory.
pub const MAX_FRAME: u32 = 1_048_574;

/// Frames made by flags (`--frames N` with `--orbit`, `--focus-from/-to`,
/// `--aperture-from/-to`), numbered 1 to N, each a change of one resolved
/// base camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// N, at least 1.
    pub frames: u32,
    /// Degrees the eye turns about the target over the N frames, around the
    /// camera's up axis (counter-clockwise seen from above, for positive
    /// degrees): frame i at `orbit_deg · (i − 1) / N`, so that 360 loops
    /// without repeating a frame.
    pub orbit_deg: Option<f64>,
    /// Focus distance at frame 1 and at frame N (linear between, both ends
    /// included).
    pub focus: Option<[f32; 2]>,
    /// Aperture radius at frame 1 and at frame N (linear, ends included).
    pub aperture: Option<[f32; 2]>,
}

/// The linear blend of `[a, b]` at `t` in [0, 1], computed in f64, exact
/// at both ends.
fn lerp(ab: [f32; 2], t: f64) -> f32 {
    if t <= 0.0 {
        return ab[0];
    }
    if t >= 1.0 {
        return ab[1];
    }
    (f64::from(ab[0]) + (f64::from(ab[1]) - f64::from(ab[0])) * t) as f32
}

impl Motion {
    /// Checks the numbers: N ≥ 1, a finite orbit, focus distances > 0 and
    /// apertures ≥ 0, all finite; errors name the flag.
    pub fn check(&self) -> Result<()> {
        if self.frames == 0 {
            return Err(invalid("--frames must be at least 1"));
        }
        if self.frames > MAX_FRAME {
            return Err(invalid(format!(
                "--frames {} is more than a sequence may have ({MAX_FRAME})",
                self.frames
            )));
        }
        if let Some(d) = self.orbit_deg.filter(|d| !d.is_finite()) {
            return Err(invalid(format!("--orbit must be a finite number, not {d}")));
        }
        if let Some([a, b]) = self.focus {
            if !(a.is_finite() && b.is_finite() && a > 0.0 && b > 0.0) {
                return Err(invalid(format!(
                    "--focus-from and --focus-to must be finite numbers > 0, not {a} and {b}"
                )));
            }
        }
        if let Some([a, b]) = self.aperture {
            if !(a.is_finite() && b.is_finite() && a >= 0.0 && b >= 0.0) {
                return Err(invalid(format!(
                    "--aperture-from and --aperture-to must be finite numbers >= 0, not {a} and {b}"
                )));
            }
        }
        Ok(())
    }

    /// The frame numbers, 1 to N.
    pub fn frames(&self) -> (u32, u32) {
        (1, self.frames)
    }

    /// The camera of frame `frame` (1 to N): `base` turned about its target
    /// by the orbit's share, with the pulled focus and aperture.
    pub fn camera(&self, base: &Camera, frame: u32) -> Camera {
        let i = f64::from(frame.saturating_sub(1));
        let n = f64::from(self.frames.max(1));
        let t = if self.frames > 1 { i / (n - 1.0) } else { 0.0 };
        let mut camera = *base;
        if let Some(deg) = self.orbit_deg {
            let angle = (deg * i / n).to_radians();
            let axis = base.up.as_dvec3().normalize();
            let target = base.target.as_dvec3();
            let arm = base.eye.as_dvec3() - target;
            camera.eye = (target + DQuat::from_axis_angle(axis, angle) * arm).as_vec3();
        }
        if let Some(focus) = self.focus {
            camera.focus_distance = lerp(focus, t);
        }
        if let Some(aperture) = self.aperture {
            camera.aperture_radius = lerp(aperture, t);
        }
        camera
    }
}

/// One keyframe of a camera path: a frame number and any camera-file
/// fields.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Keyframe {
    pub frame: u32,
    #[serde(flatten)]
    pub camera: CameraSpec,
}

/// A camera path file (`--path PATH.json`): keyframes of camera-file
/// fields, each with a frame number; the sequence runs from the first
/// keyframe's frame to the last's. `eye` and `target` move on a cubic
/// Hermite spline through the keyframes (Catmull–Rom tangents scaled to the
/// frame gaps; two keyframes give a straight line at constant speed);
/// `up`, the field of view, the focal length, the aperture and the focus
/// distance change linearly. A keyframe's frame gets its fields exactly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraPath {
    pub keyframes: Vec<Keyframe>,
}

/// The fields a keyframe may change over a path (the others must agree in
/// every keyframe that gives them).
const ANIMATED: &str =
    "eye, target, up, fovy_deg, focal_length_mm, aperture_radius, f_number, focus_distance";

impl CameraPath {
    /// Reads and checks a path file; errors name the file and the field.
    pub fn from_json_file(path: &Path) -> Result<CameraPath> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let parsed: CameraPath = serde_json::from_str(&text).map_err(|e| Error::Json {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })?;
        parsed.check().map_err(|e| match e {
            Error::InvalidArgument(msg) => {
                Error::InvalidArgument(format!("{}: {msg}", path.display()))
            }
            e => e,
        })?;
        Ok(parsed)
    }

    /// Checks the keyframes: at least one, frames strictly increasing, each
    /// animated field in every keyframe or in none, every other field the
    /// same wherever given.
    pub fn check(&self) -> Result<()> {
        let k = &self.keyframes;
        if k.is_empty() {
            return Err(invalid("a camera path needs at least one keyframe"));
        }
        if let Some(key) = k.iter().find(|f| f.frame > MAX_FRAME) {
            return Err(invalid(format!(
                "keyframe frame {} is above the largest frame number ({MAX_FRAME})",
                key.frame
            )));
        }
        for pair in k.windows(2) {
            if pair[1].frame <= pair[0].frame {
                return Err(invalid(format!(
                    "keyframe frames must increase: {} follows {}",
                    pair[1].frame, pair[0].frame
                )));
            }
        }
        macro_rules! all_or_none {
            ($($field:ident),*) => {$(
                let given = k.iter().filter(|f| f.camera.$field.is_some()).count();
                if given != 0 && given != k.len() {
                    return Err(invalid(format!(
                        "'{}' is in {given} of {} keyframes: an animated field ({ANIMATED}) must be in every keyframe or in none",
                        stringify!($field), k.len()
                    )));
                }
            )*};
        }
        all_or_none!(
            eye,
            target,
            up,
            fovy_deg,
            focal_length_mm,
            aperture_radius,
            f_number,
            focus_distance
        );
        macro_rules! constant {
            ($($field:ident),*) => {$(
                let mut values = k.iter().filter_map(|f| f.camera.$field.map(|v| (f.frame, v)));
                if let Some((_, first)) = values.next() {
                    if let Some((frame, other)) = values.find(|(_, v)| *v != first) {
                        return Err(invalid(format!(
                            "'{}' changes at keyframe {frame} ({other:?} after {first:?}); only {ANIMATED} may change",
                            stringify!($field)
                        )));
                    }
                }
            )*};
        }
        constant!(
            coordinates,
            origin,
            width,
            height,
            sensor_height_mm,
            sensor_width_mm,
            units_per_mm
        );
        Ok(())
    }

    /// The path's frames, first and last.
    pub fn frames(&self) -> (u32, u32) {
        let k = &self.keyframes;
        (k[0].frame, k[k.len() - 1].frame)
    }

    /// The camera fields at `frame` (clamped to the path's frames): a
    /// keyframe's own at its frame, interpolated between.
    pub fn spec_at(&self, frame: u32) -> CameraSpec {
        let k = &self.keyframes;
        let (first, last) = self.frames();
        let frame = frame.clamp(first, last);
        if let Some(key) = k.iter().find(|f| f.frame == frame) {
            return self.with_constants(key.camera.clone());
        }
        // Between keyframes s and s + 1.
        let s = k
            .iter()
            .rposition(|f| f.frame < frame)
            .expect("frame > first");
        let (a, b) = (&k[s].camera, &k[s + 1].camera);
        let t = f64::from(frame - k[s].frame) / f64::from(k[s + 1].frame - k[s].frame);
        let scalar = |get: fn(&CameraSpec) -> Option<f32>| -> Option<f32> {
            Some(lerp([get(a)?, get(b)?], t))
        };
        let spec = CameraSpec {
            eye: self.spline(s, frame, |c| c.eye),
            target: self.spline(s, frame, |c| c.target),
            up: match (a.up, b.up) {
                (Some(u), Some(v)) => Some(std::array::from_fn(|i| lerp([u[i], v[i]], t))),
                _ => None,
            },
            fovy_deg: scalar(|c| c.fovy_deg),
            focal_length_mm: scalar(|c| c.focal_length_mm),
            aperture_radius: scalar(|c| c.aperture_radius),
            f_number: scalar(|c| c.f_number),
            focus_distance: scalar(|c| c.focus_distance),
            ..CameraSpec::default()
        };
        self.with_constants(spec)
    }

    /// `spec` with the path's constant fields (those no keyframe animates).
    fn with_constants(&self, spec: CameraSpec) -> CameraSpec {
        let find = |get: &dyn Fn(&CameraSpec) -> bool| {
            self.keyframes
                .iter()
                .map(|f| &f.camera)
                .find(|c| get(c))
                .cloned()
                .unwrap_or_default()
        };
        CameraSpec {
            coordinates: find(&|c| c.coordinates.is_some()).coordinates,
            origin: find(&|c| c.origin.is_some()).origin,
            width: find(&|c| c.width.is_some()).width,
            height: find(&|c| c.height.is_some()).height,
            sensor_height_mm: find(&|c| c.sensor_height_mm.is_some()).sensor_height_mm,
            sensor_width_mm: find(&|c| c.sensor_width_mm.is_some()).sensor_width_mm,
            units_per_mm: find(&|c| c.units_per_mm.is_some()).units_per_mm,
            ..spec
        }
    }

    /// A point field on the Hermite spline of segment `s` at `frame`.
    fn spline(
        &self,
        s: usize,
        frame: u32,
        get: fn(&CameraSpec) -> Option<[f64; 3]>,
    ) -> Option<[f64; 3]> {
        let k = &self.keyframes;
        let p = |i: usize| get(&k[i].camera).map(DVec3::from_array);
        let t = |i: usize| f64::from(k[i].frame);
        // Catmull–Rom tangent at keyframe i, per frame; one-sided at the ends.
        let tangent = |i: usize| -> Option<DVec3> {
            let (lo, hi) = (i.saturating_sub(1), (i + 1).min(k.len() - 1));
            Some((p(hi)? - p(lo)?) / (t(hi) - t(lo)))
        };
        let (p0, p1) = (p(s)?, p(s + 1)?);
        let (m0, m1) = (tangent(s)?, tangent(s + 1)?);
        let h = t(s + 1) - t(s);
        let u = (f64::from(frame) - t(s)) / h;
        let (u2, u3) = (u * u, u * u * u);
        let h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
        let h10 = u3 - 2.0 * u2 + u;
        let h01 = -2.0 * u3 + 3.0 * u2;
        let h11 = u3 - u2;
        Some((h00 * p0 + h10 * h * m0 + h01 * p1 + h11 * h * m1).to_array())
    }

    /// The path of a rendered sequence: one keyframe per frame, with each
    /// frame's camera (`--print-camera` of a sequence).
    pub fn of_frames(frames: impl IntoIterator<Item = (u32, CameraSpec)>) -> CameraPath {
        CameraPath {
            keyframes: frames
                .into_iter()
                .map(|(frame, camera)| Keyframe { frame, camera })
                .collect(),
        }
    }

    /// The path as pretty-printed JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a camera path always serialises")
    }
}

/// An output path with a frame number in it: `shot_%04d.png` (printf's
/// `%d` or `%0Nd`; `%%` is a literal `%`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FramePattern {
    before: String,
    digits: usize,
    after: String,
}

impl FramePattern {
    /// The pattern in `path`, or None when it holds no `%d`. Errors: more
    /// than one frame number, or a `%` that is neither `%d`, `%0Nd` nor `%%`.
    pub fn parse(path: &Path) -> Result<Option<FramePattern>> {
        Ok(FramePattern::parse_with_literal(path)?.0)
    }

    /// The file a name without a frame number writes: `%%` is a `%` there
    /// too (one rule for images and sequences), so `50%%.png` writes
    /// `50%.png`. A name without `%` is returned as it is (bytes that are
    /// not UTF-8 included).
    pub fn single_image(path: &Path) -> Result<PathBuf> {
        if !path.to_string_lossy().contains('%') {
            return Ok(path.to_path_buf());
        }
        match FramePattern::parse_with_literal(path)? {
            (None, literal) => Ok(PathBuf::from(literal)),
            (Some(_), _) => Err(invalid(format!(
                "{}: a frame number pattern names a sequence",
                path.display()
            ))),
        }
    }

    /// The pattern, if any, and the text after it (the whole name, with
    /// `%%` as `%`, when there is none).
    fn parse_with_literal(path: &Path) -> Result<(Option<FramePattern>, String)> {
        let text = path.to_string_lossy();
        let bad = |why: &str| {
            invalid(format!(
                "{}: {why} (a frame number is written %d or %04d; %% is a %)",
                path.display()
            ))
        };
        let mut pattern: Option<FramePattern> = None;
        let mut literal = String::new();
        let mut chars = text.chars().peekable();
        while let Some(c) = chars.next() {
            if c != '%' {
                literal.push(c);
                continue;
            }
            if chars.peek() == Some(&'%') {
                chars.next();
                literal.push('%');
                continue;
            }
            let mut width = String::new();
            while let Some(d) = chars.peek().filter(|d| d.is_ascii_digit()) {
                width.push(*d);
                chars.next();
            }
            if chars.next() != Some('d') || (!width.is_empty() && !width.starts_with('0')) {
                return Err(bad("not a frame number pattern"));
            }
            if pattern.is_some() {
                return Err(bad("more than one frame number"));
            }
            let digits = if width.is_empty() {
                0
            } else {
                width
                    .parse::<usize>()
                    .ok()
                    .filter(|w| *w <= 10)
                    .ok_or_else(|| bad("at most 10 digits"))?
            };
            pattern = Some(FramePattern {
                before: std::mem::take(&mut literal),
                digits,
                after: String::new(),
            });
        }
        Ok(match pattern {
            Some(p) => (
                Some(FramePattern {
                    after: literal,
                    ..p
                }),
                String::new(),
            ),
            None => (None, literal),
        })
    }

    /// The path of frame `frame`.
    pub fn path(&self, frame: u32) -> PathBuf {
        PathBuf::from(format!(
            "{}{:0width$}{}",
            self.before,
            frame,
            self.after,
            width = self.digits
        ))
    }
}

/// `--frame-range A-B` (or `A`): the frames to render, both ends included.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRange {
    pub first: u32,
    pub last: u32,
}

impl FrameRange {
    /// Parses `A-B` or `A` (whole numbers, A ≤ B).
    pub fn parse(s: &str) -> Result<FrameRange> {
        let bad = || {
            invalid(format!(
                "--frame-range takes A-B or A (whole numbers, A <= B), not '{s}'"
            ))
        };
        let number = |t: &str| t.trim().parse::<u32>().map_err(|_| bad());
        let range = match s.split_once('-') {
            Some((a, b)) => FrameRange {
                first: number(a)?,
                last: number(b)?,
            },
            None => {
                let a = number(s)?;
                FrameRange { first: a, last: a }
            }
        };
        if range.first > range.last {
            return Err(bad());
        }
        Ok(range)
    }

    /// Checks that the range is one (A ≤ B) and lies within the sequence's
    /// frames.
    pub fn within(self, (first, last): (u32, u32)) -> Result<FrameRange> {
        if self.first > self.last {
            return Err(invalid(format!(
                "--frame-range takes A-B or A (whole numbers, A <= B), not '{}-{}'",
                self.first, self.last
            )));
        }
        if self.first < first || self.last > last {
            return Err(invalid(format!(
                "--frame-range {}-{} is outside the sequence's frames {first}-{last}",
                self.first, self.last
            )));
        }
        Ok(self)
    }
}

fn invalid(msg: impl Into<String>) -> Error {
    Error::InvalidArgument(msg.into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_number_frames_as_printf_does() {
        let p = FramePattern::parse(Path::new("out/shot_%04d.png"))
            .unwrap()
            .unwrap();
        assert_eq!(p.path(7), PathBuf::from("out/shot_0007.png"));
        assert_eq!(p.path(12345), PathBuf::from("out/shot_12345.png"));
        let p = FramePattern::parse(Path::new("f%d.exr")).unwrap().unwrap();
        assert_eq!(p.path(3), PathBuf::from("f3.exr"));
        let p = FramePattern::parse(Path::new("100%%_%03d.png"))
            .unwrap()
            .unwrap();
        assert_eq!(p.path(5), PathBuf::from("100%_005.png"));
        assert_eq!(FramePattern::parse(Path::new("shot.png")).unwrap(), None);
        for bad in [
            "a_%s.png",
            "a_%4d.png",
            "a_%d_%d.png",
            "a_%.png",
            "a_%011d.png",
        ] {
            assert!(FramePattern::parse(Path::new(bad)).is_err(), "{bad}");
        }
    }

    #[test]
    fn frame_ranges_parse_and_must_lie_in_the_sequence() {
        assert_eq!(
            FrameRange::parse("2-5").unwrap(),
            FrameRange { first: 2, last: 5 }
        );
        assert_eq!(
            FrameRange::parse("3").unwrap(),
            FrameRange { first: 3, last: 3 }
        );
        for bad in ["5-2", "a-3", "-3", "1-", "", "1-2-3"] {
            assert!(FrameRange::parse(bad).is_err(), "{bad}");
        }
        assert!(FrameRange::parse("2-5").unwrap().within((1, 5)).is_ok());
        assert!(FrameRange::parse("0-5").unwrap().within((1, 5)).is_err());
        assert!(FrameRange::parse("2-6").unwrap().within((1, 5)).is_err());
    }
}
