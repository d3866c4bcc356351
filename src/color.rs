//! What a point's color shows (`--color`, issue 29 item 5): the file's
//! RGB, the LiDAR intensity, the elevation, the ASPRS class or the return.
//! Colors are made on the host once, after loading, in linear light (the
//! maps below are defined on sRGB codes, as published, and converted).

use glam::Vec3;

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::image_io::srgb_to_linear;
use crate::input::linear_from_code;

/// `--color`: what a point's color shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ColorMode {
    /// The file's RGB (the default where it has any).
    Rgb,
    /// The LiDAR intensity as grey, stretched over the file's range (the
    /// default without RGB).
    Intensity,
    /// The height along the up axis (z for LiDAR and z-up PLY, else y)
    /// through viridis, over its 0.5–99.5 % range.
    Elevation,
    /// The ASPRS class through a fixed palette ([`class_srgb8`]).
    Classification,
    /// Single, first, intermediate or last of several returns.
    Return,
}

impl ColorMode {
    pub fn name(self) -> &'static str {
        match self {
            ColorMode::Rgb => "rgb",
            ColorMode::Intensity => "intensity",
            ColorMode::Elevation => "elevation",
            ColorMode::Classification => "classification",
            ColorMode::Return => "return",
        }
    }
}

/// A LAS return (its number and the pulse's count of returns, each 0–15)
/// in one byte: number in the low four bits, count in the high four.
pub fn pack_return(number: u8, count: u8) -> u8 {
    (number.min(15)) | (count.min(15) << 4)
}

/// The ranges a color mode stretches over: the intensities' (min, max)
/// and the heights' 0.5–99.5 % range. Made from the whole cloud, or, for
/// a cloud read in parts (COPC by node), once from every point of the file
/// (`CopcClouds::color_ranges`), so that every frame colors a point as the
/// file read whole does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColorRanges {
    pub intensity: (u16, u16),
    pub elevation: (f32, f32),
}

impl ColorRanges {
    /// The ranges of `cloud`'s values.
    pub fn of(cloud: &PointCloud) -> ColorRanges {
        let intensity = cloud.intensities.as_ref().map_or((0, 0), |values| {
            values
                .iter()
                .fold((u16::MAX, 0), |(lo, hi), &v| (lo.min(v), hi.max(v)))
        });
        let axis = if cloud.z_up { 2 } else { 1 };
        let heights: Vec<f32> = cloud.positions.iter().map(|p| p[axis]).collect();
        ColorRanges {
            intensity,
            elevation: percentile_range(heights, ELEVATION_TAIL),
        }
    }
}

/// The share of heights below and above the elevation's stretch: its
/// range is the 0.5–99.5 % one.
pub const ELEVATION_TAIL: f64 = 0.005;

/// The ranks (from 0) in `n` sorted values of the values at fraction `q`
/// and 1 − `q`: what [`ColorRanges`] takes for the elevation's range
/// (`n` ≥ 1).
pub fn percentile_ranks(n: usize, q: f64) -> (usize, usize) {
    let last = n.saturating_sub(1);
    let lo_at = (q * last as f64).round() as usize;
    let hi_at = ((1.0 - q) * last as f64).round() as usize;
    (lo_at, hi_at)
}

/// Recolors `cloud` by `mode`, stretched over its own ranges
/// ([`apply_over`]).
pub fn apply(cloud: &mut PointCloud, mode: ColorMode) -> Result<()> {
    let ranges = ColorRanges::of(cloud);
    apply_over(cloud, mode, &ranges)
}

/// Recolors `cloud` by `mode`. Fails, naming what is missing, where the
/// file has no such attribute (`rgb` without RGB, `intensity`,
/// `classification` or `return` outside LAS/LAZ).
pub fn apply_over(cloud: &mut PointCloud, mode: ColorMode, ranges: &ColorRanges) -> Result<()> {
    let missing = |what: &str| {
        Err(Error::InvalidArgument(format!(
            "--color {}: the cloud has no {what}",
            mode.name()
        )))
    };
    match mode {
        ColorMode::Rgb => {
            if !cloud.has_rgb {
                return missing("RGB colors");
            }
        }
        ColorMode::Intensity => {
            let Some(values) = &cloud.intensities else {
                return missing("intensities (LAS/LAZ, or a PLY `intensity`)");
            };
            let (lo, hi) = ranges.intensity;
            // The loader's grey ramp (`input::linear_from_code`).
            let span = f64::from(hi.saturating_sub(lo).max(1));
            for (c, &v) in cloud.colors.iter_mut().zip(values) {
                let v = v.clamp(lo, hi.max(lo));
                *c = Vec3::splat(linear_from_code(f64::from(v - lo), span));
            }
        }
        ColorMode::Elevation => {
            let axis = if cloud.z_up { 2 } else { 1 };
            let heights: Vec<f32> = cloud.positions.iter().map(|p| p[axis]).collect();
            let (lo, hi) = ranges.elevation;
            let span = (hi - lo).max(f32::MIN_POSITIVE);
            for (c, h) in cloud.colors.iter_mut().zip(heights) {
                *c = viridis(((h - lo) / span).clamp(0.0, 1.0));
            }
        }
        ColorMode::Classification => {
            let Some(classes) = &cloud.classifications else {
                return missing("classifications (LAS/LAZ)");
            };
            for (c, &k) in cloud.colors.iter_mut().zip(classes) {
                *c = linear(class_srgb8(k));
            }
        }
        ColorMode::Return => {
            let Some(returns) = &cloud.returns else {
                return missing("returns (LAS/LAZ)");
            };
            for (c, &r) in cloud.colors.iter_mut().zip(returns) {
                *c = linear(return_srgb8(r));
            }
        }
    }
    cloud.has_colors = true;
    Ok(())
}

/// The values at fraction `q` and 1 − `q` of `v` sorted.
fn percentile_range(mut v: Vec<f32>, q: f64) -> (f32, f32) {
    if v.is_empty() {
        return (0.0, 1.0);
    }
    let (lo_at, hi_at) = percentile_ranks(v.len(), q);
    let lo = *v.select_nth_unstable_by(lo_at, f32::total_cmp).1;
    let hi = *v.select_nth_unstable_by(hi_at, f32::total_cmp).1;
    (lo, hi)
}

fn linear(srgb8: [u8; 3]) -> Vec3 {
    Vec3::from_array(srgb8.map(|v| srgb_to_linear(f32::from(v) / 255.0)))
}

/// Viridis (matplotlib's perceptually uniform map) at nine stops, as
/// published (sRGB codes); interpolated in sRGB between them.
pub const VIRIDIS_SRGB8: [[u8; 3]; 9] = [
    [0x44, 0x01, 0x54],
    [0x47, 0x2D, 0x7B],
    [0x3B, 0x52, 0x8B],
    [0x2C, 0x72, 0x8E],
    [0x21, 0x90, 0x8C],
    [0x27, 0xAD, 0x81],
    [0x5D, 0xC8, 0x63],
    [0xAA, 0xDC, 0x32],
    [0xFD, 0xE7, 0x25],
];

/// Viridis at `t` in [0, 1], linear light.
pub fn viridis(t: f32) -> Vec3 {
    let x = t.clamp(0.0, 1.0) * (VIRIDIS_SRGB8.len() - 1) as f32;
    let i = (x.floor() as usize).min(VIRIDIS_SRGB8.len() - 2);
    let f = x - i as f32;
    let stop = |k: usize| Vec3::from_array(VIRIDIS_SRGB8[k].map(|v| f32::from(v) / 255.0));
    let srgb = stop(i).lerp(stop(i + 1), f);
    Vec3::new(
        srgb_to_linear(srgb.x),
        srgb_to_linear(srgb.y),
        srgb_to_linear(srgb.z),
    )
}

/// The palette of ASPRS classes (LAS 1.4 R15, table 17), sRGB codes:
/// ground brown, vegetation greens from light (low) to dark (high),
/// buildings orange-red, water blue, noise magenta, wires yellow, bridges
/// and roads greys; unclassified and reserved classes grey.
pub fn class_srgb8(class: u8) -> [u8; 3] {
    match class {
        2 => [0xA0, 0x52, 0x2D],       // ground
        3 => [0x9A, 0xE6, 0x7A],       // low vegetation
        4 => [0x3C, 0xB3, 0x4B],       // medium vegetation
        5 => [0x0B, 0x6E, 0x2A],       // high vegetation
        6 => [0xE0, 0x4B, 0x2B],       // building
        7 | 18 => [0xE0, 0x2D, 0xD0],  // low / high noise
        9 => [0x1E, 0x78, 0xE6],       // water
        10 => [0x6E, 0x5A, 0x46],      // rail
        11 => [0x50, 0x50, 0x55],      // road surface
        13..=16 => [0xF0, 0xDC, 0x28], // wire guard, conductor, tower, connector
        17 => [0xB4, 0xB4, 0xA0],      // bridge deck
        _ => [0x9B, 0x9B, 0x9B],       // never classified, unclassified, reserved
    }
}

/// The colors of `--color return`, sRGB codes: a single return white, the
/// first of several green, the last of several red, an intermediate one
/// blue (as CloudCompare and Potree show returns).
pub fn return_srgb8(packed: u8) -> [u8; 3] {
    let (number, count) = (packed & 15, packed >> 4);
    if count <= 1 {
        [0xF0, 0xF0, 0xF0]
    } else if number <= 1 {
        [0x3C, 0xC8, 0x50]
    } else if number >= count {
        [0xE6, 0x3C, 0x32]
    } else {
        [0x32, 0x64, 0xE6]
    }
}
