//! Signals and concurrency: SIGINT, SIGTERM or SIGHUP during a render,
//! or while its file is being written, leaves no file and no temporary; a
//! sequence stopped so keeps its finished frames (one signal: the frame in
//! flight is finished; two: it is dropped); a killed writer's temporary
//! file is cleaned up by the next write into its folder, but not another
//! machine's or a live process's; two processes writing the same output
//! leave one complete image. (A 40-frame sequence stopped by SIGTERM is in
//! tests/sequence.rs.)
//!
//! The moment of the signal is not left to timing: the tests wait for what
//! the process shows (a log line, a temporary file in the folder), and
//! `POINTLENS_INJECT_WRITE_STALL_MS` holds each write with its temporary
//! complete and not yet renamed, the window a signal must not turn into a
//! partial file.

mod common;

use std::io::{BufRead, BufReader};
use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use common::{file_names, root, scratch};

const SIGHUP: i32 = 1;
const SIGINT: i32 = 2;
const SIGTERM: i32 = 15;

fn bunny() -> String {
    root().join("data/bunny_colored.ply").display().to_string()
}

fn pointlens() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pointlens"));
    c.env("POINTLENS_VALIDATION", "1");
    c
}

fn send(child: &Child, signal: i32) {
    let ok = Command::new("kill")
        .args([format!("-{signal}"), child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill -{signal} failed");
}

/// Waits for `child` to end, failing after `limit` (and killing it).
fn wait(child: &mut Child, limit: Duration) -> ExitStatus {
    let started = Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            panic!("the process did not end within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits until a temporary file (`.NAME.tmp-…`) is in `dir`.
fn wait_for_temporary(dir: &Path, child: &mut Child) {
    wait_for_name(dir, ".tmp-", child)
}

/// Waits until a name holding `part` is in `dir`.
fn wait_for_name(dir: &Path, part: &str, child: &mut Child) {
    let started = Instant::now();
    while !file_names(dir).iter().any(|n| n.contains(part)) {
        if let Some(s) = child.try_wait().unwrap() {
            panic!("ended ({s}) before writing: {:?}", file_names(dir));
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "no {part} in two minutes"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn a_signal_during_a_render_leaves_no_file() {
    for signal in [SIGTERM, SIGINT, SIGHUP] {
        let dir = scratch(&format!("signals-render-{signal}"));
        let out = dir.join("slow.png").display().to_string();
        // An accumulation of many lens samples: seconds on lavapipe after
        // the device is chosen (the line waited for below).
        let mut child = pointlens()
            .args(["render", &bunny(), "-o", &out, "--method", "accum"])
            .args(["--samples", "2048", "--width", "320", "--height", "240"])
            .args(["--device", "llvmpipe", "-v"])
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
        let mut log = Vec::new();
        loop {
            let line = lines
                .next()
                .unwrap_or_else(|| panic!("no 'device:' line in {log:?}"))
                .unwrap();
            let found = line.contains("device:");
            log.push(line);
            if found {
                break;
            }
        }
        send(&child, signal);
        // Keep the pipe drained while it ends.
        std::thread::spawn(move || lines.for_each(drop));
        let status = wait(&mut child, Duration::from_secs(60));
        assert_eq!(status.signal(), Some(signal), "{status}, log {log:?}");
        assert!(file_names(&dir).is_empty(), "left {:?}", file_names(&dir));
    }
}

#[test]
fn a_signal_while_the_file_is_written_leaves_neither_it_nor_its_temporary() {
    for signal in [SIGTERM, SIGINT, SIGHUP] {
        let dir = scratch(&format!("signals-write-{signal}"));
        let out = dir.join("f.exr").display().to_string();
        let mut child = pointlens()
            .args([
                "render",
                &bunny(),
                "-o",
                &out,
                "--width",
                "32",
                "--height",
                "24",
            ])
            .args(["--device", "llvmpipe", "--passes", "z,coc"])
            .env("POINTLENS_INJECT_WRITE_STALL_MS", "60000")
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        wait_for_temporary(&dir, &mut child);
        send(&child, signal);
        let status = wait(&mut child, Duration::from_secs(30));
        assert_eq!(status.signal(), Some(signal), "{status}");
        assert!(file_names(&dir).is_empty(), "left {:?}", file_names(&dir));
    }
}

/// `synth` removes the file it is writing on a signal, as `render` does
/// (it used to leave a hidden temporary of hundreds of megabytes).
#[test]
fn a_signal_during_synth_leaves_no_file() {
    for signal in [SIGTERM, SIGINT, SIGHUP] {
        let dir = scratch(&format!("signals-synth-{signal}"));
        let out = dir.join("big.ply").display().to_string();
        // 750 MB: seconds of writing.
        let mut child = pointlens()
            .args(["synth", "--points", "50000000", "-o", &out, "-q"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        wait_for_temporary(&dir, &mut child);
        send(&child, signal);
        let status = wait(&mut child, Duration::from_secs(60));
        assert_eq!(status.signal(), Some(signal), "{status}");
        assert!(file_names(&dir).is_empty(), "left {:?}", file_names(&dir));
    }
}

/// `convert` removes its parts folder on a signal, while it fills it and
/// once the output's temporary exists (the parts being built into it), as
/// well as that temporary.
#[test]
fn a_signal_during_convert_leaves_no_parts_and_no_file() {
    let inputs = scratch("signals-convert-input");
    let input = inputs.join("in.laz").display().to_string();
    let o = pointlens()
        .args(["synth", "--points", "2000000", "-o", &input, "-q"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for signal in [SIGTERM, SIGINT, SIGHUP] {
        for in_output in [false, true] {
            let dir = scratch(&format!("signals-convert-{signal}-{in_output}"));
            let out = dir.join("out.copc.laz").display().to_string();
            let mut command = pointlens();
            command
                .args(["convert", &input, "-o", &out, "-q"])
                // Parts of 5,000 points: seconds of work in thousands of
                // files.
                .env("POINTLENS_CONVERT_PART_POINTS", "5000")
                .stdout(Stdio::null())
                .stderr(Stdio::null());
            let mut child = command.spawn().unwrap();
            match in_output {
                true => wait_for_temporary(&dir, &mut child),
                false => wait_for_name(&dir, ".parts-", &mut child),
            }
            send(&child, signal);
            let status = wait(&mut child, Duration::from_secs(60));
            assert_eq!(status.signal(), Some(signal), "{status}");
            assert!(file_names(&dir).is_empty(), "left {:?}", file_names(&dir));
        }
    }
}

#[test]
fn a_sequence_finishes_the_frame_being_written_on_one_signal_and_drops_it_on_two() {
    let frames = |dir: &Path| {
        pointlens()
            .args(["render", &bunny(), "-o"])
            .arg(dir.join("s_%02d.png"))
            .args(["--width", "32", "--height", "24", "--device", "llvmpipe"])
            .args(["--frames", "5", "--orbit", "90", "-q"])
            .env("POINTLENS_INJECT_WRITE_STALL_MS", "3000")
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    // One SIGINT while frame 1 is being written: frame 1 is finished, no
    // later frame is begun.
    let dir = scratch("signals-seq-one");
    let mut child = frames(&dir);
    wait_for_temporary(&dir, &mut child);
    send(&child, SIGINT);
    let status = wait(&mut child, Duration::from_secs(60));
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(1), "{status}: {err}");
    assert!(err.contains("interrupted: 1 of 5 frames written"), "{err}");
    assert_eq!(file_names(&dir), ["s_01.png"]);
    let frame = pointlens::image_io::read_image(&dir.join("s_01.png")).unwrap();
    assert_eq!((frame.width, frame.height), (32, 24));
    // SIGINT and then SIGTERM while frame 1 is being written: it ends at
    // the second, by that signal, and frame 1 is dropped with its
    // temporary. (Two different signals: two of one kind may arrive as one.)
    let dir = scratch("signals-seq-two");
    let mut child = frames(&dir);
    wait_for_temporary(&dir, &mut child);
    send(&child, SIGINT);
    std::thread::sleep(Duration::from_millis(300));
    send(&child, SIGTERM);
    let status = wait(&mut child, Duration::from_secs(60));
    assert_eq!(status.signal(), Some(SIGTERM), "{status}");
    assert!(file_names(&dir).is_empty(), "left {:?}", file_names(&dir));
}

#[test]
fn a_killed_writers_temporary_file_is_removed_by_the_next_write() {
    let dir = scratch("signals-stale");
    // A process id that runs no process, and this test's, which runs.
    let dead = (100_000..4_000_000u32)
        .find(|p| !Path::new(&format!("/proc/{p}")).exists())
        .unwrap();
    let alive = std::process::id();
    // The host name as pointlens writes it into its temporaries' names.
    let host: String = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .unwrap()
        .trim()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '.' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    let host = host.as_str();
    let temp = |name: &str, host: &str, pid: u32, n: u32| {
        let name = format!(".{name}.tmp-{host}-{pid}-{n}");
        std::fs::write(dir.join(&name), b"partial").unwrap();
        name
    };
    temp("f.png", host, dead, 0);
    temp("g.exr", host, dead, 7);
    // A live process's write, and a write of another machine sharing the
    // folder (its process id means nothing here): both stay.
    let live = temp("f.png", host, alive, 0);
    let other_host = temp("h.png", "render-node-17", dead, 3);
    std::fs::write(dir.join(".notes.tmp"), b"not ours").unwrap();
    let (b, out) = (bunny(), dir.join("f.png").display().to_string());
    let o = common::pointlens(&[
        "render", &b, "-o", &out, "--width", "16", "--height", "12", "--device", "llvmpipe",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut expected = vec![
        live,
        other_host,
        ".notes.tmp".to_string(),
        "f.png".to_string(),
    ];
    expected.sort();
    assert_eq!(file_names(&dir), expected);
}

#[test]
fn two_processes_writing_one_path_leave_one_complete_image() {
    let dir = scratch("signals-race");
    let b = bunny();
    let render = |out: &str, method: &str| {
        let mut c = pointlens();
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
        // Each write held 5 s with its temporary complete: the two
        // writes overlap (checked: both temporaries seen at once), and
        // neither process takes the other's temporary for a dead one.
        let shared = dir.join(format!("shared{round}.png")).display().to_string();
        let spawn = |method| {
            render(&shared, method)
                .env("POINTLENS_INJECT_WRITE_STALL_MS", "5000")
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        };
        let (mut one, mut two) = (spawn("pinhole"), spawn("fast"));
        let started = Instant::now();
        let mut most = 0;
        while one.try_wait().unwrap().is_none() || two.try_wait().unwrap().is_none() {
            let temps = file_names(&dir)
                .iter()
                .filter(|n| n.contains(".tmp-"))
                .count();
            most = most.max(temps);
            assert!(started.elapsed() < Duration::from_secs(120), "hung");
            std::thread::sleep(Duration::from_millis(5));
        }
        for child in [one, two] {
            let o = child.wait_with_output().unwrap();
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        }
        assert_eq!(most, 2, "round {round}: the writes did not overlap");
        let got = std::fs::read(&shared).unwrap();
        assert!(got == a || got == c, "round {round}: a mixture of the two");
    }
    assert!(
        file_names(&dir).iter().all(|n| !n.contains(".tmp-")),
        "{:?}",
        file_names(&dir)
    );
}
