//! CPU references of the DOF methods, written for clarity, not speed: the
//! tests check the GPU passes against them texel by texel on small images.

use crate::camera::Camera;
use crate::image_io::LinearImage;
use crate::passes::fast::FastWeights;
use crate::render::HostGBuffer;

/// The number of pixel centres (integer offsets) within distance c/2 of a
/// pixel centre: the pixels a splat of CoC `c` spreads its light over.
pub fn disk_pixel_count(c: f32) -> u32 {
    let r2 = 0.25 * c * c;
    let r = (0.5 * c).floor() as i64;
    let mut n = 0;
    for dy in -r..=r {
        for dx in -r..=r {
            if ((dx * dx + dy * dy) as f32) <= r2 {
                n += 1;
            }
        }
    }
    n.max(1)
}

/// Zhao's fast approximation (DESIGN §4), unbounded: every pixel Q of the
/// output averages, over all G-buffer pixels P with |p − q| ≤ c_P/2 and
/// z_P ≤ z_Q, P's color weighted by `weights`. No tiles, no window bound.
pub fn fast(gbuffer: &HostGBuffer, camera: &Camera, weights: FastWeights) -> LinearImage {
    let (w, h) = (gbuffer.width as i64, gbuffer.height as i64);
    let g = gbuffer.guard as i64;
    let coc: Vec<f32> = gbuffer.eye.iter().map(|e| camera.coc_px(e[2])).collect();
    let weight: Vec<f32> = coc
        .iter()
        .map(|&c| match weights {
            FastWeights::Area => 1.0 / disk_pixel_count(c) as f32,
            FastWeights::Uniform => 1.0,
        })
        .collect();
    let mut out = LinearImage::new(camera.width, camera.height, [0.0; 4]);
    for y in 0..camera.height as i64 {
        for x in 0..camera.width as i64 {
            let (qx, qy) = (x + g, y + g);
            let zq = gbuffer.eye[(qy * w + qx) as usize][2];
            let mut sum = [0.0f64; 3];
            let mut total = 0.0f64;
            for py in 0..h {
                for px in 0..w {
                    let i = (py * w + px) as usize;
                    let (dx, dy) = (px - qx, py - qy);
                    let c = coc[i];
                    if ((dx * dx + dy * dy) as f32) > 0.25 * c * c || gbuffer.eye[i][2] > zq {
                        continue;
                    }
                    for (s, v) in sum.iter_mut().zip(&gbuffer.color[i]) {
                        *s += (weight[i] * v) as f64;
                    }
                    total += weight[i] as f64;
                }
            }
            let mean = sum.map(|s| (s / total) as f32);
            out.set(x as u32, y as u32, [mean[0], mean[1], mean[2], 1.0]);
        }
    }
    out
}
