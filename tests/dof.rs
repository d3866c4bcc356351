//! Properties every depth-of-field method must have, checked for each.

mod common;

use common::{camera, cloud, options, with_gpu};
use glam::Vec3;
use pointlens::options::Lod;
use pointlens::options::Method;
use pointlens::options::{FastWeights, GatherWindow, RdbMode};
use pointlens::render::{Renderer, SplatSize};

const METHODS: [Method; 7] = [
    Method::paper_fast(FastWeights::Area, GatherWindow::Tiles),
    Method::paper_fast(FastWeights::Uniform, GatherWindow::Tiles),
    Method::rdb(9, RdbMode::Centre),
    Method::rdb(9, RdbMode::Pairs),
    Method::layered(1),
    Method::layered(4),
    Method::accum(16),
];

#[test]
fn a_constant_plane_keeps_its_color_at_every_coc() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let color = Vec3::new(0.7, 0.3, 0.1);
        // CoCs 0, 0.4, 1.6, 2.1, 4.9 and 8.2 px (f_px = 41.2).
        // A fronto-parallel plane at z = 2, much wider than the view, points
        // every 10 mm as 12 mm squares (no gaps), 4 m wide: far beyond the view
        // and its largest blur.
        let mut points = Vec::new();
        for j in -200..=200 {
            for i in -200..=200 {
                points.push((Vec3::new(i as f32 * 0.01, j as f32 * 0.01, -2.0), color));
            }
        }
        let scene = renderer
            .upload(&cloud(&points), SplatSize::World(0.012))
            .unwrap();
        for method in METHODS {
            for (focus, radius) in [
                (2.0, 0.05),
                (1.0, 0.01),
                (1.0, 0.04),
                (4.0, 0.1),
                (1.0, 0.12),
                (1.0, 0.2),
            ] {
                let mut cam = camera(40, 30);
                cam.focus_distance = focus;
                cam.aperture_radius = radius;
                let img = renderer
                    .render(&scene, &options(cam, method))
                    .unwrap()
                    .image;
                for (i, px) in img.pixels.iter().enumerate() {
                    let got = Vec3::from_slice(&px[..3]);
                    // fp16 storage: within 2e-3 of the plane's color.
                    assert!(
                        (got - color).abs().max_element() < 2e-3,
                        "{method:?}, S {focus}, R {radius} (CoC {:.1} px): pixel {i} is {got}",
                        cam.coc_px(2.0)
                    );
                }
            }
        }
    });
}

#[test]
fn focus_pixel_focuses_on_the_surface_seen_there() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        // Left half of the view: a plane at z = 1; right half: one at z = 2.5.
        let mut points = Vec::new();
        for j in -100..=100 {
            for i in -100..0 {
                points.push((
                    Vec3::new(i as f32 * 0.005, j as f32 * 0.005, -1.0),
                    Vec3::ONE,
                ));
            }
            for i in 0..=250 {
                points.push((
                    Vec3::new(i as f32 * 0.0125, j as f32 * 0.0125, -2.5),
                    Vec3::ONE,
                ));
            }
        }
        let scene = renderer
            .upload(&cloud(&points), SplatSize::Pixels(3.0))
            .unwrap();
        let cam = camera(40, 30);
        let near = renderer
            .depth_at_pixel(&scene, &cam, 2, Lod::default(), 5, 15)
            .unwrap();
        let far = renderer
            .depth_at_pixel(&scene, &cam, 2, Lod::default(), 35, 15)
            .unwrap();
        assert!((near - 1.0).abs() < 1e-5, "{near}");
        assert!((far - 2.5).abs() < 1e-5, "{far}");
        let outside = renderer
            .depth_at_pixel(&scene, &cam, 2, Lod::default(), 40, 0)
            .unwrap_err()
            .to_string();
        assert!(outside.contains("outside"), "{outside}");
        let lone = renderer
            .upload(
                &cloud(&[(Vec3::new(0.0, 0.0, -1.0), Vec3::ONE)]),
                SplatSize::Pixels(1.0),
            )
            .unwrap();
        let empty = renderer
            .depth_at_pixel(&lone, &cam, 2, Lod::default(), 2, 2)
            .unwrap_err()
            .to_string();
        assert!(empty.contains("background"), "{empty}");
    });
}
