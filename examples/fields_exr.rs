//! Runs the CPU reference of the bounded two-field gather
//! (`pointlens::fields::reference`) on a G-buffer written as an EXR with
//! `--passes z,coc` (channels R, G, B, A, Z, CoC) and a guard band, as
//! `scripts/research/bounded-gather/render_ext.py` writes it, so that the
//! Rust statement can be checked against the numpy one (docs/BENCHMARKS.md).
//!
//!     cargo run --release --example fields_exr -- GBUFFER.exr CAMERA.json GUARD_PX OUT.exr
//!
//! CAMERA.json is the frame's own camera (without the guard band).

use pointlens::camera::Camera;
use pointlens::host_gbuffer::HostGBuffer;
use pointlens::image_io::{read_exr_channels, write_image};

fn main() {
    let mut args = std::env::args().skip(1);
    let gbuffer_path = std::path::PathBuf::from(args.next().expect("GBUFFER.exr"));
    let camera_path = args.next().expect("CAMERA.json");
    let guard: u32 = args.next().expect("GUARD_PX").parse().expect("GUARD_PX");
    let out = std::path::PathBuf::from(args.next().expect("OUT.exr"));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&camera_path).expect("camera file"))
            .expect("camera JSON");
    let v3 = |k: &str| {
        let a = json[k].as_array().expect(k);
        glam::Vec3::new(
            a[0].as_f64().unwrap() as f32,
            a[1].as_f64().unwrap() as f32,
            a[2].as_f64().unwrap() as f32,
        )
    };
    let f = |k: &str| json[k].as_f64().expect(k) as f32;
    let camera = Camera {
        width: json["width"].as_u64().expect("width") as u32,
        height: json["height"].as_u64().expect("height") as u32,
        eye: v3("eye"),
        target: v3("target"),
        up: v3("up"),
        fovy_deg: f("fovy_deg"),
        aperture_radius: f("aperture_radius"),
        focus_distance: f("focus_distance"),
        aperture: pointlens::camera::Aperture::ROUND,
    };
    let (width, height, channels) = read_exr_channels(&gbuffer_path).expect("the G-buffer EXR");
    assert_eq!(
        (width, height),
        (camera.width + 2 * guard, camera.height + 2 * guard)
    );
    let channel = |name: &str| {
        &channels
            .iter()
            .find(|c| c.name == name)
            .unwrap_or_else(|| panic!("no channel {name}"))
            .samples
    };
    let (r, g, b, a, z, coc) = (
        channel("R"),
        channel("G"),
        channel("B"),
        channel("A"),
        channel("Z"),
        channel("CoC"),
    );
    let worst = z
        .iter()
        .zip(coc)
        .map(|(&z, &c)| (camera.coc_px(z) - c).abs() / c.max(1.0))
        .fold(0.0f32, f32::max);
    println!("CoC pass against the camera's: largest relative difference {worst:.2e}");
    let gbuffer = HostGBuffer {
        width,
        height,
        guard,
        color: (0..r.len()).map(|i| [r[i], g[i], b[i], a[i]]).collect(),
        eye: (0..r.len()).map(|i| [0.0, 0.0, z[i], a[i]]).collect(),
    };
    let started = std::time::Instant::now();
    let image = pointlens::fields::reference(&gbuffer, &camera);
    println!("reference: {:.1} s", started.elapsed().as_secs_f64());
    write_image(&image, &out).expect("the output");
}
