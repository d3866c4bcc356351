//! Measures what drawing the points in Morton order gains the G-buffer
//! raster (docs/BENCHMARKS.md, "Splat hierarchy"): the same splats (every
//! point, `--lod-px 0`) drawn in the file's order and in Morton order,
//! alternating, on the default Vulkan device (validation off: timings).
//!
//!     cargo run --release --example point_order -- FILE.ply|synthetic:N WIDTH HEIGHT [RUNS]

use glam::Vec3;
use pointlens::bench::{synthetic_cloud, BenchModel};
use pointlens::options::Lod;
use pointlens::options::Method;
use pointlens::render::{RenderOptions, Renderer, SplatSize};
use pointlens::vk::{Context, ContextOptions};

fn main() {
    let mut args = std::env::args().skip(1);
    let input = args.next().expect("FILE.ply or synthetic:N");
    let width: u32 = args.next().map_or(1920, |a| a.parse().expect("WIDTH"));
    let height: u32 = args.next().map_or(1080, |a| a.parse().expect("HEIGHT"));
    let runs: usize = args.next().map_or(3, |a| a.parse().expect("RUNS"));
    let (model, cloud) = match input.strip_prefix("synthetic:") {
        Some(n) => (
            BenchModel::Synthetic,
            synthetic_cloud(n.parse().expect("synthetic:N")),
        ),
        None => {
            let path = std::path::PathBuf::from(&input);
            (
                BenchModel::File(path.clone()),
                pointlens::input::ply::load_ply(&path).expect("a PLY file"),
            )
        }
    };
    let camera = model.camera(&cloud, width, height).expect("camera");
    let ctx = Context::new(&ContextOptions::from_env(false, None)).expect("a Vulkan device");
    let renderer = Renderer::new(&ctx).expect("renderer");
    let morton = renderer.upload(&cloud, SplatSize::Spacing).expect("upload");
    let input_order = renderer.upload_in_input_order(&cloud).expect("upload");
    let options = RenderOptions {
        camera,
        method: Method::Pinhole,
        ssaa: renderer
            .ssaa(None, None, &Method::Pinhole)
            .expect("the default K"),
        samples_per_pass: None,
        background: Vec3::ZERO,
        lod: Lod::ALL,
    };
    println!("device: {}", ctx.info.name);
    println!(
        "{} points, {width}x{height}, every point drawn",
        cloud.len()
    );
    let raster = |scene| {
        let r = renderer.render(scene, &options).expect("render");
        let ms: f64 = r
            .timings
            .passes
            .iter()
            .filter(|p| p.name == "gbuffer.raster")
            .map(|p| p.gpu_ms)
            .sum();
        (ms, r.image)
    };
    // One untimed frame each, then alternate.
    let (_, a) = raster(&input_order);
    let (_, b) = raster(&morton);
    let same = pointlens::metrics::psnr(&a, &b).expect("same size");
    println!("images: {same:.2} dB apart (equal-depth ties may differ)");
    for run in 0..runs {
        let (input_ms, _) = raster(&input_order);
        let (morton_ms, _) = raster(&morton);
        println!(
            "run {run}: gbuffer.raster input order {input_ms:.1} ms, Morton order {morton_ms:.1} ms ({:.2}x)",
            input_ms / morton_ms
        );
    }
}
