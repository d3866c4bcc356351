//! The library's render path is usable without `main.rs`: the example
//! `examples/render_scenes.rs` renders a PLY cloud, a COPC file and a scene
//! of 3D Gaussians through the public API alone (`RenderJob::run` on a
//! `SceneSpec`), under the validation layer, whose any message fails the
//! job.

mod common;

#[path = "../examples/render_scenes.rs"]
mod render_scenes;

use pointlens::image_io::read_image;
use pointlens::vk::ContextOptions;

#[test]
fn the_example_renders_every_kind_of_scene_through_the_library() {
    let dir = common::scratch("library-scenes");
    let device = ContextOptions {
        validation: true,
        device: Some("llvmpipe".into()),
    };
    let images = {
        let _one_at_a_time = common::gpu_lock();
        render_scenes::render_all(&dir, &device).expect("the three scenes render")
    };
    assert_eq!(images.len(), 3);
    for path in &images {
        let image = read_image(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(
            (image.width, image.height),
            (160, 120),
            "{}",
            path.display()
        );
        // Framed on the scene by default: a fair part of the frame shows
        // it (the background is black).
        let lit = image
            .pixels
            .iter()
            .filter(|p| p[0] + p[1] + p[2] > 0.01)
            .count();
        assert!(
            lit > image.pixels.len() / 20,
            "{}: {lit} of {} pixels show the scene",
            path.display(),
            image.pixels.len()
        );
    }
    // The library's image is the command line's, byte for byte: `main.rs`
    // adds nothing but parsing.
    let copc = dir.join("bunny.copc.laz");
    let gaussians = dir.join("gaussians.ply");
    let bunny = common::root().join("data/bunny_colored.ply");
    let layered = ["--method", "layered"];
    let accum = ["--method", "accum", "--samples", "8"];
    for (input, flags, library) in [
        (&bunny, &layered[..], &images[0]),
        (&copc, &layered[..], &images[1]),
        (&gaussians, &accum[..], &images[2]),
    ] {
        let cli = dir.join("cli.png");
        let status = std::process::Command::new(env!("CARGO_BIN_EXE_pointlens"))
            .arg("render")
            .arg(input)
            .arg("-o")
            .arg(&cli)
            .args([
                "--width",
                "160",
                "--height",
                "120",
                "--device",
                "llvmpipe",
                "--validate",
            ])
            .args(flags)
            .status()
            .expect("pointlens runs");
        assert!(status.success(), "{}: {status}", input.display());
        assert!(
            std::fs::read(&cli).unwrap() == std::fs::read(library).unwrap(),
            "{}: the command line's image differs from the library's",
            input.display()
        );
    }
}

#[test]
fn a_file_whose_kind_changed_between_its_two_reads_is_one_line_naming_it() {
    // `render` opens the device for the kind the file's first bytes show
    // while the main thread reads the file (`RenderJob::run`): a file
    // replaced between the two reads by one of another kind meets a
    // device opened for the wrong kind, refused in one line.
    use pointlens::options::Method;
    use pointlens::scene::{DeviceSetup, HostScene, SceneKind, SceneSpec};
    let bunny = common::root().join("data/bunny_colored.ply");
    let gaussians = common::root().join("data/autzen_gaussians.ply");
    let device = ContextOptions {
        validation: true,
        device: Some("llvmpipe".into()),
    };
    let _one_at_a_time = common::gpu_lock();
    for (path, opened_for) in [
        (&bunny, SceneKind::Gaussians),
        (&gaussians, SceneKind::Cloud),
    ] {
        let spec = SceneSpec::of(path);
        let host = HostScene::open(&spec, &mut |_, _| {}).unwrap();
        assert_ne!(host.kind(), opened_for);
        let built = host.build(&spec).unwrap();
        let setup = DeviceSetup::open(&device, opened_for, &spec, &Method::Pinhole).unwrap();
        let log = setup.ctx().message_log();
        let message = match built.upload(setup, &spec) {
            Ok(_) => panic!(
                "{}: uploaded to a device opened for another kind",
                path.display()
            ),
            Err(e) => e.to_string(),
        };
        assert_eq!(
            message,
            format!("{}: the file changed while it was read", path.display())
        );
        // The device, dropped with the refusal, was used and let go of
        // without a validation message.
        let messages = log.messages();
        assert!(messages.is_empty(), "validation reported {messages:?}");
    }
}
