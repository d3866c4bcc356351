//! Determinism (issue 17): every method gives the same bytes for the same
//! input and flags, run after run and whatever the number of threads the
//! CPU work (loading, the splat hierarchy, its traversal) is split over.
//! The thread count is the process's CPU affinity
//! (`std::thread::available_parallelism`), set with `taskset`.

mod common;

use std::process::Command;

use common::{root, scratch};

#[test]
fn every_method_gives_the_same_bytes_across_runs_and_thread_counts() {
    let dir = scratch("determinism");
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    assert!(cores >= 2, "needs two cores to vary the thread count");
    let bunny = root().join("data/bunny_colored.ply").display().to_string();
    let las = root().join("data/autzen_trim.las").display().to_string();
    let methods: [&[&str]; 9] = [
        &["--method", "pinhole"],
        &["--method", "fast"],
        &["--method", "fast", "--fast-gather", "tree"],
        &[
            "--method",
            "fast",
            "--fast-gather",
            "tree",
            "--fast-weights",
            "uniform",
        ],
        &["--method", "rdb", "--rdb-atomics", "64"],
        &[
            "--method",
            "rdb",
            "--rdb-atomics",
            "32",
            "--rdb-mode",
            "pairs",
        ],
        &[
            "--method",
            "rdb",
            "--rdb-memory-mb",
            "1",
            "--rdb-bins",
            "16",
        ],
        &["--method", "layered", "--layers", "3"],
        &["--method", "accum", "--samples", "8"],
    ];
    for input in [&bunny, &las] {
        for (m, method) in methods.iter().enumerate() {
            let mut outputs = Vec::new();
            // All cores, one core, all cores again.
            for (run, cpus) in ["all", "0", "all"].iter().enumerate() {
                let out = dir.join(format!("m{m}-{run}.exr"));
                let out_s = out.display().to_string();
                let mut args = vec![input.as_str(), "-o", &out_s];
                args.extend(["--width", "40", "--height", "30", "--ssaa", "2"]);
                args.extend(["--device", "llvmpipe", "--passes", "z,coc"]);
                args.extend(method.iter());
                let mut command = match *cpus {
                    "all" => Command::new(env!("CARGO_BIN_EXE_pointlens")),
                    cpu => {
                        let mut c = Command::new("taskset");
                        c.args(["-c", cpu, env!("CARGO_BIN_EXE_pointlens")]);
                        c
                    }
                };
                let o = command
                    .arg("render")
                    .args(&args)
                    .env("POINTLENS_VALIDATION", "1")
                    .output()
                    .unwrap();
                assert!(
                    o.status.success(),
                    "{method:?}: {}",
                    String::from_utf8_lossy(&o.stderr)
                );
                outputs.push(std::fs::read(&out).unwrap());
            }
            assert!(
                outputs[0] == outputs[1] && outputs[0] == outputs[2],
                "{input} {method:?}: the bytes differ between runs or thread counts"
            );
        }
    }
}
