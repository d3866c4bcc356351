//! `--splat-shape disc` (issue 29, item 4): a splat is the disc inscribed
//! in its square, drawn alike by the compute rasteriser and the sprites
//! (upscaled and multisampled plans, the depth peel included), anti-
//! aliased through the G-buffer's samples.

mod common;

use common::{assert_compute_as_close, camera, cloud, options, root, with_gpu};
use glam::Vec3;
use pointlens::image_io::LinearImage;
use pointlens::metrics::psnr;
use pointlens::options::{Method, Raster, SplatShape};
use pointlens::render::{RenderOptions, Renderer, SplatSize};

/// The covered fraction (alpha) summed over the image.
fn coverage(image: &LinearImage) -> f32 {
    image.pixels.iter().map(|p| p[3]).sum()
}

#[test]
fn a_disc_covers_a_quarter_pi_of_its_square() {
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        // One point, 40 px wide.
        let one = cloud(&[(Vec3::new(0.0, 0.0, -2.0), Vec3::ONE)]);
        let scene = renderer.upload(&one, SplatSize::Pixels(40.0)).unwrap();
        let render = |r: &Renderer, per_pass: Option<u32>| {
            let opts = RenderOptions {
                ssaa: 4,
                samples_per_pass: per_pass,
                ..options(camera(96, 72), Method::Pinhole)
            };
            r.render(&scene, &opts).unwrap().image
        };
        renderer.set_raster(Raster::Compute);
        let square = coverage(&render(&renderer, None));
        assert!((square - 1600.0).abs() < 1.0, "square {square}");
        renderer.set_splat_shape(SplatShape::Disc).unwrap();
        for (raster, per_pass) in [
            (Raster::Compute, None),
            (Raster::Sprites, None),
            (Raster::Sprites, Some(4)),
        ] {
            renderer.set_raster(raster);
            let disc = coverage(&render(&renderer, per_pass));
            let want = std::f32::consts::FRAC_PI_4 * 1600.0;
            // 16 samples a pixel: the disc's area to about a sample per
            // pixel of its rim (125 px long).
            assert!(
                (disc - want).abs() < 8.0,
                "{raster:?} {per_pass:?}: {disc} against {want}"
            );
        }
    });
}

#[test]
fn compute_and_sprite_discs_agree_on_the_bunny_with_every_method() {
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        renderer.set_splat_shape(SplatShape::Disc).unwrap();
        let bunny =
            pointlens::input::ply::load_ply(&root().join("data/bunny_colored.ply")).unwrap();
        let (lo, hi) = bunny.bounds();
        let spec = pointlens::camera::CameraSpec {
            width: Some(96),
            height: Some(72),
            ..Default::default()
        };
        let cam = pointlens::camera::resolve(&spec, lo, hi, &bunny.positions).unwrap();
        let scene = renderer.upload(&bunny, SplatSize::Spacing).unwrap();
        let mut square = Renderer::new(ctx).unwrap();
        square.set_raster(Raster::Compute);
        let square_scene = square.upload(&bunny, SplatSize::Spacing).unwrap();
        for method in [
            Method::Pinhole,
            Method::layered(2),
            Method::rdb(5, pointlens::options::RdbMode::Centre),
        ] {
            let opts = RenderOptions {
                ssaa: 4,
                ..options(cam, method)
            };
            renderer.set_raster(Raster::Compute);
            let compute = renderer.render(&scene, &opts).unwrap().image;
            renderer.set_raster(Raster::Sprites);
            let sprites = renderer.render(&scene, &opts).unwrap().image;
            let converged = RenderOptions { ssaa: 16, ..opts };
            let converged = renderer.render(&scene, &converged).unwrap().image;
            // The two take other samples (the compute rasteriser's
            // rotated grid, the sprites' grid of cell centres:
            // tests/compute_raster.rs): against the sprites at K = 16, the
            // compute discs as close as the sprites' or closer, within
            // `SAME_DB`, and within 30 dB (measured: compute 39.3–44.1 dB,
            // sprites 39.0–44.0 dB; a disc's rim is not axis-aligned, so
            // the rotated grid gains less than on a square's edges). At
            // K = 8 the sprites' reference favoured its own grid: `rdb`'s
            // compute image was 0.3 dB farther from it than the sprites',
            // and 0.5 dB nearer than theirs to K = 16 of either raster.
            let what = format!("{method:?}");
            let cc = assert_compute_as_close(&what, "K = 16", &converged, &sprites, &compute);
            assert!(cc >= 30.0, "{what}: from K = 16 compute {cc:.2} dB");
            let squares = square.render(&square_scene, &opts).unwrap().image;
            let apart = psnr(&compute, &squares).unwrap();
            assert!(
                apart < 45.0,
                "{method:?}: discs and squares alike ({apart:.2} dB)"
            );
        }
        drop(square_scene);
    });
}
