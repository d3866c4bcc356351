//! The GLSL includes that mirror CPU formulas agree with them: `lens.glsl`
//! (the thin lens of DESIGN §2) with `camera::Camera`, `concentric.glsl`
//! (the concentric map of DESIGN §5) with `camera::concentric_disk` and
//! `concentric_square`, `aperture.glsl`'s `cat_eye_blur_reach`,
//! `cat_eye_lens`, `cat_lens_area` and `cat_eye_pressed_weight` with
//! `camera::Aperture`'s `cat_eye_blur_reach`, `cat_eye_lens`,
//! `cat_eye_lens_area` and `cat_eye_pressed_weight`. `glsl/shader_check.comp` evaluates the GLSL side on
//! lavapipe for a few thousand inputs.

mod common;

use common::with_gpu;
use glam::{Vec2, Vec3};
use gpu_allocator::MemoryLocation;
use pointlens::camera::{concentric_disk, concentric_square, rdb_bin, Aperture, Camera};
use pointlens::push_constants;
use pointlens::vk::{groups, Access, Bind, Binding, Buffer, ComputePipeline, Frame};

static SHADER_CHECK: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/shader_check.comp.spv"));

push_constants! {
    struct Push {
        count: u32,
        f_px: f32,
        aperture_radius: f32,
        focus_distance: f32,
    }
}

/// A SplitMix64 stream of floats in [0, 1).
fn uniform(seed: u64) -> impl FnMut() -> f32 {
    let mut state = seed;
    move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Runs `shader_check.comp` on `inputs` (four vec4 per case) for `camera`.
fn evaluate_on_gpu(camera: &Camera, inputs: &[[f32; 4]]) -> Vec<[f32; 4]> {
    with_gpu(|ctx| {
        let pipeline = ComputePipeline::<Push>::new(
            ctx,
            "shader_check",
            SHADER_CHECK,
            &[Binding::StorageBuffer, Binding::StorageBuffer],
        )
        .unwrap();
        let bytes: &[u8] = bytemuck::cast_slice(inputs);
        let usage = ash::vk::BufferUsageFlags::STORAGE_BUFFER;
        let mut input = Buffer::new(
            ctx,
            "check inputs",
            bytes.len() as u64,
            usage,
            MemoryLocation::CpuToGpu,
        )
        .unwrap();
        input.mapped_mut().unwrap().copy_from_slice(bytes);
        let output = Buffer::new(
            ctx,
            "check outputs",
            bytes.len() as u64,
            usage,
            MemoryLocation::GpuToCpu,
        )
        .unwrap();
        let cases = (inputs.len() / 4) as u32;
        let mut frame = Frame::begin(ctx, "shader check").unwrap();
        frame.pass("shader_check", |rec| {
            rec.dispatch(
                &pipeline,
                &[Bind::StorageBuffer(&input), Bind::StorageBuffer(&output)],
                &Push {
                    count: cases,
                    f_px: camera.f_px(),
                    aperture_radius: camera.aperture_radius,
                    focus_distance: camera.focus_distance,
                },
                [groups(cases, 64), 1, 1],
            );
            rec.memory_barrier(Access::COMPUTE_WRITE, Access::HOST_READ);
        });
        frame.submit_and_wait().unwrap();
        bytemuck::cast_slice(output.mapped().unwrap()).to_vec()
    })
}

#[test]
fn lens_concentric_and_aperture_includes_agree_with_the_cpu() {
    let camera = Camera {
        width: 640,
        height: 480,
        eye: Vec3::ZERO,
        target: Vec3::new(0.0, 0.0, -1.0),
        up: Vec3::Y,
        fovy_deg: 40.0,
        aperture_radius: 0.05,
        focus_distance: 2.0,
        aperture: Aperture::ROUND,
    };
    let mut next = uniform(7);
    let mut inputs = Vec::new();
    let n = 4096;
    for i in 0..n {
        // Depths from 0.05 to 40 around S = 2, exactly S, and the background.
        let z = match i {
            0 => camera.focus_distance,
            1 => f32::INFINITY,
            _ => 0.05 + 40.0 * next() * next(),
        };
        let lens_u = concentric_disk(Vec2::new(2.0 * next() - 1.0, 2.0 * next() - 1.0));
        // Square points over [−1, 1]², the axes and the diagonals included;
        // disk points inside the unit disk, the centre included.
        let a = match i % 4 {
            0 => Vec2::new(2.0 * next() - 1.0, 0.0),
            1 => Vec2::splat(2.0 * next() - 1.0),
            _ => Vec2::new(2.0 * next() - 1.0, 2.0 * next() - 1.0),
        };
        let u = if i == 2 {
            Vec2::ZERO
        } else {
            concentric_disk(Vec2::new(2.0 * next() - 1.0, 2.0 * next() - 1.0))
        };
        inputs.push([z, lens_u.x, lens_u.y, 0.0]);
        inputs.push([a.x, a.y, u.x, u.y]);
        // The cat's eye: pixels over the frame and past its corners (|d|
        // up to 1.2), CoC ranges on either side of the focus up to past
        // the frame's half diagonal (where k changes sign), shapes from a
        // sliver to round, S from 0 to 1.
        let d = Vec2::new(2.4 * next() - 1.2, 2.4 * next() - 1.2);
        let coc = Vec2::new(900.0 * next() * next(), 900.0 * next() * next());
        let shape_reach = [1.0, 0.866_025_4, 0.25 + 0.75 * next()][i % 3];
        let cat_eye = if i % 7 == 0 { 1.0 } else { next() };
        let behind = (i % 2) as f32;
        // Centres at the frame's centre (none) and next to it (the
        // press's axis below float precision) among them.
        let centre = match i {
            3 => Vec2::ZERO,
            4 => Vec2::new(3.0e-20, -1.0e-20),
            _ => -2.0 * cat_eye * d,
        };
        inputs.push([centre.x, centre.y, coc.x, coc.y]);
        inputs.push([shape_reach, cat_eye, behind, 400.0]);
    }
    let outputs = evaluate_on_gpu(&camera, &inputs);
    assert_eq!(outputs.len(), inputs.len());
    // The cat's eye's reach: + − × ÷, abs, min, max and one length (a
    // square root, which Vulkan lets differ by a few ulp): 1e-5 of a CoC.
    let (mut worst_reach, mut zero_reach, mut some_reach) = (0.0f32, 0, 0);
    for case in 0..n {
        let [cx, cy, c0, c1] = inputs[4 * case + 2];
        let [shape_reach, cat_eye, behind, half_diag] = inputs[4 * case + 3];
        let gpu = outputs[4 * case + 2][0];
        let cpu = pointlens::camera::Aperture::cat_eye_blur_reach(
            shape_reach,
            cat_eye,
            Vec2::new(cx, cy),
            half_diag,
            Vec2::new(c0, c1),
            behind > 0.5,
        );
        worst_reach = worst_reach.max((gpu - cpu).abs());
        zero_reach += (cpu == 0.0) as u32;
        some_reach += (cpu > 0.0) as u32;
    }
    assert!(
        worst_reach <= 1e-5,
        "cat_eye_blur_reach: worst difference {worst_reach}"
    );
    // The inputs reach both outcomes: a blur and none (a sliver, or k's
    // sign changing over the range).
    assert!(
        zero_reach > n as u32 / 50 && some_reach > n as u32 / 2,
        "cat_eye_blur_reach: {zero_reach} zero, {some_reach} positive of {n}"
    );
    // The cat's eye's pressed lens and an RDB bin's weight: + − × ÷, max,
    // a length and a square root: 1e-5; the weights a ramp across 2·h of
    // lens radius (h = 0.1·√area), compared where h is at least 0.02
    // (past touching circles it shrinks to nothing: a step).
    let (mut worst_lens, mut worst_weight, mut weighed) = (0.0f32, 0.0f32, 0);
    for case in 0..n {
        let [_, _, dx, dy] = inputs[4 * case + 1];
        let [cx, cy, _, _] = inputs[4 * case + 2];
        let [lx, ly, weight, area] = outputs[4 * case + 3];
        let (u, centre) = (Vec2::new(dx, dy), Vec2::new(cx, cy));
        let cpu_lens = Aperture::cat_eye_lens(u, centre);
        if case == 3 || case == 4 {
            assert_eq!(cpu_lens, u, "no press at centre {centre}");
        }
        worst_lens = worst_lens.max((Vec2::new(lx, ly) - cpu_lens).length());
        let cpu_area = Aperture::cat_eye_lens_area(centre);
        worst_lens = worst_lens.max((area - cpu_area).abs());
        if cpu_area >= 0.04 {
            let cpu_weight = Aperture::cat_eye_pressed_weight(u, centre, 0.9 * centre, 0.1);
            worst_weight = worst_weight.max((weight - cpu_weight).abs());
            weighed += 1;
        }
    }
    assert!(
        worst_lens <= 1e-5,
        "cat_eye_lens: worst difference {worst_lens}"
    );
    assert!(
        worst_weight <= 1e-4 && weighed > n / 10,
        "cat_eye_pressed_weight: worst difference {worst_weight} over {weighed} cases"
    );
    // Tolerances: the lens formulas use only + − × ÷ and abs, so both sides
    // agree but for the GPU's division (2.5 ulp allowed): 1e-6 relative.
    // The maps go through sin, cos and atan, which Vulkan does not require
    // to be correctly rounded (lavapipe measures 3.3e-6 here): 1e-5.
    let (mut worst_coc, mut worst_offset, mut worst_map) = (0.0f32, 0.0f32, 0.0f32);
    let mut signs_differ = 0;
    let mut bins_differ = 0;
    for case in 0..n {
        let [z, ux, uy, _] = inputs[4 * case];
        let [ax, ay, dx, dy] = inputs[4 * case + 1];
        let [c, ox, oy, signed_c] = outputs[4 * case];
        let [disk_x, disk_y, square_x, square_y] = outputs[4 * case + 1];
        let cpu_c = camera.coc_px(z);
        worst_coc = worst_coc.max((c - cpu_c).abs() / cpu_c.max(1.0));
        let cpu_signed = camera.signed_coc_px(z);
        worst_coc = worst_coc.max((signed_c - cpu_signed).abs() / cpu_c.max(1.0));
        signs_differ += (signed_c.is_sign_negative() != cpu_signed.is_sign_negative()) as u32;
        let cpu_offset = camera.lens_offset_px(z, Vec2::new(ux, uy));
        worst_offset = worst_offset.max((Vec2::new(ox, oy) - cpu_offset).length() / cpu_c.max(1.0));
        let cpu_disk = concentric_disk(Vec2::new(ax, ay));
        let cpu_square = concentric_square(Vec2::new(dx, dy));
        worst_map = worst_map
            .max((Vec2::new(disk_x, disk_y) - cpu_disk).length())
            .max((Vec2::new(square_x, square_y) - cpu_square).length());
        // What the RDB's pairs mode takes from the inverse map: the bin.
        let gpu_bin = {
            let cell = |v: f32| (((v + 1.0) * 0.5 * 9.0).floor() as i64).clamp(0, 8) as u32;
            cell(square_y) * 9 + cell(square_x)
        };
        bins_differ += (gpu_bin != rdb_bin(Vec2::new(dx, dy), 9)) as u32;
    }
    assert!(
        worst_coc <= 1e-6,
        "coc_px: worst relative difference {worst_coc}"
    );
    assert_eq!(signs_differ, 0, "signed_coc_px: signs differ");
    assert!(
        worst_offset <= 1e-6,
        "lens_offset_px: worst difference {worst_offset} (relative to the CoC)"
    );
    assert!(
        worst_map <= 1e-5,
        "concentric map: worst difference {worst_map}"
    );
    // A bin can only differ for a point within ~1e-6 of a cell boundary;
    // random points land there with probability ~1e-5.
    assert!(bins_differ <= 1, "{bins_differ} of {n} RDB bins differ");
}
