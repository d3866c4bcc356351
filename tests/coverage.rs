//! The G-buffer's area coverage (`--coverage area`, the default): a pixel
//! whose 3×3 neighbourhood's samples do not all see one splat takes its
//! color from the visible areas of the nearest splats its samples found
//! (`src/passes/gbuffer_area.rs`); every other pixel keeps its samples'
//! mean, bit for bit. Under validation.

mod common;

use common::{differing, pass_count, root, with_gpu};
use glam::Vec3;
use pointlens::bench::BenchModel;
use pointlens::cloud::PointCloud;
use pointlens::image_io::LinearImage;
use pointlens::metrics::psnr;
use pointlens::options::{Coverage, Lod, Method, Raster};
use pointlens::render::{RenderOptions, Renderer, Scene, SplatSize};

fn render(
    renderer: &mut Renderer,
    scene: &Scene,
    options: &RenderOptions,
    coverage: Option<Coverage>,
) -> LinearImage {
    renderer.set_coverage(coverage);
    let r = renderer.render(scene, options).expect("render");
    let areas = pass_count(&r, "gbuffer.area");
    let area = coverage.unwrap_or_default() == Coverage::Area;
    let want = u32::from(area && !matches!(options.method, Method::Accum(_)));
    assert_eq!(areas, want, "{coverage:?} {:?}", options.method);
    r.image
}

/// The G-buffer's color is half floats: 0.3 is stored 0.29980.
const HALF_STEP: f32 = 2.5e-4;

/// The bunny on the compute raster: the renderer, the cloud and its scene.
fn bunny(ctx: &std::sync::Arc<pointlens::vk::Context>) -> (Renderer, PointCloud, Scene) {
    let mut renderer = Renderer::new(ctx).unwrap();
    renderer.set_raster(Raster::Compute);
    let cloud = BenchModel::Bunny.load(&root().join("data"), 0).unwrap();
    let scene = renderer.upload(&cloud, SplatSize::Spacing).unwrap();
    (renderer, cloud, scene)
}

/// The bunny's pinhole frame at `width` × `height`: every splat, K = 3,
/// over a blue background.
fn bunny_pinhole(cloud: &PointCloud, width: u32, height: u32) -> RenderOptions {
    RenderOptions {
        camera: BenchModel::Bunny.camera(cloud, width, height).unwrap(),
        method: Method::Pinhole,
        ssaa: 3,
        samples_per_pass: None,
        background: Vec3::new(0.05, 0.1, 0.2),
        lod: Lod {
            px: 0.0,
            blur: None,
            cull_back_faces: false,
        },
    }
}

/// One white splat 40.6 px wide at the centre (48, 36) of a 96×72 frame:
/// its square spans [27.7, 68.3) × [15.7, 56.3), so the pixels along its
/// edges are covered 0.3 of their area, its corners 0.09. By area the
/// horizontal edges come out exact (a box's y edges cut the pixel's rows
/// exactly; to the half float the G-buffer stores), the vertical ones within 1/128 (its x edges count in 64ths of
/// a pixel), at every K, where the samples give 1/K² steps (K = 3: 1/3,
/// 0.033 off). Every pixel of the edges' rows and columns is so: the
/// marking takes each pixel an edge crosses. The pixels away from the
/// edges keep the samples' mean bit for bit.
#[test]
fn area_coverage_sees_a_square_edge_as_its_area() {
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        renderer.set_raster(Raster::Compute);
        let one = common::cloud(&[(Vec3::new(0.0, 0.0, -2.0), Vec3::ONE)]);
        let scene = renderer.upload(&one, SplatSize::Pixels(40.6)).unwrap();
        for k in 1..=4u32 {
            let options = RenderOptions {
                ssaa: k,
                ..common::options(common::camera(96, 72), Method::Pinhole)
            };
            let area = render(&mut renderer, &scene, &options, Some(Coverage::Area));
            let samples = render(&mut renderer, &scene, &options, Some(Coverage::Samples));
            let alpha = |x: usize, y: usize| area.pixels[y * 96 + x][3];
            let (mut rows, mut columns) = (0.0f32, 0.0f32);
            for t in 16..=55 {
                // Left and right edges (x), top and bottom (y).
                for (x, y) in [(27, t), (68, t)] {
                    columns = columns.max((alpha(x, y) - 0.3).abs());
                }
                for (x, y) in [(t + 12, 15), (t + 12, 56)] {
                    rows = rows.max((alpha(x, y) - 0.3).abs());
                }
            }
            let corner = (alpha(27, 15) - 0.09).abs();
            eprintln!("K = {k}: rows {rows:.6}, columns {columns:.6}, corner {corner:.6} off");
            assert!(rows <= HALF_STEP, "K = {k}: a row edge {rows} off");
            assert!(
                columns <= 1.0 / 128.0 + HALF_STEP,
                "K = {k}: a column edge {columns} off"
            );
            assert!(
                corner <= 0.3 / 128.0 + HALF_STEP,
                "K = {k}: the corner {corner} off"
            );
            // Away from the edges' pixels (26–29 and 66–69 across, 14–17
            // and 54–57 down), the samples' mean, bit for bit.
            let near = |v: usize, a: usize, b: usize| {
                (a - 1..=a + 2).contains(&v) || (b - 2..=b + 1).contains(&v)
            };
            for y in 0..72 {
                for x in 0..96 {
                    let i = y * 96 + x;
                    if !near(x, 27, 68) && !near(y, 15, 56) {
                        assert_eq!(area.pixels[i], samples.pixels[i], "K = {k}: ({x}, {y})");
                    }
                }
            }
        }
    });
}

/// A compute-raster renderer, the blur limit's camera (192×72, focused at
/// depth 2 through a lens of radius 0.2) and white squares 40.6 px wide,
/// each centred at (pixel x in the row of centre 36, depth z).
fn squares_in_depth(
    ctx: &std::sync::Arc<pointlens::vk::Context>,
    squares: &[(f32, f32)],
) -> (Renderer, pointlens::camera::Camera, Scene) {
    let mut renderer = Renderer::new(ctx).unwrap();
    renderer.set_raster(Raster::Compute);
    let camera = pointlens::camera::Camera {
        aperture_radius: 0.2,
        focus_distance: 2.0,
        ..common::camera(192, 72)
    };
    let f = camera.f_px();
    let points: Vec<_> = squares
        .iter()
        .map(|&(x, z)| (Vec3::new((x - 96.0) * z / f, 0.0, -z), Vec3::ONE))
        .collect();
    let scene = renderer
        .upload(&common::cloud(&points), SplatSize::Pixels(40.6))
        .unwrap();
    (renderer, camera, scene)
}

/// The G-buffer's coverage down the middle rows (26–45) of two columns,
/// the frame rendered with `method` at K = 3 and `coverage`.
fn edge_alphas(
    renderer: &mut Renderer,
    scene: &Scene,
    camera: pointlens::camera::Camera,
    method: Method,
    coverage: Coverage,
    columns: [u32; 2],
) -> (Vec<f32>, Vec<f32>) {
    renderer.set_coverage(Some(coverage));
    let options = RenderOptions {
        ssaa: 3,
        ..common::options(camera, method)
    };
    let (_, g) = renderer.render_with_gbuffer(scene, &options).unwrap();
    let column = |x: u32| -> Vec<f32> {
        (26..46u32)
            .map(|y| g.color[((y + g.guard) * g.width + x + g.guard) as usize][3])
            .collect()
    };
    (column(columns[0]), column(columns[1]))
}

/// Through a lens that blurs the G-buffer after it, a pixel whose every
/// splat blurs past `AREA_BLUR_LIMIT_PX` keeps its samples' mean: two
/// splats 40.6 px wide side by side, one at the focus (its left edge's
/// pixels covered 0.3, by area to 1/128) and one far behind it (a CoC of 14.8 px), in the
/// G-buffer of `fast`. The in-focus square's edges resolve by area, the
/// far one's by the samples (K = 3: 1/3), bit for bit as with samples; the
/// pinhole method, which does not blur its G-buffer, takes both by area.
/// A shape blurs less far across than the CoC's disk, so the limit grows
/// by its least reach: through `layered`, 6 blades (cos 30°) leave the far
/// square to its samples, and the same squeezed 4 times take it by area.
#[test]
fn a_blurred_pixel_keeps_its_samples_where_the_lens_blurs_past_the_limit() {
    use pointlens::passes::gbuffer_area::AREA_BLUR_LIMIT_PX;
    with_gpu(|ctx| {
        let (mut renderer, camera, scene) = squares_in_depth(ctx, &[(48.0, 2.0), (144.0, 8.0)]);
        let far_coc = camera.coc_px(8.0);
        assert!(far_coc > AREA_BLUR_LIMIT_PX, "{far_coc} px");
        let alphas = |renderer: &mut Renderer, camera, method: Method, coverage: Coverage| {
            // The left edge's column of each square.
            edge_alphas(renderer, &scene, camera, method, coverage, [27, 123])
        };
        let fast = Method::Fast(Default::default());
        let (near, far) = alphas(&mut renderer, camera, fast, Coverage::Area);
        let (near_samples, far_samples) = alphas(&mut renderer, camera, fast, Coverage::Samples);
        let (_, far_pinhole) = alphas(&mut renderer, camera, Method::Pinhole, Coverage::Area);
        // A shape blurs less far across than the CoC's disk: the limit
        // grows by its least reach, cos 30° for 6 blades (the far square
        // still past it) and a quarter of that squeezed 4 times (no longer
        // past it), through layered (fast's gather refuses shapes).
        let shaped = |ratio: f32| pointlens::camera::Camera {
            aperture: pointlens::camera::Aperture {
                blades: 6,
                ratio,
                ..pointlens::camera::Aperture::ROUND
            },
            ..camera
        };
        let layered = Method::layered(2);
        let (_, far_hexagon) = alphas(&mut renderer, shaped(1.0), layered, Coverage::Area);
        let (_, far_hexagon_samples) =
            alphas(&mut renderer, shaped(1.0), layered, Coverage::Samples);
        let (_, far_squeezed) = alphas(&mut renderer, shaped(4.0), layered, Coverage::Area);
        eprintln!(
            "fast: near {:?}, far {:?}; pinhole: far {:?}; layered, 6 blades: far {:?}, squeezed {:?}",
            near[0], far[0], far_pinhole[0], far_hexagon[0], far_squeezed[0]
        );
        // A box's x edges count in 64ths of a pixel (as above).
        let column_edge = 1.0 / 128.0 + HALF_STEP;
        for (i, ((n, f), p)) in near.iter().zip(&far).zip(&far_pinhole).enumerate() {
            assert!((n - 0.3).abs() <= column_edge, "row {i}: near {n}");
            assert!((p - 0.3).abs() <= column_edge, "row {i}: pinhole's far {p}");
            let squeezed = far_squeezed[i];
            assert!(
                (squeezed - 0.3).abs() <= column_edge,
                "row {i}: squeezed far {squeezed}"
            );
            let hexagon = far_hexagon[i];
            assert_eq!(
                hexagon.to_bits(),
                far_hexagon_samples[i].to_bits(),
                "row {i}: 6 blades' far {hexagon}"
            );
            assert!((near_samples[i] - 1.0 / 3.0).abs() <= HALF_STEP, "row {i}");
            assert_eq!(f.to_bits(), far_samples[i].to_bits(), "row {i}: far {f}");
        }
    });
}

/// With the cat's eye, a pixel's limit grows by what its clipped lens
/// leaves of the blur (`Aperture::cat_eye_blur_reach`): two squares far
/// behind the focus (CoC 14.8 px; the background's 19.7) in a 192×72
/// frame, their left edges at columns 123 and 179, through `layered` with
/// S = 1. At column 123 (|d| ≈ 0.28) the blur still spans 0.68 of the
/// CoC, 10 px: its samples, bit for bit; at column 179 (|d| ≈ 0.82) only
/// 0.22, 3.3 px: by area. At S = 0.5 both keep their samples.
#[test]
fn the_cat_s_eye_leaves_a_pixel_to_its_samples_where_its_clipped_lens_still_blurs_past_the_limit() {
    with_gpu(|ctx| {
        let (mut renderer, camera, scene) = squares_in_depth(ctx, &[(144.0, 8.0), (200.0, 8.0)]);
        let mut alphas = |cat_eye: f32, coverage: Coverage| {
            let camera = pointlens::camera::Camera {
                aperture: pointlens::camera::Aperture {
                    cat_eye,
                    ..pointlens::camera::Aperture::ROUND
                },
                ..camera
            };
            let layered = Method::layered(2);
            edge_alphas(&mut renderer, &scene, camera, layered, coverage, [123, 179])
        };
        let column_edge = 1.0 / 128.0 + HALF_STEP;
        for cat_eye in [1.0, 0.5] {
            let (inner, outer) = alphas(cat_eye, Coverage::Area);
            let (inner_samples, outer_samples) = alphas(cat_eye, Coverage::Samples);
            for i in 0..inner.len() {
                assert_eq!(
                    inner[i].to_bits(),
                    inner_samples[i].to_bits(),
                    "S = {cat_eye}, row {i}: column 123's {}",
                    inner[i]
                );
                assert!(
                    (inner_samples[i] - 1.0 / 3.0).abs() <= HALF_STEP,
                    "S = {cat_eye}, row {i}: samples' {}",
                    inner_samples[i]
                );
                if cat_eye == 1.0 {
                    assert!(
                        (outer[i] - 0.3).abs() <= column_edge,
                        "S = 1, row {i}: column 179's {}",
                        outer[i]
                    );
                } else {
                    assert_eq!(
                        outer[i].to_bits(),
                        outer_samples[i].to_bits(),
                        "S = {cat_eye}, row {i}: column 179's {}",
                        outer[i]
                    );
                }
            }
        }
    });
}

/// A frame that one splat covers whole, and one with nothing in it: every
/// pixel's samples see one word, none is marked, and the images are the
/// samples' bit for bit.
#[test]
fn a_frame_of_one_splat_keeps_its_samples_bit_for_bit() {
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        renderer.set_raster(Raster::Compute);
        let one = common::cloud(&[(Vec3::new(0.0, 0.0, -2.0), Vec3::new(0.2, 0.5, 0.9))]);
        let behind = common::cloud(&[(Vec3::new(0.0, 0.0, 2.0), Vec3::ONE)]);
        for (cloud, what) in [(one, "one splat"), (behind, "nothing in view")] {
            let scene = renderer.upload(&cloud, SplatSize::Pixels(250.0)).unwrap();
            let options = RenderOptions {
                ssaa: 3,
                background: Vec3::new(0.05, 0.1, 0.2),
                ..common::options(common::camera(96, 72), Method::Pinhole)
            };
            let area = render(&mut renderer, &scene, &options, Some(Coverage::Area));
            let samples = render(&mut renderer, &scene, &options, Some(Coverage::Samples));
            assert_eq!(differing(&area, &samples), 0, "{what}");
        }
    });
}

/// The bunny's checker and outline (every splat) at 320×240: by area at
/// K = 3 the pinhole G-buffer comes closer to the compute raster's K = 8
/// than its K = 3 samples do, and each depth-of-field method, against
/// accum 32 (which takes its own samples: area coverage is of one lens
/// position), is no further than with the samples. Measured (printed):
/// pinhole 43.35 dB by samples, 51.13 by area against K = 8; layered,
/// fast and rdb 0.33–0.49 dB closer to accum 32 by area. (At 160×120
/// the bunny's splats are smaller than a pixel, more than a pixel's
/// candidates or missed by every sample: 39.57 and 40.52 dB.)
#[test]
fn area_coverage_brings_the_edges_near_k8_and_every_method_follows() {
    with_gpu(|ctx| {
        let (mut renderer, cloud, scene) = bunny(ctx);
        let base = bunny_pinhole(&cloud, 320, 240);
        let k8 = RenderOptions { ssaa: 8, ..base };
        let converged = render(&mut renderer, &scene, &k8, Some(Coverage::Samples));
        let samples = render(&mut renderer, &scene, &base, Some(Coverage::Samples));
        let area = render(&mut renderer, &scene, &base, Some(Coverage::Area));
        let (s, a) = (
            psnr(&converged, &samples).unwrap(),
            psnr(&converged, &area).unwrap(),
        );
        eprintln!("pinhole against K = 8: samples {s:.2} dB, area {a:.2} dB");
        assert!(a >= s + 5.0, "area {a:.2} dB, samples {s:.2} dB");
        let reference = RenderOptions {
            method: Method::accum(32),
            ssaa: 1,
            ..base
        };
        let reference = render(&mut renderer, &scene, &reference, None);
        let fast = Method::Fast(Default::default());
        for method in [Method::layered(2), fast, Method::rdb(5, Default::default())] {
            let options = RenderOptions { method, ..base };
            let s = psnr(
                &reference,
                &render(&mut renderer, &scene, &options, Some(Coverage::Samples)),
            )
            .unwrap();
            let a = psnr(
                &reference,
                &render(&mut renderer, &scene, &options, Some(Coverage::Area)),
            )
            .unwrap();
            eprintln!("{method:?} against accum 32: samples {s:.2} dB, area {a:.2} dB");
            assert!(
                a >= s - 0.05,
                "{method:?}: area {a:.2} dB, samples {s:.2} dB"
            );
        }
    });
}

/// One rule for where area coverage acts
/// (`pointlens::options::area_coverage_blocker`): asked for, it is refused
/// on a frame it cannot act on (accum, the sprite raster); left to the
/// default, such a frame takes the samples' mean.
#[test]
fn an_asked_for_area_coverage_that_cannot_act_is_refused() {
    with_gpu(|ctx| {
        let mut renderer = Renderer::new(ctx).unwrap();
        let one = common::cloud(&[(Vec3::new(0.0, 0.0, -2.0), Vec3::ONE)]);
        let scene = renderer.upload(&one, SplatSize::Pixels(10.5)).unwrap();
        let camera = common::camera(32, 24);
        for (method, raster) in [
            (Method::accum(2), Raster::Compute),
            (Method::Pinhole, Raster::Sprites),
        ] {
            let options = common::options(camera, method);
            renderer.set_raster(raster);
            renderer.set_coverage(Some(Coverage::Area));
            let err = renderer.render(&scene, &options).err().expect("refused");
            assert!(
                err.to_string().contains("--coverage area weighs"),
                "{method:?} {raster:?}: {err}"
            );
            renderer.set_coverage(None);
            let r = renderer.render(&scene, &options).expect("the default");
            assert_eq!(pass_count(&r, "gbuffer.area"), 0, "{method:?} {raster:?}");
        }
    });
}

/// The marking resolve reads no word in a tile of 8 × 8 pixels that no
/// splat's box, one target pixel past it, reaches: such a tile's windows
/// hold background alone. The same images bit for bit as with every tile
/// read, on the bunny at two sizes (the tiles fall elsewhere on it),
/// through the pinhole and two lenses, whole and in bands (a band's tiles
/// start at its target's first row). A fault that left out the pixel past
/// the box changed the bunny's pinhole image at 320×240.
#[test]
fn skipping_the_tiles_no_splat_reaches_changes_no_byte() {
    with_gpu(|ctx| {
        let (mut renderer, cloud, scene) = bunny(ctx);
        let fast = Method::Fast(Default::default());
        for (width, height) in [(320, 240), (203, 151)] {
            let base = bunny_pinhole(&cloud, width, height);
            for (method, budget) in [
                (Method::Pinhole, u64::MAX),
                (Method::Pinhole, width as u64 * height as u64 * 9 * 8 / 3),
                (Method::layered(2), u64::MAX),
                (fast, u64::MAX),
            ] {
                let options = RenderOptions { method, ..base };
                renderer.set_sample_budget(budget);
                renderer.set_coverage(Some(Coverage::Area));
                let [skipped, read] = [true, false].map(|skip| {
                    renderer.set_untouched_tiles_skipped(skip);
                    renderer.render(&scene, &options).expect("render")
                });
                let what = format!("{width}×{height} {method:?}, budget {budget}");
                let bands = pass_count(&read, "gbuffer.raster");
                assert_eq!(bands > 1, budget < u64::MAX, "{what}: {bands} bands");
                assert_eq!(pass_count(&skipped, "gbuffer.area"), bands, "{what}");
                let n = differing(&skipped.image, &read.image);
                assert_eq!(n, 0, "{what}: {n} pixels differ");
            }
        }
        renderer.set_untouched_tiles_skipped(true);
    });
}
