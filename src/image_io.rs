//! Linear-light images and their files: 8-bit sRGB PNG and 32-bit float EXR.
//!
//! The renderer works in linear light; [`LinearImage`] holds RGBA in linear
//! light. [`write_image`] picks the file format from the extension (`.png`:
//! sRGB-encoded 8-bit RGB, `.exr`: linear 32-bit float RGBA) and replaces the
//! target atomically, so an interrupted or failed write never leaves a
//! truncated image behind. [`read_image`] reads PNG (sRGB-decoded to linear)
//! and EXR (taken as linear) back for `compare` and the tests.

use std::ffi::OsString;
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::OnceLock;

use image::codecs::openexr::OpenExrEncoder;
use image::codecs::png::PngEncoder;
use image::{
    DynamicImage, ExtendedColorType, ImageEncoder, ImageError, ImageFormat, ImageReader,
    ImageResult,
};

use crate::error::{Error, Result};

/// A linear-light RGBA image, row-major with the top row first.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height` RGBA pixels in linear light, row by row from the top.
    pub pixels: Vec<[f32; 4]>,
}

impl LinearImage {
    /// An image of `width` × `height` pixels, all set to `fill`.
    pub fn new(width: u32, height: u32, fill: [f32; 4]) -> Self {
        Self {
            width,
            height,
            pixels: vec![fill; width as usize * height as usize],
        }
    }

    /// The pixel at column `x`, row `y` (row 0 is the top).
    ///
    /// # Panics
    /// If `(x, y)` lies outside the image.
    pub fn get(&self, x: u32, y: u32) -> [f32; 4] {
        self.pixels[self.index(x, y)]
    }

    /// Sets the pixel at column `x`, row `y` (row 0 is the top).
    ///
    /// # Panics
    /// If `(x, y)` lies outside the image.
    pub fn set(&mut self, x: u32, y: u32, value: [f32; 4]) {
        let i = self.index(x, y);
        self.pixels[i] = value;
    }

    fn index(&self, x: u32, y: u32) -> usize {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) outside a {}x{} image",
            self.width,
            self.height
        );
        y as usize * self.width as usize + x as usize
    }
}

/// Encodes a linear-light value with the sRGB transfer function (IEC
/// 61966-2-1, exact piecewise form). The input is clamped to [0, 1] first;
/// NaN maps to 0.
pub fn linear_to_srgb(c: f32) -> f32 {
    if c >= 1.0 {
        1.0
    } else {
        linear_to_srgb_extended(c)
    }
}

/// [`linear_to_srgb`] continued above 1 (brighter than white, the
/// inverse of [`srgb_to_linear`] there too: 50 → 5.33), as a PLY's float
/// colours hold highlights.
pub fn linear_to_srgb_extended(c: f32) -> f32 {
    if c.is_nan() || c <= 0.0 {
        0.0
    } else if c == 1.0 {
        1.0
    } else if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Decodes an sRGB-encoded value to linear light (IEC 61966-2-1, exact
/// piecewise form). Not clamped: values outside [0, 1] follow the
/// extended curve, and NaN stays NaN.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Encodes a linear-light value as an 8-bit sRGB code:
/// `floor(linear_to_srgb(c) * 255 + 0.5)`, so 0 → 0, 0.5 → 188, 1 → 255,
/// and anything at or above 1 → 255 (NaN → 0).
pub fn linear_to_srgb8(c: f32) -> u8 {
    (linear_to_srgb(c) * 255.0 + 0.5).floor().clamp(0.0, 255.0) as u8
}

/// The linear-light value of each 8-bit sRGB code: `lut[v] ==
/// srgb_to_linear(v as f32 / 255.0)`.
pub fn srgb8_to_linear_lut() -> &'static [f32; 256] {
    static LUT: OnceLock<[f32; 256]> = OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|v| srgb_to_linear(v as f32 / 255.0)))
}

/// Converts an IEEE 754 binary16 (half) bit pattern to `f32`, exactly:
/// normals, subnormals, signed zeros, infinities, and NaNs (payload kept).
pub fn f16_to_f32(bits: u16) -> f32 {
    let sign = u32::from(bits >> 15) << 31;
    let exponent = u32::from((bits >> 10) & 0x1f);
    let mantissa = u32::from(bits & 0x3ff);
    match (exponent, mantissa) {
        (0, 0) => f32::from_bits(sign),
        (0, m) => {
            // Subnormal: m · 2⁻²⁴, exact in f32 (m < 2¹⁰, power-of-two scale).
            let magnitude = m as f32 * f32::from_bits((127 - 24) << 23);
            f32::from_bits(sign | magnitude.to_bits())
        }
        (0x1f, m) => f32::from_bits(sign | 0x7f80_0000 | (m << 13)),
        (e, m) => f32::from_bits(sign | ((e + 127 - 15) << 23) | (m << 13)),
    }
}

/// The file formats [`write_image`] produces and [`read_image`] accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FileFormat {
    Png,
    Exr,
}

impl FileFormat {
    fn name(self) -> &'static str {
        match self {
            Self::Png => "PNG",
            Self::Exr => "EXR",
        }
    }

    fn from_path(path: &Path) -> Result<Self> {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        if ext.eq_ignore_ascii_case("png") {
            Ok(Self::Png)
        } else if ext.eq_ignore_ascii_case("exr") {
            Ok(Self::Exr)
        } else {
            let shown = match path.extension() {
                Some(e) => format!(" '.{}'", e.to_string_lossy()),
                None => ": no extension".to_owned(),
            };
            Err(Error::InvalidArgument(format!(
                "{}: unsupported output format{shown} (use .png or .exr)",
                path.display()
            )))
        }
    }
}

/// Writes `img` to `path`, choosing the format by the extension
/// (case-insensitive):
///
/// * `.png`: 8-bit sRGB-encoded RGB ([`linear_to_srgb8`]); alpha is dropped
///   and the PNG is opaque.
/// * `.exr`: linear 32-bit float RGBA.
///
/// Any other extension is an [`Error::InvalidArgument`] before anything is
/// written. The write is atomic: the image is encoded into a temporary file
/// beside the target (`.NAME.tmp-HOST-PID-N`), synced, then renamed over the
/// target (a symbolic link at `path` is replaced, not followed). On failure
/// the temporary file is removed and the target is left as it was (an
/// existing file keeps its old content, a missing one stays missing). Errors
/// name `path`: [`Error::InvalidArgument`] for a pixel count that does not
/// match the size, [`Error::Image`] for encoding, [`Error::Io`] for the file
/// system.
pub fn write_image(img: &LinearImage, path: &Path) -> Result<()> {
    let format = FileFormat::from_path(path)?;
    let expected = img.width as u64 * img.height as u64;
    if img.pixels.len() as u64 != expected {
        return Err(Error::InvalidArgument(format!(
            "{}: a {}x{} image needs {expected} pixels but has {}",
            path.display(),
            img.width,
            img.height,
            img.pixels.len()
        )));
    }

    write_atomically(path, |file| encode(img, format, file, path))
}

/// Writes a file atomically: `write` fills a new temporary file beside
/// `path` (`.NAME.tmp-HOST-PID-N`) and must sync it; the temporary is then
/// renamed over `path`. On any failure the temporary is removed and `path`
/// is left as it was. Used for every file pointlens writes. While it is
/// written the temporary is listed for [`abandon_writes`], which a signal
/// handler calls.
pub fn write_atomically(path: &Path, write: impl FnOnce(File) -> Result<()>) -> Result<()> {
    let (tmp_path, file) = create_temp_beside(path).map_err(|source| io_err(path, source))?;
    let result = write(file).and_then(|()| {
        stall_for_tests();
        // Under the list's lock: once `abandon_writes` holds it, no
        // temporary becomes a file.
        let mut in_flight = in_flight();
        let renamed = fs::rename(&tmp_path, path).map_err(|source| io_err(path, source));
        in_flight.retain(|p| *p != tmp_path);
        renamed
    });
    match result {
        Ok(()) => {
            sync_parent_dir(path);
            Ok(())
        }
        Err(e) => {
            // Best effort: the original error is the one worth reporting.
            let mut in_flight = in_flight();
            let _ = fs::remove_file(&tmp_path);
            in_flight.retain(|p| *p != tmp_path);
            Err(e)
        }
    }
}

/// A new empty temporary file beside `target`, named as
/// [`write_atomically`]'s are and removed by [`abandon_writes`] alike: for
/// a file another program writes (a video through ffmpeg), then
/// [`commit_temp`] or [`discard_temp`].
pub fn temp_beside(target: &Path) -> Result<PathBuf> {
    let (tmp, file) = create_temp_beside(target).map_err(|source| io_err(target, source))?;
    drop(file);
    Ok(tmp)
}

/// Gives the temporary `tmp` of [`temp_beside`] the name `target`.
pub fn commit_temp(tmp: &Path, target: &Path) -> Result<()> {
    let renamed = {
        let mut in_flight = in_flight();
        let renamed = fs::rename(tmp, target).map_err(|source| io_err(target, source));
        in_flight.retain(|p| p != tmp);
        renamed
    };
    if renamed.is_ok() {
        sync_parent_dir(target);
    }
    renamed
}

/// Removes the temporary `tmp` of [`temp_beside`] (if still there).
pub fn discard_temp(tmp: &Path) {
    let mut in_flight = in_flight();
    let _ = fs::remove_file(tmp);
    in_flight.retain(|p| p != tmp);
}

/// Writes `text` to `path` atomically ([`write_atomically`]).
pub fn write_text_atomically(path: &Path, text: &str) -> Result<()> {
    write_atomically(path, |mut file| {
        let io = |source| io_err(path, source);
        file.write_all(text.as_bytes()).map_err(io)?;
        file.sync_all().map_err(io)
    })
}

/// For the signal tests: `POINTLENS_INJECT_WRITE_STALL_MS=N` holds every
/// write N milliseconds with its temporary complete and not yet renamed,
/// the moment a signal must not turn into a partial file. Read once; unset,
/// nothing waits.
fn stall_for_tests() {
    static STALL: std::sync::OnceLock<Option<u64>> = std::sync::OnceLock::new();
    let stall = STALL.get_or_init(|| {
        std::env::var("POINTLENS_INJECT_WRITE_STALL_MS")
            .ok()?
            .parse()
            .ok()
    });
    if let Some(ms) = *stall {
        std::thread::sleep(std::time::Duration::from_millis(ms));
    }
}

/// The temporary files being written now, by any thread.
fn in_flight() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    static IN_FLIGHT: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
    IN_FLIGHT.lock().unwrap_or_else(|e| e.into_inner())
}

/// Removes the temporary files of the writes in progress and keeps any
/// write from finishing afterwards (their renames wait for ever): for a
/// signal handler that ends the process next, so that an interrupted write
/// leaves neither its file nor its temporary. Returns how many were removed.
pub fn abandon_writes() -> usize {
    let in_flight = in_flight();
    for tmp in in_flight.iter() {
        match tmp.is_dir() {
            // A scratch folder, which its owner may still be filling:
            // renamed first, so that no file is made in it afterwards
            // (its owner's creations through the old name fail).
            true => {
                let mut gone = tmp.clone().into_os_string();
                gone.push(".abandoned");
                let gone = PathBuf::from(gone);
                let dir = match fs::rename(tmp, &gone) {
                    Ok(()) => gone,
                    Err(_) => tmp.clone(),
                };
                // A creation already under way when it was renamed may
                // still add a file: again until it is gone.
                for _ in 0..100 {
                    if fs::remove_dir_all(&dir).is_ok() || !dir.exists() {
                        break;
                    }
                    std::thread::sleep(std::time::Duration::from_millis(2));
                }
            }
            false => {
                let _ = fs::remove_file(tmp);
            }
        }
    }
    let removed = in_flight.len();
    // Held until the process ends.
    std::mem::forget(in_flight);
    removed
}

/// Lists a scratch folder (e.g. `convert`'s parts) for
/// [`abandon_writes`], which a signal handler calls, until
/// [`unlist_scratch_dir`]: a signal then removes it with the writes in
/// progress.
pub fn list_scratch_dir(dir: &Path) {
    in_flight().push(dir.to_path_buf());
}

/// Ends [`list_scratch_dir`] (the folder's owner removes it).
pub fn unlist_scratch_dir(dir: &Path) {
    in_flight().retain(|p| p != dir);
}

/// Checks that `path` names an output format `write_image` supports, so a
/// long render can fail before it starts.
pub fn check_output_path(path: &Path) -> Result<()> {
    FileFormat::from_path(path).map(|_| ())
}

/// Fails when `path`'s folder does not exist (`flag` names the option), so
/// that a long run does not end without a place for its result.
pub fn check_parent_dir(path: &Path, flag: &str) -> Result<()> {
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() && !dir.is_dir() => Err(Error::InvalidArgument(
            format!("{flag} {}: no directory {}", path.display(), dir.display()),
        )),
        _ => Ok(()),
    }
}

/// The PNG bytes [`write_image`] would write for `img` (8-bit sRGB RGB),
/// encoded in memory: what `bench` times as the encoding cost.
pub fn encode_png(img: &LinearImage) -> Result<Vec<u8>> {
    Srgb8Image::of(img).encode_png()
}

/// An image already encoded as a PNG's pixels: 8-bit sRGB RGB, row by row
/// from the top (what the renderer's output pass reads back for `.png`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Srgb8Image {
    pub width: u32,
    pub height: u32,
    /// `3 · width · height` bytes.
    pub rgb: Vec<u8>,
}

impl Srgb8Image {
    /// The encoding of `img` on the host ([`linear_to_srgb8`] per channel;
    /// alpha dropped).
    pub fn of(img: &LinearImage) -> Srgb8Image {
        Srgb8Image {
            width: img.width,
            height: img.height,
            rgb: srgb8_rgb(img),
        }
    }

    /// The PNG file's bytes, encoded in memory.
    pub fn encode_png(&self) -> Result<Vec<u8>> {
        let mut bytes = Vec::new();
        self.check(Path::new("(memory)"))?;
        png_rgb8(&mut bytes, &self.rgb, self.width, self.height)
            .map_err(|e| encoding_error(e, Path::new("(memory)"), FileFormat::Png))?;
        Ok(bytes)
    }

    /// Writes the image to `path`, a `.png`, atomically as [`write_image`].
    pub fn write_png(&self, path: &Path) -> Result<()> {
        if FileFormat::from_path(path)? != FileFormat::Png {
            return Err(Error::InvalidArgument(format!(
                "{}: 8-bit sRGB pixels are written as PNG only",
                path.display()
            )));
        }
        self.check(path)?;
        write_atomically(path, |file| {
            let mut out = BufWriter::new(file);
            png_rgb8(&mut out, &self.rgb, self.width, self.height)
                .map_err(|e| encoding_error(e, path, FileFormat::Png))?;
            sync_buffered(out, path)
        })
    }

    fn check(&self, path: &Path) -> Result<()> {
        let expected = 3 * self.width as u64 * self.height as u64;
        if self.rgb.len() as u64 != expected {
            return Err(Error::InvalidArgument(format!(
                "{}: a {}x{} RGB image needs {expected} bytes but has {}",
                path.display(),
                self.width,
                self.height,
                self.rgb.len()
            )));
        }
        Ok(())
    }
}

/// Whether `path` names a PNG output (an error for a format
/// [`write_image`] does not write).
pub fn is_png_path(path: &Path) -> Result<bool> {
    FileFormat::from_path(path).map(|f| f == FileFormat::Png)
}

/// Checks that `path` names a PNG, for outputs that can only be PNG (a
/// chart), so a long run can fail before it starts.
pub fn check_png_path(path: &Path) -> Result<()> {
    match FileFormat::from_path(path) {
        Ok(FileFormat::Png) => Ok(()),
        _ => Err(Error::InvalidArgument(format!(
            "{}: this output is a PNG (use .png)",
            path.display()
        ))),
    }
}

/// Writes 8-bit RGB pixels (already display-encoded, e.g. a chart) as a
/// PNG, atomically like [`write_image`].
pub fn write_rgb8_png(rgb: &[u8], width: u32, height: u32, path: &Path) -> Result<()> {
    check_png_path(path)?;
    write_atomically(path, |file| {
        let mut out = BufWriter::new(file);
        png_rgb8(&mut out, rgb, width, height)
            .map_err(|e| encoding_error(e, path, FileFormat::Png))?;
        sync_buffered(out, path)
    })
}

/// Encodes `img` into `file` and syncs it to disk. Errors name `path`.
fn encode(img: &LinearImage, format: FileFormat, file: File, path: &Path) -> Result<()> {
    let mut out = BufWriter::new(file);
    let encoded = match format {
        FileFormat::Png => png_rgb8(&mut out, &srgb8_rgb(img), img.width, img.height),
        FileFormat::Exr => {
            let bytes: Vec<u8> = img
                .pixels
                .iter()
                .flatten()
                .flat_map(|v| v.to_ne_bytes())
                .collect();
            OpenExrEncoder::new(&mut out).write_image(
                &bytes,
                img.width,
                img.height,
                ExtendedColorType::Rgba32F,
            )
        }
    };
    encoded.map_err(|e| encoding_error(e, path, format))?;
    sync_buffered(out, path)
}

/// The PNG's pixels: RGB, sRGB-encoded to 8 bits ([`linear_to_srgb8`]),
/// alpha dropped.
/// One channel of an EXR file: its name and `width · height` samples, row
/// by row from the top.
#[derive(Debug, Clone, PartialEq)]
pub struct ExrChannel {
    pub name: String,
    pub samples: Vec<f32>,
}

/// Writes named 32-bit float channels as one single-part EXR (lossless ZIP
/// compression), atomically as [`write_image`]: what `--passes` writes
/// (`R`, `G`, `B`, `A`, `Z`, `CoC`; compositors read `R G B A` as the
/// image and `Z` as its depth). Errors name `path`.
pub fn write_exr_channels(
    path: &Path,
    width: u32,
    height: u32,
    channels: &[ExrChannel],
) -> Result<()> {
    use exr::prelude::{
        AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, Vec2,
        WritableImage,
    };
    if FileFormat::from_path(path)? != FileFormat::Exr {
        return Err(Error::InvalidArgument(format!(
            "{}: channels other than R, G, B are written as EXR only",
            path.display()
        )));
    }
    let expected = width as usize * height as usize;
    if let Some(c) = channels.iter().find(|c| c.samples.len() != expected) {
        return Err(Error::InvalidArgument(format!(
            "{}: channel {} has {} samples, a {width}x{height} image needs {expected}",
            path.display(),
            c.name,
            c.samples.len()
        )));
    }
    let list = channels
        .iter()
        .map(|c| AnyChannel::new(c.name.as_str(), FlatSamples::F32(c.samples.clone())))
        .collect();
    let layer = Layer::new(
        Vec2(width as usize, height as usize),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list),
    );
    let image = Image::from_layer(layer);
    write_atomically(path, |file| {
        let mut out = BufWriter::new(file);
        image
            .write()
            .to_buffered(&mut out)
            .map_err(|e| Error::Image {
                path: path.to_owned(),
                msg: format!("EXR encoding: {e}"),
            })?;
        sync_buffered(out, path)
    })
}

/// Reads every channel of the first part of an EXR file as 32-bit floats
/// (half and unsigned samples converted), sorted by name: the size and the
/// channels.
pub fn read_exr_channels(path: &Path) -> Result<(u32, u32, Vec<ExrChannel>)> {
    use exr::prelude::{read, FlatSamples, ReadChannels, ReadLayers};
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| Error::Image {
            path: path.to_owned(),
            msg: format!("EXR decoding: {e}"),
        })?;
    let layer = image.layer_data;
    let size = layer.size;
    let channels = layer
        .channel_data
        .list
        .into_iter()
        .map(|c| ExrChannel {
            name: c.name.to_string(),
            samples: match c.sample_data {
                FlatSamples::F32(v) => v,
                FlatSamples::F16(v) => v.into_iter().map(f32::from).collect(),
                FlatSamples::U32(v) => v.into_iter().map(|u| u as f32).collect(),
            },
        })
        .collect();
    Ok((size.0 as u32, size.1 as u32, channels))
}

/// Writes a premultiplied linear RGBA image as an 8-bit PNG with alpha:
/// straight (un-premultiplied) color, sRGB-encoded, and alpha = A·255
/// rounded (`--background transparent`). Atomic as [`write_image`].
pub fn write_png_rgba(img: &LinearImage, path: &Path) -> Result<()> {
    check_png_path(path)?;
    let rgba: Vec<u8> = img
        .pixels
        .iter()
        .flat_map(|p| {
            let a = p[3].clamp(0.0, 1.0);
            let straight = |c: f32| if a > 0.0 { (c / a).min(1.0) } else { 0.0 };
            let alpha = (a * 255.0).round() as u8;
            [
                linear_to_srgb8(straight(p[0])),
                linear_to_srgb8(straight(p[1])),
                linear_to_srgb8(straight(p[2])),
                alpha,
            ]
        })
        .collect();
    write_atomically(path, |file| {
        let mut out = BufWriter::new(file);
        PngEncoder::new(&mut out)
            .write_image(&rgba, img.width, img.height, ExtendedColorType::Rgba8)
            .map_err(|e| encoding_error(e, path, FileFormat::Png))?;
        sync_buffered(out, path)
    })
}

fn srgb8_rgb(img: &LinearImage) -> Vec<u8> {
    img.pixels
        .iter()
        .flat_map(|p| [p[0], p[1], p[2]].map(linear_to_srgb8))
        .collect()
}

/// Encodes 8-bit RGB pixels as a PNG into `out`.
fn png_rgb8(out: impl Write, rgb: &[u8], width: u32, height: u32) -> ImageResult<()> {
    PngEncoder::new(out).write_image(rgb, width, height, ExtendedColorType::Rgb8)
}

/// An encoder's error, naming `path`.
fn encoding_error(e: ImageError, path: &Path, format: FileFormat) -> Error {
    match e {
        // The PNG encoder reports its own format errors as I/O errors too;
        // only those from the operating system are file-system failures.
        ImageError::IoError(source) if source.raw_os_error().is_some() => io_err(path, source),
        other => image_msg(path, format!("cannot encode {}: {other}", format.name())),
    }
}

/// Flushes `out` and syncs its file to disk.
fn sync_buffered(out: BufWriter<File>, path: &Path) -> Result<()> {
    let file = out.into_inner().map_err(|e| io_err(path, e.into_error()))?;
    file.sync_all().map_err(|source| io_err(path, source))
}

/// The directory holding `path` (`.` for a bare file name).
fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Creates a new, empty temporary file in the directory of `target`, named
/// `.NAME.tmp-HOST-PID-N` after it, lists it as in flight, and returns its
/// path and handle.
fn create_temp_beside(target: &Path) -> io::Result<(PathBuf, File)> {
    remove_stale_temps(parent_dir(target));
    static COUNTER: AtomicU32 = AtomicU32::new(0);
    let pid = std::process::id();
    let host = host_name();
    let mut attempts = 0;
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let mut name = OsString::from(".");
        name.push(target.file_name().unwrap_or_default());
        name.push(format!(".tmp-{host}-{pid}-{n}"));
        let tmp = parent_dir(target).join(name);
        // Listed before it exists, so that a signal between the two finds it.
        in_flight().push(tmp.clone());
        match OpenOptions::new().write(true).create_new(true).open(&tmp) {
            Ok(file) => return Ok((tmp, file)),
            Err(e) => {
                in_flight().retain(|p| *p != tmp);
                match e.kind() {
                    // A leftover of an earlier process with the same id: try the next name.
                    io::ErrorKind::AlreadyExists if attempts < 100 => attempts += 1,
                    _ => return Err(e),
                }
            }
        }
    }
}

/// This machine's name as temporary files carry it (letters, digits, `.`
/// and `-` as they are, anything else as `_`; `localhost` where it cannot
/// be read). Read once.
fn host_name() -> &'static str {
    static HOST: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    HOST.get_or_init(|| {
        let name = fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .map(|h| h.trim().to_string())
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "localhost".to_string());
        name.chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '.' || c == '-' {
                    c
                } else {
                    '_'
                }
            })
            .collect()
    })
}

/// Removes the temporary files (`.NAME.tmp-HOST-PID-N`) that processes
/// killed mid-write (SIGKILL, a power cut) left in `dir`: those written on
/// this machine (a folder shared by a render farm holds other machines'
/// writes in progress) whose process no longer runs. Once per folder and
/// process, at its first write there, so a sequence of many frames lists
/// its folder once. Best effort, Linux only (where `/proc/PID` tells
/// whether a process runs).
fn remove_stale_temps(dir: &Path) {
    #[cfg(target_os = "linux")]
    {
        use std::collections::HashSet;
        use std::sync::Mutex;
        static CLEANED: Mutex<Option<HashSet<PathBuf>>> = Mutex::new(None);
        let mut cleaned = CLEANED.lock().unwrap_or_else(|e| e.into_inner());
        if !cleaned
            .get_or_insert_with(HashSet::new)
            .insert(dir.to_path_buf())
        {
            return;
        }
        let Ok(entries) = fs::read_dir(dir) else {
            return;
        };
        let host = host_name();
        for entry in entries.flatten() {
            let name = entry.file_name();
            let Some(name) = name.to_str() else { continue };
            let Some((writer_host, pid)) = temp_writer(name) else {
                continue;
            };
            if writer_host == host
                && pid != std::process::id()
                && !Path::new(&format!("/proc/{pid}")).exists()
            {
                let _ = fs::remove_file(entry.path());
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = dir;
}

/// The host and process id in a temporary file's name `.NAME.tmp-HOST-PID-N`.
fn temp_writer(name: &str) -> Option<(&str, u32)> {
    let rest = name.strip_prefix('.')?;
    let at = rest.rfind(".tmp-")?;
    let (rest, n) = rest[at + 5..].rsplit_once('-')?;
    let (host, pid) = rest.rsplit_once('-')?;
    n.parse::<u32>().ok()?;
    Some((host, pid.parse().ok()?))
}

/// Makes the rename durable where the platform supports syncing a directory.
/// Best effort: the image is already in place, so a failure here is ignored.
fn sync_parent_dir(path: &Path) {
    #[cfg(unix)]
    if let Ok(dir) = File::open(parent_dir(path)) {
        let _ = dir.sync_all();
    }
    #[cfg(not(unix))]
    let _ = path;
}

/// Reads a PNG or EXR file as a linear-light image. The format is taken from
/// the file's content (falling back on the extension).
///
/// * PNG (8 or 16 bits; gray, gray+alpha, RGB, RGBA, or palette): color
///   channels are sRGB-decoded to linear light, alpha is taken as is (1 when
///   the file has none).
/// * EXR: channels are taken as linear; alpha is 1 when the file has none.
///
/// Errors name `path`: [`Error::Io`] when the file cannot be opened or read,
/// [`Error::Image`] when it is not a PNG/EXR or cannot be decoded.
pub fn read_image(path: &Path) -> Result<LinearImage> {
    Ok(read_image_format(path)?.0)
}

/// Reads a PNG or EXR file as a premultiplied linear-light image, as
/// pointlens's EXR holds it: a PNG's straight color ([`write_png_rgba`])
/// is multiplied by its alpha, an EXR's is taken as it is. So the PNG and
/// the EXR of one transparent frame read alike (`pointlens compare`).
pub fn read_image_premultiplied(path: &Path) -> Result<LinearImage> {
    let (mut image, format) = read_image_format(path)?;
    if format == FileFormat::Png {
        for p in &mut image.pixels {
            let a = p[3];
            p[0] *= a;
            p[1] *= a;
            p[2] *= a;
        }
    }
    Ok(image)
}

/// [`read_image`] and the file's format.
fn read_image_format(path: &Path) -> Result<(LinearImage, FileFormat)> {
    let file = File::open(path).map_err(|source| io_err(path, source))?;
    let mut reader = ImageReader::new(BufReader::new(file))
        .with_guessed_format()
        .map_err(|source| io_err(path, source))?;
    let format = match reader
        .format()
        .or_else(|| ImageFormat::from_path(path).ok())
    {
        Some(ImageFormat::Png) => FileFormat::Png,
        Some(ImageFormat::OpenExr) => FileFormat::Exr,
        _ => return Err(image_msg(path, "not a PNG or EXR image".into())),
    };
    reader.set_format(match format {
        FileFormat::Png => ImageFormat::Png,
        FileFormat::Exr => ImageFormat::OpenExr,
    });
    let decoded = reader
        .decode()
        .map_err(|e| image_msg(path, format!("cannot decode {}: {e}", format.name())))?;
    let (width, height) = (decoded.width(), decoded.height());
    let pixels = if format == FileFormat::Exr {
        decoded.into_rgba32f().pixels().map(|p| p.0).collect()
    } else {
        srgb_pixels_to_linear(decoded)
    };
    Ok((
        LinearImage {
            width,
            height,
            pixels,
        },
        format,
    ))
}

/// sRGB-decodes the color channels of an integer image; alpha stays linear.
fn srgb_pixels_to_linear(img: DynamicImage) -> Vec<[f32; 4]> {
    let is_16_bit = matches!(
        img,
        DynamicImage::ImageLuma16(_)
            | DynamicImage::ImageLumaA16(_)
            | DynamicImage::ImageRgb16(_)
            | DynamicImage::ImageRgba16(_)
    );
    if is_16_bit {
        img.into_rgba16()
            .pixels()
            .map(|p| {
                let [r, g, b, a] = p.0.map(|v| f32::from(v) / 65535.0);
                [srgb_to_linear(r), srgb_to_linear(g), srgb_to_linear(b), a]
            })
            .collect()
    } else {
        let lut = srgb8_to_linear_lut();
        img.into_rgba8()
            .pixels()
            .map(|p| {
                let [r, g, b, a] = p.0;
                [
                    lut[usize::from(r)],
                    lut[usize::from(g)],
                    lut[usize::from(b)],
                    f32::from(a) / 255.0,
                ]
            })
            .collect()
    }
}

fn io_err(path: &Path, source: io::Error) -> Error {
    Error::Io {
        path: path.to_owned(),
        source,
    }
}

fn image_msg(path: &Path, msg: String) -> Error {
    Error::Image {
        path: path.to_owned(),
        msg,
    }
}
