//! The library's render path without the command line: a PLY cloud, the
//! same cloud converted to COPC (read node by node) and a scene of 3D
//! Gaussians, each rendered through one `RenderJob` with depth of field.
//!
//! ```sh
//! cargo run --release --example render_scenes -- OUT_DIR
//! ```
//!
//! `tests/library.rs` runs it.

use std::path::{Path, PathBuf};

use pointlens::camera::CameraSpec;
use pointlens::convert::{convert_file, ConvertOptions};
use pointlens::job::{JobSpec, RenderJob, Shot, Written};
use pointlens::options::{AccumOptions, Lod, Method};
use pointlens::scene::SceneSpec;
use pointlens::synth::{write_file, SynthKind};
use pointlens::vk::ContextOptions;

/// Renders the three kinds of scene into `out` (an existing folder),
/// through the device `device`: `bunny.png` (PLY), `bunny_copc.png` (the
/// same points as COPC) and `gaussians.png`. Returns the images' paths.
pub fn render_all(out: &Path, device: &ContextOptions) -> pointlens::Result<Vec<PathBuf>> {
    let bunny = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/bunny_colored.ply");
    let copc = out.join("bunny.copc.laz");
    convert_file(&ConvertOptions::new(&bunny, &copc, 1024), &mut |_, _| {})?;
    let gaussians = out.join("gaussians.ply");
    write_file(SynthKind::Gaussians, 2000, &gaussians, &mut |_| {})?;

    let scenes = [
        (bunny, "bunny.png", Method::Layered(Default::default())),
        (copc, "bunny_copc.png", Method::Layered(Default::default())),
        (
            gaussians,
            "gaussians.png",
            Method::Accum(AccumOptions { samples: 8 }),
        ),
    ];
    let mut written = Vec::new();
    for (input, name, method) in scenes {
        let output = out.join(name);
        let job = RenderJob::new(job_spec(&output, method))?;
        // Every flag of the scene at its default: the cameras are framed
        // on what the file holds, focused on its centre.
        job.run(&SceneSpec::of(&input), device, &mut |_| Ok(()))?;
        written.push(output);
    }
    Ok(written)
}

/// One 160×120 image into `output` by `method`, a lens that blurs.
fn job_spec(output: &Path, method: Method) -> JobSpec {
    JobSpec {
        shot: Shot::Single,
        output: output.to_path_buf(),
        frame_range: None,
        skip_existing: false,
        camera_file: None,
        camera_flags: CameraSpec {
            width: Some(160),
            height: Some(120),
            ..CameraSpec::default()
        },
        focus_pixel: None,
        method,
        ssaa: None,
        samples_per_pass: None,
        background: glam::Vec3::ZERO,
        lod: Lod::default(),
        written: Written::default(),
        timings_json: None,
        fps: None,
    }
}

#[allow(dead_code)]
fn main() -> pointlens::Result<()> {
    let out = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| ".".into()));
    std::fs::create_dir_all(&out).map_err(|source| pointlens::Error::System {
        what: "creating the output folder",
        source,
    })?;
    for image in render_all(&out, &ContextOptions::from_env(false, None))? {
        println!("{}", image.display());
    }
    Ok(())
}
