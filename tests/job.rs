//! The render job as a library (`pointlens::job`): what `pointlens render`
//! does behind its flags, called directly. Its checks before any cloud,
//! its plan (every frame's camera, `--skip-existing`), and its frames on
//! lavapipe against the same frames rendered alone.

mod common;

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use common::{file_names, root, scratch, with_gpu};
use glam::Vec3;
use pointlens::camera::{self, CameraSpec};
use pointlens::input::load_cloud;
use pointlens::job::{JobEvent, JobSpec, Passes, RenderJob, Shot, Written};
use pointlens::options::{Lod, Method};
use pointlens::render::{RenderOptions, Renderer, SplatSize};
use pointlens::report::FrameReport;
use pointlens::scene::Scenes;
use pointlens::sequence::{CameraPath, FrameRange, Motion};
use pointlens::{Error, PointCloud};

fn bunny() -> PointCloud {
    load_cloud(&root().join("data/bunny_colored.ply"), None, &mut |_, _| {}).expect("the bunny")
}

/// A job of `shot` into `output` at 64×48, pinhole, the defaults
/// elsewhere.
fn spec(shot: Shot, output: &Path) -> JobSpec {
    JobSpec {
        shot,
        output: output.to_path_buf(),
        frame_range: None,
        skip_existing: false,
        camera_file: None,
        camera_flags: CameraSpec {
            width: Some(64),
            height: Some(48),
            ..CameraSpec::default()
        },
        focus_pixel: None,
        method: Method::Pinhole,
        ssaa: Some(2),
        samples_per_pass: None,
        background: Vec3::ZERO,
        lod: Lod::default(),
        written: Written::default(),
        timings_json: None,
        fps: None,
    }
}

fn orbit(frames: u32) -> Shot {
    Shot::Motion(Motion {
        frames,
        orbit_deg: Some(90.0),
        focus: None,
        aperture: None,
    })
}

fn error_of(spec: JobSpec) -> String {
    match RenderJob::new(spec) {
        Ok(_) => panic!("the job was accepted"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_job_checks_its_outputs_and_options_before_any_cloud() {
    let dir = scratch("job-checks");
    let png = dir.join("a.png");
    let pattern = dir.join("a_%04d.png");
    let cases: Vec<(&str, JobSpec, &str)> = vec![
        (
            "a sequence into one file",
            spec(orbit(3), &png),
            "a sequence needs a frame number",
        ),
        (
            "one image into a pattern",
            spec(Shot::Single, &pattern),
            "a frame number pattern, but one frame",
        ),
        (
            "a range of one image",
            JobSpec {
                frame_range: Some(FrameRange { first: 1, last: 1 }),
                ..spec(Shot::Single, &png)
            },
            "are for sequences",
        ),
        (
            "skip-existing of one image",
            JobSpec {
                skip_existing: true,
                ..spec(Shot::Single, &png)
            },
            "are for sequences",
        ),
        (
            "a range beyond the frames",
            JobSpec {
                frame_range: Some(FrameRange { first: 2, last: 9 }),
                ..spec(orbit(3), &pattern)
            },
            "outside the sequence's frames 1-3",
        ),
        (
            "an output of no image format",
            spec(Shot::Single, &dir.join("a.jpg")),
            "a.jpg",
        ),
        (
            "a motion of no frames",
            spec(orbit(0), &pattern),
            "--frames must be at least 1",
        ),
        (
            "a range that runs backwards",
            JobSpec {
                frame_range: Some(FrameRange { first: 3, last: 2 }),
                ..spec(orbit(3), &pattern)
            },
            "A <= B",
        ),
        (
            "a missing folder",
            spec(Shot::Single, &dir.join("no/a.png")),
            "no directory",
        ),
        (
            "a numbered folder missing for frame 2",
            spec(orbit(2), &dir.join("out_%d/f.png")),
            "out_2",
        ),
        (
            "a timings file in a missing folder",
            JobSpec {
                timings_json: Some(dir.join("no/t.json")),
                ..spec(Shot::Single, &png)
            },
            "--timings-json",
        ),
        (
            "passes into a PNG",
            JobSpec {
                written: Written {
                    transparent: false,
                    passes: Passes {
                        z: true,
                        coc: false,
                    },
                },
                ..spec(Shot::Single, &png)
            },
            "--passes writes EXR channels",
        ),
        (
            "lod-blur without a traversal",
            JobSpec {
                lod: Lod {
                    px: 0.0,
                    blur: Some(1.0),
                    cull_back_faces: false,
                },
                ..spec(Shot::Single, &png)
            },
            "--lod-blur needs --lod-px above 0",
        ),
        (
            "back faces culled without a traversal",
            JobSpec {
                lod: Lod {
                    px: 0.0,
                    blur: None,
                    cull_back_faces: true,
                },
                ..spec(Shot::Single, &png)
            },
            "--cull-back-faces needs --lod-px above 0",
        ),
    ];
    std::fs::create_dir_all(dir.join("out_1")).unwrap();
    for (what, spec, phrase) in cases {
        let message = error_of(spec);
        assert!(
            message.contains(phrase),
            "{what}: '{phrase}' not in: {message}"
        );
        assert_eq!(message.lines().count(), 1, "{what}: {message}");
    }
    assert_eq!(file_names(&dir), ["out_1"], "no check wrote a file");
    // What passes the checks: a sequence into a pattern, one image into a
    // file; the range is the shot's.
    let job = RenderJob::new(spec(orbit(3), &pattern)).unwrap();
    assert!(job.is_sequence());
    assert_eq!(job.range(), FrameRange { first: 1, last: 3 });
    assert_eq!(job.output_of(2), dir.join("a_0002.png"));
    let job = RenderJob::new(spec(Shot::Single, &png)).unwrap();
    assert!(!job.is_sequence());
    assert_eq!(job.output_of(1), png);
}

#[test]
fn the_plan_resolves_every_frame_and_skips_the_existing_ones() {
    let dir = scratch("job-plan");
    let cloud = bunny();
    let pattern = dir.join("f_%d.png");
    let all = RenderJob::new(spec(orbit(4), &pattern))
        .unwrap()
        .plan(&cloud)
        .unwrap();
    assert_eq!(all.skipped, 0);
    let numbers: Vec<u32> = all.frames.iter().map(|f| f.number).collect();
    assert_eq!(numbers, [1, 2, 3, 4]);
    // Frame 1 is the camera the flags resolve to (auto-framed); the others
    // are the motion's change of it.
    let (lo, hi) = cloud.bounds();
    let flags = spec(Shot::Single, &dir.join("x.png")).camera_flags;
    let base = camera::resolve(&flags, lo, hi, &cloud.positions).unwrap();
    let Shot::Motion(motion) = orbit(4) else {
        unreachable!()
    };
    for frame in &all.frames {
        assert_eq!(frame.camera, motion.camera(&base, frame.number));
        assert_eq!(frame.output, dir.join(format!("f_{}.png", frame.number)));
    }
    // Frame 2's file exists: --skip-existing leaves it, and it is untouched.
    std::fs::write(dir.join("f_2.png"), b"kept").unwrap();
    let plan = RenderJob::new(JobSpec {
        skip_existing: true,
        ..spec(orbit(4), &pattern)
    })
    .unwrap()
    .plan(&cloud)
    .unwrap();
    assert_eq!(plan.skipped, 1);
    let numbers: Vec<u32> = plan.frames.iter().map(|f| f.number).collect();
    assert_eq!(numbers, [1, 3, 4]);
    assert_eq!(plan.frames[1].camera, all.frames[2].camera);
    assert_eq!(std::fs::read(dir.join("f_2.png")).unwrap(), b"kept");
}

#[test]
fn a_bad_keyframe_fails_the_plan_naming_its_frame_and_file() {
    let dir = scratch("job-keyframe");
    let file = dir.join("path.json");
    // Frame 3's eye is its target.
    std::fs::write(
        &file,
        r#"{ "keyframes": [
            { "frame": 1, "eye": [0, 0.1, 0.5], "target": [0, 0.1, 0] },
            { "frame": 3, "eye": [0, 0.1, 0], "target": [0, 0.1, 0] } ] }"#,
    )
    .unwrap();
    let shot = Shot::Path {
        path: CameraPath::from_json_file(&file).unwrap(),
        file: file.clone(),
    };
    let job = RenderJob::new(spec(shot, &dir.join("p_%d.png"))).unwrap();
    let message = job.plan(&bunny()).unwrap_err().to_string();
    let expected = format!("frame 3 of {}: camera: ", file.display());
    assert!(message.starts_with(&expected), "{message}");
    assert_eq!(message.lines().count(), 1, "{message}");
}

/// The bytes of a file.
fn bytes(p: &PathBuf) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn a_sequence_through_the_job_equals_its_frames_rendered_alone() {
    let dir = scratch("job-frames");
    let cloud = bunny();
    let timings = dir.join("t.json");
    let job = RenderJob::new(JobSpec {
        timings_json: Some(timings.clone()),
        method: Method::Fast(Default::default()),
        camera_flags: CameraSpec {
            aperture_radius: Some(0.01),
            ..spec(Shot::Single, &timings).camera_flags
        },
        ..spec(orbit(3), &dir.join("o_%d.png"))
    })
    .unwrap();
    let plan = job.plan(&cloud).unwrap();
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        // Stopped before the first frame: nothing is written.
        let stop = AtomicBool::new(true);
        let err = job
            .render(
                &renderer,
                Scenes::One(&scene),
                &plan,
                &stop,
                0.0,
                &mut |_| Ok(()),
            )
            .unwrap_err();
        assert!(
            matches!(
                err,
                Error::Interrupted {
                    written: 0,
                    total: 3,
                    next: 1
                }
            ),
            "{err}"
        );
        assert!(file_names(&dir).is_empty(), "{:?}", file_names(&dir));

        let mut events = Vec::new();
        let outcome = job
            .render(
                &renderer,
                Scenes::One(&scene),
                &plan,
                &AtomicBool::new(false),
                12.5,
                &mut |event| {
                    events.push(match event {
                        JobEvent::Camera { number, .. } => format!("camera {number}"),
                        JobEvent::Written { number, output, .. } => {
                            assert!(output.is_file(), "{} not written", output.display());
                            format!("written {number}")
                        }
                        other => format!("{other:?}"),
                    });
                    Ok(())
                },
            )
            .unwrap();
        let expected: Vec<String> = (1..=3)
            .flat_map(|n| [format!("camera {n}"), format!("written {n}")])
            .collect();
        assert_eq!(events, expected);
        assert_eq!(outcome.reports.len(), 3);
        for (frame, report) in plan.frames.iter().zip(&outcome.reports) {
            assert_eq!((report.width, report.height), (64, 48));
            assert_eq!(report.method, "fast");
            assert_eq!(report.points, cloud.len());
            assert_eq!(report.load_ms, 12.5);
            // The same frame rendered alone, written as the job writes it.
            let options = RenderOptions {
                camera: frame.camera,
                method: Method::Fast(Default::default()),
                ssaa: 2,
                samples_per_pass: None,
                background: Vec3::ZERO,
                lod: Lod::default(),
            };
            let alone = dir.join(format!("alone_{}.png", frame.number));
            let rendered = renderer.render_srgb8(&scene, &options).unwrap();
            rendered.image.write_png(&alone).unwrap();
            assert!(
                bytes(&alone) == bytes(&frame.output),
                "frame {} differs from the frame rendered alone",
                frame.number
            );
        }
        let numbers: Vec<u32> = outcome.cameras.iter().map(|c| c.0).collect();
        assert_eq!(numbers, [1, 2, 3]);
        // An observer's error ends the job after the frame it was told of.
        let refused = job.render(
            &renderer,
            Scenes::One(&scene),
            &plan,
            &AtomicBool::new(false),
            0.0,
            &mut |event| match event {
                JobEvent::Written { number: 2, .. } => Err(Error::InvalidArgument("enough".into())),
                _ => Ok(()),
            },
        );
        assert_eq!(refused.unwrap_err().to_string(), "enough");

        job.write_timings(&outcome.reports).unwrap();
        let text = std::fs::read_to_string(&timings).unwrap();
        let read: Vec<FrameReport> = serde_json::from_str(&text).expect("an array of reports");
        assert_eq!(read, outcome.reports);
    });
}

/// `RenderJob::run` writes a sequence's files on a writer thread while
/// the next frames render; `RenderJob::render` writes each before the next.
/// The files are the same bytes for every method, PNG and EXR with passes
/// alike, and `run` tells them written in frame order.
#[test]
fn frames_in_flight_write_the_bytes_of_frames_written_one_at_a_time() {
    let dir = scratch("job-in-flight");
    let bunny_path = root().join("data/bunny_colored.ply");
    let cloud = bunny();
    let device = pointlens::vk::ContextOptions {
        validation: true,
        device: Some("llvmpipe".into()),
    };
    let methods = [
        Method::Pinhole,
        Method::Fast(Default::default()),
        Method::Rdb(Default::default()),
        Method::Layered(Default::default()),
        Method::Accum(pointlens::options::AccumOptions { samples: 4 }),
    ];
    for (i, method) in methods.into_iter().enumerate() {
        let exr = i % 2 == 1;
        let name = |kind: &str| match exr {
            true => dir.join(format!("{kind}{i}_%d.exr")),
            false => dir.join(format!("{kind}{i}_%d.png")),
        };
        let job_into = |output: PathBuf| {
            RenderJob::new(JobSpec {
                method,
                camera_flags: CameraSpec {
                    aperture_radius: Some(0.01),
                    ..spec(Shot::Single, &output).camera_flags
                },
                written: Written {
                    passes: Passes { z: exr, coc: exr },
                    ..Written::default()
                },
                ..spec(orbit(4), &output)
            })
            .unwrap()
        };
        let in_flight = job_into(name("flight"));
        let mut order = Vec::new();
        let one_at_a_time_here = common::gpu_lock();
        let outcome = in_flight
            .run(
                &pointlens::scene::SceneSpec::of(&bunny_path),
                &device,
                &mut |event| {
                    if let JobEvent::Written { number, .. } = event {
                        order.push(number);
                    }
                    Ok(())
                },
            )
            .unwrap();
        drop(one_at_a_time_here);
        assert_eq!(order, [1, 2, 3, 4], "{}", method.short_name());
        assert_eq!(outcome.reports.len(), 4);
        let one_at_a_time = job_into(name("one"));
        let plan = one_at_a_time.plan(&cloud).unwrap();
        with_gpu(|ctx| {
            let renderer = Renderer::new(ctx).unwrap();
            let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
            one_at_a_time
                .render(
                    &renderer,
                    Scenes::One(&scene),
                    &plan,
                    &AtomicBool::new(false),
                    0.0,
                    &mut |_| Ok(()),
                )
                .unwrap();
        });
        for frame in &plan.frames {
            let flight = in_flight.output_of(frame.number);
            assert!(
                bytes(&flight) == bytes(&frame.output),
                "{}: frame {} differs",
                method.short_name(),
                frame.number
            );
        }
    }
}
