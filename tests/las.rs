//! LAS, LAZ and COPC input: every point data record format against its PLY
//! equivalent, 8-bit-in-16-bit and true 16-bit RGB, intensity as grey, the
//! double-precision re-centring (a cloud at 5,000,000 m easting renders as
//! the same cloud near the origin), camera files in file coordinates, and
//! bad files answered with one line.

mod common;

use std::path::Path;

use common::{assert_fails, pointlens, root, scratch, with_gpu};
use glam::{DVec3, Vec3};
use las::point::{Classification, Format};
use las::{Builder, Color, Point, Transform, Vector, Version, Writer};
use pointlens::camera::{self, CameraSpec, Coordinates};
use pointlens::input::las::load_las;
use pointlens::input::ply::load_ply;
use pointlens::input::{linear_from_code, load_cloud};
use pointlens::options::{FastOptions, Method};
use pointlens::render::{Renderer, SplatSize};
use pointlens::PointCloud;

/// One point as written: its integer codes and attributes.
#[derive(Debug, Clone)]
struct Rec {
    code: [i32; 3],
    intensity: u16,
    class: u8,
    rgb: [u16; 3],
}

/// A small deterministic generator (SplitMix64).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// Classes a legacy format can hold (12, overlap, is a flag there).
const CLASSES: [u8; 8] = [1, 2, 3, 4, 5, 6, 7, 9];

/// `n` points with codes in a 2000-wide cube, classes from [`CLASSES`],
/// intensities in `0..=int_max` and color channels in `0..=rgb_max`, each
/// range's ends included (the loaders normalise by the actual range).
fn records(n: usize, seed: u64, int_max: u16, rgb_max: u16) -> Vec<Rec> {
    let mut rng = Rng(seed);
    (0..n)
        .map(|i| {
            let mut code = [0; 3];
            for c in &mut code {
                *c = rng.below(2000) as i32 - 1000;
            }
            let ends = |max: u16, rng: &mut Rng| match i {
                0 => 0,
                1 => max,
                _ => rng.below(u64::from(max) + 1) as u16,
            };
            Rec {
                code,
                intensity: ends(int_max, &mut rng),
                class: CLASSES[i % CLASSES.len()],
                rgb: [
                    ends(rgb_max, &mut rng),
                    ends(rgb_max, &mut rng),
                    ends(rgb_max, &mut rng),
                ],
            }
        })
        .collect()
}

/// The version that introduced a point format.
fn version_for(format: u8) -> Version {
    match format {
        0..=3 => Version::new(1, 2),
        4 | 5 => Version::new(1, 3),
        _ => Version::new(1, 4),
    }
}

/// Writes `recs` as LAS (or LAZ, by the extension) in point `format` with
/// one `scale` and `offset` on every axis, through the `las` crate.
fn write_las(path: &Path, format: u8, recs: &[Rec], scale: f64, offset: DVec3) {
    let mut builder = Builder::from(version_for(format));
    builder.point_format = Format::new(format).unwrap();
    builder.transforms = Vector {
        x: Transform {
            scale,
            offset: offset.x,
        },
        y: Transform {
            scale,
            offset: offset.y,
        },
        z: Transform {
            scale,
            offset: offset.z,
        },
    };
    let header = builder.into_header().unwrap();
    let fmt = *header.point_format();
    let mut writer = Writer::from_path(path, header).unwrap();
    for (i, r) in recs.iter().enumerate() {
        let coord = |k: usize| f64::from(r.code[k]) * scale + offset[k];
        writer
            .write_point(Point {
                x: coord(0),
                y: coord(1),
                z: coord(2),
                intensity: r.intensity,
                classification: Classification::new(r.class).unwrap(),
                return_number: 1,
                number_of_returns: 1,
                gps_time: fmt.has_gps_time.then_some(i as f64 * 0.5),
                color: fmt.has_color.then_some(Color {
                    red: r.rgb[0],
                    green: r.rgb[1],
                    blue: r.rgb[2],
                }),
                nir: fmt.has_nir.then_some(7),
                waveform: fmt.has_waveform.then(Default::default),
                ..Point::default()
            })
            .unwrap();
    }
    writer.close().unwrap();
}

/// How the PLY equivalent stores colors.
#[derive(Debug, Clone, Copy)]
enum PlyColor {
    /// uchar red green blue from the RGB.
    Rgb8,
    /// ushort red green blue from the RGB.
    Rgb16,
    /// uchar grey from the intensity (which must span 0..=255).
    Grey8,
}

/// Writes the PLY equivalent of `recs`: binary, double coordinates
/// `code·scale` (offset 0), colors as `color` says.
fn write_ply(path: &Path, recs: &[Rec], scale: f64, color: PlyColor) {
    let (ty, size) = match color {
        PlyColor::Rgb8 | PlyColor::Grey8 => ("uchar", 1),
        PlyColor::Rgb16 => ("ushort", 2),
    };
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty double x\n\
         property double y\nproperty double z\nproperty {ty} red\nproperty {ty} green\n\
         property {ty} blue\nend_header\n",
        recs.len()
    )
    .into_bytes();
    for r in recs {
        for k in 0..3 {
            bytes.extend((f64::from(r.code[k]) * scale).to_le_bytes());
        }
        let rgb = match color {
            PlyColor::Grey8 => [r.intensity; 3],
            _ => r.rgb,
        };
        for c in rgb {
            bytes.extend(&c.to_le_bytes()[..size]);
        }
    }
    std::fs::write(path, bytes).unwrap();
}

fn load(path: &Path, origin: Option<DVec3>) -> PointCloud {
    load_cloud(path, origin, &mut |_, _| {}).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Positions and colors bit for bit, and has_colors.
fn assert_same_points(a: &PointCloud, b: &PointCloud, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: count");
    assert_eq!(a.has_colors, b.has_colors, "{what}: has_colors");
    for i in 0..a.len() {
        assert_eq!(
            a.positions[i].to_array().map(f32::to_bits),
            b.positions[i].to_array().map(f32::to_bits),
            "{what}: position {i}"
        );
        assert_eq!(
            a.colors[i].to_array().map(f32::to_bits),
            b.colors[i].to_array().map(f32::to_bits),
            "{what}: color {i}"
        );
    }
}

#[test]
fn every_point_format_as_las_and_laz_equals_its_ply_equivalent() {
    let dir = scratch("las-formats");
    let scale = 0.01;
    for format in 0..=10u8 {
        let fmt = Format::new(format).unwrap();
        // RGB formats twice: 8-bit values in the 16-bit fields, and true
        // 16-bit values; the others' intensity (0..=255) becomes grey.
        let variants: &[(u16, u16, PlyColor)] = if fmt.has_color {
            &[(4000, 255, PlyColor::Rgb8), (4000, 65535, PlyColor::Rgb16)]
        } else {
            &[(255, 0, PlyColor::Grey8)]
        };
        for &(int_max, rgb_max, ply_color) in variants {
            let recs = records(
                1500,
                u64::from(format) * 7 + u64::from(rgb_max),
                int_max,
                rgb_max,
            );
            let ply = dir.path().join(format!("f{format}-{rgb_max}.ply"));
            write_ply(&ply, &recs, scale, ply_color);
            let expected = load_ply(&ply).unwrap();
            for ext in ["las", "laz"] {
                let path = dir.path().join(format!("f{format}-{rgb_max}.{ext}"));
                write_las(&path, format, &recs, scale, DVec3::ZERO);
                let what = format!("format {format} {ext} {ply_color:?}");
                // Origin 0: the file's coordinates as they are, as the PLY's.
                let cloud = load(&path, Some(DVec3::ZERO));
                assert_same_points(&cloud, &expected, &what);
                assert!(cloud.has_colors, "{what}");
                let classes: Vec<u8> = recs.iter().map(|r| r.class).collect();
                assert_eq!(cloud.classifications.as_ref(), Some(&classes), "{what}");
                let info: Vec<&str> = cloud.file_info.iter().map(|(k, _)| k.as_str()).collect();
                assert!(info.contains(&"point_format"), "{what}: {info:?}");
                let format_line = &cloud.file_info[0].1;
                assert_eq!(
                    format_line,
                    if ext == "laz" { "LAZ" } else { "LAS" },
                    "{what}"
                );
            }
        }
    }
}

#[test]
fn intensity_is_grey_over_the_files_actual_range() {
    let dir = scratch("las-intensity");
    // Intensities 1000..=5000 (not 0..=65535): 1000 is black, 5000 white.
    let mut recs = records(500, 3, 4000, 0);
    for r in &mut recs {
        r.intensity += 1000;
    }
    for (format, note) in [(1u8, "no rgb"), (3, "rgb all zero")] {
        let path = dir.path().join(format!("i{format}.las"));
        write_las(&path, format, &recs, 0.01, DVec3::ZERO);
        let cloud = load(&path, None);
        assert!(cloud.has_colors, "{note}");
        for (c, r) in cloud.colors.iter().zip(&recs) {
            let grey = linear_from_code(f64::from(r.intensity - 1000), 4000.0);
            assert_eq!(*c, Vec3::splat(grey), "{note}");
        }
        assert_eq!(cloud.colors[0], Vec3::ZERO, "{note}: the minimum is black");
        assert_eq!(cloud.colors[1], Vec3::ONE, "{note}: the maximum is white");
    }
    // A constant intensity and no RGB: the default color, no colors.
    for r in &mut recs {
        r.intensity = 42;
    }
    let path = dir.path().join("flat.las");
    write_las(&path, 0, &recs, 0.01, DVec3::ZERO);
    let cloud = load(&path, None);
    assert!(!cloud.has_colors);
    assert!(cloud
        .colors
        .iter()
        .all(|&c| c == pointlens::input::DEFAULT_COLOR));
}

#[test]
fn rgb_is_8_bit_only_when_every_channel_fits_8_bits() {
    let dir = scratch("las-rgb-depth");
    let mut recs = records(300, 5, 100, 255);
    let path = dir.path().join("rgb8.las");
    write_las(&path, 2, &recs, 0.01, DVec3::ZERO);
    let c8 = load(&path, None);
    // One channel of one point at 256: the whole file is 16-bit.
    recs[7].rgb[2] = 256;
    let path = dir.path().join("rgb16.las");
    write_las(&path, 2, &recs, 0.01, DVec3::ZERO);
    let c16 = load(&path, None);
    for (i, r) in recs.iter().enumerate().skip(8) {
        let want8 = r.rgb.map(|v| linear_from_code(f64::from(v), 255.0));
        let want16 = r.rgb.map(|v| linear_from_code(f64::from(v), 65535.0));
        assert_eq!(c8.colors[i].to_array(), want8, "point {i}");
        assert_eq!(c16.colors[i].to_array(), want16, "point {i}");
    }
    // 255 of 255 is white; 255 of 65535 is nearly black.
    assert_eq!(c8.colors[1], Vec3::ONE);
    assert!(c16.colors[1].max_element() < 1e-3);
}

#[test]
fn far_coordinates_are_recentred_in_double_precision() {
    let dir = scratch("las-recentre");
    let recs = records(800, 11, 255, 255);
    let scale = 0.001;
    // The same codes at the origin and at 5,000,000 m easting (and
    // 4,000,000 m northing, 1,000 m up).
    let near = dir.path().join("near.laz");
    let far = dir.path().join("far.laz");
    write_las(&near, 3, &recs, scale, DVec3::ZERO);
    write_las(&far, 3, &recs, scale, DVec3::new(5e6, 4e6, 1e3));
    let (a, b) = (load(&near, None), load(&far, None));
    assert_same_points(&a, &b, "far vs near, default origins");
    assert_eq!(b.origin - a.origin, DVec3::new(5e6, 4e6, 1e3));
    // Every point's file coordinate is origin + position to within f32's
    // rounding of the re-centred value.
    for (p, r) in b.positions.iter().zip(&recs) {
        let file =
            DVec3::from_array(r.code.map(|c| f64::from(c) * scale)) + DVec3::new(5e6, 4e6, 1e3);
        let err = (b.origin + p.as_dvec3() - file).abs().max_element();
        assert!(err < 1e-7, "{err}");
    }
    // Without re-centring (origin 0) the millimetres are gone: f32 at 5e6 m
    // steps by 0.5 m, so the 2 m wide cloud keeps at most a few x values.
    let raw = load(&far, Some(DVec3::ZERO));
    let mut xs: Vec<u32> = raw.positions.iter().map(|p| p.x.to_bits()).collect();
    xs.sort_unstable();
    xs.dedup();
    assert!(xs.len() <= 5, "{} distinct x values", xs.len());
    // A given origin is used as given.
    let given = DVec3::new(5_000_000.25, 4e6, 0.0);
    let c = load(&far, Some(given));
    assert_eq!(c.origin, given);
    let file0 =
        DVec3::from_array(recs[0].code.map(|c| f64::from(c) * scale)) + DVec3::new(5e6, 4e6, 1e3);
    // Within f32's rounding of the re-centred value (z ≈ 1000 here).
    let p0 = c.positions[0];
    let ulp = f64::from(p0.abs().max_element()) * f64::from(f32::EPSILON);
    assert!((given + p0.as_dvec3() - file0).abs().max_element() <= ulp);
}

#[test]
fn a_cloud_at_5000_km_easting_renders_as_the_same_cloud_near_the_origin() {
    // A 6 cm × 4 cm patch of points 1 mm apart, colored in stripes, with a
    // second patch 3 cm behind it so that depth of field has work to do.
    let dir = scratch("las-far-render");
    let mut recs = Vec::new();
    for layer in 0..2 {
        for j in 0..40 {
            for i in 0..60 {
                recs.push(Rec {
                    code: [i + 17 * layer, j, -30 * layer],
                    intensity: 0,
                    class: 2,
                    rgb: [
                        (i * 4) as u16,
                        (j * 6) as u16,
                        if (i / 5) % 2 == 0 { 255 } else { 0 },
                    ],
                });
            }
        }
    }
    let near = dir.path().join("near.las");
    let far = dir.path().join("far.las");
    write_las(&near, 2, &recs, 0.001, DVec3::new(0.0, 0.0, 0.0));
    write_las(&far, 2, &recs, 0.001, DVec3::new(5e6, 0.0, 0.0));
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let image = |path: &Path| {
            let cloud = load(path, None);
            let (lo, hi) = cloud.bounds();
            let spec = CameraSpec {
                width: Some(64),
                height: Some(48),
                eye: Some([0.01, -0.02, 0.12]),
                target: Some([0.0, 0.0, -0.015]),
                focus_distance: Some(0.13),
                aperture_radius: Some(0.004),
                ..CameraSpec::default()
            };
            let cam = camera::resolve(&spec, lo, hi, &cloud.positions).unwrap();
            let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
            let options = common::options(cam, Method::Fast(FastOptions::default()));
            renderer.render(&scene, &options).unwrap().image
        };
        let (a, b) = (image(&near), image(&far));
        let lit = a
            .pixels
            .iter()
            .filter(|p| p[0] + p[1] + p[2] > 0.05)
            .count();
        assert!(lit > a.pixels.len() / 3, "the patch fills the frame: {lit}");
        assert!(
            a.pixels == b.pixels,
            "the far cloud's image differs from the near one's"
        );
    });
}

#[test]
fn camera_files_in_file_coordinates_equal_recentred_ones() {
    let far = root().join("data/autzen_trim.las");
    let cloud = load(&far, None);
    let origin = cloud.origin;
    let (lo, hi) = cloud.bounds();
    let recentred = CameraSpec {
        eye: Some([-300.0, -900.0, 400.0]),
        target: Some([0.0, 0.0, 0.0]),
        up: Some([0.0, 0.0, 1.0]),
        ..CameraSpec::default()
    };
    let cam = camera::resolve(
        &recentred.in_scene(origin).unwrap(),
        lo,
        hi,
        &cloud.positions,
    )
    .unwrap();
    // Printed both ways, read back, the same camera.
    for coordinates in [Coordinates::File, Coordinates::Recentred] {
        let json = cam.to_spec_in(coordinates, origin).to_json();
        let spec = CameraSpec::from_json_str(&json).unwrap();
        let back = camera::resolve(&spec.in_scene(origin).unwrap(), lo, hi, &[]).unwrap();
        assert_eq!(back, cam, "{coordinates:?}: {json}");
    }
    // File coordinates are the origin plus the scene's.
    let file = cam.to_spec_in(Coordinates::File, origin);
    let eye = DVec3::from_array(file.eye.unwrap());
    assert!((eye - origin - DVec3::new(-300.0, -900.0, 400.0)).length() < 1e-9);
    // A recentred camera that records another origin moves by the difference.
    let moved = CameraSpec {
        origin: Some((origin + DVec3::new(10.0, 0.0, 0.0)).to_array()),
        ..recentred.clone()
    };
    let c = moved.in_scene(origin).unwrap();
    assert_eq!(c.eye, Some([-290.0, -900.0, 400.0]));
    // Contradictions and unconverted specs are errors naming the field.
    let both = CameraSpec {
        coordinates: Some(Coordinates::File),
        origin: Some([1.0; 3]),
        ..recentred.clone()
    };
    assert!(both
        .in_scene(origin)
        .unwrap_err()
        .to_string()
        .contains("origin"));
    let file_spec = CameraSpec {
        coordinates: Some(Coordinates::File),
        ..recentred
    };
    assert!(camera::resolve(&file_spec, lo, hi, &[])
        .unwrap_err()
        .to_string()
        .contains("coordinates"));
}

#[test]
fn the_bundled_lidar_tile_loads_with_its_colors_crs_and_classes() {
    let path = root().join("data/autzen_trim.las");
    let mut calls = 0;
    let cloud = load_las(&path, None, &mut |done, total| {
        calls += 1;
        assert!(done <= total && total == 110_000);
    })
    .unwrap();
    assert!(calls >= 1);
    assert_eq!(cloud.len(), 110_000);
    assert!(cloud.has_colors);
    let info = |k: &str| {
        cloud
            .file_info
            .iter()
            .find(|(name, _)| name == k)
            .map(|(_, v)| v.clone())
            .unwrap_or_else(|| panic!("no {k} in {:?}", cloud.file_info))
    };
    assert_eq!(info("las_version"), "1.2");
    assert!(info("point_format").starts_with("3 "));
    assert!(info("crs").contains("NAD_1983_HARN"), "{}", info("crs"));
    assert!(info("color_source").contains("8-bit"));
    // Classes 1 and 2 (unclassified, ground) only.
    let classes = cloud.classifications.as_ref().unwrap();
    assert!(classes.iter().all(|&c| c == 1 || c == 2));
    assert!(classes.contains(&2) && classes.contains(&1));
    // Re-centred on the bounds' centre: the scene is about ±590 × ±281.
    let (lo, hi) = cloud.bounds();
    assert!((lo + hi).abs().max_element() < 0.02, "{lo} {hi}");
}

#[test]
fn info_and_print_camera_on_a_lidar_tile() {
    let path = root().join("data/autzen_trim.las").display().to_string();
    let o = pointlens(&["info", &path]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for line in [
        "format: LAS",
        "las_version: 1.2",
        "point_format: 3 (34 bytes per record)",
        "points: 110000",
        "scale: 0.01 0.01 0.01",
        "offset: 0 0 0",
        "file_bounds_min: 636001.76",
        "file_bounds_max: 637179.22",
        "origin: 636590.49 849216.55 463.38",
        "crs: WKT PROJCS[\"NAD_1983_HARN_Lambert_Conformal_Conic\"",
    ] {
        assert!(out.contains(line), "'{line}' not in:\n{out}");
    }
    let o = pointlens(&["info", &path, "--origin", "636000,849000,400"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("origin: 636000 849000 400"), "{out}");

    // --print-camera in file coordinates, rendered again from that file:
    // the same image.
    let dir = scratch("las-print-camera");
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    let cam = dir.path().join("cam.json");
    let common = ["--width", "48", "--height", "32", "--method", "fast"];
    let mut args = vec!["render", &path, "-o"];
    let a_s = a.display().to_string();
    args.push(&a_s);
    args.extend(common);
    args.extend([
        "--coordinates",
        "file",
        "--eye",
        "636300,848400,900",
        "--target",
        "636590,849216,463",
        "--up",
        "0,0,1",
        "--print-camera",
    ]);
    let o = pointlens(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json = String::from_utf8_lossy(&o.stdout);
    assert!(json.contains("\"coordinates\": \"file\""), "{json}");
    assert!(json.contains("636300"), "{json}");
    std::fs::write(&cam, json.as_bytes()).unwrap();
    let (b_s, cam_s) = (b.display().to_string(), cam.display().to_string());
    let mut args = vec!["render", &path, "-o", &b_s, "--camera", &cam_s];
    args.extend(common);
    let o = pointlens(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

#[test]
fn bad_las_and_laz_files_give_one_line_and_no_output() {
    let dir = scratch("las-bad");
    let out = dir.path().join("out.png");
    let out_s = out.display().to_string();
    let recs = records(2000, 1, 255, 255);
    let las_path = dir.path().join("good.las");
    let laz_path = dir.path().join("good.laz");
    write_las(&las_path, 3, &recs, 0.01, DVec3::ZERO);
    write_las(&laz_path, 3, &recs, 0.01, DVec3::ZERO);
    let las_bytes = std::fs::read(&las_path).unwrap();
    let laz_bytes = std::fs::read(&laz_path).unwrap();
    // Header fields (LAS 1.2): offset to point data at 96 (u32), record
    // length at 105 (u16), legacy point count at 107 (u32).
    let u32_at = |b: &[u8], at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
    let laz_data = u32_at(&laz_bytes, 96) as usize;

    let mut cases: Vec<(String, &str)> = Vec::new();
    let mut case = |name: &str, bytes: Vec<u8>, phrase: &'static str| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        cases.push((p.display().to_string(), phrase));
    };
    case(
        "truncated.las",
        las_bytes[..las_bytes.len() / 2].to_vec(),
        "truncated",
    );
    case("header-only.las", las_bytes[..150].to_vec(), "");
    let mut more = las_bytes.clone();
    more[107..111].copy_from_slice(&3000u32.to_le_bytes());
    case("count-too-large.las", more, "3000 points");
    let mut fewer = las_bytes.clone();
    fewer[107..111].copy_from_slice(&1000u32.to_le_bytes());
    case("count-too-small.las", fewer, "point count or record length");
    let mut short = las_bytes.clone();
    short[105..107].copy_from_slice(&20u16.to_le_bytes());
    case("record-too-short.las", short, "record length");
    let mut long = las_bytes.clone();
    long[105..107].copy_from_slice(&40u16.to_le_bytes());
    case("record-too-long.las", long, "record length");
    case("not-las.las", b"this is not a point cloud\n".to_vec(), "");
    case("empty.laz", Vec::new(), "");
    case(
        "truncated.laz",
        laz_bytes[..laz_bytes.len() * 2 / 3].to_vec(),
        "",
    );
    let mut lying = laz_bytes.clone();
    lying[107..111].copy_from_slice(&5000u32.to_le_bytes());
    case("count-too-large.laz", lying, "");
    // The chunk table's offset (the first 8 bytes of the point data) past
    // the end of the file, and the table itself overwritten.
    let mut table = laz_bytes.clone();
    let far = (laz_bytes.len() as i64 + 1_000_000).to_le_bytes();
    table[laz_data..laz_data + 8].copy_from_slice(&far);
    case("chunk-table-outside.laz", table, "");
    let mut table = laz_bytes.clone();
    let at = i64::from_le_bytes(laz_bytes[laz_data..laz_data + 8].try_into().unwrap()) as usize;
    for b in &mut table[at..] {
        *b = 0xA7;
    }
    case("chunk-table-garbage.laz", table, "");
    let mut data = laz_bytes.clone();
    for b in &mut data[laz_data + 8..laz_data + 400] {
        *b ^= 0x5A;
    }
    case("corrupt-chunk.laz", data, "");

    for (path, phrase) in &cases {
        for cmd in ["render", "info"] {
            let args: Vec<&str> = if cmd == "render" {
                vec![
                    "render", path, "-o", &out_s, "--width", "16", "--height", "12",
                ]
            } else {
                vec!["info", path]
            };
            let name = Path::new(path).file_name().unwrap().to_str().unwrap();
            // Every message names the file.
            assert_fails(&args, name, &out);
            if !phrase.is_empty() {
                assert_fails(&args, phrase, &out);
            }
        }
    }
}

#[test]
fn a_copc_file_reads_as_laz() {
    // tests/data/autzen.copc.laz: 107 points of the Autzen survey as COPC
    // (LAS 1.4, point format 7, 16-bit RGB), from the las crate's tests.
    let path = root().join("tests/data/autzen.copc.laz");
    let cloud = load(&path, None);
    assert_eq!(cloud.len(), 107);
    assert_eq!(cloud.file_info[0], ("format".into(), "COPC (LAZ)".into()));
    assert!(cloud.has_colors);
    let crs = &cloud.file_info.iter().find(|(k, _)| k == "crs").unwrap().1;
    assert!(crs.contains("Oregon GIC Lambert"), "{crs}");
    assert!(cloud.positions.iter().all(|p| p.is_finite()));
    // Every point lies within the file's bounds, re-centred.
    let (lo, hi) = cloud.bounds();
    assert!((lo + hi).abs().max_element() < 0.02);
}

#[test]
fn origin_and_coordinates_flags_are_checked() {
    let dir = scratch("las-flags");
    let out = dir.path().join("out.png");
    let out_s = out.display().to_string();
    let las = root().join("data/autzen_trim.las").display().to_string();
    let ply = root().join("data/bunny_colored.ply").display().to_string();
    for (args, phrase) in [
        (vec!["--origin", "1,2"], "expected X,Y,Z"),
        (vec!["--origin", "1,nan,2"], "not a finite number"),
        (vec!["--origin", "1e300,0,0"], "too far"),
        (vec!["--coordinates", "utm"], "invalid value"),
    ] {
        let mut all = vec!["render", las.as_str(), "-o", &out_s];
        all.extend(args);
        assert_fails(&all, phrase, &out);
    }
    // A PLY cloud moved by --origin: the same image as the camera moved
    // the other way.
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    let (a_s, b_s) = (a.display().to_string(), b.display().to_string());
    let size = ["--width", "40", "--height", "30", "--up", "0,1,0"];
    let mut args = vec!["render", &ply, "-o", &a_s, "--eye", "0,0.1,0.3"];
    args.extend(["--target", "0,0.1,0"]);
    args.extend(size);
    let o = pointlens(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut args = vec!["render", &ply, "-o", &b_s, "--eye", "-1,-2,0.3"];
    args.extend(["--target", "-1,-2,0", "--origin", "1,2.1,0"]);
    args.extend(size);
    let o = pointlens(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (ia, ib) = (
        pointlens::image_io::read_image(&a).unwrap(),
        pointlens::image_io::read_image(&b).unwrap(),
    );
    let psnr = pointlens::metrics::psnr(&ia, &ib).unwrap();
    // Not bitwise: the positions moved by f32 arithmetic; 40 dB allows
    // the rounding, a wrong shift direction leaves an empty frame.
    assert!(psnr > 40.0, "{psnr}");
    assert!(ia.pixels.iter().any(|p| p[0] > 0.1));
}

#[test]
fn a_file_of_no_points_is_an_error_as_an_empty_ply_is() {
    let dir = scratch("las-empty");
    let path = dir.path().join("empty.laz");
    write_las(&path, 3, &[], 0.01, DVec3::new(5e6, 0.0, 0.0));
    let err = load_cloud(&path, None, &mut |_, _| {}).unwrap_err();
    assert!(err.to_string().contains("empty"), "{err}");
    let p = path.display().to_string();
    let out = dir.path().join("out.png");
    let out_s = out.display().to_string();
    assert_fails(&["render", &p, "-o", &out_s], "the cloud is empty", &out);
    assert_fails(&["info", &p], "the cloud is empty", &out);
}

#[test]
fn a_laz_chunk_table_offset_written_at_the_end_is_followed() {
    // LASzip writers that cannot seek back write −1 where the chunk
    // table's offset goes and the offset itself as the file's last 8 bytes.
    let dir = scratch("las-chunk-offset");
    let recs = records(1200, 9, 255, 255);
    let path = dir.path().join("seek.laz");
    write_las(&path, 3, &recs, 0.01, DVec3::ZERO);
    let mut bytes = std::fs::read(&path).unwrap();
    let data = u32::from_le_bytes(bytes[96..100].try_into().unwrap()) as usize;
    let offset: [u8; 8] = bytes[data..data + 8].try_into().unwrap();
    bytes[data..data + 8].copy_from_slice(&(-1i64).to_le_bytes());
    bytes.extend(offset);
    let moved = dir.path().join("moved.laz");
    std::fs::write(&moved, bytes).unwrap();
    assert_same_points(&load(&moved, None), &load(&path, None), "offset at the end");
}
