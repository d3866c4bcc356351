//! The in-memory point cloud every loader produces and every pass consumes:
//! the type alone. Reading files is `input`'s; the splat hierarchy and the
//! spacing statistics are `tree`'s.

use std::path::Path;

use glam::{DVec3, Vec3};

/// A coordinate in the file's units for people to read: rounded to a
/// millionth (637240.4500000001 → 637240.45), far below any LAS scale.
pub fn display_coord(v: f64) -> String {
    format!("{}", (v * 1e6).round() / 1e6)
}

/// A point cloud as loaded: positions in scene units, colors in linear light.
#[derive(Debug, Clone, Default)]
pub struct PointCloud {
    pub positions: Vec<Vec3>,
    /// Linear-light RGB in [0, 1], one per point (a constant color when the
    /// file had none; see `has_colors`).
    pub colors: Vec<Vec3>,
    /// Unit normals, one per point, when the file had them.
    pub normals: Option<Vec<Vec3>>,
    /// Whether the file carried per-point colors.
    pub has_colors: bool,
    /// Names of the vertex properties the file declared, in file order
    /// (e.g. `["x", "y", "z", "red", "green", "blue"]`), for `info`.
    pub attributes: Vec<String>,
    /// The scene's origin in the file's coordinates: a point's position in
    /// the file is `origin + position`, in double precision. LAS and LAZ
    /// clouds are re-centred (see `las`); PLY clouds keep the file's
    /// coordinates (zero) unless `--origin` is given or their coordinates
    /// are double (or 32-bit integers) far from zero
    /// (`input::ply::load_ply_at`).
    pub origin: DVec3,
    /// Whether the file says its z axis points up: LAS/LAZ always (by
    /// their specification), a PLY whose header has a `comment up z` line
    /// ([`crate::input::ply::says_z_up`]). The default camera then looks
    /// at the cloud obliquely with z up (`camera::resolve_for`).
    pub z_up: bool,
    /// Whether the colors are the file's RGB (LAS: a color format whose
    /// values are not all zero; PLY: `has_colors`).
    pub has_rgb: bool,
    /// Per-point LAS intensities, for `--color intensity`.
    pub intensities: Option<Vec<u16>>,
    /// Per-point LAS return number and count of returns
    /// ([`crate::color::pack_return`]), for `--color return`.
    pub returns: Option<Vec<u8>>,
    /// Per-point classification codes (ASPRS classes), when the file had them.
    pub classifications: Option<Vec<u8>>,
    /// What `info` prints about the file beyond the cloud itself, in order:
    /// `(name, value)` (format, version, scale, offset, CRS, …).
    pub file_info: Vec<(String, String)>,
}

impl PointCloud {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Moves the scene's origin to `origin` (file coordinates): every
    /// position becomes `(origin_old + p) − origin`, computed in f64. An
    /// error (the message) when `origin` is not finite or a position would
    /// not fit in f32.
    pub fn recentre(&mut self, origin: DVec3) -> std::result::Result<(), String> {
        if !origin.is_finite() {
            return Err(format!(
                "--origin must be three finite numbers, got {origin}"
            ));
        }
        let shift = self.origin - origin;
        for p in &mut self.positions {
            let q = (p.as_dvec3() + shift).as_vec3();
            if !q.is_finite() {
                return Err(format!(
                    "a point at {} does not fit in f32 after re-centring on {origin}",
                    p.as_dvec3() + self.origin
                ));
            }
            *p = q;
        }
        self.origin = origin;
        Ok(())
    }

    /// The bounding box: (min corner, max corner); zeros for an empty cloud.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        if self.positions.is_empty() {
            return (Vec3::ZERO, Vec3::ZERO);
        }
        self.positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        )
    }

    /// The brightest linear colour channel of any point (1 is white; above
    /// it a highlight: PLY float colours above 1). 0 for no points.
    pub fn brightest(&self) -> f32 {
        self.colors
            .iter()
            .fold(0.0f32, |m, c| m.max(c.max_element()))
    }

    /// What `pointlens info` prints: one `name: value` line per item, with
    /// `median_spacing` given by the caller (the splat hierarchy's,
    /// `tree::median_spacing`: the exact one takes minutes at 10 M points).
    pub fn info_text(&self, path: &Path, median_spacing: f32) -> String {
        let (lo, hi) = self.bounds();
        let v = |p: Vec3| format!("{} {} {}", p.x, p.y, p.z);
        let yes = |b: bool| if b { "yes" } else { "no" };
        let file_info: String = self
            .file_info
            .iter()
            .map(|(name, value)| format!("{name}: {value}\n"))
            .collect();
        format!(
            "file: {}\n{file_info}points: {}\norigin: {}\nbounds_min: {}\nbounds_max: {}\n\
             extent: {}\nattributes: {}\ncolors: {}\nnormals: {}\nmedian_spacing: {}\n",
            path.display(),
            self.len(),
            format_args!(
                "{} {} {}",
                display_coord(self.origin.x),
                display_coord(self.origin.y),
                display_coord(self.origin.z)
            ),
            v(lo),
            v(hi),
            v(hi - lo),
            self.attributes.join(" "),
            match self.brightest() {
                b if b > 1.0 && self.has_colors => {
                    format!("yes, brighter than white (brightest channel {b} times white, linear)")
                }
                _ => yes(self.has_colors).to_string(),
            },
            yes(self.normals.is_some()),
            median_spacing
        )
    }
}
