//! `pointlens`: the command-line front end, a thin layer over the library.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context as _, Result};
use clap::{Args, Parser, Subcommand};
use glam::{DVec3, Vec3};

use indicatif::{ProgressBar, ProgressStyle};
use pointlens::bench::{self, BenchMethod, BenchModel, BenchOptions};
use pointlens::camera::{self, CameraSpec};
use pointlens::chart;
use pointlens::gaussian_render::GaussianRenderer;
use pointlens::image_io::{
    check_output_path, check_parent_dir, check_png_path, read_image, srgb_to_linear, write_image,
    write_text_atomically,
};
use pointlens::input::copc::CopcClouds;
use pointlens::input::load_cloud;
use pointlens::job::{
    self, CopcScenes, JobEvent, JobSpec, Outcome, Passes, Plan, RenderJob, Scenes, Shot, Written,
};
use pointlens::metrics;
use pointlens::options::{
    check_layers, check_lod_blur, check_lod_px, check_rdb_bins, check_samples,
    check_samples_per_pass, check_ssaa, AccumOptions, EdlOptions, FastGather, FastOptions,
    FastWeights, GatherWindow, LayeredOptions, Lod, Method, MethodKind, Raster, RdbAtomics,
    RdbMode, RdbOptions, SplatShape,
};
use pointlens::render::{Renderer, SplatSize};
use pointlens::sequence::{CameraPath, FrameRange, Motion};
use pointlens::vk::{Context, ContextOptions};
use pointlens::PointCloud;

#[derive(Parser)]
#[command(
    name = "pointlens",
    version,
    about = "Offline point-cloud renderer with physically based depth of field (Vulkan)",
    after_help = "Start with: pointlens render data/bunny_colored.ply -o bunny.png \
                  (depth of field by the layered method). \
                  'pointlens render --help' has worked examples.",
    subcommand_required = false,
    arg_required_else_help = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// List the Vulkan devices, numbered (the default one marked), and
    /// exit; pick one with --device N or --device NAME.
    #[arg(long)]
    list_devices: bool,
    /// More messages on stderr: -v what is done, -vv details (RUST_LOG, as
    /// `RUST_LOG=pointlens=debug`, wins over both).
    #[arg(short, long, action = clap::ArgAction::Count, global = true, conflicts_with = "quiet")]
    verbose: u8,
    /// Errors only: no progress bars, no warnings.
    #[arg(short, long, global = true)]
    quiet: bool,
}

/// Worked examples of `render --help`.
const RENDER_EXAMPLES: &str = "\
Examples:
  Depth of field, focused on what pixel 320,240 sees:
    pointlens render data/bunny_colored.ply -o bunny.png --focus-pixel 320,240
  A camera of a real lens (50 mm at f/2 on a 36 mm wide sensor, scene in metres):
    pointlens render scan.ply -o out.png --focal-length-mm 50 --sensor-width-mm 36 \\
        --f-number 2 --units-per-mm 0.001 --eye 0,0,2 --target 0,0,0 --focus-distance 2
  A turntable of 120 frames with a focus pull, as numbered PNGs:
    pointlens render data/bunny_colored.ply -o turn/bunny_%04d.png --frames 120 \\
        --orbit 360 --focus-from 0.15 --focus-to 0.3
  A camera path (JSON keyframes) to EXR with depth and CoC passes:
    pointlens render scan.ply -o shot/f_%04d.exr --path path.json --passes z,coc
  A LiDAR tile, camera in the file's coordinates (UTM metres):
    pointlens render tile.laz -o tile.png --coordinates file \\
        --eye 637000,851000,700 --target 637200,851200,400
  One machine's share of a sequence on a render farm (frames 101-200, resumable):
    pointlens render scene.ply -o shot/f_%04d.png --path path.json \\
        --frame-range 101-200 --skip-existing
See docs/SEQUENCES.md for sequences and render farms.";

#[derive(Subcommand)]
enum Command {
    /// Render a point cloud to a PNG (sRGB, 8-bit) or EXR (linear float)
    /// image, or a sequence of them.
    // Negative numbers are values (`--height -3` is a bad height, not an
    // unknown flag `-3`).
    #[command(after_help = RENDER_EXAMPLES, allow_negative_numbers = true)]
    Render(Box<RenderArgs>),
    /// Compare two images (PNG or EXR) of the same size: PSNR (dB) and max
    /// absolute error over sRGB R, G, B in [0, 1], SSIM on luma.
    Compare {
        a: PathBuf,
        b: PathBuf,
        /// Write the per-pixel difference as a heat map (black: none, white:
        /// the largest difference).
        #[arg(long, value_name = "D.png")]
        diff: Option<PathBuf>,
    },
    /// Time a matrix of methods × models × resolutions (Zhao's Table 1,
    /// extended): per-pass GPU times and frame wall time, min/median/max.
    #[command(allow_negative_numbers = true)]
    Bench(Box<BenchArgs>),
    /// Print point count, bounds and attributes of a point cloud (for LAS
    /// and LAZ also the version, point format, scale, offset, bounds in the
    /// file's coordinates, the re-centring origin and the CRS).
    Info {
        /// PLY, LAS, LAZ or COPC file (read whole).
        input: PathBuf,
        /// Re-centre on X,Y,Z (file coordinates) instead of the default.
        #[arg(long, value_name = "X,Y,Z", value_parser = parse_dvec3, allow_hyphen_values = true)]
        origin: Option<[f64; 3]>,
        #[command(flatten)]
        memory: MemoryArgs,
    },
    /// Write a cloud (PLY, LAS, LAZ or COPC) as a COPC file: an octree of
    /// LAZ chunks that `render` reads node by node.
    Convert {
        input: PathBuf,
        /// Output file, .copc.laz (replaced atomically).
        #[arg(short, long, value_name = "FILE")]
        output: PathBuf,
        #[command(flatten)]
        memory: MemoryArgs,
    },
    /// Write the bench's synthetic scene (a wavy wall and five spheres) as
    /// a binary little-endian PLY, or LAS / LAZ (by the extension),
    /// streamed: any size in bounded memory.
    #[command(allow_negative_numbers = true)]
    Synth {
        /// Number of points.
        #[arg(
            long,
            required_unless_present = "gaussians",
            conflicts_with = "gaussians"
        )]
        points: Option<u64>,
        /// Number of 3D Gaussians instead (SH degree 3, the reference
        /// code's PLY layout; -o must be .ply), centred on the scene's
        /// points: anisotropic, overlapping, semi-transparent.
        #[arg(long)]
        gaussians: Option<u64>,
        /// Output file, .ply, .las or .laz (replaced atomically).
        #[arg(short, long, value_name = "FILE")]
        output: PathBuf,
    },
}

#[derive(Args)]
struct BenchArgs {
    /// One resolution instead of 640×480 and 1920×1080 (needs --height).
    #[arg(long, requires = "height")]
    width: Option<u32>,
    #[arg(long, requires = "width")]
    height: Option<u32>,
    /// Comma-separated methods: pinhole, fast (the two-field gather),
    /// fast-tree or fast-pixels (the paper's rule, after -uniform, -fixed
    /// or both), rdbN, rdbN-pairs, layeredK, accumS (default: by the
    /// device, see below).
    #[arg(long)]
    methods: Option<String>,
    /// Comma-separated models: bunny, mug, synthetic, or PLY, LAS or LAZ
    /// files. Without --methods, --models, --width/--height and --runs the
    /// matrix is the device's default: on a GPU pinhole,fast,rdb5,rdb9,
    /// accum64 × bunny,mug,synthetic × 640x480 and 1920x1080, 5 runs; on a
    /// CPU device (lavapipe) pinhole,fast,rdb9,layered4,accum16 × bunny,mug
    /// × 640x480, 3 runs, about a minute instead of hours. It is printed on stderr.
    #[arg(long)]
    models: Option<String>,
    /// Points of the synthetic model.
    #[arg(long, default_value_t = 1_000_000)]
    points: usize,
    /// Timed runs per cell (default: the device's matrix's).
    #[arg(long)]
    runs: Option<u32>,
    /// Untimed runs before them (default: the device's matrix's).
    #[arg(long)]
    warmup: Option<u32>,
    /// K: the G-buffer takes K×K samples per pixel, 1 to 16 (default: 3 on
    /// the compute raster's rotated grid, 4 on the sprites'; 1 for accum
    /// with at least K² samples, whose lens positions then move the
    /// pixel's sample).
    #[arg(long, value_parser = checked(check_ssaa))]
    ssaa: Option<u32>,
    #[command(flatten)]
    gbuffer: GBufferArgs,
    /// Also PSNR and SSIM of each cell against accum with 256 lens samples
    /// (of every point: `--lod-px 0`).
    #[arg(long)]
    quality: bool,
    /// Comma-separated `--lod-px` values to measure, each a column of the
    /// matrix (0: every point).
    #[arg(long, value_name = "P,P,…", default_value = "1")]
    lod_px: String,
    /// Write every measurement as JSON.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Write every measurement as CSV (one row per cell and measure).
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Draw the median frame times as a bar chart (PNG).
    #[arg(long, value_name = "FILE.png")]
    chart: Option<PathBuf>,
    /// Directory of the bundled clouds (default: ./data, else the source tree's).
    #[arg(long, value_name = "DIR")]
    data: Option<PathBuf>,
    /// Use the Vulkan device numbered N in --list-devices, or the first
    /// whose name or driver contains NAME.
    #[arg(long, value_name = "N|NAME")]
    device: Option<String>,
    /// Enable the validation layer (also POINTLENS_VALIDATION=1).
    #[arg(long)]
    validate: bool,
    /// Measure nothing: read a report written by --json (on this or another
    /// machine) and print its table, CSV and chart.
    #[arg(long, value_name = "FILE", conflicts_with_all = [
        "width", "height", "methods", "models", "points", "runs", "warmup", "samples_per_pass",
        "ssaa", "quality", "data", "device", "validate", "raster", "splat_shape",
    ])]
    from_json: Option<PathBuf>,
}

#[derive(Args)]
struct RenderArgs {
    /// PLY (ASCII or binary), LAS or LAZ (COPC included) file.
    input: PathBuf,
    /// Output image: .png (sRGB 8-bit) or .exr (linear float); for a
    /// sequence with a frame number, `shot_%04d.png`.
    #[arg(short, long)]
    output: PathBuf,
    /// Camera file (JSON, DESIGN §2); the flags below override single fields.
    #[arg(long)]
    camera: Option<PathBuf>,
    #[arg(long)]
    width: Option<u32>,
    #[arg(long)]
    height: Option<u32>,
    /// pinhole | fast | rdb | layered | accum (default layered, with 2
    /// layers: the best image for its cost on the bundled scenes and LiDAR
    /// tile, docs/BENCHMARKS.md).
    #[arg(long, default_value = "layered", value_parser = method_kind)]
    method: MethodKind,
    /// Weights of the paper's rule (--fast-gather tree or pixels): area (by
    /// inverse CoC area) or uniform (the paper's plain mean).
    #[arg(long, value_enum, default_value_t)]
    fast_weights: FastWeights,
    /// Gather window of the paper's rule (--fast-gather tree or pixels):
    /// tiles (bounded by the tiles' CoCs) or fixed (the frame's largest CoC
    /// everywhere; a benchmark baseline).
    #[arg(long, value_enum, default_value_t)]
    fast_window: GatherWindow,
    /// How the fast method gathers: fields (the bounded two-field gather:
    /// 7–12 dB closer to Mitsuba's reference than the paper's rule, its
    /// cost bounded whatever the CoC; docs/BENCHMARKS.md), tree (DESIGN
    /// §4's rule, the paper's, by blocks of a tree, opened only where the
    /// gather's tests differ within a block) or pixels (the same rule pixel
    /// by pixel, the paper's loop).
    #[arg(long, value_enum, default_value_t)]
    fast_gather: FastGather,
    /// Lens bins of the ray distribution buffer per axis: N×N bins, N in 2..=16.
    #[arg(long, default_value_t = pointlens::options::DEFAULT_RDB_BINS, value_parser = checked(check_rdb_bins))]
    rdb_bins: u32,
    /// Which rays a bin receives: centre (the ray through the bin's lens
    /// cell centre) or pairs (the paper's pair-to-bin assignment).
    #[arg(long, value_enum, default_value_t)]
    rdb_mode: RdbMode,
    /// Atomics of the RDB's scatter: 64 (one pass into a buffer never
    /// cleared per frame), 32 (two passes into images cleared per tile) or
    /// auto (64 where the device has 64-bit buffer atomics); the same image.
    #[arg(long, value_enum, default_value_t)]
    rdb_atomics: RdbAtomics,
    /// Memory for the bins of the ray distribution buffer, MiB (default a
    /// quarter of the device-local heap); above it the frame is processed
    /// in tiles, with the same result.
    #[arg(long, value_name = "MB", value_parser = clap::value_parser!(u64).range(1..=1 << 40))]
    rdb_memory_mb: Option<u64>,
    /// Depth-peeled layers of `--method layered` (1-8, default 2; more
    /// only where more surfaces hide one another: docs/BENCHMARKS.md). Not
    /// for 3D Gaussians, whose depth layers follow the circle of confusion.
    #[arg(long, value_parser = checked(check_layers))]
    layers: Option<u32>,
    /// Lens samples of the accumulation reference (--method accum).
    #[arg(long, default_value_t = pointlens::options::DEFAULT_SAMPLES, value_parser = checked(check_samples))]
    samples: u32,
    /// K: the G-buffer takes K×K samples per pixel, 1 to 16 (1 = hard
    /// sprites; default 3 on the compute raster's rotated grid, 4 on the
    /// sprites' K×K grid: docs/BENCHMARKS.md; 1 for accum with at least
    /// K² samples, whose lens positions then move the pixel's sample too).
    /// A scene of 3D Gaussians is
    /// sampled at pixel centres as trained (default 1); K > 1 averages K×K
    /// cell centres.
    #[arg(long, value_parser = checked(check_ssaa))]
    ssaa: Option<u32>,
    #[command(flatten)]
    gbuffer: GBufferArgs,
    /// Vertical field of view, degrees.
    #[arg(long, allow_negative_numbers = true)]
    fovy_deg: Option<f32>,
    /// Lens aperture radius, scene units.
    #[arg(long, conflicts_with = "f_number", allow_negative_numbers = true)]
    aperture_radius: Option<f32>,
    /// f-number N: aperture radius f / 2N (needs --focal-length-mm and
    /// --units-per-mm, or those fields of the camera file).
    #[arg(long, allow_negative_numbers = true)]
    f_number: Option<f32>,
    /// Focal length, mm: with a sensor size gives the field of view, with
    /// --f-number and --units-per-mm the aperture.
    #[arg(long, value_name = "MM", allow_negative_numbers = true)]
    focal_length_mm: Option<f32>,
    /// Sensor height, mm, fitted to the image's height (Blender's vertical
    /// fit): vertical field of view 2·atan(h / 2f).
    #[arg(
        long,
        value_name = "MM",
        conflicts_with = "sensor_width_mm",
        allow_negative_numbers = true
    )]
    sensor_height_mm: Option<f32>,
    /// Sensor width, mm, fitted to the image's width (Blender's horizontal
    /// fit): vertical field of view 2·atan(w·H / (2f·W)).
    #[arg(long, value_name = "MM", allow_negative_numbers = true)]
    sensor_width_mm: Option<f32>,
    /// Scene units per millimetre (0.001 for a scene in metres), to take
    /// the focal length into scene units.
    #[arg(long, value_name = "U", allow_negative_numbers = true)]
    units_per_mm: Option<f32>,
    /// Depth of the plane in focus along the view axis, scene units.
    #[arg(long, allow_negative_numbers = true)]
    focus_distance: Option<f32>,
    /// A sequence of N frames (numbered 1 to N) changed by --orbit,
    /// --focus-from/--focus-to, --aperture-from/--aperture-to.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    frames: Option<u32>,
    /// Turn the eye about the target by DEG over the sequence, around the
    /// up axis: frame i at DEG·(i−1)/N (360 loops without a repeated frame).
    #[arg(
        long,
        value_name = "DEG",
        requires = "frames",
        conflicts_with = "path",
        allow_negative_numbers = true
    )]
    orbit: Option<f64>,
    /// Focus pull: focus distance at frame 1 (linear to --focus-to at frame N).
    #[arg(long, value_name = "S", requires_all = ["frames", "focus_to"],
          conflicts_with_all = ["focus_distance", "focus_pixel", "path"], allow_negative_numbers = true)]
    focus_from: Option<f32>,
    /// Focus distance at frame N.
    #[arg(
        long,
        value_name = "S",
        requires = "focus_from",
        allow_negative_numbers = true
    )]
    focus_to: Option<f32>,
    /// Aperture pull: aperture radius at frame 1 (linear to --aperture-to).
    #[arg(long, value_name = "R", requires_all = ["frames", "aperture_to"],
          conflicts_with_all = ["aperture_radius", "f_number", "path"], allow_negative_numbers = true)]
    aperture_from: Option<f32>,
    /// Aperture radius at frame N.
    #[arg(
        long,
        value_name = "R",
        requires = "aperture_from",
        allow_negative_numbers = true
    )]
    aperture_to: Option<f32>,
    /// Eye-dome lighting: shading from depth alone (as Potree and
    /// CloudCompare), applied before the blur; STRENGTH 1 is Potree's
    /// default, RADIUS_PX the neighbours' distance (default 1.4). Not with
    /// --method accum.
    #[arg(long, value_name = "STRENGTH[,RADIUS_PX]", value_parser = EdlOptions::parse)]
    edl: Option<EdlOptions>,
    /// A COPC file is rendered by node: the most points one frame takes
    /// (the nodes whose spacing is widest on screen first; default
    /// 10,000,000).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    point_budget: Option<u64>,
    #[command(flatten)]
    memory: MemoryArgs,
    /// Render each frame in tiles of at most N×N pixels, each with the
    /// whole frame's guard band (default: the whole frame at once where
    /// its G-buffer fits the device's images, else tiles of 2048).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    tile_px: Option<u32>,
    /// What a point's color shows: rgb (the default where the file has
    /// colors), intensity (LiDAR, grey; the default without colors),
    /// elevation (viridis over the up axis), classification (ASPRS
    /// classes) or return (single, first, intermediate, last).
    #[arg(long, value_enum, value_name = "MODE")]
    color: Option<pointlens::color::ColorMode>,
    /// A camera path: JSON keyframes of camera-file fields with a frame
    /// number each (docs/SEQUENCES.md); renders its first to last frame.
    #[arg(long, value_name = "PATH.json", conflicts_with = "frames")]
    path: Option<PathBuf>,
    /// Render only frames A to B of the sequence (or frame A): any range
    /// gives the same images as the whole run.
    #[arg(long, value_name = "A-B", value_parser = frame_range)]
    frame_range: Option<FrameRange>,
    /// Leave frames whose output file exists (to resume a sequence).
    #[arg(long)]
    skip_existing: bool,
    /// Eye position X,Y,Z (in the coordinates `--coordinates` names).
    #[arg(long, value_parser = parse_dvec3, allow_hyphen_values = true)]
    eye: Option<[f64; 3]>,
    /// Look-at target X,Y,Z.
    #[arg(long, value_parser = parse_dvec3, allow_hyphen_values = true)]
    target: Option<[f64; 3]>,
    /// Which coordinates the camera's eye and target are in (the camera
    /// file's `coordinates`; default recentred): `file`, those of the input
    /// (e.g. a LAS tile's UTM metres), or `recentred`, the file's less the
    /// cloud's origin. `--print-camera` prints in these.
    #[arg(long, value_enum)]
    coordinates: Option<camera::Coordinates>,
    /// Re-centre the cloud on X,Y,Z (file coordinates). Default: LAS/LAZ on
    /// the centre of their bounds, PLY not at all.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_dvec3, allow_hyphen_values = true)]
    origin: Option<[f64; 3]>,
    /// Up vector X,Y,Z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    up: Option<[f32; 3]>,
    /// Every splat a square of side W in scene units, facing the camera.
    #[arg(long, conflicts_with = "splat_px", allow_negative_numbers = true)]
    splat_size: Option<f32>,
    /// Every splat a P×P pixel square.
    #[arg(long, allow_negative_numbers = true)]
    splat_px: Option<f32>,
    /// Background color R,G,B, sRGB values in [0, 1] (default black), or
    /// `transparent`: alpha is the coverage (blurred with the image) and
    /// the color premultiplied by it (EXR), or straight (PNG with alpha).
    #[arg(long, value_name = "R,G,B|transparent", value_parser = parse_background)]
    background: Option<Background>,
    /// Extra EXR channels, comma-separated: `z` (channel Z: eye depth of
    /// the nearest surface, scene units, +inf on background) and `coc`
    /// (channel CoC: its circle of confusion, pixels). docs/SEQUENCES.md.
    #[arg(long, value_name = "z,coc", value_parser = parse_passes)]
    passes: Option<Passes>,
    /// Level of detail: draw a node of the splat hierarchy as one splat
    /// when it projects to at most P pixels (0: every point, no culling;
    /// default 1).
    #[arg(long, value_name = "P", allow_negative_numbers = true,
          value_parser = checked_f32(check_lod_px))]
    lod_px: Option<f32>,
    /// Blur-aware detail: a node may also stop where it projects to at most
    /// F times its circle of confusion (detail finer than the blur).
    #[arg(long, value_name = "F", allow_negative_numbers = true,
          value_parser = checked_f32(check_lod_blur))]
    lod_blur: Option<f32>,
    /// Focus on the nearest surface seen at output pixel X,Y.
    #[arg(long, value_name = "X,Y", value_parser = parse_pixel)]
    focus_pixel: Option<[u32; 2]>,
    /// Print the effective camera as a camera file (JSON) on stdout.
    #[arg(long)]
    print_camera: bool,
    /// Use the Vulkan device numbered N in --list-devices, or the first
    /// whose name or driver contains NAME.
    #[arg(long, value_name = "N|NAME")]
    device: Option<String>,
    /// Enable the Khronos validation layer with synchronization validation
    /// (also POINTLENS_VALIDATION=1); any message fails the command.
    #[arg(long)]
    validate: bool,
    /// Print per-pass GPU times and the frame's wall time.
    #[arg(long)]
    timings: bool,
    /// Write the timings as JSON.
    #[arg(long, value_name = "FILE")]
    timings_json: Option<PathBuf>,
}

/// A clap value parser for a number with the library's range check, so
/// that the flag and the library give the same message.
fn checked(
    check: fn(u32) -> pointlens::Result<u32>,
) -> impl Fn(&str) -> Result<u32, String> + Clone + Send + Sync + 'static {
    move |s| {
        let n = s
            .trim()
            .parse::<u32>()
            .map_err(|_| format!("'{s}' is not a whole number"))?;
        check(n).map_err(|e| e.to_string())
    }
}

/// [`checked`] for a real number.
fn checked_f32(
    check: fn(f32) -> pointlens::Result<f32>,
) -> impl Fn(&str) -> Result<f32, String> + Clone + Send + Sync + 'static {
    move |s| {
        let v = s
            .trim()
            .parse::<f32>()
            .map_err(|_| format!("'{s}' is not a number"))?;
        check(v).map_err(|e| e.to_string())
    }
}

/// `--frame-range`: the library's parser.
fn frame_range(s: &str) -> Result<FrameRange, String> {
    FrameRange::parse(s).map_err(|e| e.to_string())
}

/// `--method`: the library's parser, whose error names the methods.
fn method_kind(s: &str) -> Result<MethodKind, String> {
    MethodKind::parse(s).map_err(|e| e.to_string())
}

/// `--background`.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Background {
    Transparent,
    Srgb([f32; 3]),
}

fn parse_background(s: &str) -> Result<Background, String> {
    if s.trim().eq_ignore_ascii_case("transparent") {
        return Ok(Background::Transparent);
    }
    parse_vec3(s)
        .map(Background::Srgb)
        .map_err(|e| format!("{e} (or 'transparent')"))
}

/// `--passes`: the EXR channels beside R, G, B, A.
fn parse_passes(s: &str) -> Result<Passes, String> {
    let mut passes = Passes::default();
    for name in s.split(',') {
        match name.trim().to_ascii_lowercase().as_str() {
            "z" => passes.z = true,
            "coc" => passes.coc = true,
            other => return Err(format!("unknown pass '{other}' (known: z, coc)")),
        }
    }
    Ok(passes)
}

fn parse_vec3(s: &str) -> Result<[f32; 3], String> {
    parse_triple(s)
}

/// [`parse_vec3`] in double precision (positions in file coordinates).
fn parse_dvec3(s: &str) -> Result<[f64; 3], String> {
    parse_triple(s)
}

/// `X,Y,Z`: three finite numbers, each parsed as `T` itself.
fn parse_triple<T: std::str::FromStr + Copy + Default + Into<f64>>(
    s: &str,
) -> Result<[T; 3], String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(format!("expected X,Y,Z, got '{s}'"));
    }
    let mut v = [T::default(); 3];
    for (slot, p) in v.iter_mut().zip(parts) {
        *slot = p
            .trim()
            .parse::<T>()
            .ok()
            .filter(|x| (*x).into().is_finite())
            .ok_or_else(|| format!("'{p}' is not a finite number in '{s}'"))?;
    }
    Ok(v)
}

fn parse_pixel(s: &str) -> Result<[u32; 2], String> {
    let parts: Vec<&str> = s.split(',').collect();
    match parts[..] {
        [x, y] => match (x.trim().parse(), y.trim().parse()) {
            (Ok(x), Ok(y)) => Ok([x, y]),
            _ => Err(format!("expected pixel X,Y, got '{s}'")),
        },
        _ => Err(format!("expected pixel X,Y, got '{s}'")),
    }
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                let _ = e.print();
                return ExitCode::SUCCESS;
            }
            if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand {
                // `pointlens` alone: the help, and a failure status.
                let _ = e.print();
                return ExitCode::from(2);
            }
            // One line: clap's message up to its usage block, its lines
            // joined (a list of missing arguments follows its first line).
            let text = e.render().to_string();
            let message: Vec<&str> = text
                .lines()
                .map(str::trim)
                .take_while(|l| !l.is_empty() && !l.starts_with("Usage:"))
                .collect();
            let message = match message.join(" ") {
                m if m.is_empty() => "invalid arguments".to_string(),
                m => m,
            };
            eprintln!("{message} (see 'pointlens --help')");
            return ExitCode::from(2);
        }
    };
    init_logging(cli.verbose, cli.quiet);
    let quiet = cli.quiet;
    let result = match cli.command {
        _ if cli.list_devices => list_devices(),
        Some(Command::Render(args)) => render(*args, quiet),
        Some(Command::Compare { a, b, diff }) => compare(&a, &b, diff.as_deref()),
        Some(Command::Info {
            input,
            origin,
            memory,
        }) => info(&input, origin, memory, quiet),
        Some(Command::Bench(args)) => bench(*args, quiet),
        Some(Command::Synth {
            points,
            gaussians,
            output,
        }) => match gaussians {
            Some(n) => synth_gaussians(n, &output, quiet),
            None => synth(points.unwrap_or(0), &output, quiet),
        },
        Some(Command::Convert {
            input,
            output,
            memory,
        }) => convert(&input, &output, memory, quiet),
        None => Err(anyhow::anyhow!("no command given (see 'pointlens --help')")),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the chain joined, innermost cause last, without the
            // causes a message already quotes.
            let mut msg = String::new();
            for cause in e.chain().map(|c| c.to_string()) {
                if !msg.contains(&cause) {
                    if !msg.is_empty() {
                        msg += ": ";
                    }
                    msg += &cause;
                }
            }
            eprintln!("error: {msg}");
            ExitCode::FAILURE
        }
    }
}

/// `print!` that does not panic when stdout is a closed pipe
/// (`pointlens compare a b | head -1`): see [`emit`].
macro_rules! out {
    ($($arg:tt)*) => {
        emit(&format!($($arg)*))
    };
}

/// Writes `text` to stdout. A closed pipe is not a failure: the reader
/// wanted no more, so the text is dropped and the command goes on (a render
/// still writes its image); any other failure is an error.
fn emit(text: &str) -> pointlens::Result<()> {
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        Err(source) => Err(pointlens::Error::System {
            what: "writing to standard output",
            source,
        }),
    }
}

/// Logging through `log` to stderr: warnings by default, -v info, -vv
/// debug, -q errors only; `RUST_LOG` wins when set.
fn init_logging(verbose: u8, quiet: bool) {
    let level = match (quiet, verbose) {
        (true, _) => "error",
        (false, 0) => "warn",
        (false, 1) => "info",
        (false, _) => "debug",
    };
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or(level))
        .format(|buf, record| {
            let level = record.level().as_str().to_ascii_lowercase();
            writeln!(buf, "pointlens: {level}: {}", record.args())
        })
        .init();
}

/// A progress bar on stderr (drawn only when stderr is a terminal), or
/// none with `-q`.
fn progress(len: u64, template: &str, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    ProgressBar::new(len)
        .with_style(ProgressStyle::with_template(template).expect("a valid template"))
}

fn list_devices() -> Result<()> {
    let devices = Context::list_devices()?;
    if devices.is_empty() {
        bail!("the Vulkan loader reports no device");
    }
    for d in devices {
        let mark = if d.default { "*" } else { " " };
        let unusable = d
            .unusable
            .map(|u| format!(", unusable: {u}"))
            .unwrap_or_default();
        out!(
            "{mark} {}: {} [{}, Vulkan {}, {} MiB device-local{unusable}]\n",
            d.index,
            d.description,
            d.kind,
            d.api_version,
            d.heap_bytes >> 20
        )?;
    }
    out!(
        "(* the default; choose another with --device N, its number here, \
         or --device NAME, any part of its name or driver)\n"
    )?;
    Ok(())
}

fn bench(args: BenchArgs, quiet: bool) -> Result<()> {
    for (path, flag) in [(&args.json, "--json"), (&args.csv, "--csv")] {
        if let Some(p) = path {
            check_parent_dir(p, flag)?;
        }
    }
    if let Some(p) = &args.chart {
        check_parent_dir(p, "--chart")?;
        check_png_path(p).context("--chart")?;
    }
    let report = match &args.from_json {
        Some(path) => read_bench_report(path)?,
        None => measure(&args, quiet)?,
    };
    out!("{}", report.to_markdown())?;
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report)?;
        write_text_atomically(path, &text)?;
    }
    if let Some(path) = &args.csv {
        write_text_atomically(path, &report.to_csv())?;
    }
    if let Some(path) = &args.chart {
        chart::write_chart(&report, path)?;
    }
    Ok(())
}

fn read_bench_report(path: &Path) -> Result<bench::BenchReport> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("--from-json {}", path.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("--from-json {}: not a bench report", path.display()))
}

/// Runs the matrix the flags describe.
fn measure(args: &BenchArgs, quiet: bool) -> Result<bench::BenchReport> {
    let ctx = Context::new(&ContextOptions::from_env(
        args.validate,
        args.device.clone(),
    ))?;
    let default = bench::DefaultMatrix::for_device(ctx.info.device_type);
    let chosen = args.methods.is_none()
        && args.models.is_none()
        && args.width.is_none()
        && args.runs.is_none();
    if chosen && !quiet {
        eprintln!(
            "bench: no matrix given; for {} ({:?}): {} (choose with --methods, --models, --width/--height, --runs)",
            ctx.info.describe(),
            ctx.info.device_type,
            default.describe()
        );
    }
    let methods = BenchMethod::parse_list(args.methods.as_deref().unwrap_or(default.methods))?;
    let models = BenchModel::parse_list(args.models.as_deref().unwrap_or(default.models))?;
    if args.points == 0 && models.contains(&BenchModel::Synthetic) {
        bail!("--points must be at least 1 for the synthetic model");
    }
    let resolutions = match (args.width, args.height) {
        (Some(0), _) | (_, Some(0)) => bail!("--width and --height must be at least 1"),
        (Some(w), Some(h)) => vec![(w, h)],
        _ => default.resolutions.clone(),
    };
    for model in &models {
        if let BenchModel::File(p) = model {
            if !p.is_file() {
                bail!("--models: {}: no such file", p.display());
            }
        }
    }
    let data_dir = match &args.data {
        Some(d) => d.clone(),
        None if Path::new("data/bunny_colored.ply").is_file() => PathBuf::from("data"),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("data"),
    };
    let options = BenchOptions {
        methods,
        models,
        resolutions,
        points: args.points,
        runs: args.runs.unwrap_or(default.runs),
        warmup: args.warmup.unwrap_or(default.warmup),
        ssaa: args.ssaa,
        samples_per_pass: args.gbuffer.samples_per_pass,
        raster: args.gbuffer.raster.unwrap_or_default(),
        splat_shape: args.gbuffer.splat_shape.unwrap_or_default(),
        quality: args.quality,
        lod_px: args
            .lod_px
            .split(',')
            .map(|p| {
                let v = p
                    .trim()
                    .parse::<f32>()
                    .map_err(|_| anyhow::anyhow!("--lod-px: '{p}' is not a number"))?;
                Ok(check_lod_px(v)?)
            })
            .collect::<anyhow::Result<Vec<f32>>>()?,
        data_dir,
    };
    let bar = progress(
        bench::frame_count(&options),
        "{bar:30} {pos}/{len} frames, {elapsed} {msg}",
        quiet,
    );
    let report = bench::run(&ctx, &options, &mut |done, _, what| {
        bar.set_position(done);
        bar.set_message(what.to_string());
    });
    bar.finish_and_clear();
    Ok(report?)
}

/// Loads a cloud of any format, with a progress bar on stderr while a
/// LAS/LAZ file streams in (drawn only when stderr is a terminal).
fn load(input: &Path, origin: Option<[f64; 3]>, quiet: bool) -> Result<PointCloud> {
    let bar = progress(0, "loading {bar:30} {pos}/{len} points, {elapsed}", quiet);
    let started = Instant::now();
    let cloud = load_cloud(input, origin.map(DVec3::from_array), &mut |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    });
    bar.finish_and_clear();
    let cloud = cloud?;
    log::info!(
        "{}: {} points loaded in {:.2} s",
        input.display(),
        cloud.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(cloud)
}

fn info(input: &Path, origin: Option<[f64; 3]>, memory: MemoryArgs, quiet: bool) -> Result<()> {
    // `info` reads every point, COPC too.
    let advice = match pointlens::input::copc::is_copc(input) {
        true => |_: &Path| "render reads a COPC file by node, at any size".to_string(),
        false => pointlens::input::convert_advice,
    };
    pointlens::input::check_whole_read_fits(input, memory.memory_mb, false, advice)?;
    if pointlens::input::gaussians::is_gaussian_file(input) {
        let scene = pointlens::input::gaussians::load_gaussians(input)?;
        let (lo, hi) = scene.positions.iter().fold(
            (
                glam::Vec3::splat(f32::INFINITY),
                glam::Vec3::splat(f32::NEG_INFINITY),
            ),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let v = |v: glam::Vec3| format!("{} {} {}", v.x, v.y, v.z);
        out!(
            "file: {}\ngaussians: {}\nsh_degree: {}\nbounds_min: {}\nbounds_max: {}\nextent: {}\n",
            input.display(),
            scene.len(),
            scene.sh_degree,
            v(lo),
            v(hi),
            v(hi - lo)
        )?;
        return Ok(());
    }
    let cloud = load(input, origin, quiet)?;
    let (spacing, limited) =
        pointlens::tree::spacing_summary(&cloud.positions, pointlens::available_threads());
    out!("{}", cloud.info_text(input, spacing))?;
    out!(
        "isolated_points: {limited} (splats limited to {} times their neighbours' median spacing)\n",
        pointlens::tree::ISOLATED_LIMIT
    )?;
    Ok(())
}

fn convert(input: &Path, output: &Path, memory: MemoryArgs, quiet: bool) -> Result<()> {
    let name = output.to_string_lossy().to_lowercase();
    if !name.ends_with(".copc.laz") {
        bail!(
            "{}: convert writes COPC: name the output .copc.laz",
            output.display()
        );
    }
    check_parent_dir(output, "-o")?;
    if input.canonicalize().ok() == output.canonicalize().ok() && output.exists() {
        bail!("{}: the output would replace the input", output.display());
    }
    if pointlens::input::gaussians::is_gaussian_file(input) {
        bail!(
            "{}: it holds 3D Gaussians, which a COPC file of points cannot hold",
            input.display()
        );
    }
    job::watch_signals(false, Arc::new(AtomicBool::new(false)))?;
    let t = Instant::now();
    // Tests make parts small to split a small file into many, and choose
    // the threads (the file is the same on any number).
    let threads = std::env::var("POINTLENS_CONVERT_THREADS")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        .unwrap_or_else(pointlens::available_threads)
        .max(1);
    let part_points = std::env::var("POINTLENS_CONVERT_PART_POINTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(pointlens::convert::PART_POINTS);
    let done = match pointlens::input::is_las(input) {
        true => {
            // Checked as `render` checks it first (one line on a bad file).
            pointlens::input::las::check_las(input)?;
            pointlens::convert::convert_las(input, output, threads, part_points)?
        }
        // A binary PLY file streams; an ASCII one, a pipe, or a file the
        // direct reader declines is read whole.
        false => match pointlens::convert::convert_ply(input, output, threads, part_points)? {
            Some(done) => done,
            None => {
                // Perhaps by the general reader, which names what is wrong
                // with the file.
                pointlens::input::check_whole_read_fits(input, memory.memory_mb, true, |_| {
                    "convert streams only a regular binary PLY file whose vertices are all \
                         well-formed; this one it must read whole"
                        .into()
                })?;
                let cloud = load(input, None, quiet)?;
                let records = pointlens::convert::Records::of_cloud(&cloud, input)?;
                pointlens::convert::write_copc(&records, output, threads)?
            }
        },
    };
    out!(
        "{}: {} points in {} nodes on {} levels, {:.1} MB, {:.2} s\n",
        output.display(),
        done.points,
        done.nodes,
        done.levels,
        done.bytes as f64 / 1e6,
        t.elapsed().as_secs_f64()
    )?;
    Ok(())
}

/// `synth --gaussians N`.
fn synth_gaussians(count: u64, output: &Path, quiet: bool) -> Result<()> {
    if count == 0 {
        bail!("--gaussians must be at least 1");
    }
    if !output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"))
    {
        bail!("{}: Gaussians are written as .ply", output.display());
    }
    check_parent_dir(output, "-o")?;
    job::watch_signals(false, Arc::new(AtomicBool::new(false)))?;
    let bar = progress(count, "{bar:30} {pos}/{len} Gaussians, {elapsed}", quiet);
    let t = Instant::now();
    let written =
        pointlens::synth::write_gaussians(output, count, &mut |done| bar.set_position(done));
    bar.finish_and_clear();
    written?;
    let bytes = std::fs::metadata(output).map_or(0, |m| m.len());
    out!(
        "{}: {count} Gaussians, {:.1} MB, {:.2} s\n",
        output.display(),
        bytes as f64 / 1e6,
        t.elapsed().as_secs_f64()
    )?;
    Ok(())
}

fn synth(points: u64, output: &Path, quiet: bool) -> Result<()> {
    if points == 0 {
        bail!("--points must be at least 1");
    }
    check_parent_dir(output, "-o")?;
    let need = pointlens::synth::least_file_bytes(output, points);
    if let Some(free) = pointlens::synth::free_bytes(output) {
        if need > free {
            bail!(
                "{}: {points} points need at least {:.1} GB, the disk has {:.1} GB free",
                output.display(),
                need as f64 / 1e9,
                free as f64 / 1e9
            );
        }
    }
    // A signal removes the file in writing, as `render`'s do.
    job::watch_signals(false, Arc::new(AtomicBool::new(false)))?;
    let bar = progress(points, "{bar:30} {pos}/{len} points, {elapsed}", quiet);
    let t = Instant::now();
    let written = if pointlens::input::las::has_las_extension(output) {
        pointlens::synth::write_las(output, points, &mut |done| bar.set_position(done))
    } else {
        pointlens::synth::write_ply(output, points, &mut |done| bar.set_position(done))
    };
    bar.finish_and_clear();
    written?;
    let bytes = std::fs::metadata(output).map_or(0, |m| m.len());
    out!(
        "{}: {points} points, {:.1} MB, {:.2} s\n",
        output.display(),
        bytes as f64 / 1e6,
        t.elapsed().as_secs_f64()
    )?;
    Ok(())
}

fn compare(a: &Path, b: &Path, diff: Option<&Path>) -> Result<()> {
    if let Some(d) = diff {
        check_output_path(d)?;
    }
    let (ia, ib) = (read_image(a)?, read_image(b)?);
    let psnr = metrics::psnr(&ia, &ib)?;
    let ssim = metrics::ssim(&ia, &ib)?;
    let max = metrics::max_abs_error(&ia, &ib)?;
    if let Some(d) = diff {
        let heat = metrics::difference_image(&ia, &ib, max.max(1.0 / 255.0))?;
        write_image(&heat, d)?;
    }
    // Identical images: "psnr: inf" (Rust formats infinity so).
    out!("psnr: {psnr:.4}\nssim: {ssim:.6}\nmax_abs_error: {max:.6}\n")?;
    Ok(())
}

/// `pointlens render`: the flags as a [`JobSpec`], then the library's job
/// (`pointlens::job`): checks, signals, the cloud, every frame's camera,
/// the scene, the frames, the timings.
fn render(args: RenderArgs, quiet: bool) -> Result<()> {
    if pointlens::input::gaussians::is_gaussian_file(&args.input) {
        return render_gaussians(args, quiet);
    }
    let shot = shot_of(&args)?;
    let splat = splat_of(&args)?;
    let job = RenderJob::new(job_spec(&args, shot)?)?;

    // SIGINT or SIGTERM ends a sequence after the frame being rendered
    // (its file complete); a second one, or one during a single image,
    // ends the process at once, removing the file being written.
    let stop = Arc::new(AtomicBool::new(false));
    job::watch_signals(job.is_sequence(), stop.clone())?;

    let t_load = Instant::now();
    let (copc, cloud, ranges) = open_input(&args, quiet)?;
    let load_ms = t_load.elapsed().as_secs_f64() * 1e3;
    let plan = job.plan(&cloud)?;
    if !has_frames(&plan) {
        return Ok(());
    }
    let ctx = render_device(&args)?;
    let mut renderer = Renderer::new(&ctx)?;
    renderer.set_raster(args.gbuffer.raster.unwrap_or_default());
    renderer.set_edl(args.edl);
    renderer.set_tile_px(args.tile_px);
    renderer.set_splat_shape(args.gbuffer.splat_shape.unwrap_or_default())?;
    let frames = FramesArgs {
        print_camera: args.print_camera,
        timings: args.timings,
        quiet,
    };
    // The GPU's scenes, dropped before the validation check below.
    let (mut scene, mut by_node) = (None, None);
    let scenes = match copc {
        Some(clouds) => {
            drop(cloud);
            let color = args.color.map(|mode| (mode, ranges));
            Scenes::ByNode(by_node.insert(CopcScenes::new(clouds, splat, color)))
        }
        None => {
            // The hierarchy holds the points from its leaves on.
            let one = scene.insert(renderer.upload_owned(cloud, splat)?);
            Scenes::One(one)
        }
    };
    let outcome = render_frames(&job, &renderer, scenes, &plan, load_ms, &stop, frames)?;
    if args.print_camera && job.is_sequence() {
        out!("{}\n", job::camera_path(&outcome).to_json())?;
    }
    job.write_timings(&outcome.reports)?;
    drop(scene);
    drop(by_node);
    drop(renderer);
    Ok(ctx.check_validation()?)
}

/// Whether `plan` has frames to render; when not (every file exists, with
/// `--skip-existing`), says so.
fn has_frames(plan: &Plan) -> bool {
    if plan.frames.is_empty() {
        log::warn!(
            "nothing to render: the {} frames' files exist",
            plan.skipped
        );
    }
    !plan.frames.is_empty()
}

/// `render`'s device (`--device`, `--validate`), named in the log.
fn render_device(args: &RenderArgs) -> Result<Arc<Context>> {
    let ctx = Context::new(&ContextOptions::from_env(
        args.validate,
        args.device.clone(),
    ))?;
    log::info!("device: {}", ctx.info.describe());
    Ok(ctx)
}

/// `render` of a scene of 3D Gaussians (docs/ARCHITECTURE.md, "3D
/// Gaussian scenes"): the cameras framed on the Gaussians' centres, each
/// frame rendered by [`GaussianRenderer`]; flags about points are refused.
fn render_gaussians(args: RenderArgs, quiet: bool) -> Result<()> {
    let point_flags = [
        ("--splat-size", args.splat_size.is_some()),
        ("--splat-px", args.splat_px.is_some()),
        ("--color", args.color.is_some()),
        ("--edl", args.edl.is_some()),
        ("--lod-blur", args.lod_blur.is_some()),
        ("--tile-px", args.tile_px.is_some()),
        ("--origin", args.origin.is_some()),
        (
            "--samples-per-pass",
            args.gbuffer.samples_per_pass.is_some(),
        ),
        ("--raster", args.gbuffer.raster.is_some()),
        ("--lod-px", args.lod_px.is_some()),
        ("--point-budget", args.point_budget.is_some()),
        ("--splat-shape", args.gbuffer.splat_shape.is_some()),
        ("--layers", args.layers.is_some()),
    ];
    if let Some((flag, _)) = point_flags.iter().find(|(_, given)| *given) {
        bail!(
            "{}: {flag} is about points, and the file holds 3D Gaussians",
            args.input.display()
        );
    }
    let shot = shot_of(&args)?;
    let job = RenderJob::new(job_spec(&args, shot)?)?;
    job.gaussian_lens()?;
    let stop = Arc::new(AtomicBool::new(false));
    job::watch_signals(job.is_sequence(), stop.clone())?;
    pointlens::input::gaussians::check_fits(&args.input, args.memory.memory_mb)?;
    let t_load = Instant::now();
    let scene = pointlens::input::gaussians::load_gaussians(&args.input)?;
    let load_ms = t_load.elapsed().as_secs_f64() * 1e3;
    // The cameras are framed on the centres.
    let centres = PointCloud {
        colors: vec![Vec3::ZERO; scene.positions.len()],
        positions: scene.positions.clone(),
        ..PointCloud::default()
    };
    let plan = job.plan(&centres)?;
    drop(centres);
    if !has_frames(&plan) {
        return Ok(());
    }
    let ctx = render_device(&args)?;
    let renderer = GaussianRenderer::new(&ctx)?;
    let gpu = renderer.upload(&scene)?;
    drop(scene);
    let how = FramesArgs {
        print_camera: args.print_camera,
        timings: args.timings,
        quiet,
    };
    let outcome = show_frames(&job, &plan, how, &mut |events| {
        job.render_gaussians(&renderer, &gpu, &plan, &stop, load_ms, events)
    })?;
    if args.print_camera && job.is_sequence() {
        out!("{}\n", job::camera_path(&outcome).to_json())?;
    }
    job.write_timings(&outcome.reports)?;
    drop(gpu);
    drop(renderer);
    Ok(ctx.check_validation()?)
}

/// `render`'s input: a COPC file opened to be read by node, each frame
/// the nodes it needs (with its root node's points as the cloud the
/// cameras are framed on), or any other file read whole; colored by
/// `--color` over the ranges returned (the whole cloud's, or the COPC root
/// node's, for every frame).
fn open_input(
    args: &RenderArgs,
    quiet: bool,
) -> Result<(
    Option<CopcClouds>,
    PointCloud,
    pointlens::color::ColorRanges,
)> {
    let copc = match pointlens::input::copc::is_copc(&args.input) {
        true => Some(CopcClouds::open(
            &args.input,
            args.origin.map(DVec3::from_array),
            args.point_budget
                .unwrap_or(pointlens::input::copc::DEFAULT_POINT_BUDGET),
            args.memory.memory_mb,
        )?),
        false => None,
    };
    let mut cloud = match &copc {
        Some(copc) => copc.preview()?,
        None => {
            pointlens::input::check_whole_read_fits(
                &args.input,
                args.memory.memory_mb,
                false,
                pointlens::input::convert_advice,
            )?;
            load(&args.input, args.origin, quiet)?
        }
    };
    let ranges = pointlens::color::ColorRanges::of(&cloud);
    if let Some(mode) = args.color {
        pointlens::color::apply_over(&mut cloud, mode, &ranges)
            .map_err(|e| anyhow::anyhow!("{}: {e}", args.input.display()))?;
    }
    Ok((copc, cloud, ranges))
}

/// How the G-buffer is rasterised: flags of `render` and `bench`.
#[derive(clap::Args, Debug, Clone, Copy)]
struct GBufferArgs {
    /// The most samples of a pixel one G-buffer raster pass takes, 1 to 64
    /// (default: all K² in one pass into a target K times larger where the
    /// device holds it, else multisampled passes where its sample counts
    /// tile the K×K grid; 1 = one pass per sample, the reference form).
    #[arg(long, value_name = "S", value_parser = checked(check_samples_per_pass))]
    samples_per_pass: Option<u32>,
    /// How the G-buffer's splats are rasterised: sprites (hardware point
    /// sprites, the reference), compute (compute shaders into a 64-bit
    /// visibility buffer, every sample of a pixel in one pass), or auto
    /// (the default): compute where the device has 64-bit buffer atomics
    /// and no --samples-per-pass is given, else sprites.
    #[arg(long, value_enum)]
    raster: Option<Raster>,
    /// The shape of a splat: square (the default) or disc (the circle of
    /// the same diameter, anti-aliased through the G-buffer's samples
    /// alike).
    #[arg(long, value_enum, value_name = "SHAPE")]
    splat_shape: Option<SplatShape>,
}

/// `--memory-mb`, of `render` and `info`.
#[derive(clap::Args, Debug, Clone, Copy)]
struct MemoryArgs {
    /// Memory for the points, MiB (default: half of what this process may
    /// use): a file read whole (by `render` a PLY/LAS/LAZ, by `info` any,
    /// by `convert` a PLY it cannot stream) that would need more is
    /// refused in one line saying what to do (for `render`, the `pointlens
    /// convert` command that makes it COPC); a COPC file's decompressed
    /// nodes kept across the frames of a sequence stay within it.
    #[arg(long, value_name = "MB", default_value_t = pointlens::input::default_memory_mb(),
          value_parser = clap::value_parser!(u64).range(1..=1 << 30))]
    memory_mb: u64,
}

/// What `render` prints as the frames go.
#[derive(Clone, Copy)]
struct FramesArgs {
    print_camera: bool,
    timings: bool,
    quiet: bool,
}

/// Renders the plan's frames with a progress bar (sequences), the camera
/// (`--print-camera` of one image) and each frame's timings on stderr.
fn render_frames(
    job: &RenderJob,
    renderer: &Renderer,
    scenes: Scenes<'_>,
    plan: &Plan,
    load_ms: f64,
    stop: &AtomicBool,
    how: FramesArgs,
) -> Result<Outcome> {
    show_frames(job, plan, how, &mut |events| {
        job.render(renderer, scenes, plan, stop, load_ms, events)
    })
}

/// Runs `render` (the frames of `plan`) with a progress bar (sequences),
/// the camera (`--print-camera` of one image) and each frame's timings on
/// stderr, as `render` tells its events.
fn show_frames(
    job: &RenderJob,
    plan: &Plan,
    how: FramesArgs,
    render: &mut dyn FnMut(&mut job::Events<'_>) -> pointlens::Result<Outcome>,
) -> Result<Outcome> {
    let sequence = job.is_sequence();
    let bar = match sequence {
        true => progress(
            plan.frames.len() as u64,
            "{bar:30} {pos}/{len} frames, {msg}, {elapsed} elapsed, ETA {eta}",
            how.quiet,
        ),
        false => ProgressBar::hidden(),
    };
    // Frames that drew nothing of the scene: the first is named, the
    // count told at the end.
    let mut empty_frames = 0usize;
    let outcome = render(&mut |event| {
        match event {
            JobEvent::Camera { spec, .. } if how.print_camera && !sequence => {
                emit(&format!("{}\n", spec.to_json()))?;
            }
            JobEvent::Camera { .. } => {}
            JobEvent::Written {
                number,
                seconds,
                report,
                ..
            } => {
                bar.set_message(format!("{seconds:.2} s/frame"));
                bar.inc(1);
                if report.drew_nothing() {
                    empty_frames += 1;
                    let what = match report.gaussians {
                        true => "no Gaussian",
                        false => "no point",
                    };
                    if empty_frames == 1 {
                        bar.suspend(|| {
                            log::warn!(
                                "frame {number}: {what} of the scene is in view, only the \
                                 background: check the camera (a camera file's \"origin\" \
                                 places it in the coordinates of the cloud it was made for)"
                            )
                        });
                    }
                }
                if how.timings {
                    if sequence {
                        eprintln!("frame {number}:");
                    }
                    eprint!("{}", report.text());
                }
            }
        }
        Ok(())
    });
    match &outcome {
        Err(pointlens::Error::Interrupted { .. }) => bar.abandon(),
        _ => bar.finish_and_clear(),
    }
    if empty_frames > 1 {
        log::warn!(
            "{empty_frames} of {} frames showed nothing of the scene",
            plan.frames.len()
        );
    }
    Ok(outcome?)
}

/// The shot the flags ask for: `--path`, `--frames` with its motion, or
/// one image.
fn shot_of(args: &RenderArgs) -> Result<Shot> {
    if let Some(file) = &args.path {
        return Ok(Shot::Path {
            file: file.clone(),
            path: CameraPath::from_json_file(file)?,
        });
    }
    let Some(frames) = args.frames else {
        return Ok(Shot::Single);
    };
    Ok(Shot::Motion(Motion {
        frames,
        orbit_deg: args.orbit,
        focus: args.focus_from.zip(args.focus_to).map(|(a, b)| [a, b]),
        aperture: args
            .aperture_from
            .zip(args.aperture_to)
            .map(|(a, b)| [a, b]),
    }))
}

/// `--splat-size` / `--splat-px` (each a positive number), else sizes from
/// the points' spacing.
fn splat_of(args: &RenderArgs) -> Result<SplatSize> {
    if let Some(w) = args.splat_size.filter(|w| !(w.is_finite() && *w > 0.0)) {
        bail!("--splat-size must be a positive number, not {w}");
    }
    if let Some(p) = args.splat_px.filter(|p| !(p.is_finite() && *p > 0.0)) {
        bail!("--splat-px must be a positive number, not {p}");
    }
    Ok(match (args.splat_size, args.splat_px) {
        (Some(w), _) => SplatSize::World(w),
        (_, Some(p)) => SplatSize::Pixels(p),
        _ => SplatSize::Spacing,
    })
}

/// `--background` in linear light (black when transparent or not given).
fn background_of(args: &RenderArgs) -> Result<Vec3> {
    Ok(match args.background {
        Some(Background::Srgb(c)) if c.iter().any(|v| !(0.0..=1.0).contains(v)) => {
            bail!("--background takes sRGB values in [0, 1], got {c:?}")
        }
        Some(Background::Srgb(c)) => Vec3::from_array(c.map(srgb_to_linear)),
        Some(Background::Transparent) | None => Vec3::ZERO,
    })
}

/// The method and its options from the flags (the fast method's checked
/// here, before the cloud loads, as the frame checks them again).
fn method_of(args: &RenderArgs) -> Result<Method> {
    let fast = FastOptions {
        weights: args.fast_weights,
        window: args.fast_window,
        gather: args.fast_gather,
    };
    if args.method == MethodKind::Fast {
        fast.check()?;
    }
    Ok(args.method.with(
        fast,
        RdbOptions {
            bins: args.rdb_bins,
            mode: args.rdb_mode,
            memory_bytes: args.rdb_memory_mb.map(|mb| mb << 20),
            atomics: args.rdb_atomics,
        },
        AccumOptions {
            samples: args.samples,
        },
        LayeredOptions {
            layers: args.layers.unwrap_or(pointlens::options::DEFAULT_LAYERS),
            ..LayeredOptions::default()
        },
    ))
}

/// The camera flags, which win over the camera file and the path.
fn camera_flags(args: &RenderArgs) -> CameraSpec {
    CameraSpec {
        coordinates: args.coordinates,
        width: args.width,
        height: args.height,
        eye: args.eye,
        target: args.target,
        up: args.up,
        fovy_deg: args.fovy_deg,
        focal_length_mm: args.focal_length_mm,
        sensor_height_mm: args.sensor_height_mm,
        sensor_width_mm: args.sensor_width_mm,
        aperture_radius: args.aperture_radius,
        f_number: args.f_number,
        units_per_mm: args.units_per_mm,
        focus_distance: args.focus_distance,
        ..CameraSpec::default()
    }
}

/// Everything `render` asks of the job.
fn job_spec(args: &RenderArgs, shot: Shot) -> Result<JobSpec> {
    Ok(JobSpec {
        shot,
        output: args.output.clone(),
        frame_range: args.frame_range,
        skip_existing: args.skip_existing,
        camera_file: args.camera.clone(),
        camera_flags: camera_flags(args),
        focus_pixel: args.focus_pixel,
        method: method_of(args)?,
        ssaa: args.ssaa,
        samples_per_pass: args.gbuffer.samples_per_pass,
        background: background_of(args)?,
        lod: Lod {
            px: args.lod_px.unwrap_or(pointlens::options::DEFAULT_LOD_PX),
            blur: args.lod_blur,
        },
        written: Written {
            transparent: args.background == Some(Background::Transparent),
            passes: args.passes.unwrap_or_default(),
        },
        timings_json: args.timings_json.clone(),
    })
}
