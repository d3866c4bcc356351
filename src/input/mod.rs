//! Input: every point-cloud format pointlens reads, chosen by the file's
//! magic bytes — PLY ([`ply`]), LAS / LAZ / COPC ([`las`]) — into a
//! [`PointCloud`]. Loading knows nothing of the splat hierarchy: a reader
//! gives positions, linear colors, normals and the file's facts, nothing
//! more. docs/ARCHITECTURE.md, "Adding an input format".

pub mod copc;
pub mod gaussians;
pub mod las;
pub mod laz_gps;
pub mod ply;

use std::path::Path;

use glam::{DVec3, Vec3};

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::image_io::srgb_to_linear;

/// Color of a cloud without colors: sRGB (0.8, 0.8, 0.8) in linear light.
pub const DEFAULT_COLOR: Vec3 = Vec3::splat(0.603_827_4);

/// The linear-light value of a color channel stored as an sRGB-encoded
/// integer `code` out of `max_code` (e.g. 255 or 65535), clamped to [0, 1]:
/// the one conversion every reader uses.
pub fn linear_from_code(code: f64, max_code: f64) -> f32 {
    srgb_to_linear(((code / max_code) as f32).clamp(0.0, 1.0))
}

/// Loads a point cloud by its format: LAS or LAZ (COPC included) by the
/// magic bytes `LASF` or, for a file that cannot be peeked at, by the
/// extension; PLY otherwise. `origin` (file coordinates) re-centres the
/// cloud: LAS/LAZ in double precision from the integer codes (default: the
/// centre of its bounds, see `las`), PLY in double precision from the
/// file's values (default: the centre of its bounds for double or 32-bit
/// integer coordinates far from zero, else none: `ply::load_ply_at`).
/// `progress(done, total)` follows a LAS/LAZ read chunk by chunk.
pub fn load_cloud(
    path: &Path,
    origin: Option<DVec3>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<PointCloud> {
    let cloud = if is_las(path) {
        las::load_las(path, origin, progress)?
    } else {
        if let Some(origin) = origin.filter(|o| !o.is_finite()) {
            return Err(ply::ply_error(
                path,
                format!("--origin must be three finite numbers, got {origin}"),
            ));
        }
        ply::load_ply_at(path, origin)?
    };
    if let Some(i) = cloud
        .positions
        .iter()
        .position(|p| !p.is_finite() || p.abs().max_element() > MAX_COORDINATE)
    {
        let at = cloud.positions[i];
        return Err(Error::InvalidArgument(format!(
            "{}: point {i} at ({:e}, {:e}, {:e}) is beyond ±{MAX_COORDINATE:e} scene units{}, where \
             squared distances overflow f32; remove it, or rescale or re-centre the cloud (--origin)",
            path.display(),
            at.x,
            at.y,
            at.z,
            if cloud.origin == DVec3::ZERO { "" } else { " from the origin" },
        )));
    }
    Ok(cloud)
}

/// Host bytes a point of a cloud read whole takes at the peak of a
/// `render` (the cloud as read, then the splat hierarchy's build, which
/// drops it once its leaves hold the points): 53 measured for PLY and 56
/// for LAZ input (docs/BENCHMARKS.md, "COPC by node and `convert`"), with
/// room for the frame's own.
pub const WHOLE_READ_BYTES_PER_POINT: u64 = 60;

/// `--memory-mb` by default: half the memory this process may use, the
/// machine's (MemTotal of /proc/meminfo) or its control group's limit
/// where lower (a container's: cgroup v2 `memory.max`, v1
/// `memory.limit_in_bytes`); 4096 MiB where neither can be read.
pub fn default_memory_mb() -> u64 {
    let total = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        m.lines()
            .find_map(|l| l.strip_prefix("MemTotal:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            .map(|kib| kib.saturating_mul(1024))
    });
    let limit = [
        "/sys/fs/cgroup/memory.max",
        "/sys/fs/cgroup/memory/memory.limit_in_bytes",
    ]
    .iter()
    .filter_map(|f| std::fs::read_to_string(f).ok()?.trim().parse::<u64>().ok())
    .min();
    let bytes = match (total, limit) {
        (Some(t), Some(l)) => t.min(l),
        (Some(t), None) => t,
        (None, Some(l)) => l,
        (None, None) => return 4096,
    };
    (bytes / (2 << 20)).max(1)
}

/// Bytes a point of a PLY file costs the general reader (ply-rs, a map
/// per vertex), which reads what the direct one declines.
pub const GENERAL_READ_BYTES_PER_POINT: u64 = 300;

/// The points a PLY, LAS or LAZ file declares in its header and about the
/// bytes a whole read of it takes at its peak, where that can be told
/// without reading the file (not from a pipe); the header checked as its
/// reader checks it. [`WHOLE_READ_BYTES_PER_POINT`] a point; an ASCII PLY
/// file's text besides, with its line index (16 bytes a vertex); with
/// `general`, a PLY file read by the general reader.
pub fn whole_read_bytes(path: &Path, general: bool) -> Result<Option<(u64, u64)>> {
    let per_point = WHOLE_READ_BYTES_PER_POINT;
    if is_las(path) {
        let points = las::check_las(path)?;
        return Ok(Some((points, points.saturating_mul(per_point))));
    }
    Ok(
        ply::declared_points(path)?.map(|(points, ascii, payload_len)| {
            let bytes = match (general, ascii) {
                (true, _) => payload_len + points.saturating_mul(GENERAL_READ_BYTES_PER_POINT),
                (false, true) => payload_len + points.saturating_mul(per_point + 16),
                (false, false) => points.saturating_mul(per_point),
            };
            (points, bytes)
        }),
    )
}

/// Refuses, in one line ending with `advice(path)`, a cloud to be read
/// whole that would take more than `memory_mb` MiB ([`whole_read_bytes`];
/// a pipe is not checked: its size is known at its end).
pub fn check_whole_read_fits(
    path: &Path,
    memory_mb: u64,
    general: bool,
    advice: fn(&Path) -> String,
) -> Result<()> {
    let Some((points, needed)) = whole_read_bytes(path, general)? else {
        return Ok(());
    };
    if needed <= memory_mb.saturating_mul(1 << 20) {
        return Ok(());
    }
    Err(Error::InvalidArgument(format!(
        "{}: {points} points read whole need about {} MiB, more than --memory-mb {memory_mb}; {}",
        path.display(),
        needed.div_ceil(1 << 20),
        advice(path)
    )))
}

/// What to do with a PLY/LAS/LAZ file too large to read whole: the
/// `pointlens convert` command (paths quoted for a shell) that makes it
/// COPC, which `render` reads by node at any size.
pub fn convert_advice(path: &Path) -> String {
    // The name without its last extension, made distinct from the input.
    let stem = path
        .file_stem()
        .map_or("cloud".into(), |n| n.to_string_lossy());
    let mut output = path.with_file_name(format!("{stem}.copc.laz"));
    if output == path {
        output = path.with_file_name(format!("{stem}-converted.copc.laz"));
    }
    // A relative name that a command line would take for an option.
    let word = |p: &Path| {
        let s = p.to_string_lossy();
        match s.starts_with('-') {
            true => format!("./{s}"),
            false => s.into_owned(),
        }
    };
    format!(
        "convert it to COPC, which renders by node at any size: pointlens convert {} -o {}",
        shell_word(&word(path)),
        shell_word(&word(&output))
    )
}

/// `s` as one word of a POSIX shell command: as it is where it holds
/// only characters no shell treats specially, else in single quotes.
fn shell_word(s: &str) -> String {
    let plain = |c: char| c.is_ascii_alphanumeric() || "/._-+,=:@%".contains(c);
    // A leading `=` expands in zsh.
    match !s.is_empty() && !s.starts_with('=') && s.chars().all(plain) {
        true => s.to_string(),
        false => format!("'{}'", s.replace('\'', "'\\''")),
    }
}

/// The largest coordinate magnitude a rendered point may have (after
/// re-centring): squared distances of such points still fit f32
/// (1e18² = 1e36 < 3.4e38), so depths, CoCs and the splat hierarchy's
/// spheres stay finite.
pub const MAX_COORDINATE: f32 = 1e18;

/// What a file holds, by its magic bytes (and, for a PLY file, its
/// header): the one place a scene's kind is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputKind {
    /// Points read whole: PLY, LAS or LAZ.
    Cloud,
    /// A COPC file, read node by node ([`copc`]).
    Copc,
    /// 3D Gaussians in the reference code's PLY layout ([`gaussians`]).
    Gaussians,
}

/// The kind of the file at `path` ([`InputKind`]). What cannot be read is
/// a [`InputKind::Cloud`], whose reader names what is wrong with it.
pub fn kind_of(path: &Path) -> InputKind {
    if gaussians::is_gaussian_file(path) {
        InputKind::Gaussians
    } else if copc::is_copc(path) {
        InputKind::Copc
    } else {
        InputKind::Cloud
    }
}

/// Whether the points of the cloud at `path` may have normals, known
/// before it is read: a PLY file's header says; LAS and LAZ carry none;
/// what is not a regular file may (its reading tells).
pub fn may_have_normals(path: &Path) -> Result<bool> {
    if is_las(path) {
        return Ok(false);
    }
    Ok(ply::declares_normals(path)?.unwrap_or(true))
}

/// Whether `path` holds a LAS or LAZ file: by its first four bytes where it
/// is a regular file, else by its extension.
pub fn is_las(path: &Path) -> bool {
    use std::io::Read;
    match std::fs::File::open(path) {
        Ok(file) if file.metadata().is_ok_and(|m| m.is_file()) => {
            let mut magic = Vec::with_capacity(4);
            match file.take(4).read_to_end(&mut magic) {
                Ok(_) if las::has_magic(&magic) => true,
                Ok(_) if magic.starts_with(b"ply") => false,
                _ => las::has_las_extension(path),
            }
        }
        _ => las::has_las_extension(path),
    }
}

#[cfg(test)]
mod tests {
    use super::shell_word;

    #[test]
    fn a_path_is_one_shell_word() {
        assert_eq!(shell_word("/data/a-1_b.laz"), "/data/a-1_b.laz");
        assert_eq!(shell_word("my scan.laz"), "'my scan.laz'");
        assert_eq!(shell_word("it's.ply"), r"'it'\''s.ply'");
        assert_eq!(shell_word("$HOME"), "'$HOME'");
        assert_eq!(shell_word(""), "''");
        assert_eq!(shell_word("=x.laz"), "'=x.laz'");
    }

    #[test]
    fn the_advice_names_a_distinct_output() {
        let advice = |p: &str| super::convert_advice(std::path::Path::new(p));
        assert!(advice("/d/a.v1.laz").ends_with("convert /d/a.v1.laz -o /d/a.v1.copc.laz"));
        assert!(advice("scan.copc.laz").ends_with("convert scan.copc.laz -o scan.copc.copc.laz"));
        assert!(advice("x.copc.laz.copc.laz").contains("-o x.copc.laz.copc.copc.laz"));
        assert!(advice("-x.las").ends_with("convert ./-x.las -o ./-x.copc.laz"));
    }
}
