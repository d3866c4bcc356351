//! `pointlens`: the command-line front end, a thin layer over the library.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Context as _, Result};
use clap::{Args, Parser, Subcommand};
use glam::{DVec3, Vec3};

use indicatif::{ProgressBar, ProgressStyle};
use pointlens::bench::{self, BenchMethod, BenchModel, BenchOptions};
use pointlens::camera::{self, CameraSpec};
use pointlens::chart;
use pointlens::cloud::load_cloud;
use pointlens::cloud::srgb_to_linear;
use pointlens::image_io::{
    check_output_path, check_png_path, is_png_path, read_image, write_atomically, write_image,
};
use pointlens::metrics;
use pointlens::options::{
    check_layers, check_lod, check_lod_blur, check_lod_px, check_rdb_bins, check_samples,
    check_samples_per_pass, check_ssaa, AccumOptions, FastOptions, FastWeights, GatherWindow,
    LayeredOptions, MethodKind, RdbAtomics, RdbMode, RdbOptions,
};
use pointlens::render::{RenderOptions, Renderer, SplatSize};
use pointlens::report::FrameReport;
use pointlens::tree::Lod;
use pointlens::vk::{Context, ContextOptions};
use pointlens::PointCloud;

#[derive(Parser)]
#[command(
    name = "pointlens",
    version,
    about = "Offline point-cloud renderer with physically based depth of field (Vulkan)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a point cloud to a PNG (sRGB, 8-bit) or EXR (linear float) image.
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
    Bench(Box<BenchArgs>),
    /// Print point count, bounds and attributes of a point cloud (for LAS
    /// and LAZ also the version, point format, scale, offset, bounds in the
    /// file's coordinates, the re-centring origin and the CRS).
    Info {
        /// PLY, LAS or LAZ file.
        input: PathBuf,
        /// Re-centre on X,Y,Z (file coordinates) instead of the default.
        #[arg(long, value_name = "X,Y,Z", value_parser = parse_dvec3, allow_hyphen_values = true)]
        origin: Option<[f64; 3]>,
    },
    /// Write the bench's synthetic scene (a wavy wall and five spheres) as
    /// a binary little-endian PLY, or LAS / LAZ (by the extension),
    /// streamed: any size in bounded memory.
    Synth {
        /// Number of points.
        #[arg(long)]
        points: u64,
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
    /// Comma-separated methods: pinhole, fast, fast-uniform, fast-fixed,
    /// rdbN, rdbN-pairs, layeredK, accumS.
    #[arg(long, default_value = BenchMethod::DEFAULT)]
    methods: String,
    /// Comma-separated models: bunny, mug, synthetic, or PLY, LAS or LAZ files.
    #[arg(long, default_value = BenchModel::DEFAULT)]
    models: String,
    /// Points of the synthetic model.
    #[arg(long, default_value_t = 1_000_000)]
    points: usize,
    /// Timed runs per cell.
    #[arg(long, default_value_t = 5)]
    runs: u32,
    /// Untimed runs before them.
    #[arg(long, default_value_t = 2)]
    warmup: u32,
    /// K: the G-buffer takes K×K samples per pixel, 1 to 16.
    #[arg(long, default_value_t = pointlens::options::DEFAULT_SSAA, value_parser = checked(check_ssaa))]
    ssaa: u32,
    /// The most samples one G-buffer raster pass takes, 1 to 64 (default:
    /// the device's best: multisampled passes where its sample counts tile
    /// the K×K grid; 1 = one pass per sample, the reference form).
    #[arg(long, value_name = "S", value_parser = checked(check_samples_per_pass))]
    samples_per_pass: Option<u32>,
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
    /// Use the Vulkan device whose name or driver contains NAME.
    #[arg(long, value_name = "NAME")]
    device: Option<String>,
    /// Enable the validation layer (also POINTLENS_VALIDATION=1).
    #[arg(long)]
    validate: bool,
    /// Measure nothing: read a report written by --json (on this or another
    /// machine) and print its table, CSV and chart.
    #[arg(long, value_name = "FILE", conflicts_with_all = [
        "width", "height", "methods", "models", "points", "runs", "warmup", "samples_per_pass",
        "ssaa", "quality", "data", "device", "validate",
    ])]
    from_json: Option<PathBuf>,
}

#[derive(Args)]
struct RenderArgs {
    /// PLY (ASCII or binary), LAS or LAZ (COPC included) file.
    input: PathBuf,
    /// Output image: .png (sRGB 8-bit) or .exr (linear float).
    #[arg(short, long)]
    output: PathBuf,
    /// Camera file (JSON, DESIGN §2); the flags below override single fields.
    #[arg(long)]
    camera: Option<PathBuf>,
    #[arg(long)]
    width: Option<u32>,
    #[arg(long)]
    height: Option<u32>,
    /// pinhole | fast | rdb | layered | accum.
    #[arg(long, default_value = "pinhole", value_parser = method_kind)]
    method: MethodKind,
    /// Weights of the fast method: area (by inverse CoC area) or uniform
    /// (the paper's plain mean).
    #[arg(long, value_enum, default_value_t)]
    fast_weights: FastWeights,
    /// Gather window of the fast method: tiles (bounded by the tiles' CoCs)
    /// or fixed (the frame's largest CoC everywhere; a benchmark baseline).
    #[arg(long, value_enum, default_value_t)]
    fast_window: GatherWindow,
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
    /// Depth-peeled layers of `--method layered` (1-8).
    #[arg(long, default_value_t = pointlens::options::DEFAULT_LAYERS, value_parser = checked(check_layers))]
    layers: u32,
    /// Lens samples of the accumulation reference (--method accum).
    #[arg(long, default_value_t = pointlens::options::DEFAULT_SAMPLES, value_parser = checked(check_samples))]
    samples: u32,
    /// K: the G-buffer takes K×K samples per pixel, 1 to 16 (1 = hard sprites).
    #[arg(long, default_value_t = pointlens::options::DEFAULT_SSAA, value_parser = checked(check_ssaa))]
    ssaa: u32,
    /// The most samples one G-buffer raster pass takes, 1 to 64 (default:
    /// the device's best: multisampled passes where its sample counts tile
    /// the K×K grid; 1 = one pass per sample, the reference form).
    #[arg(long, value_name = "S", value_parser = checked(check_samples_per_pass))]
    samples_per_pass: Option<u32>,
    /// Vertical field of view, degrees.
    #[arg(long, allow_negative_numbers = true)]
    fovy_deg: Option<f32>,
    /// Lens aperture radius, scene units.
    #[arg(long, conflicts_with = "f_number", allow_negative_numbers = true)]
    aperture_radius: Option<f32>,
    /// f-number (needs focal_length_mm and units_per_mm from a camera file).
    #[arg(long, allow_negative_numbers = true)]
    f_number: Option<f32>,
    /// Depth of the plane in focus along the view axis, scene units.
    #[arg(long, allow_negative_numbers = true)]
    focus_distance: Option<f32>,
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
    /// Background color R,G,B, sRGB values in [0, 1] (default black).
    #[arg(long, value_parser = parse_vec3)]
    background: Option<[f32; 3]>,
    /// Level of detail: draw a node of the splat hierarchy as one splat
    /// when it projects to at most P pixels (0: every point, no culling).
    #[arg(long, value_name = "P", default_value_t = 1.0, allow_negative_numbers = true,
          value_parser = checked_f32(check_lod_px))]
    lod_px: f32,
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
    /// Use the Vulkan device whose name or driver contains NAME.
    #[arg(long, value_name = "NAME")]
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

/// `--method`: the library's parser, whose error names the methods.
fn method_kind(s: &str) -> Result<MethodKind, String> {
    MethodKind::parse(s).map_err(|e| e.to_string())
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
            // One line: clap's first line, without its usage block.
            let text = e.render().to_string();
            let first = text.lines().next().unwrap_or("invalid arguments");
            eprintln!("{first} (see 'pointlens --help')");
            return ExitCode::from(2);
        }
    };
    let result = match cli.command {
        Command::Render(args) => render(*args),
        Command::Compare { a, b, diff } => compare(&a, &b, diff.as_deref()),
        Command::Info { input, origin } => info(&input, origin),
        Command::Bench(args) => bench(*args),
        Command::Synth { points, output } => synth(points, &output),
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

/// Fails early when `path`'s directory does not exist, so a long run does
/// not end without a place for its result.
fn check_parent_dir(path: &Path, flag: &str) -> Result<()> {
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() && !dir.is_dir() => {
            bail!("{flag} {}: no directory {}", path.display(), dir.display())
        }
        _ => Ok(()),
    }
}

fn bench(args: BenchArgs) -> Result<()> {
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
        None => measure(&args)?,
    };
    print!("{}", report.to_markdown());
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report)?;
        write_text(path, &text)?;
    }
    if let Some(path) = &args.csv {
        write_text(path, &report.to_csv())?;
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
fn measure(args: &BenchArgs) -> Result<bench::BenchReport> {
    let methods = BenchMethod::parse_list(&args.methods)?;
    let models = BenchModel::parse_list(&args.models)?;
    if args.points == 0 && models.contains(&BenchModel::Synthetic) {
        bail!("--points must be at least 1 for the synthetic model");
    }
    let resolutions = match (args.width, args.height) {
        (Some(0), _) | (_, Some(0)) => bail!("--width and --height must be at least 1"),
        (Some(w), Some(h)) => vec![(w, h)],
        _ => vec![(640, 480), (1920, 1080)],
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
        runs: args.runs,
        warmup: args.warmup,
        ssaa: args.ssaa,
        samples_per_pass: args.samples_per_pass,
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
    let ctx = Context::new(&ContextOptions::from_env(
        args.validate,
        args.device.clone(),
    ))?;
    let bar = ProgressBar::new(bench::frame_count(&options)).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} frames, {elapsed} {msg}")
            .expect("a valid template"),
    );
    let report = bench::run(&ctx, &options, &mut |done, _, what| {
        bar.set_position(done);
        bar.set_message(what.to_string());
    });
    bar.finish_and_clear();
    Ok(report?)
}

/// Writes `text` to `path` atomically.
fn write_text(path: &Path, text: &str) -> Result<()> {
    write_atomically(path, |mut file| {
        let io = |source| pointlens::Error::Io {
            path: path.to_path_buf(),
            source,
        };
        file.write_all(text.as_bytes()).map_err(io)?;
        file.sync_all().map_err(io)
    })?;
    Ok(())
}

/// Loads a cloud of any format, with a progress bar on stderr while a
/// LAS/LAZ file streams in (drawn only when stderr is a terminal).
fn load(input: &Path, origin: Option<[f64; 3]>) -> Result<PointCloud> {
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("loading {bar:30} {pos}/{len} points, {elapsed}")
            .expect("a valid template"),
    );
    let cloud = load_cloud(input, origin.map(DVec3::from_array), &mut |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    });
    bar.finish_and_clear();
    Ok(cloud?)
}

fn info(input: &Path, origin: Option<[f64; 3]>) -> Result<()> {
    let cloud = load(input, origin)?;
    print!("{}", cloud.info_text(input));
    Ok(())
}

fn synth(points: u64, output: &Path) -> Result<()> {
    if points == 0 {
        bail!("--points must be at least 1");
    }
    check_parent_dir(output, "-o")?;
    let bar = ProgressBar::new(points).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} points, {elapsed}")
            .expect("a valid template"),
    );
    let t = Instant::now();
    let written = if pointlens::las::has_las_extension(output) {
        pointlens::synth::write_las(output, points, &mut |done| bar.set_position(done))
    } else {
        pointlens::synth::write_ply(output, points, &mut |done| bar.set_position(done))
    };
    bar.finish_and_clear();
    written?;
    let bytes = std::fs::metadata(output).map_or(0, |m| m.len());
    println!(
        "{}: {points} points, {:.1} MB, {:.2} s",
        output.display(),
        bytes as f64 / 1e6,
        t.elapsed().as_secs_f64()
    );
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
    println!("psnr: {psnr:.4}");
    println!("ssim: {ssim:.6}");
    println!("max_abs_error: {max:.6}");
    Ok(())
}

fn render(args: RenderArgs) -> Result<()> {
    let method = args.method.with(
        FastOptions {
            weights: args.fast_weights,
            window: args.fast_window,
        },
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
            layers: args.layers,
            ..LayeredOptions::default()
        },
    );
    check_output_path(&args.output)?;
    if let Some(w) = args.splat_size.filter(|w| !(w.is_finite() && *w > 0.0)) {
        bail!("--splat-size must be a positive number, not {w}");
    }
    if let Some(p) = args.splat_px.filter(|p| !(p.is_finite() && *p > 0.0)) {
        bail!("--splat-px must be a positive number, not {p}");
    }
    let background = match args.background {
        Some(c) if c.iter().any(|v| !(0.0..=1.0).contains(v)) => {
            bail!("--background takes sRGB values in [0, 1], got {c:?}")
        }
        Some(c) => Vec3::from_array(c.map(srgb_to_linear)),
        None => Vec3::ZERO,
    };

    let t_load = Instant::now();
    let cloud = load(&args.input, args.origin)?;
    let load_ms = t_load.elapsed().as_secs_f64() * 1e3;

    let flags = CameraSpec {
        coordinates: args.coordinates,
        width: args.width,
        height: args.height,
        eye: args.eye,
        target: args.target,
        up: args.up,
        fovy_deg: args.fovy_deg,
        aperture_radius: args.aperture_radius,
        f_number: args.f_number,
        focus_distance: args.focus_distance,
        ..CameraSpec::default()
    };
    let spec = match &args.camera {
        Some(path) => {
            let spec = CameraSpec::from_json_file(path)?.overridden_by(&flags);
            spec.require_complete()
                .with_context(|| path.display().to_string())?;
            spec
        }
        None => flags,
    };
    let coordinates = spec.coordinates.unwrap_or_default();
    let origin = cloud.origin;
    let spec = spec.in_scene(origin)?;
    let (lo, hi) = cloud.bounds();
    let mut cam = camera::resolve(&spec, lo, hi, &cloud.positions)?;

    let splat = match (args.splat_size, args.splat_px) {
        (Some(w), _) => SplatSize::World(w),
        (_, Some(p)) => SplatSize::Pixels(p),
        _ => SplatSize::Spacing,
    };
    let ctx = Context::new(&ContextOptions::from_env(
        args.validate,
        args.device.clone(),
    ))?;
    let renderer = Renderer::new(&ctx)?;
    let scene = renderer.upload(&cloud, splat)?;
    let points = cloud.len();
    drop(cloud); // The hierarchy holds the points from here on.
    let lod = Lod {
        px: args.lod_px,
        blur: args.lod_blur,
    };
    check_lod(&lod)?;
    if let Some([x, y]) = args.focus_pixel {
        cam.focus_distance = renderer.depth_at_pixel(&scene, &cam, args.ssaa, lod, x, y)?;
    }
    if args.print_camera {
        println!("{}", cam.to_spec_in(coordinates, origin).to_json());
    }
    let options = RenderOptions {
        camera: cam,
        method,
        ssaa: args.ssaa,
        samples_per_pass: args.samples_per_pass,
        background,
        lod,
    };
    // PNG pixels are encoded on the device; EXR gets the linear floats.
    let (rendered, encode_ms) = if is_png_path(&args.output)? {
        let rendered = renderer.render_srgb8(&scene, &options)?;
        let t_encode = Instant::now();
        rendered.image.write_png(&args.output)?;
        (rendered.map(|_| ()), t_encode.elapsed().as_secs_f64() * 1e3)
    } else {
        let rendered = renderer.render(&scene, &options)?;
        let t_encode = Instant::now();
        write_image(&rendered.image, &args.output)?;
        (rendered.map(|_| ()), t_encode.elapsed().as_secs_f64() * 1e3)
    };

    let report = FrameReport {
        samples_per_pass: rendered.samples_per_pass,
        counts: rendered.counts.clone(),
        lod: rendered.lod,
        load_ms,
        encode_ms,
        ..FrameReport::new(
            &ctx.info,
            method.short_name(),
            (cam.width, cam.height),
            args.ssaa,
            points,
            rendered.guard,
            &rendered.timings,
            scene.upload,
        )
    };
    if args.timings {
        eprint!("{}", report.text());
    }
    if let Some(path) = &args.timings_json {
        write_text(path, &report.to_json())?;
    }
    drop(scene);
    drop(renderer);
    Ok(ctx.check_validation()?)
}
