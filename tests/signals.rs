//! Signals and concurrency (issue 17): a render stopped by SIGTERM leaves
//! no file, a killed writer's temporary file is cleaned up by the next
//! write into its folder, and two processes writing the same output leave
//! one complete image. (A sequence stopped by SIGTERM is in
//! tests/sequence.rs.)

mod common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{root, scratch};

fn bunny() -> String {
    root().join("data/bunny_colored.ply").display().to_string()
}

fn names(dir: &std::path::Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn sigterm_during_a_render_leaves_no_file() {
    let dir = scratch("signals-term");
    let out = dir.join("slow.png");
    // An accumulation of many lens samples: seconds on lavapipe.
    let b = bunny();
    let out_s = out.display().to_string();
    let mut child = Command::new(env!("CARGO_BIN_EXE_pointlens"))
        .args([
            "render",
            &b,
            "-o",
            &out_s,
            "--method",
            "accum",
            "--samples",
            "2048",
        ])
        .args(["--width", "320", "--height", "240", "--device", "llvmpipe"])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the render ended too soon to be stopped"
    );
    Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    let started = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "SIGTERM did not stop it"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(!status.success());
    assert!(names(&dir).is_empty(), "left {:?}", names(&dir));
}

#[test]
fn a_killed_writers_temporary_file_is_removed_by_the_next_write() {
    let dir = scratch("signals-stale");
    // A process id that runs no process, and this test's, which runs.
    let dead = (100_000..4_000_000u32)
        .find(|p| !std::path::Path::new(&format!("/proc/{p}")).exists())
        .unwrap();
    let alive = std::process::id();
    std::fs::write(dir.join(format!(".f.png.tmp-{dead}-0")), b"partial").unwrap();
    std::fs::write(dir.join(format!(".g.exr.tmp-{dead}-7")), b"partial").unwrap();
    std::fs::write(dir.join(format!(".f.png.tmp-{alive}-0")), b"in progress").unwrap();
    std::fs::write(dir.join(".notes.tmp"), b"not ours").unwrap();
    let (b, out) = (bunny(), dir.join("f.png").display().to_string());
    let o = common::pointlens(&[
        "render", &b, "-o", &out, "--width", "16", "--height", "12", "--device", "llvmpipe",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        names(&dir),
        [
            format!(".f.png.tmp-{alive}-0"),
            ".notes.tmp".to_string(),
            "f.png".to_string()
        ]
    );
}

#[test]
fn two_processes_writing_one_path_leave_one_complete_image() {
    let dir = scratch("signals-race");
    let b = bunny();
    let render = |out: &str, method: &str| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_pointlens"));
        c.args(["render", &b, "-o", out, "--method", method])
            .args(["--width", "64", "--height", "48", "--device", "llvmpipe"]);
        c
    };
    // Each alone, for reference.
    let (a, c) = (dir.join("a.png"), dir.join("c.png"));
    assert!(render(&a.display().to_string(), "pinhole")
        .status()
        .unwrap()
        .success());
    assert!(render(&c.display().to_string(), "fast")
        .status()
        .unwrap()
        .success());
    let (a, c) = (std::fs::read(a).unwrap(), std::fs::read(c).unwrap());
    assert_ne!(a, c);
    for round in 0..3 {
        let shared = dir.join(format!("shared{round}.png")).display().to_string();
        let mut one = render(&shared, "pinhole").spawn().unwrap();
        let mut two = render(&shared, "fast").spawn().unwrap();
        assert!(one.wait().unwrap().success() && two.wait().unwrap().success());
        let got = std::fs::read(&shared).unwrap();
        assert!(got == a || got == c, "round {round}: a mixture of the two");
    }
    assert!(
        names(&dir).iter().all(|n| !n.contains(".tmp-")),
        "{:?}",
        names(&dir)
    );
}
