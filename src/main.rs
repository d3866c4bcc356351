//! `pointlens`: the command-line front end. It only parses: each command's
//! flags become the library's options (`JobSpec` and `SceneSpec`,
//! `BenchRequest`, `ConvertOptions`), and one call of the library does the
//! work (docs/ARCHITECTURE.md, "The command line").

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Result;
use clap::{Args, Parser, Subcommand};

use pointlens::bench::{self, BenchOutputs, BenchRequest};
use pointlens::camera::{self, CameraSpec};
use pointlens::console::{self, emit, progress, RenderConsole};
use pointlens::convert::{convert_file, ConvertOptions};
use pointlens::flags::{
    checked, checked_f32, frame_range, method_kind, parse_background, parse_dvec3, parse_passes,
    parse_pixel, parse_vec3, Background,
};
use pointlens::job::{JobSpec, Passes, RenderJob, Shot, Written};
use pointlens::options::{
    check_layers, check_lod_blur, check_lod_px, check_rdb_bins, check_samples,
    check_samples_per_pass, check_ssaa, Coverage, EdlOptions, FastGather, FastWeights,
    GatherWindow, Lod, Method, MethodFlags, MethodKind, Raster, RdbAtomics, RdbMode, SplatShape,
};
use pointlens::scene::SceneSpec;
use pointlens::sequence::{FrameRange, Motion};
use pointlens::synth::SynthKind;
use pointlens::vk::ContextOptions;

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

#[derive(Subcommand)]
enum Command {
    /// Render a point cloud to a PNG (sRGB, 8-bit) or EXR (linear float)
    /// image, or a sequence of them.
    // Negative numbers are values (`--height -3` is a bad height, not an
    // unknown flag `-3`).
    #[command(after_help = console::RENDER_EXAMPLES, allow_negative_numbers = true)]
    Render(Box<RenderArgs>),
    /// Compare two images (PNG or EXR; colour premultiplied) of the same size:
    /// PSNR (dB) and max absolute error over sRGB R, G, B in [0, 1], SSIM on luma.
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
        #[arg(long, required_unless_present_any = ["gaussians", "lights"])]
        points: Option<u64>,
        /// Number of 3D Gaussians instead (SH degree 3, the reference
        /// code's PLY layout; -o must be .ply), centred on the scene's
        /// points: anisotropic, overlapping, semi-transparent.
        #[arg(long, conflicts_with_all = ["points", "lights"])]
        gaussians: Option<u64>,
        /// Number of points of the bokeh scene instead (-o must be .ply): a
        /// card in focus among 48 lights brighter than white (float colours).
        #[arg(long, conflicts_with = "points")]
        lights: Option<u64>,
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
    /// Also PSNR and SSIM of each cell against accum with 256 lens samples (every point), and
    /// the PSNR of its G-buffer's pinhole image against every splat's at K = 16 by samples.
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
        "ssaa", "quality", "data", "device", "validate", "raster", "splat_shape", "coverage",
    ])]
    from_json: Option<PathBuf>,
}

#[derive(Args)]
struct RenderArgs {
    /// PLY (ASCII or binary), LAS or LAZ (COPC included) file.
    input: PathBuf,
    /// Output image: .png (sRGB 8-bit) or .exr (linear float); for a
    /// sequence with a frame number, `shot_%04d.png`, or one video,
    /// `film.mp4` (H.264) or `film.webm` (VP9), written through ffmpeg.
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
    /// inverse CoC area, the default) or uniform (the paper's plain mean).
    #[arg(long, value_enum)]
    fast_weights: Option<FastWeights>,
    /// Gather window of the paper's rule (--fast-gather tree or pixels):
    /// tiles (bounded by the tiles' CoCs, the default) or fixed (the
    /// frame's largest CoC everywhere; a benchmark baseline).
    #[arg(long, value_enum)]
    fast_window: Option<GatherWindow>,
    /// How the fast method gathers: fields (the default, the bounded two-field gather:
    /// 7–12 dB closer to Mitsuba's reference than the paper's rule, its
    /// cost bounded whatever the CoC; docs/BENCHMARKS.md), tree (DESIGN
    /// §4's rule, the paper's, by blocks of a tree, opened only where the
    /// gather's tests differ within a block) or pixels (the same rule pixel
    /// by pixel, the paper's loop).
    #[arg(long, value_enum)]
    fast_gather: Option<FastGather>,
    /// Lens bins of the ray distribution buffer per axis: N×N bins, N in
    /// 2..=16 (default 9).
    #[arg(long, value_parser = checked(check_rdb_bins))]
    rdb_bins: Option<u32>,
    /// Which rays a bin receives: centre (the default: the ray through the
    /// bin's lens cell centre) or pairs (the paper's pair-to-bin assignment).
    #[arg(long, value_enum)]
    rdb_mode: Option<RdbMode>,
    /// Atomics of the RDB's scatter: 64 (one pass into a buffer never
    /// cleared per frame), 32 (two passes into images cleared per tile) or
    /// auto (the default: 64 where the device has 64-bit buffer atomics);
    /// the same image.
    #[arg(long, value_enum)]
    rdb_atomics: Option<RdbAtomics>,
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
    /// Lens samples of the accumulation reference (--method accum; default
    /// 256).
    #[arg(long, value_parser = checked(check_samples))]
    samples: Option<u32>,
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
    aperture: camera::ApertureSpec,
    #[command(flatten)]
    gbuffer: GBufferArgs,
    /// Vertical field of view, degrees.
    #[arg(long)]
    fovy_deg: Option<f32>,
    /// Lens aperture radius, scene units.
    #[arg(long, conflicts_with = "f_number")]
    aperture_radius: Option<f32>,
    /// f-number N: aperture radius f / 2N (needs --focal-length-mm and
    /// --units-per-mm, or those fields of the camera file).
    #[arg(long)]
    f_number: Option<f32>,
    /// Focal length, mm: with a sensor size gives the field of view, with
    /// --f-number and --units-per-mm the aperture.
    #[arg(long, value_name = "MM")]
    focal_length_mm: Option<f32>,
    /// Sensor height, mm, fitted to the image's height (Blender's vertical
    /// fit): vertical field of view 2·atan(h / 2f).
    #[arg(long, value_name = "MM", conflicts_with = "sensor_width_mm")]
    sensor_height_mm: Option<f32>,
    /// Sensor width, mm, fitted to the image's width (Blender's horizontal
    /// fit): vertical field of view 2·atan(w·H / (2f·W)).
    #[arg(long, value_name = "MM")]
    sensor_width_mm: Option<f32>,
    /// Scene units per millimetre (0.001 for a scene in metres), to take
    /// the focal length into scene units.
    #[arg(long, value_name = "U")]
    units_per_mm: Option<f32>,
    /// Depth of the plane in focus along the view axis, scene units.
    #[arg(long)]
    focus_distance: Option<f32>,
    /// A sequence of N frames (numbered 1 to N) changed by --orbit,
    /// --focus-from/--focus-to, --aperture-from/--aperture-to.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    frames: Option<u32>,
    /// Turn the eye about the target by DEG over the sequence, around the
    /// up axis: frame i at DEG·(i−1)/N (360 loops without a repeated frame).
    #[arg(long, value_name = "DEG", requires = "frames", conflicts_with = "path")]
    orbit: Option<f64>,
    /// Focus pull: focus distance at frame 1 (linear to --focus-to at frame N).
    #[arg(long, value_name = "S", requires_all = ["frames", "focus_to"],
          conflicts_with_all = ["focus_distance", "focus_pixel", "path"])]
    focus_from: Option<f32>,
    /// Focus distance at frame N.
    #[arg(long, value_name = "S", requires = "focus_from")]
    focus_to: Option<f32>,
    /// Aperture pull: aperture radius at frame 1 (linear to --aperture-to).
    #[arg(long, value_name = "R", requires_all = ["frames", "aperture_to"],
          conflicts_with_all = ["aperture_radius", "f_number", "path"])]
    aperture_from: Option<f32>,
    /// Aperture radius at frame N.
    #[arg(long, value_name = "R", requires = "aperture_from")]
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
    #[arg(long, conflicts_with = "splat_px")]
    splat_size: Option<f32>,
    /// Every splat a P×P pixel square.
    #[arg(long)]
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
    /// Level of detail: draw a node of the splat hierarchy as one splat where
    /// it projects to at most P pixels (0: every point, no traversal; default 1).
    #[arg(long, value_name = "P", value_parser = checked_f32(check_lod_px))]
    lod_px: Option<f32>,
    /// Blur-aware detail: a node may also stop where it projects to at most
    /// F times its circle of confusion (detail finer than the blur).
    #[arg(long, value_name = "F", value_parser = checked_f32(check_lod_blur))]
    lod_blur: Option<f32>,
    /// Skip points whose normals face away from the whole lens: fewer splats
    /// on closed scans, but they show at silhouettes and through holes.
    #[arg(long)]
    cull_back_faces: bool,
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
    /// Frames a second of a video output (-o film.mp4 or film.webm;
    /// default 24).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=240))]
    fps: Option<u32>,
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
    /// How the G-buffer's splats are rasterised: sprites (hardware point sprites,
    /// the reference), compute (compute shaders into a 64-bit visibility buffer,
    /// every sample of a pixel in one pass), or auto (the default): compute where
    /// the device has 64-bit buffer atomics and no --samples-per-pass, else sprites.
    #[arg(long, value_enum)]
    raster: Option<Raster>,
    /// The shape of a splat: square (the default) or disc (the circle of the
    /// same diameter, anti-aliased through the G-buffer's samples alike).
    #[arg(long, value_enum, value_name = "SHAPE")]
    splat_shape: Option<SplatShape>,
    /// How the G-buffer weighs a pixel's splats (default: area).
    #[arg(long, value_enum, value_name = "HOW")]
    coverage: Option<Coverage>,
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

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        // Help and version on stdout; a mistake in one line on stderr.
        Err(e) => return ExitCode::from(console::show_parse_error(&e)),
    };
    console::init_logging(cli.verbose, cli.quiet);
    let result = match cli.command {
        _ if cli.list_devices => console::devices_text()
            .and_then(|text| emit(&text))
            .map_err(anyhow::Error::from),
        Some(command) => run(command, cli.quiet),
        None => Err(anyhow::anyhow!("no command given (see 'pointlens --help')")),
    };
    if let Err(e) = result {
        let chain: Vec<String> = e.chain().map(|c| c.to_string()).collect();
        eprintln!("error: {}", console::error_line(&chain));
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}

/// Runs the command the flags name.
fn run(command: Command, quiet: bool) -> Result<()> {
    match command {
        Command::Render(args) => render(*args, quiet),
        Command::Compare { a, b, diff } => Ok(emit(&pointlens::metrics::compare_files(
            &a,
            &b,
            diff.as_deref(),
        )?)?),
        Command::Info {
            input,
            origin,
            memory,
        } => {
            let origin = origin.map(glam::DVec3::from_array);
            let text = console::loading(quiet, |progress| {
                pointlens::scene::info_text(&input, origin, memory.memory_mb, progress)
            })?;
            Ok(emit(&text)?)
        }
        Command::Bench(args) => bench(*args, quiet),
        Command::Synth {
            points,
            gaussians,
            lights,
            output,
        } => synth(SynthKind::of(points, gaussians, lights), &output, quiet),
        Command::Convert {
            input,
            output,
            memory,
        } => convert(
            ConvertOptions::new(&input, &output, memory.memory_mb),
            quiet,
        ),
    }
}

/// `pointlens render`: the flags as a job and a scene, then the library's
/// job (`RenderJob::run`), its events shown by [`RenderConsole`].
fn render(args: RenderArgs, quiet: bool) -> Result<()> {
    let scene = scene_spec(&args)?;
    let job = RenderJob::new(job_spec(&args)?)?;
    let mut console = RenderConsole::new(args.print_camera, args.timings, job.is_sequence(), quiet);
    let device = ContextOptions::from_env(args.validate, args.device.clone());
    let outcome = job.run(&scene, &device, &mut |event| console.on(event));
    console.finish(&outcome)?;
    Ok(outcome.map(drop)?)
}

/// `pointlens bench`: a report measured (or read with --from-json),
/// printed as a table and written as JSON, CSV and a chart where asked.
fn bench(args: BenchArgs, quiet: bool) -> Result<()> {
    let outputs = BenchOutputs {
        json: args.json.clone(),
        csv: args.csv.clone(),
        chart: args.chart.clone(),
    };
    outputs.check()?;
    let report = match &args.from_json {
        Some(path) => bench::BenchReport::read_json(path)?,
        None => {
            let device = ContextOptions::from_env(args.validate, args.device.clone());
            bench::measure(&bench_request(&args)?, &device, quiet)?
        }
    };
    emit(&report.to_markdown())?;
    Ok(outputs.write(&report)?)
}

/// `pointlens convert`, with a progress bar while a PLY file is read
/// whole.
fn convert(options: ConvertOptions, quiet: bool) -> Result<()> {
    let t = std::time::Instant::now();
    let done = console::loading(quiet, |progress| convert_file(&options, progress))?;
    Ok(emit(&format!(
        "{}\n",
        done.summary(&options.output, t.elapsed())
    ))?)
}

/// `pointlens synth --points N`, `--gaussians N` or `--lights N`.
fn synth((kind, count): (SynthKind, u64), output: &Path, quiet: bool) -> Result<()> {
    let t = std::time::Instant::now();
    let template = format!("{{bar:30}} {{pos}}/{{len}} {kind}, {{elapsed}}");
    let bar = progress(count, &template, quiet);
    let bytes = pointlens::synth::write_file(kind, count, output, &mut |d| bar.set_position(d));
    bar.finish_and_clear();
    let (out, mb, s) = (
        output.display(),
        bytes? as f64 / 1e6,
        t.elapsed().as_secs_f64(),
    );
    Ok(emit(&format!(
        "{out}: {count} {kind}, {mb:.1} MB, {s:.2} s\n"
    ))?)
}

/// The bench's flags as a request (the device fills in the rest).
fn bench_request(args: &BenchArgs) -> Result<BenchRequest> {
    Ok(BenchRequest {
        methods: args.methods.clone(),
        models: args.models.clone(),
        size: args.width.zip(args.height),
        points: args.points,
        runs: args.runs,
        warmup: args.warmup,
        ssaa: args.ssaa,
        samples_per_pass: args.gbuffer.samples_per_pass,
        raster: args.gbuffer.raster,
        splat_shape: args.gbuffer.splat_shape,
        coverage: args.gbuffer.coverage,
        quality: args.quality,
        lod_px: pointlens::flags::lod_px_list(&args.lod_px).map_err(anyhow::Error::msg)?,
        data_dir: args.data.clone(),
    })
}

/// How `render` reads and draws its input.
fn scene_spec(args: &RenderArgs) -> Result<SceneSpec> {
    Ok(SceneSpec {
        input: args.input.clone(),
        origin: args.origin.map(glam::DVec3::from_array),
        memory_mb: args.memory.memory_mb,
        point_budget: args.point_budget,
        splat: pointlens::flags::splat_size(args.splat_size, args.splat_px)?,
        color: args.color,
        edl: args.edl,
        tile_px: args.tile_px,
        raster: args.gbuffer.raster,
        splat_shape: args.gbuffer.splat_shape,
        coverage: args.gbuffer.coverage,
    })
}

/// The method and its options from the flags (one given that the method
/// does not read is refused).
fn method_of(args: &RenderArgs) -> Result<Method> {
    Ok(args.method.with_flags(&MethodFlags {
        fast_weights: args.fast_weights,
        fast_window: args.fast_window,
        fast_gather: args.fast_gather,
        rdb_bins: args.rdb_bins,
        rdb_mode: args.rdb_mode,
        rdb_memory_mb: args.rdb_memory_mb,
        rdb_atomics: args.rdb_atomics,
        layers: args.layers,
        samples: args.samples,
    })?)
}

/// Everything `render` asks of the job.
fn job_spec(args: &RenderArgs) -> Result<JobSpec> {
    let pair = |a: Option<f32>, b: Option<f32>| a.zip(b).map(|(a, b)| [a, b]);
    Ok(JobSpec {
        shot: Shot::of(
            args.path.as_deref(),
            args.frames.map(|frames| Motion {
                frames,
                orbit_deg: args.orbit,
                focus: pair(args.focus_from, args.focus_to),
                aperture: pair(args.aperture_from, args.aperture_to),
            }),
        )?,
        output: args.output.clone(),
        frame_range: args.frame_range,
        skip_existing: args.skip_existing,
        camera_file: args.camera.clone(),
        // The camera flags win over the camera file and the path.
        camera_flags: CameraSpec {
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
            aperture: args.aperture.clone(),
            ..CameraSpec::default()
        },
        focus_pixel: args.focus_pixel,
        method: method_of(args)?,
        ssaa: args.ssaa,
        samples_per_pass: args.gbuffer.samples_per_pass,
        background: Background::linear_of(args.background)?,
        lod: Lod {
            px: args.lod_px.unwrap_or(pointlens::options::DEFAULT_LOD_PX),
            blur: args.lod_blur,
            cull_back_faces: args.cull_back_faces,
        },
        written: Written {
            transparent: args.background == Some(Background::Transparent),
            passes: args.passes.unwrap_or_default(),
        },
        timings_json: args.timings_json.clone(),
        fps: args.fps,
    })
}
