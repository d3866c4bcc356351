//! Highlights brighter than white (linear colours above 1, as a PLY's float
//! colours above 1 give): every method carries their light through the
//! blur (the splats' codes are of the cloud's colour scale,
//! `SplatTree::color_scale`, which the G-buffer's resolves multiply back),
//! an EXR keeps it and a PNG clips after the blur, as a camera does.

mod common;

use common::{cloud, with_gpu};
use glam::Vec3;
use pointlens::image_io::{LinearImage, Srgb8Image};
use pointlens::options::{FastOptions, Method, RdbMode};
use pointlens::render::{Renderer, SplatSize};

/// Linear brightness of the highlight: 20 times white.
const BRIGHT: f32 = 20.0;

/// A 5×5 cluster of points (3 cm apart) at depth 3, colour `color`: a
/// highlight behind the focus.
fn highlight(color: Vec3) -> Vec<(Vec3, Vec3)> {
    (0..25)
        .map(|i| {
            let (x, y) = ((i % 5) as f32 - 2.0, (i / 5) as f32 - 2.0);
            (Vec3::new(0.03 * x, 0.03 * y, -3.0), color)
        })
        .collect()
}

/// A grey square of points in focus (depth 1), half the frame's width.
fn subject() -> Vec<(Vec3, Vec3)> {
    (0..40 * 40)
        .map(|i| {
            let (x, y) = ((i % 40) as f32 - 20.0, (i / 40) as f32 - 20.0);
            (
                Vec3::new(0.006 * x - 0.15, 0.006 * y, -1.0),
                Vec3::splat(0.3),
            )
        })
        .collect()
}

/// The frame through a lens of radius 0.1 focused at 1 (the highlight's
/// CoC 13 px) by `method`.
fn render(renderer: &Renderer, points: &[(Vec3, Vec3)], method: Method) -> LinearImage {
    let scene = renderer
        .upload(&cloud(points), SplatSize::Pixels(2.0))
        .unwrap();
    let mut camera = common::camera(96, 72);
    camera.aperture_radius = 0.1;
    renderer
        .render(&scene, &common::options(camera, method))
        .unwrap()
        .image
}

fn methods() -> [(&'static str, Method); 5] {
    [
        ("pinhole", Method::Pinhole),
        ("accum", Method::accum(64)),
        ("layered", Method::layered(2)),
        ("rdb", Method::rdb(9, RdbMode::Centre)),
        ("fast", Method::Fast(FastOptions::default())),
    ]
}

/// A highlight 20 times white images to 20 times the image of a white one,
/// in every method, and stays brighter than white after its blur (peaks
/// measured: pinhole 20, accum 5.47, layered 5.28, RDB 6.42, fast 5.45,
/// required above 1.5); the largest difference (measured 0.0034) is the
/// G-buffer's half floats (2^-11 of the value) and each method's sums of
/// them, held to 0.5 % of the peak.
#[test]
fn a_highlight_brighter_than_white_keeps_its_light_in_every_method() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        for (name, method) in methods() {
            let bright = render(&renderer, &highlight(Vec3::splat(BRIGHT)), method);
            let white = render(&renderer, &highlight(Vec3::ONE), method);
            let peak = bright.pixels.iter().map(|p| p[0]).fold(0.0, f32::max);
            let worst = bright
                .pixels
                .iter()
                .zip(&white.pixels)
                .map(|(b, w)| {
                    (0..3)
                        .map(|c| (b[c] - BRIGHT * w[c]).abs())
                        .fold(0.0, f32::max)
                })
                .fold(0.0, f32::max);
            eprintln!("{name}: peak {peak:.3}, largest difference from 20 × white {worst:.4}");
            assert!(
                peak > 1.5,
                "{name}: the highlight's peak {peak} is not above white"
            );
            assert!(
                worst <= 0.005 * peak,
                "{name}: {worst} from 20 times the white highlight's image (peak {peak})"
            );
        }
    });
}

/// A grey subject in focus with the highlight behind it: each method's PNG
/// is its linear frame encoded (clipped at white after the blur), the
/// highlight clips to 255 where it is brighter than white, and the
/// subject's grey is that of the subject alone to within the 16-bit codes
/// of the brighter scale (a code step of 20/65535).
#[test]
fn a_png_clips_the_highlight_after_the_blur() {
    with_gpu(|ctx| {
        let renderer = Renderer::new(ctx).unwrap();
        let mut points = subject();
        points.extend(highlight(Vec3::splat(BRIGHT)));
        let scene = renderer
            .upload(&cloud(&points), SplatSize::Pixels(2.0))
            .unwrap();
        assert_eq!(scene.tree().color_scale(), BRIGHT);
        let alone = renderer
            .upload(&cloud(&subject()), SplatSize::Pixels(2.0))
            .unwrap();
        assert_eq!(alone.tree().color_scale(), 1.0);
        let mut camera = common::camera(96, 72);
        camera.aperture_radius = 0.1;
        for (name, method) in methods() {
            let options = common::options(camera, method);
            let linear = renderer.render(&scene, &options).unwrap().image;
            let png = renderer.render_srgb8(&scene, &options).unwrap().image;
            assert_eq!(png, Srgb8Image::of(&linear), "{name}");
            let clipped = linear.pixels.iter().filter(|p| p[0] > 1.0).count();
            assert!(clipped > 0, "{name}: no pixel brighter than white");
            // The subject's centre, far from the highlight's blur.
            let subject_only = renderer.render(&alone, &options).unwrap().image;
            let at = (36 * 96 + 28) as usize;
            let (a, b) = (linear.pixels[at][0], subject_only.pixels[at][0]);
            assert!(
                (a - b).abs() <= 1e-3,
                "{name}: the subject {a} against {b} alone"
            );
        }
    });
}

/// Through the command line: a PLY whose float colours are 2 (4.95 times
/// white) says so in `info` and renders its light into the EXR; colours
/// brighter than 128 times white (a float of 40) are clamped to it with a
/// warning, and layered, in focus, renders the cap whole (its fixed-point
/// sums hold 512); `convert` warns that LAS's RGB clips them to white.
#[test]
fn the_command_line_keeps_highlights_and_says_what_it_clamps() {
    let dir = common::scratch("highlights-cli");
    let write = |name: &str, value: f64| {
        let path = dir.join(name);
        let rows: Vec<Vec<f64>> = (0..16)
            .map(|i| {
                vec![
                    (i % 4) as f64 * 0.01,
                    (i / 4) as f64 * 0.01,
                    0.0,
                    value,
                    value,
                    value,
                ]
            })
            .collect();
        common::write_binary_ply(&path, &common::XYZ_RGB_FLOATS, &rows);
        path
    };
    let (bright, blinding) = (write("bright.ply", 2.0), write("blinding.ply", 40.0));
    // A frame of `input` by `method` into an EXR: the image's peak red
    // and the run's stderr.
    let render = |input: &std::path::Path, method: &str| {
        let exr = input.with_extension(format!("{method}.exr"));
        let (input, out) = (input.to_str().unwrap(), exr.to_str().unwrap());
        let frame = ["--width", "48", "--height", "36", "--method", method];
        let mut args = vec!["render", input, "-o", out];
        args.extend_from_slice(&frame);
        let err = String::from_utf8_lossy(&common::assert_runs(&args).stderr).into_owned();
        let image = pointlens::image_io::read_image(&exr).unwrap();
        let peak = image.pixels.iter().map(|p| p[0]).fold(0.0, f32::max);
        (peak, err)
    };
    let info = common::assert_runs(&["info", bright.to_str().unwrap()]);
    let info = String::from_utf8_lossy(&info.stdout);
    assert!(
        info.contains("colors: yes, brighter than white (brightest channel 4.95"),
        "{info}"
    );
    let (peak, err) = render(&bright, "pinhole");
    assert!(!err.contains("brighter"), "{err}");
    assert!(peak > 4.9 && peak < 5.0, "peak {peak}");
    let (peak, err) = render(&blinding, "pinhole");
    assert!(
        err.contains(
            "16 points are brighter than 128 times white (linear); their colours are clamped to it"
        ),
        "{err}"
    );
    assert_eq!(peak, 128.0);
    let (peak, _) = render(&blinding, "layered");
    assert!((peak - 128.0).abs() < 0.1, "layered's peak {peak}");
    let copc = dir.join("bright.copc.laz");
    let o = common::assert_runs(&[
        "convert",
        bright.to_str().unwrap(),
        "-o",
        copc.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("16 points are brighter than white (float colours above 1), which LAS's 16-bit RGB cannot hold: their colours are clipped to white"),
        "{err}"
    );
}
