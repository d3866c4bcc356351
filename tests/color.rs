//! `--color` (issue 29, item 5): each mode on a small LAS whose values are
//! known, and the modes a file cannot give refused in one line.

mod common;

use common::{pointlens, root, scratch};
use glam::Vec3;
use las::point::{Classification, Format};
use las::{Builder, Point, Transform, Vector, Version, Writer};
use pointlens::color::{apply, class_srgb8, return_srgb8, viridis, ColorMode, VIRIDIS_SRGB8};
use pointlens::image_io::srgb_to_linear;
use pointlens::input::{linear_from_code, load_cloud};

/// (z, intensity, class, return number, returns of the pulse).
const POINTS: [(f64, u16, u8, u8, u8); 5] = [
    (0.0, 100, 2, 1, 1),
    (1.0, 300, 5, 1, 3),
    (2.0, 200, 6, 2, 3),
    (3.0, 500, 9, 3, 3),
    (4.0, 400, 18, 2, 2),
];

fn write_small_las(path: &std::path::Path) {
    let mut builder = Builder::from(Version::new(1, 2));
    builder.point_format = Format::new(1).unwrap();
    let axis = Transform {
        scale: 0.01,
        offset: 0.0,
    };
    builder.transforms = Vector {
        x: axis,
        y: axis,
        z: axis,
    };
    let mut writer = Writer::from_path(path, builder.into_header().unwrap()).unwrap();
    for (i, &(z, intensity, class, number, count)) in POINTS.iter().enumerate() {
        writer
            .write_point(Point {
                x: i as f64,
                y: 0.0,
                z,
                intensity,
                classification: Classification::new(class).unwrap(),
                return_number: number,
                number_of_returns: count,
                gps_time: Some(0.0),
                ..Point::default()
            })
            .unwrap();
    }
    writer.close().unwrap();
}

fn linear(srgb8: [u8; 3]) -> Vec3 {
    Vec3::from_array(srgb8.map(|v| srgb_to_linear(f32::from(v) / 255.0)))
}

#[test]
fn each_color_mode_shows_its_attribute() {
    let dir = scratch("color-modes");
    let path = dir.join("small.las");
    write_small_las(&path);
    let load = || load_cloud(&path, None, &mut |_, _| {}).unwrap();

    // No RGB in point format 1: intensity is the default, as grey.
    let cloud = load();
    assert!(!cloud.has_rgb);
    let mut intensity = load();
    apply(&mut intensity, ColorMode::Intensity).unwrap();
    assert_eq!(intensity.colors, cloud.colors, "intensity is the default");
    for (c, p) in intensity.colors.iter().zip(POINTS) {
        assert_eq!(
            *c,
            Vec3::splat(linear_from_code(f64::from(p.1 - 100), 400.0))
        );
    }

    // Elevation: z from 0 to 4 over viridis (its first and last stops at
    // the ends, brighter upwards).
    let mut elevation = load();
    apply(&mut elevation, ColorMode::Elevation).unwrap();
    assert!(
        (elevation.colors[0] - linear(VIRIDIS_SRGB8[0]))
            .abs()
            .max_element()
            < 1e-6
    );
    assert!(
        (elevation.colors[4] - linear(VIRIDIS_SRGB8[8]))
            .abs()
            .max_element()
            < 1e-6
    );
    assert!((elevation.colors[2] - viridis(0.5)).abs().max_element() < 1e-6);
    let luma = |c: Vec3| c.dot(Vec3::new(0.2126, 0.7152, 0.0722));
    assert!(elevation.colors.windows(2).all(|w| luma(w[1]) > luma(w[0])));

    let mut classes = load();
    apply(&mut classes, ColorMode::Classification).unwrap();
    for (c, p) in classes.colors.iter().zip(POINTS) {
        assert_eq!(*c, linear(class_srgb8(p.2)), "class {}", p.2);
    }
    assert_ne!(class_srgb8(2), class_srgb8(6));

    let mut returns = load();
    apply(&mut returns, ColorMode::Return).unwrap();
    let expected = [
        [0xF0, 0xF0, 0xF0], // single
        [0x3C, 0xC8, 0x50], // first of 3
        [0x32, 0x64, 0xE6], // second of 3
        [0xE6, 0x3C, 0x32], // last of 3
        [0xE6, 0x3C, 0x32], // last of 2
    ];
    for (i, (c, e)) in returns.colors.iter().zip(expected).enumerate() {
        assert_eq!(*c, linear(e), "point {i}");
        assert_eq!(
            return_srgb8(pointlens::color::pack_return(POINTS[i].3, POINTS[i].4)),
            e
        );
    }

    // What the file cannot give.
    let err = apply(&mut load(), ColorMode::Rgb).unwrap_err().to_string();
    assert!(err.contains("no RGB"), "{err}");
}

#[test]
fn the_command_line_refuses_a_mode_the_file_lacks() {
    let dir = scratch("color-cli");
    let out = dir.join("x.png");
    common::assert_fails(
        &[
            "render",
            &root().join("data/bunny_colored.ply").display().to_string(),
            "-o",
            &out.display().to_string(),
            "--color",
            "intensity",
            "--width",
            "16",
            "--height",
            "12",
        ],
        "has no intensities",
        &out,
    );
    let las = dir.join("small.las");
    write_small_las(&las);
    for mode in ["intensity", "elevation", "classification", "return"] {
        let o = pointlens(&[
            "render",
            &las.display().to_string(),
            "-o",
            &out.display().to_string(),
            "--color",
            mode,
            "--width",
            "16",
            "--height",
            "12",
        ]);
        assert!(
            o.status.success(),
            "{mode}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
}
