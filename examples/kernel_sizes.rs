//! Measures the passes that have a GPU's and a CPU's cut of their work
//! (`passes::kernel_sizes`, docs/decisions/kernel-sizes.md) both ways on
//! one device, alternating in every round: `layered.composite` (a row per
//! workgroup or per invocation), the RDB's `rdb.scatter` and `rdb.resolve`
//! (64-bit bins a plane per bin, or a pixel's side by side) and
//! `fast.fields_bands` (a coarse texel per workgroup or per invocation).
//! Prints each pass's median GPU time per cut, and fails unless both cuts
//! gave the same bits in every frame (`fast`, whose float sums add in
//! another order: within 80 dB of each other). `scripts/gpu-check` runs it
//! on a lent GPU; on lavapipe it says what the GPU's cut would cost a CPU.
//!
//!     cargo run --release --example kernel_sizes -- [WIDTH HEIGHT POINTS ROUNDS]

use glam::Vec3;
use pointlens::bench::BenchModel;
use pointlens::image_io::LinearImage;
use pointlens::options::Method;
use pointlens::passes::kernel_sizes::KernelSizes;
use pointlens::render::{RenderOptions, Renderer, SplatSize};
use pointlens::vk::{Context, ContextOptions};

fn main() {
    if let Err(e) = run() {
        eprintln!("kernel_sizes: {e}");
        std::process::exit(1);
    }
}

fn run() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: &str| args.get(i).cloned().unwrap_or(default.into());
    let width: u32 = arg(0, "1920").parse()?;
    let height: u32 = arg(1, "1080").parse()?;
    let points: usize = arg(2, "1000000").parse()?;
    let rounds: usize = arg(3, "5").parse()?;
    let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
    let cloud = BenchModel::Synthetic.load(&data, points)?;
    let ctx = Context::new(&ContextOptions::from_env(false, None))?;
    let gpu = KernelSizes::for_gpu(
        ctx.info.subgroup_size,
        ctx.info.max_compute_workgroup_invocations,
    );
    let cuts = [("gpu", gpu), ("cpu", KernelSizes::ALONE)];
    // A renderer per cut, each keeping its pipelines and buffers from
    // frame to frame; both draw the one scene of the device.
    let mut renderers = Vec::new();
    for (_, sizes) in cuts {
        let mut renderer = Renderer::new(&ctx)?;
        renderer.set_kernel_sizes(sizes);
        renderers.push(renderer);
    }
    let scene = renderers[0].upload(&cloud, SplatSize::Spacing)?;
    let own = match KernelSizes::for_device(&ctx.info) == gpu {
        true => "gpu",
        false => "cpu",
    };
    println!(
        "{} · {width}x{height} · {points} synthetic points · {rounds} rounds · the device's own cut: {own} · gpu: {gpu:?}",
        ctx.info.describe()
    );
    // (method, its passes that have two cuts, whether the cuts give the
    // same bits)
    for (method, passes, exact) in [
        ("layered2", &["layered.composite"][..], true),
        ("rdb9", &["rdb.scatter", "rdb.resolve"][..], true),
        ("fast", &["fast.fields_bands"][..], false),
    ] {
        let options = RenderOptions {
            camera: BenchModel::Synthetic.camera(&cloud, width, height)?,
            method: Method::parse_short(method)?,
            ssaa: 3,
            samples_per_pass: None,
            background: Vec3::ZERO,
            lod: Default::default(),
        };
        // [cut][pass]: GPU ms per round; [cut]: GPU total per round.
        let mut times = vec![vec![Vec::new(); passes.len()]; cuts.len()];
        let mut totals = vec![Vec::new(); cuts.len()];
        let mut worst_db = f64::INFINITY;
        for round in 0..=rounds {
            let mut images: Vec<LinearImage> = Vec::new();
            for (c, renderer) in renderers.iter().enumerate() {
                let frame = renderer.render(&scene, &options)?;
                images.push(frame.image);
                // Round 0 warms both cuts' pipelines and allocations.
                if round == 0 {
                    continue;
                }
                for (p, name) in passes.iter().enumerate() {
                    let ms = frame
                        .timings
                        .passes
                        .iter()
                        .filter(|t| t.name == *name)
                        .map(|t| t.gpu_ms)
                        .sum();
                    times[c][p].push(ms);
                }
                totals[c].push(frame.timings.gpu_total_ms());
            }
            let bits = |i: usize| -> Vec<u32> {
                images[i]
                    .pixels
                    .iter()
                    .flatten()
                    .map(|v| v.to_bits())
                    .collect()
            };
            match exact {
                true => anyhow::ensure!(
                    bits(0) == bits(1),
                    "{method}: the two cuts differ in round {round}"
                ),
                false => worst_db = worst_db.min(pointlens::metrics::psnr(&images[0], &images[1])?),
            }
        }
        for (c, (cut, _)) in cuts.iter().enumerate() {
            let mut line = format!(
                "{method} {cut:>6}: GPU total {:8.3} ms",
                median(&mut totals[c])
            );
            for (p, name) in passes.iter().enumerate() {
                line += &format!("  {name} {:8.3}", median(&mut times[c][p]));
            }
            println!("{line}");
        }
        match exact {
            true => println!("{method}: both cuts gave the same bits in every frame"),
            false => {
                anyhow::ensure!(
                    worst_db > 80.0,
                    "{method}: the cuts are {worst_db:.1} dB apart"
                );
                println!("{method}: the cuts' images {worst_db:.1} dB PSNR of each other at worst (the float sums' order)");
            }
        }
    }
    Ok(())
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
