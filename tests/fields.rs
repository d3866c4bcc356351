//! The bounded two-field gather (`--fast-gather fields`, issue 28, item 5;
//! `pointlens::fields`) on lavapipe: its passes against the CPU reference,
//! and its image against accum.

mod common;

use common::{differing, options, pass_count, root, with_gpu};
use glam::Vec3;
use pointlens::bench::BenchModel;
use pointlens::camera::Camera;
use pointlens::metrics::psnr;
use pointlens::options::{FastGather, FastOptions, Method};
use pointlens::render::{RenderOptions, Renderer, Scene, SplatSize};

const FIELDS: Method = Method::Fast(FastOptions {
    weights: pointlens::options::FastWeights::Area,
    window: pointlens::options::GatherWindow::Tiles,
    gather: FastGather::Fields,
});

/// The bundled scenes, uploaded, each with the bench's camera at 160×120
/// and the eye-depth range of its points.
fn scenes(renderer: &Renderer) -> Vec<(&'static str, Scene, Camera, (f32, f32))> {
    let models = [
        ("bunny", BenchModel::Bunny),
        ("mug", BenchModel::Mug),
        (
            "autzen",
            BenchModel::File(root().join("data/autzen_trim.las")),
        ),
    ];
    models
        .into_iter()
        .map(|(name, model)| {
            let cloud = model.load(&root().join("data"), 0).unwrap();
            let camera = model.camera(&cloud, 160, 120).unwrap();
            let depths = cloud
                .positions
                .iter()
                .map(|&p| camera.eye_from_world(p).z)
                .filter(|&z| z > 0.0)
                .fold((f32::INFINITY, 0.0f32), |(lo, hi), z| {
                    (lo.min(z), hi.max(z))
                });
            let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
            (name, scene, camera, depths)
        })
        .collect()
}

/// `camera` with its aperture scaled to a background CoC of `coc_px`.
fn with_background_coc(mut camera: Camera, coc_px: f32) -> Camera {
    camera.aperture_radius *= coc_px / camera.coc_px(f32::INFINITY);
    camera
}

#[test]
fn the_passes_equal_the_cpu_reference_at_every_band_level() {
    // Background CoCs of 12 to 300 px, focused on the scene's centre or
    // nearer, and a frame whose points' CoCs reach 300 px: the bands to
    // their open top level (radii of 128 px and more, asserted below). In
    // both cuts of the bands (`passes::kernel_sizes`): an invocation per
    // texel (lavapipe's), and a GPU's workgroup per texel of the coarse
    // levels, whose float sums add in another order.
    use pointlens::passes::kernel_sizes::KernelSizes;
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        let gpu_cut = KernelSizes::for_gpu(
            ctx.info.subgroup_size,
            ctx.info.max_compute_workgroup_invocations,
        );
        assert!(gpu_cut.bands_shared_level.is_some());
        // The band levels the surfaces of the frames reach (0: full
        // resolution).
        let mut levels = std::collections::BTreeSet::new();
        let scenes = scenes(&renderer);
        for (cut, sizes) in [("alone", KernelSizes::ALONE), ("shared", gpu_cut)] {
            renderer.set_kernel_sizes(sizes);
            for (name, scene, camera, depths) in &scenes {
                let (camera, depths) = (*camera, *depths);
                // The last frame: 320×240, focused at twice the distance, the
                // points' largest CoC 300 px (under the 320 px past which a
                // point in front of the focus would leave the G-buffer for
                // the veil, which the reference does not draw).
                let mut top = camera;
                (top.width, top.height) = (320, 240);
                top.focus_distance *= 2.0;
                top.aperture_radius *= 300.0 / top.max_coc_px(depths.0, depths.1);
                let frames = [
                    with_background_coc(camera, 12.0),
                    Camera {
                        focus_distance: 0.8 * camera.focus_distance,
                        ..with_background_coc(camera, 48.0)
                    },
                    with_background_coc(camera, 300.0),
                    top,
                ];
                for cam in frames {
                    let coc = cam.coc_px(f32::INFINITY).round();
                    let focus_scale = cam.focus_distance / camera.focus_distance;
                    let (gpu, gbuffer) = renderer
                        .render_with_gbuffer(scene, &options(cam, FIELDS))
                        .unwrap();
                    // Each cut's sums go in a fixed order: the same bits
                    // every time.
                    let again = renderer.render(scene, &options(cam, FIELDS)).unwrap();
                    assert!(
                        common::image_bits(&again.image) == common::image_bits(&gpu.image),
                        "{cut}: {name}: two renders differ"
                    );
                    let cpu = pointlens::fields::reference(&gbuffer, &cam);
                    levels.extend(gbuffer.eye.iter().filter(|e| e[2].is_finite()).map(|e| {
                        pointlens::fields::band_level(0.5 * cam.coc_px(e[2])).unwrap_or(0)
                    }));
                    // The GPU sums in float32 in the reference's order of
                    // terms, but its results pass through rgba16f (a step of
                    // 2^-11 relative) and its sqrt, log2 and divisions may
                    // differ from the CPU's in the last bit: 4e-3 relative, or
                    // 1e-3 absolute for values near 0.
                    let worst = gpu
                        .image
                        .pixels
                        .iter()
                        .zip(&cpu.pixels)
                        .flat_map(|(a, b)| {
                            (0..4).map(move |c| (a[c] - b[c]).abs() / b[c].abs().max(0.25))
                        })
                        .fold(0.0f32, f32::max);
                    let db = psnr(&cpu, &gpu.image).unwrap();
                    eprintln!("{cut}: {name}, background CoC {coc} px, focus ×{focus_scale}: worst {worst:.2e}, {db:.1} dB");
                    assert!(
                    worst < 4e-3,
                    "{cut}: {name}, CoC {coc}: the passes differ from the reference by {worst:.2e}"
                );
                }
            }
        }
        assert_eq!(
            levels,
            (0..=pointlens::fields::LEVELS).collect(),
            "not every band level was reached"
        );
    });
}

/// PSNR floors of the two-field gather against accum 64 on the bundled
/// scenes, at 160×120 with the bench's camera and a 48 px background CoC
/// (the paper's `fast` floor test's frames, `tests/fast.rs`): measured
/// 39.88, 31.01 and 43.48 dB (the paper's `fast` 29.59, 26.82, 39.84;
/// `layered1` 38.90, 31.86, 43.72), each floor its measure less 1 dB (both renders are deterministic; the margin is for
/// another driver's rounding).
const FLOORS_DB: [f64; 3] = [38.9, 30.0, 42.5];

#[test]
fn it_meets_its_floor_against_accum_and_beats_the_papers_fast() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        for ((name, scene, camera, _), floor) in scenes(&renderer).into_iter().zip(FLOORS_DB) {
            let cam = with_background_coc(camera, 48.0);
            let base = RenderOptions {
                background: Vec3::new(0.05, 0.1, 0.2),
                ..options(cam, Method::accum(64))
            };
            let reference = renderer.render(&scene, &base).unwrap().image;
            let render = |method| {
                let o = RenderOptions { method, ..base };
                renderer.render(&scene, &o).unwrap().image
            };
            let fields = psnr(&reference, &render(FIELDS)).unwrap();
            let paper = psnr(&reference, &render(Method::Fast(FastOptions::PAPER))).unwrap();
            let layered = psnr(&reference, &render(Method::layered(1))).unwrap();
            eprintln!("{name}: fields {fields:.2} dB, the paper's fast {paper:.2}, layered1 {layered:.2} against accum 64");
            assert!(
                fields >= floor,
                "{name}: {fields:.2} dB against accum 64, floor {floor} dB"
            );
            assert!(
                fields > paper + 1.0,
                "{name}: fields {fields:.2} dB is not above the paper's fast {paper:.2} dB"
            );
        }
    });
}

/// A frame in tiles is the frame rendered whole (the texels of a tile are
/// the whole frame's, `passes::fields::anchor`): every bundled scene,
/// its background blurred 100 px (more once focused in front of its
/// centre, so that near blur crosses the seams too), in 3×3 tiles of
/// 53–54 × 40 px (`--tile-px 54`: corners off the 64-pixel top-level
/// texels). Measured: bunny and tile bit for bit, the mug 93.4 dB (a
/// tile's G-buffer holds less of its guard band's far edge than the whole
/// frame's, whose top-level texels may reach a seam); with the anchor at 0
/// the bunny is 56.6 dB. Tolerance 85 dB, between the two.
#[test]
fn a_frame_in_tiles_is_the_whole_frame() {
    with_gpu(|ctx| {
        let whole = Renderer::new(ctx).unwrap();
        let mut tiled = Renderer::new(ctx).unwrap();
        tiled.set_tile_px(Some(54));
        let whole_scenes = scenes(&whole);
        let tiled_scenes = scenes(&tiled);
        for ((name, scene, camera, depths), (_, tiled_scene, ..)) in
            whole_scenes.iter().zip(&tiled_scenes)
        {
            let mut camera = with_background_coc(*camera, 100.0);
            camera.focus_distance = depths.0 + 0.3 * (depths.1 - depths.0);
            let options = options(camera, FIELDS);
            let a = whole.render(scene, &options).unwrap();
            let b = tiled.render(tiled_scene, &options).unwrap();
            assert_eq!(pass_count(&b, "output"), 9, "{name}: 3 × 3 tiles");
            let db = psnr(&a.image, &b.image).unwrap();
            let differing = differing(&a.image, &b.image);
            eprintln!(
                "{name}: guard {} px, tiled vs whole {db:.2} dB, {differing} pixels differ",
                a.guard
            );
            assert!(
                db >= 85.0,
                "{name}: the tiled frame is {db:.2} dB from the whole one"
            );
        }
    });
}
