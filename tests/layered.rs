//! The layered method (DESIGN §6): partial occlusion against the
//! accumulation reference, more layers never worse, no seam where the peel
//! cuts a surface, the spreading filter's disk (against its CPU form) and
//! energy, the degenerate cases, the modified peel, and bitwise
//! reproducibility.

mod common;

use common::{camera, cloud, options, scratch, with_gpu};
use glam::Vec3;
use pointlens::bench::BenchModel;
use pointlens::camera::Camera;
use pointlens::image_io::{write_image, LinearImage};
use pointlens::metrics;
use pointlens::options::{Coverage, FastWeights, GatherWindow, LayeredOptions, Method, RdbMode};
use pointlens::passes::spread_disk;
use pointlens::render::{RenderOptions, Renderer, Scene, SplatSize};

const W: u32 = 64;
const H: u32 = 48;

/// A textured plane at z = −3 (a 0.2-unit checker, tinted light and dark)
/// behind a vertical bar at z = −1 (x in [−0.1, 0.1], 13 px wide, or
/// [−0.3, 0.3] when `wide`) of `bar_color`. `plane_color` replaces the
/// checker when given.
fn occlusion_scene(
    bar_color: Vec3,
    plane_color: Option<Vec3>,
    with_bar: bool,
    wide: bool,
) -> Vec<(Vec3, Vec3)> {
    let mut points = Vec::new();
    for j in -75..=75 {
        for i in -100..=100 {
            let (x, y) = (i as f32 * 0.02, j as f32 * 0.02);
            let checker = ((x / 0.2).floor() as i32 + (y / 0.2).floor() as i32).rem_euclid(2);
            let c = plane_color.unwrap_or(if checker == 0 {
                Vec3::new(0.8, 0.75, 0.6)
            } else {
                Vec3::new(0.1, 0.15, 0.25)
            });
            points.push((Vec3::new(x, y, -3.0), c));
        }
    }
    if with_bar {
        for j in -200..=200 {
            let half = if wide { 60 } else { 20 };
            for i in -half..=half {
                let p = Vec3::new(i as f32 * 0.005, j as f32 * 0.005, -1.0);
                points.push((p, bar_color));
            }
        }
    }
    points
}

const ORANGE: Vec3 = Vec3::new(0.9, 0.35, 0.05);

/// Focused on the plane; the bar's CoC is about 8.8 px.
fn occlusion_camera() -> Camera {
    let mut cam = camera(W, H);
    cam.focus_distance = 3.0;
    cam.aperture_radius = 0.1;
    cam
}

fn upload(renderer: &Renderer, points: &[(Vec3, Vec3)]) -> Scene {
    // Splat sizes from each point's spacing: the plane's 0.02, the bar's
    // 0.005.
    renderer.upload(&cloud(points), SplatSize::Spacing).unwrap()
}

fn render(renderer: &Renderer, scene: &Scene, cam: Camera, method: Method) -> LinearImage {
    renderer.render(scene, &options(cam, method)).unwrap().image
}

fn psnr(a: &LinearImage, b: &LinearImage) -> f64 {
    metrics::psnr(a, b).unwrap()
}

/// Mean absolute RGB error over the pixels `inside` selects.
fn band_error(a: &LinearImage, b: &LinearImage, inside: impl Fn(u32, u32) -> bool) -> f32 {
    let (mut sum, mut n) = (0.0, 0);
    for y in 0..a.height {
        for x in 0..a.width {
            if inside(x, y) {
                let i = (y * a.width + x) as usize;
                sum += (0..3)
                    .map(|c| (a.pixels[i][c] - b.pixels[i][c]).abs())
                    .sum::<f32>();
                n += 1;
            }
        }
    }
    assert!(n > 0, "an empty band");
    sum / n as f32
}

/// Writes `image` to a scratch directory when a comparison fails, so that
/// it can be looked at.
fn keep(name: &str, images: &[(&str, &LinearImage)]) -> String {
    let dir = scratch(name);
    for (n, img) in images {
        write_image(img, &dir.join(format!("{n}.png"))).unwrap();
    }
    let path = dir.path().display().to_string();
    std::mem::forget(dir);
    path
}

#[test]
fn layered_sees_the_background_through_a_blurred_occluder() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let scene = upload(&renderer, &occlusion_scene(ORANGE, None, true, false));
        let cam = occlusion_camera();
        let reference = render(&renderer, &scene, cam, Method::accum(128));
        let layered = render(&renderer, &scene, cam, Method::layered(4));
        let single = render(&renderer, &scene, cam, Method::layered(1));
        let rdb = render(&renderer, &scene, cam, Method::rdb(9, RdbMode::Centre));
        let fast = render(
            &renderer,
            &scene,
            cam,
            Method::paper_fast(FastWeights::Area, GatherWindow::Tiles),
        );
        let (pl, pr, pf, p1) = (
            psnr(&layered, &reference),
            psnr(&rdb, &reference),
            psnr(&fast, &reference),
            psnr(&single, &reference),
        );
        let where_ = || {
            keep(
                "layered-occlusion",
                &[
                    ("accum", &reference),
                    ("layered4", &layered),
                    ("layered1", &single),
                    ("rdb9", &rdb),
                    ("fast-tree", &fast),
                ],
            )
        };
        eprintln!(
            "PSNR against accum: layered4 {pl:.2}, layered1 {p1:.2}, rdb9 {pr:.2}, fast {pf:.2} dB"
        );
        assert!(
            pl > pr && pl > pf,
            "layered4 {pl:.2} dB, rdb9 {pr:.2}, fast {pf:.2}; images in {}",
            where_()
        );
        // Inside the bar's pinhole silhouette, within its blur radius of the
        // edge, the lens sees the background past the bar. The bar spans
        // x in [−0.1, 0.1] at z = 1: pixels 32 ± 6.6 (f = 65.9 px).
        let f = cam.f_px();
        let half = 0.1 * f;
        let blur = cam.coc_px(1.0) / 2.0;
        let inner_band = |x: u32, _y: u32| {
            let d = half - ((x as f32 + 0.5) - W as f32 / 2.0).abs();
            (0.5..blur - 0.5).contains(&d)
        };
        let e4 = band_error(&layered, &reference, inner_band);
        let e1 = band_error(&single, &reference, inner_band);
        let er = band_error(&rdb, &reference, inner_band);
        eprintln!("inner edge band error: layered4 {e4:.4}, layered1 {e1:.4}, rdb9 {er:.4}");
        // One layer has no surface behind the bar: there, its edge shows the
        // black background instead.
        assert!(
            e4 < 0.5 * e1,
            "layered4 {e4:.4}, layered1 {e1:.4}; images in {}",
            where_()
        );
        assert!(
            e4 < er,
            "layered4 {e4:.4}, rdb9 {er:.4}; images in {}",
            where_()
        );
    });
}

#[test]
fn more_layers_are_never_worse_and_the_modified_peel_only_drops_what_is_unseen() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let scene = upload(&renderer, &occlusion_scene(ORANGE, None, true, true));
        let cam = occlusion_camera();
        let reference = render(&renderer, &scene, cam, Method::accum(128));
        let mut last = f64::NEG_INFINITY;
        for k in 1..=4 {
            let img = render(&renderer, &scene, cam, Method::layered(k));
            let p = psnr(&img, &reference);
            eprintln!("layered{k}: {p:.3} dB");
            // fp16 output and fixed-point sums: 0.05 dB of slack.
            assert!(p >= last - 0.05, "layered{k} {p:.3} dB after {last:.3} dB");
            last = p;
        }
        // The plain peel (every occluded pixel kept) against the modified
        // one: the same image within rounding, with pixels discarded.
        let layered = |keep_occluded| {
            let method = Method::Layered(LayeredOptions {
                layers: 4,
                keep_occluded,
            });
            options(cam, method)
        };
        let modified = renderer.render(&scene, &layered(false)).unwrap();
        let plain = renderer.render(&scene, &layered(true)).unwrap();
        let count = |r: &pointlens::render::Rendered, name: &str| {
            r.counts
                .iter()
                .find(|(n, _)| n == name)
                .map(|c| c.1)
                .unwrap()
        };
        // Each later layer is one peel pass and its resolve, whatever the
        // first layer's plan (SSAA 2 here: one upscaled pass of 4 samples).
        let passes = |r: &pointlens::render::Rendered, name: &str| {
            r.timings
                .passes
                .iter()
                .find(|p| p.name == name)
                .map_or(0, |p| p.count)
        };
        assert_eq!(passes(&modified, "peel.raster"), 3);
        assert_eq!(passes(&modified, "peel.resolve"), 3);
        assert_eq!(passes(&modified, "gbuffer.raster"), 1);
        let discarded: u64 = (1..4)
            .map(|l| count(&modified, &format!("layered.layer{l}.discarded_px")))
            .sum();
        assert_eq!(count(&modified, "layered.layer0.discarded_px"), 0);
        assert!(discarded > 0, "the modified peel discarded nothing");
        for l in 0..4 {
            let kept = format!("layered.layer{l}.kept_px");
            let dropped = format!("layered.layer{l}.discarded_px");
            assert_eq!(
                count(&modified, &kept) + count(&modified, &dropped),
                count(&plain, &kept),
                "layer {l}: kept + discarded = the layer's covered pixels"
            );
        }
        let p = psnr(&modified.image, &plain.image);
        assert!(p > 60.0, "modified peel {p:.1} dB from the plain one");
    });
}

#[test]
fn a_surface_cut_by_the_peel_shows_no_seam() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        // A uniform plane behind a bar of the same color: the peel cuts the
        // plane at the bar's silhouette into the first layer (beside the
        // bar) and the second (behind it). Whatever the blur, the image is
        // the plane's color wherever the plane fills the lens's view.
        let c = Vec3::new(0.6, 0.4, 0.2);
        let cut = upload(&renderer, &occlusion_scene(c, Some(c), true, false));
        let whole = upload(&renderer, &occlusion_scene(c, Some(c), false, false));
        let cam = occlusion_camera();
        let alone = render(&renderer, &whole, cam, Method::layered(4));
        let layered = render(&renderer, &cut, cam, Method::layered(4));
        let single = render(&renderer, &cut, cam, Method::layered(1));
        let worst = |img: &LinearImage| {
            img.pixels
                .iter()
                .map(|p| (Vec3::from_slice(&p[..3]) - c).abs().max_element())
                .fold(0.0f32, f32::max)
        };
        let (wa, wl, w1) = (worst(&alone), worst(&layered), worst(&single));
        eprintln!(
            "largest deviation: plane alone {wa:.4}, cut in 4 layers {wl:.4}, 1 layer {w1:.4}"
        );
        // fp16 output: 2e-3; the cut adds at most that again.
        assert!(wa < 2e-3, "the plane alone deviates by {wa}");
        assert!(
            wl < 4e-3,
            "the cut plane deviates by {wl}; images in {}",
            keep("layered-seam", &[("cut", &layered), ("alone", &alone)])
        );
        // The test can fail: one layer has nothing behind the bar.
        assert!(w1 > 0.05, "one layer deviates by only {w1}");
    });
}

#[test]
fn a_single_pixel_spreads_as_the_cpu_disk_says_with_its_energy() {
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        // One sample lit: the samples' G-buffer (by area the splat's
        // square lights the four pixels it straddles).
        renderer.set_coverage(Some(Coverage::Samples));
        let color = Vec3::new(0.9, 0.5, 0.25);
        // One point on the axis at z = 1, one pixel wide; focus at 2.
        let scene = renderer
            .upload(
                &cloud(&[(Vec3::new(0.0, 0.0, -1.0), color)]),
                SplatSize::Pixels(1.0),
            )
            .unwrap();
        let mut cam = camera(W, H);
        cam.focus_distance = 2.0;
        let one_sample = |cam: Camera, method| RenderOptions {
            ssaa: 1,
            ..options(cam, method)
        };
        // The pixel the point lands on: the pinhole image's one lit pixel.
        let pinhole = renderer
            .render(&scene, &one_sample(cam, Method::Pinhole))
            .unwrap()
            .image;
        let lit: Vec<usize> = (0..pinhole.pixels.len())
            .filter(|&i| pinhole.pixels[i][0] > 0.0)
            .collect();
        assert_eq!(
            lit.len(),
            1,
            "the pinhole image lights {} pixels",
            lit.len()
        );
        let (sx, sy) = ((lit[0] as u32 % W) as i32, (lit[0] as u32 / W) as i32);
        cam.aperture_radius = 1.0;
        let coc_per_unit = cam.coc_px(1.0);
        // From under a pixel (the spread radius's correction matters
        // most there) to a disk 13 px wide.
        for coc in [0.4f32, 1.3, 2.6, 5.5, 13.0] {
            cam.aperture_radius = coc / coc_per_unit;
            let img = renderer
                .render(&scene, &one_sample(cam, Method::layered(2)))
                .unwrap()
                .image;
            let mut expected = vec![Vec3::ZERO; (W * H) as usize];
            for (dx, dy, w) in spread_disk::weights(spread_disk::spread_radius_px(coc)) {
                let (x, y) = (sx + dx, sy + dy);
                expected[(y as u32 * W + x as u32) as usize] += color * w as f32;
            }
            let mut energy = Vec3::ZERO;
            for (i, want) in expected.iter().enumerate() {
                let got = Vec3::from_slice(&img.pixels[i][..3]);
                energy += got;
                // fp16 output (2^-11 relative) and 2^-22 fixed point.
                let tolerance = 1e-3 * want.max_element() + 1e-5;
                assert!(
                    (got - *want).abs().max_element() <= tolerance,
                    "CoC {coc} px: pixel ({}, {}) is {got}, the CPU disk gives {want}; image in {}",
                    i as u32 % W,
                    i as u32 / W,
                    keep("layered-single-pixel", &[("actual", &img)])
                );
            }
            let rel = (energy - color).abs() / color;
            // fp16 output of small values: 1 %.
            assert!(
                rel.max_element() < 0.01,
                "CoC {coc} px: energy {energy}, not {color}"
            );
        }
    });
}

#[test]
fn without_blur_layered_is_the_pinhole_image_and_runs_repeat_bitwise() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let scene = upload(&renderer, &occlusion_scene(ORANGE, None, true, false));
        let mut sharp = occlusion_camera();
        sharp.aperture_radius = 0.0;
        let pinhole = render(&renderer, &scene, sharp, Method::Pinhole);
        for k in [1, 4] {
            let img = render(&renderer, &scene, sharp, Method::layered(k));
            let worst = img
                .pixels
                .iter()
                .zip(&pinhole.pixels)
                .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).abs()).fold(0.0f32, f32::max))
                .fold(0.0f32, f32::max);
            // fp16 and 2^-22 fixed point: within 2e-3.
            assert!(
                worst < 2e-3,
                "layered{k} without blur is {worst} from pinhole"
            );
        }
        let cam = occlusion_camera();
        let a = render(&renderer, &scene, cam, Method::layered(4));
        let b = render(&renderer, &scene, cam, Method::layered(4));
        assert!(
            common::image_bits(&a) == common::image_bits(&b),
            "two runs differ"
        );
    });
}

#[test]
fn a_sharp_surface_and_a_blurred_one_do_not_leak_into_each_other() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        // In focus: a red half-plane (x < 0) at z = 1; behind it a blue
        // plane at z = 4, blurred (CoC 9.9 px). The red edge is at pixel
        // column 32.
        let (red, blue) = (Vec3::new(0.8, 0.0, 0.0), Vec3::new(0.0, 0.1, 0.7));
        let mut points = Vec::new();
        for j in -150..=150 {
            for i in -250..0 {
                points.push((Vec3::new(i as f32 * 0.004, j as f32 * 0.004, -1.0), red));
            }
        }
        for j in -100..=100 {
            for i in -150..=150 {
                points.push((Vec3::new(i as f32 * 0.04, j as f32 * 0.04, -4.0), blue));
            }
        }
        let scene = upload(&renderer, &points);
        let mut cam = camera(W, H);
        cam.focus_distance = 1.0;
        cam.aperture_radius = 0.1;
        assert!(cam.coc_px(4.0) > 9.0);
        for method in [Method::accum(64), Method::layered(4)] {
            let img = render(&renderer, &scene, cam, method);
            for y in 0..H {
                for x in 0..W {
                    let p = img.pixels[(y * W + x) as usize];
                    // The sharp red does not spread beyond its edge...
                    if x >= 34 {
                        assert!(p[0] < 0.01, "{method:?}: red {} at ({x}, {y})", p[0]);
                    }
                    // ...and the blurred blue does not spread over it.
                    if x <= 29 {
                        assert!(p[2] < 0.01, "{method:?}: blue {} at ({x}, {y})", p[2]);
                    }
                }
            }
        }
    });
}

#[test]
fn culling_the_peel_s_splats_changes_no_layered_image() {
    // The sprites' peel draws only the splats that can pass its test
    // somewhere (passes::peel_cull): the same images bit for bit, fewer
    // splats drawn. (The compute rasteriser's peel draws every splat.)
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        renderer.set_raster(pointlens::options::Raster::Sprites);
        let cases = [
            (BenchModel::Bunny, SplatSize::Spacing),
            (BenchModel::Mug, SplatSize::Spacing),
            // Sizes in pixels: the cull's diameter from --splat-px.
            (BenchModel::Bunny, SplatSize::Pixels(3.0)),
            // The LiDAR tile, where the cull drops the most.
            (
                BenchModel::File(common::root().join("data/autzen_trim.las")),
                SplatSize::Spacing,
            ),
        ];
        for (model, splat) in cases.iter().cloned() {
            let cloud = model.load(&common::root().join("data"), 0).unwrap();
            let scene = renderer.upload(&cloud, splat).unwrap();
            for (ssaa, layers) in [(2, 4), (4, 2), (1, 3)] {
                let options = RenderOptions {
                    camera: model.camera(&cloud, 96, 72).unwrap(),
                    method: Method::Layered(LayeredOptions {
                        layers,
                        keep_occluded: false,
                    }),
                    ssaa,
                    samples_per_pass: None,
                    background: Vec3::new(0.05, 0.1, 0.2),
                    lod: pointlens::options::Lod::default(),
                };
                renderer.set_peel_cull(false);
                let all = renderer.render(&scene, &options).unwrap();
                renderer.set_peel_cull(true);
                let culled = renderer.render(&scene, &options).unwrap();
                let differ = common::differing(&all.image, &culled.image);
                assert_eq!(
                    differ, 0,
                    "{model:?} K={ssaa} layers {layers}: pixels differ"
                );
                let culls = common::pass_count(&culled, "peel.cull");
                assert_eq!(culls, layers - 1);
            }
        }
    });
}

/// The cuts of the composite and the spread (`passes::kernel_sizes`)
/// write the bytes of the form a CPU device takes: the composite's rows
/// shared by a workgroup, its invocations' sums scanned and carried from
/// step to step along the row, as an invocation per row; the spread's list
/// taken in 2, 3 or 7 streams (`glsl/workgroup_order.glsl`) as in its
/// order. The sums are integers (`glsl/layered_fixed.glsl`), so no order
/// of them rounds differently, and a tile the streams left out or took
/// twice would change them. Workgroups of 8 and 24 take a 168-column row
/// (the frame and its guard) in several steps, 64 in one; the frame has
/// middle slices, whose rows sum only the columns their spread touched.
#[test]
fn every_cut_of_the_composite_and_the_spread_writes_the_same_bytes() {
    use pointlens::passes::kernel_sizes::KernelSizes;
    with_gpu(|ctx| {
        let device = KernelSizes::for_device(&ctx.info);
        let in_order = KernelSizes {
            workgroup_streams: 1,
            ..device
        };
        assert_eq!(in_order, KernelSizes::ALONE);
        let mut renderer = Renderer::new(ctx).unwrap();
        let cloud = BenchModel::Bunny
            .load(&common::root().join("data"), 0)
            .unwrap();
        let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        for method in [Method::layered(1), Method::layered(2)] {
            let mut camera = BenchModel::Bunny.camera(&cloud, 150, 61).unwrap();
            camera.aperture_radius *= 4.0;
            let options = options(camera, method);
            renderer.set_kernel_sizes(KernelSizes::ALONE);
            let alone = renderer.render(&scene, &options).unwrap();
            let slices = alone
                .counts
                .iter()
                .find(|(name, _)| name == "layered.slices")
                .map(|&(_, n)| n);
            assert!(slices > Some(2), "{method:?}: {slices:?} slices");
            let alone_bits = common::image_bits(&alone.image);
            let first = alone.image.pixels[0];
            assert!(
                alone.image.pixels.iter().any(|p| *p != first),
                "{method:?}: one colour"
            );
            let rows = [8, 24, 64].map(|row_threads| KernelSizes {
                row_threads,
                ..KernelSizes::ALONE
            });
            let streams = [2, 3, 7].map(|workgroup_streams| KernelSizes {
                workgroup_streams,
                ..KernelSizes::ALONE
            });
            for sizes in rows.into_iter().chain(streams) {
                renderer.set_kernel_sizes(sizes);
                let cut = renderer.render(&scene, &options).unwrap().image;
                assert!(
                    common::image_bits(&cut) == alone_bits,
                    "{method:?}: {sizes:?} differs"
                );
            }
        }
    });
}
