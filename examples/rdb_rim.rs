//! How the two RDB formulations treat the rim of a blurred object, against
//! the accumulation reference (docs/RDB.md): a white half-plane at z = 1
//! over a black plane in focus at z = 2, 64×32 px, K = 4, on the default
//! device. For each CoC of the white plane and each method it prints the
//! light the rim loses inside the silhouette and the light it spreads over
//! the background outside, both summed across the edge and averaged over
//! the middle 8 rows (in units of the white plane's color times a pixel).
//!
//! `cargo run --release --example rdb_rim` (about 7 minutes on lavapipe).

use glam::Vec3;
use pointlens::camera::Camera;
use pointlens::options::Method;
use pointlens::options::RdbMode;
use pointlens::render::{RenderOptions, Renderer, SplatSize};
use pointlens::vk::{Context, ContextOptions};
use pointlens::PointCloud;

fn main() -> anyhow::Result<()> {
    let mut positions = Vec::new();
    let mut colors = Vec::new();
    for j in -150..=150 {
        for i in -150..=150 {
            positions.push(Vec3::new(i as f32 * 0.01, j as f32 * 0.01, -2.0));
            colors.push(Vec3::ZERO);
        }
    }
    for j in -100..=100 {
        for i in -100..=0 {
            positions.push(Vec3::new(i as f32 * 0.004, j as f32 * 0.004, -1.0));
            colors.push(Vec3::ONE);
        }
    }
    let cloud = PointCloud {
        positions,
        colors,
        normals: None,
        has_colors: true,
        attributes: vec!["x".into(), "y".into(), "z".into()],
        ..Default::default()
    };
    let ctx = Context::new(&ContextOptions::from_env(false, None))?;
    let renderer = Renderer::new(&ctx)?;
    let scene = renderer.upload(&cloud, SplatSize::World(0.012))?;
    println!("| CoC (px) | method | lost inside | spread outside |");
    println!("|---:|---|---:|---:|");
    for aperture_radius in [0.1, 0.2, 0.3] {
        let camera = Camera {
            width: 64,
            height: 32,
            eye: Vec3::ZERO,
            target: Vec3::new(0.0, 0.0, -1.0),
            up: Vec3::Y,
            fovy_deg: 40.0,
            aperture_radius,
            focus_distance: 2.0,
            aperture: pointlens::camera::Aperture::ROUND,
        };
        for (name, method) in [
            ("accum 256", Method::accum(256)),
            ("rdb 9×9 centre", Method::rdb(9, RdbMode::Centre)),
            ("rdb 9×9 pairs", Method::rdb(9, RdbMode::Pairs)),
            ("rdb 5×5 centre", Method::rdb(5, RdbMode::Centre)),
            ("rdb 5×5 pairs", Method::rdb(5, RdbMode::Pairs)),
        ] {
            let options = RenderOptions {
                camera,
                method,
                ssaa: 4,
                samples_per_pass: None,
                background: Vec3::ZERO,
                lod: pointlens::options::Lod::default(),
            };
            let image = renderer.render(&scene, &options)?.image;
            // The silhouette runs between columns 32 and 33.
            let column = |x: u32| (12..20).map(|y| image.get(x, y)[0]).sum::<f32>() / 8.0;
            let inside: f32 = (20..33).map(|x| 1.0 - column(x)).sum();
            let outside: f32 = (33..48).map(column).sum();
            println!(
                "| {:.1} | {name} | {inside:.3} | {outside:.3} |",
                camera.coc_px(1.0)
            );
        }
    }
    Ok(())
}
