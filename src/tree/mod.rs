//! The splat hierarchy (DESIGN §3, Zhao §2 after QSplat): bounding spheres
//! over the points in Morton order, built once per cloud, and the per-frame
//! traversal that culls and picks the level of detail.
//!
//! A pure data structure: it takes points ([`Points`]: positions, linear
//! colors, normals) and a size rule ([`LeafSize`]), and gives splats in its
//! own type ([`Splat`]). It knows nothing of the renderer: the GPU vertex
//! and the rule from spacing to diameter live on the render side
//! (`render`, `passes::splat_raster`).
//!
//! - `morton`: the points' Morton order (a parallel radix sort);
//! - `spacing`: local point spacing, the tree's (a window in Morton order)
//!   and the exact k-nearest-neighbour one it approximates;
//! - `traverse`: the per-frame traversal (culling, level of detail).
//!
//! Layout (docs/ARCHITECTURE.md, "Splat hierarchy"). Level 0 holds the
//! points themselves, sorted by the Morton code of their position, as
//! [`Splat`]s (24 bytes: position, world diameter, linear color as UNORM16;
//! the color's fourth channel holds the octahedral normal). Level l ≥ 1
//! groups runs of at most 8 consecutive nodes of level l − 1, broken
//! wherever Morton order jumps (the next node farther from the one before
//! than `GROUP_JUMP_RADII` of their radii), so that each group is compact.
//! An inner node is a [`Node`] (32 bytes: its splat — centre, diameter of
//! the bounding sphere, mean color, mean normal — the normal cone's
//! half-angle, and its first child; the children run to the next node's
//! first child). About 30.8 bytes per point for every level together, at
//! most 32.

mod morton;
pub mod spacing;
mod traverse;

use std::time::Instant;

use bytemuck::Zeroable;
use glam::{Vec2, Vec3};

pub use morton::morton_order;
use spacing::tree_spacing_limited_owned;
pub use spacing::{
    exact_spacing, limit_isolated, median, median_spacing, spacing_summary, tree_spacing,
    tree_spacing_limited, ISOLATED_BLOCK, ISOLATED_LIMIT, SPACING_BIAS, SPACING_NEIGHBOURS,
    SPACING_WINDOW,
};
pub use traverse::{max_coc_px, min_coc_px, sphere_decision, Traversal, Widening};

/// The points a tree is built of, in any order: positions, linear-light
/// colors in [0, 1] (one per point) and, when known, unit normals.
#[derive(Debug, Clone, Copy)]
pub struct Points<'a> {
    pub positions: &'a [Vec3],
    pub colors: &'a [Vec3],
    pub normals: Option<&'a [Vec3]>,
}

/// A node of the hierarchy as one splat: a sphere and what it looks like.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Splat {
    /// Centre (xyz) and world diameter (w) of the splat's sphere.
    pub position_size: [f32; 4],
    /// Linear RGB as 16-bit UNORM codes of the tree's colour scale
    /// ([`SplatTree::color_scale`]: code 65535 is 1, white, unless the
    /// cloud is brighter), and the octahedral normal
    /// ([`oct_encode`]; 0 when the points have no normals).
    pub color: [u16; 4],
}

const _: () = assert!(std::mem::size_of::<Splat>() == 24);

impl Splat {
    /// The centre.
    pub fn centre(&self) -> Vec3 {
        Vec3::from_slice(&self.position_size[..3])
    }

    /// The splat's sphere: centre and radius (half the diameter).
    pub fn sphere(&self) -> (Vec3, f32) {
        (self.centre(), 0.5 * self.position_size[3])
    }
}

/// The most children of an inner node.
pub const FANOUT: usize = 8;

/// A group of consecutive nodes ends where the next one lies farther from
/// its predecessor than this many times the larger of their radii: there
/// Morton order jumped across a cell boundary, and a node spanning the jump
/// would be too large for the level of detail.
pub const GROUP_JUMP_RADII: f32 = 4.0;

/// An inner node: its splat (centre, diameter of the bounding sphere, mean
/// linear color, octahedral mean normal in the color's alpha) and the
/// half-angle of the cone that holds every normal beneath it (radians;
/// π: any direction).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Node {
    pub splat: Splat,
    pub cone_rad: f32,
    /// Its first child in the level below; the children run to the next
    /// node's first child (the last node's: to the end of that level).
    pub first_child: u32,
}

const _: () = assert!(std::mem::size_of::<Node>() == 32);

/// How a leaf's world diameter is chosen (DESIGN §3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LeafSize<'a> {
    /// This multiple of the tree's local spacing ([`tree_spacing`]; where
    /// a point's is 0, of the median spacing).
    SpacingTimes(f32),
    /// Every leaf this world diameter.
    World(f32),
    /// Zero: the raster sizes splats in pixels.
    Zero,
    /// Each point's world diameter, in the order of [`Points`].
    PerPoint(&'a [f32]),
    /// `SpacingTimes`, each point's diameter at most the one given (in the
    /// order of [`Points`]): a point of a coarse COPC node no wider than
    /// its node's spacing allows, whatever its neighbours in the frame.
    SpacingTimesAtMost(f32, &'a [f32]),
}

/// The hierarchy of one cloud.
#[derive(Debug, Clone, Default)]
pub struct SplatTree {
    /// Level 0: the points in Morton order.
    leaves: Vec<Splat>,
    /// Levels 1, 2, …: the last holds the root alone.
    levels: Vec<Vec<Node>>,
    /// For each node of levels 2, 3, … (`[level - 2][i]`): the smallest
    /// diameter of an inner node beneath it, which bounds what the level
    /// of detail could emit below it ([`SplatTree::inner_diameter_below`]).
    inner_diameter_below: Vec<Vec<f32>>,
    has_normals: bool,
    /// The largest angle between a point's normal and its stored
    /// (quantised) one: the leaves' normal cone.
    leaf_cone_rad: f32,
    /// Where each step of the build went.
    pub build: BuildTimes,
    /// Leaves whose spacing [`limit_isolated`] bounded (isolated points).
    pub isolated_limited: u64,
    /// The linear colour of code 65535 where the cloud is brighter than
    /// white (0 or 1: white); see [`SplatTree::color_scale`].
    color_scale: f32,
}

/// The brightest linear colour a splat keeps: 128 times white (a brighter
/// channel is clamped to it, with a warning). The layered method's
/// fixed-point sums hold a pixel's channel below 512
/// (`passes::layered::FRACTION_BITS`): 128 leaves room for the fragments
/// that overlap there. Codes are of the cloud's brightest channel, so a
/// brighter cloud's darkest tones are coarser: a step of 128/65535 at the
/// cap.
pub const BRIGHTEST_LINEAR: f32 = 128.0;

/// The colour scale of `colors` (linear): 1, or their brightest channel
/// where that is above 1 (at most [`BRIGHTEST_LINEAR`], with a warning
/// where a channel is brighter). Not-a-number channels count as 0.
fn color_scale_of(colors: &[Vec3]) -> f32 {
    let brightest = colors.iter().fold(1.0f32, |m, c| m.max(c.max_element()));
    if brightest > BRIGHTEST_LINEAR {
        let over = colors
            .iter()
            .filter(|c| c.max_element() > BRIGHTEST_LINEAR)
            .count();
        log::warn!(
            "{over} points are brighter than {BRIGHTEST_LINEAR} times white (linear); \
             their colours are clamped to it"
        );
    }
    brightest.min(BRIGHTEST_LINEAR)
}

/// Wall times of the build's steps, milliseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BuildTimes {
    pub morton_sort_ms: f64,
    pub spacing_ms: f64,
    pub levels_ms: f64,
    pub total_ms: f64,
}

impl SplatTree {
    /// Builds the hierarchy of `points` on `threads` threads (the result is
    /// the same bytes whatever the count).
    pub fn build(points: Points, size: LeafSize, threads: usize) -> SplatTree {
        let started = Instant::now();
        let threads = threads.max(1);
        if points.positions.is_empty() {
            return SplatTree::default();
        }
        let (leaves, leaf_cone_rad, color_scale) = Self::leaves_of(points, size, threads);
        SplatTree {
            color_scale,
            ..Self::from_leaves(
                leaves,
                leaf_cone_rad,
                size,
                points.normals.is_some(),
                threads,
                started,
            )
        }
    }

    /// [`SplatTree::build`] of the points of `owner` (`points_of` gives
    /// them), which it takes and drops as soon as the leaves hold its
    /// points: the same tree, with the owner's bytes (a cloud's 24 or more
    /// a point) no longer beside the build's.
    pub fn build_owned<T>(
        owner: T,
        points_of: impl for<'a> Fn(&'a T) -> Points<'a>,
        size: LeafSize,
        threads: usize,
    ) -> SplatTree {
        let started = Instant::now();
        let threads = threads.max(1);
        let points = points_of(&owner);
        if points.positions.is_empty() {
            return SplatTree::default();
        }
        let has_normals = points.normals.is_some();
        let (leaves, leaf_cone_rad, color_scale) = Self::leaves_of(points, size, threads);
        drop(owner);
        SplatTree {
            color_scale,
            ..Self::from_leaves(leaves, leaf_cone_rad, size, has_normals, threads, started)
        }
    }

    /// The leaves: `points` in Morton order as splats (sizes per point
    /// where `size` gives them), their normals' cone and the colour scale
    /// of their codes.
    fn leaves_of(points: Points, size: LeafSize, threads: usize) -> (Vec<Splat>, f32, f32) {
        let n = points.positions.len();
        let order = morton_order(points.positions, threads);
        let per_point = match size {
            LeafSize::PerPoint(d) | LeafSize::SpacingTimesAtMost(_, d) => Some(d),
            _ => None,
        };
        let normals = points.normals;
        let scale = color_scale_of(points.colors);
        let mut leaves: Vec<Splat> = vec![Splat::zeroed(); n];
        let leaf_cone = par_chunks(&mut leaves, CHUNK, threads, |c, out| {
            let mut worst = 0.0f32;
            for (j, v) in out.iter_mut().enumerate() {
                let i = order[c * CHUNK + j] as usize;
                let p = points.positions[i];
                // Scale 1 divides exactly: a cloud within white keeps its
                // codes.
                let col = points.colors[i] / scale;
                let packed = match normals {
                    Some(ns) => {
                        let packed = oct_encode(ns[i]);
                        worst = worst.max(angle(ns[i], oct_decode(packed)));
                        packed
                    }
                    None => 0,
                };
                *v = Splat {
                    position_size: [p.x, p.y, p.z, per_point.map_or(0.0, |d| d[i])],
                    color: [unorm16(col.x), unorm16(col.y), unorm16(col.z), packed],
                };
            }
            worst
        });
        drop(order);
        let leaf_cone_rad = leaf_cone.iter().fold(0.0f32, |m, &w| m.max(w));
        (leaves, leaf_cone_rad, scale)
    }

    /// The tree over `leaves` (from [`SplatTree::leaves_of`]; the build
    /// began at `started`): splat sizes, then the levels.
    fn from_leaves(
        mut leaves: Vec<Splat>,
        leaf_cone_rad: f32,
        size: LeafSize,
        has_normals: bool,
        threads: usize,
        started: Instant,
    ) -> SplatTree {
        let sorted_ms = ms_since(started);
        let spacing_started = Instant::now();
        let mut isolated_limited = 0;
        match size {
            LeafSize::World(w) => leaves.iter_mut().for_each(|v| v.position_size[3] = w),
            LeafSize::Zero | LeafSize::PerPoint(_) => {}
            LeafSize::SpacingTimes(k) | LeafSize::SpacingTimesAtMost(k, _) => {
                // The leaves hold their bounds (`leaves_of`) where given.
                let bounded = matches!(size, LeafSize::SpacingTimesAtMost(..));
                let in_order: Vec<Vec3> = leaves.iter().map(Splat::centre).collect();
                let at = |i: usize| leaves[i].centre();
                let (spacing, limited) = tree_spacing_limited_owned(in_order, &at, threads);
                isolated_limited = limited;
                let fallback = median(spacing.clone());
                for (v, s) in leaves.iter_mut().zip(spacing) {
                    let d = k * if s > 0.0 { s } else { fallback };
                    let size = &mut v.position_size[3];
                    *size = if bounded { d.min(*size) } else { d };
                }
            }
        }
        let spacing_ms = ms_since(spacing_started);

        let levels_started = Instant::now();
        let mut levels: Vec<Vec<Node>> = Vec::new();
        // Points beneath each node of the level below (the mean color's
        // weights).
        let mut beneath: Vec<u32> = vec![1; leaves.len()];
        loop {
            let prev = levels.last();
            let below = prev.map_or(leaves.len(), Vec::len);
            if below <= 1 {
                break;
            }
            let get = |j: usize| -> (Splat, f32) {
                match prev {
                    None => (leaves[j], leaf_cone_rad),
                    Some(p) => (p[j].splat, p[j].cone_rad),
                }
            };
            let mut starts = group_starts(below, |j| get(j).0, GROUP_JUMP_RADII);
            if starts.len() * 5 > below {
                // Groups of fewer than 5 on average (many isolated nodes):
                // fixed groups of 8 for this level instead, so that the
                // inner nodes stay under n/4 (n/5 + n/25 + …): 32 bytes a
                // point at most with the leaves, and 0.2 more for the
                // inner diameters below the nodes of levels 2 and up.
                starts = (0..below).step_by(FANOUT).map(|j| j as u32).collect();
            }
            let mut nodes = vec![Node::zeroed(); starts.len()];
            let end = |g: usize| starts.get(g + 1).map_or(below, |&e| e as usize);
            par_chunks(&mut nodes, CHUNK / FANOUT, threads, |c, out| {
                for (j, node) in out.iter_mut().enumerate() {
                    let g = c * (CHUNK / FANOUT) + j;
                    let children: Vec<(Splat, f32, f32)> = (starts[g] as usize..end(g))
                        .map(|k| {
                            let (s, cone) = get(k);
                            (s, cone, beneath[k] as f32)
                        })
                        .collect();
                    *node = Node {
                        first_child: starts[g],
                        ..merge(&children, has_normals)
                    };
                }
            });
            beneath = (0..starts.len())
                .map(|g| beneath[starts[g] as usize..end(g)].iter().sum())
                .collect();
            levels.push(nodes);
        }
        let inner_diameter_below = inner_diameters_below(&levels);
        let levels_ms = ms_since(levels_started);
        SplatTree {
            leaves,
            levels,
            inner_diameter_below,
            has_normals,
            leaf_cone_rad,
            build: BuildTimes {
                morton_sort_ms: sorted_ms,
                spacing_ms,
                levels_ms,
                total_ms: ms_since(started),
            },
            isolated_limited,
            color_scale: 1.0,
        }
    }

    /// The same points and splat sizes as [`SplatTree::build`], drawn in
    /// the points' own order and without a hierarchy (every frame draws
    /// every point, whatever the LOD): for measuring what Morton order
    /// gains the raster (`examples/point_order.rs`).
    pub fn build_in_input_order(points: Points, size: LeafSize, threads: usize) -> SplatTree {
        let mut tree = SplatTree::build(points, size, threads);
        let order = morton_order(points.positions, threads);
        let mut leaves = vec![Splat::zeroed(); tree.leaves.len()];
        for (v, &i) in tree.leaves.iter().zip(&order) {
            leaves[i as usize] = *v;
        }
        tree.leaves = leaves;
        tree.levels.clear();
        tree.inner_diameter_below.clear();
        tree
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.leaves.len()
    }

    /// The linear colour of a splat's code 65535: 1 (white), or the
    /// cloud's brightest channel where it is brighter (a highlight of
    /// linear-light PLY colours; at most [`BRIGHTEST_LINEAR`]). The
    /// G-buffer's resolves multiply every covered sample by it.
    pub fn color_scale(&self) -> f32 {
        self.color_scale.max(1.0)
    }

    /// Whether the tree has no points.
    pub fn is_empty(&self) -> bool {
        self.leaves.is_empty()
    }

    /// The points in Morton order (level 0).
    pub fn leaves(&self) -> &[Splat] {
        &self.leaves
    }

    /// The inner levels, from the leaves' parents up to the root.
    pub fn levels(&self) -> &[Vec<Node>] {
        &self.levels
    }

    /// Whether the points had normals (`--cull-back-faces` needs them).
    pub fn has_normals(&self) -> bool {
        self.has_normals
    }

    /// Host bytes of every level together.
    pub fn bytes(&self) -> usize {
        self.leaves.len() * std::mem::size_of::<Splat>()
            + self.levels.iter().map(Vec::len).sum::<usize>() * std::mem::size_of::<Node>()
            + self
                .inner_diameter_below
                .iter()
                .map(Vec::len)
                .sum::<usize>()
                * std::mem::size_of::<f32>()
    }

    /// The whole tree as bytes (leaves, then each level): the same for the
    /// same points whatever the thread count (a test).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = bytemuck::cast_slice(&self.leaves).to_vec();
        for l in &self.levels {
            b.extend_from_slice(bytemuck::cast_slice(l));
        }
        b.extend_from_slice(&self.leaf_cone_rad.to_le_bytes());
        b.extend_from_slice(&self.color_scale().to_le_bytes());
        b
    }

    /// Node `i` of level `level` (0: a leaf) as (splat, cone half-angle).
    pub fn node(&self, level: usize, i: usize) -> (Splat, f32) {
        if level == 0 {
            (self.leaves[i], self.leaf_cone_rad)
        } else {
            let n = &self.levels[level - 1][i];
            (n.splat, n.cone_rad)
        }
    }

    /// The smallest diameter of an inner node beneath node `i` of `level`
    /// ≥ 1 (infinite where only leaves are beneath it).
    pub fn inner_diameter_below(&self, level: usize, i: usize) -> f32 {
        match level {
            0 | 1 => f32::INFINITY,
            _ => self.inner_diameter_below[level - 2][i],
        }
    }

    /// The leaves beneath node `i` of `level` (0: the leaf itself), as
    /// indices into [`SplatTree::leaves`]: every level keeps its
    /// children's order, so they are one run.
    pub fn leaves_below(&self, level: usize, i: usize) -> std::ops::Range<usize> {
        let first_leaf = |mut level: usize, mut i: usize| {
            while level > 0 {
                i = self.levels[level - 1][i].first_child as usize;
                level -= 1;
            }
            i
        };
        let end = if i + 1 < self.level_len(level) {
            first_leaf(level, i + 1)
        } else {
            self.leaves.len()
        };
        first_leaf(level, i)..end
    }

    /// The children of node `i` of `level` ≥ 1, as indices into `level` − 1.
    pub fn children(&self, level: usize, i: usize) -> std::ops::Range<usize> {
        let nodes = &self.levels[level - 1];
        let end = nodes
            .get(i + 1)
            .map_or(self.level_len(level - 1), |n| n.first_child as usize);
        nodes[i].first_child as usize..end
    }

    /// Number of nodes of `level` (0: the leaves).
    pub fn level_len(&self, level: usize) -> usize {
        if level == 0 {
            self.leaves.len()
        } else {
            self.levels[level - 1].len()
        }
    }
}

/// [`SplatTree::inner_diameter_below`] of every node of levels 2, 3, …:
/// the smallest over its children of their diameter and of theirs.
fn inner_diameters_below(levels: &[Vec<Node>]) -> Vec<Vec<f32>> {
    let mut below: Vec<Vec<f32>> = Vec::with_capacity(levels.len().saturating_sub(1));
    for l in 1..levels.len() {
        let (children, nodes) = (&levels[l - 1], &levels[l]);
        let of_child = |c: usize| {
            let d = children[c].splat.position_size[3];
            below.last().map_or(d, |b: &Vec<f32>| d.min(b[c]))
        };
        let level: Vec<f32> = (0..nodes.len())
            .map(|i| {
                let end = nodes
                    .get(i + 1)
                    .map_or(children.len(), |n| n.first_child as usize);
                (nodes[i].first_child as usize..end)
                    .map(of_child)
                    .fold(f32::INFINITY, f32::min)
            })
            .collect();
        below.push(level);
    }
    below
}

/// Points per unit of parallel work in the build.
const CHUNK: usize = 1 << 16;

/// The parent of `children` (splat, cone, leaves beneath): the sphere
/// holding theirs, their mean color and normal weighted by leaves beneath,
/// and the cone holding their cones.
fn merge(children: &[(Splat, f32, f32)], has_normals: bool) -> Node {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for (s, ..) in children {
        let (c, r) = s.sphere();
        lo = lo.min(c - r);
        hi = hi.max(c + r);
    }
    let centre = 0.5 * (lo + hi);
    let mut radius = 0.0f32;
    for (s, ..) in children {
        let (c, r) = s.sphere();
        radius = radius.max(c.distance(centre) + r);
    }
    // Rounding: the parent must hold every child.
    radius = radius * (1.0 + 4.0 * f32::EPSILON) + f32::MIN_POSITIVE;
    let weight: f32 = children.iter().map(|c| c.2).sum();
    let mut color = [0.0f32; 3];
    for (s, _, w) in children {
        for (sum, &v) in color.iter_mut().zip(&s.color[..3]) {
            *sum += v as f32 * w;
        }
    }
    let color = color.map(|c| (c / weight).round().clamp(0.0, 65535.0) as u16);
    let (packed, cone_rad) = if has_normals {
        let mean: Vec3 = children
            .iter()
            .map(|(s, _, w)| oct_decode(s.color[3]) * *w)
            .sum();
        if mean.length() < 1e-3 * weight {
            (0, std::f32::consts::PI)
        } else {
            let packed = oct_encode(mean);
            let axis = oct_decode(packed);
            let cone = children
                .iter()
                .map(|(s, cone, _)| angle(axis, oct_decode(s.color[3])) + cone)
                .fold(0.0f32, f32::max);
            (packed, cone.min(std::f32::consts::PI))
        }
    } else {
        (0, std::f32::consts::PI)
    };
    Node {
        splat: Splat {
            position_size: [centre.x, centre.y, centre.z, 2.0 * radius],
            color: [color[0], color[1], color[2], packed],
        },
        cone_rad,
        first_child: 0,
    }
}

/// Where each group of the next level starts among `count` consecutive
/// nodes (`splat(j)`): at most `FANOUT` to a group, and a new group
/// wherever a node lies farther from the one before than `jump_radii`
/// times the larger of their radii. Sequential: the same for any threads.
fn group_starts(count: usize, splat: impl Fn(usize) -> Splat, jump_radii: f32) -> Vec<u32> {
    let sphere = |j: usize| splat(j).sphere();
    let mut starts = Vec::with_capacity(count / 4 + 1);
    let mut start = 0usize;
    starts.push(0);
    let (mut last_c, mut last_r) = sphere(0);
    for j in 1..count {
        let (c, r) = sphere(j);
        if j - start == FANOUT || c.distance(last_c) > jump_radii * r.max(last_r) {
            start = j;
            starts.push(j as u32);
        }
        (last_c, last_r) = (c, r);
    }
    starts
}

/// The angle between two unit vectors, radians.
fn angle(a: Vec3, b: Vec3) -> f32 {
    a.dot(b).clamp(-1.0, 1.0).acos()
}

fn unorm16(c: f32) -> u16 {
    (c.clamp(0.0, 1.0) * 65535.0 + 0.5) as u16
}

/// A direction as 8 + 8 bits (octahedral map): x in the low byte.
pub fn oct_encode(n: Vec3) -> u16 {
    let n = n / (n.x.abs() + n.y.abs() + n.z.abs()).max(f32::MIN_POSITIVE);
    let p = if n.z >= 0.0 {
        Vec2::new(n.x, n.y)
    } else {
        let sign = |v: f32| if v >= 0.0 { 1.0 } else { -1.0 };
        Vec2::new((1.0 - n.y.abs()) * sign(n.x), (1.0 - n.x.abs()) * sign(n.y))
    };
    let q = |v: f32| ((v.clamp(-1.0, 1.0) * 0.5 + 0.5) * 255.0).round() as u16;
    q(p.x) | (q(p.y) << 8)
}

/// The unit direction of [`oct_encode`]'s bits.
pub fn oct_decode(bits: u16) -> Vec3 {
    let d = |b: u16| (b & 0xFF) as f32 / 255.0 * 2.0 - 1.0;
    let (x, y) = (d(bits), d(bits >> 8));
    let z = 1.0 - x.abs() - y.abs();
    let t = (-z).max(0.0);
    let sign = |v: f32| if v >= 0.0 { 1.0 } else { -1.0 };
    Vec3::new(x - t * sign(x), y - t * sign(y), z).normalize()
}

/// Runs `f(chunk index, chunk)` over `data` in chunks of `chunk` items on
/// up to `threads` threads (contiguous runs of chunks per thread), and
/// returns `f`'s results in chunk order.
fn par_chunks<T: Send, R: Send>(
    data: &mut [T],
    chunk: usize,
    threads: usize,
    f: impl Fn(usize, &mut [T]) -> R + Sync,
) -> Vec<R> {
    let chunk = chunk.max(1);
    let chunks = data.len().div_ceil(chunk);
    let per = chunks.div_ceil(threads.max(1)).max(1);
    std::thread::scope(|scope| {
        let handles: Vec<_> = data
            .chunks_mut(chunk * per)
            .enumerate()
            .map(|(t, run)| {
                let f = &f;
                scope.spawn(move || {
                    run.chunks_mut(chunk)
                        .enumerate()
                        .map(|(j, c)| f(t * per + j, c))
                        .collect::<Vec<R>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("a build thread does not panic"))
            .collect()
    })
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points owned by a test.
    struct Cloud {
        positions: Vec<Vec3>,
        colors: Vec<Vec3>,
        normals: Option<Vec<Vec3>>,
    }

    impl Cloud {
        fn points(&self) -> Points<'_> {
            Points {
                positions: &self.positions,
                colors: &self.colors,
                normals: self.normals.as_deref(),
            }
        }
    }

    /// Uniform numbers in [0, 1) from `seed`, the same on every run.
    pub(super) fn lcg(seed: u64) -> impl FnMut() -> f32 {
        let mut state = seed;
        move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    fn cloud(n: usize, seed: u64, normals: bool) -> Cloud {
        let mut next = lcg(seed);
        let positions: Vec<Vec3> = (0..n)
            .map(|_| Vec3::new(next(), next(), 0.1 * next()))
            .collect();
        let colors = (0..n).map(|_| Vec3::new(next(), next(), next())).collect();
        let normals = normals.then(|| {
            (0..n)
                .map(|_| Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize())
                .collect()
        });
        Cloud {
            positions,
            colors,
            normals,
        }
    }

    #[test]
    fn the_build_is_the_same_bytes_whatever_the_threads() {
        let c = cloud(200_000, 7, true);
        let one = SplatTree::build(c.points(), LeafSize::SpacingTimes(1.0), 1).to_bytes();
        for t in [2, 3, 8] {
            assert!(
                one == SplatTree::build(c.points(), LeafSize::SpacingTimes(1.0), t).to_bytes(),
                "threads {t}"
            );
        }
    }

    /// The build that drops its cloud early is the same tree.
    #[test]
    fn the_build_of_an_owned_cloud_is_the_same_bytes() {
        let c = cloud(200_000, 11, true);
        let expected = SplatTree::build(c.points(), LeafSize::SpacingTimes(1.0), 2).to_bytes();
        let owned = SplatTree::build_owned(c, Cloud::points, LeafSize::SpacingTimes(1.0), 2);
        assert!(expected == owned.to_bytes());
    }

    #[test]
    fn every_node_holds_its_children_and_their_cones() {
        let c = cloud(20_000, 3, true);
        let tree = SplatTree::build(c.points(), LeafSize::SpacingTimes(1.0), 2);
        assert_eq!(tree.levels().last().map(Vec::len), Some(1), "one root");
        assert!(tree.bytes() as f64 / c.positions.len() as f64 <= 32.0);
        for level in 1..=tree.levels().len() {
            for i in 0..tree.level_len(level) {
                let (p, cone) = tree.node(level, i);
                let pc = p.centre();
                let axis = oct_decode(p.color[3]);
                for k in tree.children(level, i) {
                    let (s, child_cone) = tree.node(level - 1, k);
                    let sc = s.centre();
                    let reach = pc.distance(sc) + 0.5 * s.position_size[3];
                    assert!(reach <= 0.5 * p.position_size[3], "level {level} node {i}");
                    let a = angle(axis, oct_decode(s.color[3])) + child_cone;
                    assert!(
                        a <= cone + 1e-6 || cone == std::f32::consts::PI,
                        "cone at level {level} node {i}"
                    );
                }
            }
        }
        // Every point's true normal lies in its leaf's cone.
        let order = morton_order(&c.positions, 1);
        let normals = c.normals.as_ref().unwrap();
        for (leaf, &i) in tree.leaves().iter().zip(&order) {
            let a = angle(oct_decode(leaf.color[3]), normals[i as usize]);
            assert!(a <= tree.leaf_cone_rad && tree.leaf_cone_rad < 0.02);
        }
    }

    #[test]
    fn groups_break_at_jumps_and_the_tree_stays_within_32_bytes_a_point() {
        // Pairs of close points, the pairs far apart: every group of the
        // first level would be a pair, so that level takes fixed groups.
        let positions: Vec<Vec3> = (0..40_000)
            .map(|i| Vec3::new((i / 2) as f32, (i % 2) as f32 * 0.01, 0.0))
            .collect();
        let n = positions.len();
        let c = Cloud {
            colors: vec![Vec3::splat(0.5); n],
            positions,
            normals: None,
        };
        let tree = SplatTree::build(c.points(), LeafSize::SpacingTimes(1.0), 2);
        assert!(tree.bytes() as f64 / n as f64 <= 32.0, "{}", tree.bytes());
        // A cloud of two clusters far apart: no group of the first level
        // holds points of both.
        let mut positions: Vec<Vec3> = Vec::new();
        for i in 0..4004 {
            let p = Vec3::new((i % 20) as f32, (i / 20 % 20) as f32, (i / 400) as f32) * 0.01;
            positions.push(
                p + if i % 2 == 0 {
                    Vec3::ZERO
                } else {
                    Vec3::splat(5.0)
                },
            );
        }
        let c = Cloud {
            colors: vec![Vec3::splat(0.5); positions.len()],
            positions,
            normals: None,
        };
        let tree = SplatTree::build(c.points(), LeafSize::SpacingTimes(1.0), 2);
        for g in 0..tree.level_len(1) {
            let xs: Vec<f32> = tree
                .children(1, g)
                .map(|k| tree.leaves()[k].position_size[0])
                .collect();
            assert!(
                xs.iter().all(|&x| x < 1.0) || xs.iter().all(|&x| x > 4.0),
                "{xs:?}"
            );
            assert!(xs.len() <= FANOUT);
        }
    }

    #[test]
    fn a_node_color_is_the_mean_of_its_points() {
        let c = cloud(64, 5, false);
        let tree = SplatTree::build(c.points(), LeafSize::World(0.01), 1);
        let root = tree.levels().last().unwrap()[0].splat;
        for ch in 0..3 {
            let mean = c.colors.iter().map(|v| v[ch]).sum::<f32>() / 64.0;
            assert!((root.color[ch] as f32 / 65535.0 - mean).abs() < 2e-4);
        }
    }

    #[test]
    fn octahedral_normals_round_trip_within_a_degree() {
        for i in 0..2000 {
            let t = i as f32 * 0.6180339;
            let z = 2.0 * (t.fract()) - 1.0;
            let phi = i as f32 * 2.399963;
            let r = (1.0 - z * z).sqrt();
            let n = Vec3::new(r * phi.cos(), r * phi.sin(), z);
            assert!(
                angle(n, oct_decode(oct_encode(n))) < 1.0f32.to_radians(),
                "{n}"
            );
        }
    }
}
