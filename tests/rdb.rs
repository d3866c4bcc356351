//! The ray distribution buffer (`--method rdb`, DESIGN §5) on lavapipe.

mod common;

use common::{camera, cloud, root, with_gpu};
use glam::Vec3;
use pointlens::camera::Camera;
use pointlens::image_io::LinearImage;
use pointlens::metrics::psnr;
use pointlens::passes::fast::{FastWeights, GatherWindow};
use pointlens::passes::rdb::RdbMode;
use pointlens::ply::load_ply;
use pointlens::reference;
use pointlens::render::{Method, RenderOptions, Renderer, Scene, SplatSize};

fn options(cam: Camera, method: Method, samples: u32) -> RenderOptions {
    RenderOptions {
        camera: cam,
        method,
        ssaa: 2,
        background: Vec3::ZERO,
        samples,
    }
}

fn render(renderer: &Renderer, scene: &Scene, cam: Camera, method: Method) -> LinearImage {
    renderer
        .render(scene, &options(cam, method, 256))
        .unwrap()
        .image
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
        };
        for (bins, mode) in [
            (5, RdbMode::Centre),
            (9, RdbMode::Centre),
            (5, RdbMode::Pairs),
            (9, RdbMode::Pairs),
        ] {
            let method = Method::Rdb(bins, mode);
            let (gpu, gbuffer) = renderer
                .render_with_gbuffer(&scene, &options(cam, method, 1))
                .unwrap();
            let again = renderer.render(&scene, &options(cam, method, 1)).unwrap();
            assert_eq!(
                gpu.image, again.image,
                "{bins}×{bins} {mode:?}: two runs differ"
            );
            let cpu = reference::rdb(&gbuffer, &cam, bins, mode);
            let mut differ = 0;
            for (a, b) in gpu.image.pixels.iter().zip(&cpu.pixels) {
                // rgba16f storage: 2^-11 relative.
                if (0..3).any(|c| (a[c] - b[c]).abs() > 1e-3 * b[c].abs().max(0.05)) {
                    differ += 1;
                }
            }
            // A float rounding at an exact .5 pixel offset may send one ray
            // to a neighbouring pixel on one side only: allow 1 % of pixels.
            assert!(
                differ * 100 <= gpu.image.pixels.len(),
                "{bins}×{bins} {mode:?}: {differ} pixels differ"
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
fn with_partial_occlusion_rdb_is_closer_to_accum_than_fast() {
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
            .render(&scene, &options(cam, Method::Accum, 256))
            .unwrap()
            .image;
        let rdb = psnr(
            &reference,
            &render(&renderer, &scene, cam, Method::Rdb(9, RdbMode::Centre)),
        )
        .unwrap();
        let fast = psnr(
            &reference,
            &render(
                &renderer,
                &scene,
                cam,
                Method::Fast(FastWeights::Area, GatherWindow::Tiles),
            ),
        )
        .unwrap();
        assert!(
            rdb > fast,
            "RDB {rdb:.2} dB, fast {fast:.2} dB against accum"
        );
    });
}
