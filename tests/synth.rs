//! The synthetic scene: its generator gives the bench's cloud of before,
//! and `pointlens synth` writes it as a binary PLY that loads back.

mod common;

use common::{assert_fails, file_names, pointlens, scratch};
use glam::Vec3;
use pointlens::bench::synthetic_cloud;
use pointlens::image_io::{linear_to_srgb8, srgb8_to_linear_lut};
use pointlens::input::ply::{load_ply, load_ply_direct};
use pointlens::synth::{self, RECORD_BYTES};

/// The bench's generator as it was before `synth` (one sequential
/// SplitMix64 stream): the reference the new one must match bit for bit.
fn sequential_reference(count: usize) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    };
    let spheres = [
        (Vec3::new(-0.6, -0.3, 0.9), 0.25),
        (Vec3::new(0.5, 0.35, 0.6), 0.3),
        (Vec3::new(0.0, -0.05, 0.35), 0.2),
        (Vec3::new(-0.45, 0.45, 0.15), 0.15),
        (Vec3::new(0.6, -0.5, 1.2), 0.12),
    ];
    let mut positions = Vec::with_capacity(count);
    let mut colors = Vec::with_capacity(count);
    for i in 0..count {
        let p = if i % 10 < 7 {
            let (x, y) = (2.0 * next() - 1.0, 2.0 * next() - 1.0);
            Vec3::new(x, y, 0.08 * (6.0 * x).sin() * (5.0 * y).cos() - 0.3)
        } else {
            let k = i / 10 * 3 + i % 10 - 7;
            let (center, radius) = spheres[k % spheres.len()];
            let z = 2.0 * next() - 1.0;
            let phi = std::f32::consts::TAU * next();
            let r = (1.0 - z * z).sqrt();
            center + radius * Vec3::new(r * phi.cos(), r * phi.sin(), z)
        };
        let cell = |v: f32| (v * 8.0).floor() as i32;
        let even = (cell(p.x) + cell(p.y) + cell(p.z)).rem_euclid(2) == 0;
        let hue = 0.5 + 0.5 * p.x;
        colors.push(if even {
            Vec3::new(0.8 * hue + 0.1, 0.5, 0.9 - 0.8 * hue)
        } else {
            Vec3::splat(0.05)
        });
        positions.push(p);
    }
    (positions, colors)
}

fn bits(v: &[Vec3]) -> Vec<[u32; 3]> {
    v.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
}

#[test]
fn the_generator_gives_the_bench_cloud_of_before_from_any_point_on() {
    let count = 100_003;
    let (positions, colors) = sequential_reference(count);
    let cloud = synthetic_cloud(count);
    assert_eq!(bits(&cloud.positions), bits(&positions));
    assert_eq!(bits(&cloud.colors), bits(&colors));
    assert!(cloud.has_colors && cloud.normals.is_none());
    assert_eq!(cloud.attributes, ["x", "y", "z"]);
    // Any range on its own gives the same points.
    let (p, c): (Vec<Vec3>, Vec<Vec3>) = synth::points(54_321..54_400).unzip();
    assert_eq!(bits(&p), bits(&positions[54_321..54_400]));
    assert_eq!(bits(&c), bits(&colors[54_321..54_400]));
}

#[test]
fn synth_writes_a_ply_that_loads_back_as_the_bench_cloud() {
    let dir = scratch("synth-cli");
    let path = dir.join("s.ply");
    let path_s = path.display().to_string();
    let o = pointlens(&["synth", "--points", "1000", "-o", &path_s]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(file_names(&dir), ["s.ply"], "a temporary file was left");
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(
        bytes.len(),
        synth::ply_header(1000).len() + 1000 * RECORD_BYTES
    );

    let cloud = load_ply_direct(&path).unwrap().expect("read directly");
    let expected = synthetic_cloud(1000);
    assert_eq!(cloud.len(), 1000);
    assert_eq!(bits(&cloud.positions), bits(&expected.positions));
    // Colors: the 8-bit sRGB codes of the linear colors, decoded.
    let lut = srgb8_to_linear_lut();
    let rounded: Vec<Vec3> = expected
        .colors
        .iter()
        .map(|c| Vec3::from_array(c.to_array().map(|v| lut[linear_to_srgb8(v) as usize])))
        .collect();
    assert_eq!(bits(&cloud.colors), bits(&rounded));
    assert!(cloud.has_colors && cloud.normals.is_none());
    assert_eq!(cloud.attributes, ["x", "y", "z", "red", "green", "blue"]);
    // Both colors of the checker occur.
    assert!(cloud.colors.iter().any(|c| c.x != c.y));
    assert!(cloud.colors.iter().any(|c| c.x == c.y));

    // Written a chunk of 7 points at a time: the same bytes.
    let chunked = dir.join("chunked.ply");
    let mut seen = Vec::new();
    synth::write_ply_with_chunk(&chunked, 1000, 7, &mut |done| seen.push(done)).unwrap();
    assert_eq!(std::fs::read(&chunked).unwrap(), bytes);
    assert_eq!(seen.len(), 1000usize.div_ceil(7));
    assert_eq!(seen.last(), Some(&1000));
    assert_eq!(load_ply(&chunked).unwrap().len(), 1000);
}

#[test]
fn synth_with_bad_input_fails_with_one_line_and_no_file() {
    let dir = scratch("synth-bad");
    let file = dir.join("s.ply");
    let file_s = file.display().to_string();
    assert_fails(
        &["synth", "--points", "0", "-o", &file_s],
        "--points must be at least 1",
        &file,
    );
    assert_fails(
        &["synth", "--points", "ten", "-o", &file_s],
        "--points",
        &file,
    );
    let missing = dir.join("no/such/dir/s.ply");
    assert_fails(
        &[
            "synth",
            "--points",
            "10",
            "-o",
            &missing.display().to_string(),
        ],
        "no directory",
        &missing,
    );
    // A directory where the file should go: the rename fails, the
    // directory stays as it was, and no temporary file is left.
    let taken = dir.join("taken.ply");
    std::fs::create_dir(&taken).unwrap();
    let o = pointlens(&[
        "synth",
        "--points",
        "10",
        "-o",
        &taken.display().to_string(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("taken.ply"), "{err}");
    assert!(taken.is_dir());
    assert_eq!(file_names(&dir), ["taken.ply"]);
    // The library refuses an empty cloud too.
    let err = synth::write_ply(&file, 0, &mut |_| {}).unwrap_err();
    assert!(err.to_string().contains("at least 1 point"), "{err}");
    assert!(!file.exists());
}

/// `synth --lights N` writes the bokeh scene: float colours, a quarter of
/// the points brighter than white when read back (the lights), the card
/// within white; refused in one line without a count, with a LAS name, or
/// beside --points.
#[test]
fn synth_lights_writes_the_bokeh_scene() {
    let dir = scratch("synth-lights");
    let file = dir.join("lights.ply");
    let file_s = file.display().to_string();
    common::assert_runs(&["synth", "--lights", "4000", "-o", &file_s]);
    let cloud = load_ply(&file).unwrap();
    assert_eq!(cloud.len(), 4000);
    let bright = cloud
        .colors
        .iter()
        .filter(|c| c.max_element() > 1.0)
        .count();
    assert_eq!(bright, 1000);
    let brightest = cloud
        .colors
        .iter()
        .map(|c| c.max_element())
        .fold(0.0, f32::max);
    assert!((brightest - 50.0).abs() < 0.01, "{brightest}");
    let las = dir.join("lights.las");
    for (args, phrase, out) in [
        (vec!["--lights", "0"], "--lights must be at least 1", &file),
        (vec!["--lights", "10"], "--lights is written as .ply", &las),
        (
            vec!["--lights", "10", "--points", "10"],
            "cannot be used with",
            &file,
        ),
    ] {
        std::fs::remove_file(&file).ok();
        let out_s = out.display().to_string();
        let mut all = vec!["synth"];
        all.extend(args);
        all.extend(["-o", out_s.as_str()]);
        assert_fails(&all, phrase, out);
    }
}
