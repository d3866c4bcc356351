//! The in-memory point cloud every loader produces and every pass consumes.

use std::collections::HashMap;
use std::path::Path;

use glam::{DVec3, IVec3, Vec3};

pub use crate::image_io::{linear_to_srgb, srgb_to_linear};

/// Color of a cloud without colors: sRGB (0.8, 0.8, 0.8) in linear light.
pub const DEFAULT_COLOR: Vec3 = Vec3::splat(0.603_827_4);

/// How many neighbours `local_spacing` averages over.
pub const SPACING_NEIGHBOURS: usize = 8;

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
    /// coordinates (zero) unless `--origin` is given.
    pub origin: DVec3,
    /// Per-point classification codes (ASPRS classes), when the file had them.
    pub classifications: Option<Vec<u8>>,
    /// What `info` prints about the file beyond the cloud itself, in order:
    /// `(name, value)` (format, version, scale, offset, CRS, …).
    pub file_info: Vec<(String, String)>,
}

/// A coordinate in the file's units for people to read: rounded to a
/// millionth (637240.4500000001 → 637240.45), far below any LAS scale.
pub fn display_coord(v: f64) -> String {
    format!("{}", (v * 1e6).round() / 1e6)
}

/// The linear-light value of a color channel stored as an sRGB-encoded
/// integer `code` out of `max_code` (e.g. 255 or 65535), clamped to [0, 1]:
/// the one conversion every loader uses.
pub fn linear_from_code(code: f64, max_code: f64) -> f32 {
    srgb_to_linear(((code / max_code) as f32).clamp(0.0, 1.0))
}

/// Loads a point cloud by its format: LAS or LAZ (COPC included) by the
/// magic bytes `LASF` or, for a file that cannot be peeked at, by the
/// extension; PLY otherwise. `origin` (file coordinates) re-centres the
/// cloud: LAS/LAZ in double precision from the integer codes (default: the
/// centre of its bounds, see `las`), PLY from its f32 positions (default:
/// none). `progress(done, total)` follows a LAS/LAZ read chunk by chunk.
pub fn load_cloud(
    path: &Path,
    origin: Option<DVec3>,
    progress: &mut dyn FnMut(u64, u64),
) -> crate::Result<PointCloud> {
    let cloud = if is_las(path) {
        crate::las::load_las(path, origin, progress)?
    } else {
        let mut cloud = crate::ply::load_ply(path)?;
        if let Some(origin) = origin {
            cloud.recentre(origin).map_err(|msg| crate::Error::Ply {
                path: path.to_path_buf(),
                msg,
            })?;
        }
        cloud
    };
    if let Some(i) = cloud
        .positions
        .iter()
        .position(|p| !p.is_finite() || p.abs().max_element() > MAX_COORDINATE)
    {
        let at = cloud.positions[i];
        return Err(crate::Error::InvalidArgument(format!(
            "{}: point {i} at ({:e}, {:e}, {:e}) is beyond ±{MAX_COORDINATE:e} scene units{}, where \
             squared distances overflow f32; remove it, or rescale or re-centre the cloud (--origin)",
            path.display(),
            at.x,
            at.y,
            at.z,
            if cloud.origin == DVec3::ZERO { "" } else { " from the origin" },
        )));
    }
    Ok(cloud)
}

/// The largest coordinate magnitude a rendered point may have (after
/// re-centring): squared distances of such points still fit f32
/// (1e18² = 1e36 < 3.4e38), so depths, CoCs and the splat hierarchy's
/// spheres stay finite.
pub const MAX_COORDINATE: f32 = 1e18;

/// Whether `path` holds a LAS or LAZ file: by its first four bytes where it
/// is a regular file, else by its extension.
fn is_las(path: &Path) -> bool {
    use std::io::Read;
    match std::fs::File::open(path) {
        Ok(file) if file.metadata().is_ok_and(|m| m.is_file()) => {
            let mut magic = Vec::with_capacity(4);
            match file.take(4).read_to_end(&mut magic) {
                Ok(_) if crate::las::has_magic(&magic) => true,
                Ok(_) if magic.starts_with(b"ply") => false,
                _ => crate::las::has_las_extension(path),
            }
        }
        _ => crate::las::has_las_extension(path),
    }
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

    /// Per point, the mean distance to its `SPACING_NEIGHBOURS` nearest other
    /// points (fewer when the cloud is smaller; 0 for a single point). Exact,
    /// deterministic, and fast: a uniform grid searched ring by ring.
    pub fn local_spacing(&self) -> Vec<f32> {
        let n = self.positions.len();
        let k = SPACING_NEIGHBOURS.min(n.saturating_sub(1));
        if k == 0 {
            return vec![0.0; n];
        }
        let grid = Grid::new(&self.positions);
        let mut spacing = vec![0.0; n];
        // Each point's search is independent: split the points into one
        // contiguous chunk per core. Same result whatever the split.
        let threads = crate::available_threads();
        let chunk = n.div_ceil(threads).max(1024);
        std::thread::scope(|scope| {
            for (c, out) in spacing.chunks_mut(chunk).enumerate() {
                let (grid, points) = (&grid, &self.positions);
                scope.spawn(move || {
                    let mut best = Vec::with_capacity(k + 1);
                    for (j, s) in out.iter_mut().enumerate() {
                        grid.nearest(points, c * chunk + j, k, &mut best);
                        *s = best.iter().map(|d2: &f32| d2.sqrt()).sum::<f32>() / k as f32;
                    }
                });
            }
        });
        spacing
    }

    /// The median of `local_spacing` (0 for fewer than two points): a robust
    /// spacing for the whole cloud.
    pub fn median_spacing(&self) -> f32 {
        median(self.local_spacing())
    }

    /// What `pointlens info` prints: one `name: value` line per item (the
    /// median spacing is the splat hierarchy's, `tree::median_spacing`:
    /// the exact one takes minutes at 10 M points).
    pub fn info_text(&self, path: &Path) -> String {
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
            yes(self.has_colors),
            yes(self.normals.is_some()),
            crate::tree::median_spacing(&self.positions, crate::available_threads())
        )
    }
}

/// The median of a series (the upper one of an even count; 0 when empty).
pub fn median(mut v: Vec<f32>) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    *m
}

/// A uniform grid over a point set: the points sorted by cell, and each
/// occupied cell's range in that order.
struct Grid {
    origin: Vec3,
    cell: f32,
    order: Vec<u32>,
    cells: HashMap<IVec3, (u32, u32)>,
    /// Number of cells along each axis (the search never goes beyond).
    dims: IVec3,
}

impl Grid {
    /// Chooses the cell size so that an occupied cell holds about 2–16
    /// points, whether the cloud fills a volume or lies on a surface.
    fn new(points: &[Vec3]) -> Grid {
        let (lo, hi) = points.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let extent = (hi - lo).max(Vec3::splat(1e-12));
        let n = points.len() as f32;
        // Start coarse (8 points per cell if the cloud filled a cube of its
        // largest extent) and halve while occupied cells are crowded, as
        // they are for a surface or a line.
        let largest = extent.max_element();
        let mut cell = largest / (n / 8.0).cbrt().max(1.0);
        loop {
            let grid = Grid::build(points, lo, extent, cell);
            let mean = n / grid.cells.len() as f32;
            if mean <= 16.0 || cell <= largest / 4096.0 {
                return grid;
            }
            cell /= 2.0;
        }
    }

    fn build(points: &[Vec3], origin: Vec3, extent: Vec3, cell: f32) -> Grid {
        let key = |p: Vec3| ((p - origin) / cell).floor().as_ivec3();
        let mut order: Vec<u32> = (0..points.len() as u32).collect();
        order.sort_by_key(|&i| {
            let c = key(points[i as usize]);
            (c.x, c.y, c.z, i)
        });
        let mut cells = HashMap::new();
        let mut start = 0usize;
        while start < order.len() {
            let c = key(points[order[start] as usize]);
            let mut end = start + 1;
            while end < order.len() && key(points[order[end] as usize]) == c {
                end += 1;
            }
            cells.insert(c, (start as u32, end as u32));
            start = end;
        }
        Grid {
            origin,
            cell,
            order,
            cells,
            dims: (extent / cell).floor().as_ivec3() + IVec3::ONE,
        }
    }

    /// The squared distances of the `k` nearest points to point `i` (other
    /// than itself), ascending, into `best`.
    fn nearest(&self, points: &[Vec3], i: usize, k: usize, best: &mut Vec<f32>) {
        best.clear();
        let q = points[i];
        let home = ((q - self.origin) / self.cell).floor().as_ivec3();
        let max_ring = self.dims.max_element();
        // Ring r: the cells at Chebyshev distance r from `home`, clipped to
        // the grid (a flat cloud has one layer of cells).
        let lo = -home;
        let hi = self.dims - IVec3::ONE - home;
        for r in 0..=max_ring {
            for dz in (-r).max(lo.z)..=r.min(hi.z) {
                for dy in (-r).max(lo.y)..=r.min(hi.y) {
                    for dx in (-r).max(lo.x)..=r.min(hi.x) {
                        if dx.abs().max(dy.abs()).max(dz.abs()) != r {
                            continue;
                        }
                        let Some(&(s, e)) = self.cells.get(&(home + IVec3::new(dx, dy, dz))) else {
                            continue;
                        };
                        for &j in &self.order[s as usize..e as usize] {
                            if j as usize == i {
                                continue;
                            }
                            let d2 = q.distance_squared(points[j as usize]);
                            if best.len() < k || d2 < best[k - 1] {
                                let at = best.partition_point(|&b| b <= d2);
                                best.insert(at, d2);
                                best.truncate(k);
                            }
                        }
                    }
                }
            }
            // Every point in ring r+1 or beyond is at least r cells away.
            let reach = r as f32 * self.cell;
            if best.len() == k && best[k - 1] <= reach * reach {
                return;
            }
        }
    }
}
