//! Video output (`-o film.mp4`, `-o film.webm`): a sequence through the
//! installed ffmpeg (`scripts/setup.sh` installs it; a machine without it
//! fails these tests, it does not skip them). Checked by ffprobe (frame
//! count, size, codec) and against the same frames written as PNG.

mod common;

use std::path::Path;
use std::process::Command;

use common::{assert_fails, assert_runs, file_names, root, scratch};
use pointlens::image_io::read_image;

fn bunny() -> String {
    root().join("data/bunny_colored.ply").display().to_string()
}

/// Small frames of a 6-frame orbit on lavapipe.
const ORBIT: [&str; 12] = [
    "--width",
    "64",
    "--height",
    "48",
    "--device",
    "llvmpipe",
    "--frames",
    "6",
    "--orbit",
    "90",
    "--aperture-radius",
    "0.01",
];

/// `ffprobe`'s facts of the video stream at `path`: codec, width,
/// height and the number of frames decoded.
fn probe(path: &Path) -> (String, u32, u32, u32) {
    let out = Command::new("ffprobe")
        .args(["-v", "error", "-select_streams", "v:0", "-count_frames"])
        .args([
            "-show_entries",
            "stream=codec_name,width,height,nb_read_frames",
        ])
        .args(["-of", "csv=p=0"])
        .arg(path)
        .output()
        .expect("ffprobe is installed (scripts/setup.sh installs ffmpeg)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let fields: Vec<&str> = text.trim().split(',').collect();
    let [codec, width, height, frames] = fields[..] else {
        panic!("ffprobe said {text}");
    };
    let number = |s: &str| s.parse::<u32>().unwrap_or_else(|_| panic!("{s} in {text}"));
    (
        codec.to_string(),
        number(width),
        number(height),
        number(frames),
    )
}

/// Frame `n` (from 0) of the video at `path`, decoded to PNG by ffmpeg.
fn decoded_frame(path: &Path, n: u32, png: &Path) {
    let out = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-i"])
        .arg(path)
        .args(["-vf", &format!("select=eq(n\\,{n})"), "-frames:v", "1"])
        .arg(png)
        .output()
        .expect("ffmpeg is installed");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_sequence_becomes_one_video_of_its_frames() {
    let dir = scratch("video");
    let frames = dir.join("f_%d.png");
    let b = bunny();
    let mut args = vec!["render", &b, "-o"];
    let frames_arg = frames.display().to_string();
    args.push(&frames_arg);
    args.extend(ORBIT);
    assert_runs(&args);
    for (name, codec) in [("film.mp4", "h264"), ("film.webm", "vp9")] {
        let film = dir.join(name);
        let film_arg = film.display().to_string();
        let mut args = vec!["render", &b, "-o", &film_arg, "--fps", "12"];
        args.extend(ORBIT);
        assert_runs(&args);
        assert_eq!(probe(&film), (codec.to_string(), 64, 48, 6), "{name}");
        // Lossy (yuv420p halves the colour's resolution), so close, not
        // equal: frames 1 and 6 of the video against their PNG frames. 28
        // dB holds H.264 at CRF 18 and VP9 at CRF 24 on these small frames
        // with sharp splat edges; a frame out of order or another frame's
        // pixels score under 20 dB.
        for n in [1u32, 6] {
            let decoded = dir.join(format!("decoded_{name}_{n}.png"));
            decoded_frame(&film, n - 1, &decoded);
            let (a, b) = (
                read_image(&decoded).unwrap(),
                read_image(&dir.join(format!("f_{n}.png"))).unwrap(),
            );
            let psnr = pointlens::metrics::psnr(&a, &b).unwrap();
            assert!(psnr > 28.0, "{name} frame {n}: {psnr:.1} dB from its PNG");
            let other = read_image(&dir.join(format!("f_{}.png", 7 - n))).unwrap();
            let wrong = pointlens::metrics::psnr(&a, &other).unwrap();
            assert!(wrong < psnr, "{name} frame {n}: closer to frame {}", 7 - n);
        }
    }
    // Only the frames and the two videos: no temporary left.
    let left: Vec<String> = file_names(&dir)
        .into_iter()
        .filter(|n| !n.starts_with("f_") && !n.starts_with("decoded_"))
        .collect();
    assert_eq!(left, ["film.mp4", "film.webm"]);
}

#[test]
fn what_a_video_cannot_be_is_refused_in_one_line_before_rendering() {
    let dir = scratch("video-refused");
    let film = dir.join("film.mp4");
    let f = film.display().to_string();
    let b = bunny();
    let small = ["--width", "64", "--height", "48", "--device", "llvmpipe"];
    let cases: [(Vec<&str>, &str); 7] = [
        (vec![], "a video needs a sequence"),
        (
            vec!["--frames", "3", "--skip-existing"],
            "--skip-existing is for numbered frames",
        ),
        (
            vec!["--frames", "3", "--background", "transparent"],
            "a video has no alpha",
        ),
        (
            vec!["--frames", "3", "--passes", "z"],
            "--passes writes EXR channels",
        ),
        (
            vec!["--frames", "3", "--width", "63"],
            "a video's frames need an even width and height",
        ),
        (vec!["--frames", "3", "--fps", "0"], "--fps"),
        (vec!["--frames", "3", "--fps", "500"], "--fps"),
    ];
    for (extra, phrase) in cases {
        let mut args = vec!["render", &b, "-o", &f];
        match extra.contains(&"--width") {
            true => args.extend(["--height", "48", "--device", "llvmpipe"]),
            false => args.extend(small),
        }
        args.extend(extra);
        assert_fails(&args, phrase, &film);
    }
    // --fps without a video cannot act.
    let png = dir.join("f_%d.png").display().to_string();
    let mut args = vec!["render", &b, "-o", &png, "--frames", "2", "--fps", "30"];
    args.extend(small);
    assert_fails(&args, "--fps is for a video output", &dir.join("f_1.png"));
    // No ffmpeg on PATH: one line that says so, no file.
    let o = Command::new(env!("CARGO_BIN_EXE_pointlens"))
        .args(["render", &b, "-o", &f, "--frames", "2"])
        .args(small)
        .env("PATH", "/nonexistent")
        .env("POINTLENS_VALIDATION", "1")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("none is on PATH"), "{err}");
    assert!(file_names(&dir).is_empty(), "{:?}", file_names(&dir));
}

/// SIGINT during a video: the frame in flight finishes, no video is
/// written and nothing is left beside it; the message says so.
#[test]
fn an_interrupted_video_leaves_no_file() {
    use std::os::unix::process::ExitStatusExt as _;
    let dir = scratch("video-signal");
    let film = dir.join("long.mp4");
    let mut child = Command::new(env!("CARGO_BIN_EXE_pointlens"))
        .args(["render", &bunny(), "-o"])
        .arg(&film)
        .args(["--width", "96", "--height", "72", "--device", "llvmpipe"])
        .args(["--frames", "100000", "--orbit", "360", "-q"])
        .env("POINTLENS_VALIDATION", "1")
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // ffmpeg writes its temporary beside the video once frames flow.
    let started = std::time::Instant::now();
    while file_names(&dir).is_empty() {
        assert!(started.elapsed().as_secs() < 60, "no temporary appeared");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let status = child.wait().unwrap();
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert_eq!((status.code(), status.signal()), (Some(1), None), "{err}");
    assert!(
        err.contains("not written") && err.contains("frames rendered"),
        "{err}"
    );
    assert!(file_names(&dir).is_empty(), "left {:?}", file_names(&dir));
}

#[test]
fn a_video_of_3d_gaussians_and_a_camera_path_frame_range() {
    let dir = scratch("video-gaussians");
    let gaussians = dir.join("g.ply");
    let g = gaussians.display().to_string();
    assert_runs(&["synth", "--gaussians", "500", "-o", &g, "-q"]);
    let film = dir.join("g.webm");
    let f = film.display().to_string();
    assert_runs(&[
        "render",
        &g,
        "-o",
        &f,
        "--width",
        "32",
        "--height",
        "24",
        "--device",
        "llvmpipe",
        "--frames",
        "5",
        "--orbit",
        "40",
        "--frame-range",
        "2-4",
        "--method",
        "accum",
        "--samples",
        "4",
    ]);
    assert_eq!(probe(&film), ("vp9".to_string(), 32, 24, 3));
}
