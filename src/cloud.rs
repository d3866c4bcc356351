//! The in-memory point cloud every loader produces and every pass consumes.

use std::collections::HashMap;
use std::path::Path;

use glam::{IVec3, Vec3};

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
        format!(
            "file: {}\npoints: {}\nbounds_min: {}\nbounds_max: {}\nextent: {}\n\
             attributes: {}\ncolors: {}\nnormals: {}\nmedian_spacing: {}\n",
            path.display(),
            self.len(),
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
