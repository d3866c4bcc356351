//! `pointlens bench`: frame timings of a matrix of methods × models ×
//! resolutions, each model seen through a fixed camera, with optional
//! quality against the accumulation reference (Zhao's Table 1, extended)
//! and of each cell's G-buffer against the pixel integral of its splats.
//!
//! A cell is one (model, resolution, method). It gets `warmup` untimed
//! frames, then `runs` timed ones; each timed frame yields per-pass GPU
//! times (timestamp queries) and the frame's wall time (command recording
//! to the result readable on the host). Cloud upload and PNG encoding are
//! measured apart and never part of a frame.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::camera::{self, Camera, CameraSpec};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::gbuffer::depth_range;
use crate::image_io::LinearImage;
use crate::input::ply::load_ply;
use crate::metrics::{psnr, ssim};
use crate::options::Lod;
use crate::options::{AccumOptions, Coverage, Method, Raster, SplatShape};
use crate::render::{RenderOptions, Renderer, Scene, SplatSize};
pub use crate::report::{DeviceReport, LodReport, Upload};
use crate::vk::{Context, FrameTimings};
use clap::ValueEnum;

/// Lens samples of the quality reference (`--quality`).
pub const REFERENCE_SAMPLES: u32 = 256;

/// K of the G-buffer reference (`--quality`): the pinhole image of every
/// splat by the means of K × K samples on the run's raster. The compute
/// raster's rotated grid sees a square's edge in steps of 1/K² of a
/// pixel: the pixel integral of the squares, as Mitsuba's pinhole render
/// of them is, without its noise (the sprites' grid in steps of 1/K).
pub const GBUFFER_REFERENCE_SSAA: u32 = 16;

/// The matrix `bench` runs when none is given, chosen by the device: the
/// full one (Zhao's Table 1 extended) on a GPU, one that finishes in a few
/// minutes on a CPU implementation such as lavapipe (where the full one
/// takes hours).
#[derive(Debug, Clone, PartialEq)]
pub struct DefaultMatrix {
    pub methods: &'static str,
    pub models: &'static str,
    pub resolutions: Vec<(u32, u32)>,
    pub runs: u32,
    pub warmup: u32,
}

impl DefaultMatrix {
    /// The default for a device of this type.
    pub fn for_device(device_type: ash::vk::PhysicalDeviceType) -> DefaultMatrix {
        if device_type == ash::vk::PhysicalDeviceType::CPU {
            DefaultMatrix {
                methods: "pinhole,fast,rdb9,layered4,accum16",
                models: "bunny,mug",
                resolutions: vec![(640, 480)],
                runs: 3,
                warmup: 1,
            }
        } else {
            DefaultMatrix {
                methods: BenchMethod::DEFAULT,
                models: BenchModel::DEFAULT,
                resolutions: vec![(640, 480), (1920, 1080)],
                runs: 5,
                warmup: 2,
            }
        }
    }

    /// One line saying what was picked.
    pub fn describe(&self) -> String {
        let resolutions: Vec<String> = self
            .resolutions
            .iter()
            .map(|(w, h)| format!("{w}x{h}"))
            .collect();
        format!(
            "methods {}, models {}, {}, {} runs after {} warm-up",
            self.methods,
            self.models,
            resolutions.join(" and "),
            self.runs,
            self.warmup
        )
    }
}

/// A method of the matrix, as named on the command line.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchMethod {
    /// `pinhole`, `fast`, `fast-uniform-tree`, `rdb9`, `rdb5-pairs`, `layered4`,
    /// `accum64`, …
    pub name: String,
    pub method: Method,
}

impl BenchMethod {
    /// The methods of the default matrix.
    pub const DEFAULT: &'static str = "pinhole,fast,rdb5,rdb9,accum64";

    /// Parses one name of `--methods` ([`Method::parse_short`]).
    pub fn parse(name: &str) -> Result<BenchMethod> {
        let method = Method::parse_short(name)
            .map_err(|e| Error::InvalidArgument(format!("--methods: {e}")))?;
        Ok(BenchMethod {
            name: name.to_string(),
            method,
        })
    }

    /// Lens samples: accum's, 1 for every other method (they all start
    /// from the pinhole G-buffer; layered peels it into K layers, still
    /// through one lens position).
    pub fn samples(&self) -> u32 {
        match self.method {
            Method::Accum(o) => o.samples,
            Method::Pinhole | Method::Fast(_) | Method::Rdb(_) | Method::Layered(_) => 1,
        }
    }

    /// Whether the method's image is one G-buffer through its lens: every
    /// method's but accum's, whose lens positions each take their own.
    pub fn blurs_one_gbuffer(&self) -> bool {
        !matches!(self.method, Method::Accum(_))
    }

    /// Parses a comma-separated list.
    pub fn parse_list(list: &str) -> Result<Vec<BenchMethod>> {
        split_list(list, "--methods")?
            .into_iter()
            .map(BenchMethod::parse)
            .collect()
    }
}

fn split_list<'a>(list: &'a str, flag: &str) -> Result<Vec<&'a str>> {
    let items: Vec<&str> = list.split(',').map(str::trim).collect();
    if items.iter().any(|i| i.is_empty()) {
        return Err(Error::InvalidArgument(format!(
            "{flag}: empty entry in '{list}'"
        )));
    }
    Ok(items)
}

/// A model of the matrix: a bundled cloud, the synthetic cloud, or a PLY, LAS or LAZ
/// file, each with its fixed camera.
#[derive(Debug, Clone, PartialEq)]
pub enum BenchModel {
    /// `data/bunny_colored.ply`, auto-framed from +z (the default camera).
    Bunny,
    /// `data/pcl_table_scene_mug_rgb.ply` from its sensor's viewpoint.
    Mug,
    /// [`synthetic_cloud`] of `--points` points, auto-framed from +z.
    Synthetic,
    /// Any PLY, LAS or LAZ file, auto-framed from +z.
    File(PathBuf),
}

impl BenchModel {
    pub const DEFAULT: &'static str = "bunny,mug,synthetic";

    pub fn parse(name: &str) -> Result<BenchModel> {
        Ok(match name {
            "bunny" => BenchModel::Bunny,
            "mug" => BenchModel::Mug,
            "synthetic" => BenchModel::Synthetic,
            _ if [".ply", ".las", ".laz"]
                .iter()
                .any(|e| name.to_ascii_lowercase().ends_with(e)) =>
            {
                BenchModel::File(name.into())
            }
            _ => {
                return Err(Error::InvalidArgument(format!(
                "--models: unknown model '{name}' (known: bunny, mug, synthetic, or a .ply, .las or .laz file)"
            )))
            }
        })
    }

    pub fn parse_list(list: &str) -> Result<Vec<BenchModel>> {
        split_list(list, "--models")?
            .into_iter()
            .map(BenchModel::parse)
            .collect()
    }

    pub fn name(&self) -> String {
        match self {
            BenchModel::Bunny => "bunny".into(),
            BenchModel::Mug => "mug".into(),
            BenchModel::Synthetic => "synthetic".into(),
            BenchModel::File(p) => p.display().to_string(),
        }
    }

    /// Loads (or generates) the cloud; bundled clouds are looked up in
    /// `data_dir`.
    pub fn load(&self, data_dir: &Path, points: usize) -> Result<PointCloud> {
        match self {
            BenchModel::Bunny => load_ply(&data_dir.join("bunny_colored.ply")),
            BenchModel::Mug => load_ply(&data_dir.join("pcl_table_scene_mug_rgb.ply")),
            BenchModel::Synthetic => Ok(synthetic_cloud(points)),
            BenchModel::File(p) => crate::input::load_cloud(p, None, &mut |_, _| {}),
        }
    }

    /// The model's fixed camera at `width`×`height`: fields not given here
    /// follow DESIGN §2's defaults (auto-framing, focus on the model's
    /// centre, automatic aperture), which depend only on the cloud and the
    /// size.
    pub fn camera(&self, cloud: &PointCloud, width: u32, height: u32) -> Result<Camera> {
        let mut spec = CameraSpec {
            width: Some(width),
            height: Some(height),
            ..CameraSpec::default()
        };
        if *self == BenchModel::Mug {
            // The scan's sensor: at the origin, looking down +z, y down.
            spec.eye = Some([0.0, 0.0, 0.0]);
            spec.target = Some([0.0, 0.0, 1.0]);
            spec.up = Some([0.0, -1.0, 0.0]);
            spec.fovy_deg = Some(27.95);
        }
        let (lo, hi) = cloud.bounds();
        camera::resolve(&spec, lo, hi, &cloud.positions)
    }
}

/// A deterministic synthetic scene of `count` points for scaling tests
/// ([`crate::synth`]): a wavy wall facing +z (70 % of the points) and five
/// spheres in front of it at different depths, colored by a checker of
/// their position, so that a lens blurs something at every depth.
pub fn synthetic_cloud(count: usize) -> PointCloud {
    crate::synth::cloud(count)
}

/// What to measure.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    pub methods: Vec<BenchMethod>,
    pub models: Vec<BenchModel>,
    pub resolutions: Vec<(u32, u32)>,
    /// Size of the synthetic cloud.
    pub points: usize,
    pub runs: u32,
    pub warmup: u32,
    /// K of the K×K SSAA G-buffer, for every method (None: each method's
    /// default on the measured frames' raster, [`Renderer::ssaa`]: accum's
    /// is 1, the others' the raster's).
    pub ssaa: Option<u32>,
    /// The most samples per G-buffer raster pass (None: the device's best).
    pub samples_per_pass: Option<u32>,
    /// How the measured frames' G-buffers are rasterised (the quality
    /// reference always by sprites, the reference path).
    pub raster: Raster,
    /// The shape of the splats (`--splat-shape`), the reference's too.
    pub splat_shape: SplatShape,
    /// How the measured frames' G-buffers weigh the splats within a pixel
    /// (`--coverage`; None: the default, area where it can act).
    pub coverage: Option<Coverage>,
    /// PSNR and SSIM of each cell against accum with 256 samples.
    pub quality: bool,
    /// The `--lod-px` values to measure (an axis of the matrix).
    pub lod_px: Vec<f32>,
    /// Where the bundled clouds are.
    pub data_dir: PathBuf,
}

/// min, median and max of a series, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    pub min: f64,
    pub median: f64,
    pub max: f64,
}

impl Stats {
    /// Of a non-empty series.
    pub fn of(values: &[f64]) -> Stats {
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        };
        Stats {
            min: v[0],
            median,
            max: v[n - 1],
        }
    }

    /// Of `value` over a non-empty series of frames.
    pub fn over(frames: &[FrameTimings], value: impl Fn(&FrameTimings) -> f64) -> Stats {
        Stats::of(&frames.iter().map(value).collect::<Vec<_>>())
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PassStats {
    pub name: String,
    /// Scopes of this name per frame (e.g. 16 rasters at K = 4).
    pub count: u32,
    pub gpu_ms: Stats,
}

/// The CoC range of a cell's camera, pixels.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct CocRange {
    /// Smallest CoC of the points in front of the camera (0 when the focus
    /// plane lies within their depth range).
    pub min: f32,
    /// Largest CoC of the points.
    pub max: f32,
    /// The background's CoC, c(∞) = 2R·f_px/S.
    pub background: f32,
}

impl CocRange {
    pub fn of(camera: &Camera, positions: &[Vec3]) -> CocRange {
        let background = camera.coc_px(f32::INFINITY);
        match depth_range(camera, positions) {
            Some((lo, hi)) => {
                let s = camera.focus_distance;
                let min = if (lo..=hi).contains(&s) {
                    0.0
                } else {
                    camera.coc_px(lo).min(camera.coc_px(hi))
                };
                CocRange {
                    min,
                    max: camera.max_coc_px(lo, hi),
                    background,
                }
            }
            None => CocRange {
                min: 0.0,
                max: 0.0,
                background,
            },
        }
    }
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Quality {
    /// Infinite for identical images, which JSON writes as null.
    #[serde(deserialize_with = "infinite_where_null")]
    pub psnr_db: f64,
    pub ssim: f64,
}

/// A PSNR as JSON holds it: null where it was infinite (serde_json writes
/// a float that is not finite as null).
fn infinite_where_null<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

impl Quality {
    /// `image` against `reference`.
    fn of(reference: &LinearImage, image: &LinearImage) -> Result<Quality> {
        Ok(Quality {
            psnr_db: psnr(reference, image)?,
            ssim: ssim(reference, image)?,
        })
    }
}

/// One (model, resolution, method) cell.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Cell {
    pub model: String,
    pub points: usize,
    pub width: u32,
    pub height: u32,
    pub method: String,
    pub ssaa: u32,
    /// Samples per G-buffer raster pass (1 in reports written before
    /// multisampled passes).
    #[serde(default = "one")]
    pub samples_per_pass: u32,
    /// Lens samples (accum; 1 otherwise).
    pub samples: u32,
    pub camera: CameraSpec,
    pub coc_px: CocRange,
    /// `--lod-px` of the cell (0 in reports written before the splat
    /// hierarchy: every point was drawn).
    #[serde(default)]
    pub lod_px: f32,
    /// The splat hierarchy's work in the cell's first frame (the later
    /// frames reuse its splats: same camera).
    #[serde(default)]
    pub lod: LodReport,
    pub runs: u32,
    pub warmup: u32,
    pub frame_wall_ms: Stats,
    pub gpu_total_ms: Stats,
    /// Each timed frame's host share: its wall less its GPU time (None in
    /// reports written before it).
    #[serde(default)]
    pub host_ms: Option<Stats>,
    /// The part of the host share spent copying the pixels out of the
    /// readback buffer (None in reports written before it).
    #[serde(default)]
    pub readback_ms: Option<Stats>,
    /// The cell's first frame's wall (its first warm-up frame: the cell's
    /// allocations and first use), apart from the steady frames above.
    #[serde(default)]
    pub first_frame_wall_ms: Option<f64>,
    pub passes: Vec<PassStats>,
    pub upload: Upload,
    /// Encoding each timed frame as PNG in memory, after the cell's timed
    /// frames (which run back to back).
    pub png_encode_ms: Stats,
    /// Against accum with 256 samples (`--quality`), else null.
    pub quality: Option<Quality>,
    /// The cell's G-buffer against the G-buffer reference (`--quality`;
    /// [`GBUFFER_REFERENCE_SSAA`]): the pinhole image at the cell's K,
    /// LOD, raster, splat shape and coverage. Null for accum, whose lens
    /// positions each take a G-buffer of their own, and without
    /// `--quality` (and in reports written before it).
    #[serde(default)]
    pub gbuffer_quality: Option<Quality>,
}

/// Everything `bench` measured.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BenchReport {
    pub pointlens_version: String,
    pub device: DeviceReport,
    pub runs: u32,
    pub warmup: u32,
    pub ssaa: u32,
    /// `--raster` of the measured frames ("sprites" or "compute"; absent
    /// from reports before it existed).
    #[serde(default)]
    pub raster: String,
    /// `--splat-shape` ("square" or "disc"; absent from reports before it
    /// existed, which were squares).
    #[serde(default = "square")]
    pub splat_shape: String,
    /// `--coverage` ("area" or "samples"; absent from reports before it
    /// existed, whose G-buffers were their samples' means).
    #[serde(default = "samples")]
    pub coverage: String,
    pub quality_reference: Option<String>,
    /// What the cells' G-buffers are measured against (`--quality`; absent
    /// from reports written before).
    #[serde(default)]
    pub gbuffer_reference: Option<String>,
    /// What a measured frame reads back and encodes: `png`, the device's
    /// sRGB 8-bit pixels encoded as PNG, as `render` writes a PNG (empty
    /// in reports written before: linear pixels read back, encoded on the
    /// host).
    #[serde(default)]
    pub output: String,
    pub cells: Vec<Cell>,
}

/// Progress of a bench: called with (frames done, frames in all, what is
/// rendering now) before each frame.
pub type Progress<'a> = &'a mut dyn FnMut(u64, u64, &str);

/// The number of frames [`run`] renders (for a progress bar).
pub fn frame_count(options: &BenchOptions) -> u64 {
    let per_method = (options.warmup + options.runs) as u64;
    let per_lod = per_method * options.methods.len() as u64;
    // With --quality: accum's reference; and where a method but accum's
    // is measured, the G-buffers' and a pinhole frame of each such cell's.
    let gbuffers = options
        .methods
        .iter()
        .filter(|m| m.blurs_one_gbuffer())
        .count() as u64;
    let per_quality =
        1 + measures_gbuffers(options) as u64 * (1 + gbuffers * options.lod_px.len() as u64);
    let per_resolution =
        per_lod * options.lod_px.len() as u64 + options.quality as u64 * per_quality;
    per_resolution * (options.resolutions.len() * options.models.len()) as u64
}

/// Whether the run measures its cells' G-buffers: with `--quality`, where
/// a method but accum (whose lens positions each take a G-buffer) is in
/// the matrix.
fn measures_gbuffers(options: &BenchOptions) -> bool {
    options.quality && options.methods.iter().any(BenchMethod::blurs_one_gbuffer)
}

/// Runs the matrix on `ctx`.
pub fn run(ctx: &Arc<Context>, options: &BenchOptions, progress: Progress) -> Result<BenchReport> {
    check_matrix(options)?;
    let mut renderer = Renderer::new(ctx)?;
    renderer.set_splat_shape(options.splat_shape)?;
    renderer.set_raster(options.raster);
    renderer.set_coverage(options.coverage);
    // The run's K (the report's): the methods' but accum's, whose default
    // is its own (each cell records its K), and the quality reference's.
    let ssaa = renderer.ssaa(options.ssaa, options.samples_per_pass, &Method::Pinhole)?;
    let total = frame_count(options);
    let mut done = 0u64;
    let mut cells = Vec::new();
    for model in &options.models {
        let cloud = model.load(&options.data_dir, options.points)?;
        let scene = renderer.upload(&cloud, SplatSize::Spacing)?;
        let upload = scene.upload;
        for &(width, height) in &options.resolutions {
            let camera = model.camera(&cloud, width, height)?;
            let coc = CocRange::of(&camera, &cloud.positions);
            let frame = |method: Method, ssaa: u32, lod_px: f32| RenderOptions {
                camera,
                method,
                ssaa,
                samples_per_pass: options.samples_per_pass,
                background: Vec3::ZERO,
                lod: Lod {
                    px: lod_px,
                    blur: None,
                    cull_back_faces: false,
                },
            };
            let what = |method: &str| format!("{} {width}×{height} {method}", model.name());
            let mut step = |label: &str| {
                progress(done, total, &what(label));
                done += 1;
            };
            let (reference, gbuffer_reference) =
                quality_references(&mut renderer, &scene, options, &frame, ssaa, &mut step)?;
            renderer.set_raster(options.raster);
            // The cells whose G-buffers are measured: (index, K, LOD).
            let mut pending = Vec::new();
            for (&lod_px, m) in options
                .lod_px
                .iter()
                .flat_map(|px| options.methods.iter().map(move |m| (px, m)))
            {
                let ssaa = renderer.ssaa(options.ssaa, options.samples_per_pass, &m.method)?;
                let options_m = frame(m.method, ssaa, lod_px);
                let what = |m: &str| match options.lod_px.len() {
                    1 => what(m),
                    _ => what(&format!("{m} lod-px {lod_px}")),
                };
                let mut step = |label: &str| {
                    progress(done, total, &what(label));
                    done += 1;
                };
                let Measured {
                    timings,
                    encode,
                    first_wall_ms,
                    image,
                    samples_per_pass,
                    lod,
                } = measure_cell(&renderer, &scene, &options_m, options, &m.name, &mut step)?;
                let quality = match (&reference, &image) {
                    (Some(reference), Some(image)) => Some(Quality::of(reference, image)?),
                    _ => None,
                };
                if gbuffer_reference.is_some() && m.blurs_one_gbuffer() {
                    pending.push((cells.len(), ssaa, lod_px));
                }
                cells.push(Cell {
                    model: model.name(),
                    points: cloud.len(),
                    width,
                    height,
                    method: m.name.clone(),
                    ssaa,
                    samples_per_pass,
                    samples: m.samples(),
                    camera: camera.to_spec(),
                    coc_px: coc,
                    lod_px,
                    lod,
                    runs: options.runs,
                    warmup: options.warmup,
                    frame_wall_ms: Stats::over(&timings, |t| t.wall_ms),
                    gpu_total_ms: Stats::over(&timings, FrameTimings::gpu_total_ms),
                    host_ms: Some(Stats::over(&timings, |t| {
                        (t.wall_ms - t.gpu_total_ms()).max(0.0)
                    })),
                    readback_ms: Some(Stats::over(&timings, |t| t.readback_ms)),
                    first_frame_wall_ms: Some(first_wall_ms),
                    passes: pass_stats(&timings),
                    upload,
                    png_encode_ms: Stats::of(&encode),
                    quality,
                    gbuffer_quality: None,
                });
            }
            if let Some(reference) = &gbuffer_reference {
                let mut step = |label: &str| {
                    progress(done, total, &what(label));
                    done += 1;
                };
                let (r, f) = (&renderer, &frame);
                measure_gbuffers(r, &scene, reference, f, &mut cells, pending, &mut step)?;
            }
        }
    }
    progress(done, total, "done");
    drop(renderer);
    ctx.check_validation()?;
    Ok(report(ctx, options, ssaa, cells))
}

/// Measures each `pending` cell's G-buffer (index, K, LOD) against
/// `reference`, through `renderer` and `scene`, `frame` making the frames
/// (method, K, LOD): the pinhole frame of its K, LOD and coverage (the
/// method's own keeps its samples where its lens blurs every splat past a
/// few pixels, which this does not). After the timed cells, whose splats
/// they would otherwise replace between them (a `Scene` keeps the last
/// view's alone); `step` before each.
fn measure_gbuffers(
    renderer: &Renderer,
    scene: &Scene,
    reference: &LinearImage,
    frame: &dyn Fn(Method, u32, f32) -> RenderOptions,
    cells: &mut [Cell],
    pending: Vec<(usize, u32, f32)>,
    step: &mut dyn FnMut(&str),
) -> Result<()> {
    for (cell, ssaa, lod_px) in pending {
        let c = &mut cells[cell];
        step(&format!("{} G-buffer", c.method));
        let image = renderer
            .render(scene, &frame(Method::Pinhole, ssaa, lod_px))?
            .image;
        c.gbuffer_quality = Some(Quality::of(reference, &image)?);
    }
    Ok(())
}

/// The references of `--quality` of one model at one resolution, whose
/// frames `frame` makes (method, K, LOD): accum's image with
/// [`REFERENCE_SAMPLES`] lens samples at K = `ssaa`, and where the run
/// measures G-buffers every splat's pinhole image at
/// [`GBUFFER_REFERENCE_SSAA`] by samples; `step` before each. The renderer's
/// raster is the run's after them, and its coverage.
fn quality_references(
    renderer: &mut Renderer,
    scene: &Scene,
    options: &BenchOptions,
    frame: &dyn Fn(Method, u32, f32) -> RenderOptions,
    ssaa: u32,
    step: &mut dyn FnMut(&str),
) -> Result<(Option<LinearImage>, Option<LinearImage>)> {
    let mut frames = None;
    if options.quality {
        step("reference (accum 256)");
        let reference = Method::Accum(AccumOptions {
            samples: REFERENCE_SAMPLES,
        });
        // Every point: what the LOD's cost is measured against, by the
        // samples of each lens position (accum's own).
        renderer.set_raster(Raster::Sprites);
        renderer.set_coverage(None);
        frames = Some(renderer.render(scene, &frame(reference, ssaa, 0.0))?.image);
    }
    let mut gbuffers = None;
    if measures_gbuffers(options) {
        step("G-buffer reference (pinhole, K = 16)");
        // Every splat by its samples, on the run's raster (the sprites
        // round a splat's place and size, the compute raster does not).
        renderer.set_raster(crate::options::frame_raster(
            options.raster,
            options.samples_per_pass,
            None,
        )?);
        renderer.set_coverage(Some(Coverage::Samples));
        let reference = RenderOptions {
            samples_per_pass: None,
            ..frame(Method::Pinhole, GBUFFER_REFERENCE_SSAA, 0.0)
        };
        gbuffers = Some(renderer.render(scene, &reference)?.image);
    }
    renderer.set_raster(options.raster);
    renderer.set_coverage(options.coverage);
    Ok((frames, gbuffers))
}

/// Refuses a matrix that cannot run: no timed run, a `--lod-px` out of
/// range, or an empty axis.
fn check_matrix(options: &BenchOptions) -> Result<()> {
    if options.runs == 0 {
        return Err(Error::InvalidArgument("--runs must be at least 1".into()));
    }
    for &px in &options.lod_px {
        crate::options::check_lod_px(px)?;
    }
    if options.methods.is_empty()
        || options.models.is_empty()
        || options.resolutions.is_empty()
        || options.lod_px.is_empty()
    {
        return Err(Error::InvalidArgument("bench: the matrix is empty".into()));
    }
    let raster = crate::options::frame_raster(options.raster, options.samples_per_pass, None)?;
    for m in &options.methods {
        crate::options::check_coverage_with(
            options.coverage,
            &m.method,
            Some(raster),
            Some(options.splat_shape),
        )?;
    }
    Ok(())
}

/// What one cell's timed frames gave.
struct Measured {
    /// Each timed frame's timings.
    timings: Vec<FrameTimings>,
    /// Each timed frame's PNG encoding, milliseconds.
    encode: Vec<f64>,
    /// The first frame's wall, milliseconds.
    first_wall_ms: f64,
    /// The frame in linear light, rendered once more untimed (`--quality`).
    image: Option<LinearImage>,
    samples_per_pass: u32,
    /// The splat hierarchy's work in the first frame.
    lod: LodReport,
}

/// Renders one cell's frames (`frame` of `scene`): `options.warmup`
/// untimed, then `options.runs` timed, each image then encoded as PNG
/// (timed apart). `step` is called before each frame with what renders:
/// `name`, "(warm-up)" added for the untimed.
fn measure_cell(
    renderer: &Renderer,
    scene: &Scene,
    frame: &RenderOptions,
    options: &BenchOptions,
    name: &str,
    step: &mut dyn FnMut(&str),
) -> Result<Measured> {
    let mut lod = None;
    let mut first_wall_ms = None;
    for _ in 0..options.warmup {
        step(&format!("{name} (warm-up)"));
        let r = renderer.render_srgb8(scene, frame)?;
        first_wall_ms.get_or_insert(r.timings.wall_ms);
        lod.get_or_insert(r.lod);
    }
    let mut timings = Vec::new();
    let mut images = Vec::new();
    let mut samples_per_pass = 1;
    // The timed frames back to back, as a sequence's render thread draws
    // them (its files are encoded on another): an encode between them
    // would let a GPU lower its clocks.
    for _ in 0..options.runs {
        step(name);
        // The frame as `render` writes a PNG: its sRGB 8-bit pixels.
        let r = renderer.render_srgb8(scene, frame)?;
        first_wall_ms.get_or_insert(r.timings.wall_ms);
        lod.get_or_insert(r.lod);
        timings.push(r.timings);
        images.push(r.image);
        samples_per_pass = r.samples_per_pass;
    }
    let mut encode = Vec::new();
    for image in &images {
        let t = Instant::now();
        image.encode_png()?;
        encode.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let image = match options.quality {
        true => Some(renderer.render(scene, frame)?.image),
        false => None,
    };
    Ok(Measured {
        timings,
        encode,
        first_wall_ms: first_wall_ms.expect("runs ≥ 1"),
        image,
        samples_per_pass,
        lod: lod.expect("runs ≥ 1"),
    })
}

/// The report of a run on `ctx` of `options` at K = `ssaa`, of its
/// `cells`.
fn report(ctx: &Context, options: &BenchOptions, ssaa: u32, cells: Vec<Cell>) -> BenchReport {
    BenchReport {
        pointlens_version: env!("CARGO_PKG_VERSION").to_string(),
        device: DeviceReport::of(&ctx.info),
        runs: options.runs,
        warmup: options.warmup,
        ssaa,
        raster: options
            .raster
            .to_possible_value()
            .map(|v| v.get_name().to_string())
            .unwrap_or_default(),
        splat_shape: options
            .splat_shape
            .to_possible_value()
            .map(|v| v.get_name().to_string())
            .unwrap_or_default(),
        coverage: options
            .coverage
            .unwrap_or_default()
            .to_possible_value()
            .map(|v| v.get_name().to_string())
            .unwrap_or_default(),
        quality_reference: options
            .quality
            .then(|| format!("accum with {REFERENCE_SAMPLES} lens samples")),
        gbuffer_reference: measures_gbuffers(options).then(|| gbuffer_reference(ctx, options)),
        output: "png".into(),
        cells,
    }
}

/// What the run's G-buffers are measured against: every splat's pinhole
/// image at [`GBUFFER_REFERENCE_SSAA`] by samples on the run's raster.
fn gbuffer_reference(ctx: &Context, options: &BenchOptions) -> String {
    let k = GBUFFER_REFERENCE_SSAA;
    let raster = crate::options::frame_raster(
        options.raster,
        options.samples_per_pass,
        Some(ctx.info.buffer_int64_atomics),
    );
    let what = match (raster, options.splat_shape) {
        (Ok(Raster::Compute), SplatShape::Square) => format!(
            "the squares' pixel integral: the rotated grid sees their edges in steps of 1/{} of a pixel",
            k * k
        ),
        (Ok(Raster::Compute), SplatShape::Disc) => "the compute raster's discs".into(),
        _ => format!("the sprites' {k} × {k} grid"),
    };
    format!("pinhole image of every splat at K = {k} by samples ({what})")
}

/// Per-pass statistics over the runs, passes in recording order.
fn pass_stats(runs: &[FrameTimings]) -> Vec<PassStats> {
    runs[0]
        .passes
        .iter()
        .map(|p| {
            let values: Vec<f64> = runs
                .iter()
                .map(|r| {
                    r.passes
                        .iter()
                        .find(|q| q.name == p.name)
                        .map_or(0.0, |q| q.gpu_ms)
                })
                .collect();
            PassStats {
                name: p.name.clone(),
                count: p.count,
                gpu_ms: Stats::of(&values),
            }
        })
        .collect()
}

impl BenchReport {
    /// A cell's method as the table and the chart name it: with its K
    /// where that is not the run's (accum's default, without `--ssaa`).
    pub fn label(&self, c: &Cell) -> String {
        match c.ssaa == self.ssaa {
            true => c.method.clone(),
            false => format!("{} (K = {})", c.method, c.ssaa),
        }
    }

    /// The summary table (Markdown): one row per cell.
    pub fn to_markdown(&self) -> String {
        let d = &self.device;
        let mut s = format!(
            "Device: {} ({} {}, Vulkan {}); K = {}{}, {} runs after {} warm-up; milliseconds, median (min–max)\n\n",
            d.name,
            d.driver,
            d.driver_info,
            d.api_version,
            self.ssaa,
            match self.cells.iter().any(|c| c.ssaa != self.ssaa) {
                true => " (a method at its own default K names it)",
                false => "",
            },
            self.runs,
            self.warmup
        );
        let quality = self.quality_reference.is_some();
        let gbuffer = self.gbuffer_reference.is_some();
        if let (Some(frames), Some(gbuffers)) = (&self.quality_reference, &self.gbuffer_reference) {
            s += &format!("PSNR and SSIM against {frames}; each G-buffer's pinhole image against the {gbuffers}\n\n");
        }
        s += "| model | points | resolution | method | lod px | splats | traversal | CoC px (points; background) | frame wall | GPU total | host | first frame | DOF passes | tree build | PNG encode |";
        s += if quality { " PSNR dB | SSIM |" } else { "" };
        s += if gbuffer {
            " G-buffer PSNR dB |\n"
        } else {
            "\n"
        };
        s += "|---|---:|---|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|";
        s += if quality { "---:|---:|" } else { "" };
        s += if gbuffer { "---:|\n" } else { "\n" };
        for c in &self.cells {
            let method = self.label(c);
            let dof: f64 = c
                .passes
                .iter()
                .filter(|p| {
                    !p.name.starts_with("gbuffer")
                        && !["readback", "output"].contains(&p.name.as_str())
                })
                .map(|p| p.gpu_ms.median)
                .sum::<f64>()
                + 0.0; // an empty sum is −0.0
            s += &format!(
                "| {} | {} | {}×{} | {} | {} | {} | {:.1} | {:.1}–{:.1}; {:.1} | {} | {:.1} | {} | {} | {:.1} | {:.1} | {:.1} |",
                c.model,
                c.points,
                c.width,
                c.height,
                method,
                c.lod_px,
                c.lod.splats_emitted,
                c.lod.traversal_ms,
                c.coc_px.min,
                c.coc_px.max,
                c.coc_px.background,
                fmt_stats(&c.frame_wall_ms),
                c.gpu_total_ms.median,
                c.host_ms.map_or("–".into(), |h| format!("{:.1}", h.median)),
                c.first_frame_wall_ms.map_or("–".into(), |f| format!("{f:.1}")),
                dof,
                c.upload.tree_ms,
                c.png_encode_ms.median,
            );
            if let Some(q) = &c.quality {
                s += &format!(" {} | {:.4} |", fmt_db(q.psnr_db), q.ssim);
            } else if quality {
                s += " | |";
            }
            if gbuffer {
                s += &match &c.gbuffer_quality {
                    Some(q) => format!(" {} |", fmt_db(q.psnr_db)),
                    None => " – |".into(),
                };
            }
            s += "\n";
        }
        s
    }

    /// One row per (cell, measure): the frame's wall time, its GPU total,
    /// its host share, every pass, the splat sizes, the upload, the PNG
    /// encoding and the cell's first frame.
    pub fn to_csv(&self) -> String {
        let mut s = String::from(
            "model,points,width,height,method,ssaa,samples,lod_px,splats,coc_min_px,coc_max_px,coc_background_px,measure,count,min_ms,median_ms,max_ms,psnr_db,ssim,gbuffer_psnr_db\n",
        );
        for c in &self.cells {
            let (p, q) = match &c.quality {
                Some(q) => (fmt_db(q.psnr_db), format!("{:.6}", q.ssim)),
                None => (String::new(), String::new()),
            };
            let g = c
                .gbuffer_quality
                .map_or(String::new(), |q| fmt_db(q.psnr_db));
            let mut row = |measure: &str, count: u32, st: Stats| {
                s += &format!(
                    "{},{},{},{},{},{},{},{},{},{:.3},{:.3},{:.3},{},{},{:.4},{:.4},{:.4},{},{},{}\n",
                    csv_field(&c.model),
                    c.points,
                    c.width,
                    c.height,
                    csv_field(&c.method),
                    c.ssaa,
                    c.samples,
                    c.lod_px,
                    c.lod.splats_emitted,
                    c.coc_px.min,
                    c.coc_px.max,
                    c.coc_px.background,
                    csv_field(measure),
                    count,
                    st.min,
                    st.median,
                    st.max,
                    p,
                    q,
                    g
                );
            };
            row("frame_wall", 1, c.frame_wall_ms);
            row("gpu_total", 1, c.gpu_total_ms);
            if let Some(host) = c.host_ms {
                row("host", 1, host);
            }
            for pass in &c.passes {
                row(&format!("pass:{}", pass.name), pass.count, pass.gpu_ms);
            }
            let once = |v: f64| Stats {
                min: v,
                median: v,
                max: v,
            };
            row("splat_sizes", 1, once(c.upload.splat_sizes_ms));
            row("tree_build", 1, once(c.upload.tree_ms));
            row("traversal", 1, once(c.lod.traversal_ms));
            row("upload_gpu", 1, once(c.upload.gpu_ms));
            row("upload_wall", 1, once(c.upload.wall_ms));
            row("png_encode", 1, c.png_encode_ms);
            if let Some(first) = c.first_frame_wall_ms {
                row("first_frame_wall", 1, once(first));
            }
        }
        s
    }
}

fn fmt_stats(s: &Stats) -> String {
    format!("{:.1} ({:.1}–{:.1})", s.median, s.min, s.max)
}

/// PSNR with two decimals ("inf" for identical images, as Rust formats it).
fn fmt_db(db: f64) -> String {
    format!("{db:.2}")
}

/// A CSV field, quoted when it holds a comma, a quote or a line break.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn one() -> u32 {
    1
}

/// The splat shape of reports written before `--splat-shape` existed.
fn square() -> String {
    "square".into()
}

fn samples() -> String {
    "samples".into()
}

/// What `pointlens bench` is asked, before the device's default matrix
/// fills in what is not given (None).
#[derive(Debug, Clone, Default)]
pub struct BenchRequest {
    /// Comma-separated methods (`BenchMethod::parse_list`).
    pub methods: Option<String>,
    /// Comma-separated models (`BenchModel::parse_list`).
    pub models: Option<String>,
    /// One resolution instead of the matrix's.
    pub size: Option<(u32, u32)>,
    /// Points of the synthetic model.
    pub points: usize,
    pub runs: Option<u32>,
    pub warmup: Option<u32>,
    pub ssaa: Option<u32>,
    pub samples_per_pass: Option<u32>,
    pub raster: Option<Raster>,
    pub splat_shape: Option<SplatShape>,
    pub coverage: Option<Coverage>,
    pub quality: bool,
    pub lod_px: Vec<f32>,
    /// The bundled clouds' folder (default: ./data, else the source
    /// tree's).
    pub data_dir: Option<PathBuf>,
}

/// Runs the matrix `request` describes on the device `device`, the
/// device's default matrix where it says nothing (said on stderr unless
/// `quiet`), with a progress bar over the frames.
pub fn measure(
    request: &BenchRequest,
    device: &crate::vk::ContextOptions,
    quiet: bool,
) -> Result<BenchReport> {
    let ctx = Context::new(device)?;
    let default = DefaultMatrix::for_device(ctx.info.device_type);
    let r = request;
    let chosen = r.methods.is_none() && r.models.is_none() && r.size.is_none() && r.runs.is_none();
    if chosen && !quiet {
        eprintln!(
            "bench: no matrix given; for {} ({:?}): {} (choose with --methods, --models, --width/--height, --runs)",
            ctx.info.describe(),
            ctx.info.device_type,
            default.describe()
        );
    }
    let invalid = |msg: String| Err(Error::InvalidArgument(msg));
    let methods = BenchMethod::parse_list(r.methods.as_deref().unwrap_or(default.methods))?;
    let models = BenchModel::parse_list(r.models.as_deref().unwrap_or(default.models))?;
    if r.points == 0 && models.contains(&BenchModel::Synthetic) {
        return invalid("--points must be at least 1 for the synthetic model".into());
    }
    let resolutions = match r.size {
        Some((0, _)) | Some((_, 0)) => {
            return invalid("--width and --height must be at least 1".into())
        }
        Some(size) => vec![size],
        None => default.resolutions.clone(),
    };
    for model in &models {
        if let BenchModel::File(p) = model {
            if !p.is_file() {
                return invalid(format!("--models: {}: no such file", p.display()));
            }
        }
    }
    let data_dir = match &r.data_dir {
        Some(d) => d.clone(),
        None if Path::new("data/bunny_colored.ply").is_file() => PathBuf::from("data"),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("data"),
    };
    let options = BenchOptions {
        methods,
        models,
        resolutions,
        points: r.points,
        runs: r.runs.unwrap_or(default.runs),
        warmup: r.warmup.unwrap_or(default.warmup),
        ssaa: r.ssaa,
        samples_per_pass: r.samples_per_pass,
        raster: r.raster.unwrap_or_default(),
        splat_shape: r.splat_shape.unwrap_or_default(),
        coverage: r.coverage,
        quality: r.quality,
        lod_px: r.lod_px.clone(),
        data_dir,
    };
    let bar = crate::console::progress(
        frame_count(&options),
        "{bar:30} {pos}/{len} frames, {elapsed} {msg}",
        quiet,
    );
    let report = run(&ctx, &options, &mut |done, _, what| {
        bar.set_position(done);
        bar.set_message(what.to_string());
    });
    bar.finish_and_clear();
    report
}

impl BenchReport {
    /// A report written by `bench --json` (on this or another machine).
    pub fn read_json(path: &Path) -> Result<BenchReport> {
        let within =
            |e: String| Error::InvalidArgument(format!("--from-json {}: {e}", path.display()));
        let text = std::fs::read_to_string(path).map_err(|e| within(e.to_string()))?;
        serde_json::from_str(&text).map_err(|e| within(format!("not a bench report: {e}")))
    }
}

/// Where `pointlens bench` writes its report besides the table on stdout.
#[derive(Debug, Clone, Default)]
pub struct BenchOutputs {
    /// Every measurement as JSON (`--json`).
    pub json: Option<PathBuf>,
    /// One row per cell and measure (`--csv`).
    pub csv: Option<PathBuf>,
    /// The median frame times as a bar chart, PNG (`--chart`).
    pub chart: Option<PathBuf>,
}

impl BenchOutputs {
    /// Checks, before anything is measured, that each file can be
    /// written: its folder exists, and the chart is named .png.
    pub fn check(&self) -> Result<()> {
        for (path, flag) in [(&self.json, "--json"), (&self.csv, "--csv")] {
            if let Some(p) = path {
                crate::image_io::check_parent_dir(p, flag)?;
            }
        }
        if let Some(p) = &self.chart {
            crate::image_io::check_parent_dir(p, "--chart")?;
            crate::image_io::check_png_path(p).map_err(|e| e.within("--chart"))?;
        }
        Ok(())
    }

    /// Writes `report` to each file asked for (atomically).
    pub fn write(&self, report: &BenchReport) -> Result<()> {
        if let Some(path) = &self.json {
            let text = serde_json::to_string_pretty(report)
                .map_err(|e| Error::InvalidArgument(format!("--json: {e}")))?;
            crate::image_io::write_text_atomically(path, &text)?;
        }
        if let Some(path) = &self.csv {
            crate::image_io::write_text_atomically(path, &report.to_csv())?;
        }
        if let Some(path) = &self.chart {
            crate::chart::write_chart(report, path)?;
        }
        Ok(())
    }
}
