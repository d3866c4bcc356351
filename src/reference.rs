//! CPU references of the DOF methods, written for clarity, not speed: the
//! tests check the GPU passes against them texel by texel on small images.

use glam::Vec2;

use crate::camera::{rdb_bin, rdb_lens_table, Camera};
use crate::host_gbuffer::HostGBuffer;
use crate::image_io::LinearImage;
use crate::options::{FastWeights, RdbMode};

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

/// The pixel offsets a pixel of CoC `c` spreads its light over through
/// the camera's aperture: the disk's ([`disk_pixel_count`]) or, for a
/// shape, those that reach by the taps' own test
/// ([`crate::camera::Aperture::reaches`]; the lattice is symmetric, so
/// either side of the focus).
pub fn tap_count(camera: &Camera, c: f32) -> u32 {
    let aperture = &camera.aperture;
    if !aperture.is_shaped() {
        return disk_pixel_count(c);
    }
    let h = 0.5 * c;
    let m = h.max(0.0).ceil() as i64 + 1;
    let mut n = 0;
    for dy in -m..=m {
        for dx in -m..=m {
            if aperture.reaches(Vec2::new(dx as f32, dy as f32), h, true) {
                n += 1;
            }
        }
    }
    n.max(1)
}

/// Zhao's fast approximation (DESIGN §4), unbounded: every pixel Q of the
/// output averages, over all G-buffer pixels P with |p − q| ≤ c_P/2 (for a
/// shaped aperture: p − q reaches Q through it, [`Aperture::reaches`]) and
/// z_P ≤ z_Q, P's color weighted by `weights` (area: over [`tap_count`]).
/// No tiles, no window bound.
///
/// [`Aperture::reaches`]: crate::camera::Aperture::reaches
pub fn fast(gbuffer: &HostGBuffer, camera: &Camera, weights: FastWeights) -> LinearImage {
    let mut out = LinearImage::new(camera.width, camera.height, [0.0; 4]);
    let pixels: Vec<(u32, u32)> = (0..camera.height)
        .flat_map(|y| (0..camera.width).map(move |x| (x, y)))
        .collect();
    for ((x, y), value) in pixels
        .iter()
        .zip(fast_at(gbuffer, camera, weights, &pixels))
    {
        out.set(*x, *y, value);
    }
    out
}

/// [`fast`] at the given output pixels only (x, y), in their order.
pub fn fast_at(
    gbuffer: &HostGBuffer,
    camera: &Camera,
    weights: FastWeights,
    pixels: &[(u32, u32)],
) -> Vec<[f32; 4]> {
    let (w, h) = (gbuffer.width as i64, gbuffer.height as i64);
    let g = gbuffer.guard as i64;
    let coc: Vec<f32> = gbuffer.eye.iter().map(|e| camera.coc_px(e[2])).collect();
    let shaped = camera.aperture.is_shaped();
    let weight: Vec<f32> = coc
        .iter()
        .map(|&c| match weights {
            FastWeights::Area => 1.0 / tap_count(camera, c) as f32,
            FastWeights::Uniform => 1.0,
        })
        .collect();
    pixels
        .iter()
        .map(|&(x, y)| {
            let (qx, qy) = (x as i64 + g, y as i64 + g);
            let zq = gbuffer.eye[(qy * w + qx) as usize][2];
            let mut sum = [0.0f64; 4];
            let mut total = 0.0f64;
            for py in 0..h {
                for px in 0..w {
                    let i = (py * w + px) as usize;
                    let (dx, dy) = (px - qx, py - qy);
                    let c = coc[i];
                    let zp = gbuffer.eye[i][2];
                    let reaches = match shaped {
                        true => camera.aperture.reaches(
                            Vec2::new(dx as f32, dy as f32),
                            0.5 * c,
                            zp >= camera.focus_distance,
                        ),
                        false => ((dx * dx + dy * dy) as f32) <= 0.25 * c * c,
                    };
                    if !reaches || zp > zq {
                        continue;
                    }
                    for (s, v) in sum.iter_mut().zip(&gbuffer.color[i]) {
                        *s += (weight[i] * v) as f64;
                    }
                    total += weight[i] as f64;
                }
            }
            // Alpha: the contributors' coverage, weighted as the color.
            sum.map(|s| (s / total) as f32)
        })
        .collect()
}

/// The bins of a ray distribution buffer: per output pixel and lens bin the
/// G-buffer index of the source that won it, if any.
pub struct RdbBins {
    pub width: u32,
    pub height: u32,
    pub bins: u32,
    /// (depth bits, source index) per (pixel, bin), bin fastest;
    /// (u32::MAX, u32::MAX) for an empty bin.
    cells: Vec<(u32, u32)>,
}

impl RdbBins {
    /// The G-buffer index of the source bin `bin` of output pixel (x, y)
    /// kept, None when no ray reached it.
    pub fn winner(&self, x: u32, y: u32, bin: u32) -> Option<u32> {
        let n2 = (self.bins * self.bins) as usize;
        let cell = self.cells[(y * self.width + x) as usize * n2 + bin as usize];
        (cell.1 != u32::MAX).then_some(cell.1)
    }
}

/// The scatter of the ray distribution buffer (DESIGN §5), as
/// `rdb_scatter.comp` computes it: per output pixel and lens bin the nearest
/// source offered to it (smallest depth, then smallest G-buffer index).
pub fn rdb_bins(gbuffer: &HostGBuffer, camera: &Camera, bins: u32, mode: RdbMode) -> RdbBins {
    let (gw, gh) = (gbuffer.width as i64, gbuffer.height as i64);
    let (w, h) = (camera.width as i64, camera.height as i64);
    let g = gbuffer.guard as i64;
    let n2 = (bins * bins) as usize;
    let table = rdb_lens_table(bins);
    let mut cells = vec![(u32::MAX, u32::MAX); (w * h) as usize * n2];
    let mut offer = |q: (i64, i64), bin: usize, key: (u32, u32)| {
        if q.0 >= 0 && q.1 >= 0 && q.0 < w && q.1 < h {
            let cell = &mut cells[(q.1 * w + q.0) as usize * n2 + bin];
            *cell = (*cell).min(key);
        }
    };
    for py in 0..gh {
        for px in 0..gw {
            let source = (py * gw + px) as u32;
            let z = gbuffer.eye[source as usize][2];
            let key = (z.to_bits(), source);
            let p = (px - g, py - g);
            let c = camera.coc_px(z);
            match mode {
                RdbMode::Centre => {
                    for (b, u) in table.iter().enumerate() {
                        let o = camera.lens_offset_px(z, *u);
                        let d = ((o.x + 0.5).floor() as i64, (o.y + 0.5).floor() as i64);
                        offer((p.0 + d.0, p.1 + d.1), b, key);
                    }
                }
                RdbMode::Pairs if c < 2.0 => {
                    for b in 0..n2 {
                        offer(p, b, key);
                    }
                }
                RdbMode::Pairs => {
                    let r = (0.5 * c).floor() as i64;
                    for dy in -r..=r {
                        for dx in -r..=r {
                            if ((dx * dx + dy * dy) as f32) > 0.25 * c * c {
                                continue;
                            }
                            let u = camera.lens_sign(z) * 2.0 * Vec2::new(dx as f32, dy as f32) / c;
                            offer((p.0 + dx, p.1 + dy), rdb_bin(u, bins) as usize, key);
                        }
                    }
                }
            }
        }
    }
    RdbBins {
        width: camera.width,
        height: camera.height,
        bins,
        cells,
    }
}

/// The ray distribution buffer (DESIGN §5), as `rdb_scatter.comp` and
/// `rdb_resolve.comp` compute it: the bins of [`rdb_bins`], then per output
/// pixel the mean color of the filled bins' sources (the G-buffer color
/// where no bin is filled).
pub fn rdb(gbuffer: &HostGBuffer, camera: &Camera, bins: u32, mode: RdbMode) -> LinearImage {
    let buffer = rdb_bins(gbuffer, camera, bins, mode);
    let (gw, g) = (gbuffer.width, gbuffer.guard);
    let mut out = LinearImage::new(camera.width, camera.height, [0.0; 4]);
    for y in 0..camera.height {
        for x in 0..camera.width {
            let filled: Vec<u32> = (0..bins * bins)
                .filter_map(|b| buffer.winner(x, y, b))
                .collect();
            // Alpha: the sources' mean coverage, as the color.
            let color = if filled.is_empty() {
                gbuffer.color[((y + g) * gw + x + g) as usize]
            } else {
                let mut sum = [0.0f32; 4];
                for s in &filled {
                    for (acc, v) in sum.iter_mut().zip(&gbuffer.color[*s as usize]) {
                        *acc += v;
                    }
                }
                sum.map(|v| v / filled.len() as f32)
            };
            out.set(x, y, color);
        }
    }
    out
}
