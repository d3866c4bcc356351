//! The output pass (issue 12): the frame's pixels converted on the device —
//! 8-bit sRGB for PNG, linear f32 for EXR — equal the host's conversion of
//! the same frame, on the bundled scenes, for every method, under
//! validation.

mod common;

use std::collections::HashSet;

use common::{root, scratch, with_gpu};
use glam::Vec3;
use pointlens::bench::BenchModel;
use pointlens::image_io::{f16_to_f32, linear_to_srgb8, read_image, write_png_rgba, Srgb8Image};
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

/// The bunny's frame of 83×61 by `method` over a bright background.
fn bunny_options(cloud: &pointlens::cloud::PointCloud, method: Method) -> RenderOptions {
    RenderOptions {
        camera: BenchModel::Bunny.camera(cloud, 83, 61).unwrap(),
        method,
        ssaa: 2,
        samples_per_pass: None,
        background: Vec3::new(0.9, 0.35, 0.02),
        lod: pointlens::options::Lod::default(),
    }
}

/// A frame in both formats: the bits of its floats and its sRGB bytes.
fn both_formats(
    renderer: &Renderer,
    scene: &pointlens::render::Scene,
    options: &RenderOptions,
) -> (Vec<u32>, Srgb8Image) {
    let linear = renderer.render(scene, options).unwrap().image;
    (
        common::image_bits(&linear),
        renderer.render_srgb8(scene, options).unwrap().image,
    )
}

/// The two renders of a frame in both formats are the same bytes, and not
/// a frame of the background alone.
fn assert_same_frames(a: &(Vec<u32>, Srgb8Image), b: &(Vec<u32>, Srgb8Image), what: &str) {
    assert_eq!(a.0, b.0, "{what}: linear");
    assert_eq!(a.1, b.1, "{what}: sRGB");
    assert!(a.1.rgb.chunks(3).any(|p| p != &a.1.rgb[..3]), "{what}");
}

/// The output pass writing a device-local buffer that a copy moves to the
/// host (the path of a discrete GPU) gives the bytes of the direct path
/// (lavapipe's), for both formats, a frame in bands of tiles included.
#[test]
fn staged_output_equals_the_direct_output() {
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        let cloud = BenchModel::Bunny.load(&root().join("data"), 0).unwrap();
        let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        for (method, tile_px) in [
            (Method::Pinhole, None),
            (Method::rdb(9, RdbMode::Centre), None),
            (Method::accum(3), Some(40)),
        ] {
            let options = bunny_options(&cloud, method);
            renderer.set_tile_px(tile_px);
            // Between the two, frames over another background go through
            // the pooled host buffers: a staged frame whose copy did not
            // land would read those, not the direct frame's bytes.
            let poison = RenderOptions {
                background: Vec3::new(0.1, 0.8, 0.5),
                ..options
            };
            renderer.set_staged_output(Some(false));
            let direct = both_formats(&renderer, &scene, &options);
            both_formats(&renderer, &scene, &poison);
            renderer.set_staged_output(Some(true));
            let staged = both_formats(&renderer, &scene, &options);
            assert_same_frames(&direct, &staged, &format!("{method:?}, tiles {tile_px:?}"));
        }
    });
}

/// The pipelines made without code a frame does not run write the general
/// pipelines' bytes, in both formats: the output's without the veil's
/// (`VEIL_CODE`) and the G-buffer resolves' of a pass that holds every
/// sample (`WHOLE_PASS`: the compute raster's, by area and by samples, the
/// sprites' upscaled plan), for a pinhole and a layered frame.
#[test]
fn the_specialized_pipelines_write_the_general_ones_bytes() {
    use pointlens::options::{Coverage, LayeredOptions, Raster};
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        let cloud = BenchModel::Bunny.load(&root().join("data"), 0).unwrap();
        let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        for (raster, coverage) in [
            (Raster::Compute, Coverage::Area),
            (Raster::Compute, Coverage::Samples),
            (Raster::Sprites, Coverage::Samples),
        ] {
            renderer.set_raster(raster);
            renderer.set_coverage(Some(coverage));
            for method in [Method::Pinhole, Method::Layered(LayeredOptions::default())] {
                let options = bunny_options(&cloud, method);
                renderer.set_specialized_pipelines(true);
                let specialized = both_formats(&renderer, &scene, &options);
                renderer.set_specialized_pipelines(false);
                let general = both_formats(&renderer, &scene, &options);
                let what = format!("{raster:?} {coverage:?} {method:?}");
                assert_same_frames(&specialized, &general, &what);
            }
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

/// The nearest half float to `v` (round to nearest, ties to even), as
/// bits: the rounding of the output pass's `packHalf2x16`.
fn f32_to_f16_bits(v: f32) -> u16 {
    let bits = v.to_bits();
    let sign = ((bits >> 16) & 0x8000) as u16;
    let magnitude = f32::from_bits(bits & 0x7fff_ffff);
    if magnitude.is_nan() {
        return sign | 0x7e00;
    }
    // The halves of this sign are in increasing order of their bits.
    let (mut lo, mut hi) = (0u16, 0x7c00u16);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if f16_to_f32(mid) < magnitude {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    // lo: the least half ≥ magnitude; its predecessor may be nearer.
    if lo > 0 {
        let (below, above) = (f16_to_f32(lo - 1), f16_to_f32(lo));
        let (d_below, d_above) = (magnitude - below, above - magnitude);
        // Past the largest finite half by half an ulp or more: infinity.
        if d_below < d_above || (d_below == d_above && (lo - 1) % 2 == 0) {
            return sign | (lo - 1);
        }
    }
    sign | lo
}

/// The splats a frame drew as a veil, from its `--timings` report (0 when
/// the report has no veil line).
fn veiled_splats(stderr: &str) -> u64 {
    stderr
        .lines()
        .find_map(|l| l.strip_prefix("splats too near the lens, drawn as a veil: "))
        .map_or(0, |n| n.trim().parse().expect("a count"))
}

/// Issue 47, defect 1: the PNG of a frame with a veil is the EXR of the
/// same frame converted to 8 bits, for every method, opaque and
/// transparent, on both rasters. The output pass veiled 4 pixels per
/// invocation for the PNG and ran out of llvmpipe's loop iterations on a
/// veil of some thousand splats: every fourth pixel black, or three in
/// four.
///
/// Opaque, the PNG's code of each channel must be exactly the code of the
/// EXR's float rounded to the nearest half float, as the output pass
/// encodes (its table holds a code per half); the EXR's float itself is
/// the veil's mean in f32, so its direct 8-bit code may differ from that
/// by one where the rounding to a half crosses a code's edge, and that is
/// the only difference allowed (0 codes after the half rounding, at most 1
/// before it). Transparent, both files come from the same floats and the
/// PNG's bytes must be exactly `write_png_rgba`'s of the EXR's pixels.
#[test]
fn a_veiled_frames_png_is_its_exr_in_8_bits_for_every_method() {
    let dir = scratch("veiled_png_exr");
    // The bunny seen from inside (issue 47's camera): 34 k of its splats
    // in front of the focus plane blur past what a G-buffer holds and
    // become the veil of fast, rdb and layered. `accum` veils only splats
    // nearer than its near plane (a millionth of the farthest depth):
    // 9 specks 1e-7 in front of the lens.
    let cloud = BenchModel::Bunny.load(&root().join("data"), 0).unwrap();
    let (eye, forward) = (Vec3::new(-0.02, 0.1, 0.07), Vec3::new(0.0, 0.0, -1.0));
    let mut points: Vec<([f32; 3], [u8; 3])> = cloud
        .positions
        .iter()
        .zip(&cloud.colors)
        .map(|(p, c)| (p.to_array(), c.to_array().map(linear_to_srgb8)))
        .collect();
    for i in -1..=1 {
        for j in -1..=1 {
            let p = eye + 1e-7 * forward + 3e-8 * Vec3::new(i as f32, j as f32, 0.0);
            points.push((p.to_array(), [250, 40, 40]));
        }
    }
    let ply = dir.join("bunny_specks.ply");
    common::write_ascii_ply(&ply, &points);
    let ply = ply.display().to_string();
    let methods: [&[&str]; 6] = [
        &["--method", "pinhole"],
        &["--method", "fast"],
        &["--method", "fast", "--fast-gather", "tree"],
        &["--method", "rdb"],
        &["--method", "layered"],
        &["--method", "accum", "--samples", "16"],
    ];
    // Every disagreement, so that a failure shows all the frames it hit.
    let mut failures = Vec::new();
    for (m, method) in methods.iter().enumerate() {
        for transparent in [false, true] {
            // Each method on both rasters, one per background.
            let raster = match (m + transparent as usize) % 2 {
                0 => "compute",
                _ => "sprites",
            };
            let what = format!("{method:?} --raster {raster} transparent {transparent}");
            let mut veiled = Vec::new();
            let mut paths = Vec::new();
            for ext in ["png", "exr"] {
                let out = dir.join(format!("f.{ext}"));
                let out = out.display().to_string();
                // An odd size: the PNG's bytes pack 4 pixels per 3 words
                // across rows, and the last group is partial.
                let mut args = vec![
                    "render",
                    &ply,
                    "-o",
                    &out,
                    "--width",
                    "61",
                    "--height",
                    "37",
                    "--eye",
                    "-0.02,0.1,0.07",
                    "--target",
                    "-0.02,0.1,-0.3",
                    "--focus-distance",
                    "0.35",
                    "--aperture-radius",
                    "0.1",
                    "--raster",
                    raster,
                    "--timings",
                ];
                args.extend_from_slice(method);
                if transparent {
                    args.extend_from_slice(&["--background", "transparent"]);
                }
                let o = common::assert_runs(&args);
                veiled.push(veiled_splats(&String::from_utf8_lossy(&o.stderr)));
                paths.push(out);
            }
            assert_eq!(veiled[0], veiled[1], "{what}");
            // Not vacuous: the frame has its veil (pinhole has none).
            let least = match method[1] {
                "pinhole" => 0,
                "accum" => 9,
                _ => 30_000,
            };
            assert!(veiled[0] >= least, "{what}: {} veiled", veiled[0]);
            if least == 0 {
                assert_eq!(veiled[0], 0, "{what}");
            }
            let exr = read_image(std::path::Path::new(&paths[1])).unwrap();
            let png = image::open(&paths[0]).unwrap();
            assert_eq!((png.width(), png.height()), (61, 37), "{what}");
            if transparent {
                // The PNG is RGBA; the EXR's pixels through the same
                // host encoding give its bytes.
                let again = dir.join("again.png");
                write_png_rgba(&exr, &again).unwrap();
                let expected = image::open(&again).unwrap().into_rgba8().into_raw();
                let got = png.into_rgba8().into_raw();
                let wrong = got.iter().zip(&expected).filter(|(a, b)| a != b).count();
                if wrong > 0 {
                    failures.push(format!("{what}: {wrong} bytes differ"));
                }
                assert!(got.chunks(4).any(|p| p[3] > 0 && p[3] < 255), "{what}");
            } else {
                let got = png.into_rgb8().into_raw();
                let codes = |f: &dyn Fn(f32) -> u8| -> Vec<u8> {
                    exr.pixels
                        .iter()
                        .flat_map(|p| [p[0], p[1], p[2]].map(f))
                        .collect()
                };
                let halved = codes(&|v| linear_to_srgb8(f16_to_f32(f32_to_f16_bits(v))));
                let direct = codes(&linear_to_srgb8);
                let wrong = got.iter().zip(&halved).filter(|(a, b)| a != b).count();
                let black = got.chunks(3).filter(|p| p == &[0, 0, 0]).count();
                if wrong > 0 {
                    failures.push(format!(
                        "{what}: {wrong} codes differ, {black} black pixels"
                    ));
                }
                let worst = got
                    .iter()
                    .zip(&direct)
                    .map(|(&a, &b)| a.abs_diff(b))
                    .max()
                    .unwrap();
                if worst > 1 {
                    failures.push(format!("{what}: {worst} codes from the EXR's"));
                }
                let distinct: HashSet<u8> = got.iter().copied().collect();
                assert!(distinct.len() > 20, "{what}: {} codes", distinct.len());
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
