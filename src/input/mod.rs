//! Input: every point-cloud format pointlens reads, chosen by the file's
//! magic bytes — PLY ([`ply`]), LAS / LAZ / COPC ([`las`]) — into a
//! [`PointCloud`]. Loading knows nothing of the splat hierarchy: a reader
//! gives positions, linear colors, normals and the file's facts, nothing
//! more. docs/ARCHITECTURE.md, "Adding an input format".

pub mod copc;
pub mod las;
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
/// centre of its bounds, see `las`), PLY from its f32 positions (default:
/// none). `progress(done, total)` follows a LAS/LAZ read chunk by chunk.
pub fn load_cloud(
    path: &Path,
    origin: Option<DVec3>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<PointCloud> {
    let cloud = if is_las(path) {
        las::load_las(path, origin, progress)?
    } else {
        let mut cloud = ply::load_ply(path)?;
        if let Some(origin) = origin {
            cloud.recentre(origin).map_err(|msg| Error::Ply {
                path: path.to_path_buf(),
                msg,
            })?;
        }
        cloud
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

/// The largest coordinate magnitude a rendered point may have (after
/// re-centring): squared distances of such points still fit f32
/// (1e18² = 1e36 < 3.4e38), so depths, CoCs and the splat hierarchy's
/// spheres stay finite.
pub const MAX_COORDINATE: f32 = 1e18;

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
