//! The value parsers of the command line's flags: one parser per kind of
//! value, each with the library's range check or parser behind it, so that
//! a flag and the library give the same message. Clap calls them; the
//! library's types come out.

use glam::Vec3;

use crate::image_io::srgb_to_linear;
use crate::job::Passes;
use crate::options::MethodKind;
use crate::render::SplatSize;
use crate::sequence::FrameRange;

/// A clap value parser for a number with the library's range check, so
/// that the flag and the library give the same message.
pub fn checked(
    check: fn(u32) -> crate::error::Result<u32>,
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
pub fn checked_f32(
    check: fn(f32) -> crate::error::Result<f32>,
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
pub fn frame_range(s: &str) -> Result<FrameRange, String> {
    FrameRange::parse(s).map_err(|e| e.to_string())
}

/// `--method`: the library's parser, whose error names the methods.
pub fn method_kind(s: &str) -> Result<MethodKind, String> {
    MethodKind::parse(s).map_err(|e| e.to_string())
}

/// `--background`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Background {
    Transparent,
    Srgb([f32; 3]),
}

pub fn parse_background(s: &str) -> Result<Background, String> {
    if s.trim().eq_ignore_ascii_case("transparent") {
        return Ok(Background::Transparent);
    }
    parse_vec3(s)
        .map(Background::Srgb)
        .map_err(|e| format!("{e} (or 'transparent')"))
}

/// `--passes`: the EXR channels beside R, G, B, A.
pub fn parse_passes(s: &str) -> Result<Passes, String> {
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

pub fn parse_vec3(s: &str) -> Result<[f32; 3], String> {
    parse_triple(s)
}

/// [`parse_vec3`] in double precision (positions in file coordinates).
pub fn parse_dvec3(s: &str) -> Result<[f64; 3], String> {
    parse_triple(s)
}

/// `X,Y,Z`: three finite numbers, each parsed as `T` itself.
pub fn parse_triple<T: std::str::FromStr + Copy + Default + Into<f64>>(
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

pub fn parse_pixel(s: &str) -> Result<[u32; 2], String> {
    let parts: Vec<&str> = s.split(',').collect();
    match parts[..] {
        [x, y] => match (x.trim().parse(), y.trim().parse()) {
            (Ok(x), Ok(y)) => Ok([x, y]),
            _ => Err(format!("expected pixel X,Y, got '{s}'")),
        },
        _ => Err(format!("expected pixel X,Y, got '{s}'")),
    }
}

impl Background {
    /// `--background` in linear light: black when not given.
    pub fn linear_of(background: Option<Background>) -> crate::error::Result<Vec3> {
        background.map_or(Ok(Vec3::ZERO), Background::linear)
    }

    /// The background in linear light (black when transparent), its sRGB
    /// values checked to lie in [0, 1].
    pub fn linear(self) -> crate::error::Result<Vec3> {
        match self {
            Background::Srgb(c) if c.iter().any(|v| !(0.0..=1.0).contains(v)) => {
                Err(crate::error::Error::InvalidArgument(format!(
                    "--background takes sRGB values in [0, 1], got {c:?}"
                )))
            }
            Background::Srgb(c) => Ok(Vec3::from_array(c.map(srgb_to_linear))),
            Background::Transparent => Ok(Vec3::ZERO),
        }
    }
}

/// `--lod-px` of `bench`: comma-separated levels, each checked as
/// `render`'s.
pub fn lod_px_list(s: &str) -> Result<Vec<f32>, String> {
    s.split(',')
        .map(|p| {
            let v = p
                .trim()
                .parse::<f32>()
                .map_err(|_| format!("--lod-px: '{p}' is not a number"))?;
            crate::options::check_lod_px(v).map_err(|e| e.to_string())
        })
        .collect()
}

/// `--splat-size` / `--splat-px` (each a positive number), else sizes
/// from the points' spacing.
pub fn splat_size(size: Option<f32>, px: Option<f32>) -> crate::error::Result<SplatSize> {
    let refuse = |flag: &str, v: f32| {
        Err(crate::error::Error::InvalidArgument(format!(
            "{flag} must be a positive number, not {v}"
        )))
    };
    if let Some(w) = size.filter(|w| !(w.is_finite() && *w > 0.0)) {
        return refuse("--splat-size", w);
    }
    if let Some(p) = px.filter(|p| !(p.is_finite() && *p > 0.0)) {
        return refuse("--splat-px", p);
    }
    Ok(match (size, px) {
        (Some(w), _) => SplatSize::World(w),
        (_, Some(p)) => SplatSize::Pixels(p),
        _ => SplatSize::Spacing,
    })
}
