//! The synthetic scene of `pointlens bench` and `pointlens synth`: a wavy
//! wall facing +z (70 % of the points) and five spheres in front of it at
//! different depths, colored by a checker of their position, so that a lens
//! blurs something at every depth.
//!
//! The points come from a SplitMix64 stream (the same scene on every
//! machine), two draws per point. SplitMix64's state only advances by a
//! constant, so point `i` is a function of `i` alone ([`point`]): any range
//! of the scene can be made on its own, in parallel and in chunks, and
//! gives the points of the whole scene in order.

use std::io::Write;
use std::ops::Range;
use std::path::Path;

use glam::Vec3;

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::image_io::{linear_to_srgb8, write_atomically};

pub mod lights;

/// SplitMix64's increment, which is also the stream's starting state.
const GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// The spheres: centre and radius.
const SPHERES: [(Vec3, f32); 5] = [
    (Vec3::new(-0.6, -0.3, 0.9), 0.25),
    (Vec3::new(0.5, 0.35, 0.6), 0.3),
    (Vec3::new(0.0, -0.05, 0.35), 0.2),
    (Vec3::new(-0.45, 0.45, 0.15), 0.15),
    (Vec3::new(0.6, -0.5, 1.2), 0.12),
];

/// Draw `j` of the stream, uniform in [0, 1) with 24 bits: the state after
/// `j + 1` steps from `GAMMA`, mixed.
fn draw(j: u64) -> f32 {
    let mut z = GAMMA.wrapping_mul(j.wrapping_add(2));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
}

/// Point `i` of the scene: its position and linear color.
pub fn point(i: u64) -> (Vec3, Vec3) {
    let (a, b) = (draw(2 * i), draw(2 * i + 1));
    let p = if i % 10 < 7 {
        let (x, y) = (2.0 * a - 1.0, 2.0 * b - 1.0);
        Vec3::new(x, y, 0.08 * (6.0 * x).sin() * (5.0 * y).cos() - 0.3)
    } else {
        // The k-th sphere point goes to sphere k mod 5: all get as many.
        let k = i / 10 * 3 + i % 10 - 7;
        let (center, radius) = SPHERES[(k % SPHERES.len() as u64) as usize];
        // Uniform on the sphere: z uniform in [−1, 1], angle uniform.
        let z = 2.0 * a - 1.0;
        let phi = std::f32::consts::TAU * b;
        let r = (1.0 - z * z).sqrt();
        center + radius * Vec3::new(r * phi.cos(), r * phi.sin(), z)
    };
    let cell = |v: f32| (v * 8.0).floor() as i32;
    let even = (cell(p.x) + cell(p.y) + cell(p.z)).rem_euclid(2) == 0;
    let hue = 0.5 + 0.5 * p.x;
    let color = if even {
        Vec3::new(0.8 * hue + 0.1, 0.5, 0.9 - 0.8 * hue)
    } else {
        Vec3::splat(0.05)
    };
    (p, color)
}

/// The points `range` of the scene, in order: positions and linear colors.
pub fn points(range: Range<u64>) -> impl Iterator<Item = (Vec3, Vec3)> {
    range.map(point)
}

/// The first `count` points of the scene as a cloud (colors, no normals).
pub fn cloud(count: usize) -> PointCloud {
    let (positions, colors) = points(0..count as u64).unzip();
    PointCloud {
        positions,
        colors,
        normals: None,
        has_colors: true,
        attributes: vec!["x".into(), "y".into(), "z".into()],
        ..PointCloud::default()
    }
}

/// Points that [`write_ply`] makes and writes at a time.
pub const CHUNK_POINTS: usize = 1 << 20;

/// Bytes of one vertex record of the file: x, y, z float; red, green,
/// blue uchar.
pub const RECORD_BYTES: usize = 15;

/// The PLY header of a scene of `count` points.
pub fn ply_header(count: u64) -> String {
    format!(
        "ply\nformat binary_little_endian 1.0\n\
         comment pointlens synth: the synthetic scene of pointlens bench\n\
         element vertex {count}\n\
         property float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         end_header\n"
    )
}

/// Writes the first `count` points of the scene to `path` as a binary
/// little-endian PLY: positions as float, colors as 8-bit sRGB
/// ([`linear_to_srgb8`]). Streamed, [`CHUNK_POINTS`] at a time (made on
/// every core), so that any count takes bounded memory; written
/// atomically ([`write_atomically`]): a failure leaves no file at `path`.
/// `progress` is told the points written so far after each chunk.
pub fn write_ply(path: &Path, count: u64, progress: &mut dyn FnMut(u64)) -> Result<()> {
    write_ply_with_chunk(path, count, CHUNK_POINTS, progress)
}

/// [`write_ply`] making `chunk_points` points at a time (at least one).
pub fn write_ply_with_chunk(
    path: &Path,
    count: u64,
    chunk_points: usize,
    progress: &mut dyn FnMut(u64),
) -> Result<()> {
    if count == 0 {
        return Err(Error::InvalidArgument(
            "a synthetic cloud needs at least 1 point".into(),
        ));
    }
    let chunk = chunk_points.max(1) as u64;
    write_atomically(path, |mut file| {
        let io = |source| Error::Io {
            path: path.to_path_buf(),
            source,
        };
        file.write_all(ply_header(count).as_bytes()).map_err(io)?;
        let mut buf = Vec::new();
        let mut start = 0;
        while start < count {
            let end = count.min(start + chunk);
            buf.resize((end - start) as usize * RECORD_BYTES, 0);
            encode_records(start..end, &mut buf);
            file.write_all(&buf).map_err(io)?;
            progress(end);
            start = end;
        }
        file.sync_all().map_err(io)
    })
}

/// The fewest bytes `synth` writes for `count` points at `path` (by its
/// extension): PLY and LAS exactly their records (15 and 26 bytes, as
/// [`write_ply`] and [`write_las`] write them), LAZ a stated lower bound of
/// 8 bytes a point (measured: 11.1 for 10^6 points).
pub fn least_file_bytes(path: &Path, count: u64) -> u64 {
    let per_point = match (crate::input::las::has_las_extension(path), is_laz(path)) {
        (true, true) => 8,
        (true, false) => 26,
        (false, _) => RECORD_BYTES as u64,
    };
    count.saturating_mul(per_point)
}

/// Whether `path` names a LAZ file (`.laz`, any case): [`write_las`]
/// compresses it.
fn is_laz(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("laz"))
}

/// The bytes free to this user on the file system that holds `path`'s
/// folder, as `df` reports them; None where `df` cannot say.
pub fn free_bytes(path: &Path) -> Option<u64> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let out = std::process::Command::new("df")
        .args(["-B1", "--output=avail"])
        .arg(dir)
        .stderr(std::process::Stdio::null())
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .nth(1)?
        .trim()
        .parse()
        .ok()
}

/// The LAS/LAZ scale of [`write_las`]'s coordinates: a micrometre of the
/// scene's 2-unit-wide wall.
pub const LAS_SCALE: f64 = 1e-6;

/// Writes the first `count` points of the scene to `path` as LAS 1.2, point
/// format 2 (RGB), LAZ-compressed where the extension is `.laz` (on every
/// core): coordinates on a [`LAS_SCALE`] grid, colors as 16-bit sRGB (the
/// 8-bit code × 257). Streamed and written atomically like [`write_ply`].
pub fn write_las(path: &Path, count: u64, progress: &mut dyn FnMut(u64)) -> Result<()> {
    use las::{Builder, Color, Point, PointDataBuilder, Transform, Vector, Writer};
    if count == 0 {
        return Err(Error::InvalidArgument(
            "a synthetic cloud needs at least 1 point".into(),
        ));
    }
    let fail = |e: las::Error| Error::Las {
        path: path.to_path_buf(),
        msg: e.to_string(),
    };
    let mut builder = Builder::from((1, 2));
    builder.point_format = las::point::Format::new(2).map_err(fail)?;
    builder.point_format.is_compressed = is_laz(path);
    builder.generating_software = "pointlens synth".into();
    let axis = Transform {
        scale: LAS_SCALE,
        offset: 0.0,
    };
    builder.transforms = Vector {
        x: axis,
        y: axis,
        z: axis,
    };
    let header = builder.into_header().map_err(fail)?;
    write_atomically(path, |file| {
        let mut writer = Writer::new(
            std::io::BufWriter::with_capacity(1 << 20, file),
            header.clone(),
        )
        .map_err(fail)?;
        let mut start = 0;
        while start < count {
            let end = count.min(start + CHUNK_POINTS as u64);
            let points = points(start..end).map(|(p, c)| {
                let [red, green, blue] = c.to_array().map(|v| u16::from(linear_to_srgb8(v)) * 257);
                Point {
                    x: f64::from(p.x),
                    y: f64::from(p.y),
                    z: f64::from(p.z),
                    return_number: 1,
                    number_of_returns: 1,
                    color: Some(Color { red, green, blue }),
                    ..Point::default()
                }
            });
            let data = PointDataBuilder::new()
                .for_header(&header)
                .build_from_points(points)
                .map_err(fail)?;
            writer.write_points(&data).map_err(fail)?;
            progress(end);
            start = end;
        }
        let file = writer
            .into_inner()
            .map_err(fail)?
            .into_inner()
            .map_err(|e| Error::Io {
                path: path.to_path_buf(),
                source: e.into_error(),
            })?;
        file.sync_all().map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })
    })
}

/// The PLY records of points `range` into `out` (exactly their size),
/// split over every core.
fn encode_records(range: Range<u64>, out: &mut [u8]) {
    let n = out.len() / RECORD_BYTES;
    let threads = crate::available_threads().min(n.div_ceil(16_384)).max(1);
    let per_thread = n.div_ceil(threads);
    std::thread::scope(|scope| {
        for (t, part) in out.chunks_mut(per_thread * RECORD_BYTES).enumerate() {
            let first = range.start + (t * per_thread) as u64;
            scope.spawn(move || {
                for (record, i) in part.chunks_exact_mut(RECORD_BYTES).zip(first..) {
                    let (p, c) = point(i);
                    for (a, v) in p.to_array().into_iter().enumerate() {
                        record[4 * a..4 * a + 4].copy_from_slice(&v.to_le_bytes());
                    }
                    for (a, v) in c.to_array().into_iter().enumerate() {
                        record[12 + a] = linear_to_srgb8(v);
                    }
                }
            });
        }
    });
}

/// Floats of one Gaussian of [`write_gaussians`]: x y z, nx ny nz, f_dc
/// (3), f_rest (45, degree 3), opacity, scale (3), rot (4).
pub const GAUSSIAN_FLOATS: usize = 62;

/// Draw `k` (< 64) of Gaussian `i`'s own stream, uniform in [0, 1): apart
/// from the points' draws.
fn gaussian_draw(i: u64, k: u64) -> f32 {
    draw((1 << 50) + 64 * i + k)
}

/// Gaussian `i` of a synthetic scene of `count` (`synth --gaussians`), as
/// the reference code stores it (pre-activation): centred on point `i` of
/// the scene, its DC term the point's color as trained (sRGB-encoded),
/// small SH terms of degree 3, an opacity between 0.2 and 0.99, and
/// standard deviations of 0.3 to 1.5 times the mean spacing of `count`
/// points along axes turned at random: anisotropic, overlapping and
/// semi-transparent.
pub fn gaussian(i: u64, count: u64) -> [f32; GAUSSIAN_FLOATS] {
    const C0: f32 = 0.282_094_8;
    let (p, color) = point(i);
    let d = |k: u64| gaussian_draw(i, k);
    // The scene's surfaces: about 6.9 square units.
    let spacing = (6.9 / count.max(1) as f32).sqrt();
    let mut v = [0.0f32; GAUSSIAN_FLOATS];
    v[..3].copy_from_slice(&p.to_array());
    for c in 0..3 {
        let encoded = crate::image_io::linear_to_srgb(color[c]);
        v[6 + c] = (encoded - 0.5) / C0;
    }
    for k in 0..45 {
        v[9 + k] = 0.1 * (2.0 * d(k as u64) - 1.0);
    }
    let opacity = 0.2 + 0.79 * d(45);
    v[54] = (opacity / (1.0 - opacity)).ln();
    for a in 0..3 {
        v[55 + a] = (spacing * (0.3 + 1.2 * d(46 + a as u64))).ln();
    }
    let q = [d(49), d(50), d(51), d(52)].map(|x| 2.0 * x - 1.0);
    let norm = q.iter().map(|x| x * x).sum::<f32>().sqrt().max(1e-6);
    for (k, x) in q.iter().enumerate() {
        v[58 + k] = x / norm;
    }
    v
}

/// The PLY header of [`write_gaussians`]: the reference code's layout.
pub fn gaussian_header(count: u64) -> String {
    let mut h = format!(
        "ply\nformat binary_little_endian 1.0\n\
         comment pointlens synth: Gaussians on the synthetic scene of pointlens bench\n\
         element vertex {count}\n"
    );
    // The reference code's layout: normals after the centre.
    let mut names = crate::input::gaussians::property_names(45);
    names.splice(3..3, ["nx", "ny", "nz"].map(String::from));
    assert_eq!(names.len(), GAUSSIAN_FLOATS);
    for n in names {
        h += &format!("property float {n}\n");
    }
    h + "end_header\n"
}

/// Writes `count` Gaussians of [`gaussian`] to `path` (binary PLY, the
/// reference code's layout), [`CHUNK_POINTS`] at a time, atomically.
pub fn write_gaussians(path: &Path, count: u64, progress: &mut dyn FnMut(u64)) -> Result<()> {
    if count == 0 {
        return Err(Error::InvalidArgument(
            "a synthetic scene needs at least 1 Gaussian".into(),
        ));
    }
    write_float_records(
        path,
        &gaussian_header(count),
        count,
        |i| gaussian(i, count),
        progress,
    )
}

/// Writes the PLY `header` and `count` records of floats, record `i` being
/// `record(i)` (little-endian), to `path` atomically, [`CHUNK_POINTS`] at
/// a time, telling `progress` the records written.
fn write_float_records<const N: usize>(
    path: &Path,
    header: &str,
    count: u64,
    record: impl Fn(u64) -> [f32; N],
    progress: &mut dyn FnMut(u64),
) -> Result<()> {
    write_atomically(path, |mut file| {
        let io = |source| Error::Io {
            path: path.to_path_buf(),
            source,
        };
        file.write_all(header.as_bytes()).map_err(io)?;
        let mut start = 0;
        while start < count {
            let end = count.min(start + CHUNK_POINTS as u64);
            let buf: Vec<u8> = (start..end)
                .flat_map(&record)
                .flat_map(f32::to_le_bytes)
                .collect();
            file.write_all(&buf).map_err(io)?;
            progress(end);
            start = end;
        }
        file.sync_all().map_err(io)
    })
}

/// What `pointlens synth` writes: `count` points (PLY, or LAS / LAZ by the
/// extension), `count` 3D Gaussians (PLY), or the bokeh scene of `count`
/// points ([`lights`], PLY).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SynthKind {
    Points,
    Gaussians,
    Lights,
}

impl SynthKind {
    /// The kind and count of `synth`'s flags `--points`, `--gaussians`
    /// and `--lights` (at most one given; none: points, count 0).
    pub fn of(
        points: Option<u64>,
        gaussians: Option<u64>,
        lights: Option<u64>,
    ) -> (SynthKind, u64) {
        match (gaussians, lights) {
            (Some(n), _) => (SynthKind::Gaussians, n),
            (_, Some(n)) => (SynthKind::Lights, n),
            _ => (SynthKind::Points, points.unwrap_or(0)),
        }
    }
}

impl std::fmt::Display for SynthKind {
    /// What is counted: "points" or "Gaussians".
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(match self {
            SynthKind::Points | SynthKind::Lights => "points",
            SynthKind::Gaussians => "Gaussians",
        })
    }
}

/// `pointlens synth`: checks the count, the output's name and folder and,
/// for points, the free disk; makes SIGINT and SIGTERM remove the file in
/// writing; writes `count` items of `kind` to `output`, `progress(done)`
/// as they go. Returns the file's size in bytes.
pub fn write_file(
    kind: SynthKind,
    count: u64,
    output: &Path,
    progress: &mut dyn FnMut(u64),
) -> Result<u64> {
    let invalid = |msg: String| Err(Error::InvalidArgument(msg));
    let what = match kind {
        SynthKind::Points => "--points",
        SynthKind::Gaussians => "--gaussians",
        SynthKind::Lights => "--lights",
    };
    if count == 0 {
        return invalid(format!("{what} must be at least 1"));
    }
    let ply = output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    if kind != SynthKind::Points && !ply {
        return invalid(format!("{}: {what} is written as .ply", output.display()));
    }
    crate::image_io::check_parent_dir(output, "-o")?;
    if kind != SynthKind::Gaussians {
        let need = match kind {
            SynthKind::Lights => count.saturating_mul(lights::RECORD_BYTES),
            _ => least_file_bytes(output, count),
        };
        if let Some(free) = free_bytes(output).filter(|&free| need > free) {
            return invalid(format!(
                "{}: {count} points need at least {:.1} GB, the disk has {:.1} GB free",
                output.display(),
                need as f64 / 1e9,
                free as f64 / 1e9
            ));
        }
    }
    // A signal removes the file in writing, as `render`'s do.
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    crate::job::watch_signals(false, stop)?;
    match kind {
        SynthKind::Gaussians => write_gaussians(output, count, progress)?,
        SynthKind::Points if crate::input::las::has_las_extension(output) => {
            write_las(output, count, progress)?
        }
        SynthKind::Points => write_ply(output, count, progress)?,
        SynthKind::Lights => lights::write(output, count, progress)?,
    }
    Ok(std::fs::metadata(output).map_or(0, |m| m.len()))
}
