//! Local point spacing: the tree's, from a window of neighbours in Morton
//! order (fixed cost per point), and the exact k-nearest-neighbour spacing
//! it approximates (the tests' reference).

use std::collections::HashMap;

use glam::{IVec3, Vec3};

use super::morton::{morton_keys, morton_order, radix_sort};
use super::{par_chunks, CHUNK};

/// How many points `tree_spacing` looks at on either side of a point in
/// Morton order.
pub const SPACING_WINDOW: usize = 12;

/// How many nearest neighbours a point's local spacing averages over (the
/// exact [`exact_spacing`] and the tree's [`tree_spacing`] alike).
pub const SPACING_NEIGHBOURS: usize = 8;

/// The tree's local spacing of every point of `p` (the points in Morton
/// order): the mean distance to its `SPACING_NEIGHBOURS` nearest among the
/// `SPACING_WINDOW` points on either side of it in Morton order, the
/// smaller of two Morton orders whose cell boundaries differ (a point
/// alone in its cell of one order, its neighbours far before or after it,
/// has them beside it in the other). An approximation of
/// [`exact_spacing`]'s exact k nearest neighbours, at a fixed
/// cost per point; 0 for a single point.
pub fn tree_spacing(p: &[Vec3], threads: usize) -> Vec<f32> {
    tree_spacing_of(std::borrow::Cow::Borrowed(p), &|i| p[i], threads)
}

/// [`tree_spacing`] of `p`, which it drops once the second order's codes
/// are made (`at(i)` is then point i): at most 36 bytes a point besides
/// `at`'s, where the hierarchy's build gives its points' copy.
fn tree_spacing_of(
    p: std::borrow::Cow<'_, [Vec3]>,
    at: &(dyn Fn(usize) -> Vec3 + Sync),
    threads: usize,
) -> Vec<f32> {
    let mut spacing = window_spacing(&p, threads);
    // The second order, as indices into the first (both are spatially
    // coherent, so the gather and scatter below stay mostly in cache).
    let keys = morton_keys(&p, threads, Some(SECOND_ORDER_SHIFT));
    drop(p);
    let second = radix_sort(keys, threads);
    let in_second: Vec<Vec3> = second.iter().map(|&i| at(i as usize)).collect();
    let other = window_spacing(&in_second, threads);
    for (&i, s) in second.iter().zip(other) {
        let slot = &mut spacing[i as usize];
        *slot = slot.min(s);
    }
    spacing.iter_mut().for_each(|s| *s /= SPACING_BIAS);
    spacing
}

/// [`tree_spacing`] with isolated points limited ([`limit_isolated`]), and
/// how many were.
pub fn tree_spacing_limited(p: &[Vec3], threads: usize) -> (Vec<f32>, u64) {
    let mut spacing = tree_spacing(p, threads);
    let limited = limit_isolated(&mut spacing, threads);
    (spacing, limited)
}

/// [`tree_spacing_limited`] of points it owns, dropped early (`at(i)`
/// gives point i afterwards; see [`tree_spacing_of`]).
pub(super) fn tree_spacing_limited_owned(
    p: Vec<Vec3>,
    at: &(dyn Fn(usize) -> Vec3 + Sync),
    threads: usize,
) -> (Vec<f32>, u64) {
    let mut spacing = tree_spacing_of(std::borrow::Cow::Owned(p), at, threads);
    let limited = limit_isolated(&mut spacing, threads);
    (spacing, limited)
}

/// A point's spacing may exceed its neighbourhood's by at most this factor
/// ([`limit_isolated`]).
pub const ISOLATED_LIMIT: f32 = 2.0;

/// Points per block of the neighbourhood in [`limit_isolated`].
pub const ISOLATED_BLOCK: usize = 256;

/// Bounds each spacing of `spacing` (points in Morton order) by the
/// density of the hierarchy around it: [`ISOLATED_LIMIT`] × the median of
/// the median spacings of its block of [`ISOLATED_BLOCK`] consecutive
/// points in Morton order and the two blocks beside it. A point far from
/// the others (a bird, a wire, a stray return) takes its own spacing, and
/// with it its splat, from its far neighbours: tens of times the surfaces'
/// around it, a square tens of pixels wide; so do a few dozen such returns
/// together (a sparse layer of noise above trees), which are each other's
/// nearest neighbours. The blocks around them are mostly the surfaces'
/// points, whose spacing is the local density; a region where hundreds of
/// consecutive points are sparse (the far field of a terrestrial scan) is
/// its own neighbourhood and keeps its sizes. Returns how many spacings
/// were limited.
pub fn limit_isolated(spacing: &mut [f32], threads: usize) -> u64 {
    let n = spacing.len();
    if n < 3 {
        return 0;
    }
    let block_median: Vec<f32> = spacing
        .chunks(ISOLATED_BLOCK)
        .map(|block| median(block.iter().copied().filter(|s| *s > 0.0).collect()))
        .collect();
    let blocks = block_median.len();
    let bound_of = |b: usize| {
        let mut around = [
            block_median[b.saturating_sub(1)],
            block_median[b],
            block_median[(b + 1).min(blocks - 1)],
        ];
        around.sort_by(f32::total_cmp);
        ISOLATED_LIMIT * around[1]
    };
    let counts = par_chunks(spacing, ISOLATED_BLOCK, threads, |b, out| {
        let bound = bound_of(b);
        let mut limited = 0u64;
        if bound > 0.0 {
            for s in out.iter_mut().filter(|s| **s > bound) {
                *s = bound;
                limited += 1;
            }
        }
        limited
    });
    counts.into_iter().sum()
}

/// How much the window's estimate exceeds the exact k-nearest-neighbour
/// spacing (it picks the nearest among fewer candidates), divided out: the
/// ratio of the mean spacings, measured on the bundled clouds with two
/// orders of 12 on either side, 1.0959 (bunny) and 1.0969 (mug), so that
/// the splats cover as much as the exact sizes' on average.
pub const SPACING_BIAS: f32 = 1.096;

/// The median of [`tree_spacing`] over `positions` (any order; 0 for fewer
/// than two points): what `info` prints, in the time of a tree build
/// rather than the exact k-NN search's.
pub fn median_spacing(positions: &[Vec3], threads: usize) -> f32 {
    median(morton_spacing(positions, threads))
}

/// [`median_spacing`] and how many points [`limit_isolated`] limits: what
/// `info` prints.
pub fn spacing_summary(positions: &[Vec3], threads: usize) -> (f32, u64) {
    let spacing = morton_spacing(positions, threads);
    let limited = limit_isolated(&mut spacing.clone(), threads);
    (median(spacing), limited)
}

/// [`tree_spacing`] of `positions` (any order), in Morton order.
fn morton_spacing(positions: &[Vec3], threads: usize) -> Vec<f32> {
    let order = morton_order(positions, threads);
    let in_order: Vec<Vec3> = order.iter().map(|&i| positions[i as usize]).collect();
    tree_spacing(&in_order, threads)
}

/// Where the second Morton order's cube starts, in units of the first's
/// side: no common dyadic boundary with the first for several levels.
const SECOND_ORDER_SHIFT: Vec3 = Vec3::new(0.381_966, 0.236_068, 0.145_898);

/// Per point of `p` (in Morton order), the mean distance to its
/// `SPACING_NEIGHBOURS` nearest among the `SPACING_WINDOW` points on either
/// side.
fn window_spacing(p: &[Vec3], threads: usize) -> Vec<f32> {
    const K: usize = SPACING_NEIGHBOURS;
    let n = p.len();
    let k = K.min(n.saturating_sub(1));
    let mut spacing = vec![0.0f32; n];
    if k == 0 {
        return spacing;
    }
    par_chunks(&mut spacing, CHUNK, threads, |c, out| {
        for (j, s) in out.iter_mut().enumerate() {
            let i = c * CHUNK + j;
            let q = p[i];
            let mut best = [f32::INFINITY; K];
            let lo = i.saturating_sub(SPACING_WINDOW);
            let hi = (i + SPACING_WINDOW).min(n - 1);
            for &other in p[lo..i].iter().chain(&p[i + 1..=hi]) {
                insert_sorted(&mut best, q.distance_squared(other));
            }
            *s = best[..k].iter().map(|d2| d2.sqrt()).sum::<f32>() / k as f32;
        }
    });
    spacing
}

/// Inserts `d` into the ascending `best`, dropping the largest, without
/// a branch: the new best[t] is min(best[t], max(best[t − 1], d)) (so the
/// compiler makes it a few vector min/max).
#[inline(always)]
fn insert_sorted(best: &mut [f32; SPACING_NEIGHBOURS], d: f32) {
    let mut shifted = [f32::NEG_INFINITY; SPACING_NEIGHBOURS];
    shifted[1..].copy_from_slice(&best[..SPACING_NEIGHBOURS - 1]);
    for (b, s) in best.iter_mut().zip(shifted) {
        *b = b.min(s.max(d));
    }
}

/// Per point of `positions`, the mean distance to its `SPACING_NEIGHBOURS`
/// nearest other points (fewer when there are fewer; 0 for a single point).
/// Exact, deterministic, and fast: a uniform grid searched ring by ring,
/// on `threads` threads (the same result for any count). The reference
/// [`tree_spacing`] approximates.
pub fn exact_spacing(positions: &[Vec3], threads: usize) -> Vec<f32> {
    let n = positions.len();
    let k = SPACING_NEIGHBOURS.min(n.saturating_sub(1));
    if k == 0 {
        return vec![0.0; n];
    }
    let grid = Grid::new(positions);
    let mut spacing = vec![0.0; n];
    // Each point's search is independent: split the points into one
    // contiguous chunk per core. Same result whatever the split.
    let chunk = n.div_ceil(threads.max(1)).max(1024);
    std::thread::scope(|scope| {
        for (c, out) in spacing.chunks_mut(chunk).enumerate() {
            let (grid, points) = (&grid, positions);
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
