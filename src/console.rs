//! What the command line shows as a command works: stdout that tolerates
//! a closed pipe, progress bars on stderr, and a render job's events
//! (the camera, each frame's timings, warnings) as `pointlens render`
//! prints them. The binary owns no display code of its own.

use std::io::Write as _;

use indicatif::{ProgressBar, ProgressStyle};

use crate::error::{Error, Result};
use crate::job::{camera_path, JobEvent, Outcome};

/// Worked examples of `render --help`.
pub const RENDER_EXAMPLES: &str = "\
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

/// Writes `text` to stdout. A closed pipe is not a failure: the reader
/// wanted no more (`pointlens compare a b | head -1`), so the text is
/// dropped and the command goes on (a render still writes its image); any
/// other failure is an error.
pub fn emit(text: &str) -> Result<()> {
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        Err(source) => Err(Error::System {
            what: "writing to standard output",
            source,
        }),
    }
}

/// The bar of points read while a file is read whole.
const LOADING: &str = "loading {bar:30} {pos}/{len} points, {elapsed}";

/// A progress bar on stderr (drawn only when stderr is a terminal), or
/// none when `quiet`.
pub fn progress(len: u64, template: &str, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    ProgressBar::new(len)
        .with_style(ProgressStyle::with_template(template).expect("a valid template"))
}

/// What `pointlens render` prints of a job's events: a bar while a file
/// is read whole, a bar over a sequence's frames, the camera of one image
/// (`--print-camera`), each frame's timings (`--timings`) and the job's
/// warnings, all on stderr but the camera.
pub struct RenderConsole {
    print_camera: bool,
    timings: bool,
    sequence: bool,
    quiet: bool,
    loading: ProgressBar,
    frames: ProgressBar,
}

impl RenderConsole {
    pub fn new(print_camera: bool, timings: bool, sequence: bool, quiet: bool) -> RenderConsole {
        RenderConsole {
            print_camera,
            timings,
            sequence,
            quiet,
            loading: progress(0, LOADING, quiet),
            frames: ProgressBar::hidden(),
        }
    }

    /// Shows `event`.
    pub fn on(&mut self, event: JobEvent) -> Result<()> {
        match event {
            JobEvent::Loading { done, total } => {
                self.loading.set_length(total);
                self.loading.set_position(done);
            }
            JobEvent::Planned { frames } => {
                self.loading.finish_and_clear();
                if self.sequence {
                    self.frames = progress(
                        frames as u64,
                        "{bar:30} {pos}/{len} frames, {msg}, {elapsed} elapsed, ETA {eta}",
                        self.quiet,
                    );
                }
            }
            JobEvent::Camera { spec, .. } if self.print_camera && !self.sequence => {
                emit(&format!("{}\n", spec.to_json()))?;
            }
            JobEvent::Camera { .. } => {}
            JobEvent::Warning(message) => self.frames.suspend(|| log::warn!("{message}")),
            JobEvent::Written {
                number,
                seconds,
                report,
                ..
            } => {
                self.frames.set_message(format!("{seconds:.2} s/frame"));
                self.frames.inc(1);
                if self.timings {
                    if self.sequence {
                        eprintln!("frame {number}:");
                    }
                    eprint!("{}", report.text());
                }
            }
        }
        Ok(())
    }

    /// Ends the bars once the job is done (`outcome`: its result) and, for
    /// a sequence with `--print-camera`, prints its cameras as a path.
    pub fn finish(&self, outcome: &Result<Outcome>) -> Result<()> {
        self.loading.finish_and_clear();
        match outcome {
            Err(Error::Interrupted { .. } | Error::VideoInterrupted { .. }) => {
                self.frames.abandon()
            }
            _ => self.frames.finish_and_clear(),
        }
        if let Ok(outcome) = outcome {
            if self.print_camera && self.sequence && !outcome.cameras.is_empty() {
                emit(&format!("{}\n", camera_path(outcome).to_json()))?;
            }
        }
        Ok(())
    }
}

/// What `pointlens --list-devices` prints: the Vulkan devices, numbered,
/// the default marked.
pub fn devices_text() -> Result<String> {
    let devices = crate::vk::Context::list_devices()?;
    if devices.is_empty() {
        return Err(Error::InvalidArgument(
            "the Vulkan loader reports no device".into(),
        ));
    }
    let mut text = String::new();
    for d in devices {
        let mark = if d.default { "*" } else { " " };
        let unusable = d
            .unusable
            .map(|u| format!(", unusable: {u}"))
            .unwrap_or_default();
        text += &format!(
            "{mark} {}: {} [{}, Vulkan {}, {} MiB device-local{unusable}]\n",
            d.index,
            d.description,
            d.kind,
            d.api_version,
            d.heap_bytes >> 20
        );
    }
    text += "(* the default; choose another with --device N, its number here, \
             or --device NAME, any part of its name or driver)\n";
    Ok(text)
}

/// Shows a command line clap could not parse and returns the exit status:
/// help and version printed (0; 2 for `pointlens` alone, which shows the
/// help), any other error as one line on stderr (2): clap's message up to
/// its usage block, its lines joined (a list of missing arguments follows
/// its first line).
pub fn show_parse_error(e: &clap::Error) -> u8 {
    use clap::error::ErrorKind;
    match e.kind() {
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
            let _ = e.print();
            return 0;
        }
        ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            let _ = e.print();
            return 2;
        }
        _ => {}
    }
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
    2
}

/// An error's chain of messages (outermost first) as one line, innermost
/// cause last, without the causes a message already quotes.
pub fn error_line(chain: &[String]) -> String {
    let mut line = String::new();
    for cause in chain {
        if !line.contains(cause.as_str()) {
            if !line.is_empty() {
                line += ": ";
            }
            line += cause;
        }
    }
    line
}

/// Logging through `log` to stderr: warnings by default, -v info, -vv
/// debug, -q errors only; `RUST_LOG` wins when set.
pub fn init_logging(verbose: u8, quiet: bool) {
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

/// Runs `work` with a bar on stderr of the points read as it reads a file
/// (`progress(done, total)`), cleared when it returns.
pub fn loading<T>(quiet: bool, work: impl FnOnce(&mut dyn FnMut(u64, u64)) -> T) -> T {
    let bar = progress(0, LOADING, quiet);
    let result = work(&mut |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    });
    bar.finish_and_clear();
    result
}
