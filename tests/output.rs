//! The output pass (issue 12): the frame's pixels converted on the device —
//! 8-bit sRGB for PNG, linear f32 for EXR — equal the host's conversion of
//! the same frame, on the bundled scenes, for every method, under
//! validation.

mod common;

use std::collections::HashSet;

use common::{root, scratch, with_gpu};
use glam::Vec3;
use pointlens::bench::BenchModel;
use pointlens::image_io::{f16_to_f32, read_image, Srgb8Image};
use pointlens::options::{FastWeights, GatherWindow, Method, RdbMode};
use pointlens::render::{RenderOptions, Renderer, SplatSize};

/// The bits of every f32 a half float holds.
fn half_values() -> HashSet<u32> {
    (0..=u16::MAX).map(|h| f16_to_f32(h).to_bits()).collect()
}

#[test]
fn device_output_equals_the_host_conversion() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let halves = half_values();
        let mut checked = 0usize;
        for model in [BenchModel::Bunny, BenchModel::Mug] {
            let cloud = model.load(&root().join("data"), 0).unwrap();
            let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
            // An odd width: the sRGB form packs 4 pixels per group across
            // rows, and the last group is partial.
            let camera = model.camera(&cloud, 83, 61).unwrap();
            for method in [
                Method::Pinhole,
                Method::paper_fast(FastWeights::Area, GatherWindow::Tiles),
                Method::rdb(9, RdbMode::Centre),
                Method::accum(4),
            ] {
                let options = RenderOptions {
                    camera,
                    method,
                    ssaa: 2,
                    samples_per_pass: None,
                    // A bright background: codes up to 255 and linear
                    // values near 1.
                    background: Vec3::new(0.9, 0.35, 0.02),
                    lod: pointlens::options::Lod::default(),
                };
                let linear = renderer.render(&scene, &options).unwrap();
                let srgb = renderer.render_srgb8(&scene, &options).unwrap();
                let what = format!("{model:?} {method:?}");
                assert_eq!(srgb.image.rgb.len(), 3 * 83 * 61, "{what}");
                // The frame is deterministic, so the two renders hold the
                // same rgba16f result: the device's sRGB bytes must be the
                // host's encoding of the device's floats.
                assert_eq!(srgb.image, Srgb8Image::of(&linear.image), "{what}");
                // The floats are the rgba16f values, unchanged.
                for p in &linear.image.pixels {
                    for &v in p {
                        assert!(halves.contains(&v.to_bits()), "{what}: {v} is no half");
                    }
                }
                checked += srgb.image.rgb.len();
                let distinct: HashSet<u8> = srgb.image.rgb.iter().copied().collect();
                assert!(distinct.len() > 40, "{what}: {} codes", distinct.len());
            }
        }
        assert!(checked > 100_000);
    });
}

/// The output pass writing a device-local buffer that a copy moves to the
/// host (the path of a discrete GPU) gives the bytes of the direct path
/// (lavapipe's), for both formats, a frame in bands of tiles included.
#[test]
fn staged_output_equals_the_direct_output() {
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        let model = BenchModel::Bunny;
        let cloud = model.load(&root().join("data"), 0).unwrap();
        let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        for (method, tile_px) in [
            (Method::Pinhole, None),
            (Method::rdb(9, RdbMode::Centre), None),
            (Method::accum(3), Some(40)),
        ] {
            let options = RenderOptions {
                camera: model.camera(&cloud, 83, 61).unwrap(),
                method,
                ssaa: 2,
                samples_per_pass: None,
                background: Vec3::new(0.9, 0.35, 0.02),
                lod: pointlens::options::Lod::default(),
            };
            renderer.set_tile_px(tile_px);
            let mut linear = Vec::new();
            let mut srgb = Vec::new();
            // Between the two, frames over another background go through
            // the pooled host buffers: a staged frame whose copy did not
            // land would read those, not the direct frame's bytes.
            let poison = RenderOptions {
                background: Vec3::new(0.1, 0.8, 0.5),
                ..options
            };
            for staged in [false, true] {
                if staged {
                    renderer.set_staged_output(Some(false));
                    renderer.render(&scene, &poison).unwrap();
                    renderer.render_srgb8(&scene, &poison).unwrap();
                }
                renderer.set_staged_output(Some(staged));
                linear.push(renderer.render(&scene, &options).unwrap().image);
                srgb.push(renderer.render_srgb8(&scene, &options).unwrap().image);
            }
            let what = format!("{method:?}, tiles {tile_px:?}");
            let bits = |i: &pointlens::image_io::LinearImage| {
                i.pixels
                    .iter()
                    .flatten()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            };
            assert_eq!(bits(&linear[0]), bits(&linear[1]), "{what}: linear");
            assert_eq!(srgb[0], srgb[1], "{what}: sRGB");
            // Not a frame of the background alone.
            assert!(
                srgb[0]
                    .rgb
                    .chunks(3)
                    .any(|p| p != srgb[0].rgb[..3].to_vec()),
                "{what}"
            );
        }
    });
}

#[test]
fn render_writes_the_device_encoded_png() {
    // The CLI's PNG comes from the device's bytes; its EXR from the floats.
    let dir = scratch("output_png");
    let png = dir.path().join("b.png");
    let exr = dir.path().join("b.exr");
    let bunny = root().join("data/bun_zipper.ply").display().to_string();
    for out in [&png, &exr] {
        let o = common::pointlens(&[
            "render",
            &bunny,
            "-o",
            &out.display().to_string(),
            "--width",
            "64",
            "--height",
            "48",
            "--method",
            "fast",
            "--validate",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let from_png = read_image(&png).unwrap();
    let from_exr = read_image(&exr).unwrap();
    // The PNG's codes are exactly the host encoding of the EXR's floats.
    let expected = Srgb8Image::of(&from_exr);
    let got = Srgb8Image::of(&from_png);
    assert_eq!(got, expected);
}
