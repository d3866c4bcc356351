//! The splat hierarchy (DESIGN §3, Zhao §2): culling, level of detail,
//! determinism, and the images it gives on lavapipe against drawing every
//! point and against the exact k-nearest-neighbour splat sizes.

mod common;

use common::{camera, with_gpu};
use glam::Vec3;
use pointlens::bench::{synthetic_cloud, BenchModel};
use pointlens::camera::Camera;
use pointlens::image_io::LinearImage;
use pointlens::metrics;
use pointlens::options::Lod;
use pointlens::options::{FastWeights, GatherWindow, Method};
use pointlens::render::{splat_diameters, RenderOptions, Renderer, SplatSize};
use pointlens::tree::{max_coc_px, LeafSize, Points, SplatTree, Widening};
use pointlens::PointCloud;

const THREADS: usize = 2;

/// A cloud's points as the hierarchy takes them.
fn points(cloud: &PointCloud) -> Points<'_> {
    Points {
        positions: &cloud.positions,
        colors: &cloud.colors,
        normals: cloud.normals.as_deref(),
    }
}

fn lcg(seed: u64) -> impl FnMut() -> f32 {
    let mut state = seed;
    move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Points filling a cube of side 8 around the origin, the camera inside.
fn cube_cloud(n: usize) -> PointCloud {
    let mut next = lcg(11);
    let positions: Vec<Vec3> = (0..n)
        .map(|_| 8.0 * Vec3::new(next(), next(), next()) - 4.0)
        .collect();
    PointCloud {
        colors: vec![Vec3::splat(0.5); n],
        positions,
        normals: None,
        has_colors: true,
        attributes: vec![],
        ..Default::default()
    }
}

fn inside_camera() -> Camera {
    let mut cam = camera(64, 48);
    cam.eye = Vec3::new(0.1, 0.2, 0.3);
    cam.target = Vec3::new(1.0, 0.5, 2.0);
    cam.up = Vec3::Y;
    cam.fovy_deg = 40.0;
    cam.focus_distance = 2.0;
    cam.aperture_radius = 0.15;
    cam
}

#[test]
fn culling_keeps_exactly_what_can_reach_the_image() {
    let cloud = cube_cloud(60_000);
    let tree = SplatTree::build(points(&cloud), LeafSize::World(0.001), THREADS);
    let cam = inside_camera();
    // A threshold no inner node meets: the emitted splats are the leaves
    // that survive culling.
    let lod = Lod {
        px: 1e-4,
        blur: None,
        cull_back_faces: false,
    };
    let emitted = tree.traverse(&cam, lod, Widening::default(), THREADS);
    assert_eq!(emitted.inner_emitted, 0);
    let eye_from_world = cam.eye_from_world_transform();
    let f = cam.f_px();
    let (w, h) = (cam.width as f32, cam.height as f32);
    let mut kept: Vec<[u32; 3]> = Vec::new();
    for v in &emitted.splats {
        let e = eye_from_world.apply(v.centre());
        assert!(e.z > 0.0, "a point behind the lens was emitted: z {}", e.z);
        let (x, y) = (w / 2.0 + f * e.x / e.z, h / 2.0 - f * e.y / e.z);
        // The widening: half the point's CoC and 1 px, plus the sphere of
        // radius r as a plane through the eye tilted to that edge sees it
        // (r·|a|/z px for the plane's normal a = (f, 0, w/2 + margin)).
        let margin = 0.5 * cam.coc_px(e.z) + 1.0;
        let a = (f * f + (0.5 * w.max(h) + margin).powi(2)).sqrt();
        let reach = margin + 0.5 * v.position_size[3] * a / e.z + 1e-3 * margin;
        let out = (-x).max(x - w).max(-y).max(y - h);
        assert!(
            out <= reach,
            "emitted {out} px outside the image, reach {reach}"
        );
        kept.push([0, 1, 2].map(|i| v.position_size[i].to_bits()));
    }
    kept.sort_unstable();
    // Every point whose centre projects into the image, or whose blur
    // (CoC / 2 around it) reaches it, is kept.
    let mut inside = 0;
    let mut blurred_in = 0;
    for p in &cloud.positions {
        if let Some((px, z)) = cam.project(*p) {
            let out = (-px.x).max(px.x - w).max(-px.y).max(px.y - h);
            if out <= 0.5 * cam.coc_px(z) {
                inside += 1;
                blurred_in += (out > 1.0) as u32;
                let key = [p.x, p.y, p.z].map(f32::to_bits);
                assert!(
                    kept.binary_search(&key).is_ok(),
                    "{p} ({out} px out) was culled"
                );
            }
        }
    }
    assert!(
        blurred_in > 100,
        "{blurred_in} points outside the image blur into it"
    );
    assert!(inside > 1000 && emitted.splats.len() < cloud.len() / 2);
    // Behind the camera: a cloud entirely behind emits nothing.
    let away = (cam.eye - cam.target).normalize();
    let mut behind = cam;
    behind.eye = cam.eye + 20.0 * away;
    behind.target = behind.eye + away;
    let none = tree.traverse(&behind, Lod::default(), Widening::default(), THREADS);
    assert!(none.splats.is_empty(), "{} emitted", none.splats.len());
}

/// A plane of points at z = 2 facing `normal`, seen from the origin.
fn plane(normal: Option<Vec3>) -> PointCloud {
    let mut positions = Vec::new();
    for j in 0..80 {
        for i in 0..80 {
            positions.push(Vec3::new(i as f32 / 40.0 - 1.0, j as f32 / 40.0 - 1.0, 2.0));
        }
    }
    let n = positions.len();
    PointCloud {
        colors: vec![Vec3::splat(0.5); n],
        normals: normal.map(|d| vec![d.normalize(); n]),
        positions,
        has_colors: true,
        attributes: vec![],
        ..Default::default()
    }
}

fn plane_camera(aperture_radius: f32) -> Camera {
    let mut cam = camera(64, 64);
    cam.eye = Vec3::ZERO;
    cam.target = Vec3::Z;
    cam.up = Vec3::Y;
    cam.fovy_deg = 70.0;
    cam.focus_distance = 2.0;
    cam.aperture_radius = aperture_radius;
    cam
}

/// With `--cull-back-faces`, the nodes whose normals face away from the
/// whole lens are dropped; without it (the default), or without normals,
/// none is.
#[test]
fn back_facing_cones_are_culled_when_asked_and_clouds_without_normals_are_not() {
    let traverse = |normal: Option<Vec3>, aperture: f32, cull_back_faces: bool| {
        let tree = SplatTree::build(points(&plane(normal)), LeafSize::World(0.02), THREADS);
        let lod = Lod {
            px: 1e-4,
            blur: None,
            cull_back_faces,
        };
        tree.traverse(&plane_camera(aperture), lod, Widening::default(), THREADS)
            .splats
    };
    let count = |normal: Option<Vec3>, aperture: f32| traverse(normal, aperture, true).len();
    let all = count(None, 0.0);
    assert!(all > 6000, "{all}");
    // The same splats as without normals (the normal rides in the
    // colour's fourth channel, so the positions and sizes are compared).
    let places = |splats: Vec<pointlens::tree::Splat>| -> Vec<[f32; 4]> {
        splats.iter().map(|s| s.position_size).collect()
    };
    let without = places(traverse(None, 0.0, false));
    assert_eq!(without.len(), all);
    for normal in [Vec3::Z, -Vec3::Z, Vec3::new(0.0, 1.0, 0.1)] {
        assert_eq!(
            places(traverse(Some(normal), 0.0, false)),
            without,
            "not culling, facing {normal}"
        );
    }
    assert_eq!(count(Some(-Vec3::Z), 0.0), all, "facing the camera");
    assert_eq!(count(Some(Vec3::Z), 0.0), 0, "facing away");
    assert_eq!(
        count(Some(Vec3::Z), 0.5),
        0,
        "facing away from every lens point"
    );
    // Nearly edge-on: n = (0, 1, 0.1) at p = (x, y, 2) faces a lens point
    // (a, b, 0) iff b − y − 0.2 > 0. The centre of the lens sees the back
    // of the points above y = −0.2; a lens of radius 1.5 sees every
    // point's front from its rim (y ≤ 1 < 1.3), so none may be culled.
    // A single point (a tree without inner nodes) is tested alike.
    let one = |cull_back_faces: bool| {
        let cloud = PointCloud {
            positions: vec![Vec3::new(0.0, 0.0, 2.0)],
            colors: vec![Vec3::splat(0.5)],
            normals: Some(vec![Vec3::Z]),
            has_colors: true,
            attributes: vec![],
            ..Default::default()
        };
        let tree = SplatTree::build(points(&cloud), LeafSize::World(0.02), THREADS);
        let lod = Lod {
            px: 1e-4,
            blur: None,
            cull_back_faces,
        };
        tree.traverse(&plane_camera(0.0), lod, Widening::default(), THREADS)
            .splats
            .len()
    };
    assert_eq!(
        (one(false), one(true)),
        (1, 0),
        "a single point facing away"
    );
    let tilted = Vec3::new(0.0, 1.0, 0.1);
    let from_centre = count(Some(tilted), 0.0);
    assert!(from_centre < all * 2 / 3, "{from_centre} of {all}");
    assert_eq!(count(Some(tilted), 1.5), all, "seen from the lens's rim");
}

#[test]
fn coarser_lod_emits_fewer_splats_and_no_node_above_the_threshold() {
    let cloud = synthetic_cloud(300_000);
    let tree = SplatTree::build(points(&cloud), SplatSize::Spacing.leaf_size(), THREADS);
    let cam = BenchModel::Synthetic.camera(&cloud, 320, 240).unwrap();
    let f = cam.f_px();
    let eye_from_world = cam.eye_from_world_transform();
    let mut last = usize::MAX;
    for px in [1.0, 2.0, 4.0, 8.0] {
        let t = tree.traverse(
            &cam,
            Lod {
                px,
                blur: None,
                cull_back_faces: false,
            },
            Widening::default(),
            THREADS,
        );
        assert!(t.splats.len() < last, "lod {px}: {} splats", t.splats.len());
        assert!(t.inner_emitted > 0, "lod {px}: no inner node");
        last = t.splats.len();
        let leaves: std::collections::HashSet<[u32; 4]> = tree
            .leaves()
            .iter()
            .map(|v| v.position_size.map(f32::to_bits))
            .collect();
        for v in &t.splats {
            if leaves.contains(&v.position_size.map(f32::to_bits)) {
                continue;
            }
            let z = eye_from_world.apply(v.centre()).z;
            let size = f * v.position_size[3] / z;
            assert!(size <= px, "an inner node of {size} px at lod {px}");
        }
    }
    // Blur-aware detail stops sooner.
    let blur = |f: Option<f32>| {
        tree.traverse(
            &cam,
            Lod {
                px: 1.0,
                blur: f,
                cull_back_faces: false,
            },
            Widening::default(),
            THREADS,
        )
        .splats
        .len()
    };
    assert!(blur(Some(1.0)) < blur(None));
    // The same splats whatever the thread count.
    let one = tree
        .traverse(&cam, Lod::default(), Widening::default(), 1)
        .splats;
    for threads in [2, 3, 7] {
        assert!(
            one == tree
                .traverse(&cam, Lod::default(), Widening::default(), threads)
                .splats
        );
    }
}

#[test]
fn largest_coc_of_a_depth_range_is_at_an_end() {
    let cam = plane_camera(0.1);
    for (z0, z1) in [(0.5, 1.0), (1.0, 3.0), (3.0, 9.0)] {
        let m = max_coc_px(&cam, z0, z1);
        for i in 0..=100 {
            let z = z0 + (z1 - z0) * i as f32 / 100.0;
            assert!(cam.coc_px(z) <= m * (1.0 + 1e-6));
        }
    }
}

fn psnr(a: &LinearImage, b: &LinearImage) -> f64 {
    metrics::psnr(a, b).expect("same size")
}

/// The common test options (SSAA 2) with `lod`.
fn options(camera: Camera, method: Method, lod: Lod) -> RenderOptions {
    RenderOptions {
        lod,
        ..common::options(camera, method)
    }
}

fn bundled(model: &BenchModel) -> PointCloud {
    model.load(&common::root().join("data"), 0).unwrap()
}

/// The pinhole image at `--lod-px 1` against every point drawn (`--lod-px
/// 0`) on the bundled clouds at 640×480. Neither is dense enough for a
/// node of 8 points to project under a pixel, and by default nothing is
/// culled but what the frame cannot show, so the two are the same bytes. With
/// `--cull-back-faces` the bunny (it has normals) drops its back faces:
/// fewer splats, and an image that differs where they showed (its
/// silhouettes and its scan's holes; 38.5 dB, bounded at 35).
#[test]
fn lod_one_pixel_against_every_point() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        for model in [BenchModel::Bunny, BenchModel::Mug] {
            let cloud = bundled(&model);
            let cam = model.camera(&cloud, 640, 480).unwrap();
            let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
            let render = |lod| {
                renderer
                    .render(&scene, &options(cam, Method::Pinhole, lod))
                    .unwrap()
            };
            let all = render(Lod::ALL);
            let lod = render(Lod::default());
            assert_eq!(all.lod.splats_emitted, cloud.len() as u64);
            // The mug's scan reaches past the frame: the frustum drops some.
            assert_eq!(lod.lod.inner_emitted, 0, "{model:?}");
            assert!(lod.image == all.image, "{model:?}");
            if cloud.normals.is_some() {
                let culled = render(Lod {
                    cull_back_faces: true,
                    ..Lod::default()
                });
                let db = psnr(&culled.image, &all.image);
                eprintln!(
                    "{model:?}: back faces culled, {} of {} splats, {db:.2} dB",
                    culled.lod.splats_emitted,
                    cloud.len()
                );
                assert!(culled.lod.splats_emitted < cloud.len() as u64 * 3 / 4);
                assert!((35.0..60.0).contains(&db), "{model:?}: {db:.2} dB");
            }
        }
    });
}

/// Where the LOD does replace most points (300,000 synthetic points at
/// 96×72, about 40 per pixel), its image against a finely sampled image of
/// every point (SSAA 8) is nearly as close as every point drawn at the
/// same SSAA 2: a node of at most one pixel with its points' mean color is
/// a filter of them, and what differs is at the checker's edges, where 4
/// samples per pixel of single points are noisy too (measured 25.79
/// against 26.69 dB on a 2×2 grid of cell centres; 26.62 against 28.25 dB
/// on the compute rasteriser's rotated grid, whose 4 samples see edges
/// better: within 2 dB).
#[test]
fn lod_where_it_replaces_most_points_is_as_close_as_the_sampling() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let cloud = synthetic_cloud(300_000);
        let cam = BenchModel::Synthetic.camera(&cloud, 96, 72).unwrap();
        let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        let render = |lod, ssaa| {
            let o = RenderOptions {
                ssaa,
                ..options(cam, Method::Pinhole, lod)
            };
            renderer.render(&scene, &o).unwrap()
        };
        let fine = render(Lod::ALL, 8).image;
        let all = psnr(&render(Lod::ALL, 2).image, &fine);
        let lod = render(Lod::default(), 2);
        let db = psnr(&lod.image, &fine);
        eprintln!(
            "{} of {} splats ({} inner): {db:.2} dB, every point {all:.2} dB",
            lod.lod.splats_emitted,
            cloud.len(),
            lod.lod.inner_emitted
        );
        assert!(lod.lod.splats_emitted < cloud.len() as u64 / 2);
        assert!(db >= all - 2.0, "{db:.2} dB against {all:.2} dB");
    });
}

/// Splat sizes from the tree (local spacing over neighbours in Morton
/// order) against the exact k-nearest-neighbour sizes: the `fast` image of
/// each, against `accum` of the exact sizes, within 1 dB.
#[test]
fn tree_splat_sizes_match_knn_sizes_against_accum() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        for model in [BenchModel::Bunny, BenchModel::Mug] {
            let cloud = bundled(&model);
            let cam = model.camera(&cloud, 320, 240).unwrap();
            let knn = renderer
                .upload_sized(&cloud, &splat_diameters(&cloud, SplatSize::Spacing))
                .unwrap();
            let tree = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
            let render = |scene, method| {
                renderer
                    .render(scene, &options(cam, method, Lod::default()))
                    .unwrap()
                    .image
            };
            let reference = render(&knn, Method::accum(64));
            for method in [
                Method::paper_fast(FastWeights::Area, GatherWindow::Tiles),
                Method::Pinhole,
            ] {
                let a = psnr(&render(&knn, method), &reference);
                let b = psnr(&render(&tree, method), &reference);
                eprintln!("{model:?} {method:?}: k-NN {a:.2} dB, tree {b:.2} dB");
                assert!(b >= a - 1.0, "{model:?} {method:?}: {b:.2} vs {a:.2} dB");
            }
        }
    });
}

/// `info`'s median spacing (the tree's) against the exact k-NN median on
/// the bundled clouds: within 5 % (measured −0.4 % and +0.8 %).
#[test]
fn tree_median_spacing_is_near_the_exact_one() {
    for model in [BenchModel::Bunny, BenchModel::Mug] {
        let cloud = bundled(&model);
        let exact =
            pointlens::tree::median(pointlens::tree::exact_spacing(&cloud.positions, THREADS));
        let tree = pointlens::tree::median_spacing(&cloud.positions, THREADS);
        eprintln!("{model:?}: exact {exact}, tree {tree}");
        assert!(
            (tree / exact - 1.0).abs() < 0.05,
            "{model:?}: {tree} vs {exact}"
        );
    }
}

/// `limit_isolated`: a stray among a surface's points is bounded by twice
/// the blocks' median; a region whose hundreds of points are all sparse
/// keeps its spacing.
#[test]
fn isolated_spacings_are_limited_by_the_blocks_around() {
    use pointlens::tree::{limit_isolated, ISOLATED_BLOCK, ISOLATED_LIMIT};
    let mut spacing = vec![1.0f32; 4 * ISOLATED_BLOCK];
    spacing[300] = 40.0; // a stray in the second block
    for s in &mut spacing[2 * ISOLATED_BLOCK..] {
        *s = 10.0; // two sparse blocks
    }
    spacing[3 * ISOLATED_BLOCK + 7] = 15.0; // within 2 × the sparse median
    let before = spacing.clone();
    assert_eq!(limit_isolated(&mut spacing, 2), 1);
    assert_eq!(spacing[300], ISOLATED_LIMIT * 1.0);
    for (i, (a, b)) in before.iter().zip(&spacing).enumerate() {
        if i != 300 {
            assert_eq!(a, b, "spacing {i}");
        }
    }
}
