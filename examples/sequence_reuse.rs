//! Measures what recycling a frame's images between the frames of a
//! sequence saves (docs/BENCHMARKS.md, "Sequences"): renders the frames of
//! an orbit of the bundled bunny with the frame pool on (the default) and
//! off (every frame makes and destroys its own images), alternating the
//! two in every round, and prints the median time per frame, from the call
//! to the pixels on the host, allocation included.
//!
//!     cargo run --release --example sequence_reuse -- [WIDTH HEIGHT FRAMES ROUNDS METHOD]

use std::time::Instant;

use glam::Vec3;
use pointlens::camera::{self, CameraSpec};
use pointlens::options::Method;
use pointlens::render::{RenderOptions, Renderer, SplatSize};
use pointlens::sequence::Motion;
use pointlens::vk::{Context, ContextOptions};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: &str| args.get(i).cloned().unwrap_or(default.into());
    let width: u32 = arg(0, "640").parse().expect("WIDTH");
    let height: u32 = arg(1, "480").parse().expect("HEIGHT");
    let frames: u32 = arg(2, "12").parse().expect("FRAMES");
    let rounds: usize = arg(3, "3").parse().expect("ROUNDS");
    let method = Method::parse_short(&arg(4, "rdb9")).expect("METHOD");
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/bunny_colored.ply");
    let cloud = pointlens::input::load_cloud(&path, None, &mut |_, _| {}).expect("bunny");
    let ctx = Context::new(&ContextOptions::from_env(false, None)).expect("Vulkan");
    let renderer = Renderer::new(&ctx).expect("renderer");
    let scene = renderer.upload(&cloud, SplatSize::Spacing).expect("scene");
    let (lo, hi) = cloud.bounds();
    let spec = CameraSpec {
        width: Some(width),
        height: Some(height),
        ..CameraSpec::default()
    };
    let base = camera::resolve(&spec, lo, hi, &cloud.positions).expect("camera");
    let motion = Motion {
        frames,
        orbit_deg: Some(360.0),
        focus: None,
        aperture: None,
    };
    println!(
        "{} · {width}x{height} · {} · {frames} frames × {rounds} rounds",
        ctx.info.describe(),
        method.short_name()
    );
    let mut times = [Vec::new(), Vec::new()];
    for _ in 0..rounds {
        for (i, pooled) in [true, false].into_iter().enumerate() {
            ctx.set_frame_pool(pooled);
            for frame in 1..=frames {
                let options = RenderOptions {
                    camera: motion.camera(&base, frame),
                    method,
                    ssaa: 4,
                    samples_per_pass: None,
                    background: Vec3::ZERO,
                    lod: Default::default(),
                };
                let t = Instant::now();
                renderer.render_srgb8(&scene, &options).expect("frame");
                // The first frame of a run makes the images either way.
                if frame > 1 {
                    times[i].push(t.elapsed().as_secs_f64() * 1e3);
                }
            }
        }
    }
    let (created, reused, _) = ctx.pool_counts();
    for (name, t) in ["pool on", "pool off"].iter().zip(&mut times) {
        t.sort_by(f64::total_cmp);
        println!(
            "{name}: median {:.2} ms per frame (min {:.2}, max {:.2}, {} frames)",
            t[t.len() / 2],
            t[0],
            t[t.len() - 1],
            t.len()
        );
    }
    println!("objects created {created}, reused {reused}");
}
