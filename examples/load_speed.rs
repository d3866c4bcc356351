//! Measures load throughput by input format (docs/BENCHMARKS.md, "LiDAR
//! input"): writes the synthetic scene as PLY, LAS and LAZ with `pointlens
//! synth`'s writers into a temporary folder (or takes the files given),
//! then loads each in turn, alternating the formats in every round, and
//! prints min / median wall time and points per second.
//!
//!     cargo run --release --example load_speed -- [POINTS] [RUNS] [FILE...]

use std::time::Instant;

use pointlens::input::load_cloud;

fn main() {
    let mut args = std::env::args().skip(1);
    let points: u64 = args
        .next()
        .map_or(1_000_000, |a| a.parse().expect("POINTS"));
    let runs: usize = args.next().map_or(5, |a| a.parse().expect("RUNS"));
    let mut files: Vec<std::path::PathBuf> = args.map(Into::into).collect();
    let dir = std::env::temp_dir().join(format!("pointlens-load-speed-{}", std::process::id()));
    if files.is_empty() {
        std::fs::create_dir_all(&dir).expect("temporary folder");
        for ext in ["ply", "las", "laz"] {
            let path = dir.join(format!("synthetic.{ext}"));
            let t = Instant::now();
            if ext == "ply" {
                pointlens::synth::write_ply(&path, points, &mut |_| {}).expect("write");
            } else {
                pointlens::synth::write_las(&path, points, &mut |_| {}).expect("write");
            }
            println!(
                "wrote {} ({:.1} MB) in {:.2} s",
                path.display(),
                std::fs::metadata(&path).map_or(0, |m| m.len()) as f64 / 1e6,
                t.elapsed().as_secs_f64()
            );
            files.push(path);
        }
    }
    let mut times = vec![Vec::new(); files.len()];
    let mut counts = vec![0; files.len()];
    for round in 0..runs {
        // Alternate the order as well, so that no format always goes first.
        let order: Vec<usize> = if round % 2 == 0 {
            (0..files.len()).collect()
        } else {
            (0..files.len()).rev().collect()
        };
        for i in order {
            let t = Instant::now();
            let cloud = load_cloud(&files[i], None, &mut |_, _| {}).expect("load");
            times[i].push(t.elapsed().as_secs_f64());
            counts[i] = cloud.len();
        }
    }
    println!(
        "{:<40} {:>10} {:>9} {:>9} {:>12}",
        "file", "points", "min s", "median s", "M points/s"
    );
    for (i, path) in files.iter().enumerate() {
        let t = &mut times[i];
        t.sort_by(f64::total_cmp);
        let median = t[t.len() / 2];
        println!(
            "{:<40} {:>10} {:>9.3} {:>9.3} {:>12.2}",
            path.file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into()),
            counts[i],
            t[0],
            median,
            counts[i] as f64 / median / 1e6
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
