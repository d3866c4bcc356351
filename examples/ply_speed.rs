//! Measures PLY loading speed (docs/BENCHMARKS.md, "PLY loading"): writes a
//! synthetic cloud as binary little-endian and as ASCII PLY (float xyz,
//! uchar rgb, float normals) into a temporary folder, then times the direct
//! reader (`load_ply`) and the general one (`load_ply_general`) in
//! alternation, and checks that they give the same cloud.
//!
//!     cargo run --release --example ply_speed [POINTS] [RUNS] [direct|both] [binary|ascii]

use std::io::Write;
use std::time::Instant;

use pointlens::bench::synthetic_cloud;
use pointlens::input::ply::{load_ply, load_ply_general};

fn main() {
    let mut args = std::env::args().skip(1);
    let points: usize = args
        .next()
        .map_or(2_000_000, |a| a.parse().expect("POINTS"));
    let runs: usize = args.next().map_or(3, |a| a.parse().expect("RUNS"));
    // `direct`: time only the direct reader (for profiling it).
    let direct_only = args.next().as_deref() == Some("direct");
    // `binary` or `ascii`: that encoding only.
    let only = args.next();
    let cloud = synthetic_cloud(points);
    let dir = std::env::temp_dir().join(format!("pointlens-ply-speed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary folder");
    let header = |format: &str| {
        format!(
            "ply\nformat {format} 1.0\nelement vertex {points}\nproperty float x\nproperty float y\n\
             property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
             property float nx\nproperty float ny\nproperty float nz\nend_header\n"
        )
    };
    let srgb8 = |c: f32| (pointlens::image_io::linear_to_srgb(c) * 255.0).round() as u8;
    let mut binary = header("binary_little_endian").into_bytes();
    let mut ascii = header("ascii").into_bytes();
    for (i, (p, c)) in cloud.positions.iter().zip(&cloud.colors).enumerate() {
        let n = [(i % 7) as f32 * 0.1, 0.5, 1.0];
        for v in p.to_array() {
            binary.extend(v.to_le_bytes());
        }
        binary.extend(c.to_array().map(srgb8));
        for v in n {
            binary.extend(v.to_le_bytes());
        }
        let rgb = c.to_array().map(srgb8);
        writeln!(
            ascii,
            "{} {} {} {} {} {} {} {} {}",
            p.x, p.y, p.z, rgb[0], rgb[1], rgb[2], n[0], n[1], n[2]
        )
        .expect("in memory");
    }
    for (name, bytes) in [("binary", &binary), ("ascii", &ascii)] {
        if only.as_deref().is_some_and(|o| o != name) {
            continue;
        }
        let path = dir.join(format!("{name}.ply"));
        std::fs::write(&path, bytes).expect("write");
        let mb = bytes.len() as f64 / 1e6;
        let (mut direct, mut general, mut read) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..runs {
            let t = Instant::now();
            let file = std::fs::read(&path).expect("read");
            read.push(t.elapsed().as_secs_f64());
            drop(file);
            let t = Instant::now();
            let a = load_ply(&path).expect("direct");
            direct.push(t.elapsed().as_secs_f64());
            if direct_only {
                continue;
            }
            let t = Instant::now();
            let b = load_ply_general(&path).expect("general");
            general.push(t.elapsed().as_secs_f64());
            assert_eq!(a.positions, b.positions, "{name}: positions differ");
            assert_eq!(a.colors, b.colors, "{name}: colors differ");
            assert_eq!(a.normals, b.normals, "{name}: normals differ");
        }
        let best = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
        println!(
            "{name}: {points} points, {mb:.1} MB (reading the file alone: {:.1} ms): direct {:.1} ms ({:.0} MB/s), general {:.1} ms ({:.1} MB/s), {:.1}x",
            best(&read) * 1e3,
            best(&direct) * 1e3,
            mb / best(&direct),
            best(&general) * 1e3,
            mb / best(&general),
            best(&general) / best(&direct)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
