//! The per-frame traversal (DESIGN §3, Zhao §2): from the root, cull what
//! cannot reach the image and stop where a node is small enough for the
//! level of detail.

use std::time::Instant;

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
}

impl View {
    fn new(camera: &Camera, lod: Lod, widening: Widening) -> View {
        View {
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
}
impl SplatTree {
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
        let view = View::new(camera, lod, widening);
        // Breadth first from the root until there is work for every
        // thread: a list in Morton order of emitted splats and subtrees
        // still to walk (a fixed target, so the same list whatever
        // `threads`).
        enum Item {
            Splat(Splat, bool),
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
        let results: Vec<Vec<(Vec<Splat>, u64, u64)>> = std::thread::scope(|scope| {
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
        out: &mut Vec<Splat>,
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
    fn test(&self, view: &View, s: &Splat, cone_rad: f32, leaf: bool) -> Test {
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
