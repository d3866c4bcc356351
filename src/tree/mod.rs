//! The splat hierarchy (DESIGN §3, Zhao §2 after QSplat): bounding spheres
//! over the points in Morton order, built once per cloud, and the per-frame
//! traversal that culls and picks the level of detail.
//!
//! Layout (docs/ARCHITECTURE.md, "Splat hierarchy"). Level 0 holds the
//! points themselves, sorted by the Morton code of their position, as the
//! splat vertices the raster pass reads (24 bytes: position, world
//! diameter, linear color as UNORM16; the color's unused alpha holds the
//! octahedral normal). Level l ≥ 1 groups runs of at most 8 consecutive
//! nodes of level l − 1, broken wherever Morton order jumps (the next node
//! farther from the one before than `GROUP_JUMP_RADII` of their radii), so
//! that each group is compact. An inner node is a [`Node`] (32 bytes: its
//! splat — centre, diameter of the bounding sphere, mean color, mean
//! normal — the normal cone's half-angle, and its first child; the
//! children run to the next node's first child). About 30.8 bytes per
//! point for every level together, at most 32.

use std::time::Instant;

use bytemuck::Zeroable;
use glam::{Vec2, Vec3};

use crate::camera::{Camera, EyeFromWorld};
use crate::cloud::PointCloud;
use crate::passes::splat_raster::SplatVertex;

/// The most children of an inner node.
pub const FANOUT: usize = 8;

/// A group of consecutive nodes ends where the next one lies farther from
/// its predecessor than this many times the larger of their radii: there
/// Morton order jumped across a cell boundary, and a node spanning the jump
/// would be too large for the level of detail.
pub const GROUP_JUMP_RADII: f32 = 4.0;

/// How many points `tree_spacing` looks at on either side of a point in
/// Morton order.
pub const SPACING_WINDOW: usize = 12;

/// How many of those nearest candidates it averages (as the k-NN spacing
/// of `PointCloud::local_spacing`).
pub const SPACING_NEIGHBOURS: usize = crate::cloud::SPACING_NEIGHBOURS;

/// An inner node: its splat (centre, diameter of the bounding sphere, mean
/// linear color, octahedral mean normal in the color's alpha) and the
/// half-angle of the cone that holds every normal beneath it (radians;
/// π: any direction).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Node {
    pub splat: SplatVertex,
    pub cone_rad: f32,
    /// Its first child in the level below; the children run to the next
    /// node's first child (the last node's: to the end of that level).
    pub first_child: u32,
}

const _: () = assert!(std::mem::size_of::<Node>() == 32);

/// How a leaf's world diameter is chosen (DESIGN §3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LeafSize<'a> {
    /// `SPACING_TO_DIAMETER` × the tree's local spacing ([`tree_spacing`]).
    Spacing,
    /// Every leaf this world diameter.
    World(f32),
    /// Zero: the raster sizes splats in pixels.
    Zero,
    /// Each point's world diameter, in the cloud's order.
    PerPoint(&'a [f32]),
}

/// The hierarchy of one cloud.
#[derive(Debug, Clone, Default)]
pub struct SplatTree {
    /// Level 0: the points in Morton order.
    leaves: Vec<SplatVertex>,
    /// Levels 1, 2, …: the last holds the root alone.
    levels: Vec<Vec<Node>>,
    has_normals: bool,
    /// The largest angle between a point's normal and its stored
    /// (quantised) one: the leaves' normal cone.
    leaf_cone_rad: f32,
    /// Where each step of the build went.
    pub build: BuildTimes,
}

/// Wall times of the build's steps, milliseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BuildTimes {
    pub morton_sort_ms: f64,
    pub spacing_ms: f64,
    pub levels_ms: f64,
    pub total_ms: f64,
}

/// What a frame asks of the traversal (DESIGN §3, `--lod-px`, `--lod-blur`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lod {
    /// Emit an inner node when its projected diameter is at most this many
    /// pixels. 0: no traversal, every point is drawn.
    pub px: f32,
    /// Also emit it when its projected diameter is at most this multiple
    /// of the smallest CoC over its depth range (None: off).
    pub blur: Option<f32>,
}

impl Default for Lod {
    fn default() -> Lod {
        Lod {
            px: 1.0,
            blur: None,
        }
    }
}

impl Lod {
    /// Every point, no culling (`--lod-px 0`).
    pub const ALL: Lod = Lod {
        px: 0.0,
        blur: None,
    };

    /// Whether the frame draws every point without a traversal.
    pub fn draws_all(&self) -> bool {
        self.px == 0.0
    }
}

/// What widens the frustum beyond each node's own CoC (DESIGN §3: blurred
/// geometry entering the frame still counts).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Widening {
    /// The background's CoC when the method blurs the background (its
    /// guard band holds it, so pixels that far out take part), else 0.
    pub background_coc_px: f32,
    /// `--splat-px`: splats drawn this wide whatever their sphere (0: off).
    pub splat_px: f32,
}

/// One frame's splats and what the traversal did.
#[derive(Debug, Clone, Default)]
pub struct Traversal {
    pub splats: Vec<SplatVertex>,
    /// Nodes tested (leaves included).
    pub nodes_visited: u64,
    /// Inner nodes among the emitted splats.
    pub inner_emitted: u64,
    /// Wall time, milliseconds.
    pub ms: f64,
}

/// The camera-dependent part of the tests, made once per frame.
#[derive(Debug, Clone, Copy)]
struct View {
    camera: Camera,
    eye_from_world: EyeFromWorld,
    f_px: f32,
    centre: Vec2,
    widening: Widening,
    lod: Lod,
}

enum Test {
    Cull,
    Emit,
    Recurse,
}

impl SplatTree {
    /// Builds the hierarchy of `cloud` on `threads` threads (the result is
    /// the same bytes whatever the count).
    pub fn build(cloud: &PointCloud, size: LeafSize, threads: usize) -> SplatTree {
        let started = Instant::now();
        let threads = threads.max(1);
        let n = cloud.len();
        if n == 0 {
            return SplatTree::default();
        }
        let order = morton_order(&cloud.positions, threads);
        let per_point = match size {
            LeafSize::PerPoint(d) => Some(d),
            _ => None,
        };
        let normals = cloud.normals.as_deref();
        let mut leaves: Vec<SplatVertex> = vec![SplatVertex::zeroed(); n];
        let leaf_cone = par_chunks(&mut leaves, CHUNK, threads, |c, out| {
            let mut worst = 0.0f32;
            for (j, v) in out.iter_mut().enumerate() {
                let i = order[c * CHUNK + j] as usize;
                let p = cloud.positions[i];
                let col = cloud.colors[i];
                let packed = match normals {
                    Some(ns) => {
                        let packed = oct_encode(ns[i]);
                        worst = worst.max(angle(ns[i], oct_decode(packed)));
                        packed
                    }
                    None => 0,
                };
                *v = SplatVertex {
                    position_size: [p.x, p.y, p.z, per_point.map_or(0.0, |d| d[i])],
                    color: [unorm16(col.x), unorm16(col.y), unorm16(col.z), packed],
                };
            }
            worst
        });
        drop(order);
        let leaf_cone_rad = leaf_cone.iter().fold(0.0f32, |m, &w| m.max(w));
        let sorted_ms = ms_since(started);

        let spacing_started = Instant::now();
        match size {
            LeafSize::World(w) => leaves.iter_mut().for_each(|v| v.position_size[3] = w),
            LeafSize::Zero | LeafSize::PerPoint(_) => {}
            LeafSize::Spacing => {
                let in_order: Vec<Vec3> = leaves.iter().map(SplatVertex::centre).collect();
                let spacing = tree_spacing(&in_order, threads);
                drop(in_order);
                let fallback = crate::cloud::median(spacing.clone());
                for (v, s) in leaves.iter_mut().zip(spacing) {
                    v.position_size[3] =
                        crate::render::SPACING_TO_DIAMETER * if s > 0.0 { s } else { fallback };
                }
            }
        }
        let spacing_ms = ms_since(spacing_started);

        let levels_started = Instant::now();
        let has_normals = normals.is_some();
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
            let get = |j: usize| -> (SplatVertex, f32) {
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
                // point at most with the leaves.
                starts = (0..below).step_by(FANOUT).map(|j| j as u32).collect();
            }
            let mut nodes = vec![Node::zeroed(); starts.len()];
            let end = |g: usize| starts.get(g + 1).map_or(below, |&e| e as usize);
            par_chunks(&mut nodes, CHUNK / FANOUT, threads, |c, out| {
                for (j, node) in out.iter_mut().enumerate() {
                    let g = c * (CHUNK / FANOUT) + j;
                    let children: Vec<(SplatVertex, f32, f32)> = (starts[g] as usize..end(g))
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
        let levels_ms = ms_since(levels_started);
        SplatTree {
            leaves,
            levels,
            has_normals,
            leaf_cone_rad,
            build: BuildTimes {
                morton_sort_ms: sorted_ms,
                spacing_ms,
                levels_ms,
                total_ms: ms_since(started),
            },
        }
    }

    /// The same points and splat sizes as [`SplatTree::build`], drawn in
    /// the cloud's own order and without a hierarchy (every frame draws
    /// every point, whatever the LOD): for measuring what Morton order
    /// gains the raster (`examples/point_order.rs`).
    pub fn build_in_input_order(cloud: &PointCloud, size: LeafSize, threads: usize) -> SplatTree {
        let mut tree = SplatTree::build(cloud, size, threads);
        let order = morton_order(&cloud.positions, threads);
        let mut leaves = vec![SplatVertex::zeroed(); tree.leaves.len()];
        for (v, &i) in tree.leaves.iter().zip(&order) {
            leaves[i as usize] = *v;
        }
        tree.leaves = leaves;
        tree.levels.clear();
        tree
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.leaves.len()
    }

    /// Whether the tree has no points.
    pub fn is_empty(&self) -> bool {
        self.leaves.is_empty()
    }

    /// The points in Morton order (level 0).
    pub fn leaves(&self) -> &[SplatVertex] {
        &self.leaves
    }

    /// The inner levels, from the leaves' parents up to the root.
    pub fn levels(&self) -> &[Vec<Node>] {
        &self.levels
    }

    /// Whether the cloud had normals (else no back-face culling).
    pub fn has_normals(&self) -> bool {
        self.has_normals
    }

    /// Host bytes of every level together.
    pub fn bytes(&self) -> usize {
        self.leaves.len() * std::mem::size_of::<SplatVertex>()
            + self.levels.iter().map(Vec::len).sum::<usize>() * std::mem::size_of::<Node>()
    }

    /// The whole tree as bytes (leaves, then each level): the same for the
    /// same cloud whatever the thread count (a test).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = bytemuck::cast_slice(&self.leaves).to_vec();
        for l in &self.levels {
            b.extend_from_slice(bytemuck::cast_slice(l));
        }
        b.extend_from_slice(&self.leaf_cone_rad.to_le_bytes());
        b
    }

    /// Node `i` of level `level` (0: a leaf) as (splat, cone half-angle).
    pub fn node(&self, level: usize, i: usize) -> (SplatVertex, f32) {
        if level == 0 {
            (self.leaves[i], self.leaf_cone_rad)
        } else {
            let n = &self.levels[level - 1][i];
            (n.splat, n.cone_rad)
        }
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

    /// The splats of one frame (DESIGN §3, Zhao §2): from the root, drop
    /// nodes outside the view frustum widened by their largest CoC (and by
    /// `widening`), drop
    /// nodes whose normal cone faces away from every point of the lens,
    /// emit a node when it is a leaf or its projected diameter is at most
    /// `lod.px` (or `lod.blur` × its smallest CoC), otherwise recurse.
    /// With `lod.px` 0, every point in Morton order. Output order is Morton
    /// order, whatever `threads`.
    pub fn traverse(
        &self,
        camera: &Camera,
        lod: Lod,
        widening: Widening,
        threads: usize,
    ) -> Traversal {
        let started = Instant::now();
        if lod.draws_all() || self.levels.is_empty() {
            return Traversal {
                splats: self.leaves.clone(),
                nodes_visited: 0,
                inner_emitted: 0,
                ms: ms_since(started),
            };
        }
        let view = View {
            camera: *camera,
            eye_from_world: camera.eye_from_world_transform(),
            f_px: camera.f_px(),
            centre: Vec2::new(camera.width as f32 / 2.0, camera.height as f32 / 2.0),
            widening,
            lod,
        };
        // Breadth first from the root until there is work for every
        // thread: a list in Morton order of emitted splats and subtrees
        // still to walk (a fixed target, so the same list whatever
        // `threads`).
        enum Item {
            Splat(SplatVertex, bool),
            Subtree(usize, usize),
        }
        let top = self.levels.len();
        let mut items = vec![Item::Subtree(top, 0)];
        let mut visited = 0u64;
        loop {
            let pending = items
                .iter()
                .filter(|i| matches!(i, Item::Subtree(l, _) if *l > 0))
                .count();
            if pending == 0 || pending >= FRONTIER {
                break;
            }
            let mut next = Vec::with_capacity(items.len() * FANOUT);
            for item in items {
                match item {
                    Item::Subtree(level, i) if level > 0 => {
                        visited += 1;
                        let (s, cone) = self.node(level, i);
                        match self.test(&view, &s, cone, false) {
                            Test::Cull => {}
                            Test::Emit => next.push(Item::Splat(s, true)),
                            Test::Recurse => {
                                next.extend(
                                    self.children(level, i).map(|c| Item::Subtree(level - 1, c)),
                                );
                            }
                        }
                    }
                    other => next.push(other),
                }
            }
            items = next;
        }
        let subtrees: Vec<(usize, usize)> = items
            .iter()
            .filter_map(|i| match i {
                Item::Subtree(l, n) => Some((*l, *n)),
                Item::Splat(..) => None,
            })
            .collect();
        // Each subtree depth first, split over the threads in contiguous
        // runs; outputs joined in order.
        let per = subtrees.len().div_ceil(threads.max(1)).max(1);
        let results: Vec<Vec<(Vec<SplatVertex>, u64, u64)>> = std::thread::scope(|scope| {
            let handles: Vec<_> = subtrees
                .chunks(per)
                .map(|run| {
                    let view = &view;
                    scope.spawn(move || {
                        run.iter()
                            .map(|&(l, i)| {
                                let mut out = Vec::new();
                                let (mut visited, mut inner) = (0u64, 0u64);
                                self.walk(view, l, i, &mut out, &mut visited, &mut inner);
                                (out, visited, inner)
                            })
                            .collect()
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().expect("a traversal thread does not panic"))
                .collect()
        });
        let mut walked = results.into_iter().flatten();
        let mut splats = Vec::new();
        let mut inner_emitted = 0u64;
        for item in items {
            match item {
                Item::Splat(s, inner) => {
                    splats.push(s);
                    inner_emitted += inner as u64;
                }
                Item::Subtree(..) => {
                    let (out, v, inner) = walked.next().expect("one result per subtree");
                    splats.extend_from_slice(&out);
                    visited += v;
                    inner_emitted += inner;
                }
            }
        }
        Traversal {
            splats,
            nodes_visited: visited,
            inner_emitted,
            ms: ms_since(started),
        }
    }

    /// Depth-first walk of the subtree at (level, i).
    fn walk(
        &self,
        view: &View,
        level: usize,
        i: usize,
        out: &mut Vec<SplatVertex>,
        visited: &mut u64,
        inner: &mut u64,
    ) {
        *visited += 1;
        let (s, cone) = self.node(level, i);
        match self.test(view, &s, cone, level == 0) {
            Test::Cull => {}
            Test::Emit => {
                out.push(s);
                *inner += (level > 0) as u64;
            }
            Test::Recurse => {
                for c in self.children(level, i) {
                    self.walk(view, level - 1, c, out, visited, inner);
                }
            }
        }
    }

    /// The traversal's decision for one node.
    fn test(&self, view: &View, s: &SplatVertex, cone_rad: f32, leaf: bool) -> Test {
        let (centre, r) = s.sphere();
        let e = view.eye_from_world.apply(centre);
        let in_front = e.z - r > 0.0;
        // Behind the lens, nothing of it can be seen. A leaf is one depth,
        // so its CoC is that depth's; an inner node's is the largest over
        // its sphere's depths, unbounded when the sphere reaches the lens
        // plane (then no frustum test).
        let coc_px = if leaf {
            if e.z <= 0.0 {
                return Test::Cull;
            }
            Some(view.camera.coc_px(e.z))
        } else {
            if e.z + r <= 0.0 {
                return Test::Cull;
            }
            in_front.then(|| max_coc_px(&view.camera, e.z - r, e.z + r))
        };
        if coc_px.is_some_and(|c| outside_frustum(view, e, r, c)) {
            return Test::Cull;
        }
        if self.has_normals && back_facing(view, centre, r, s.color[3], cone_rad) {
            return Test::Cull;
        }
        if leaf {
            return Test::Emit;
        }
        if in_front {
            // The size the vertex shader draws: f_px · diameter / z.
            let size_px = view.f_px * s.position_size[3] / e.z;
            if size_px <= view.lod.px {
                return Test::Emit;
            }
            if let Some(f) = view.lod.blur {
                if size_px <= f * min_coc_px(&view.camera, e.z - r, e.z + r) {
                    return Test::Emit;
                }
            }
        }
        Test::Recurse
    }
}

/// Breadth-first expansion stops at this many subtrees.
const FRONTIER: usize = 4096;

/// Points per unit of parallel work in the build.
const CHUNK: usize = 1 << 16;

/// The largest CoC in pixels over eye depths [z0, z1], 0 < z0 ≤ z1 (the
/// CoC falls towards the focus plane from either side, so an end holds it).
pub fn max_coc_px(camera: &Camera, z0: f32, z1: f32) -> f32 {
    camera.coc_px(z0).max(camera.coc_px(z1))
}

/// The smallest CoC in pixels over eye depths [z0, z1], 0 < z0 ≤ z1.
pub fn min_coc_px(camera: &Camera, z0: f32, z1: f32) -> f32 {
    let s = camera.focus_distance;
    if z0 <= s && s <= z1 {
        0.0
    } else {
        camera.coc_px(z0).min(camera.coc_px(z1))
    }
}

/// Whether the sphere (eye-space centre `e`, radius `r`, wholly in front
/// of the lens) lies outside the frustum of the image widened by
/// max(`coc_px`, the background's CoC) / 2 + `--splat-px` / 2 + 1 px on
/// every side: then neither it nor its blur reaches the image (the extra
/// 1 px holds sprites clamped to one pixel and the SSAA jitter).
fn outside_frustum(view: &View, e: Vec3, r: f32, coc_px: f32) -> bool {
    let w = &view.widening;
    let margin = 0.5 * coc_px.max(w.background_coc_px) + 0.5 * w.splat_px + 1.0;
    let f = view.f_px;
    let (w, h) = (view.camera.width as f32, view.camera.height as f32);
    let (x0, x1) = (-margin, w + margin);
    let (y0, y1) = (-margin, h + margin);
    let c = view.centre;
    // Each side as a plane through the eye, a·e ≥ 0 inside (pixel x =
    // c.x + f·x/z, pixel y = c.y − f·y/z).
    let sides = [
        Vec3::new(f, 0.0, c.x - x0),
        Vec3::new(-f, 0.0, x1 - c.x),
        Vec3::new(0.0, -f, c.y - y0),
        Vec3::new(0.0, f, y1 - c.y),
    ];
    sides.iter().any(|a| a.dot(e) < -r * a.length())
}

/// Whether every normal of the cone (axis from `packed`, half-angle
/// `cone_rad`) faces away from every point of the lens disk (within the
/// aperture radius of the eye) for every point of the sphere.
fn back_facing(view: &View, centre: Vec3, r: f32, packed: u16, cone_rad: f32) -> bool {
    if cone_rad >= std::f32::consts::FRAC_PI_2 {
        return false;
    }
    let to_eye = view.camera.eye - centre;
    let d = to_eye.length();
    let reach = r + view.camera.aperture_radius;
    if d <= reach {
        return false;
    }
    // The directions from the sphere to the lens lie within `spread` of
    // `to_eye`; the normals within `cone_rad` of `n`.
    let spread = (reach / d).asin();
    let n = oct_decode(packed);
    let between = angle(n, to_eye / d);
    between > std::f32::consts::FRAC_PI_2 + cone_rad + spread + ANGLE_SLACK_RAD
}

/// Rounding slack of the angle tests (f32 acos/asin).
const ANGLE_SLACK_RAD: f32 = 1e-3;

/// The parent of `children` (splat, cone, leaves beneath): the sphere
/// holding theirs, their mean color and normal weighted by leaves beneath,
/// and the cone holding their cones.
fn merge(children: &[(SplatVertex, f32, f32)], has_normals: bool) -> Node {
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
        splat: SplatVertex {
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
fn group_starts(count: usize, splat: impl Fn(usize) -> SplatVertex, jump_radii: f32) -> Vec<u32> {
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

/// The points' order by 63-bit Morton code of their position quantised to
/// 2^21 steps over the bounding cube; equal codes keep input order (a
/// stable LSD radix sort, so the order is unique).
pub fn morton_order(positions: &[Vec3], threads: usize) -> Vec<u32> {
    morton_order_in(positions, threads, None)
}

/// [`morton_order`] over a cube twice the size, moved by `shift` (in
/// units of the bounding cube's side, each in [0, 1)): another order whose
/// cell boundaries fall elsewhere.
fn morton_order_in(positions: &[Vec3], threads: usize, shift: Option<Vec3>) -> Vec<u32> {
    let (lo, hi) = positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let mut extent = (hi - lo).max_element().max(f32::MIN_POSITIVE);
    let mut origin = lo;
    if let Some(shift) = shift {
        origin -= shift * extent;
        extent *= 2.0;
    }
    let scale = ((1u32 << 21) - 1) as f32 / extent;
    let mut keys = vec![0u64; positions.len()];
    par_chunks(&mut keys, CHUNK, threads, |c, out| {
        for (j, k) in out.iter_mut().enumerate() {
            let q = ((positions[c * CHUNK + j] - origin) * scale)
                .round()
                .clamp(Vec3::ZERO, Vec3::splat(((1u32 << 21) - 1) as f32))
                .as_uvec3();
            *k = spread3(q.x) | spread3(q.y) << 1 | spread3(q.z) << 2;
        }
    });
    radix_sort(keys, threads)
}

/// The low 21 bits of `v`, two zero bits after each.
fn spread3(v: u32) -> u64 {
    let mut x = (v & 0x1F_FFFF) as u64;
    x = (x | x << 32) & 0x1F_0000_0000_FFFF;
    x = (x | x << 16) & 0x1F_0000_FF00_00FF;
    x = (x | x << 8) & 0x100F_00F0_0F00_F00F;
    x = (x | x << 4) & 0x10C3_0C30_C30C_30C3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// The stable order of `keys` (LSD radix sort, 8 bits a pass, passes where
/// every key has the same digit skipped), on `threads` threads: each pass
/// counts digits per chunk in parallel, then scatters each chunk to its
/// own offsets, so the result is the same for any split. The arrays are
/// atomics (relaxed: plain loads and stores on x86) so that the threads
/// may write to disjoint, scattered indices without `unsafe`.
fn radix_sort(keys: Vec<u64>, threads: usize) -> Vec<u32> {
    use std::sync::atomic::{AtomicU32, AtomicU64, Ordering::Relaxed};
    let n = keys.len();
    let mut keys: Vec<AtomicU64> = keys.into_iter().map(AtomicU64::new).collect();
    let mut index: Vec<AtomicU32> = (0..n as u32).map(AtomicU32::new).collect();
    let mut keys_out: Vec<AtomicU64> = (0..n).map(|_| AtomicU64::new(0)).collect();
    let mut index_out: Vec<AtomicU32> = (0..n).map(|_| AtomicU32::new(0)).collect();
    let chunk = n.div_ceil(threads.max(1)).max(CHUNK);
    for pass in 0..8 {
        let shift = pass * 8;
        let digit = |k: &AtomicU64| (k.load(Relaxed) >> shift) as usize & 0xFF;
        let counts: Vec<[usize; 256]> = std::thread::scope(|scope| {
            let handles: Vec<_> = keys
                .chunks(chunk)
                .map(|part| {
                    scope.spawn(move || {
                        let mut c = [0usize; 256];
                        part.iter().for_each(|k| c[digit(k)] += 1);
                        c
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().expect("a counting thread does not panic"))
                .collect()
        });
        if (0..256).any(|d| counts.iter().map(|c| c[d]).sum::<usize>() == n) {
            continue; // Every key has the same digit: the order stands.
        }
        // Offsets: digit-major, then chunk order (stability).
        let mut offsets = vec![[0usize; 256]; counts.len()];
        let mut at = 0usize;
        for d in 0..256 {
            for (o, c) in offsets.iter_mut().zip(&counts) {
                o[d] = at;
                at += c[d];
            }
        }
        std::thread::scope(|scope| {
            for ((part, idx), mut off) in keys.chunks(chunk).zip(index.chunks(chunk)).zip(offsets) {
                let (keys_out, index_out) = (&keys_out, &index_out);
                scope.spawn(move || {
                    for (k, i) in part.iter().zip(idx) {
                        let d = digit(k);
                        keys_out[off[d]].store(k.load(Relaxed), Relaxed);
                        index_out[off[d]].store(i.load(Relaxed), Relaxed);
                        off[d] += 1;
                    }
                });
            }
        });
        std::mem::swap(&mut keys, &mut keys_out);
        std::mem::swap(&mut index, &mut index_out);
    }
    index.into_iter().map(AtomicU32::into_inner).collect()
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

/// The tree's local spacing of every point of `p` (the points in Morton
/// order): the mean distance to its `SPACING_NEIGHBOURS` nearest among the
/// `SPACING_WINDOW` points on either side of it in Morton order, the
/// smaller of two Morton orders whose cell boundaries differ (a point
/// alone in its cell of one order, its neighbours far before or after it,
/// has them beside it in the other). An approximation of
/// `PointCloud::local_spacing`'s exact k nearest neighbours, at a fixed
/// cost per point; 0 for a single point.
pub fn tree_spacing(p: &[Vec3], threads: usize) -> Vec<f32> {
    let mut spacing = window_spacing(p, threads);
    // The second order, as indices into the first (both are spatially
    // coherent, so the gather and scatter below stay mostly in cache).
    let second = morton_order_in(p, threads, Some(SECOND_ORDER_SHIFT));
    let in_second: Vec<Vec3> = second.iter().map(|&i| p[i as usize]).collect();
    let other = window_spacing(&in_second, threads);
    for (&i, s) in second.iter().zip(other) {
        let slot = &mut spacing[i as usize];
        *slot = slot.min(s);
    }
    spacing.iter_mut().for_each(|s| *s /= SPACING_BIAS);
    spacing
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
    let order = morton_order(positions, threads);
    let in_order: Vec<Vec3> = order.iter().map(|&i| positions[i as usize]).collect();
    crate::cloud::median(tree_spacing(&in_order, threads))
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

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize, seed: u64, normals: bool) -> PointCloud {
        let mut state = seed;
        let mut next = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let positions: Vec<Vec3> = (0..n)
            .map(|_| Vec3::new(next(), next(), 0.1 * next()))
            .collect();
        let colors = (0..n).map(|_| Vec3::new(next(), next(), next())).collect();
        let normals = normals.then(|| {
            (0..n)
                .map(|_| Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize())
                .collect()
        });
        PointCloud {
            positions,
            colors,
            normals,
            has_colors: true,
            attributes: vec![],
            ..Default::default()
        }
    }

    #[test]
    fn morton_order_is_a_stable_sort_by_code() {
        let mut positions: Vec<Vec3> = (0..5000)
            .map(|i| {
                Vec3::new(
                    (i * 7919 % 100) as f32,
                    (i * 104729 % 37) as f32,
                    (i % 11) as f32,
                )
            })
            .collect();
        positions.push(positions[3]); // a duplicate: input order kept
        for threads in [1, 2, 3] {
            let order = morton_order(&positions, threads);
            let mut sorted: Vec<u32> = (0..positions.len() as u32).collect();
            let code = |p: Vec3| {
                let q = (p / 99.0 * ((1u32 << 21) - 1) as f32).round().as_uvec3();
                spread3(q.x) | spread3(q.y) << 1 | spread3(q.z) << 2
            };
            sorted.sort_by_key(|&i| (code(positions[i as usize]), i));
            assert_eq!(order, sorted, "threads {threads}");
        }
    }

    #[test]
    fn spread3_interleaves() {
        assert_eq!(spread3(0b1011), 0b1_000_001_001);
        assert_eq!(spread3(0x1F_FFFF).count_ones(), 21);
        assert_eq!(spread3(0x1F_FFFF) >> 60, 1);
    }

    #[test]
    fn the_build_is_the_same_bytes_whatever_the_threads() {
        let c = cloud(200_000, 7, true);
        let one = SplatTree::build(&c, LeafSize::Spacing, 1).to_bytes();
        for t in [2, 3, 8] {
            assert!(
                one == SplatTree::build(&c, LeafSize::Spacing, t).to_bytes(),
                "threads {t}"
            );
        }
    }

    #[test]
    fn every_node_holds_its_children_and_their_cones() {
        let c = cloud(20_000, 3, true);
        let tree = SplatTree::build(&c, LeafSize::Spacing, 2);
        assert_eq!(tree.levels().last().map(Vec::len), Some(1), "one root");
        assert!(tree.bytes() as f64 / c.len() as f64 <= 32.0);
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
        let c = PointCloud {
            colors: vec![Vec3::splat(0.5); n],
            positions,
            normals: None,
            has_colors: true,
            attributes: vec![],
            ..Default::default()
        };
        let tree = SplatTree::build(&c, LeafSize::Spacing, 2);
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
        let c = PointCloud {
            colors: vec![Vec3::splat(0.5); positions.len()],
            positions,
            ..c
        };
        let tree = SplatTree::build(&c, LeafSize::Spacing, 2);
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
        let tree = SplatTree::build(&c, LeafSize::World(0.01), 1);
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
