//! Sequences (`--frames`, `--path`), frame ranges for render farms,
//! `--skip-existing`, signals, compositing passes and the photographic
//! flags, through the `pointlens` binary as a user runs it (validation on).
//! Images are compared byte for byte where the claim is "the same frame".

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{assert_fails, file_names, pointlens, root, scratch};
use pointlens::camera::{self, CameraSpec};
use pointlens::image_io::{read_exr_channels, read_image};

fn bunny() -> String {
    root().join("data/bunny_colored.ply").display().to_string()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Small, fast frames: 48×36, 2×2 SSAA, on lavapipe.
const SMALL: [&str; 8] = [
    "--width", "48", "--height", "36", "--ssaa", "2", "--device", "llvmpipe",
];

/// Runs `render bunny -o OUT SMALL extra…` and asserts success.
fn render(out: &Path, extra: &[&str]) -> Output {
    let (b, out) = (bunny(), out.display().to_string());
    let mut args = vec!["render", &b, "-o", &out];
    args.extend(SMALL);
    args.extend(extra);
    let o = pointlens(&args);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    assert!(!stderr(&o).contains("validation"), "{}", stderr(&o));
    o
}

fn bytes(p: PathBuf) -> Vec<u8> {
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn an_orbit_writes_its_frames_and_any_split_into_ranges_gives_the_same_bytes() {
    let dir = scratch("seq-orbit");
    let (whole, split) = (dir.join("whole"), dir.join("split"));
    std::fs::create_dir_all(&whole).unwrap();
    std::fs::create_dir_all(&split).unwrap();
    let orbit = ["--frames", "3", "--orbit", "90"];
    render(&whole.join("o_%04d.png"), &orbit);
    assert_eq!(
        file_names(&whole),
        ["o_0001.png", "o_0002.png", "o_0003.png"],
        "the frames, numbered from 1, and nothing else"
    );
    // Two machines' ranges: frame 2 alone, then frames 1 and 3.
    let mut args = orbit.to_vec();
    args.extend(["--frame-range", "2"]);
    render(&split.join("o_%04d.png"), &args);
    assert_eq!(file_names(&split), ["o_0002.png"]);
    let mut args = orbit.to_vec();
    args.extend(["--frame-range", "1-3", "--skip-existing"]);
    render(&split.join("o_%04d.png"), &args);
    for f in ["o_0001.png", "o_0002.png", "o_0003.png"] {
        assert!(
            bytes(whole.join(f)) == bytes(split.join(f)),
            "{f} differs between the whole run and the ranges"
        );
    }
    // The orbit moves the camera: the frames differ.
    assert_ne!(
        bytes(whole.join("o_0001.png")),
        bytes(whole.join("o_0002.png"))
    );
}

#[test]
fn frame_2_of_a_focus_pull_is_the_frame_at_the_mid_focus() {
    let dir = scratch("seq-focus");
    let pull = [
        "--frames",
        "3",
        "--focus-from",
        "0.2",
        "--focus-to",
        "0.4",
        "--eye",
        "0,0.1,0.3",
        "--target",
        "-0.02,0.1,0",
        "--aperture-radius",
        "0.01",
    ];
    render(&dir.join("p_%d.png"), &pull);
    assert_eq!(file_names(&dir), ["p_1.png", "p_2.png", "p_3.png"]);
    // Frame 2 of 3 focuses halfway: 0.3, rendered alone as one image.
    let mut single: Vec<&str> = pull[6..].to_vec();
    single.extend(["--focus-distance", "0.3"]);
    render(&dir.join("single.png"), &single);
    assert!(bytes(dir.join("p_2.png")) == bytes(dir.join("single.png")));
    // Focus at 0.2 and at 0.4 are different images.
    assert_ne!(bytes(dir.join("p_1.png")), bytes(dir.join("p_3.png")));
}

#[test]
fn a_path_reproduces_its_keyframes_exactly() {
    let dir = scratch("seq-path");
    let keys = [
        r#""eye": [0.02, 0.12, 0.3], "target": [-0.02, 0.1, 0.0], "focus_distance": 0.28, "aperture_radius": 0.004, "fovy_deg": 38"#,
        r#""eye": [0.2, 0.15, 0.22], "target": [-0.01, 0.11, 0.0], "focus_distance": 0.3, "aperture_radius": 0.008, "fovy_deg": 44"#,
    ];
    let path = dir.join("path.json");
    std::fs::write(
        &path,
        format!(
            r#"{{"keyframes": [{{"frame": 1, {}}}, {{"frame": 4, {}}}]}}"#,
            keys[0], keys[1]
        ),
    )
    .unwrap();
    let path_s = path.display().to_string();
    let o = render(
        &dir.join("k_%02d.png"),
        &["--path", &path_s, "--print-camera"],
    );
    assert_eq!(
        file_names(&dir),
        ["k_01.png", "k_02.png", "k_03.png", "k_04.png", "path.json"]
    );
    // --print-camera of a sequence: a path with every frame, whose
    // keyframes are the path's at frames 1 and 4.
    let printed: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let printed = printed["keyframes"].as_array().unwrap();
    assert_eq!(printed.len(), 4);
    assert_eq!(printed[3]["focus_distance"].as_f64().unwrap() as f32, 0.3);
    for (key, frame) in keys.iter().zip(["k_01.png", "k_04.png"]) {
        let cam = dir.join(format!("{frame}.json"));
        std::fs::write(&cam, format!(r#"{{"width": 48, "height": 36, {key}}}"#)).unwrap();
        let alone = dir.join(format!("alone_{frame}"));
        render(&alone, &["--camera", &cam.display().to_string()]);
        assert!(
            bytes(dir.join(frame)) == bytes(alone.clone()),
            "{frame} differs from its keyframe rendered alone"
        );
    }
    // Between the keyframes the camera moves: frame 2 is neither end.
    let middle = bytes(dir.join("k_02.png"));
    assert_ne!(middle, bytes(dir.join("k_01.png")));
    assert_ne!(middle, bytes(dir.join("k_04.png")));
}

#[test]
fn exr_passes_hold_the_gbuffer_depth_and_the_coc_of_design_2() {
    let dir = scratch("seq-exr");
    let out = dir.join("f.exr");
    let o = render(
        &out,
        &[
            "--passes",
            "z,coc",
            "--background",
            "transparent",
            "--print-camera",
            "--method",
            "pinhole",
        ],
    );
    let (w, h, channels) = read_exr_channels(&out).unwrap();
    assert_eq!((w, h), (48, 36));
    let names: Vec<&str> = channels.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["A", "B", "CoC", "G", "R", "Z"]);
    let get = |n: &str| &channels.iter().find(|c| c.name == n).unwrap().samples;

    // The G-buffer of the same camera, through the library.
    let spec = CameraSpec::from_json_str(std::str::from_utf8(&o.stdout).unwrap()).unwrap();
    let cam = camera::resolve(&spec, glam::Vec3::ZERO, glam::Vec3::ZERO, &[]).unwrap();
    let cloud = pointlens::input::load_cloud(Path::new(&bunny()), None, &mut |_, _| {}).unwrap();
    let gbuffer = common::with_gpu(|ctx| {
        let renderer = pointlens::render::Renderer::new(ctx).unwrap();
        let scene = renderer
            .upload(&cloud, pointlens::render::SplatSize::Spacing)
            .unwrap();
        let options = common::options(cam, pointlens::options::Method::Pinhole);
        renderer.render_with_gbuffer(&scene, &options).unwrap().1
    });
    let (z, coc, alpha) = (get("Z"), get("CoC"), get("A"));
    let mut surface = 0;
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let g = gbuffer.eye[((y + gbuffer.guard) * gbuffer.width + x + gbuffer.guard) as usize];
            // Z is the G-buffer's eye depth, bit for bit (+inf on background).
            assert_eq!(z[i].to_bits(), g[2].to_bits(), "Z at {x},{y}");
            // CoC = 2R·f_px·|z − S| / (z·S); 2R·f_px / S at infinity.
            let (r, s) = (
                f64::from(cam.aperture_radius),
                f64::from(cam.focus_distance),
            );
            let f_px = 18.0 / (f64::from(cam.fovy_deg).to_radians() / 2.0).tan();
            let zf = f64::from(z[i]);
            let expected = match zf.is_finite() {
                true => 2.0 * r * f_px * (zf - s).abs() / (zf * s),
                false => 2.0 * r * f_px / s,
            };
            let got = f64::from(coc[i]);
            assert!(
                (got - expected).abs() <= 1e-5 * expected.max(1.0),
                "CoC at {x},{y}: {got} vs {expected}"
            );
            // Alpha is the coverage: 0 where no point is, (0, 1] where one is.
            match zf.is_finite() {
                true => {
                    assert!(alpha[i] > 0.0 && alpha[i] <= 1.0, "A at {x},{y}");
                    surface += 1;
                }
                false => assert_eq!(alpha[i], 0.0, "A at {x},{y}"),
            }
        }
    }
    assert!(surface > 100, "the bunny covers {surface} pixels");
}

#[test]
fn a_transparent_png_has_alpha_and_an_opaque_exr_has_alpha_one() {
    let dir = scratch("seq-alpha");
    let png = dir.join("t.png");
    render(
        &png,
        &["--background", "transparent", "--method", "pinhole"],
    );
    let decoded = image::open(&png).unwrap();
    assert_eq!(decoded.color(), image::ColorType::Rgba8);
    let rgba = decoded.to_rgba8();
    assert_eq!(rgba.get_pixel(0, 0)[3], 0, "a corner sees no point");
    assert!(rgba.pixels().any(|p| p[3] == 255), "the bunny is opaque");
    // Every method's blur carries coverage: alpha 0 away from the points,
    // between 0 and 1 on blurred edges.
    // Against accum's (the reference, 64 lens samples) the approximate
    // methods' alpha differs as their color does: a mean absolute
    // difference under 0.05 (measured 0.014–0.019 on lavapipe: the blur's
    // shape; an alpha of 1 everywhere would differ by the whole share of
    // background in the frame).
    let mut alphas = Vec::new();
    for method in ["accum", "fast", "rdb", "layered"] {
        let exr = dir.join(format!("{method}.exr"));
        render(
            &exr,
            &[
                "--background",
                "transparent",
                "--method",
                method,
                "--samples",
                "64",
            ][..if method == "accum" { 6 } else { 4 }],
        );
        let (_, _, channels) = read_exr_channels(&exr).unwrap();
        let a = channels
            .into_iter()
            .find(|c| c.name == "A")
            .unwrap()
            .samples;
        assert!(a.contains(&0.0), "{method}: no transparent pixel");
        assert!(
            a.iter().any(|&v| v > 0.0 && v < 1.0),
            "{method}: no blurred edge"
        );
        alphas.push((method, a));
    }
    let reference = &alphas[0].1;
    for (method, a) in &alphas[1..] {
        let mean = a
            .iter()
            .zip(reference)
            .map(|(x, y)| (x - y).abs())
            .sum::<f32>()
            / a.len() as f32;
        eprintln!("{method}: alpha differs from accum's by {mean} on average");
        assert!(
            mean < 0.05,
            "{method}: alpha differs from accum's by {mean}"
        );
    }
    let exr = dir.join("o.exr");
    render(&exr, &["--background", "0.2,0.3,0.4"]);
    let (_, _, channels) = read_exr_channels(&exr).unwrap();
    let a = &channels.iter().find(|c| c.name == "A").unwrap().samples;
    assert!(a.iter().all(|&v| v == 1.0), "an opaque background: A = 1");
    let image = read_image(&exr).unwrap();
    assert!(
        image.pixels[0][2] > image.pixels[0][0],
        "the blue background"
    );
}

#[test]
fn photographic_flags_equal_the_camera_file_fields() {
    let dir = scratch("seq-photo");
    let pose = [
        "--eye",
        "0,0.1,0.3",
        "--target",
        "-0.02,0.1,0",
        "--focus-distance",
        "0.3",
    ];
    let mut flags = pose.to_vec();
    flags.extend([
        "--focal-length-mm",
        "50",
        "--sensor-width-mm",
        "36",
        "--f-number",
        "2.8",
        "--units-per-mm",
        "0.001",
    ]);
    render(&dir.join("flags.png"), &flags);
    let cam = dir.join("cam.json");
    std::fs::write(
        &cam,
        r#"{"width": 48, "height": 36, "eye": [0, 0.1, 0.3], "target": [-0.02, 0.1, 0],
            "focus_distance": 0.3, "focal_length_mm": 50, "sensor_width_mm": 36,
            "f_number": 2.8, "units_per_mm": 0.001}"#,
    )
    .unwrap();
    render(
        &dir.join("file.png"),
        &["--camera", &cam.display().to_string()],
    );
    assert!(bytes(dir.join("flags.png")) == bytes(dir.join("file.png")));
    // The sensor's width spans the image's: θ = 2·atan(36·36 / (2·50·48)).
    let o = render(
        &dir.join("p.png"),
        &[&flags[..], &["--print-camera"]].concat(),
    );
    let printed: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let fovy = (2.0 * (36.0f64 * 36.0 / (2.0 * 50.0 * 48.0)).atan()).to_degrees();
    let got = printed["fovy_deg"].as_f64().unwrap();
    assert!((got - fovy).abs() < 1e-4, "{got} vs {fovy}");
    let radius = printed["aperture_radius"].as_f64().unwrap();
    assert!((radius - 50.0 * 0.001 / 5.6).abs() < 1e-7, "{radius}");
}

#[test]
fn the_readme_photographic_example_equals_its_camera_file() {
    // The README's worked example, run as written (from the repository root).
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let block = readme
        .split("<!-- photographic example -->")
        .nth(1)
        .expect("README marks its photographic example");
    let commands: Vec<Vec<String>> = block
        .lines()
        .skip_while(|l| !l.starts_with("```"))
        .skip(1)
        .take_while(|l| !l.starts_with("```"))
        .collect::<Vec<_>>()
        .join("\n")
        .replace("\\\n", " ")
        .lines()
        .map(|l| l.split_whitespace().map(String::from).collect())
        .collect();
    assert_eq!(commands.len(), 2, "two commands: flags, camera file");
    let dir = scratch("seq-readme");
    let mut outputs = Vec::new();
    for (i, command) in commands.iter().enumerate() {
        assert_eq!(command[..2], ["pointlens", "render"]);
        let mut args: Vec<String> = command[1..].to_vec();
        let at = args.iter().position(|a| a == "-o").unwrap();
        let out = dir.join(format!("readme_{i}.png"));
        args[at + 1] = out.display().to_string();
        for a in args.iter_mut() {
            if a.starts_with("data/") || a.starts_with("docs/") {
                *a = root().join(&*a).display().to_string();
            }
        }
        args.extend(["--device".into(), "llvmpipe".into()]);
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = pointlens(&refs);
        assert!(o.status.success(), "{refs:?}: {}", stderr(&o));
        outputs.push(bytes(out));
    }
    assert!(outputs[0] == outputs[1], "the README's two commands differ");
}

#[test]
fn a_terminated_sequence_leaves_only_complete_frames() {
    let dir = scratch("seq-term");
    let (b, out) = (bunny(), dir.join("t_%03d.png").display().to_string());
    let mut args = vec!["render", &b, "-o", &out];
    args.extend(SMALL);
    args.extend(["--frames", "40", "--orbit", "360"]);
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_pointlens"))
        .args(&args)
        .env("POINTLENS_VALIDATION", "1")
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait for the first frame, then SIGTERM; a run that ends before it
    // fails the test at once, with its stderr (not after the 5 minutes).
    let started = std::time::Instant::now();
    while !dir.join("t_001.png").exists() {
        if child.try_wait().unwrap().is_some() {
            let o = child.wait_with_output().unwrap();
            panic!(
                "the sequence ended before its first frame ({}): {}",
                o.status,
                stderr(&o)
            );
        }
        assert!(
            started.elapsed().as_secs() < 300,
            "no frame after 5 minutes"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let pid = child.id().to_string();
    let kill = std::process::Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .unwrap();
    assert!(kill.success());
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert!(!o.status.success(), "a stopped sequence fails");
    assert!(err.contains("interrupted"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let names = file_names(&dir);
    assert!(names.len() < 40, "it stopped early: {names:?}");
    for (i, name) in names.iter().enumerate() {
        // Only frames, numbered in order from 1, each a complete PNG.
        assert_eq!(*name, format!("t_{:03}.png", i + 1), "{names:?}");
        let image = read_image(&dir.join(name)).unwrap();
        assert_eq!((image.width, image.height), (48, 36));
    }
}

#[test]
fn bad_sequences_fail_with_one_line_and_no_file() {
    let dir = scratch("seq-bad");
    let b = bunny();
    let pat = dir.join("s_%04d.png").display().to_string();
    let one = dir.join("s.png").display().to_string();
    let first = dir.join("s_0001.png");
    let base = |o: &str, extra: &[&str]| -> Vec<String> {
        let mut v: Vec<String> = ["render", &b, "-o", o].map(String::from).to_vec();
        v.extend(SMALL.iter().map(|s| s.to_string()));
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    let cases: [(Vec<String>, &str, &Path); 9] = [
        (base(&pat, &["--frames", "0"]), "--frames", &first),
        (
            base(&one, &["--frames", "3"]),
            "frame number",
            Path::new(&one),
        ),
        (base(&pat, &[]), "one frame to render", &first),
        (
            base(&pat, &["--frames", "3", "--frame-range", "2-5"]),
            "outside the sequence's frames 1-3",
            &first,
        ),
        (
            base(&pat, &["--frames", "3", "--frame-range", "3-2"]),
            "--frame-range",
            &first,
        ),
        (
            base(&one, &["--frame-range", "1"]),
            "for sequences",
            Path::new(&one),
        ),
        (
            base(
                &dir.join("s_%s.png").display().to_string(),
                &["--frames", "2"],
            ),
            "not a frame number pattern",
            &first,
        ),
        (base(&one, &["--passes", "z"]), "EXR", Path::new(&one)),
        (
            base(
                &pat,
                &["--frames", "2", "--focus-from", "0", "--focus-to", "1"],
            ),
            "--focus-from",
            &first,
        ),
    ];
    for (args, phrase, output) in &cases {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        assert_fails(&refs, phrase, output);
    }
    // A path whose keyframes do not increase, or animate a field in only
    // some keyframes.
    for (json, phrase) in [
        (
            r#"{"keyframes": [{"frame": 3}, {"frame": 2}]}"#,
            "must increase",
        ),
        (
            r#"{"keyframes": [{"frame": 1, "focus_distance": 1}, {"frame": 2}]}"#,
            "'focus_distance' is in 1 of 2 keyframes",
        ),
        (
            r#"{"keyframes": [{"frame": 1, "width": 8}, {"frame": 2, "width": 9}]}"#,
            "'width' changes at keyframe 2",
        ),
        (r#"{"keyframes": []}"#, "at least one keyframe"),
    ] {
        let path = dir.join("bad.json");
        std::fs::write(&path, json).unwrap();
        let args = base(&pat, &["--path", &path.display().to_string()]);
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        assert_fails(&refs, phrase, &first);
    }
}

#[test]
fn skip_existing_leaves_existing_frames_untouched() {
    let dir = scratch("seq-skip");
    std::fs::write(dir.join("s_2.png"), b"kept").unwrap();
    let o = render(
        &dir.join("s_%d.png"),
        &["--frames", "3", "--skip-existing", "-v"],
    );
    assert_eq!(bytes(dir.join("s_2.png")), b"kept");
    assert!(read_image(&dir.join("s_1.png")).is_ok());
    assert!(read_image(&dir.join("s_3.png")).is_ok());
    // -v says what it did, frame by frame.
    let err = stderr(&o);
    assert!(
        err.contains("frame 2:") && err.contains("exists, skipped"),
        "{err}"
    );
    assert!(err.contains("frame 3:"), "{err}");
    // -q says nothing.
    let o = render(&dir.join("q_%d.png"), &["--frames", "1", "-q"]);
    assert_eq!(stderr(&o), "");
}

#[test]
fn list_devices_marks_the_default() {
    let o = pointlens(&["--list-devices"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    let marked: Vec<&str> = text.lines().filter(|l| l.starts_with("* ")).collect();
    assert_eq!(marked.len(), 1, "{text}");
    assert!(text.contains("llvmpipe"), "{text}");
    // `--device N` takes the number the list gives the device: the marked
    // one renders by its number, and a number past the list fails naming
    // the devices.
    let number = marked[0][2..].split(':').next().unwrap().to_string();
    let dir = scratch("seq-device-number");
    let o = pointlens(&[
        "render",
        &bunny(),
        "-o",
        dir.join("n.png").to_str().unwrap(),
        "--width",
        "8",
        "--height",
        "6",
        "--method",
        "pinhole",
        "--device",
        &number,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = pointlens(&[
        "render",
        &bunny(),
        "-o",
        dir.join("m.png").to_str().unwrap(),
        "--width",
        "8",
        "--height",
        "6",
        "--device",
        "4000",
    ]);
    let err = stderr(&o);
    assert!(
        !o.status.success() && err.contains("no Vulkan 1.3 device matches '4000'"),
        "{err}"
    );
    assert!(err.contains(&format!("{number}: llvmpipe")), "{err}");
    assert!(!dir.join("m.png").exists());
}

#[test]
fn recycled_images_change_no_method_s_frame_and_memory_stays_flat() {
    use pointlens::options::{Method, RdbAtomics, RdbMode, RdbOptions};
    let cloud = pointlens::input::load_cloud(Path::new(&bunny()), None, &mut |_, _| {}).unwrap();
    let (lo, hi) = cloud.bounds();
    let spec = CameraSpec {
        width: Some(40),
        height: Some(30),
        ..CameraSpec::default()
    };
    let base = camera::resolve(&spec, lo, hi, &cloud.positions).unwrap();
    let orbit = pointlens::sequence::Motion {
        frames: 4,
        orbit_deg: Some(90.0),
        focus: None,
        aperture: None,
    };
    let rdb = |atomics| {
        Method::Rdb(RdbOptions {
            bins: 5,
            mode: RdbMode::Centre,
            memory_bytes: None,
            atomics,
        })
    };
    let methods = [
        Method::Pinhole,
        Method::Fast(Default::default()),
        Method::paper_fast(Default::default(), Default::default()),
        rdb(RdbAtomics::Int64),
        rdb(RdbAtomics::Int32),
        Method::layered(3),
        Method::accum(4),
    ];
    common::with_gpu(|ctx| {
        let renderer = pointlens::render::Renderer::new(ctx).unwrap();
        let scene = renderer
            .upload(&cloud, pointlens::render::SplatSize::Spacing)
            .unwrap();
        for method in methods {
            let frame = |i: u32| {
                let options = common::options(orbit.camera(&base, i), method);
                renderer.render(&scene, &options).unwrap().image
            };
            // Frame 1 with new images, then frames 2–4 and 1 again with
            // frame 1's (and each other's) images recycled.
            ctx.release_pool();
            let first = frame(1);
            let one_frame = ctx.allocated_bytes();
            let (created, _, _) = ctx.pool_counts();
            let (frames_made, frames_taken) = ctx.frame_object_counts();
            let mut bytes = Vec::new();
            for i in [2, 3, 4, 1, 1, 1, 1] {
                let again = frame(i);
                bytes.push(ctx.allocated_bytes());
                if i == 1 {
                    assert!(
                        again == first,
                        "{}: frame 1 changed when rendered into recycled images",
                        method.short_name()
                    );
                }
            }
            // Frame 1 again and again takes every image from the pool and
            // what other frames left is freed within two frames: memory
            // stops changing, at about one frame's (the splats of the
            // frames before may differ by a few vertices).
            let (created_after, reused, _) = ctx.pool_counts();
            assert!(reused > 0, "{}: nothing reused", method.short_name());
            // Each frame's command pool, fence and timestamp pools are the
            // first frame's: none is made after it.
            let (frames_made_after, frames_taken_after) = ctx.frame_object_counts();
            assert_eq!(
                frames_made_after,
                frames_made,
                "{}: frames made their own command pools",
                method.short_name()
            );
            assert!(
                frames_taken_after - frames_taken >= bytes.len() as u64,
                "{}: {} frames took {} kept command pools",
                method.short_name(),
                bytes.len(),
                frames_taken_after - frames_taken
            );
            let n = bytes.len();
            assert!(
                bytes[n - 1] < one_frame + one_frame / 10,
                "{}: {bytes:?} vs one frame's {one_frame}",
                method.short_name()
            );
            assert_eq!(
                bytes[n - 2],
                bytes[n - 1],
                "{}: memory grew between two identical frames (created {created} → {created_after}; {bytes:?} vs {one_frame})",
                method.short_name()
            );
        }
    });
}

#[test]
fn render_without_a_method_is_layered_with_two_layers_and_its_help_gives_the_common_tasks() {
    // The default by the quality-per-time table of docs/BENCHMARKS.md
    // (issue 28): layered with 2 layers.
    let dir = scratch("seq-default-method");
    let out = |name: &str| dir.join(name);
    render(&out("default.png"), &[]);
    render(
        &out("layered2.png"),
        &["--method", "layered", "--layers", "2"],
    );
    render(&out("layered.png"), &["--method", "layered"]);
    render(&out("rdb.png"), &["--method", "rdb"]);
    // The raster by docs/BENCHMARKS.md's table: compute where the device
    // has 64-bit buffer atomics (lavapipe has).
    render(&out("compute.png"), &["--raster", "compute"]);
    render(&out("sprites.png"), &["--raster", "sprites"]);
    assert_eq!(bytes(out("default.png")), bytes(out("layered2.png")));
    assert_eq!(bytes(out("default.png")), bytes(out("layered.png")));
    assert_eq!(bytes(out("default.png")), bytes(out("compute.png")));
    assert_ne!(bytes(out("default.png")), bytes(out("sprites.png")));
    // Not a method whose image would equal any other's here.
    assert_ne!(bytes(out("default.png")), bytes(out("rdb.png")));
    let o = pointlens(&["render", "--help"]);
    assert!(o.status.success());
    let help = String::from_utf8_lossy(&o.stdout);
    for task in [
        "--focus-pixel",
        "--orbit 360",
        "--focus-from",
        "tile.laz",
        "--frame-range 101-200 --skip-existing",
        "default: layered",
    ] {
        assert!(
            help.contains(task),
            "'{task}' not in render --help:\n{help}"
        );
    }
}

#[test]
fn render_without_ssaa_takes_three_on_the_compute_raster_four_on_the_sprites_and_one_for_accum() {
    // The default K follows the raster (docs/BENCHMARKS.md, "The default
    // K follows the raster"): the compute raster's rotated grid at K = 3
    // sees edges more finely than the sprites' grid at 4. accum's is 1 on
    // either when its lens positions are at least the raster's K² samples,
    // each moving the pixel's sample ("accum's default K").
    let dir = scratch("seq-default-ssaa");
    let out = |name: &str| dir.join(name);
    let ssaa_of = |name: &str| -> u64 {
        let t: serde_json::Value =
            serde_json::from_slice(&bytes(out(&format!("{name}.json")))).expect("timings JSON");
        t["ssaa"].as_u64().expect("ssaa in the timings")
    };
    for (name, flags) in [
        ("default", &[][..]),
        ("k3", &["--ssaa", "3"][..]),
        ("k4", &["--ssaa", "4"][..]),
        ("sprites", &["--raster", "sprites"][..]),
        ("sprites-k3", &["--raster", "sprites", "--ssaa", "3"][..]),
        ("sprites-k4", &["--raster", "sprites", "--ssaa", "4"][..]),
        ("accum", &["--method", "accum", "--samples", "16"][..]),
        (
            "accum-k1",
            &["--method", "accum", "--samples", "16", "--ssaa", "1"][..],
        ),
        (
            "accum-k3",
            &["--method", "accum", "--samples", "16", "--ssaa", "3"][..],
        ),
        (
            "accum-sprites",
            &[
                "--method",
                "accum",
                "--samples",
                "16",
                "--raster",
                "sprites",
            ][..],
        ),
        // Fewer lens positions than the raster's K² samples keep its K.
        ("accum8", &["--method", "accum", "--samples", "8"][..]),
    ] {
        let (b, png) = (bunny(), out(&format!("{name}.png")).display().to_string());
        let json = out(&format!("{name}.json")).display().to_string();
        // SMALL without its --ssaa.
        let mut args = vec!["render", &b, "-o", &png, "--timings-json", &json];
        args.extend(["--width", "48", "--height", "36", "--device", "llvmpipe"]);
        args.extend(flags);
        let o = pointlens(&args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        assert!(!stderr(&o).contains("validation"), "{}", stderr(&o));
    }
    assert_eq!((ssaa_of("default"), ssaa_of("sprites")), (3, 4));
    assert_eq!(bytes(out("default.png")), bytes(out("k3.png")));
    assert_ne!(bytes(out("default.png")), bytes(out("k4.png")));
    assert_eq!(bytes(out("sprites.png")), bytes(out("sprites-k4.png")));
    assert_ne!(bytes(out("sprites.png")), bytes(out("sprites-k3.png")));
    assert_eq!((ssaa_of("accum"), ssaa_of("accum-sprites")), (1, 1));
    assert_eq!(ssaa_of("accum8"), 3);
    assert_eq!(bytes(out("accum.png")), bytes(out("accum-k1.png")));
    assert_ne!(bytes(out("accum.png")), bytes(out("accum-k3.png")));
}

#[test]
fn pointlens_alone_prints_its_help_and_fails() {
    let o = pointlens(&[]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert!(err.contains("Usage: pointlens"), "{err}");
    assert!(err.contains("--list-devices"), "{err}");
}

#[test]
fn a_lidar_path_in_file_coordinates_with_autofocus_per_frame() {
    // A fly-over of the Autzen tile with the keyframes in the file's
    // coordinates (feet of a state plane): frame 1 equals the same camera
    // rendered alone from a camera file, and --focus-pixel refocuses every
    // frame on what the image centre sees.
    let dir = scratch("seq-lidar");
    let las = root().join("data/autzen_trim.las").display().to_string();
    let key1 = r#""eye": [636300.0, 848700.0, 1100.0], "target": [636590.0, 849216.0, 460.0], "up": [0, 0, 1], "aperture_radius": 6.0, "focus_distance": 900, "fovy_deg": 50"#;
    let key2 = r#""eye": [636900.0, 848700.0, 1000.0], "target": [636700.0, 849216.0, 460.0], "up": [0, 0, 1], "aperture_radius": 6.0, "focus_distance": 900, "fovy_deg": 50"#;
    let path = dir.join("fly.json");
    std::fs::write(
        &path,
        format!(
            r#"{{"keyframes": [{{"frame": 1, "coordinates": "file", {key1}}}, {{"frame": 3, "coordinates": "file", {key2}}}]}}"#
        ),
    )
    .unwrap();
    let run = |out: &Path, extra: &[&str]| -> Output {
        let out = out.display().to_string();
        let mut args = vec!["render", las.as_str(), "-o", &out];
        args.extend(SMALL);
        args.extend(extra);
        let o = pointlens(&args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        o
    };
    let path_s = path.display().to_string();
    run(&dir.join("fly_%d.png"), &["--path", &path_s]);
    let cam = dir.join("key1.json");
    std::fs::write(&cam, format!(r#"{{"coordinates": "file", {key1}}}"#)).unwrap();
    run(
        &dir.join("alone.png"),
        &["--camera", &cam.display().to_string()],
    );
    assert!(bytes(dir.join("fly_1.png")) == bytes(dir.join("alone.png")));
    // Autofocus on the centre pixel, frame by frame: the printed path's
    // focus distances are the depths seen there, not the keyframes' 900.
    let o = run(
        &dir.join("af_%d.png"),
        &[
            "--path",
            &path_s,
            "--focus-pixel",
            "24,18",
            "--print-camera",
        ],
    );
    let printed: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let focus: Vec<f64> = printed["keyframes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k["focus_distance"].as_f64().unwrap())
        .collect();
    assert_eq!(focus.len(), 3);
    assert!(focus.iter().all(|f| (*f - 900.0).abs() > 1.0), "{focus:?}");
    assert!(focus[0] != focus[2], "{focus:?}");
    // The printed path keeps the file's coordinates.
    assert_eq!(printed["keyframes"][0]["coordinates"], "file");
    assert_eq!(
        printed["keyframes"][0]["eye"][0].as_f64().unwrap(),
        636300.0
    );
}
