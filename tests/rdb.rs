//! The ray distribution buffer (`--method rdb`, DESIGN §5) on lavapipe.

mod common;

use common::{camera, cloud, root, with_gpu};
use glam::Vec3;
use pointlens::camera::rdb_lens_table;
use pointlens::camera::Camera;
use pointlens::host_gbuffer::HostGBuffer;
use pointlens::image_io::LinearImage;
use pointlens::input::ply::load_ply;
use pointlens::metrics::psnr;
use pointlens::options::Method;
use pointlens::options::{FastWeights, GatherWindow};
use pointlens::options::{RdbAtomics, RdbMode, RdbOptions};
use pointlens::passes::rdb::{bytes_per_pixel, TilePlan};
use pointlens::reference;
use pointlens::render::{RenderOptions, Renderer, Scene, SplatSize};

fn options(cam: Camera, method: Method) -> RenderOptions {
    RenderOptions {
        camera: cam,
        method,
        ssaa: 2,
        samples_per_pass: None,
        background: Vec3::ZERO,
        lod: pointlens::options::Lod::default(),
    }
}

fn render(renderer: &Renderer, scene: &Scene, cam: Camera, method: Method) -> LinearImage {
    renderer.render(scene, &options(cam, method)).unwrap().image
}

#[test]
fn gpu_rdb_equals_the_cpu_reference_on_a_crop_of_a_real_scan_and_is_deterministic() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let scan = load_ply(&root().join("data/pcl_table_scene_mug_rgb.ply")).unwrap();
        let scene = renderer.upload(&scan, SplatSize::Spacing).unwrap();
        // The scanner's view of the mug, a 40×32 crop, blurred around it.
        let cam = Camera {
            width: 40,
            height: 32,
            eye: Vec3::ZERO,
            target: Vec3::new(0.08, 0.08, 1.0),
            up: Vec3::new(0.0, -1.0, 0.0),
            fovy_deg: 5.0,
            aperture_radius: 0.02,
            focus_distance: 1.1,
            aperture: pointlens::camera::Aperture::ROUND,
        };
        for (bins, mode) in [
            (5, RdbMode::Centre),
            (9, RdbMode::Centre),
            (5, RdbMode::Pairs),
            (9, RdbMode::Pairs),
        ] {
            let method = Method::rdb(bins, mode);
            let (gpu, gbuffer) = renderer
                .render_with_gbuffer(&scene, &options(cam, method))
                .unwrap();
            let again = renderer.render(&scene, &options(cam, method)).unwrap();
            assert_eq!(
                gpu.image, again.image,
                "{bins}×{bins} {mode:?}: two runs differ"
            );
            let cpu = reference::rdb(&gbuffer, &cam, bins, mode);
            // The result is stored as rgba16f: every channel (alpha, the
            // sources' mean coverage, included) within 1e-3
            // relative (0.05 absolute floor) and within one fp16 step of a
            // value below 1 (2^-11) of the reference; a ray landing in
            // another pixel would move a whole bin's share (≥ 1/N² of a
            // color). Measured on lavapipe for all four configurations: no
            // pixel differs, worst channel 4.86e-4. (It allowed 1 % of the
            // pixels to differ by any amount before.)
            let differ = gpu
                .image
                .pixels
                .iter()
                .zip(&cpu.pixels)
                .filter(|(a, b)| (0..4).any(|c| (a[c] - b[c]).abs() > 1e-3 * b[c].abs().max(0.05)))
                .count();
            assert_eq!(differ, 0, "{bins}×{bins} {mode:?}: {differ} pixels differ");
            let worst = gpu
                .image
                .pixels
                .iter()
                .zip(&cpu.pixels)
                .flat_map(|(a, b)| (0..4).map(move |c| (a[c] - b[c]).abs()))
                .fold(0.0f32, f32::max);
            assert!(
                worst <= 1.0 / 2048.0,
                "{bins}×{bins} {mode:?}: worst difference {worst} from the CPU reference"
            );
            let blurred = gbuffer
                .eye
                .iter()
                .filter(|e| cam.coc_px(e[2]) > 3.0)
                .count();
            assert!(
                blurred > 200,
                "the crop must blur: {blurred} pixels with a CoC over 3 px"
            );
        }
    });
}

/// A textured plane (a checker of 9.6 cm cells, about 5 px at z = 1 here)
/// at z = −`depth`, tilted about the x axis by `tilt` radians, much wider
/// than the view; points every 8 mm.
fn textured_plane(depth: f32, tilt: f32) -> pointlens::PointCloud {
    let mut points = Vec::new();
    for j in -150i32..=150 {
        for i in -150i32..=150 {
            let (x, y) = (i as f32 * 0.008, j as f32 * 0.008);
            let checker = ((i.div_euclid(12) + j.div_euclid(12)) % 2 == 0) as u8 as f32;
            let color = Vec3::new(0.2 + 0.6 * checker, 0.3, 0.8 - 0.6 * checker);
            points.push((Vec3::new(x, y * tilt.cos(), -depth - y * tilt.sin()), color));
        }
    }
    cloud(&points)
}

#[test]
fn with_partial_occlusion_rdb_is_closer_to_accum_than_the_papers_fast() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        // A blurred red foreground bar over a textured background in focus.
        let mut plane = textured_plane(2.0, 0.0);
        for j in -60..=60 {
            for i in -100..=0 {
                plane
                    .positions
                    .push(Vec3::new(i as f32 * 0.002, j as f32 * 0.002, -1.0));
                plane.colors.push(Vec3::new(1.0, 0.1, 0.1));
            }
        }
        let scene = renderer.upload(&plane, SplatSize::World(0.01)).unwrap();
        let mut cam = camera(48, 36);
        cam.focus_distance = 2.0;
        // The bar at z = 1 blurs to c = 2R·f_px·|1 − 2|/2 = 0.1 · 65.9 ≈ 6.6 px.
        cam.aperture_radius = 0.1;
        let reference = renderer
            .render(&scene, &options(cam, Method::accum(256)))
            .unwrap()
            .image;
        let rdb = psnr(
            &reference,
            &render(&renderer, &scene, cam, Method::rdb(9, RdbMode::Centre)),
        )
        .unwrap();
        let fast = psnr(
            &reference,
            &render(
                &renderer,
                &scene,
                cam,
                Method::paper_fast(FastWeights::Area, GatherWindow::Tiles),
            ),
        )
        .unwrap();
        assert!(
            rdb > fast,
            "RDB {rdb:.2} dB, fast {fast:.2} dB against accum"
        );
    });
}

#[test]
fn tile_plans_cover_the_frame_once_within_the_budget() {
    for (w, h, bins, budget) in [
        (64, 48, 9, 1 << 20),
        (64, 48, 16, 1 << 20),
        (37, 29, 5, 3000),
        (3840, 2160, 16, 512 << 20),
        (5, 400, 2, 32 * 7),
    ] {
        let plan = TilePlan::new(w, h, bins, budget, u64::MAX).unwrap();
        let [tw, th] = plan.tile_size;
        assert!(
            tw as u64 * th as u64 * bytes_per_pixel(bins) <= budget,
            "{w}×{h}, {bins}: tile {tw}×{th} over {budget} bytes"
        );
        let mut covered = vec![0u8; (w * h) as usize];
        for t in &plan.tiles {
            assert!(t.size[0] <= tw && t.size[1] <= th && t.size[0] > 0 && t.size[1] > 0);
            for y in t.origin[1]..t.origin[1] + t.size[1] {
                for x in t.origin[0]..t.origin[0] + t.size[0] {
                    covered[(y * w + x) as usize] += 1;
                }
            }
        }
        assert!(
            covered.iter().all(|&c| c == 1),
            "{w}×{h}: not one tile per pixel"
        );
    }
    // A frame within the budget is one tile of the frame's size.
    let whole = TilePlan::new(64, 48, 9, 64 * 48 * 648, u64::MAX).unwrap();
    assert_eq!(whole.tile_size, [64, 48]);
    assert_eq!(whole.tiles.len(), 1);
    // 3840×2160 at N = 16 is 17.0 GB of bins: 512 MiB tiles are 32 or more.
    let big = TilePlan::new(3840, 2160, 16, 512 << 20, u64::MAX).unwrap();
    assert!(big.tiles.len() >= 32, "{} tiles", big.tiles.len());
    // Each of the two images is one allocation: the device's limit binds too.
    let capped = TilePlan::new(64, 48, 9, u64::MAX, 1000 * 324).unwrap();
    let [tw, th] = capped.tile_size;
    assert!(tw * th <= 1000, "tile {tw}×{th} over the allocation limit");
    // Not even one pixel fits: an error naming the flag.
    let err = TilePlan::new(64, 48, 16, 2047, u64::MAX).unwrap_err();
    assert!(err.to_string().contains("--rdb-memory-mb"), "{err}");
}

/// The scanner's view of the mug from the PCL scan, `width`×`height`,
/// blurred around it.
fn mug_camera(width: u32, height: u32) -> Camera {
    Camera {
        width,
        height,
        eye: Vec3::ZERO,
        target: Vec3::new(0.08, 0.08, 1.0),
        up: Vec3::new(0.0, -1.0, 0.0),
        fovy_deg: 5.0 * height as f32 / 32.0,
        aperture_radius: 0.02,
        focus_distance: 1.1,
        aperture: pointlens::camera::Aperture::ROUND,
    }
}

#[test]
fn tiled_equals_untiled_bitwise() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let scan = load_ply(&root().join("data/pcl_table_scene_mug_rgb.ply")).unwrap();
        let scene = renderer.upload(&scan, SplatSize::Spacing).unwrap();
        // The cat's eye at S = 1: RDB's bins pressed into each pixel's.
        let mut cat_eye = mug_camera(61, 45);
        cat_eye.aperture.cat_eye = 1.0;
        for (bins, mode, budget, cam) in [
            (5, RdbMode::Centre, 100_000, mug_camera(61, 45)),
            // --rdb-memory-mb 1
            (16, RdbMode::Centre, 1 << 20, mug_camera(61, 45)),
            (9, RdbMode::Pairs, 1 << 20, mug_camera(61, 45)),
            // Tiles of a few pixels, far smaller than their apron.
            (4, RdbMode::Centre, 128 * 30, mug_camera(61, 45)),
            (9, RdbMode::Centre, 128 * 30, cat_eye),
        ] {
            let method = Method::rdb(bins, mode);
            let whole = renderer.render(&scene, &options(cam, method)).unwrap();
            let mut tiled_options = options(cam, method);
            tiled_options.method = Method::Rdb(RdbOptions {
                bins,
                mode,
                memory_bytes: Some(budget),
                ..RdbOptions::default()
            });
            let tiled = renderer.render(&scene, &tiled_options).unwrap();
            let tiles = |r: &pointlens::render::Rendered| {
                r.timings
                    .passes
                    .iter()
                    .find(|p| p.name == "rdb.resolve")
                    .map_or(0, |p| p.count)
            };
            assert_eq!(tiles(&whole), 1, "{bins}×{bins} {mode:?}: untiled");
            let expected = TilePlan::new(cam.width, cam.height, bins, budget, u64::MAX).unwrap();
            assert!(expected.tiles.len() > 1);
            assert_eq!(
                tiles(&tiled) as usize,
                expected.tiles.len(),
                "{bins}×{bins} {mode:?}: tiles"
            );
            let differ = whole
                .image
                .pixels
                .iter()
                .zip(&tiled.image.pixels)
                .filter(|(a, b)| a.map(f32::to_bits) != b.map(f32::to_bits))
                .count();
            assert_eq!(
                differ,
                0,
                "{bins}×{bins} {mode:?} in {} tiles: {differ} pixels differ",
                expected.tiles.len()
            );
        }
    });
}

#[test]
fn a_near_and_a_far_point_seen_through_one_lens_position_share_its_bin() {
    // An axis camera focused at 2; a G-buffer of background (z = +∞) with a
    // point in front of the focus plane (z = 1, c ≈ 33 px) and one behind it
    // (z = 4, c ≈ 16 px), each placed where the ray from lens position u_b
    // through output pixel Q meets its depth.
    let mut cam = camera(64, 64);
    cam.focus_distance = 2.0;
    cam.aperture_radius = 0.25;
    let bins = 5;
    let q = (32i64, 32i64);
    let guard = 40u32;
    let size = 64 + 2 * guard;
    for (b, u) in rdb_lens_table(bins).iter().enumerate() {
        for mode in [RdbMode::Centre, RdbMode::Pairs] {
            let mut eye = vec![[0.0, 0.0, f32::INFINITY, 1.0]; (size * size) as usize];
            let mut place = |z: f32| {
                let o = cam.lens_offset_px(z, *u);
                let p = (
                    q.0 - (o.x + 0.5).floor() as i64,
                    q.1 - (o.y + 0.5).floor() as i64,
                );
                let index = (p.1 + guard as i64) * size as i64 + p.0 + guard as i64;
                eye[index as usize][2] = z;
                index as u32
            };
            let (near, far) = (place(1.0), place(4.0));
            if near == far {
                // The lens centre: both points on Q's own pixel ray.
                continue;
            }
            let gbuffer = |eye: Vec<[f32; 4]>| HostGBuffer {
                width: size,
                height: size,
                guard,
                color: vec![[0.5; 4]; (size * size) as usize],
                eye,
            };
            // Alone, the far point is what Q sees through bin b ...
            let mut far_only = eye.clone();
            far_only[near as usize][2] = f32::INFINITY;
            let alone = reference::rdb_bins(&gbuffer(far_only), &cam, bins, mode);
            assert_eq!(
                alone.winner(q.0 as u32, q.1 as u32, b as u32),
                Some(far),
                "{mode:?} bin {b}: the far point is not in the bin"
            );
            // ... and with the near point on the same ray, the near one wins
            // that same bin.
            let both = reference::rdb_bins(&gbuffer(eye), &cam, bins, mode);
            assert_eq!(
                both.winner(q.0 as u32, q.1 as u32, b as u32),
                Some(near),
                "{mode:?} bin {b}: the near point is not in the bin"
            );
        }
    }
}

#[test]
fn without_occlusion_rdb_9x9_is_within_35_db_of_accum() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        // A checker of 9.6 cm cells on a plane through (0, 0, −2) tilted by
        // 0.8 rad about x, points every 2.4 cm (about 1 px) cut to the view
        // and its guard band: it fills the frame, 1.45 ≤ z ≤ 3.2 there.
        let mut points = Vec::new();
        let tilt: f32 = 0.8;
        for j in -84i32..=84 {
            for i in -84i32..=84 {
                let (x, y) = (i as f32 * 0.024, j as f32 * 0.024);
                let p = Vec3::new(x, y * tilt.cos(), -2.0 - y * tilt.sin());
                if p.x.abs() > 0.1 - 0.6 * p.z || p.y.abs() > 0.1 - 0.45 * p.z {
                    continue;
                }
                let checker = ((i.div_euclid(4) + j.div_euclid(4)) % 2 == 0) as u8 as f32;
                points.push((p, Vec3::new(0.2 + 0.6 * checker, 0.3, 0.8 - 0.6 * checker)));
            }
        }
        let scene = renderer
            .upload(&cloud(&points), SplatSize::World(0.036))
            .unwrap();
        let mut cam = camera(64, 48);
        cam.focus_distance = 2.0;
        cam.aperture_radius = 0.355;
        // SSAA 4 (the default; 38.5 dB): with 2×2 samples the G-buffer puts
        // the edges near focus on half pixels, where the reference, whose
        // lens samples move them a little, does not (33.4 dB).
        let options = |method| RenderOptions {
            ssaa: 4,
            samples_per_pass: None,
            ..options(cam, method)
        };
        let reference = renderer
            .render(&scene, &options(Method::accum(256)))
            .unwrap()
            .image;
        let (rdb, gbuffer) = renderer
            .render_with_gbuffer(&scene, &options(Method::rdb(9, RdbMode::Centre)))
            .unwrap();
        // The frame is covered, and its CoCs reach up to N = 9 px.
        let g = gbuffer.guard as usize;
        let mut max_coc = 0.0f32;
        for y in g..g + 48 {
            for x in g..g + 64 {
                let z = gbuffer.eye[y * gbuffer.width as usize + x][2];
                assert!(z.is_finite(), "background at ({x}, {y})");
                max_coc = max_coc.max(cam.coc_px(z));
            }
        }
        assert!((8.0..=9.0).contains(&max_coc), "largest CoC {max_coc} px");
        let db = psnr(&reference, &rdb.image).unwrap();
        eprintln!("RDB 9×9 centre against accum 256: {db:.2} dB");
        assert!(db >= 35.0, "RDB 9×9 centre: {db:.2} dB against accum 256");
    });
}

#[test]
fn both_atomics_give_the_same_image_bit_for_bit_across_frames_and_tag_wraps() {
    with_gpu(|ctx| {
        assert!(
            ctx.info.buffer_int64_atomics,
            "the test device has no 64-bit buffer atomics"
        );
        let renderer = Renderer::new(ctx).unwrap();
        let scan = load_ply(&root().join("data/pcl_table_scene_mug_rgb.ply")).unwrap();
        let scene = renderer.upload(&scan, SplatSize::Spacing).unwrap();
        let cam = mug_camera(61, 45);
        let count = |r: &pointlens::render::Rendered, name: &str| {
            r.timings
                .passes
                .iter()
                .find(|p| p.name == name)
                .map_or(0, |p| p.count)
        };
        let mut fills = 0;
        // Frames in a row on one renderer: the 64-bit bins are kept, reused,
        // grown (16×16 bins after 9×9), and their 31 tags run out within
        // the frame of 4×4 bins in tiles of 30 pixels (92 tiles).
        for (bins, mode, budget) in [
            (5, RdbMode::Centre, None),
            (9, RdbMode::Pairs, None),
            (16, RdbMode::Centre, Some(1 << 20)),
            (4, RdbMode::Centre, Some(128 * 30)),
            (5, RdbMode::Centre, None),
            (9, RdbMode::Centre, Some(100_000)),
        ] {
            let render = |atomics| {
                let mut o = options(cam, Method::rdb(bins, mode));
                o.method = Method::Rdb(RdbOptions {
                    bins,
                    mode,
                    memory_bytes: budget,
                    atomics,
                });
                renderer.render(&scene, &o).unwrap()
            };
            let wide = render(RdbAtomics::Int64);
            let split = render(RdbAtomics::Int32);
            let what = format!("{bins}×{bins} {mode:?} budget {budget:?}");
            let differ = wide
                .image
                .pixels
                .iter()
                .zip(&split.image.pixels)
                .filter(|(a, b)| a.map(f32::to_bits) != b.map(f32::to_bits))
                .count();
            assert_eq!(differ, 0, "{what}: {differ} pixels differ");
            // One scatter pass per tile and no clear in the 64-bit form; a
            // clear and two scatters per tile in the 32-bit one.
            let tiles = count(&wide, "rdb.resolve");
            assert_eq!(tiles, count(&split, "rdb.resolve"), "{what}");
            assert_eq!(count(&wide, "rdb.scatter"), tiles, "{what}");
            assert_eq!(count(&wide, "rdb.clear"), 0, "{what}");
            assert_eq!(count(&split, "rdb.clear"), tiles, "{what}");
            assert_eq!(count(&split, "rdb.depth"), tiles, "{what}");
            let filled = count(&wide, "rdb.fill");
            if tiles > 31 {
                // A fill before the first tile (made anew, or tags left)
                // and one after every 31 uses.
                assert!(
                    (tiles / 31..=tiles / 31 + 1).contains(&filled),
                    "{what}: {filled} fills for {tiles} tiles"
                );
            }
            fills += filled;
        }
        assert!(fills >= 3, "{fills} fills: made, grown, wrapped");
    });
}

#[test]
fn pairs_mode_past_the_devices_loop_limit_is_refused_in_one_line() {
    // `--rdb-mode pairs` scans a source's whole disk in one invocation:
    // CoCs of 256 px and more pass llvmpipe's 65,535 loop iterations per
    // invocation, which would drop part of each disk without a word. A
    // plane 3 units away, focused at 0.3 through a lens of radius 1: CoCs
    // of about 400 px (behind the focus, so no veil takes them). Refused on a device with a loop limit (lavapipe), in
    // one line naming the way out; the default mode renders the frame.
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let scene = renderer
            .upload(&textured_plane(3.0, 0.0), SplatSize::Spacing)
            .unwrap();
        let mut cam = camera(64, 48);
        cam.aperture_radius = 1.0;
        cam.focus_distance = 0.3;
        assert!(cam.coc_px(3.0) > 256.0, "{}", cam.coc_px(3.0));
        let pairs = renderer.render(&scene, &options(cam, Method::rdb(9, RdbMode::Pairs)));
        match ctx.info.loop_iterations_limit() {
            Some(_) => {
                let err = pairs.err().expect("refused").to_string();
                assert!(
                    !err.contains('\n') && err.contains("use --rdb-mode centre"),
                    "{err}"
                );
            }
            None => assert!(pairs.is_ok()),
        }
        let centre = render(&renderer, &scene, cam, Method::rdb(9, RdbMode::Centre));
        assert!(centre.pixels.iter().any(|p| p[3] > 0.5));
    });
}

/// The 64-bit bins in either layout (`passes::kernel_sizes`: a pixel's
/// bins side by side, lavapipe's; a plane per bin, a GPU's) give the same
/// bits: the same words meet the same atomicMin. Centre and pairs modes,
/// a frame in tiles of unequal sizes (each tile's planes are its own
/// size), the cat's eye's weighted resolve, and the round pipelines left
/// as they were.
#[test]
fn both_layouts_of_the_64_bit_bins_give_the_same_bits() {
    use pointlens::passes::kernel_sizes::KernelSizes;
    with_gpu(|ctx| {
        assert!(!KernelSizes::for_device(&ctx.info).rdb_bin_major);
        let mut renderer = Renderer::new(ctx).unwrap();
        let scan = load_ply(&root().join("data/pcl_table_scene_mug_rgb.ply")).unwrap();
        let scene = renderer.upload(&scan, SplatSize::Spacing).unwrap();
        let mut cat_eye = mug_camera(61, 45);
        cat_eye.aperture.cat_eye = 1.0;
        for (bins, mode, budget, cam) in [
            (9, RdbMode::Centre, None, mug_camera(61, 45)),
            (5, RdbMode::Pairs, None, mug_camera(61, 45)),
            (9, RdbMode::Centre, Some(100_000), mug_camera(61, 45)),
            (5, RdbMode::Centre, None, cat_eye),
        ] {
            let o = options(
                cam,
                Method::Rdb(RdbOptions {
                    bins,
                    mode,
                    memory_bytes: budget,
                    atomics: RdbAtomics::Int64,
                }),
            );
            let mut frames = Vec::new();
            for bin_major in [false, true] {
                renderer.set_kernel_sizes(KernelSizes {
                    rdb_bin_major: bin_major,
                    ..KernelSizes::ALONE
                });
                frames.push(renderer.render(&scene, &o).unwrap());
            }
            let what = format!(
                "{bins}×{bins} {mode:?} budget {budget:?} cat's eye {}",
                cam.aperture.cat_eye
            );
            let tiles = frames[0]
                .timings
                .passes
                .iter()
                .find(|p| p.name == "rdb.resolve")
                .map_or(0, |p| p.count);
            if budget.is_some() {
                assert!(tiles > 2, "{what}: {tiles} tiles");
            }
            assert!(
                common::image_bits(&frames[0].image) == common::image_bits(&frames[1].image),
                "{what}: the layouts differ"
            );
            let first = frames[0].image.pixels[0];
            assert!(
                frames[0].image.pixels.iter().any(|p| *p != first),
                "{what}: one colour"
            );
        }
    });
}
