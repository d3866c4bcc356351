//! Posters in tiles (issue 29, item 6; docs/ARCHITECTURE.md, "Posters in
//! tiles"): a frame rendered window by window, each with the whole frame's
//! splats, depth range and guard band, is the frame rendered whole, for
//! every method, under the veil and eye-dome lighting; a poster wider than
//! the device's largest image renders.
//!
//! Tolerance: a tile's projection moves the whole frame's by an integer
//! number of pixels, so a sprite's position rounds differently in the last
//! bit of its float, and a sample on a splat's very edge may fall the other
//! way (lavapipe snaps sprites to whole pixels: `viewportSubPixelBits` 0).
//! The measured differences are a few such samples; the floors below are
//! far above what a misplaced tile or a missing guard band gives (a tile
//! shifted by one pixel is below 30 dB, checked).

mod common;

use common::{differing, pass_count, pointlens, root, scratch, with_gpu};
use glam::Vec3;
use pointlens::camera::{Camera, CameraSpec};
use pointlens::image_io::{read_image, write_image, LinearImage};
use pointlens::metrics::{difference_image, psnr};
use pointlens::options::{
    EdlOptions, FastGather, FastOptions, FastWeights, GatherWindow, Lod, Method, Raster, RdbMode,
};
use pointlens::render::{RenderOptions, Renderer, Scene, SplatSize};
use pointlens::PointCloud;

/// The tile side the tests force: tiles far smaller than the frame and
/// than the guard band, with frames of odd sizes, so that every tile edge
/// lies in the image.
const TILE_PX: u32 = 24;

fn bunny() -> PointCloud {
    pointlens::input::ply::load_ply(&root().join("data/bunny_colored.ply")).unwrap()
}

/// The bunny's automatic camera at `width` × `height`, with a lens of
/// `aperture_radius` focused on its nearest part.
fn bunny_camera(cloud: &PointCloud, width: u32, height: u32, aperture_radius: f32) -> Camera {
    let (lo, hi) = cloud.bounds();
    let spec = CameraSpec {
        width: Some(width),
        height: Some(height),
        ..CameraSpec::default()
    };
    let camera = pointlens::camera::resolve(&spec, lo, hi, &cloud.positions).unwrap();
    Camera {
        aperture_radius,
        focus_distance: 0.8 * camera.focus_distance,
        ..camera
    }
}

fn options(camera: Camera, method: Method) -> RenderOptions {
    RenderOptions {
        camera,
        method,
        ssaa: 2,
        samples_per_pass: None,
        background: Vec3::new(0.1, 0.2, 0.4),
        lod: Lod::default(),
    }
}

fn render(renderer: &Renderer, scene: &Scene, options: &RenderOptions) -> LinearImage {
    match renderer.render(scene, options) {
        Ok(r) => r.image,
        Err(e) => panic!("{:?}: {e}", options.method),
    }
}

/// Requires `tiled` to be `whole` within `min_db`; on failure writes both
/// and their difference (×4) beside each other in a scratch folder, kept.
fn assert_same_frame(name: &str, whole: &LinearImage, tiled: &LinearImage, min_db: f64) {
    let db = psnr(whole, tiled).unwrap();
    let differing = differing(whole, tiled);
    eprintln!(
        "{name}: tiled vs whole {db:.2} dB, {differing} of {} pixels differ",
        whole.pixels.len()
    );
    if db < min_db {
        let dir = std::env::temp_dir().join(format!("pointlens-tiles-{name}"));
        std::fs::create_dir_all(&dir).unwrap();
        write_image(whole, &dir.join("whole.png")).unwrap();
        write_image(tiled, &dir.join("actual.png")).unwrap();
        let diff = difference_image(whole, tiled, 0.25).unwrap();
        write_image(&diff, &dir.join("difference.png")).unwrap();
        panic!(
            "{name}: the tiled frame is {db:.2} dB from the whole one, below {min_db} dB; \
             see {}",
            dir.display()
        );
    }
}

/// Every method's frame in 24-pixel tiles is its frame rendered whole: a
/// 97×71 view of the bunny with a lens whose blur reaches ~20 px, so that
/// each tile's guard band holds blur from its neighbours; and those that
/// follow the cat's eye, with it at S = 1.
#[test]
fn every_method_renders_the_same_frame_in_tiles() {
    with_gpu(|ctx| {
        let cloud = bunny();
        let whole_renderer = Renderer::new(ctx).unwrap();
        let mut tiled_renderer = Renderer::new(ctx).unwrap();
        tiled_renderer.set_tile_px(Some(TILE_PX));
        let scene = whole_renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        let tiled_scene = tiled_renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        let camera = bunny_camera(&cloud, 97, 71, 0.06);
        let methods = [
            ("pinhole", Method::Pinhole, 60.0),
            (
                "fast",
                Method::paper_fast(FastWeights::Area, GatherWindow::Tiles),
                60.0,
            ),
            (
                "fast-fields",
                Method::Fast(FastOptions {
                    weights: FastWeights::Area,
                    window: GatherWindow::Tiles,
                    gather: FastGather::Fields,
                }),
                60.0,
            ),
            ("rdb9", Method::rdb(9, RdbMode::Centre), 60.0),
            ("layered2", Method::layered(2), 60.0),
            ("accum16", Method::accum(16), 60.0),
            // The cat's eye: each pixel's lens is its own by its place in
            // the whole frame (RDB's bins pressed into it by the scatter).
            ("rdb9 cat's eye", Method::rdb(9, RdbMode::Centre), 60.0),
            ("layered2 cat's eye", Method::layered(2), 60.0),
            ("accum16 cat's eye", Method::accum(16), 60.0),
        ];
        for (name, method, floor) in methods {
            let mut camera = camera;
            if name.ends_with("cat's eye") {
                camera.aperture.cat_eye = 1.0;
            }
            let options = options(camera, method);
            let whole = whole_renderer.render(&scene, &options).unwrap();
            let tiled = tiled_renderer.render(&tiled_scene, &options).unwrap();
            assert_eq!(whole.guard, tiled.guard, "{name}: one guard band");
            eprintln!("{name}: guard band {} px", whole.guard);
            // accum's band holds only its squares: each lens position
            // projects every point itself (its tiles still blur across
            // their seams).
            if name != "pinhole" && !name.starts_with("accum16") {
                assert!(
                    whole.guard >= TILE_PX / 3,
                    "{name}: a guard band of {} px does not reach across a tile",
                    whole.guard
                );
            }
            // The tiles' timings add up: 5 × 3 tiles drew a G-buffer each.
            assert_eq!(
                pass_count(&tiled, "output"),
                15,
                "{name}: one output pass per tile"
            );
            assert_same_frame(name, &whole.image, &tiled.image, floor);
        }
    });
}

/// The sprite raster (hardware points, snapped to whole pixels on
/// lavapipe) gives the same frame in tiles as the compute raster does.
#[test]
fn the_sprite_raster_renders_the_same_frame_in_tiles() {
    with_gpu(|ctx| {
        let cloud = bunny();
        let mut whole_renderer = Renderer::new(ctx).unwrap();
        let mut tiled_renderer = Renderer::new(ctx).unwrap();
        whole_renderer.set_raster(Raster::Sprites);
        tiled_renderer.set_raster(Raster::Sprites);
        tiled_renderer.set_tile_px(Some(TILE_PX));
        let scene = whole_renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        let tiled_scene = tiled_renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        let camera = bunny_camera(&cloud, 97, 71, 0.06);
        for (name, method) in [
            ("sprites-pinhole", Method::Pinhole),
            ("sprites-rdb9", Method::rdb(9, RdbMode::Centre)),
            ("sprites-accum16", Method::accum(16)),
        ] {
            let options = options(camera, method);
            let whole = render(&whole_renderer, &scene, &options);
            let tiled = render(&tiled_renderer, &tiled_scene, &options);
            assert_same_frame(name, &whole, &tiled, 60.0);
        }
    });
}

/// The check above can fail: the frame one pixel off its place (what a
/// tile misplaced by a pixel gives) is far below its floor.
#[test]
fn a_frame_one_pixel_off_would_fail_the_check() {
    with_gpu(|ctx| {
        let cloud = bunny();
        let renderer = Renderer::new(ctx).unwrap();
        let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        let camera = bunny_camera(&cloud, 97, 71, 0.06);
        let method = Method::layered(2);
        let whole = render(&renderer, &scene, &options(camera, method));
        // The whole frame shifted right by one pixel: what a tile one
        // pixel off its place gives.
        let mut shifted = whole.clone();
        for y in 0..whole.height as usize {
            for x in 1..whole.width as usize {
                let w = whole.width as usize;
                shifted.pixels[y * w + x] = whole.pixels[y * w + x - 1];
            }
        }
        let db = psnr(&whole, &shifted).unwrap();
        assert!(db < 30.0, "a shift by one pixel is {db:.2} dB");
    });
}

/// Points at the lens (a veil: composited per output pixel of the whole
/// frame) and eye-dome lighting (which reads neighbours a radius away: the
/// band holds them) come out of tiles as out of the whole frame.
#[test]
fn the_veil_and_eye_dome_lighting_are_the_same_in_tiles() {
    with_gpu(|ctx| {
        let mut cloud = bunny();
        let camera = bunny_camera(&cloud, 83, 61, 0.002);
        common::add_specks_at_the_lens(&mut cloud, &camera);
        let mut whole_renderer = Renderer::new(ctx).unwrap();
        let mut tiled_renderer = Renderer::new(ctx).unwrap();
        tiled_renderer.set_tile_px(Some(TILE_PX));
        let scene = whole_renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        let tiled_scene = tiled_renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        let options = options(camera, Method::layered(2));
        let whole = whole_renderer.render(&scene, &options).unwrap();
        let tiled = tiled_renderer.render(&tiled_scene, &options).unwrap();
        assert!(whole.lod.veiled > 0, "the specks are a veil");
        assert_same_frame("veil", &whole.image, &tiled.image, 60.0);

        let edl = Some(EdlOptions {
            strength: 1.0,
            radius_px: 3.0,
        });
        whole_renderer.set_edl(edl);
        tiled_renderer.set_edl(edl);
        let pinhole = RenderOptions {
            method: Method::Pinhole,
            ..options
        };
        let whole = whole_renderer.render(&scene, &pinhole).unwrap();
        let tiled = tiled_renderer.render(&tiled_scene, &pinhole).unwrap();
        assert!(
            whole.guard >= 3,
            "the band holds the shading's radius: {} px",
            whole.guard
        );
        assert_same_frame("edl", &whole.image, &tiled.image, 60.0);
    });
}

/// A tiled frame's G-buffer is read back as the whole frame's output part
/// (the EXR depth pass), and `--focus-pixel` reads one pixel's window.
#[test]
fn a_tiled_gbuffer_and_the_focus_pixel_are_the_whole_frames() {
    with_gpu(|ctx| {
        let cloud = bunny();
        let renderer = Renderer::new(ctx).unwrap();
        let mut tiled_renderer = Renderer::new(ctx).unwrap();
        tiled_renderer.set_tile_px(Some(TILE_PX));
        let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        let tiled_scene = tiled_renderer.upload(&cloud, SplatSize::Spacing).unwrap();
        let camera = bunny_camera(&cloud, 61, 47, 0.0);
        let options = options(camera, Method::Pinhole);
        let (_, whole) = renderer.render_with_gbuffer(&scene, &options).unwrap();
        let (_, tiled) = tiled_renderer
            .render_with_gbuffer(&tiled_scene, &options)
            .unwrap();
        assert_eq!((tiled.width, tiled.height, tiled.guard), (61, 47, 0));
        let g = whole.guard;
        let (mut seen, mut close) = (0, 0);
        for y in 0..47u32 {
            for x in 0..61u32 {
                let a = whole.eye[((y + g) * whole.width + x + g) as usize][2];
                let b = tiled.eye[(y * 61 + x) as usize][2];
                if a.is_finite() {
                    seen += 1;
                    close += usize::from((a - b).abs() <= 1e-5 * a);
                } else {
                    assert_eq!(a, b, "background at ({x}, {y}) in both");
                }
            }
        }
        assert!(seen > 500, "the bunny covers {seen} pixels");
        assert!(
            close as f64 >= 0.99 * seen as f64,
            "{close} of {seen} depths agree"
        );
        let (x, y) = (30, 23);
        let z = renderer
            .depth_at_pixel(&scene, &camera, 2, Lod::default(), x, y)
            .unwrap();
        let expected = whole.eye[((y + g) * whole.width + x + g) as usize][2];
        assert!(
            (z - expected).abs() <= 1e-5 * expected,
            "--focus-pixel {x},{y}: {z} against the G-buffer's {expected}"
        );
    });
}

/// The probe's case: a 16384×1 pinhole image (16386×3 with its band,
/// beyond lavapipe's 16384 px) and a poster 20000 px wide with depth of
/// field render, in tiles the user did not ask for; the poster is the
/// same in tiles of another size (3 of 6667 px, seams elsewhere).
#[test]
fn posters_beyond_the_device_limit_render() {
    let dir = scratch("posters");
    let data = root().join("data/bunny_colored.ply");
    let data = data.to_str().unwrap();
    let out = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    let o = pointlens(&[
        "render",
        data,
        "--method",
        "pinhole",
        "--width",
        "16384",
        "--height",
        "1",
        "-o",
        &out("line.png"),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let line = read_image(std::path::Path::new(&out("line.png"))).unwrap();
    assert_eq!((line.width, line.height), (16384, 1));

    let poster = |name: &str, extra: &[&str]| {
        let mut args = vec![
            "render", data, "--method", "rdb", "--width", "20000", "--height", "32", "--ssaa", "1",
            "-o",
        ];
        let path = out(name);
        args.push(&path);
        args.extend_from_slice(extra);
        let o = pointlens(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        read_image(std::path::Path::new(&path)).unwrap()
    };
    let auto = poster("auto.png", &[]);
    let other = poster("other.png", &["--tile-px", "7000"]);
    assert_eq!((auto.width, auto.height), (20000, 32));
    let lit = auto
        .pixels
        .iter()
        .filter(|p| p[0] + p[1] + p[2] > 0.05)
        .count();
    // The bunny, 32 px high at the centre, where two of the automatic
    // tiles of 2000 px meet (x = 10000).
    assert!(lit > 200, "the poster shows the bunny: {lit} lit pixels");
    assert_same_frame("poster", &auto, &other, 60.0);
}
