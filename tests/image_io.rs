//! Tests of `image_io`: sRGB and half-float conversions, PNG/EXR round trips,
//! the exact bytes of written PNGs, and the atomic, all-or-nothing writes.

use std::fs;
use std::path::Path;

use pointlens::image_io::{
    f16_to_f32, linear_to_srgb, linear_to_srgb8, read_image, srgb8_to_linear_lut, srgb_to_linear,
    write_image, LinearImage,
};
use pointlens::Error;

mod common;
use common::{file_names, scratch};

/// A small image with varied, in-range linear values and alpha.
fn gradient(width: u32, height: u32) -> LinearImage {
    let mut img = LinearImage::new(width, height, [0.0; 4]);
    for y in 0..height {
        for x in 0..width {
            let u = x as f32 / (width - 1) as f32;
            let v = y as f32 / (height - 1) as f32;
            img.set(x, y, [u, v, u * v, 0.25 + 0.5 * u]);
        }
    }
    img
}

/// Decodes a PNG without any color conversion: (color type, raw 8-bit RGB).
fn raw_png(path: &Path) -> (image::ColorType, Vec<u8>) {
    let img = image::open(path).expect("decode PNG");
    (img.color(), img.to_rgb8().into_raw())
}

#[test]
fn linear_image_accessors() {
    let mut img = LinearImage::new(3, 2, [0.1, 0.2, 0.3, 1.0]);
    assert_eq!(img.pixels.len(), 6);
    assert_eq!(img.get(2, 1), [0.1, 0.2, 0.3, 1.0]);
    img.set(2, 1, [1.0, 0.0, 0.0, 0.5]);
    assert_eq!(img.get(2, 1), [1.0, 0.0, 0.0, 0.5]);
    // Row-major, top row first.
    assert_eq!(img.pixels[5], [1.0, 0.0, 0.0, 0.5]);
}

#[test]
#[should_panic(expected = "outside")]
fn linear_image_get_out_of_range_panics() {
    LinearImage::new(3, 2, [0.0; 4]).get(3, 0);
}

#[test]
fn srgb_transfer_functions() {
    assert_eq!(linear_to_srgb(0.0), 0.0);
    assert_eq!(linear_to_srgb(1.0), 1.0);
    assert_eq!(linear_to_srgb(-0.5), 0.0);
    assert_eq!(linear_to_srgb(7.0), 1.0);
    assert_eq!(linear_to_srgb(f32::NAN), 0.0);
    assert_eq!(linear_to_srgb(f32::INFINITY), 1.0);
    assert_eq!(linear_to_srgb(f32::NEG_INFINITY), 0.0);
    // Linear segment.
    assert!((linear_to_srgb(0.001) - 0.012_92).abs() < 1e-7);
    // 1.055 · 0.5^(1/2.4) − 0.055 = 0.735356983…
    assert!((linear_to_srgb(0.5) - 0.735_357).abs() < 1e-6);
    // ((0.5 + 0.055) / 1.055)^2.4 = 0.214041140…
    assert!((srgb_to_linear(0.5) - 0.214_041_14).abs() < 1e-6);
    assert!((srgb_to_linear(0.04) - 0.04 / 12.92).abs() < 1e-9);
    // The two pieces meet: both functions are continuous at the knee.
    let knee = 0.003_130_8_f32;
    assert!((linear_to_srgb(knee) - linear_to_srgb(knee + 1e-7)).abs() < 1e-5);
    assert!((srgb_to_linear(0.040_45) - srgb_to_linear(0.040_46)).abs() < 1e-5);
    // Inverse of each other on [0, 1].
    for i in 0..=1000 {
        let c = i as f32 / 1000.0;
        assert!((srgb_to_linear(linear_to_srgb(c)) - c).abs() < 1e-5, "{c}");
        assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-5, "{c}");
    }
}

#[test]
fn srgb8_encoding_and_lut() {
    // Hand-computed: floor(255 · srgb(c) + 0.5).
    let cases = [
        (0.0, 0),
        (1.0, 255),
        (0.5, 188),    // srgb 0.735357 → 188.016
        (0.2140, 127), // srgb 0.499956 → 127.989: just below the 127/128 boundary at 0.2140411
        (0.2159, 128), // srgb 0.502003 → 128.511
        (0.18, 118),   // srgb 0.461356 → 118.146
        (0.001, 3),    // srgb 0.01292  → 3.795
        (0.25, 137),   // srgb 0.537099 → 137.460
        (0.9, 243),    // srgb 0.954687 → 243.945
        (2.0, 255),
        (-1.0, 0),
        (f32::NAN, 0),
    ];
    for (c, expected) in cases {
        assert_eq!(linear_to_srgb8(c), expected, "linear {c}");
    }
    // The LUT decodes every code, and encoding a decoded code gives it back.
    let lut = srgb8_to_linear_lut();
    assert_eq!(lut[0], 0.0);
    assert_eq!(lut[255], 1.0);
    for v in 0..=255u8 {
        assert_eq!(lut[v as usize], srgb_to_linear(v as f32 / 255.0));
        assert_eq!(linear_to_srgb8(lut[v as usize]), v);
    }
}

/// A reference half decode written differently from the library's bit
/// shuffling: the textbook formula in f64 with `powi`.
fn f16_reference(bits: u16) -> f64 {
    let sign = if bits & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exponent = i32::from((bits >> 10) & 0x1f);
    let fraction = f64::from(bits & 0x3ff) / 1024.0;
    match exponent {
        0 => sign * 2f64.powi(-14) * fraction,
        31 if fraction == 0.0 => sign * f64::INFINITY,
        31 => f64::NAN,
        e => sign * 2f64.powi(e - 15) * (1.0 + fraction),
    }
}

#[test]
fn f16_to_f32_matches_reference_for_all_65536_values() {
    for bits in 0..=u16::MAX {
        let got = f16_to_f32(bits);
        let want = f16_reference(bits);
        let negative = bits & 0x8000 != 0;
        assert_eq!(got.is_sign_negative(), negative, "sign of {bits:#06x}");
        if want.is_nan() {
            assert!(got.is_nan(), "{bits:#06x} → {got}, want NaN");
            // The payload survives in the top mantissa bits.
            assert_eq!(
                (got.to_bits() >> 13) & 0x3ff,
                u32::from(bits & 0x3ff),
                "{bits:#06x}"
            );
        } else {
            // Every half is exactly representable in f32, so the comparison is
            // exact (signed zeros included, via the sign check above).
            assert_eq!(f64::from(got), want, "{bits:#06x}");
        }
    }
    // Spot checks.
    assert_eq!(f16_to_f32(0x3c00), 1.0);
    assert_eq!(f16_to_f32(0xc000), -2.0);
    assert_eq!(f16_to_f32(0x7bff), 65504.0);
    assert_eq!(f16_to_f32(0x0001), 2f32.powi(-24));
    assert_eq!(f16_to_f32(0x03ff), 1023.0 * 2f32.powi(-24));
    assert_eq!(f16_to_f32(0x0400), 2f32.powi(-14));
    assert_eq!(f16_to_f32(0x3555), 0.333_251_95);
    assert_eq!(f16_to_f32(0x7c00), f32::INFINITY);
    assert_eq!(f16_to_f32(0xfc00), f32::NEG_INFINITY);
    assert_eq!(f16_to_f32(0x8000).to_bits(), (-0.0f32).to_bits());
}

#[test]
fn png_round_trip_within_one_8_bit_step() {
    let dir = scratch("png-round-trip");
    let path = dir.join("out.png");
    let img = gradient(17, 9);
    write_image(&img, &path).unwrap();
    let back = read_image(&path).unwrap();
    assert_eq!((back.width, back.height), (17, 9));
    for (p, q) in img.pixels.iter().zip(&back.pixels) {
        for c in 0..3 {
            let step = (linear_to_srgb(p[c]) - linear_to_srgb(q[c])).abs() * 255.0;
            assert!(step <= 0.5 + 1e-3, "{p:?} → {q:?}");
        }
        // Alpha is dropped: the PNG is opaque.
        assert_eq!(q[3], 1.0);
    }
    assert_eq!(file_names(&dir), ["out.png"]);
}

#[test]
fn exr_round_trip_is_exact() {
    let dir = scratch("exr-round-trip");
    let path = dir.join("out.exr");
    let mut img = gradient(13, 7);
    // Values a PNG could not hold: above 1, negative, tiny, huge.
    img.set(0, 0, [4.5, -0.25, 1e-30, 0.0]);
    img.set(12, 6, [65504.0, 1e20, 0.1, 2.0]);
    write_image(&img, &path).unwrap();
    let back = read_image(&path).unwrap();
    assert_eq!(back, img);
    assert_eq!(file_names(&dir), ["out.exr"]);
}

#[test]
fn extension_is_case_insensitive() {
    let dir = scratch("extension-case");
    let img = gradient(4, 3);
    write_image(&img, &dir.join("a.PNG")).unwrap();
    write_image(&img, &dir.join("b.Exr")).unwrap();
    assert_eq!(raw_png(&dir.join("a.PNG")).0, image::ColorType::Rgb8);
    assert_eq!(read_image(&dir.join("b.Exr")).unwrap(), img);
}

#[test]
fn written_png_holds_the_expected_srgb_bytes() {
    let dir = scratch("png-bytes");
    let path = dir.join("bytes.png");
    let mut img = LinearImage::new(4, 2, [0.0; 4]);
    // Row 0.
    img.set(0, 0, [0.0, 1.0, 0.5, 0.3]);
    img.set(1, 0, [0.2140, 0.2159, 0.18, 0.0]);
    img.set(2, 0, [0.001, 0.25, 0.9, 1.0]);
    img.set(3, 0, [2.0, -1.0, f32::NAN, 1.0]);
    // Row 1: grey ramp.
    img.set(0, 1, [0.0031308; 4]);
    img.set(1, 1, [0.01; 4]);
    img.set(2, 1, [0.1; 4]);
    img.set(3, 1, [0.75; 4]);
    write_image(&img, &path).unwrap();

    let (color, raw) = raw_png(&path);
    assert_eq!(color, image::ColorType::Rgb8, "8-bit RGB, no alpha");
    #[rustfmt::skip]
    let expected: [u8; 24] = [
        0, 255, 188,     127, 128, 118,    3, 137, 243,      255, 0, 0,
        10, 10, 10,      25, 25, 25,       89, 89, 89,       225, 225, 225,
    ];
    assert_eq!(raw, expected);
}

#[test]
fn reads_16_bit_gray_and_alpha_pngs() {
    let dir = scratch("png-variants");

    let gray = dir.join("gray8.png");
    image::GrayImage::from_raw(2, 1, vec![0, 128])
        .unwrap()
        .save(&gray)
        .unwrap();
    let img = read_image(&gray).unwrap();
    assert_eq!(img.pixels[0], [0.0, 0.0, 0.0, 1.0]);
    let v = srgb_to_linear(128.0 / 255.0);
    assert_eq!(img.pixels[1], [v, v, v, 1.0]);

    let rgba = dir.join("rgba8.png");
    image::RgbaImage::from_raw(1, 1, vec![255, 188, 0, 51])
        .unwrap()
        .save(&rgba)
        .unwrap();
    let img = read_image(&rgba).unwrap();
    let p = img.pixels[0];
    assert_eq!(p[0], 1.0);
    assert_eq!(p[1], srgb_to_linear(188.0 / 255.0));
    assert_eq!(p[2], 0.0);
    assert!(
        (p[3] - 0.2).abs() < 1e-6,
        "alpha is not sRGB-decoded: {p:?}"
    );

    let rgb16 = dir.join("rgb16.png");
    let buf: image::ImageBuffer<image::Rgb<u16>, Vec<u16>> =
        image::ImageBuffer::from_raw(1, 1, vec![65535, 32768, 0]).unwrap();
    buf.save(&rgb16).unwrap();
    let img = read_image(&rgb16).unwrap();
    let p = img.pixels[0];
    assert_eq!(p[0], 1.0);
    assert!(
        (p[1] - srgb_to_linear(32768.0 / 65535.0)).abs() < 1e-6,
        "{p:?}"
    );
    assert_eq!(p[2], 0.0);
    assert_eq!(p[3], 1.0);
}

#[test]
fn unsupported_extension_errors_and_writes_nothing() {
    let dir = scratch("bad-extension");
    let img = gradient(4, 3);
    for name in ["out.jpg", "out.xyz", "out", "out.png.bak"] {
        let path = dir.join(name);
        let err = write_image(&img, &path).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, Error::InvalidArgument(_)), "{err:?}");
        assert!(msg.contains(&path.display().to_string()), "{msg}");
        assert!(msg.contains("unsupported output format"), "{msg}");
        assert!(msg.contains("use .png or .exr"), "{msg}");
        assert!(!msg.contains('\n'), "{msg}");
    }
    let msg = write_image(&img, &dir.join("out.xyz"))
        .unwrap_err()
        .to_string();
    assert!(
        msg.ends_with("unsupported output format '.xyz' (use .png or .exr)"),
        "{msg}"
    );
    assert!(file_names(&dir).is_empty(), "{:?}", file_names(&dir));
}

#[test]
fn wrong_pixel_count_errors_and_writes_nothing() {
    let dir = scratch("pixel-count");
    let mut img = gradient(4, 3);
    img.pixels.pop();
    let err = write_image(&img, &dir.join("out.png")).unwrap_err();
    assert!(matches!(err, Error::InvalidArgument(_)), "{err:?}");
    assert!(file_names(&dir).is_empty());
}

#[test]
fn missing_directory_errors_naming_the_path_and_leaves_nothing() {
    let dir = scratch("missing-dir");
    let path = dir.join("no/such/dir/out.png");
    let err = write_image(&gradient(4, 3), &path).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    assert!(msg.starts_with(&path.display().to_string()), "{msg}");
    assert!(!msg.contains('\n'), "{msg}");
    assert!(file_names(&dir).is_empty(), "{:?}", file_names(&dir));
}

#[test]
fn overwriting_replaces_the_target_and_leaves_no_temporary() {
    let dir = scratch("overwrite");
    let path = dir.join("out.png");
    fs::write(&path, b"old").unwrap();
    let img = LinearImage::new(2, 2, [0.5, 0.5, 0.5, 1.0]);
    write_image(&img, &path).unwrap();
    assert_eq!(raw_png(&path).1, [188; 12]);
    assert_eq!(file_names(&dir), ["out.png"]);
}

#[test]
fn failed_encode_keeps_the_old_target_and_leaves_no_temporary() {
    let dir = scratch("failed-encode");
    for name in ["out.png", "out.exr"] {
        let path = dir.join(name);
        fs::write(&path, b"old content").unwrap();
        // A 0×0 image has no valid PNG or EXR encoding.
        let err = write_image(&LinearImage::new(0, 0, [0.0; 4]), &path).unwrap_err();
        assert!(matches!(err, Error::Image { .. }), "{err:?}");
        assert!(
            err.to_string().starts_with(&path.display().to_string()),
            "{err}"
        );
        assert!(err.to_string().contains("cannot encode"), "{err}");
        assert_eq!(fs::read(&path).unwrap(), b"old content");
    }
    assert_eq!(file_names(&dir), ["out.exr", "out.png"]);

    // A missing target stays missing.
    let path = dir.join("new.png");
    write_image(&LinearImage::new(0, 3, [0.0; 4]), &path).unwrap_err();
    assert_eq!(file_names(&dir), ["out.exr", "out.png"]);
}

#[test]
fn failed_rename_keeps_the_target_and_leaves_no_temporary() {
    let dir = scratch("failed-rename");
    // The target is a directory: the encode succeeds, the rename cannot.
    let path = dir.join("out.png");
    fs::create_dir(&path).unwrap();
    fs::write(path.join("keep.txt"), b"keep").unwrap();
    let err = write_image(&gradient(4, 3), &path).unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    assert!(
        err.to_string().starts_with(&path.display().to_string()),
        "{err}"
    );
    assert!(path.is_dir());
    assert_eq!(fs::read(path.join("keep.txt")).unwrap(), b"keep");
    assert_eq!(file_names(&dir), ["out.png"]);
}

#[test]
fn read_errors_name_the_path() {
    let dir = scratch("read-errors");

    let missing = dir.join("missing.png");
    let err = read_image(&missing).unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    assert!(
        err.to_string().starts_with(&missing.display().to_string()),
        "{err}"
    );

    for (name, content) in [
        ("garbage.png", &b"this is not an image"[..]),
        ("truncated.png", &b"\x89PNG\r\n\x1a\n\0\0"[..]),
        ("garbage.exr", &b"v/1\x01 not really"[..]),
        ("notes.txt", &b"hello"[..]),
    ] {
        let path = dir.join(name);
        fs::write(&path, content).unwrap();
        let err = read_image(&path).unwrap_err();
        let msg = err.to_string();
        assert!(msg.starts_with(&path.display().to_string()), "{msg}");
        assert!(!msg.contains('\n'), "{msg}");
    }
}
