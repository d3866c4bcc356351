//! Video output: `-o film.mp4` (H.264) or `-o film.webm` (VP9) writes a
//! sequence's frames through an installed `ffmpeg`, fed raw 8-bit sRGB
//! frames through a pipe in frame order. The file is written beside its
//! name and renamed when ffmpeg has finished it, as every output is: an
//! interrupted or failed video leaves no file.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};

use crate::error::{Error, Result};
use crate::image_io::Srgb8Image;

/// A video container pointlens writes, by the output's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Container {
    /// `.mp4`: H.264 (libx264), yuv420p.
    Mp4,
    /// `.webm`: VP9 (libvpx-vp9), yuv420p.
    Webm,
}

impl Container {
    /// The container `path` names (None: not a video).
    pub fn of(path: &Path) -> Option<Container> {
        let ext = path.extension()?.to_str()?;
        match ext.to_ascii_lowercase().as_str() {
            "mp4" => Some(Container::Mp4),
            "webm" => Some(Container::Webm),
            _ => None,
        }
    }

    /// ffmpeg's arguments for its muxer and encoder.
    fn ffmpeg_args(self) -> &'static [&'static str] {
        match self {
            Container::Mp4 => &["-c:v", "libx264", "-crf", "18", "-f", "mp4"],
            Container::Webm => &[
                "-c:v",
                "libvpx-vp9",
                "-crf",
                "24",
                "-b:v",
                "0",
                "-f",
                "webm",
            ],
        }
    }
}

/// `--fps`: the frame rate of a video when not given.
pub const DEFAULT_FPS: u32 = 24;

/// The ffmpeg on `PATH`, refused in one line where there is none.
pub fn ffmpeg(output: &Path) -> Result<PathBuf> {
    let found = std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|dir| dir.join("ffmpeg"))
            .find(|candidate| candidate.is_file())
    });
    found.ok_or_else(|| {
        Error::InvalidArgument(format!(
            "-o {}: a video is written through ffmpeg, and none is on PATH \
             (install it, e.g. apt install ffmpeg, or write frames: shot_%04d.png)",
            output.display()
        ))
    })
}

/// The frame sizes a container takes: yuv420p needs an even width and
/// height.
pub fn check_size(output: &Path, width: u32, height: u32) -> Result<()> {
    if width % 2 == 1 || height % 2 == 1 {
        return Err(Error::InvalidArgument(format!(
            "-o {}: a video's frames need an even width and height (yuv420p), not {width}×{height}",
            output.display()
        )));
    }
    Ok(())
}

/// A video in writing: ffmpeg reading frames from its standard input into
/// a temporary file beside the output.
pub struct VideoWriter {
    child: Child,
    stdin: Option<ChildStdin>,
    temp: PathBuf,
    path: PathBuf,
    width: u32,
    height: u32,
    frames: u64,
}

impl VideoWriter {
    /// Starts `ffmpeg` on a video at `path` of `width`×`height` frames at
    /// `fps` frames a second.
    pub fn start(path: &Path, width: u32, height: u32, fps: u32) -> Result<VideoWriter> {
        let container = Container::of(path).ok_or_else(|| {
            Error::InvalidArgument(format!("{}: not a video (.mp4, .webm)", path.display()))
        })?;
        check_size(path, width, height)?;
        let ffmpeg = ffmpeg(path)?;
        let temp = crate::image_io::temp_beside(path)?;
        let spawned = Command::new(ffmpeg)
            .args(["-hide_banner", "-loglevel", "error", "-nostdin", "-y"])
            .args(["-f", "rawvideo", "-pix_fmt", "rgb24"])
            .args(["-s", &format!("{width}x{height}")])
            .args(["-r", &fps.to_string(), "-i", "pipe:0"])
            .args(container.ffmpeg_args())
            .args(["-pix_fmt", "yuv420p"])
            .arg(&temp)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn();
        let mut child = match spawned {
            Ok(child) => child,
            Err(source) => {
                crate::image_io::discard_temp(&temp);
                return Err(Error::System {
                    what: "starting ffmpeg",
                    source,
                });
            }
        };
        Ok(VideoWriter {
            stdin: child.stdin.take(),
            child,
            temp,
            path: path.to_path_buf(),
            width,
            height,
            frames: 0,
        })
    }

    /// Appends `frame`, which must be the video's size.
    pub fn push(&mut self, frame: &Srgb8Image) -> Result<()> {
        if (frame.width, frame.height) != (self.width, self.height) {
            return Err(Error::InvalidArgument(format!(
                "-o {}: frame {} is {}×{}, the video's frames {}×{}: a video's frames are one size",
                self.path.display(),
                self.frames + 1,
                frame.width,
                frame.height,
                self.width,
                self.height
            )));
        }
        let stdin = self.stdin.as_mut().expect("open until finished");
        if let Err(e) = stdin.write_all(&frame.rgb) {
            return Err(self.failure(&e.to_string()));
        }
        self.frames += 1;
        Ok(())
    }

    /// Ends the video: ffmpeg finishes the file, which then takes its name.
    pub fn finish(mut self) -> Result<()> {
        drop(self.stdin.take());
        let status = self.child.wait().map_err(|source| Error::System {
            what: "waiting for ffmpeg",
            source,
        })?;
        if !status.success() {
            return Err(self.failure(&status.to_string()));
        }
        crate::image_io::commit_temp(&self.temp, &self.path)
    }

    /// The error of an ffmpeg that failed (`what`), with its own last
    /// message.
    fn failure(&mut self, what: &str) -> Error {
        drop(self.stdin.take());
        let _ = self.child.kill();
        let _ = self.child.wait();
        let mut said = String::new();
        if let Some(mut stderr) = self.child.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut stderr, &mut said);
        }
        let said = said.lines().last().unwrap_or("").trim().to_string();
        Error::InvalidArgument(format!(
            "{}: ffmpeg failed ({what}){}",
            self.path.display(),
            if said.is_empty() {
                String::new()
            } else {
                format!(": {said}")
            }
        ))
    }
}

impl Drop for VideoWriter {
    /// A video not finished leaves no file: ffmpeg is stopped and the
    /// temporary removed.
    fn drop(&mut self) {
        if self.stdin.take().is_some() || self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
        crate::image_io::discard_temp(&self.temp);
    }
}
