//! A reproducer for a heap corruption seen at the exit of a test process
//! that ran two tests at once: Vulkan contexts (lavapipe under the
//! validation layer) created, used and destroyed on several threads at
//! once, then the process exits (docs/bench/history/heap-at-exit.md).
//!
//! `two_contexts [THREADS [ROUNDS [FRAMES]]]` (default 2, 4, 0): each of
//! THREADS threads makes ROUNDS contexts one after another, each with a
//! renderer (its pipelines compiled) and FRAMES frames of a small cloud
//! rendered through it. With FRAMES > 0 the threads' contexts overlap as
//! a test harness's do: each thread waits a different few milliseconds
//! before each context, so one thread's context is made or destroyed while
//! another's renders.
//!
//! ```sh
//! m=/lib/x86_64-linux-gnu/libc_malloc_debug.so.0  # glibc ≥ 2.34 reads MALLOC_CHECK_ only with it
//! for i in $(seq 100); do LD_PRELOAD=$m MALLOC_CHECK_=3 target/release/examples/two_contexts 3 4 3 || echo "abort $i"; done
//! ```

use std::sync::Arc;
use std::time::Duration;

use glam::Vec3;
use pointlens::camera::{Aperture, Camera};
use pointlens::options::{Lod, Method};
use pointlens::render::{RenderOptions, Renderer, SplatSize};
use pointlens::vk::{Context, ContextOptions};
use pointlens::PointCloud;

/// A 16×16 grid of coloured points a unit in front of the camera.
fn small_cloud() -> PointCloud {
    let points: Vec<(Vec3, Vec3)> = (0..256)
        .map(|i| {
            let (x, y) = ((i % 16) as f32 / 15.0 - 0.5, (i / 16) as f32 / 15.0 - 0.5);
            (
                Vec3::new(x, y, -1.5 - 0.3 * x),
                Vec3::new(x + 0.5, y + 0.5, 0.5),
            )
        })
        .collect();
    PointCloud {
        positions: points.iter().map(|p| p.0).collect(),
        colors: points.iter().map(|p| p.1).collect(),
        has_colors: true,
        attributes: vec!["x".into(), "y".into(), "z".into()],
        ..Default::default()
    }
}

fn one_context(frames: usize, cloud: &PointCloud) -> pointlens::Result<()> {
    let ctx: Arc<Context> = Context::new(&ContextOptions {
        validation: true,
        device: Some("llvmpipe".into()),
    })?;
    let renderer = Renderer::new(&ctx)?;
    if frames > 0 {
        let scene = renderer.upload(cloud, SplatSize::Spacing)?;
        let camera = Camera {
            width: 48,
            height: 36,
            eye: Vec3::ZERO,
            target: Vec3::new(0.0, 0.0, -1.0),
            up: Vec3::Y,
            fovy_deg: 50.0,
            aperture_radius: 0.02,
            focus_distance: 1.5,
            aperture: Aperture::ROUND,
        };
        let methods = [Method::layered(2), Method::accum(4), Method::Pinhole];
        for f in 0..frames {
            let options = RenderOptions {
                camera,
                method: methods[f % methods.len()],
                ssaa: 3,
                samples_per_pass: None,
                background: Vec3::ZERO,
                lod: Lod::default(),
            };
            renderer.render(&scene, &options)?;
        }
    }
    drop(renderer);
    ctx.check_validation()
}

fn main() -> pointlens::Result<()> {
    let arg = |i: usize, default: usize| {
        std::env::args()
            .nth(i)
            .map_or(default, |a| a.parse().expect("a count"))
    };
    let (threads, rounds, frames) = (arg(1, 2), arg(2, 4), arg(3, 0));
    let cloud = Arc::new(small_cloud());
    if frames == 0 {
        // Both threads' contexts at the same time, round by round.
        for _ in 0..rounds {
            let handles: Vec<_> = (0..threads)
                .map(|_| {
                    let cloud = cloud.clone();
                    std::thread::spawn(move || one_context(0, &cloud))
                })
                .collect();
            for h in handles {
                h.join().expect("no panic")?;
            }
        }
        return Ok(());
    }
    let handles: Vec<_> = (0..threads)
        .map(|t| {
            let cloud = cloud.clone();
            std::thread::spawn(move || {
                for r in 0..rounds {
                    std::thread::sleep(Duration::from_millis(((t * 37 + r * 11) % 50) as u64));
                    one_context(frames, &cloud)?;
                }
                Ok::<(), pointlens::Error>(())
            })
        })
        .collect();
    for h in handles {
        h.join().expect("no panic")?;
    }
    Ok(())
}
