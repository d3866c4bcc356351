//! The bounded two-field gather (docs/BENCHMARKS.md, "A gather worth
//! having: measured in numpy"): the constants and tables its
//! shaders and its CPU reference share, and the reference itself.
//!
//! Per G-buffer pixel P: premultiplied colour c (alpha = coverage), eye
//! depth z (+∞ on background), CoC radius r = c_px(z)/2. P is a *surface*
//! where z is finite, in the *near field* where z < S (the focus
//! distance), else in the *far field* (background included).
//!
//! - **Bands** (a scatter of the surfaces, as alpha): each surface spreads
//!   its colour over its disk with total weight 1. One of CoC radius under
//!   [`B0`] px does so at full resolution by the disk-pixel overlap table
//!   ([`OverlapTable`]); a larger one joins the band of level L (texels of
//!   2^L px) whose radii are [B·2^(L−1), B·2^L) (B = [`BAND`]; the first
//!   from B0, the last open), summed per texel with its sub-texel centroid
//!   and RMS radius, spread over the texels its disk reaches, and brought
//!   back to full resolution bilinearly. Two sets: the near field, and all
//!   surfaces.
//! - **Rings** (a gather of the far field): a surface receiver Q takes
//!   1 + 8 + … + 8K taps ([`RINGS`] = K) over its own disk, from the far
//!   field's mip level whose texels match the ring spacing; each tap is in
//!   front of Q or behind it by its mean inverse depth, and reaches Q by
//!   its mean radius. Receivers of radius under K + ½ take the integer
//!   offsets at full resolution with the overlap table instead.
//! - **Composite**: a surface receiver puts its front (the front taps and
//!   the near-field bands) as alpha over its normalised back; a background
//!   receiver puts the all-surface bands over its own colour.
//!
//! Every pixel costs a bounded number of taps, whatever its CoC.

use crate::camera::Camera;
use crate::host_gbuffer::HostGBuffer;
use crate::image_io::LinearImage;

/// CoC radius (px) under which a surface spreads at full resolution.
pub const B0: f32 = 3.0;
/// A band's largest radius in its own texels: level L (texels of 2^L px)
/// holds radii [BAND·2^(L−1), BAND·2^L) px (the first from [`B0`]).
pub const BAND: f32 = 4.0;
/// Rings of the far-field gather: 1 + 8 + 16 + … + 8K taps.
pub const RINGS: u32 = 3;
/// Band levels 1..=LEVELS and far-field mip levels 0..=LEVELS.
pub const LEVELS: u32 = 6;
/// Radius steps of an overlap table (radius 0 to its largest).
pub const TABLE_STEPS: u32 = 512;
/// Sub-samples per axis of a receiver pixel when a table is built.
const TABLE_SUPERSAMPLES: u32 = 32;
/// Half a pixel's diagonal, rounded up: how far past a disk's radius a
/// pixel square it touches may be centred.
pub const HALF_DIAGONAL: f32 = 0.7072;

/// The radius of the rings' receivers that take the full-resolution
/// offsets instead: K + ½.
pub fn small_radius() -> f32 {
    RINGS as f32 + 0.5
}

/// The band level (1..=LEVELS) of a surface of CoC radius `r` ≥ [`B0`]
/// px; None under it (the full-resolution band).
pub fn band_level(r: f32) -> Option<u32> {
    if r < B0 {
        return None;
    }
    Some(
        (1..LEVELS)
            .find(|&l| r < BAND * (1 << l) as f32)
            .unwrap_or(LEVELS),
    )
}

/// The integer texel offsets a band texel's disk can reach below the top
/// level (its radius at most [`BAND`] texels, its centroid within half a
/// texel's diagonal of its centre). At the open top level a radius past
/// [`BAND`] texels (256 px) is clipped to this reach (5.2 texels, 333 px):
/// its light is kept (the spread normalises over the same offsets), its
/// disk is not.
pub fn band_offsets() -> Vec<[i32; 2]> {
    disk_offsets(BAND + 0.5 + HALF_DIAGONAL)
}

/// The band weight of a texel with radius `rho` and centroid `cen` (texel
/// units) at a receiver texel `d + cen` away: the part of the receiver's
/// width the disk's edge passes, clamped to [0, 1].
pub fn band_weight(rho: f32, d: [i32; 2], cen: [f32; 2]) -> f32 {
    let (y, x) = (d[0] as f32 + cen[0], d[1] as f32 + cen[1]);
    (rho - (x * x + y * y).sqrt() + 0.5).clamp(0.0, 1.0)
}

/// The taps of the rings, in units of the ring spacing: (dy, dx, |d|),
/// the centre first, then ring k's 8k taps at angles 2π(j + ½(k mod 2))/8k.
pub fn ring_taps() -> Vec<[f32; 3]> {
    let mut taps = vec![[0.0, 0.0, 0.0]];
    for k in 1..=RINGS {
        let n = 8 * k;
        for j in 0..n {
            let theta = std::f32::consts::TAU * (j as f32 + 0.5 * (k % 2) as f32) / n as f32;
            let k = k as f32;
            taps.push([k * theta.sin(), k * theta.cos(), k]);
        }
    }
    taps
}

/// The integer offsets d with |d| < `reach`, row by row.
fn disk_offsets(reach: f32) -> Vec<[i32; 2]> {
    let n = reach.ceil() as i32;
    let mut out = Vec::new();
    for dy in -n..=n {
        for dx in -n..=n {
            if ((dx * dx + dy * dy) as f32) < reach * reach {
                out.push([dy, dx]);
            }
        }
    }
    out
}

/// How a disk of radius r centred on a source pixel's centre shares its
/// light among the pixels it touches: per offset d (|d| < r_max + ½√2)
/// the part of the pixel square at d the disk covers, normalised over d to
/// sum to 1 (a radius near 0 gives all of it to the source's own pixel),
/// at [`TABLE_STEPS`] + 1 radii from 0 to r_max. The same numbers go to the
/// shaders (a storage buffer) and the reference.
#[derive(Debug, Clone)]
pub struct OverlapTable {
    pub r_max: f32,
    pub offsets: Vec<[i32; 2]>,
    /// `offsets.len()` rows of `TABLE_STEPS + 1` weights.
    pub weights: Vec<f32>,
}

impl OverlapTable {
    pub fn new(r_max: f32) -> OverlapTable {
        let offsets = disk_offsets(r_max + HALF_DIAGONAL);
        let steps = TABLE_STEPS as usize + 1;
        let n = TABLE_SUPERSAMPLES;
        let sub: Vec<f32> = (0..n).map(|i| (i as f32 + 0.5) / n as f32 - 0.5).collect();
        let mut weights = vec![0.0f32; offsets.len() * steps];
        for (k, d) in offsets.iter().enumerate() {
            // Squared distances of the pixel's sub-samples from the source.
            let mut d2: Vec<f32> = sub
                .iter()
                .flat_map(|&uy| {
                    sub.iter().map(move |&ux| {
                        let (y, x) = (d[0] as f32 + uy, d[1] as f32 + ux);
                        x * x + y * y
                    })
                })
                .collect();
            d2.sort_by(f32::total_cmp);
            for i in 0..steps {
                let rho = (i as f32 * r_max / TABLE_STEPS as f32).max(1e-3);
                let inside = d2.partition_point(|&v| v <= rho * rho);
                weights[k * steps + i] = inside as f32 / d2.len() as f32;
            }
        }
        let centre = offsets
            .iter()
            .position(|d| *d == [0, 0])
            .expect("the centre is an offset");
        for i in 0..steps {
            let sum: f32 = (0..offsets.len()).map(|k| weights[k * steps + i]).sum();
            if sum == 0.0 {
                weights[centre * steps + i] = 1.0;
                continue;
            }
            for k in 0..offsets.len() {
                weights[k * steps + i] /= sum;
            }
        }
        OverlapTable {
            r_max,
            offsets,
            weights,
        }
    }

    /// The radius step of `r`: round half to even of r · steps / r_max,
    /// clamped to the table (a larger disk shares as the largest).
    pub fn step(&self, r: f32) -> usize {
        let s = (r * TABLE_STEPS as f32 / self.r_max).round_ties_even();
        s.clamp(0.0, TABLE_STEPS as f32) as usize
    }

    /// The share of offset row `k` for a disk of radius `r`.
    pub fn share(&self, k: usize, r: f32) -> f32 {
        self.weights[k * (TABLE_STEPS as usize + 1) + self.step(r)]
    }
}

/// The largest floor(r²) [`disk_count`] looks up; past it, π r².
pub const DISK_COUNT_MAX: u32 = 65535;

/// N by floor(r²) for r² up to [`DISK_COUNT_MAX`]: the integer offsets d
/// with |d|² ≤ m, for m = 0, 1, …
pub fn disk_counts() -> &'static [u32] {
    static COUNTS: std::sync::OnceLock<Vec<u32>> = std::sync::OnceLock::new();
    COUNTS.get_or_init(|| {
        let m_max = DISK_COUNT_MAX as i64;
        let r = (m_max as f64).sqrt().ceil() as i64;
        let mut histogram = vec![0u32; DISK_COUNT_MAX as usize + 1];
        for dy in -r..=r {
            for dx in -r..=r {
                let m = dx * dx + dy * dy;
                if m <= m_max {
                    histogram[m as usize] += 1;
                }
            }
        }
        let mut total = 0;
        histogram
            .iter()
            .map(|&h| {
                total += h;
                total
            })
            .collect()
    })
}

/// N(r): the pixel centres within distance r of a pixel centre (the same
/// as `reference::disk_pixel_count(2r)`), by table up to r² =
/// [`DISK_COUNT_MAX`], π r² past it.
pub fn disk_count(r: f32) -> f32 {
    let m = (r * r).floor();
    if m <= DISK_COUNT_MAX as f32 {
        return disk_counts()[m as usize] as f32;
    }
    std::f32::consts::PI * r * r
}

/// What the shaders read of the tables, laid end to end as
/// `glsl/fields.glsl` expects: the full-resolution band's overlap table,
/// the rings', [`disk_counts`], and the ring taps (dy, dx, |d|, 0).
pub fn tables() -> Vec<f32> {
    let mut out = OverlapTable::new(B0).weights;
    out.extend(OverlapTable::new(small_radius()).weights);
    out.extend(disk_counts().iter().map(|&n| n as f32));
    for tap in ring_taps() {
        out.extend([tap[0], tap[1], tap[2], 0.0]);
    }
    out
}

/// One G-buffer pixel as the gather sees it.
#[derive(Clone, Copy)]
struct Source {
    color: [f32; 4],
    /// CoC radius, px.
    r: f32,
    /// 1/z (0 on background).
    inv_z: f32,
    surface: bool,
    near: bool,
}

/// A plane of `width × height` values of `C` channels.
struct Plane<const C: usize> {
    width: usize,
    height: usize,
    v: Vec<[f32; C]>,
}

impl<const C: usize> Plane<C> {
    fn new(width: usize, height: usize) -> Self {
        Plane {
            width,
            height,
            v: vec![[0.0; C]; width * height],
        }
    }
    /// The value at (x, y), zero outside.
    fn at(&self, x: i64, y: i64) -> [f32; C] {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return [0.0; C];
        }
        self.v[y as usize * self.width + x as usize]
    }
    fn add(&mut self, x: usize, y: usize, value: [f32; C], scale: f32) {
        let s = &mut self.v[y * self.width + x];
        for (a, b) in s.iter_mut().zip(value) {
            *a += b * scale;
        }
    }
    /// Bilinear at texel coordinates (texel centres at integers), indices
    /// clamped to the plane.
    fn bilinear(&self, x: f32, y: f32) -> [f32; C] {
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let clamp_x = |i: f32| (i as i64).clamp(0, self.width as i64 - 1);
        let clamp_y = |i: f32| (i as i64).clamp(0, self.height as i64 - 1);
        let (xa, xb, ya, yb) = (
            clamp_x(x0),
            clamp_x(x0 + 1.0),
            clamp_y(y0),
            clamp_y(y0 + 1.0),
        );
        let (a, b, c, d) = (
            self.at(xa, ya),
            self.at(xb, ya),
            self.at(xa, yb),
            self.at(xb, yb),
        );
        let mut out = [0.0; C];
        for i in 0..C {
            let top = a[i] + (b[i] - a[i]) * fx;
            let bottom = c[i] + (d[i] - c[i]) * fx;
            out[i] = top + (bottom - top) * fy;
        }
        out
    }
}

/// The bands of one set of surfaces (`member`) at every G-buffer pixel:
/// premultiplied colour (4) and the spread weight (alpha of the field).
fn bands(
    sources: &[Source],
    width: usize,
    height: usize,
    member: impl Fn(&Source) -> bool,
    table: &OverlapTable,
) -> Plane<5> {
    let mut out = Plane::<5>::new(width, height);
    let at = |x: i64, y: i64| -> Option<&Source> {
        if x < 0 || y < 0 || x >= width as i64 || y >= height as i64 {
            return None;
        }
        Some(&sources[y as usize * width + x as usize])
    };
    // Full resolution: the sources under B0 px, by the overlap table.
    for y in 0..height {
        for x in 0..width {
            for (k, d) in table.offsets.iter().enumerate() {
                let Some(p) = at(x as i64 + d[1] as i64, y as i64 + d[0] as i64) else {
                    continue;
                };
                if !member(p) || p.r >= B0 {
                    continue;
                }
                let share = table.share(k, p.r);
                let c = p.color;
                out.add(x, y, [c[0], c[1], c[2], c[3], 1.0], share);
            }
        }
    }
    let offsets = band_offsets();
    for level in 1..=LEVELS {
        let t = 1usize << level;
        let (tw, th) = (width.div_ceil(t), height.div_ceil(t));
        // Per texel: mean colour (4) and mean count over its t² pixels,
        // the RMS radius in texels, the centroid (y, x) in texels.
        let mut mean = Plane::<5>::new(tw, th);
        let mut shape = Plane::<3>::new(tw, th);
        for ty in 0..th {
            for tx in 0..tw {
                let (mut sum, mut n, mut r2, mut cy, mut cx) = ([0.0f32; 4], 0.0f32, 0.0, 0.0, 0.0);
                for iy in 0..t {
                    for ix in 0..t {
                        let Some(p) = at((tx * t + ix) as i64, (ty * t + iy) as i64) else {
                            continue;
                        };
                        if !member(p) || band_level(p.r) != Some(level) {
                            continue;
                        }
                        for (s, c) in sum.iter_mut().zip(p.color) {
                            *s += c;
                        }
                        n += 1.0;
                        r2 += p.r * p.r;
                        cy += (iy as f32 + 0.5) / t as f32 - 0.5;
                        cx += (ix as f32 + 0.5) / t as f32 - 0.5;
                    }
                }
                if n == 0.0 {
                    continue;
                }
                let cells = (t * t) as f32;
                let rho = (r2 / n).sqrt() / t as f32;
                let cen = [cy / n, cx / n];
                let spread: f32 = offsets.iter().map(|&d| band_weight(rho, d, cen)).sum();
                let i = ty * tw + tx;
                mean.v[i] = [sum[0], sum[1], sum[2], sum[3], n].map(|v| v / cells / spread);
                shape.v[i] = [rho, cen[0], cen[1]];
            }
        }
        let mut spread = Plane::<5>::new(tw, th);
        for ty in 0..th {
            for tx in 0..tw {
                for &d in &offsets {
                    let (sx, sy) = (tx as i64 + d[1] as i64, ty as i64 + d[0] as i64);
                    let m = mean.at(sx, sy);
                    if m[4] == 0.0 {
                        continue;
                    }
                    let s = shape.at(sx, sy);
                    let w = band_weight(s[0], d, [s[1], s[2]]);
                    spread.add(tx, ty, m, w);
                }
            }
        }
        for y in 0..height {
            for x in 0..width {
                let u = (x as f32 + 0.5) / t as f32 - 0.5;
                let v = (y as f32 + 0.5) / t as f32 - 0.5;
                out.add(x, y, spread.bilinear(u, v), 1.0);
            }
        }
    }
    out
}

/// The far field's mip: per pixel (c·far (4), far, r·far, (1/z)·far), each
/// level the mean of the 2×2 below it (zero past the edge).
fn far_mip(sources: &[Source], width: usize, height: usize) -> Vec<Plane<7>> {
    let mut base = Plane::<7>::new(width, height);
    for (v, p) in base.v.iter_mut().zip(sources) {
        if !p.near {
            let c = p.color;
            *v = [c[0], c[1], c[2], c[3], 1.0, p.r, p.inv_z];
        }
    }
    let mut levels = vec![base];
    for _ in 1..=LEVELS {
        let below = levels.last().expect("level 0");
        let (w, h) = (below.width.div_ceil(2), below.height.div_ceil(2));
        let mut next = Plane::<7>::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let mut s = [0.0f32; 7];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let v = below.at((2 * x + dx) as i64, (2 * y + dy) as i64);
                    for (a, b) in s.iter_mut().zip(v) {
                        *a += b;
                    }
                }
                next.v[y * w + x] = s.map(|v| 0.25 * v);
            }
        }
        levels.push(next);
    }
    levels
}

/// The CPU reference of the bounded two-field gather (module docs) on a
/// host G-buffer: the output image, the guard band cropped.
pub fn reference(gbuffer: &HostGBuffer, camera: &Camera) -> LinearImage {
    let (width, height) = (gbuffer.width as usize, gbuffer.height as usize);
    let focus = camera.focus_distance;
    let sources: Vec<Source> = gbuffer
        .color
        .iter()
        .zip(&gbuffer.eye)
        .map(|(c, e)| {
            let z = e[2];
            let surface = z.is_finite();
            Source {
                color: *c,
                r: 0.5 * camera.coc_px(z),
                inv_z: if surface { 1.0 / z } else { 0.0 },
                surface,
                near: surface && z < focus,
            }
        })
        .collect();
    let band_table = OverlapTable::new(B0);
    let ring_table = OverlapTable::new(small_radius());
    let near = bands(&sources, width, height, |p| p.near, &band_table);
    let all = bands(&sources, width, height, |p| p.surface, &band_table);
    let mip = far_mip(&sources, width, height);
    let taps = ring_taps();
    let g = gbuffer.guard as usize;
    let mut out = LinearImage::new(camera.width, camera.height, [0.0; 4]);
    for y in 0..camera.height as usize {
        for x in 0..camera.width as usize {
            let (qx, qy) = (x + g, y + g);
            let q = sources[qy * width + qx];
            let (front, back) = if q.surface {
                // The near-field bands, then the taps in front (the
                // shader's order of additions).
                let (ring, back) = rings(&mip, &ring_table, &taps, q, qx, qy);
                let mut front = near.at(qx as i64, qy as i64);
                for (a, b) in front.iter_mut().zip(ring) {
                    *a += b;
                }
                (front, back)
            } else {
                let c = q.color;
                (all.at(qx as i64, qy as i64), [c[0], c[1], c[2], c[3], 1.0])
            };
            out.set(x as u32, y as u32, composite(front, back));
        }
    }
    out
}

/// Front (premultiplied colour, weight) as alpha over the normalised back.
pub fn composite(front: [f32; 5], back: [f32; 5]) -> [f32; 4] {
    let alpha = if back[4] > 1e-9 {
        front[4].clamp(0.0, 1.0)
    } else {
        1.0
    };
    let (wf, wb) = (front[4].max(1e-12), back[4].max(1e-12));
    [0, 1, 2, 3].map(|i| front[i] / wf * alpha + back[i] / wb * (1.0 - alpha))
}

/// The rings of surface receiver `q` at G-buffer pixel (qx, qy): the far
/// field's taps in front of it and behind it, each (colour sums, weight).
fn rings(
    mip: &[Plane<7>],
    table: &OverlapTable,
    taps: &[[f32; 3]],
    q: Source,
    qx: usize,
    qy: usize,
) -> ([f32; 5], [f32; 5]) {
    let (mut front, mut back) = ([0.0f32; 5], [0.0f32; 5]);
    let add = |sums: &mut [f32; 5], c: [f32; 4], w: f32| {
        for i in 0..4 {
            sums[i] += w * c[i];
        }
        sums[4] += w;
    };
    if q.r < small_radius() {
        for (k, d) in table.offsets.iter().enumerate() {
            let v = mip[0].at(qx as i64 + d[1] as i64, qy as i64 + d[0] as i64);
            if v[4] == 0.0 {
                continue;
            }
            let c = [v[0], v[1], v[2], v[3]];
            if v[6] > q.inv_z {
                add(&mut front, c, table.share(k, v[5]));
            } else {
                add(&mut back, c, table.share(k, v[5].min(q.r)));
            }
        }
        return (front, back);
    }
    let spacing = q.r / small_radius();
    let area = std::f32::consts::PI * q.r * q.r / taps.len() as f32;
    let level = spacing
        .max(1.0)
        .log2()
        .round_ties_even()
        .clamp(0.0, LEVELS as f32) as usize;
    let t = (1usize << level) as f32;
    for tap in taps {
        let (py, px) = (qy as f32 + tap[0] * spacing, qx as f32 + tap[1] * spacing);
        let v = mip[level].bilinear((px + 0.5) / t - 0.5, (py + 0.5) / t - 0.5);
        let n = v[4];
        if n <= 1e-6 {
            continue;
        }
        let c = [v[0] / n, v[1] / n, v[2] / n, v[3] / n];
        let (r, inv_z) = (v[5] / n, v[6] / n);
        let rb = r.min(q.r);
        let dist = tap[2] * spacing;
        let (cover, cover_back) = if tap[2] == 0.0 {
            let half = 0.5 * spacing;
            let disk = |r: f32| std::f32::consts::PI * r.min(half).powi(2) / area;
            (disk(r), disk(rb))
        } else {
            let edge = |r: f32| ((r - dist) / spacing + 0.5).clamp(0.0, 1.0);
            (edge(r), edge(rb))
        };
        if inv_z > q.inv_z {
            add(&mut front, c, area * n * cover / disk_count(r));
        } else {
            add(&mut back, c, area * n * cover_back / disk_count(rb));
        }
    }
    (front, back)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_overlap_table_shares_all_of_a_disk_and_keeps_a_point_in_its_pixel() {
        let t = OverlapTable::new(B0);
        let rows = t.offsets.len();
        for i in 0..=TABLE_STEPS as usize {
            let sum: f32 = (0..rows)
                .map(|k| t.weights[k * (TABLE_STEPS as usize + 1) + i])
                .sum();
            assert!((sum - 1.0).abs() < 1e-5, "step {i}: {sum}");
        }
        let centre = t.offsets.iter().position(|d| *d == [0, 0]).unwrap();
        assert_eq!(t.share(centre, 0.0), 1.0);
        assert_eq!(t.share(centre, 0.4), 1.0);
        // A disk of radius 1.5 reaches its 4 neighbours by a fifth-ish
        // each and keeps most in its own pixel; symmetric in d.
        let at = |d: [i32; 2]| t.share(t.offsets.iter().position(|o| *o == d).unwrap(), 1.5);
        assert!(at([0, 0]) > at([0, 1]) && at([0, 1]) > at([1, 1]));
        assert_eq!(at([0, 1]), at([1, 0]));
        assert_eq!(at([0, 1]), at([0, -1]));
        // |d| < 3.7072: 45 offsets for B0 = 3, 57 for the rings' 3.5.
        assert_eq!(rows, 45);
        assert_eq!(OverlapTable::new(small_radius()).offsets.len(), 57);
    }

    #[test]
    fn band_levels_ring_taps_and_disk_counts() {
        assert_eq!(band_level(2.9), None);
        assert_eq!(band_level(3.0), Some(1));
        assert_eq!(band_level(7.9), Some(1));
        assert_eq!(band_level(8.0), Some(2));
        assert_eq!(band_level(127.9), Some(5));
        assert_eq!(band_level(128.0), Some(6));
        assert_eq!(band_level(1e6), Some(6));
        assert_eq!(ring_taps().len(), 49);
        for r in [0.0, 0.4, 1.0, 1.5, 2.9, 17.3, 100.0, 255.9] {
            assert_eq!(
                disk_count(r),
                crate::reference::disk_pixel_count(2.0 * r) as f32,
                "r = {r}"
            );
        }
        assert_eq!(band_offsets().len(), 89);
    }
}
