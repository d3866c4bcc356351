//! The GPU test harness: every GPU test runs on lavapipe with the Khronos
//! validation layer and synchronization validation on, and ends with the
//! canary: no validation message, no live allocation. A missing driver or
//! layer fails the test with an install hint; nothing is skipped.

#![allow(dead_code)]

pub mod craft;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::{Arc, Mutex, MutexGuard};

use glam::Vec3;
use pointlens::camera::Camera;
use pointlens::image_io::{read_image, write_image, LinearImage};
use pointlens::metrics;
use pointlens::options::Method;
use pointlens::render::RenderOptions;
use pointlens::vk::{Context, ContextOptions};
use pointlens::PointCloud;

/// Held by every test that makes a Vulkan context, so that a test process
/// holds one test's contexts at a time. The validation layer of Debian 12
/// (1.3.239) finds its state for every call in a map of the process's
/// instances and devices that it changes, without a lock, as one is made
/// or destroyed; past two entries the map is a hash table, which a call on
/// another thread can read mid-change. A test of tests/accum.rs running
/// beside others crashed so, in a lookup of that table under
/// vkCmdBeginDebugUtilsLabelEXT (once in about 200 runs, with a core). One
/// process of `pointlens` holds one context, of one instance and one
/// device: the map's two entries that need no table.
pub fn gpu_lock() -> MutexGuard<'static, ()> {
    static GPU: Mutex<()> = Mutex::new(());
    // A test that failed holding it leaves nothing for the next to mend.
    GPU.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Runs `test` with a validated lavapipe context, then checks the canary,
/// one such test at a time in the process ([`gpu_lock`]).
/// `POINTLENS_TEST_DEVICE` names another device (as `--device` does) for
/// checks on a lent GPU; the suite and CI run on lavapipe.
pub fn with_gpu<R>(test: impl FnOnce(&Arc<Context>) -> R) -> R {
    let _one_at_a_time = gpu_lock();
    let device = std::env::var("POINTLENS_TEST_DEVICE")
        .ok()
        .filter(|d| !d.is_empty())
        .unwrap_or_else(|| "llvmpipe".into());
    let ctx = match Context::new(&ContextOptions {
        validation: true,
        device: Some(device),
    }) {
        Ok(ctx) => ctx,
        Err(e) => panic!(
            "GPU tests need lavapipe and the validation layer: {e}\n\
             install: sudo apt-get install mesa-vulkan-drivers vulkan-validationlayers libvulkan1"
        ),
    };
    assert!(ctx.validation_enabled());
    let log = ctx.message_log();
    let result = test(&ctx);
    let live = ctx.live_allocations();
    assert!(live.is_empty(), "allocations left alive: {live:?}");
    assert_eq!(
        Arc::strong_count(&ctx),
        1,
        "a GPU resource outlived the test"
    );
    drop(ctx);
    let messages = log.messages();
    assert!(
        messages.is_empty(),
        "validation reported {} message(s):\n{}",
        messages.len(),
        messages
            .iter()
            .map(|m| m.to_string())
            .collect::<Vec<_>>()
            .join("\n")
    );
    result
}

/// The project's root directory.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A fresh scratch directory for one test, removed when the value is
/// dropped at the end of the test; kept (and its path printed) when the
/// test panics, so that its files can be looked at.
pub struct Scratch(PathBuf);

impl Scratch {
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("scratch files kept in {}", self.0.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// The names in `dir`, sorted.
pub fn file_names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// A fresh scratch directory for one test (see [`Scratch`]).
pub fn scratch(name: &str) -> Scratch {
    let dir = std::env::temp_dir().join(format!("pointlens-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch directory");
    Scratch(dir)
}

/// Compares `actual` with the reviewed reference PNG `tests/reference/NAME.png`
/// and requires at least `min_psnr_db`. On failure writes `NAME-actual.png`
/// and `NAME-difference.png` beside the reference (git-ignored). A missing
/// reference fails unless `POINTLENS_WRITE_REFERENCE=1`, which writes it.
pub fn assert_matches_reference(name: &str, actual: &LinearImage, min_psnr_db: f64) {
    let dir = root().join("tests/reference");
    let reference = dir.join(format!("{name}.png"));
    if !reference.exists() {
        if std::env::var("POINTLENS_WRITE_REFERENCE").as_deref() == Ok("1") {
            std::fs::create_dir_all(&dir).expect("tests/reference");
            write_image(actual, &reference).expect("write reference");
            eprintln!(
                "wrote {} — review it before committing",
                reference.display()
            );
            return;
        }
        panic!(
            "missing reference image {}; run with POINTLENS_WRITE_REFERENCE=1 to create it, then review it",
            reference.display()
        );
    }
    let expected = read_image(&reference).expect("read reference");
    let psnr = metrics::psnr(&expected, actual).expect("same size as the reference");
    if psnr < min_psnr_db {
        let out = |suffix: &str| dir.join(format!("{name}-{suffix}.png"));
        write_image(actual, &out("actual")).expect("write actual");
        let diff = metrics::difference_image(&expected, actual, 0.25).expect("difference");
        write_image(&diff, &out("difference")).expect("write difference");
        panic!(
            "{name}: PSNR {psnr:.2} dB against {} is below {min_psnr_db} dB; see {} and {}",
            reference.display(),
            out("actual").display(),
            out("difference").display()
        );
    }
}

/// Writes an ASCII PLY with positions and 8-bit sRGB colors.
pub fn write_ascii_ply(path: &Path, points: &[([f32; 3], [u8; 3])]) {
    let mut s = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        points.len()
    );
    for (p, c) in points {
        s += &format!("{} {} {} {} {} {}\n", p[0], p[1], p[2], c[0], c[1], c[2]);
    }
    std::fs::write(path, s).expect("write ply");
}

/// A cloud of (position, linear color) pairs.
pub fn cloud(points: &[(Vec3, Vec3)]) -> PointCloud {
    PointCloud {
        positions: points.iter().map(|p| p.0).collect(),
        colors: points.iter().map(|p| p.1).collect(),
        normals: None,
        has_colors: true,
        attributes: vec!["x".into(), "y".into(), "z".into()],
        ..Default::default()
    }
}

/// A flat square of points on the plane y = `y`, x in [−half, half], z in
/// [−depth, −near] (in front of a camera at the origin looking down −z), on
/// a grid of `step` (rows at multiples of it), in a checker of `check`
/// squares.
pub fn checkered_plane(
    y: f32,
    half: f32,
    near: f32,
    depth: f32,
    step: f32,
    check: f32,
) -> PointCloud {
    let mut points = Vec::new();
    let n = (2.0 * half / step) as i32;
    let (first, m) = ((near / step).round() as i32, (depth / step) as i32);
    for i in 0..=n {
        for j in first..=m {
            let (x, z) = (-half + i as f32 * step, -(j as f32) * step);
            let odd = ((x / check).floor() + (z / check).floor()) as i32 & 1 == 1;
            let color = if odd {
                Vec3::new(0.9, 0.8, 0.2)
            } else {
                Vec3::new(0.1, 0.5, 0.1)
            };
            points.push((Vec3::new(x, y, z), color));
        }
    }
    cloud(&points)
}

/// A pinhole camera at the origin looking down −z, 40° vertical field of view.
pub fn camera(width: u32, height: u32) -> Camera {
    Camera {
        width,
        height,
        eye: Vec3::ZERO,
        target: Vec3::new(0.0, 0.0, -1.0),
        up: Vec3::Y,
        fovy_deg: 40.0,
        aperture_radius: 0.0,
        focus_distance: 1.0,
        aperture: pointlens::camera::Aperture::ROUND,
    }
}

/// Runs the `pointlens` binary with validation on (any message fails it).
pub fn pointlens(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pointlens"))
        .args(args)
        .env("POINTLENS_VALIDATION", "1")
        .output()
        .expect("run pointlens")
}

/// A run that must succeed: its output, or a failure showing its stderr.
pub fn assert_runs(args: &[&str]) -> Output {
    let o = pointlens(args);
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// A failed run: non-zero exit, exactly one line on stderr containing
/// `phrase`, no panic, and no file at `output`.
pub fn assert_fails(args: &[&str], phrase: &str, output: &Path) {
    let o = pointlens(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{args:?} succeeded");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{args:?}: not one line:\n{err}"
    );
    assert!(err.contains(phrase), "{args:?}: '{phrase}' not in: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(!output.exists(), "{args:?} left {}", output.display());
}

/// The options of most test renders: `method` through `camera` at SSAA 2
/// with the device's sample plan, over a black background.
pub fn options(camera: Camera, method: Method) -> RenderOptions {
    RenderOptions {
        camera,
        method,
        ssaa: 2,
        samples_per_pass: None,
        background: Vec3::ZERO,
        lod: pointlens::options::Lod::default(),
    }
}

/// The bits of every channel of every pixel: for images that must be the
/// same byte for byte (-0.0 apart from 0.0, one NaN apart from another).
pub fn image_bits(image: &LinearImage) -> Vec<u32> {
    image.pixels.iter().flatten().map(|v| v.to_bits()).collect()
}

/// Pixels that differ at all, of the total.
pub fn differing(
    a: &pointlens::image_io::LinearImage,
    b: &pointlens::image_io::LinearImage,
) -> usize {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .filter(|(p, q)| p != q)
        .count()
}

/// How many times the frame ran pass `name` (0: not at all).
pub fn pass_count(r: &pointlens::render::Rendered, name: &str) -> u32 {
    let pass = r.timings.passes.iter().find(|p| p.name == name);
    pass.map_or(0, |p| p.count)
}

/// How much worse than the sprites' image the compute rasteriser's may be
/// against a reference, dB: the two sample other points at K ≥ 2 (the
/// compute rasteriser's rotated grid), and the compute image must be as
/// close or closer.
pub const SAME_DB: f64 = 0.2;

/// The PSNR of `compute` against `reference`, asserted at least the
/// sprites' image's less [`SAME_DB`]; both printed, the reference named
/// `against`.
pub fn assert_compute_as_close(
    what: &str,
    against: &str,
    reference: &LinearImage,
    sprites: &LinearImage,
    compute: &LinearImage,
) -> f64 {
    let s = metrics::psnr(reference, sprites).unwrap();
    let c = metrics::psnr(reference, compute).unwrap();
    eprintln!("{what}: against {against} sprites {s:.2} dB, compute {c:.2} dB");
    assert!(
        c >= s - SAME_DB,
        "{what}: against {against} {c:.2} dB (compute), {s:.2} dB (sprites)"
    );
    c
}

/// The G-buffer raster passes of a frame (the depth peel's excluded).
pub fn rasters(r: &pointlens::render::Rendered) -> u32 {
    r.timings
        .passes
        .iter()
        .filter(|p| p.name.ends_with(".raster") && !p.name.starts_with("peel"))
        .map(|p| p.count)
        .sum()
}

/// Adds 9 red specks 1 mm in front of `camera`'s lens, 0.3 mm apart across
/// the view (points at the lens: a veil, `crate::veil`).
pub fn add_specks_at_the_lens(cloud: &mut PointCloud, camera: &Camera) {
    let (right, up, forward) = camera.basis();
    for i in -1..=1 {
        for j in -1..=1 {
            let p = camera.eye + 0.001 * forward + 0.0003 * (i as f32 * right + j as f32 * up);
            cloud.positions.push(p);
            cloud.colors.push(Vec3::new(1.0, 0.2, 0.2));
            if let Some(normals) = &mut cloud.normals {
                normals.push(-forward);
            }
        }
    }
}

/// Writes a binary little-endian PLY whose vertices have `properties`
/// (type, name), e.g. `("double", "x")`, one row of values per vertex
/// (each written as its property's type).
pub fn write_binary_ply(path: &Path, properties: &[(&str, &str)], rows: &[Vec<f64>]) {
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\n",
        rows.len()
    );
    for (ty, name) in properties {
        bytes += &format!("property {ty} {name}\n");
    }
    bytes += "end_header\n";
    let mut bytes = bytes.into_bytes();
    for row in rows {
        assert_eq!(row.len(), properties.len(), "a value per property");
        for ((ty, _), &v) in properties.iter().zip(row) {
            match *ty {
                "double" => bytes.extend_from_slice(&v.to_le_bytes()),
                "float" => bytes.extend_from_slice(&(v as f32).to_le_bytes()),
                "uchar" => bytes.push(v as u8),
                "ushort" => bytes.extend_from_slice(&(v as u16).to_le_bytes()),
                "int" => bytes.extend_from_slice(&(v as i32).to_le_bytes()),
                other => panic!("type {other} not written by the test"),
            }
        }
    }
    std::fs::write(path, bytes).expect("write ply");
}

/// The properties of a PLY of float positions and float colours.
pub const XYZ_RGB_FLOATS: [(&str, &str); 6] = [
    ("float", "x"),
    ("float", "y"),
    ("float", "z"),
    ("float", "red"),
    ("float", "green"),
    ("float", "blue"),
];

/// `count` points of a unit cube with its least corner at `corner`
/// (a fixed pseudo-random sequence).
pub fn cube_points(count: usize, corner: f64) -> Vec<[f64; 3]> {
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..count)
        .map(|_| [corner + next(), corner + next(), corner + next()])
        .collect()
}

/// `points` written twice with double x, y, z, as binary little-endian PLY
/// (`far.ply`) and as ASCII PLY (`far-ascii.ply`) in `dir`; returns
/// (binary, ASCII).
pub fn write_double_plys(dir: &Path, points: &[[f64; 3]]) -> (PathBuf, PathBuf) {
    let props = [("double", "x"), ("double", "y"), ("double", "z")];
    let rows: Vec<Vec<f64>> = points.iter().map(|p| p.to_vec()).collect();
    let binary = dir.join("far.ply");
    write_binary_ply(&binary, &props, &rows);
    let ascii = dir.join("far-ascii.ply");
    let mut text = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty double x\nproperty double y\n\
         property double z\nend_header\n",
        points.len()
    );
    for p in points {
        text += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    std::fs::write(&ascii, text).expect("write ply");
    (binary, ascii)
}
