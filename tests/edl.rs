//! Eye-dome lighting (`--edl`, issue 29 item 5): it darkens depth
//! discontinuities, leaves a surface facing the camera unchanged (bit for
//! bit), changes nothing at strength 0, and runs before every blurring
//! method under validation.

mod common;

use common::{camera, cloud, options, with_gpu};
use glam::Vec3;
use pointlens::image_io::LinearImage;
use pointlens::options::{EdlOptions, FastWeights, GatherWindow, Method, RdbMode};
use pointlens::render::{Renderer, SplatSize};

/// A grey wall at z = −2 filling the view, and before it a square patch at
/// z = −1 covering the middle third (both facing the camera, points every
/// 4 mm).
fn wall_and_patch() -> pointlens::PointCloud {
    let mut points = Vec::new();
    for i in -300..=300 {
        for j in -250..=250 {
            points.push((
                Vec3::new(i as f32 * 0.004, j as f32 * 0.004, -2.0),
                Vec3::splat(0.5),
            ));
        }
    }
    for i in -60..=60 {
        for j in -60..=60 {
            points.push((
                Vec3::new(i as f32 * 0.002, j as f32 * 0.002, -1.0),
                Vec3::splat(0.8),
            ));
        }
    }
    cloud(&points)
}

fn luma(image: &LinearImage, x: u32, y: u32) -> f32 {
    let p = image.pixels[(y * image.width + x) as usize];
    p[0] + p[1] + p[2]
}

#[test]
fn edl_darkens_edges_and_leaves_a_facing_surface_alone() {
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        let scene = renderer
            .upload(&wall_and_patch(), SplatSize::Spacing)
            .unwrap();
        let cam = camera(96, 72);
        let render =
            |r: &Renderer, method: Method| r.render(&scene, &options(cam, method)).unwrap().image;
        let plain = render(&renderer, Method::Pinhole);
        renderer.set_edl(Some(EdlOptions {
            strength: 0.0,
            radius_px: 1.4,
        }));
        assert_eq!(
            render(&renderer, Method::Pinhole).pixels,
            plain.pixels,
            "strength 0"
        );
        renderer.set_edl(Some(EdlOptions {
            strength: 1.0,
            radius_px: 2.0,
        }));
        let shaded = render(&renderer, Method::Pinhole);
        // The patch spans about x 39–57 at y 36; the wall beside its left
        // edge (x 36–38) is darker, the wall's far interior (x 5) and the
        // patch's middle (x 48) are unchanged.
        let mut edge = 0;
        for y in 30..42 {
            for x in 30..66 {
                let (a, b) = (luma(&plain, x, y), luma(&shaded, x, y));
                assert!(b <= a, "({x}, {y}) brighter: {a} -> {b}");
                edge += (b < 0.9 * a) as u32;
            }
        }
        assert!(edge >= 20, "only {edge} edge pixels darkened by 10 %");
        for (x, y) in [(5, 5), (5, 36), (90, 60), (48, 36)] {
            assert_eq!(
                plain.pixels[(y * 96 + x) as usize],
                shaded.pixels[(y * 96 + x) as usize],
                "({x}, {y})"
            );
        }
        // Before each blurring method, under validation.
        let lens = pointlens::camera::Camera {
            aperture_radius: 0.02,
            focus_distance: 1.0,
            ..cam
        };
        for method in [
            Method::paper_fast(FastWeights::Area, GatherWindow::Tiles),
            Method::rdb(5, RdbMode::Centre),
            Method::layered(2),
        ] {
            let with = renderer
                .render(&scene, &options(lens, method))
                .unwrap()
                .image;
            assert!(with.pixels.iter().flatten().all(|v| v.is_finite()));
        }
        assert!(renderer
            .render(&scene, &options(lens, Method::accum(4)))
            .is_err());
    });
}
