//! The `pointlens` binary as a user runs it: outputs, timings, and bad input
//! giving one clear line on stderr, a non-zero exit and no output file.

mod common;

use std::process::Output;

use common::{assert_fails, pointlens, root, scratch, write_ascii_ply};
use pointlens::image_io::read_image;
use pointlens::passes::rdb::TilePlan;

fn bunny() -> String {
    root().join("data/bunny_colored.ply").display().to_string()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn render_writes_png_and_linear_exr_with_timings_and_no_validation_message() {
    let dir = scratch("cli-render");
    let png = dir.join("bunny.png");
    let exr = dir.join("bunny.exr");
    let json = dir.join("timings.json");
    let common = [
        "--width",
        "96",
        "--height",
        "72",
        "--device",
        "llvmpipe",
        "--validate",
    ];
    let bunny = bunny();
    let mut args = vec!["render", &bunny, "-o"];
    let png_s = png.display().to_string();
    args.push(&png_s);
    args.extend(common);
    let json_s = json.display().to_string();
    args.extend(["--timings", "--timings-json", &json_s]);
    let o = pointlens(&args);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("validation"), "{err}");
    assert!(
        !err.contains("in view"),
        "a warning of an empty frame: {err}"
    );
    for pass in [
        "gbuffer.raster",
        "gbuffer.resolve",
        "output",
        "frame wall",
        "host (wall - gpu)",
        "readback copy",
    ] {
        assert!(err.contains(pass), "timings lack {pass}: {err}");
    }
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(t["passes"].as_array().unwrap().len() >= 3);
    let wall_ms = t["frame_wall_ms"].as_f64().unwrap();
    assert!(wall_ms > 0.0);
    // The readback's copy is measured, and within the frame's host share.
    let readback_ms = t["readback_ms"].as_f64().unwrap();
    let host_ms = wall_ms - t["gpu_total_ms"].as_f64().unwrap();
    assert!(
        readback_ms > 0.0 && readback_ms <= host_ms,
        "{readback_ms} of {host_ms}"
    );

    let exr_s = exr.display().to_string();
    let mut args = vec!["render", &bunny, "-o", &exr_s];
    args.extend(common);
    let o = pointlens(&args);
    assert!(o.status.success(), "{}", stderr(&o));

    // The EXR holds linear values: sRGB-encoding them gives the PNG's bytes.
    let a = read_image(&png).unwrap();
    let b = read_image(&exr).unwrap();
    assert_eq!((a.width, a.height), (96, 72));
    let mut max_diff = 0.0f32;
    let mut lit = 0;
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        for c in 0..3 {
            max_diff = max_diff.max((p[c] - q[c]).abs());
        }
        if q[0] + q[1] + q[2] > 0.05 {
            lit += 1;
        }
    }
    assert!(
        max_diff < 0.01,
        "PNG and EXR disagree by {max_diff} (linear)"
    );
    assert!(lit > 500, "the bunny is missing: {lit} lit pixels");
    // Linear, not sRGB-encoded: some mid-grey values exist whose sRGB
    // encoding is well above the stored value.
    assert!(b.pixels.iter().any(|p| p[0] > 0.05 && p[0] < 0.2));
}

/// A camera that sees nothing of the cloud (looking away from it, as a
/// camera file made for a cloud re-centred elsewhere does) renders the
/// background and says so in one warning (a sequence: the first empty
/// frame and their count); -q silences it.
#[test]
fn a_frame_without_the_scene_warns() {
    let dir = scratch("cli-empty-frame");
    let png = dir.join("away.png");
    let png_s = png.display().to_string();
    let bunny = bunny();
    let away = [
        "render", &bunny, "-o", &png_s, "--width", "48", "--height", "36", "--device", "llvmpipe",
        "--eye", "0,0,5", "--target", "0,0,10",
    ];
    let o = pointlens(&away);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("frame 1: no point of the scene is in view, only the background"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(png.is_file());
    let quiet: Vec<&str> = away.iter().copied().chain(["-q"]).collect();
    let o = pointlens(&quiet);
    assert!(o.status.success());
    assert_eq!(stderr(&o), "");
    // A sequence names its first empty frame and counts them at the end.
    let seq = dir.join("away_%04d.png").display().to_string();
    let mut frames = away.to_vec();
    frames[3] = &seq;
    frames.extend(["--frames", "3"]);
    let o = pointlens(&frames);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert_eq!(err.lines().count(), 2, "{err}");
    assert!(err.contains("frame 1: no point"), "{err}");
    assert!(
        err.contains("3 of 3 frames showed nothing of the scene"),
        "{err}"
    );
}

#[test]
fn info_prints_count_bounds_and_attributes() {
    let o = pointlens(&["info", &bunny()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.contains("points: 35947"), "{out}");
    assert!(out.contains("red") && out.contains("nx"), "{out}");
    assert!(out.contains("bounds_min"), "{out}");
}

#[test]
fn print_camera_round_trips_through_a_camera_file() {
    let dir = scratch("cli-camera");
    let out = dir.join("a.png");
    let out_s = out.display().to_string();
    let o = pointlens(&[
        "render",
        &bunny(),
        "-o",
        &out_s,
        "--width",
        "64",
        "--height",
        "48",
        "--print-camera",
        "--device",
        "llvmpipe",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let cam = dir.join("cam.json");
    std::fs::write(&cam, &o.stdout).unwrap();
    let out2 = dir.join("b.png");
    let out2_s = out2.display().to_string();
    let cam_s = cam.display().to_string();
    let o = pointlens(&[
        "render",
        &bunny(),
        "-o",
        &out2_s,
        "--camera",
        &cam_s,
        "--device",
        "llvmpipe",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(read_image(&out).unwrap(), read_image(&out2).unwrap());
}

#[test]
fn bad_input_gives_one_line_and_no_output() {
    let dir = scratch("cli-bad");
    let out = dir.join("out.png");
    let out_s = out.display().to_string();
    let b = bunny();

    assert_fails(
        &["render", "no/such.ply", "-o", &out_s],
        "no/such.ply",
        &out,
    );
    assert_fails(
        &["render", &b, "-o", &dir.join("x.jpg").display().to_string()],
        "unsupported output format",
        &dir.join("x.jpg"),
    );
    assert_fails(
        &["render", &b, "-o", &out_s, "--method", "magic"],
        "unknown method 'magic'; available methods: pinhole, fast, rdb, layered, accum",
        &out,
    );
    assert_fails(&["render", &b, "-o", &out_s, "--ssaa", "0"], "--ssaa", &out);
    assert_fails(
        &[
            "render",
            &b,
            "-o",
            &out_s,
            "--raster",
            "compute",
            "--samples-per-pass",
            "4",
        ],
        "--samples-per-pass limits the sprite raster's passes",
        &out,
    );
    for (flags, phrase) in [
        (
            &["--lod-px", "-1"][..],
            "--lod-px must be between 0 and 1024, not -1",
        ),
        (
            &["--lod-px", "NaN"],
            "--lod-px must be between 0 and 1024, not NaN",
        ),
        (&["--lod-px", "two"], "'two' is not a number"),
        (
            &["--lod-blur", "0"],
            "--lod-blur must be above 0 and at most 16, not 0",
        ),
        (
            &["--lod-blur", "inf"],
            "--lod-blur must be above 0 and at most 16, not inf",
        ),
        (
            &["--lod-px", "0", "--lod-blur", "1"],
            "--lod-blur needs --lod-px above 0",
        ),
        (
            &["--lod-px", "0", "--cull-back-faces"],
            "--cull-back-faces needs --lod-px above 0",
        ),
    ] {
        let args: Vec<&str> = ["render", &b, "-o", &out_s]
            .iter()
            .chain(flags)
            .copied()
            .collect();
        assert_fails(&args, phrase, &out);
    }
    // Points without normals have nothing to cull by (the mug's file).
    let mug = root()
        .join("data/pcl_table_scene_mug_rgb.ply")
        .display()
        .to_string();
    assert_fails(
        &["render", &mug, "-o", &out_s, "--cull-back-faces"],
        "pcl_table_scene_mug_rgb.ply: --cull-back-faces needs the points' normals, and the file has none",
        &out,
    );
    // Refused by the header, before the file is read: a PLY file without
    // normals whose payload is cut short says so, not that it is short.
    let short = dir.join("short.ply");
    let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\n\
        property float x\nproperty float y\nproperty float z\nend_header\n"
        .to_vec();
    bytes.extend([0u8; 100]);
    std::fs::write(&short, bytes).unwrap();
    let short_s = short.display().to_string();
    assert_fails(
        &["render", &short_s, "-o", &out_s, "--cull-back-faces"],
        "short.ply: --cull-back-faces needs the points' normals",
        &out,
    );
    assert_fails(&["render", &short_s, "-o", &out_s], "truncated", &out);
    assert_fails(
        &["render", &b, "-o", &out_s, "--focus-distance", "-1"],
        "focus_distance",
        &out,
    );
    assert_fails(&["render", &b, "-o", &out_s, "--width", "0"], "width", &out);
    // Beyond the device's images a frame renders in tiles (tests/tiles.rs);
    // beyond 65536 px a side it is refused.
    assert_fails(
        &[
            "render", &b, "-o", &out_s, "--width", "100000", "--device", "llvmpipe",
        ],
        "65536",
        &out,
    );
    assert_fails(
        &[
            "render",
            &b,
            "-o",
            &out_s,
            "--method",
            "rdb",
            "--rdb-memory-mb",
            "0",
        ],
        "--rdb-memory-mb",
        &out,
    );
    assert_fails(
        &[
            "render",
            &b,
            "-o",
            &out_s,
            "--method",
            "rdb",
            "--rdb-bins",
            "17",
        ],
        "--rdb-bins",
        &out,
    );
    // --layers out of 1..=8: clap's one line naming the flag and the
    // range, and the usage error's exit status 2.
    for k in ["0", "9"] {
        let args = [
            "render", &b, "-o", &out_s, "--method", "layered", "--layers", k,
        ];
        assert_fails(&args, "--layers must be between 1 and 8", &out);
        assert_eq!(pointlens(&args).status.code(), Some(2), "--layers {k}");
    }
    assert_fails(
        &["render", &b, "-o", &out_s, "--frobnicate"],
        "frobnicate",
        &out,
    );
    assert_fails(
        &["render", &b, "-o", &out_s, "--device", "no-such-gpu"],
        "no-such-gpu",
        &out,
    );
    assert_fails(
        &[
            "render",
            &b,
            "-o",
            &dir.join("missing/out.png").display().to_string(),
            "--device",
            "llvmpipe",
        ],
        "missing",
        &dir.join("missing/out.png"),
    );

    let cam = dir.join("cam.json");
    let cam_s = cam.display().to_string();
    for (content, phrase) in [
        // A camera file must be complete: this one lacks the focus distance.
        (
            r#"{"width": 64, "height": 48, "eye": [0, 0, 1], "target": [0, 0, 0], "fovy_deg": 40, "aperture_radius": 0.01}"#,
            "focus_distance",
        ),
        ("{ not json", "cam.json"),
    ] {
        std::fs::write(&cam, content).unwrap();
        assert_fails(
            &["render", &b, "-o", &out_s, "--camera", &cam_s],
            phrase,
            &out,
        );
    }

    let ply = dir.join("bad.ply");
    std::fs::write(&ply, "this is not a ply file\n").unwrap();
    assert_fails(
        &["render", &ply.display().to_string(), "-o", &out_s],
        "bad.ply",
        &out,
    );
    write_ascii_ply(&ply, &[]);
    assert_fails(&["info", &ply.display().to_string()], "bad.ply", &out);

    assert_fails(
        &[
            "render",
            &b,
            "-o",
            &out_s,
            "--focus-pixel",
            "0,0",
            "--device",
            "llvmpipe",
        ],
        "sees no point",
        &out,
    );
    assert_fails(
        &["render", &b, "-o", &out_s, "--focus-pixel", "3"],
        "X,Y",
        &out,
    );

    // An existing output survives a failed render untouched.
    std::fs::write(&out, b"old").unwrap();
    let o = pointlens(&["render", &b, "-o", &out_s, "--method", "magic"]);
    assert!(!o.status.success());
    assert_eq!(std::fs::read(&out).unwrap(), b"old");
}

#[test]
fn focus_pixel_sets_the_printed_focus_distance() {
    let dir = scratch("cli-focus");
    let out = dir.join("f.png").display().to_string();
    let b = bunny();
    let focus_of = |method: &str, extra: &[&str]| -> Result<f64, String> {
        let mut args = vec!["render", &b, "-o", &out, "--width", "64", "--height", "48"];
        args.extend(["--device", "llvmpipe", "--print-camera", "--method", method]);
        args.extend(extra);
        let o = pointlens(&args);
        if !o.status.success() {
            return Err(stderr(&o));
        }
        let cam: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        Ok(cam["focus_distance"].as_f64().unwrap())
    };
    let focus = |extra: &[&str]| focus_of("fast", extra).unwrap();
    let centre = focus(&[]);
    let at_pixel = focus(&["--focus-pixel", "32,24"]);
    // The default focuses on the model's centre; the pixel at the image
    // centre sees the bunny's front surface, nearer than its centre.
    assert!(
        at_pixel > 0.0 && at_pixel < centre,
        "{at_pixel} vs {centre}"
    );
    // Every method focuses alike: accum's default K (1) is not the probe's,
    // which is the pinhole G-buffer's (3 here). A row across the bunny's
    // silhouette, where one sample and nine see different surfaces.
    for x in (6..60).step_by(6) {
        let pixel = format!("{x},24");
        let extra = ["--focus-pixel", pixel.as_str()];
        let accum = ["--focus-pixel", pixel.as_str(), "--samples", "16"];
        assert_eq!(
            focus_of("accum", &accum),
            focus_of("fast", &extra),
            "pixel {pixel}"
        );
    }
}

#[test]
fn rdb_memory_budget_tiles_the_frame_without_changing_a_bit() {
    let dir = scratch("cli-rdb-tiles");
    let b = bunny();
    let render = |name: &str, extra: &[&str]| -> Vec<u8> {
        let out = dir.join(name).display().to_string();
        let mut args = vec!["render", &b, "-o", &out, "--width", "64", "--height", "48"];
        args.extend(["--method", "rdb", "--rdb-bins", "16", "--timings"]);
        args.extend(["--device", "llvmpipe"]);
        args.extend(extra);
        let o = pointlens(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        let report = stderr(&o);
        let resolves = report
            .lines()
            .find(|l| l.starts_with("rdb.resolve"))
            .and_then(|l| l.split_whitespace().last())
            .unwrap_or_else(|| panic!("no rdb.resolve in the timings:\n{report}"));
        // 64×48 pixels of 16×16 bins are 6.3 MB: tiles of 1 MiB or less.
        let tiles = match extra.is_empty() {
            true => 1,
            false => TilePlan::new(64, 48, 16, 1 << 20, u64::MAX)
                .unwrap()
                .tiles
                .len(),
        };
        assert_eq!(resolves, tiles.to_string(), "timings:\n{report}");
        std::fs::read(&out).unwrap()
    };
    let whole = render("whole.exr", &[]);
    let tiled = render("tiled.exr", &["--rdb-memory-mb", "1"]);
    assert!(whole == tiled, "the tiled EXR differs from the untiled one");
}

/// `%%` is a `%` in every output name, a single image's too (it used to
/// write `50%%.png` literally).
#[test]
fn a_percent_sign_is_written_the_same_for_images_and_sequences() {
    let dir = scratch("cli-percent");
    let bunny = bunny();
    for (name, frames) in [("50%%.png", None), ("s%%_%02d.png", Some("2"))] {
        let out = dir.join(name).display().to_string();
        let mut args = vec![
            "render", &bunny, "-o", &out, "--width", "16", "--height", "12", "--method", "pinhole",
        ];
        if let Some(n) = frames {
            args.extend(["--frames", n]);
        }
        let o = pointlens(&args);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    assert_eq!(
        common::file_names(&dir),
        ["50%.png", "s%_01.png", "s%_02.png"]
    );
}

/// An `up` whose length overflows single precision is still a direction:
/// the image is the unit vector's, byte for byte.
#[test]
fn an_up_of_1e30_is_a_direction() {
    let dir = scratch("cli-up");
    let bunny = bunny();
    let mut images = Vec::new();
    for up in ["0,1,0", "0,1e30,0", "0,1e-30,0"] {
        let out = dir.join(format!("up-{up}.png")).display().to_string();
        let o = pointlens(&[
            "render", &bunny, "-o", &out, "--width", "24", "--height", "16", "--up", up,
        ]);
        assert!(o.status.success(), "--up {up}: {}", stderr(&o));
        images.push(std::fs::read(&out).unwrap());
    }
    assert!(images[1] == images[0] && images[2] == images[0]);
}

/// Splats wider than the frame (a `--splat-size` far above the points'
/// spacing) make a frame slow and show nothing behind them: the render
/// says so in one warning; splats sized by their spacing do not warn.
#[test]
fn splats_wider_than_the_frame_are_warned_of() {
    let dir = scratch("cli-wide-splats");
    let out = dir.join("wide.png").display().to_string();
    let b = bunny();
    let small = ["--width", "16", "--height", "12", "--device", "llvmpipe"];
    let mut args = vec!["render", &b, "-o", &out, "--method", "pinhole"];
    args.extend(small);
    let run = pointlens(&args);
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(
        !stderr(&run).contains("covers the whole frame"),
        "{}",
        stderr(&run)
    );
    args.extend(["--splat-size", "1"]);
    let run = pointlens(&args);
    let err = stderr(&run);
    assert!(run.status.success(), "{err}");
    assert_eq!(
        err.matches("each covers the whole frame").count(),
        1,
        "{err}"
    );
}

/// The README's synopsis ("## Use") names every flag each command takes,
/// as `--help` lists them (but help, version, -v and -q, and --output,
/// written so there): one list of flags, which the synopsis follows.
#[test]
fn the_readme_synopsis_names_every_flag() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let usage = readme
        .split("## Use")
        .nth(1)
        .and_then(|s| s.split("```").nth(1))
        .expect("README.md has a ## Use section with a code block");
    // An option's line of clap's help: "  -o, --output <OUT>" or
    // "      --camera <CAM.json>" (the examples are indented further).
    let flag_of = |line: &str| -> Option<String> {
        let rest = line.strip_prefix("      --").or_else(|| {
            line.strip_prefix("  -")?
                .split_once(", --")
                .map(|(_, long)| long)
        })?;
        let end = rest
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
            .unwrap_or(rest.len());
        Some(format!("--{}", &rest[..end]))
    };
    let mut missing = Vec::new();
    // (the command, the fewest options its --help has: a parse that finds
    // none cannot pass)
    for (command, fewest) in [
        ("", 5),
        ("render", 60),
        ("compare", 4),
        ("bench", 20),
        ("info", 5),
        ("convert", 5),
        ("synth", 7),
    ] {
        // The command's line and the lines continuing it.
        let head = match command {
            "" => "pointlens [".to_string(),
            c => format!("pointlens {c} "),
        };
        let mut lines = usage.lines().skip_while(|l| !l.starts_with(&head));
        let first = lines.next().unwrap_or_else(|| panic!("no '{head}' line"));
        let synopsis: String = std::iter::once(first)
            .chain(lines.take_while(|l| l.starts_with(' ')))
            .collect::<Vec<_>>()
            .join("\n");
        let args: Vec<&str> = [command, "--help"]
            .into_iter()
            .filter(|a| !a.is_empty())
            .collect();
        let help = std::process::Command::new(env!("CARGO_BIN_EXE_pointlens"))
            .args(&args)
            .env_remove("CLICOLOR_FORCE")
            .env("NO_COLOR", "1")
            .output()
            .unwrap();
        assert!(help.status.success(), "{args:?}");
        let help = String::from_utf8_lossy(&help.stdout).into_owned();
        let flags: Vec<String> = help.lines().filter_map(flag_of).collect();
        assert!(flags.len() >= fewest, "{args:?}: {flags:?}");
        for flag in flags {
            let global = ["--help", "--version", "--verbose", "--quiet", "--output"]
                .contains(&flag.as_str());
            let named = synopsis.match_indices(&flag).any(|(i, _)| {
                !synopsis[i + flag.len()..]
                    .starts_with(|c: char| c.is_ascii_alphanumeric() || c == '-')
            });
            if !global && !named {
                missing.push(format!("pointlens {command} {flag}"));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "not in README.md's synopsis: {missing:?}"
    );
}
