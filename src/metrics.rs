//! Image error metrics (DESIGN §8 `compare`): PSNR and max error over the
//! sRGB-encoded R, G, B values in [0, 1]; SSIM (Wang et al. 2004) on their
//! luma.

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

/// Luma of the sRGB-encoded image (Y′ = 0.299 R′ + 0.587 G′ + 0.114 B′).
fn luma(img: &LinearImage) -> Vec<f64> {
    img.pixels
        .iter()
        .map(|p| {
            let [r, g, b] = [0, 1, 2].map(|c| linear_to_srgb(p[c]) as f64);
            0.299 * r + 0.587 * g + 0.114 * b
        })
        .collect()
}

/// Normalised 1D Gaussian of `size` taps, σ = 1.5.
fn gaussian(size: usize) -> Vec<f64> {
    let c = (size as f64 - 1.0) / 2.0;
    let w: Vec<f64> = (0..size)
        .map(|i| (-((i as f64 - c).powi(2)) / (2.0 * 1.5 * 1.5)).exp())
        .collect();
    let sum: f64 = w.iter().sum();
    w.into_iter().map(|v| v / sum).collect()
}

/// Separable 'valid' filtering of a w×h image with kernels `kx`, `ky`.
fn filter_valid(img: &[f64], w: usize, h: usize, kx: &[f64], ky: &[f64]) -> Vec<f64> {
    let (ow, oh) = (w + 1 - kx.len(), h + 1 - ky.len());
    let rows: Vec<f64> = (0..h)
        .flat_map(|y| {
            (0..ow).map(move |x| {
                kx.iter()
                    .enumerate()
                    .map(|(i, k)| k * img[y * w + x + i])
                    .sum()
            })
        })
        .collect();
    (0..oh)
        .flat_map(|y| {
            let rows = &rows;
            (0..ow).map(move |x| {
                ky.iter()
                    .enumerate()
                    .map(|(j, k)| k * rows[(y + j) * ow + x])
                    .sum()
            })
        })
        .collect()
}

/// Mean SSIM (Wang, Bovik, Sheikh and Simoncelli 2004) on luma: an 11×11
/// Gaussian window with σ = 1.5 over every position where it fits inside the
/// image (a window as large as the image where the image is smaller),
/// K1 = 0.01, K2 = 0.03, dynamic range 1. Identical images give 1.
pub fn ssim(a: &LinearImage, b: &LinearImage) -> Result<f64> {
    check_sizes(a, b)?;
    let (w, h) = (a.width as usize, a.height as usize);
    if w == 0 || h == 0 {
        return Ok(1.0);
    }
    let (kx, ky) = (gaussian(w.min(11)), gaussian(h.min(11)));
    let (x, y) = (luma(a), luma(b));
    let product = |p: &[f64], q: &[f64]| p.iter().zip(q).map(|(u, v)| u * v).collect::<Vec<f64>>();
    let f = |img: &[f64]| filter_valid(img, w, h, &kx, &ky);
    let (mx, my) = (f(&x), f(&y));
    let (sxx, syy, sxy) = (
        f(&product(&x, &x)),
        f(&product(&y, &y)),
        f(&product(&x, &y)),
    );
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let n = mx.len() as f64;
    let total: f64 = (0..mx.len())
        .map(|i| {
            let (ux, uy) = (mx[i], my[i]);
            let vx = sxx[i] - ux * ux;
            let vy = syy[i] - uy * uy;
            let cxy = sxy[i] - ux * uy;
            ((2.0 * ux * uy + c1) * (2.0 * cxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2))
        })
        .sum();
    Ok(total / n)
}

/// `pointlens compare`: PSNR, SSIM and the largest absolute error of the
/// images at `a` and `b` as `name: value` lines, and where `diff` names a
/// file the difference as a heat map (black: none, white: the largest).
/// Both are compared premultiplied, as an EXR holds its color: a
/// transparent PNG's straight color is multiplied by its alpha
/// ([`crate::image_io::read_image_premultiplied`]).
pub fn compare_files(
    a: &std::path::Path,
    b: &std::path::Path,
    diff: Option<&std::path::Path>,
) -> Result<String> {
    if let Some(d) = diff {
        crate::image_io::check_output_path(d)?;
    }
    let (ia, ib) = (
        crate::image_io::read_image_premultiplied(a)?,
        crate::image_io::read_image_premultiplied(b)?,
    );
    let psnr = psnr(&ia, &ib)?;
    let ssim = ssim(&ia, &ib)?;
    let max = max_abs_error(&ia, &ib)?;
    if let Some(d) = diff {
        let heat = difference_image(&ia, &ib, max.max(1.0 / 255.0))?;
        crate::image_io::write_image(&heat, d)?;
    }
    // Identical images: "psnr: inf" (Rust formats infinity so).
    Ok(format!(
        "psnr: {psnr:.4}\nssim: {ssim:.6}\nmax_abs_error: {max:.6}\n"
    ))
}
