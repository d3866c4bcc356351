//! Which raster passes take the K×K sub-pixel samples of the G-buffer
//! (DESIGN §3): one sample per pass with the jitter in the projection, or
//! S samples per multisampled pass at the device's standard sample
//! locations, each pass offset so that the passes together take exactly the
//! K×K grid of pixel-cell centres.
//!
//! Or, where the device can hold them, all K² samples in one pass
//! ([`SamplePlan::upscaled`]): a one-sample target K times the output's
//! width and height, whose pixel centres are exactly the grid's cell
//! centres; each splat is drawn once (issue 28: lavapipe's point path
//! costs per splat, not per sample).
//!
//! A multisampled pass offset by `jitter` (added to every splat's pixel
//! position) samples the scene at `q + location_s − jitter` for the pixel
//! with corner `q`. That point lies in pixel `q + floor(location_s −
//! jitter)`; the resolve reads it there, at a read offset of 0 or +1 pixel
//! per axis, so each output pixel gets its own K² grid points: the same
//! sample set as the one-sample passes, in a different order.

use glam::Vec2;

/// Sub-pixel offset of sample `index` of a K×K grid in the one-sample
/// form: cell centres of the pixel, row by row, relative to the pixel
/// centre.
pub fn ssaa_jitter(index: u32, k: u32) -> Vec2 {
    let (i, j) = (index % k, index / k);
    Vec2::new(
        (i as f32 + 0.5) / k as f32 - 0.5,
        (j as f32 + 0.5) / k as f32 - 0.5,
    )
}

/// The standard sample locations of Vulkan (`standardSampleLocations`) for
/// 1, 2, 4 and 8 samples, in 1/16 pixel from the pixel's top-left corner.
fn standard_locations(samples: u32) -> Option<&'static [[i32; 2]]> {
    Some(match samples {
        1 => &[[8, 8]],
        2 => &[[12, 12], [4, 4]],
        4 => &[[6, 2], [14, 6], [2, 10], [10, 14]],
        8 => &[
            [9, 5],
            [7, 11],
            [13, 9],
            [5, 3],
            [3, 13],
            [1, 7],
            [11, 15],
            [15, 1],
        ],
        _ => return None,
    })
}

/// One raster pass of a [`SamplePlan`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedPass {
    /// Sub-pixel offset added to every splat's position, pixels.
    pub jitter: Vec2,
    /// Per sample s, bit 2s: read one pixel to the right; bit 2s + 1: one
    /// pixel down (the resolve's read offset).
    pub read_offsets: u32,
    /// Per sample, its index in the one-sample form (the order DESIGN §3's
    /// "ties to the lowest sample index" means), < K² ≤ 256.
    pub indices: [u8; 8],
}

impl PlannedPass {
    /// `indices` as the resolve reads them: byte s of the 8 is sample s's.
    pub fn packed_indices(&self) -> [u32; 2] {
        PlannedPass::pack_indices(self.indices)
    }

    /// Per-sample indices as the resolve reads them.
    pub fn pack_indices(i: [u8; 8]) -> [u32; 2] {
        [
            u32::from_le_bytes([i[0], i[1], i[2], i[3]]),
            u32::from_le_bytes([i[4], i[5], i[6], i[7]]),
        ]
    }
}

/// The raster passes of one lens position's K×K samples.
#[derive(Debug, Clone, PartialEq)]
pub struct SamplePlan {
    /// Samples per pixel of the sample targets of every pass (1: the
    /// one-sample form).
    pub samples_per_pass: u32,
    /// Target pixels per output pixel along each axis: 1, or K for the
    /// upscaled plan (output pixel p's samples are the target's K×K block
    /// at K·p).
    pub scale: u32,
    /// Horizontal bands of the G-buffer drawn one after the other, each
    /// with every pass (1, or more for an upscaled target that would not
    /// fit whole: [`SamplePlan::in_bands`]).
    pub bands: u32,
    pub passes: Vec<PlannedPass>,
}

impl SamplePlan {
    /// K² one-sample passes with the jitter in the projection: the form
    /// every device supports, and the reference for the others.
    pub fn single(ssaa: u32) -> SamplePlan {
        SamplePlan {
            samples_per_pass: 1,
            scale: 1,
            bands: 1,
            passes: (0..ssaa * ssaa)
                .map(|s| PlannedPass {
                    jitter: ssaa_jitter(s, ssaa),
                    read_offsets: 0,
                    indices: [s as u8, 0, 0, 0, 0, 0, 0, 0],
                })
                .collect(),
        }
    }

    /// K²/S passes of S standard-location samples that together take the
    /// K×K grid exactly, or None when the S locations do not tile it (e.g.
    /// 4 samples for K = 2 or 3: the locations are not on that grid).
    pub fn multisampled(ssaa: u32, samples: u32) -> Option<SamplePlan> {
        let locations = standard_locations(samples)?;
        let k = ssaa as i64;
        if samples == 1 || (k * k) % samples as i64 != 0 {
            return None;
        }
        // Exact arithmetic in units of 1/L pixel: the locations are in
        // 1/16, the grid points (2i + 1)/(2K).
        let l = lcm(16, 2 * k);
        let cell = |i: i64| (2 * i + 1) * (l / (2 * k));
        let mut taken = vec![false; (k * k) as usize];
        let mut passes = Vec::new();
        for first in 0..(k * k) {
            if taken[first as usize] {
                continue;
            }
            let (gx, gy) = (cell(first % k), cell(first / k));
            let scale = l / 16;
            // The pass whose location `anchor` lands on grid point `first`,
            // when all its locations land on grid points not yet taken.
            let attempt = |anchor: &[i32; 2]| -> Option<(Vec<usize>, i64, i64, u32)> {
                let jx = (anchor[0] as i64 * scale - gx).rem_euclid(l);
                let jy = (anchor[1] as i64 * scale - gy).rem_euclid(l);
                let mut hits = Vec::with_capacity(locations.len());
                let mut read_offsets = 0u32;
                for (s, loc) in locations.iter().enumerate() {
                    let x = loc[0] as i64 * scale - jx;
                    let y = loc[1] as i64 * scale - jy;
                    // Grid index of a coordinate, when it is on the grid.
                    let on_grid = |v: i64| {
                        let twice = v.rem_euclid(l) * 2 * k;
                        (twice % l == 0 && (twice / l) % 2 == 1).then_some((twice / l - 1) / 2)
                    };
                    let index = (on_grid(y)? * k + on_grid(x)?) as usize;
                    if taken[index] || hits.contains(&index) {
                        return None;
                    }
                    hits.push(index);
                    // floor(x / L) is 0 or −1 (0 ≤ location, jitter < L): a
                    // point left of (above) the pixel is read one to the
                    // right (down).
                    read_offsets |= u32::from(x < 0) << (2 * s) | u32::from(y < 0) << (2 * s + 1);
                }
                Some((hits, jx, jy, read_offsets))
            };
            let (hits, jx, jy, read_offsets) = locations.iter().find_map(attempt)?;
            for &index in &hits {
                taken[index] = true;
            }
            // The one-sample form's sample s, jittered by cell centre − ½,
            // samples the mirrored cell K² − 1 − s.
            let mut indices = [0u8; 8];
            for (slot, cell) in indices.iter_mut().zip(&hits) {
                *slot = (k * k - 1 - *cell as i64) as u8;
            }
            passes.push(PlannedPass {
                jitter: Vec2::new(jx as f32 / l as f32, jy as f32 / l as f32),
                read_offsets,
                indices,
            });
        }
        Some(SamplePlan {
            samples_per_pass: samples,
            scale: 1,
            bands: 1,
            passes,
        })
    }

    /// All K² samples in one unjittered pass into a one-sample target of K
    /// times the output's width and height: target pixel K·p + (i, j) of
    /// output pixel p has its centre at p + ((i + ½)/K, (j + ½)/K), cell
    /// (i, j)'s centre, so the samples are the one-sample form's; the
    /// resolve folds them in that form's index order (its sample s takes
    /// the mirrored cell K² − 1 − s, see [`SamplePlan::multisampled`]).
    /// The compute rasteriser draws the same target, but samples target
    /// pixel K·p + (i, j) on a rotated grid, at p + ((i + 1 − (j + ½)/K)/K,
    /// (j + (i + ½)/K)/K) (`glsl/splat_compute_main.glsl`); the resolve
    /// and its order are the same.
    pub fn upscaled(ssaa: u32) -> SamplePlan {
        SamplePlan {
            samples_per_pass: 1,
            scale: ssaa,
            bands: 1,
            passes: vec![PlannedPass {
                jitter: Vec2::ZERO,
                read_offsets: 0,
                indices: [0; 8],
            }],
        }
    }

    /// The plan drawn in `bands` horizontal bands of the G-buffer, one
    /// after the other (each band's target holds its rows alone).
    pub fn in_bands(self, bands: u32) -> SamplePlan {
        SamplePlan {
            bands: bands.max(1),
            ..self
        }
    }

    /// The rows of each band of a G-buffer `height` rows tall, (first,
    /// end): bands of equal height (the last one shorter).
    pub fn band_rows(&self, height: u32) -> Vec<(u32, u32)> {
        let rows = height.div_ceil(self.bands).max(1);
        (0..height)
            .step_by(rows as usize)
            .map(|first| (first, (first + rows).min(height)))
            .collect()
    }

    /// Samples of one output pixel that one pass takes.
    pub fn samples_per_pixel_per_pass(&self) -> u32 {
        self.samples_per_pass * self.scale * self.scale
    }

    /// The plan with the fewest passes among the sample counts in
    /// `supported` (bit S set: S samples per pixel) that tile the K×K
    /// grid; the one-sample plan when none does.
    pub fn best(ssaa: u32, supported: u32) -> SamplePlan {
        [8, 4, 2]
            .into_iter()
            .filter(|s| supported & s != 0)
            .find_map(|s| SamplePlan::multisampled(ssaa, s))
            .unwrap_or_else(|| SamplePlan::single(ssaa))
    }

    /// Whether any pass reads a neighbouring pixel (the targets then need
    /// one extra column and row).
    pub fn reads_neighbours(&self) -> bool {
        self.passes.iter().any(|p| p.read_offsets != 0)
    }

    /// The passes for lens positions `lens` (outer) × this plan (inner),
    /// each with the index and position of its lens position.
    pub fn with_lens<'a>(
        &'a self,
        lens: &'a [Vec2],
    ) -> impl Iterator<Item = (u32, Vec2, &'a PlannedPass)> + 'a {
        lens.iter()
            .enumerate()
            .flat_map(move |(l, &lens_u)| self.passes.iter().map(move |p| (l as u32, lens_u, p)))
    }
}

fn lcm(a: i64, b: i64) -> i64 {
    fn gcd(a: i64, b: i64) -> i64 {
        if b == 0 {
            a
        } else {
            gcd(b, a % b)
        }
    }
    a / gcd(a, b) * b
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sample positions of each pass of `plan` within the output pixel
    /// (pixel units from its top-left corner), in the order the resolve
    /// folds them.
    fn positions(plan: &SamplePlan) -> Vec<Vec2> {
        let locations = standard_locations(plan.samples_per_pass).expect("a planned count");
        plan.passes
            .iter()
            .flat_map(|pass| {
                locations.iter().enumerate().map(move |(s, loc)| {
                    let d = Vec2::new(
                        (pass.read_offsets >> (2 * s) & 1) as f32,
                        (pass.read_offsets >> (2 * s + 1) & 1) as f32,
                    );
                    Vec2::new(loc[0] as f32, loc[1] as f32) / 16.0 - pass.jitter + d
                })
            })
            .collect()
    }

    /// The K×K grid of cell centres, sorted.
    fn grid(k: u32) -> Vec<(u32, u32)> {
        let mut v: Vec<_> = (0..k * k)
            .map(|s| {
                let p = (Vec2::new((s % k) as f32, (s / k) as f32) + 0.5) / k as f32;
                ((p.x * 1024.0) as u32, (p.y * 1024.0) as u32)
            })
            .collect();
        v.sort();
        v
    }

    /// Each sample's index is that of the one-sample form's sample at the
    /// same position.
    fn check_indices(plan: &SamplePlan, k: u32) {
        let single = positions(&SamplePlan::single(k));
        let s = plan.samples_per_pass as usize;
        for (n, p) in positions(plan).iter().enumerate() {
            let index = plan.passes[n / s].indices[n % s] as usize;
            assert!(
                (single[index] - *p).abs().max_element() < 1e-6,
                "K={k} S={s}: sample {n} at {p} has index {index}, at {}",
                single[index]
            );
        }
    }

    fn sorted_positions(plan: &SamplePlan) -> Vec<(u32, u32)> {
        let mut v: Vec<_> = positions(plan)
            .into_iter()
            .map(|p| ((p.x * 1024.0) as u32, (p.y * 1024.0) as u32))
            .collect();
        v.sort();
        v
    }

    #[test]
    fn multisampled_plans_take_exactly_the_grid() {
        let mut found = Vec::new();
        for k in 1..=16 {
            for s in [2, 4, 8] {
                if let Some(plan) = SamplePlan::multisampled(k, s) {
                    assert_eq!(plan.passes.len() as u32 * s, k * k, "K={k} S={s}");
                    assert_eq!(sorted_positions(&plan), grid(k), "K={k} S={s}");
                    check_indices(&plan, k);
                    assert!(plan
                        .passes
                        .iter()
                        .all(|p| (0.0..1.0).contains(&p.jitter.x)
                            && (0.0..1.0).contains(&p.jitter.y)));
                    found.push((k, s));
                }
            }
        }
        // The cases that matter: K = 4 (the default) with 4 samples, K = 2
        // with 2, K = 8 with 8.
        for case in [(2, 2), (4, 4), (4, 2), (8, 8), (8, 4)] {
            assert!(found.contains(&case), "{case:?} not planned: {found:?}");
        }
        // 4 standard locations are not on the 2×2 or 3×3 grid.
        assert!(SamplePlan::multisampled(2, 4).is_none());
        assert!(SamplePlan::multisampled(3, 4).is_none());
    }

    #[test]
    fn the_single_plan_is_the_jittered_grid() {
        let plan = SamplePlan::single(4);
        assert_eq!(plan.passes.len(), 16);
        assert!(!plan.reads_neighbours());
        // Jitter j moves the splats by j: pixel centre 0.5 samples 0.5 − j.
        assert_eq!(sorted_positions(&plan), grid(4));
        check_indices(&plan, 4);
    }

    #[test]
    fn the_upscaled_plan_is_the_grid_in_one_pass_folded_in_index_order() {
        for k in 1..=8u32 {
            let plan = SamplePlan::upscaled(k);
            assert_eq!(plan.passes.len(), 1);
            assert_eq!(plan.samples_per_pixel_per_pass(), k * k);
            // Target pixel (i, j) of the block: its centre, in output pixels
            // from the output pixel's corner, is a cell centre.
            let mut centres: Vec<Vec2> = (0..k * k)
                .map(|c| (Vec2::new((c % k) as f32, (c / k) as f32) + 0.5) / k as f32)
                .collect();
            let mut sorted: Vec<(u32, u32)> = centres
                .iter()
                .map(|p| ((p.x * 1024.0) as u32, (p.y * 1024.0) as u32))
                .collect();
            sorted.sort();
            assert_eq!(sorted, grid(k));
            // The resolve folds index s from cell K² − 1 − s: the one-sample
            // form's sample s at the same position.
            let single = positions(&SamplePlan::single(k));
            centres.reverse();
            for (s, p) in centres.iter().enumerate() {
                assert!((single[s] - *p).abs().max_element() < 1e-6, "K={k} s={s}");
            }
        }
    }

    #[test]
    fn bands_cover_every_row_once() {
        for bands in 1..=7 {
            let plan = SamplePlan::upscaled(4).in_bands(bands);
            for height in [1, 2, 7, 480, 1081] {
                let rows = plan.band_rows(height);
                assert!(rows.len() as u32 <= bands.max(1));
                assert_eq!(rows[0].0, 0);
                assert_eq!(rows.last().unwrap().1, height);
                assert!(rows.windows(2).all(|w| w[0].1 == w[1].0 && w[0].0 < w[0].1));
            }
        }
    }

    #[test]
    fn best_prefers_fewer_passes() {
        assert_eq!(SamplePlan::best(4, 1 | 4).samples_per_pass, 4);
        assert_eq!(SamplePlan::best(4, 1 | 4).passes.len(), 4);
        assert_eq!(SamplePlan::best(4, 1 | 2 | 4 | 8).samples_per_pass, 4);
        assert_eq!(SamplePlan::best(2, 1 | 4).samples_per_pass, 1);
        assert_eq!(SamplePlan::best(3, 1 | 2 | 4 | 8).samples_per_pass, 1);
        assert_eq!(SamplePlan::best(8, 1 | 4 | 8).passes.len(), 8);
        assert_eq!(SamplePlan::best(1, 1 | 4).passes.len(), 1);
    }
}
