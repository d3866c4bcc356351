//! Image error metrics (DESIGN §8 `compare`): computed on sRGB-encoded
//! R, G, B values in [0, 1].

use crate::error::{Error, Result};
use crate::image_io::{linear_to_srgb, LinearImage};

fn check_sizes(a: &LinearImage, b: &LinearImage) -> Result<()> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(Error::InvalidArgument(format!(
            "image sizes differ: {}x{} and {}x{}",
            a.width, a.height, b.width, b.height
        )));
    }
    Ok(())
}

fn srgb_pairs<'a>(a: &'a LinearImage, b: &'a LinearImage) -> impl Iterator<Item = (f64, f64)> + 'a {
    a.pixels.iter().zip(&b.pixels).flat_map(|(p, q)| {
        (0..3).map(move |c| (linear_to_srgb(p[c]) as f64, linear_to_srgb(q[c]) as f64))
    })
}

/// Mean squared error over R, G, B of the sRGB-encoded images.
pub fn mse(a: &LinearImage, b: &LinearImage) -> Result<f64> {
    check_sizes(a, b)?;
    let n = a.pixels.len() as f64 * 3.0;
    if n == 0.0 {
        return Ok(0.0);
    }
    Ok(srgb_pairs(a, b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        / n)
}

/// PSNR in dB with peak 1 (`f64::INFINITY` for identical images).
pub fn psnr(a: &LinearImage, b: &LinearImage) -> Result<f64> {
    let m = mse(a, b)?;
    Ok(if m == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (1.0 / m).log10()
    })
}

/// Largest absolute difference of a sRGB-encoded channel value.
pub fn max_abs_error(a: &LinearImage, b: &LinearImage) -> Result<f64> {
    check_sizes(a, b)?;
    Ok(srgb_pairs(a, b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max))
}

/// A heat map of the per-pixel largest sRGB channel difference, scaled so
/// that `full_scale` maps to white (black: no difference), as a linear image.
pub fn difference_image(a: &LinearImage, b: &LinearImage, full_scale: f64) -> Result<LinearImage> {
    check_sizes(a, b)?;
    let pixels = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(p, q)| {
            let d = (0..3)
                .map(|c| (linear_to_srgb(p[c]) - linear_to_srgb(q[c])).abs() as f64)
                .fold(0.0, f64::max);
            let t = (d / full_scale).clamp(0.0, 1.0) as f32;
            // black → red → yellow → white
            [
                (3.0 * t).min(1.0),
                (3.0 * t - 1.0).clamp(0.0, 1.0),
                (3.0 * t - 2.0).clamp(0.0, 1.0),
                1.0,
            ]
        })
        .collect();
    Ok(LinearImage {
        width: a.width,
        height: a.height,
        pixels,
    })
}
