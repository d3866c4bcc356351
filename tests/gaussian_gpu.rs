//! 3D Gaussians on the device (issue 31; docs/ARCHITECTURE.md, "3D
//! Gaussian scenes"): the radix sort and prefix sum against the CPU's, and
//! the device's pinhole and thin-lens images against the CPU reference
//! (crate::gaussians), under validation.

mod common;

use glam::{Quat, Vec2, Vec3};
use pointlens::camera::{lens_samples, Camera};
use pointlens::gaussian_render::GaussianRenderer;
use pointlens::gaussians::{render_reference_lens, TILE_PX};
use pointlens::input::gaussians::GaussianScene;
use pointlens::passes::radix_sort::{
    words_buffer, RadixSort, ScanScratch, SortScratch, SortedIn, NONE,
};
use pointlens::vk::{Access, Buffer, Frame};

/// A fixed sequence of numbers in [0, 1).
struct Sequence(u32);

impl Sequence {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (self.0 >> 8) as f32 / (1u32 << 24) as f32
    }
    fn word(&mut self) -> u32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        self.0
    }
}

fn upload_words(ctx: &std::sync::Arc<pointlens::vk::Context>, name: &str, words: &[u32]) -> Buffer {
    Buffer::with_bytes(
        ctx,
        name,
        bytemuck::cast_slice(words),
        ash::vk::BufferUsageFlags::STORAGE_BUFFER
            | ash::vk::BufferUsageFlags::TRANSFER_SRC
            | ash::vk::BufferUsageFlags::TRANSFER_DST,
    )
    .unwrap()
}

fn read_words(buffer: &Buffer) -> Vec<u32> {
    bytemuck::pod_collect_to_vec(buffer.mapped().unwrap())
}

/// Sorts of random keys of every size around a block (4096) and of a few
/// blocks, by all 32 bits and by their low 13 (higher bits zero), with
/// many equal keys: the device's order is the CPU's stable sort's, values
/// included; and the prefix sum of values read through the sorted order.
#[test]
fn the_radix_sort_is_stable_and_the_scan_exact() {
    common::with_gpu(|ctx| {
        let sort = RadixSort::new(ctx).unwrap();
        let mut seq = Sequence(7);
        for (n, bits) in [
            (1u32, 32u32),
            (4095, 32),
            (4096, 13),
            (4097, 32),
            (50_001, 13),
            (70_000, 32),
        ] {
            let keys: Vec<u32> = (0..n)
                .map(|_| match bits {
                    32 => seq.word() % 9000 * 477_211, // many repeats, high bits set
                    _ => seq.word() % (1 << bits),
                })
                .collect();
            let values: Vec<u32> = (0..n).map(|i| i * 3 + 1).collect();
            let small: Vec<u32> = (0..n).map(|_| seq.word() % 17).collect();
            let key_buffer = upload_words(ctx, "test keys", &keys);
            let value_buffer = upload_words(ctx, "test values", &values);
            // Values index `small`: the scan reads small[value / 3].
            let index: Vec<u32> = (0..n).collect();
            let index_buffer = upload_words(ctx, "test index", &index);
            let small_buffer = upload_words(ctx, "test small", &small);
            let counts = upload_words(ctx, "test counts", &[n, 0, 0, 0]);
            let scratch = SortScratch::new(ctx, "test sort", n).unwrap();
            let scan_scratch = ScanScratch::new(ctx, "test scan", n).unwrap();
            let prefix = words_buffer(ctx, "test prefix", n as u64).unwrap();
            let host = |name: &str| {
                Buffer::new(
                    ctx,
                    name,
                    4 * n as u64,
                    ash::vk::BufferUsageFlags::TRANSFER_DST,
                    gpu_allocator::MemoryLocation::GpuToCpu,
                )
                .unwrap()
            };
            let (keys_out, values_out, prefix_out) =
                (host("keys out"), host("values out"), host("prefix out"));
            let counts_out = Buffer::new(
                ctx,
                "counts out",
                16,
                ash::vk::BufferUsageFlags::TRANSFER_DST,
                gpu_allocator::MemoryLocation::GpuToCpu,
            )
            .unwrap();
            let mut frame = Frame::begin(ctx, "sort test").unwrap();
            frame.pass("sort", |rec| {
                rec.memory_barrier(Access::HOST_READ, Access::COMPUTE_READ_WRITE);
                let at = sort.record_sort(
                    rec,
                    &key_buffer,
                    &value_buffer,
                    &scratch,
                    &counts,
                    0,
                    n,
                    bits,
                );
                let (k, v) = match at {
                    SortedIn::Input => (&key_buffer, &value_buffer),
                    SortedIn::Scratch => (&scratch.keys, &scratch.values),
                };
                // The scan of small[] in input order, its total to counts[1..3].
                sort.record_scan(
                    rec,
                    &small_buffer,
                    Some(&index_buffer),
                    &prefix,
                    &scan_scratch,
                    &counts,
                    n,
                    NONE,
                    1,
                );
                rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COPY_SRC);
                rec.copy_buffer(k, &keys_out);
                rec.copy_buffer(v, &values_out);
                rec.copy_buffer(&prefix, &prefix_out);
                rec.copy_buffer(&counts, &counts_out);
                rec.memory_barrier(Access::COPY_WRITE, Access::HOST_READ);
            });
            frame.submit_and_wait().unwrap();
            let mut expected: Vec<(u32, u32)> =
                keys.iter().copied().zip(values.iter().copied()).collect();
            expected.sort_by_key(|p| p.0); // stable
            let got: Vec<(u32, u32)> = read_words(&keys_out)
                .into_iter()
                .zip(read_words(&values_out))
                .collect();
            assert!(got == expected, "sort of {n} keys by {bits} bits differs");
            let mut sum = 0u32;
            let expected_prefix: Vec<u32> = small
                .iter()
                .map(|v| {
                    let s = sum;
                    sum += v;
                    s
                })
                .collect();
            assert_eq!(read_words(&prefix_out), expected_prefix, "prefix of {n}");
            let c = read_words(&counts_out);
            assert_eq!((c[1], c[2]), (sum, sum), "total of {n}");
        }
    });
}

/// `n` Gaussians in a box in front of the camera at the origin looking
/// down +z: anisotropic and turned, overlapping, opacities from nearly
/// clear to the 0.99 cap, SH degree 3.
fn random_scene(n: usize, seed: u32) -> GaussianScene {
    let mut s = Sequence(seed);
    let degree = 3u32;
    let coefficients = 16;
    let mut scene = GaussianScene {
        positions: Vec::new(),
        scales: Vec::new(),
        rotations: Vec::new(),
        opacities: Vec::new(),
        sh_degree: degree,
        sh: Vec::new(),
    };
    for _ in 0..n {
        scene.positions.push(Vec3::new(
            2.0 * s.next() - 1.0,
            1.6 * s.next() - 0.8,
            3.0 + 3.0 * s.next(),
        ));
        let size = 0.01 + 0.12 * s.next() * s.next();
        scene.scales.push(Vec3::new(
            size * (0.2 + s.next()),
            size * (0.2 + s.next()),
            size * (0.2 + s.next()),
        ));
        let axis = Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5).normalize_or(Vec3::Z);
        scene
            .rotations
            .push(Quat::from_axis_angle(axis, 6.0 * s.next()));
        scene.opacities.push(0.02 + 0.999 * s.next().sqrt());
        for k in 0..coefficients {
            let amplitude = if k == 0 { 1.5 } else { 0.3 };
            for _ in 0..3 {
                scene.sh.push(amplitude * (2.0 * s.next() - 1.0));
            }
        }
    }
    scene
}

fn camera(width: u32, height: u32) -> Camera {
    Camera {
        width,
        height,
        eye: Vec3::ZERO,
        target: Vec3::new(0.0, 0.0, 1.0),
        up: Vec3::Y,
        fovy_deg: 30.0,
        aperture_radius: 0.0,
        focus_distance: 4.0,
        aperture: pointlens::camera::Aperture::ROUND,
    }
}

/// Largest and mean absolute difference of two linear RGB images.
fn differences(gpu: &pointlens::image_io::LinearImage, cpu: &[Vec3]) -> (f32, f32) {
    let (mut max, mut sum) = (0.0f32, 0.0f64);
    for (g, c) in gpu.pixels.iter().zip(cpu) {
        let d = (Vec3::new(g[0], g[1], g[2]) - *c).abs().max_element();
        max = max.max(d);
        sum += d as f64;
    }
    (max, (sum / cpu.len() as f64) as f32)
}

/// The device's image of `scene` through `camera`'s pinhole at `ssaa` ×
/// `ssaa` cell centres, checked against the CPU reference's within the
/// tolerance of [`the_pinhole_image_is_the_cpu_references`]: the device's
/// frame and the reference image.
fn pinhole_against_reference(
    renderer: &GaussianRenderer,
    scene: &GaussianScene,
    camera: &Camera,
    ssaa: u32,
    what: &str,
) -> (pointlens::gaussian_render::GaussianFrame, Vec<Vec3>) {
    let gpu = renderer.upload(scene).unwrap();
    let frame = renderer
        .render(&gpu, camera, &[Vec2::ZERO], ssaa, Vec3::ZERO)
        .unwrap();
    let cpu = render_reference_lens(scene, camera, Vec3::ZERO, &[Vec2::ZERO], ssaa);
    let (max, mean) = differences(&frame.image, &cpu);
    eprintln!("{what}: max {max:e}, mean {mean:e}");
    assert!(
        max <= 1e-4 && mean <= 1e-6,
        "{what}: max {max}, mean {mean}"
    );
    (frame, cpu)
}

/// The device's pinhole image is the CPU reference's, decoded to linear
/// light, on 2,000 overlapping Gaussians at 100 × 84 (edge tiles partly
/// outside): the two differ only in the order of floating-point operations
/// (the device computes T = J W by rows) and in exp, sqrt and pow: 8e-7
/// at most on lavapipe; tolerance 1e-4 for a pixel (room for a GPU's
/// faster exp and pow), 1e-6 on average. A denser scene of 5,000 over a
/// background goes the same way.
#[test]
fn the_pinhole_image_is_the_cpu_references() {
    common::with_gpu(|ctx| {
        let mut renderer = GaussianRenderer::new(ctx).unwrap();
        for (n, seed, background) in [(2000, 3, Vec3::ZERO), (5000, 4, Vec3::new(0.05, 0.2, 1.0))] {
            let scene = random_scene(n, seed);
            let camera = camera(100, 84);
            // The SH in two buffers, split mid-scene (10^6 Gaussians of
            // degree 3 need it on lavapipe).
            renderer.set_sh_split_limit(n / 3);
            let mut scene = scene;
            // Gaussians too large for floats near the eye, and one of
            // radius ~10^9 px: culled, or clamped to the image, on both.
            for (z, log_scale) in [(0.5f32, 40.0f32), (1.0, 20.0), (4.0, 14.0)] {
                scene.positions.push(Vec3::new(0.1, 0.0, z));
                scene.scales.push(Vec3::splat(log_scale.exp()));
                scene.rotations.push(Quat::IDENTITY);
                scene.opacities.push(0.01);
                scene.sh.extend([0.0; 48]);
            }
            let gpu = renderer.upload(&scene).unwrap();
            let frame = renderer
                .render(&gpu, &camera, &[Vec2::ZERO], 1, background)
                .unwrap();
            // The reference composites over the background as trained:
            // encoded; the renderer takes it in linear light.
            let encoded = background
                .to_array()
                .map(pointlens::image_io::linear_to_srgb);
            let cpu = render_reference_lens(&scene, &camera, Vec3::from(encoded), &[Vec2::ZERO], 1);
            let (max, mean) = differences(&frame.image, &cpu);
            eprintln!(
                "pinhole, {n} Gaussians: max {max:e}, mean {mean:e}, {} tile entries",
                frame.entries
            );
            assert!(max <= 1e-4 && mean <= 1e-6, "max {max}, mean {mean}");
            // Not a blank image: the scene covers most pixels.
            let lit = cpu
                .iter()
                .filter(|c| (**c - background).abs().max_element() > 0.05)
                .count();
            assert!(lit > cpu.len() / 2, "{lit} pixels show Gaussians");
            assert!(frame.entries as usize > n, "{} entries", frame.entries);
        }
    });
}

/// With a lens, every lens point re-projects every Gaussian through its
/// sheared projection and the images average in linear light: the
/// device's 40-point `accum` is the CPU reference's of the same points
/// (the pinhole's tolerance; 5e-7 at most measured), and differs from the pinhole image.
#[test]
fn the_thin_lens_image_is_the_cpu_references() {
    common::with_gpu(|ctx| {
        let renderer = GaussianRenderer::new(ctx).unwrap();
        let scene = random_scene(1500, 5);
        let mut camera = camera(80, 64);
        camera.aperture_radius = 0.08;
        // 40: two submissions (32 chains each at most).
        let lens = lens_samples(40);
        let gpu = renderer.upload(&scene).unwrap();
        let frame = renderer
            .render(&gpu, &camera, &lens, 1, Vec3::ZERO)
            .unwrap();
        let cpu = render_reference_lens(&scene, &camera, Vec3::ZERO, &lens, 1);
        let (max, mean) = differences(&frame.image, &cpu);
        eprintln!("accum 40: max {max:e}, mean {mean:e}");
        assert!(max <= 1e-4 && mean <= 1e-6, "max {max}, mean {mean}");
        let pinhole = render_reference_lens(&scene, &camera, Vec3::ZERO, &[Vec2::ZERO], 1);
        let (blur, _) = differences(&frame.image, &pinhole);
        assert!(blur > 0.05, "the lens changes the image by {blur}");
        // A timing for every pass of the chain.
        let names: Vec<&str> = frame
            .timings
            .passes
            .iter()
            .map(|p| p.name.as_str())
            .collect();
        for pass in ["project", "depth sort", "tile list", "tile sort", "blend"] {
            assert!(
                names.contains(&format!("gaussians: {pass}").as_str()),
                "{names:?}"
            );
        }
    });
}

/// Through the cat's eye (S = 1) each pixel averages the lens points by
/// the part of each one's lens cell its circle passes
/// (`Aperture::cat_eye_weight`, the points in pixel axes: y down), and one
/// whose circle reaches no cell the points nearest it:
/// the device's 40-point `accum` is the CPU reference's images of each
/// point weighed so per pixel (the pinhole's tolerance), and the cat's eye
/// changes the image.
#[test]
fn the_cats_eye_weighs_each_lens_point_per_pixel() {
    use pointlens::camera::Aperture;
    common::with_gpu(|ctx| {
        let renderer = GaussianRenderer::new(ctx).unwrap();
        let scene = random_scene(1500, 5);
        let mut camera = camera(80, 64);
        camera.aperture_radius = 0.08;
        camera.aperture.cat_eye = 1.0;
        let lens = lens_samples(40);
        let gpu = renderer.upload(&scene).unwrap();
        let frame = renderer
            .render(&gpu, &camera, &lens, 1, Vec3::ZERO)
            .unwrap();
        let half_cell = Aperture::lens_cell_half_width(lens.len() as u32);
        let images: Vec<Vec<Vec3>> = lens
            .iter()
            .map(|&u| render_reference_lens(&scene, &camera, Vec3::ZERO, &[u], 1))
            .collect();
        let (w, h) = (camera.width, camera.height);
        let (mut expected, mut clipped, mut unlit) = (Vec::new(), 0, 0);
        for y in 0..h {
            for x in 0..w {
                let centre = camera.aperture.cat_eye_centre(x, y, w, h);
                let (mut sum, mut weights) = (Vec3::ZERO, 0.0f64);
                for (u, image) in lens.iter().zip(&images) {
                    let u = Vec2::new(u.x, -u.y);
                    let weight = f64::from(Aperture::cat_eye_weight(u, centre, half_cell));
                    sum += image[(y * w + x) as usize] * weight as f32;
                    weights += weight;
                }
                clipped += usize::from(weights < lens.len() as f64 - 0.5);
                // No cell reaches into the circle: the fallback's weights.
                unlit += usize::from(weights < 1e-6);
                expected.push(sum / weights as f32);
            }
        }
        let (max, mean) = differences(&frame.image, &expected);
        eprintln!("cat's eye: max {max:e}, mean {mean:e}; {clipped} pixels clipped, {unlit} through no point");
        assert!(max <= 1e-4 && mean <= 1e-6, "max {max}, mean {mean}");
        assert!(clipped > (w * h / 2) as usize, "{clipped} pixels clipped");
        assert!(unlit > 0, "no pixel's circle passes no point");
        let round = render_reference_lens(&scene, &camera, Vec3::ZERO, &lens, 1);
        let (change, _) = differences(&frame.image, &round);
        assert!(change > 0.05, "the cat's eye changes the image by {change}");
    });
}

/// A tile list longer than the renderer's first guess: the frame is
/// rendered again with room for it, and equals (bitwise) a frame rendered
/// with room from the start.
#[test]
fn a_tile_list_that_outgrows_its_buffer_renders_again() {
    common::with_gpu(|ctx| {
        // 600 large Gaussians over 512 × 512 (1,024 tiles): far more than
        // the 65,536 entries a first frame has room for.
        let mut scene = random_scene(600, 6);
        for s in &mut scene.scales {
            *s *= 6.0;
        }
        let camera = camera(512, 512);
        let first = GaussianRenderer::new(ctx).unwrap();
        let gpu = first.upload(&scene).unwrap();
        let grown = first
            .render(&gpu, &camera, &[Vec2::ZERO], 1, Vec3::ZERO)
            .unwrap();
        assert!(
            grown.retries >= 1 && grown.entries > 65_536,
            "{} entries, {} retries",
            grown.entries,
            grown.retries
        );
        let again = first
            .render(&gpu, &camera, &[Vec2::ZERO], 1, Vec3::ZERO)
            .unwrap();
        assert_eq!(again.retries, 0, "the renderer keeps the room it learnt");
        assert!(grown.image.pixels == again.image.pixels);
        let tiles = (512 / TILE_PX as u32).pow(2);
        assert!(grown.entries <= 600 * tiles);
    });
}

/// `--ssaa 3`: every lens point at the 3 × 3 cell centres of the pixel,
/// averaged in linear light, as the CPU reference samples them (the
/// pinhole's tolerance); it smooths the pinhole image's edges.
#[test]
fn supersampling_takes_the_cell_centres() {
    common::with_gpu(|ctx| {
        let renderer = GaussianRenderer::new(ctx).unwrap();
        let scene = random_scene(800, 8);
        let camera = camera(64, 48);
        let (frame, _) = pinhole_against_reference(&renderer, &scene, &camera, 3, "ssaa 3");
        let centres = render_reference_lens(&scene, &camera, Vec3::ZERO, &[Vec2::ZERO], 1);
        let (moved, _) = differences(&frame.image, &centres);
        assert!(moved > 0.01, "supersampling changes the image by {moved}");
    });
}

/// PSNR (dB) of `image` against `reference`, RGB in linear light clamped
/// to [0, 1].
fn psnr(
    image: &pointlens::image_io::LinearImage,
    reference: &pointlens::image_io::LinearImage,
) -> f64 {
    let mut sum = 0.0f64;
    for (a, b) in image.pixels.iter().zip(&reference.pixels) {
        for c in 0..3 {
            let d = (a[c].clamp(0.0, 1.0) - b[c].clamp(0.0, 1.0)) as f64;
            sum += d * d;
        }
    }
    let mse = sum / (3 * image.pixels.len()) as f64;
    10.0 * (1.0 / mse.max(1e-20)).log10()
}

/// PSNR of `layered` and of `pinhole` (the scene's pinhole image) against
/// `accum 256` (the reference) through `camera`'s lens.
fn layered_against_accum(
    renderer: &GaussianRenderer,
    gpu: &pointlens::gaussian_render::GpuGaussians,
    camera: &Camera,
    pinhole: &pointlens::image_io::LinearImage,
    what: &str,
) -> (f64, f64) {
    let accum = renderer
        .render(gpu, camera, &lens_samples(256), 1, Vec3::ZERO)
        .unwrap();
    let layered = renderer.render_layered(gpu, camera, Vec3::ZERO).unwrap();
    let p = psnr(&layered.image, &accum.image);
    let p_pin = psnr(pinhole, &accum.image);
    eprintln!("{what}: layered against accum 256 {p:.1} dB (pinhole {p_pin:.1} dB)");
    (p, p_pin)
}

/// The layered method on Gaussians against `accum 256` (the reference) on
/// 3,000 Gaussians 3 to 6 units deep focused at 4 with CoCs up to 7 px:
/// 39.7 dB measured where the pinhole image reaches 26.2 — floors 35 dB
/// and 8 dB above the pinhole; and with no lens (one layer) the pinhole
/// image (81 dB measured, the layers' half floats; floor 60).
#[test]
fn layered_gaussians_approach_accum() {
    common::with_gpu(|ctx| {
        let renderer = GaussianRenderer::new(ctx).unwrap();
        let scene = random_scene(3000, 9);
        let mut camera = camera(96, 72);
        let gpu = renderer.upload(&scene).unwrap();
        let pinhole = renderer
            .render(&gpu, &camera, &[Vec2::ZERO], 1, Vec3::ZERO)
            .unwrap();
        let sharp = renderer.render_layered(&gpu, &camera, Vec3::ZERO).unwrap();
        let p0 = psnr(&sharp.image, &pinhole.image);
        eprintln!("layered at R = 0 against pinhole: {p0:.1} dB");
        camera.aperture_radius = 0.3;
        let (p, p_pin) =
            layered_against_accum(&renderer, &gpu, &camera, &pinhole.image, "random scene");
        assert!(p0 > 60.0, "{p0} dB");
        assert!(p > 35.0 && p > p_pin + 8.0, "{p} dB, pinhole {p_pin} dB");
    });
}

/// Many depth layers without blur give the pinhole image: a dark
/// semi-transparent Gaussian over a bright one over a coloured background
/// (each layer's light is signed: the dark one takes light away), and the
/// random scene, in 6 layers at a lens of CoCs under 0.01 px (no spread
/// beyond the pixel). Measured 66.1 dB, the centre within 9e-4; floors
/// 55 dB and 2e-3 (the layers' half floats: a layer is stored over the
/// background and the background taken out again).
#[test]
fn layers_without_blur_give_the_pinhole_image() {
    common::with_gpu(|ctx| {
        let mut renderer = GaussianRenderer::new(ctx).unwrap();
        renderer.set_layer_count(6);
        let mut scene = random_scene(1500, 10);
        // Dark over bright, at the image's centre, both large.
        for (z, color, opacity) in [(3.2f32, 0.02f32, 0.6f32), (5.5, 1.0, 0.95)] {
            scene.positions.push(Vec3::new(0.0, 0.0, z));
            scene.scales.push(Vec3::splat(0.3));
            scene.rotations.push(Quat::IDENTITY);
            scene.opacities.push(opacity);
            let dc = (color - 0.5) / 0.282_094_8;
            scene.sh.extend([dc, dc, dc]);
            scene.sh.extend([0.0; 45]);
        }
        let mut camera = camera(96, 72);
        camera.aperture_radius = 1e-5;
        let background = Vec3::new(0.3, 0.6, 0.9);
        let gpu = renderer.upload(&scene).unwrap();
        let pinhole = renderer
            .render(&gpu, &camera, &[Vec2::ZERO], 1, background)
            .unwrap();
        let layered = renderer.render_layered(&gpu, &camera, background).unwrap();
        let p = psnr(&layered.image, &pinhole.image);
        let centre = |i: &pointlens::image_io::LinearImage| i.pixels[36 * 96 + 48];
        eprintln!(
            "6 layers without blur: {p:.1} dB; centre {:?} against {:?}",
            centre(&layered.image),
            centre(&pinhole.image)
        );
        assert!(p > 55.0, "{p} dB");
        let (l, q) = (centre(&layered.image), centre(&pinhole.image));
        assert!(
            (l[0] - q[0]).abs() < 2e-3,
            "dark over bright: {l:?} against {q:?}"
        );
    });
}

/// The bundled trained scene (`data/autzen_gaussians.ply`: 23,998
/// Gaussians of SH degree 3 fitted to views of the LiDAR tile; data/README.md)
/// in the tilt-shift view of docs/BENCHMARKS.md at 96 × 72, focused at
/// 600.74 ft: the device's pinhole image is the CPU reference's (the
/// random scenes' tolerance; 4.8e-7 at most measured), and with R = 30 ft
/// (CoCs of a few pixels at this size) `layered` approaches `accum 256`
/// far above the pinhole image. Measured on lavapipe: layered 45.7 dB,
/// pinhole 32.9 dB; floors 40 dB and 8 dB above the pinhole.
#[test]
fn the_bundled_trained_scene() {
    common::with_gpu(|ctx| {
        let scene = pointlens::input::gaussians::load_gaussians(
            &common::root().join("data/autzen_gaussians.ply"),
        )
        .unwrap();
        assert_eq!(scene.sh_degree, 3);
        assert!(scene.len() > 20_000, "{} Gaussians", scene.len());
        let mut camera = Camera {
            width: 96,
            height: 72,
            eye: Vec3::new(0.0, -520.0, 300.0),
            target: Vec3::new(0.0, 80.0, -20.0),
            up: Vec3::Z,
            fovy_deg: 45.0,
            aperture_radius: 0.0,
            focus_distance: 600.74,
            aperture: pointlens::camera::Aperture::ROUND,
        };
        let renderer = GaussianRenderer::new(ctx).unwrap();
        let (pinhole, cpu) =
            pinhole_against_reference(&renderer, &scene, &camera, 1, "trained scene, pinhole");
        let gpu = renderer.upload(&scene).unwrap();
        let lit = cpu.iter().filter(|c| c.max_element() > 0.05).count();
        assert!(lit > cpu.len() / 3, "{lit} pixels show the scene");
        camera.aperture_radius = 30.0;
        let (p, p_pin) =
            layered_against_accum(&renderer, &gpu, &camera, &pinhole.image, "trained scene");
        assert!(p > 40.0 && p > p_pin + 8.0, "{p} dB, pinhole {p_pin} dB");
    });
}

/// A tile whose list is longer than llvmpipe's loop limit: 70,000
/// Gaussians of opacity 0.003 over one 16 × 16 tile, each below the blend's
/// 1/255 cut-off (skipped, as the reference skips them, but each a turn of
/// the blend's loop), in front of one opaque coloured Gaussian. llvmpipe
/// ends an invocation's loops after 65,535 iterations in all
/// (LP_MAX_TGSI_LOOP_ITERATIONS): a blend that loops once per entry never
/// reaches the opaque one and leaves the background. The pinhole image is
/// the CPU reference's: the opaque Gaussian's colour; the layered method's
/// layers without blur give it too.
#[test]
fn a_tile_list_longer_than_llvmpipes_loop_limit_blends_whole() {
    common::with_gpu(|ctx| {
        let renderer = GaussianRenderer::new(ctx).unwrap();
        let n = 70_000;
        let mut s = Sequence(11);
        let mut scene = GaussianScene::default();
        let mut add = |position: Vec3, opacity: f32, dc: [f32; 3]| {
            scene.positions.push(position);
            scene.scales.push(Vec3::splat(1.0));
            scene.rotations.push(Quat::IDENTITY);
            scene.opacities.push(opacity);
            scene.sh.extend(dc);
        };
        for _ in 0..n {
            let p = Vec3::new(0.2 * s.next() - 0.1, 0.2 * s.next() - 0.1, 3.0 + s.next());
            add(p, 0.003, [1.0, 1.0, 1.0]);
        }
        add(Vec3::new(0.0, 0.0, 6.0), 0.99, [1.2, -0.5, 0.3]);
        let mut camera = camera(16, 16);
        let (frame, cpu) =
            pinhole_against_reference(&renderer, &scene, &camera, 1, "70,001 on a tile");
        assert_eq!(frame.entries, n + 1, "every Gaussian on the one tile");
        // The opaque one shows in the middle (the faint ones are skipped).
        let middle = cpu[8 * 16 + 8];
        assert!(middle.x > 0.3 && middle.x > 2.0 * middle.y, "{middle:?}");
        // The layered method's layers walk the same list: without blur
        // they give the pinhole image (as `layers_without_blur_give_the_pinhole_image`).
        camera.aperture_radius = 1e-5;
        let gpu = renderer.upload(&scene).unwrap();
        let layered = renderer.render_layered(&gpu, &camera, Vec3::ZERO).unwrap();
        let p = psnr(&layered.image, &frame.image);
        assert!(p > 55.0, "layers: {p} dB from the pinhole image");
    });
}

/// The composite's rows shared by a workgroup write the bytes of a row
/// per invocation on Gaussian layers too (`passes::kernel_sizes`; the
/// points' test is in tests/layered.rs): the random scene through a lens,
/// in workgroups of 8 (several steps along each row) and 64.
#[test]
fn layered_gaussians_the_same_with_rows_shared() {
    use pointlens::passes::kernel_sizes::KernelSizes;
    common::with_gpu(|ctx| {
        let mut renderer = GaussianRenderer::new(ctx).unwrap();
        let scene = random_scene(3000, 9);
        let mut camera = camera(96, 72);
        camera.aperture_radius = 0.3;
        let gpu = renderer.upload(&scene).unwrap();
        let alone = renderer
            .render_layered(&gpu, &camera, Vec3::ZERO)
            .unwrap()
            .image;
        let first = alone.pixels[0];
        assert!(alone.pixels.iter().any(|p| *p != first), "one colour");
        for row_threads in [8, 64] {
            renderer
                .set_kernel_sizes(KernelSizes {
                    row_threads,
                    ..KernelSizes::ALONE
                })
                .unwrap();
            let shared = renderer
                .render_layered(&gpu, &camera, Vec3::ZERO)
                .unwrap()
                .image;
            assert!(
                common::image_bits(&shared) == common::image_bits(&alone),
                "rows shared by {row_threads} differ"
            );
        }
    });
}
