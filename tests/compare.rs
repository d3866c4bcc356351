//! Image metrics and `pointlens compare`.

mod common;

use std::process::Command;

use common::scratch;
use pointlens::image_io::srgb_to_linear;
use pointlens::image_io::{write_image, LinearImage};
use pointlens::metrics::{max_abs_error, psnr, ssim};

/// A w×h image whose sRGB-encoded R, G, B are all `srgb`.
fn flat(w: u32, h: u32, srgb: f32) -> LinearImage {
    let v = srgb_to_linear(srgb);
    LinearImage::new(w, h, [v, v, v, 1.0])
}

#[test]
fn identical_images_give_infinite_psnr_and_ssim_one() {
    let mut img = flat(16, 12, 0.3);
    img.set(3, 4, [0.9, 0.1, 0.5, 1.0]);
    assert_eq!(psnr(&img, &img).unwrap(), f64::INFINITY);
    assert!((ssim(&img, &img).unwrap() - 1.0).abs() < 1e-12);
    assert_eq!(max_abs_error(&img, &img).unwrap(), 0.0);
}

#[test]
fn hand_computed_cases() {
    // One channel of one pixel of an 8×8 image off by 0.5 (sRGB):
    // MSE = 0.25 / (64 · 3); PSNR = 10 log10(768) = 28.8536 dB.
    let a = flat(8, 8, 0.0);
    let mut b = a.clone();
    b.set(2, 5, [srgb_to_linear(0.5), 0.0, 0.0, 1.0]);
    assert!((psnr(&a, &b).unwrap() - 28.8536).abs() < 1e-3);
    assert!((max_abs_error(&a, &b).unwrap() - 0.5).abs() < 1e-6);
    // Two flat images of luma 0.5 and 0.25: no variance, so
    // SSIM = (2·0.5·0.25 + C1) / (0.5² + 0.25² + C1), C1 = 1e-4
    //      = 0.2501 / 0.3126 = 0.800064.
    let ssim_flat = ssim(&flat(20, 20, 0.5), &flat(20, 20, 0.25)).unwrap();
    assert!((ssim_flat - 0.800064).abs() < 1e-5, "{ssim_flat}");
    // Inverting a pattern's contrast drives SSIM negative.
    let mut p = flat(16, 16, 0.2);
    let mut q = flat(16, 16, 0.8);
    for y in 0..16 {
        for x in (y % 2..16).step_by(2) {
            p.set(x, y, [srgb_to_linear(0.8); 4]);
            q.set(x, y, [srgb_to_linear(0.2); 4]);
        }
    }
    assert!(ssim(&p, &q).unwrap() < 0.0);
    // Sizes must match.
    assert!(psnr(&flat(4, 4, 0.0), &flat(4, 5, 0.0)).is_err());
}

#[test]
fn compare_command_prints_name_value_lines_and_a_difference_image() {
    let dir = scratch("compare");
    let (a, b, d) = (dir.join("a.png"), dir.join("b.exr"), dir.join("d.png"));
    write_image(&flat(8, 8, 0.0), &a).unwrap();
    let mut img = flat(8, 8, 0.0);
    img.set(2, 5, [srgb_to_linear(0.5), 0.0, 0.0, 1.0]);
    write_image(&img, &b).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_pointlens"))
        .args([
            "compare",
            a.to_str().unwrap(),
            b.to_str().unwrap(),
            "--diff",
            d.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let value = |name: &str| -> f64 {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("{name}: ")))
            .unwrap_or_else(|| panic!("no {name} in {text}"));
        line[name.len() + 2..].parse().unwrap()
    };
    assert!((value("psnr") - 28.8536).abs() < 1e-3, "{text}");
    assert!(value("ssim") < 1.0);
    assert!((value("max_abs_error") - 0.5).abs() < 1e-6);
    let heat = pointlens::image_io::read_image(&d).unwrap();
    assert_eq!(
        heat.get(2, 5),
        [1.0, 1.0, 1.0, 1.0],
        "the largest difference is white"
    );
    assert_eq!(heat.get(0, 0)[..3], [0.0, 0.0, 0.0]);

    let same = Command::new(env!("CARGO_BIN_EXE_pointlens"))
        .args(["compare", a.to_str().unwrap(), a.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8(same.stdout).unwrap(),
        "psnr: inf\nssim: 1.000000\nmax_abs_error: 0.000000\n"
    );

    let small = dir.join("small.png");
    write_image(&flat(4, 4, 0.0), &small).unwrap();
    let bad = Command::new(env!("CARGO_BIN_EXE_pointlens"))
        .args(["compare", a.to_str().unwrap(), small.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let err = String::from_utf8(bad.stderr).unwrap();
    assert!(
        err.contains("sizes differ") && err.lines().count() == 1,
        "{err}"
    );
}

/// A transparent frame's PNG (straight color and alpha) and EXR
/// (premultiplied) compare as one image: `compare` premultiplies the PNG.
/// They differ only by the PNG's 8-bit codes (measured 60.2 dB; asserted
/// above 45); compared straight against premultiplied they would be
/// 15.2 dB apart here.
#[test]
fn compare_reads_a_transparent_png_as_its_exr() {
    let dir = scratch("compare-alpha");
    let (png, exr) = (dir.join("t.png"), dir.join("t.exr"));
    let mut img = LinearImage::new(16, 8, [0.0; 4]);
    for y in 0..8 {
        for x in 0..16 {
            let a = (x + 1) as f32 / 16.0;
            let v = 0.6 * a * (y + 1) as f32 / 8.0;
            img.set(x, y, [v, 0.5 * v, 0.25 * v, a]);
        }
    }
    pointlens::image_io::write_png_rgba(&img, &png).unwrap();
    write_image(&img, &exr).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_pointlens"))
        .args(["compare", png.to_str().unwrap(), exr.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let psnr: f64 = text.lines().next().unwrap()["psnr: ".len()..]
        .parse()
        .unwrap();
    assert!(psnr > 45.0, "{text}");
    let straight = pointlens::image_io::read_image(&png).unwrap();
    let premultiplied = pointlens::image_io::read_image_premultiplied(&png).unwrap();
    let apart = pointlens::metrics::psnr(&straight, &premultiplied).unwrap();
    eprintln!("compare {psnr:.2} dB; straight against premultiplied {apart:.2} dB");
    assert!(apart < 25.0, "straight against premultiplied: {apart} dB");
}
