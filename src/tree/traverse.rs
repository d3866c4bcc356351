//! The per-frame traversal (DESIGN §3, Zhao §2): from the root, cull what
//! cannot reach the image and stop where a node is small enough for the
//! level of detail.

use std::time::Instant;

use bytemuck::Zeroable;
use glam::{Vec2, Vec3};

use super::{angle, ms_since, oct_decode, Splat, SplatTree, FANOUT};
use crate::camera::{Camera, EyeFromWorld};
use crate::options::Lod;

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
    pub splats: Vec<Splat>,
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
    /// Whether a subtree whose every leaf the tests would emit is taken
    /// whole ([`SplatTree::holds_its_leaves`]); off only to test that it
    /// gives the same splats.
    whole_subtrees: bool,
}

impl View {
    fn new(camera: &Camera, lod: Lod, widening: Widening) -> View {
        View {
            whole_subtrees: true,
            camera: *camera,
            eye_from_world: camera.eye_from_world_transform(),
            f_px: camera.f_px(),
            centre: Vec2::new(camera.width as f32 / 2.0, camera.height as f32 / 2.0),
            widening,
            lod,
        }
    }
}

enum Test {
    Cull,
    Emit,
    Recurse,
    /// Every leaf beneath, in order, and nothing else: what recursing
    /// would emit.
    Leaves,
}

/// A run of a traversal's output: an inner node's splat, or leaves in
/// order (indices into [`SplatTree::leaves`]).
enum Piece {
    Inner(Splat),
    Leaves(std::ops::Range<usize>),
}

/// `piece` after `pieces`, a run of leaves joined to the run it continues.
fn push_piece(pieces: &mut Vec<Piece>, piece: Piece) {
    if let (Some(Piece::Leaves(last)), Piece::Leaves(run)) = (pieces.last_mut(), &piece) {
        if last.end == run.start {
            last.end = run.end;
            return;
        }
    }
    pieces.push(piece);
}

impl SplatTree {
    /// The splats of one frame (DESIGN §3, Zhao §2): from the root, drop
    /// nodes outside the view frustum widened by their largest CoC (and by
    /// `widening`), with `lod.cull_back_faces` drop nodes whose normal
    /// cone faces away from every point of the lens, emit a node when it
    /// is a leaf or its projected diameter is at most `lod.px` (or
    /// `lod.blur` × its smallest CoC), otherwise recurse.
    /// With `lod.px` 0, every point in Morton order. Output order is Morton
    /// order, whatever `threads`.
    pub fn traverse(
        &self,
        camera: &Camera,
        lod: Lod,
        widening: Widening,
        threads: usize,
    ) -> Traversal {
        self.traverse_with(View::new(camera, lod, widening), threads)
    }

    /// [`SplatTree::traverse`] through `view`.
    fn traverse_with(&self, view: View, threads: usize) -> Traversal {
        let started = Instant::now();
        let lod = view.lod;
        if lod.draws_all() {
            return Traversal {
                splats: self.leaves.clone(),
                nodes_visited: 0,
                inner_emitted: 0,
                ms: ms_since(started),
            };
        }
        if self.levels.is_empty() {
            // No inner node (a single point, or none): each leaf tested.
            let splats: Vec<Splat> = (0..self.leaves.len())
                .filter(|&i| matches!(self.test(&view, 0, i), Test::Emit))
                .map(|i| self.leaves[i])
                .collect();
            return Traversal {
                splats,
                nodes_visited: self.leaves.len() as u64,
                inner_emitted: 0,
                ms: ms_since(started),
            };
        }
        // Breadth first from the root until there is work for every
        // thread: a list in Morton order of emitted pieces and subtrees
        // still to walk (a fixed target, so the same list whatever
        // `threads`).
        enum Item {
            Piece(Piece),
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
                        match self.test(&view, level, i) {
                            Test::Cull => {}
                            Test::Emit => {
                                next.push(Item::Piece(Piece::Inner(self.node(level, i).0)))
                            }
                            Test::Recurse => {
                                next.extend(
                                    self.children(level, i).map(|c| Item::Subtree(level - 1, c)),
                                );
                            }
                            Test::Leaves => {
                                next.push(Item::Piece(Piece::Leaves(self.leaves_below(level, i))))
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
                Item::Piece(_) => None,
            })
            .collect();
        // Each subtree depth first, split over the threads in contiguous
        // runs; outputs joined in order.
        let per = subtrees.len().div_ceil(threads.max(1)).max(1);
        let results: Vec<Vec<(Vec<Piece>, u64)>> = std::thread::scope(|scope| {
            let handles: Vec<_> = subtrees
                .chunks(per)
                .map(|run| {
                    let view = &view;
                    scope.spawn(move || {
                        run.iter()
                            .map(|&(l, i)| {
                                let (mut out, mut visited) = (Vec::new(), 0u64);
                                self.walk(view, l, i, &mut out, &mut visited);
                                (out, visited)
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
        // The pieces in order, each subtree's walk in its place.
        let mut walked = results.into_iter().flatten();
        let mut pieces: Vec<Piece> = Vec::new();
        for item in items {
            match item {
                Item::Piece(p) => push_piece(&mut pieces, p),
                Item::Subtree(..) => {
                    let (out, v) = walked.next().expect("one result per subtree");
                    out.into_iter().for_each(|p| push_piece(&mut pieces, p));
                    visited += v;
                }
            }
        }
        let (splats, inner_emitted) = self.splats_of(&pieces, threads);
        Traversal {
            splats,
            nodes_visited: visited,
            inner_emitted,
            ms: ms_since(started),
        }
    }

    /// The splats of `pieces`, in order, copied on up to `threads`
    /// threads (a frame's splats are megabytes of fresh pages), and how
    /// many are inner nodes.
    fn splats_of(&self, pieces: &[Piece], threads: usize) -> (Vec<Splat>, u64) {
        let mut inner_emitted = 0u64;
        let bytes: Vec<&[u8]> = pieces
            .iter()
            .map(|p| match p {
                Piece::Inner(s) => {
                    inner_emitted += 1;
                    bytemuck::bytes_of(s)
                }
                Piece::Leaves(run) => bytemuck::cast_slice(&self.leaves[run.clone()]),
            })
            .collect();
        let mut splats = vec![
            Splat::zeroed();
            bytes.iter().map(|b| b.len()).sum::<usize>() / size_of::<Splat>()
        ];
        crate::copy_in_parallel(&bytes, bytemuck::cast_slice_mut(&mut splats), threads);
        (splats, inner_emitted)
    }

    /// Depth-first walk of the subtree at (level, i): what it emits
    /// appended to `out`.
    fn walk(&self, view: &View, level: usize, i: usize, out: &mut Vec<Piece>, visited: &mut u64) {
        *visited += 1;
        match self.test(view, level, i) {
            Test::Cull => {}
            Test::Emit if level > 0 => out.push(Piece::Inner(self.node(level, i).0)),
            Test::Emit => push_piece(out, Piece::Leaves(i..i + 1)),
            Test::Recurse => {
                for c in self.children(level, i) {
                    self.walk(view, level - 1, c, out, visited);
                }
            }
            Test::Leaves => push_piece(out, Piece::Leaves(self.leaves_below(level, i))),
        }
    }

    /// The traversal's decision for node `i` of `level` (0: a leaf).
    fn test(&self, view: &View, level: usize, i: usize) -> Test {
        let (s, cone_rad) = self.node(level, i);
        let leaf = level == 0;
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
        if self.culls_back_faces(view) && back_facing(view, centre, r, s.color[3], cone_rad) {
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
            if view.whole_subtrees && self.holds_its_leaves(view, level, i, &s, e, cone_rad) {
                return Test::Leaves;
            }
        }
        Test::Recurse
    }

    /// Whether the traversal drops the nodes that face away from the lens:
    /// asked for (`--cull-back-faces`), and the points have normals.
    fn culls_back_faces(&self, view: &View) -> bool {
        self.has_normals && view.lod.cull_back_faces
    }

    /// Whether recursing into inner node `i` of `level` (splat `s`, wholly
    /// in front of the lens, at eye-space centre `e`, normal cone
    /// `cone_rad`) would emit every leaf beneath it and nothing else, so
    /// that the leaves can be taken as one run. Sufficient conditions,
    /// each with room for the rounding of the tests it stands for:
    /// - the sphere lies inside the image's frustum unwidened (every test
    ///   beneath widens it by at least 1 px, and every sphere beneath lies
    ///   in this one);
    /// - culling back faces, every normal of the cone faces the eye from
    ///   every point of the sphere (so no cone beneath faces away from the
    ///   whole lens);
    /// - no inner node beneath is small enough to be emitted: the smallest
    ///   one's size at the sphere's far depth exceeds the LOD threshold
    ///   and, for `lod.blur`, the largest CoC over the sphere's depths
    ///   times the factor (a node's smallest CoC beneath is at most that).
    fn holds_its_leaves(
        &self,
        view: &View,
        level: usize,
        i: usize,
        s: &Splat,
        e: Vec3,
        cone_rad: f32,
    ) -> bool {
        let (centre, r) = s.sphere();
        let (z0, z1) = (e.z - r, e.z + r);
        if !inside_frustum(view, e, r) {
            return false;
        }
        if self.culls_back_faces(view) {
            let to_eye = view.camera.eye - centre;
            let d = to_eye.length();
            if d <= r {
                return false;
            }
            let between = angle(oct_decode(s.color[3]), to_eye / d);
            let worst = cone_rad + between + (r / d).asin() + WHOLE_SLACK_RAD;
            if worst >= std::f32::consts::FRAC_PI_2 {
                return false;
            }
        }
        let smallest_px = view.f_px * self.inner_diameter_below(level, i) / z1;
        let emits_below = |threshold_px: f32| smallest_px <= threshold_px * (1.0 + SIZE_SLACK);
        if emits_below(view.lod.px) {
            return false;
        }
        !view
            .lod
            .blur
            .is_some_and(|f| emits_below(f * max_coc_px(&view.camera, z0, z1)))
    }
}

/// What the traversal decides for a world-space sphere (centre, radius r)
/// whose points are `spacing` apart: the decision the traversal makes of an inner node, for callers that
/// choose among their own groups of points (COPC's octree nodes,
/// `crate::input::copc_frame`): None when the sphere cannot reach the
/// frame (frustum widened as the traversal widens it), else whether a
/// group this coarse is fine enough (`true`: stop; `false`: its finer
/// points are wanted).
pub fn sphere_decision(
    camera: &Camera,
    lod: Lod,
    widening: Widening,
    centre: Vec3,
    r: f32,
    spacing: f32,
) -> Option<bool> {
    let view = View::new(camera, lod, widening);
    let e = view.eye_from_world.apply(centre);
    if e.z + r <= 0.0 {
        return None;
    }
    let in_front = e.z - r > 0.0;
    if in_front && outside_frustum(&view, e, r, max_coc_px(camera, e.z - r, e.z + r)) {
        return None;
    }
    if !in_front || lod.draws_all() {
        return Some(false);
    }
    // Its spacing as drawn at its nearest depth.
    let size_px = view.f_px * spacing / (e.z - r);
    let blurred = lod
        .blur
        .is_some_and(|f| size_px <= f * min_coc_px(camera, e.z - r, e.z + r));
    Some(size_px <= lod.px || blurred)
}

/// Breadth-first expansion stops at this many subtrees.
const FRONTIER: usize = 4096;

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
    frustum_sides(view, margin)
        .iter()
        .any(|a| a.dot(e) < -r * a.length())
}

/// The image's frustum widened by `margin` pixels on every side, as the
/// planes through the eye of its four sides, a·e ≥ 0 inside (pixel x =
/// c.x + f·x/z, pixel y = c.y − f·y/z).
fn frustum_sides(view: &View, margin: f32) -> [Vec3; 4] {
    let f = view.f_px;
    let (w, h) = (view.camera.width as f32, view.camera.height as f32);
    let (x0, x1) = (-margin, w + margin);
    let (y0, y1) = (-margin, h + margin);
    let c = view.centre;
    [
        Vec3::new(f, 0.0, c.x - x0),
        Vec3::new(-f, 0.0, x1 - c.x),
        Vec3::new(0.0, -f, c.y - y0),
        Vec3::new(0.0, f, y1 - c.y),
    ]
}

/// Whether the sphere (eye-space centre `e`, radius `r`, wholly in front
/// of the lens) lies wholly inside the image's frustum, unwidened.
fn inside_frustum(view: &View, e: Vec3, r: f32) -> bool {
    frustum_sides(view, 0.0)
        .iter()
        .all(|a| a.dot(e) >= r * a.length())
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

/// Room a whole subtree leaves for the rounding of the cones it stands
/// for: each level's cone adds an angle rounded by up to about
/// [`ANGLE_SLACK_RAD`] / 3 (f32 acos near 0), over tens of levels.
const WHOLE_SLACK_RAD: f32 = 0.02;

/// Relative room a whole subtree leaves for the rounding of the sizes and
/// depths beneath it (each node's own transform and division).
const SIZE_SLACK: f32 = 1e-3;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Aperture;
    use crate::tree::{LeafSize, Points};

    impl SplatTree {
        /// [`SplatTree::traverse`] testing every node, no run of leaves
        /// taken whole: what the traversal must equal.
        fn traverse_each_node(
            &self,
            camera: &Camera,
            lod: Lod,
            widening: Widening,
            threads: usize,
        ) -> Traversal {
            let view = View {
                whole_subtrees: false,
                ..View::new(camera, lod, widening)
            };
            self.traverse_with(view, threads)
        }
    }

    /// A sphere of radius 1 about the origin, its normals outwards (so
    /// the normal cones are narrow where the points are close), and a
    /// denser patch on it (nodes of mixed sizes).
    fn sphere(n: usize, normals: bool) -> (Vec<Vec3>, Vec<Vec3>, Option<Vec<Vec3>>) {
        let mut next = crate::tree::tests::lcg(7);
        let positions: Vec<Vec3> = (0..n)
            .map(|k| {
                let (u, v) = (2.0 * next() - 1.0, std::f32::consts::TAU * next());
                let (u, v) = if k % 4 == 0 {
                    (0.9 + 0.1 * u.abs(), 0.3 * v)
                } else {
                    (u, v)
                };
                let s = (1.0 - u * u).max(0.0).sqrt();
                Vec3::new(s * v.cos(), s * v.sin(), u)
            })
            .collect();
        let colors = (0..n).map(|_| Vec3::new(next(), next(), next())).collect();
        let normals = normals.then(|| positions.clone());
        (positions, colors, normals)
    }

    fn camera(eye: Vec3, width: u32, aperture_radius: f32) -> Camera {
        Camera {
            width,
            height: width * 3 / 4,
            eye,
            target: Vec3::ZERO,
            up: Vec3::Y,
            fovy_deg: 40.0,
            aperture_radius,
            focus_distance: eye.length() - 1.0,
            aperture: Aperture::ROUND,
        }
    }

    /// Taking a subtree's leaves whole gives the splats, in order, that
    /// testing each of its nodes gives: every tree (without normals, and
    /// with them, culling back faces or not), camera (the sphere whole in
    /// view, filling it, cut by the frame's edges, through a pinhole and a
    /// wide lens), LOD rule and widening, whatever the threads; and it does
    /// take runs whole (fewer nodes tested) where the sphere is wholly in
    /// view.
    #[test]
    fn runs_of_leaves_taken_whole_are_what_each_node_gives() {
        for normals in [false, true] {
            let (positions, colors, normals) = sphere(40_000, normals);
            let points = Points {
                positions: &positions,
                colors: &colors,
                normals: normals.as_deref(),
            };
            let tree = SplatTree::build(points, LeafSize::SpacingTimes(1.5), 2);
            // With normals, the walk that culls back faces too.
            let cull = tree.has_normals();
            let cameras = [
                camera(Vec3::new(0.3, 0.2, 6.0), 640, 0.0),
                camera(Vec3::new(0.3, 0.2, 6.0), 1920, 0.2),
                camera(Vec3::new(-1.0, 0.5, 2.2), 640, 0.05),
                camera(Vec3::new(0.0, 0.0, 1.3), 320, 0.3),
            ];
            let lods = [
                Lod {
                    px: 1.0,
                    blur: None,
                    cull_back_faces: cull,
                },
                Lod {
                    px: 0.3,
                    blur: None,
                    cull_back_faces: cull,
                },
                Lod {
                    px: 4.0,
                    blur: None,
                    cull_back_faces: cull,
                },
                Lod {
                    px: 1.0,
                    blur: Some(1.0),
                    cull_back_faces: cull,
                },
            ];
            // With normals, each rule also without the cull (the default).
            let lods: Vec<Lod> = lods
                .into_iter()
                .flat_map(|l| match l.cull_back_faces {
                    true => vec![
                        Lod {
                            cull_back_faces: false,
                            ..l
                        },
                        l,
                    ],
                    false => vec![l],
                })
                .collect();
            let widenings = [
                Widening::default(),
                Widening {
                    background_coc_px: 40.0,
                    splat_px: 3.0,
                },
            ];
            for (c, cam) in cameras.iter().enumerate() {
                for &lod in &lods {
                    for widening in widenings {
                        let each = tree.traverse_each_node(cam, lod, widening, 2);
                        for threads in [1, 3] {
                            let whole = tree.traverse(cam, lod, widening, threads);
                            let what = format!(
                                "normals {}, camera {c}, {lod:?}, {widening:?}",
                                tree.has_normals()
                            );
                            assert!(
                                whole.splats == each.splats,
                                "{what}: {} and {} splats",
                                whole.splats.len(),
                                each.splats.len()
                            );
                            assert_eq!(whole.inner_emitted, each.inner_emitted, "{what}");
                            if c < 2 && lod.px >= 1.0 {
                                assert!(
                                    whole.nodes_visited * 2 < each.nodes_visited,
                                    "{what}: {} of {} nodes tested",
                                    whole.nodes_visited,
                                    each.nodes_visited
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// A node's leaves are one run, the runs of a level's nodes follow one
    /// another over every leaf, and the inner diameter below a node is
    /// the smallest of the inner nodes beneath it.
    #[test]
    fn a_node_holds_one_run_of_leaves_and_its_smallest_inner_node() {
        let (positions, colors, _) = sphere(20_000, false);
        let points = Points {
            positions: &positions,
            colors: &colors,
            normals: None,
        };
        let tree = SplatTree::build(points, LeafSize::SpacingTimes(1.5), 2);
        for level in 1..=tree.levels().len() {
            let mut end = 0;
            for i in 0..tree.level_len(level) {
                let run = tree.leaves_below(level, i);
                assert_eq!(run.start, end, "level {level} node {i}");
                end = run.end;
                // The children's runs make up the node's.
                let children = tree.children(level, i);
                let first = tree.leaves_below(level - 1, children.start).start;
                let last = tree.leaves_below(level - 1, children.end - 1).end;
                assert_eq!(first..last, run);
                // Every inner node beneath, walked.
                let mut smallest = f32::INFINITY;
                let mut below: Vec<(usize, usize)> = children.map(|c| (level - 1, c)).collect();
                while let Some((l, c)) = below.pop() {
                    if l > 0 {
                        smallest = smallest.min(tree.node(l, c).0.position_size[3]);
                        below.extend(tree.children(l, c).map(|g| (l - 1, g)));
                    }
                }
                assert_eq!(tree.inner_diameter_below(level, i), smallest);
            }
            assert_eq!(end, tree.len(), "level {level} covers every leaf");
        }
    }
}
