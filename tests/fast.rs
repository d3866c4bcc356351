//! Zhao's fast approximation (`--method fast`, DESIGN §4) on lavapipe.

mod common;

use common::{camera, cloud, options, root, with_gpu};
use glam::{Vec2, Vec3};
use pointlens::camera::Camera;
use pointlens::image_io::LinearImage;
use pointlens::input::ply::load_ply;
use pointlens::options::Method;
use pointlens::options::{FastWeights, GatherWindow};
use pointlens::reference;
use pointlens::render::{RenderOptions, Renderer, SplatSize};
use pointlens::PointCloud;

fn render(
    renderer: &Renderer,
    cloud: &PointCloud,
    splat: SplatSize,
    cam: Camera,
    method: Method,
) -> LinearImage {
    let scene = renderer.upload(cloud, splat).unwrap();
    renderer
        .render(&scene, &options(cam, method))
        .unwrap()
        .image
}

const FAST: Method = Method::fast(FastWeights::Area, GatherWindow::Tiles);

#[test]
fn gpu_fast_equals_the_cpu_reference_on_a_crop_of_a_real_scan() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let scan = load_ply(&root().join("data/pcl_table_scene_mug_rgb.ply")).unwrap();
        let scene = renderer.upload(&scan, SplatSize::Spacing).unwrap();
        // The scanner's own view of the mug (y down in the scan), a 48×40
        // crop around it, focused on the mug with the table in front and the
        // wall behind blurred.
        let mut cam = Camera {
            width: 48,
            height: 40,
            eye: Vec3::ZERO,
            target: Vec3::new(0.08, 0.08, 1.0),
            up: Vec3::new(0.0, -1.0, 0.0),
            fovy_deg: 6.0,
            aperture_radius: 0.03,
            focus_distance: 1.0,
        };
        for weights in [FastWeights::Area, FastWeights::Uniform] {
            for focus in [1.0, 1.3] {
                cam.focus_distance = focus;
                let (gpu, gbuffer) = renderer
                    .render_with_gbuffer(
                        &scene,
                        &options(cam, Method::fast(weights, GatherWindow::Tiles)),
                    )
                    .unwrap();
                let cpu = reference::fast(&gbuffer, &cam, weights);
                // The tile-bounded window finds exactly what the worst-case
                // window finds, in the same order: identical bits.
                let fixed = renderer
                    .render(
                        &scene,
                        &options(cam, Method::fast(weights, GatherWindow::Fixed)),
                    )
                    .unwrap();
                assert_eq!(
                    gpu.image, fixed.image,
                    "{weights:?}: tiles and fixed window differ"
                );
                let mut worst = 0.0f32;
                for (a, b) in gpu.image.pixels.iter().zip(&cpu.pixels) {
                    // Color and alpha (the coverage, weighted as the color).
                    for c in 0..4 {
                        // The GPU stores rgba16f: a relative error of 2^-11.
                        let err = (a[c] - b[c]).abs() / b[c].abs().max(0.05);
                        worst = worst.max(err);
                    }
                }
                assert!(
                    worst < 2e-3,
                    "{weights:?}, S = {focus}: GPU and CPU differ by {worst} (relative)"
                );
                let blurred = gbuffer
                    .eye
                    .iter()
                    .filter(|e| e[2].is_finite() && cam.coc_px(e[2]) > 3.0)
                    .count();
                assert!(
                    blurred > 100,
                    "the test must blur: only {blurred} pixels have a CoC over 3 px"
                );
            }
        }
    });
}

#[test]
fn an_out_of_focus_point_blurs_to_a_disk_of_the_coc_diameter() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        // A white point in front of the focus plane over a black background
        // plane at the focus distance (so the background itself is sharp).
        let mut cam = camera(64, 64);
        cam.focus_distance = 2.0;
        // f_px = 87.919; at z = 1, S = 2: c = 2R · 87.919 · 1 / 2 = 16 px for R = 0.181986.
        cam.aperture_radius = 0.181986;
        assert!((cam.coc_px(1.0) - 16.0).abs() < 1e-3);
        let f_px = cam.f_px();
        let mut points = vec![(Vec3::new(0.5 / f_px, -0.5 / f_px, -1.0), Vec3::ONE)];
        for j in -100..=100 {
            for i in -100..=100 {
                points.push((
                    Vec3::new(i as f32 * 0.01, j as f32 * 0.01, -2.0),
                    Vec3::ZERO,
                ));
            }
        }
        let img = render(
            &renderer,
            &cloud(&points),
            SplatSize::Pixels(1.0),
            cam,
            FAST,
        );
        // The point covers pixel (32, 32) exactly; with area weights its
        // light spreads evenly over the pixel centres of its 16 px disk.
        let lit: Vec<Vec2> = (0..64 * 64)
            .filter(|&i| img.pixels[i][0] > 1e-4)
            .map(|i| Vec2::new((i % 64) as f32, (i / 64) as f32))
            .collect();
        let centre = Vec2::new(32.0, 32.0);
        let radius = lit
            .iter()
            .map(|p| p.distance(centre))
            .fold(0.0f32, f32::max);
        assert!(
            (2.0 * radius - 16.0).abs() <= 1.0,
            "disk diameter {}",
            2.0 * radius
        );
        let expected = reference::disk_pixel_count(16.0);
        assert!(
            (lit.len() as i64 - expected as i64).abs() <= 4,
            "{} lit pixels, disk holds {expected}",
            lit.len()
        );
        // A point in focus stays one pixel.
        cam.focus_distance = 1.0;
        let sharp = render(
            &renderer,
            &cloud(&points),
            SplatSize::Pixels(1.0),
            cam,
            FAST,
        );
        let lit = (0..64 * 64).filter(|&i| sharp.pixels[i][0] > 1e-4).count();
        assert_eq!(lit, 1);
    });
}

#[test]
fn a_sharp_foreground_keeps_its_silhouette_over_a_blurred_background() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let mut cam = camera(48, 48);
        cam.focus_distance = 1.0;
        cam.aperture_radius = 0.05;
        // A red square in focus at z = 1 covering the left half, a white
        // background plane far behind (CoC about 17 px).
        let f_px = cam.f_px();
        let mut points = Vec::new();
        let step = 0.5 / f_px;
        let mut y = -30.0 * step * 2.0;
        while y < 60.0 * step {
            let mut x = -60.0 * step;
            while x < 0.0 {
                points.push((Vec3::new(x, y, -1.0), Vec3::new(1.0, 0.0, 0.0)));
                x += step;
            }
            y += step;
        }
        for j in -120..=120 {
            for i in -120..=120 {
                points.push((Vec3::new(i as f32 * 0.02, j as f32 * 0.02, -4.0), Vec3::ONE));
            }
        }
        let img = render(
            &renderer,
            &cloud(&points),
            SplatSize::World(0.03),
            cam,
            FAST,
        );
        for y in 4..44 {
            // Inside the silhouette, near its edge (column 24 plus the
            // splats' 1 px overhang): pure red, no bleeding of the blurred
            // white background.
            let inside = img.get(20, y);
            assert!(inside[0] > 0.99 && inside[1] < 1e-3, "row {y}: {inside:?}");
            // Just outside: the white background; the sharp red square
            // spreads no light onto it.
            let outside = img.get(28, y);
            assert!(outside[1] > 0.99, "row {y}: {outside:?}");
        }
    });
}

#[test]
fn background_only_tiles_take_the_short_path_with_the_same_bits() {
    // The bunny small in a wide frame on a colored background: the tiles
    // far from it see only background within their gather window, and the
    // gather takes its all-background path there. Tiles (with that path)
    // and the fixed window (without it) must agree bit for bit, and both
    // with the CPU reference.
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let bunny = load_ply(&root().join("data/bunny_colored.ply")).unwrap();
        let scene = renderer.upload(&bunny, SplatSize::Spacing).unwrap();
        let (lo, hi) = bunny.bounds();
        let centre = (lo + hi) / 2.0;
        let cam = Camera {
            width: 128,
            height: 96,
            eye: centre + Vec3::new(0.0, 0.0, 0.6),
            target: centre,
            up: Vec3::Y,
            fovy_deg: 40.0,
            aperture_radius: 0.004,
            focus_distance: 0.6,
        };
        // A colored background takes the short loop; a black one skips it.
        for (weights, background) in [
            (FastWeights::Area, Vec3::new(0.2, 0.45, 0.7)),
            (FastWeights::Uniform, Vec3::new(0.2, 0.45, 0.7)),
            (FastWeights::Area, Vec3::ZERO),
        ] {
            let options = |window| RenderOptions {
                background,
                ..options(cam, Method::fast(weights, window))
            };
            let (tiles, gbuffer) = renderer
                .render_with_gbuffer(&scene, &options(GatherWindow::Tiles))
                .unwrap();
            let fixed = renderer
                .render(&scene, &options(GatherWindow::Fixed))
                .unwrap();
            let differ = tiles
                .image
                .pixels
                .iter()
                .zip(&fixed.image.pixels)
                .filter(|(a, b)| a.map(f32::to_bits) != b.map(f32::to_bits))
                .count();
            assert_eq!(
                differ, 0,
                "{weights:?}: {differ} pixels differ between the paths"
            );
            let cpu = reference::fast(&gbuffer, &cam, weights);
            let worst = tiles
                .image
                .pixels
                .iter()
                .zip(&cpu.pixels)
                .flat_map(|(a, b)| (0..4).map(move |c| (a[c] - b[c]).abs() / b[c].abs().max(0.05)))
                .fold(0.0f32, f32::max);
            assert!(worst < 2e-3, "{weights:?}: GPU and CPU differ by {worst}");
            // Tiles (16 px) whose square 16 px apron holds no point: the
            // gather window is at most the largest CoC / 2 < 16 px, so these
            // took the all-background path.
            let max_coc = gbuffer
                .eye
                .iter()
                .map(|e| cam.coc_px(e[2]))
                .fold(0.0f32, f32::max);
            assert!(max_coc / 2.0 < 16.0, "largest CoC {max_coc}");
            let (w, h) = (gbuffer.width as i64, gbuffer.height as i64);
            let point = |x: i64, y: i64| {
                (0..w).contains(&x)
                    && (0..h).contains(&y)
                    && gbuffer.eye[(y * w + x) as usize][2].is_finite()
            };
            let empty_tiles = (0..(h + 15) / 16)
                .flat_map(|ty| (0..(w + 15) / 16).map(move |tx| (tx, ty)))
                .filter(|&(tx, ty)| {
                    !(ty * 16 - 16..ty * 16 + 32)
                        .any(|y| (tx * 16 - 16..tx * 16 + 32).any(|x| point(x, y)))
                })
                .count();
            assert!(empty_tiles >= 8, "only {empty_tiles} background-only tiles");
            assert!(
                gbuffer.eye.iter().filter(|e| e[2].is_finite()).count() > 500,
                "the bunny must be in view"
            );
        }
    });
}
