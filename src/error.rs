//! The library's one error type. Every variant renders as one line that a
//! user can act on; the binary prints it and exits non-zero.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An I/O failure on a named file.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A PLY file that cannot be read: says which file and what is wrong.
    #[error("{path}: {msg}")]
    Ply { path: PathBuf, msg: String },
    /// A LAS or LAZ file that cannot be read: says which file and what is wrong.
    #[error("{path}: {msg}")]
    Las { path: PathBuf, msg: String },
    /// A camera file or camera flag with a missing or impossible value; names the field.
    #[error("camera: {field}: {msg}")]
    Camera { field: &'static str, msg: String },
    /// A file that is not valid JSON or not of the camera file's shape.
    #[error("{path}: {msg}")]
    Json { path: PathBuf, msg: String },
    /// Encoding or decoding an image file.
    #[error("{path}: {msg}")]
    Image { path: PathBuf, msg: String },
    /// A Vulkan call failed (with what to do about the results a user
    /// can act on).
    #[error("Vulkan: {call} failed: {result:?}{}", vk_hint(*result))]
    Vulkan {
        call: &'static str,
        result: ash::vk::Result,
    },
    /// Vulkan is missing or unusable (no loader, no driver, no layer, no device).
    #[error("{0}")]
    VulkanSetup(String),
    /// GPU memory allocation failed.
    #[error("validation reported {0} message(s) (printed above)")]
    Validation(usize),

    #[error("GPU allocation failed: {0}")]
    Allocation(String),
    /// An argument with a value the program cannot use.
    #[error("{0}")]
    InvalidArgument(String),
    /// A call to the operating system that names no file failed.
    #[error("{what}: {source}")]
    System {
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
    /// A sequence stopped by a signal between frames (`job::watch_signals`):
    /// the frames before `next` are complete.
    #[error(
        "interrupted: {written} of {total} frames written, frame {next} and later not rendered \
         (run again with --skip-existing to resume)"
    )]
    Interrupted {
        written: usize,
        total: usize,
        next: u32,
    },
    /// A video stopped by a signal between frames: no file is written.
    #[error("interrupted: {rendered} of {total} frames rendered, the video {} not written", path.display())]
    VideoInterrupted {
        path: std::path::PathBuf,
        rendered: usize,
        total: usize,
    },
    /// An error and where it happened (a file, a frame).
    #[error("{context}: {source}")]
    Within {
        context: String,
        #[source]
        source: Box<Error>,
    },
}

impl Error {
    /// This error, said to have happened in `context` ("frame 3 of
    /// path.json: …").
    pub fn within(self, context: impl Into<String>) -> Error {
        Error::Within {
            context: context.into(),
            source: Box::new(self),
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// What a user can do about a failed Vulkan call's result.
fn vk_hint(result: ash::vk::Result) -> &'static str {
    use ash::vk::Result as R;
    match result {
        R::ERROR_DEVICE_LOST => {
            " (the GPU was lost: a driver reset or a frame that ran too long; run again, \
             with a smaller frame: --width/--height, --lod-px, --rdb-memory-mb, --samples)"
        }
        R::ERROR_OUT_OF_DEVICE_MEMORY | R::ERROR_OUT_OF_HOST_MEMORY => {
            " (out of memory: a smaller frame needs less: --width/--height, --rdb-memory-mb, \
             --rdb-bins, --layers, or --lod-px above 0)"
        }
        _ => "",
    }
}

/// Wraps an `ash` result with the name of the call, for one-line errors.
pub(crate) trait VkContext<T> {
    fn vk(self, call: &'static str) -> Result<T>;
}

impl<T> VkContext<T> for std::result::Result<T, ash::vk::Result> {
    fn vk(self, call: &'static str) -> Result<T> {
        self.map_err(|result| Error::Vulkan { call, result })
    }
}
