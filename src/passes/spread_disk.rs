//! The layered method's spreading disk on the CPU (DESIGN §6): the weights
//! `glsl/layered_spread.comp` gives the pixels around a fragment, and the
//! radius it spreads a CoC with (looked up by `glsl/layered_prepare.comp`
//! in the table built here).
//!
//! Why not the CoC's own radius: the G-buffer's pixel is already the mean
//! of its K×K samples (a box filter), and the spread's anti-aliased disk
//! gives each pixel its overlap with the disk (a second box), so spreading
//! with the CoC's radius blurs by a pixel box more than the lens does (the
//! accumulation reference is box ⊗ lens disk, once), and leaves a CoC under
//! a pixel unblurred. The spread radius is the one whose disk, as the
//! spread draws it, has the lens disk's second moment: r²/4 per axis for a
//! CoC of radius r. See docs/ARCHITECTURE.md ("The spread radius").

use std::sync::OnceLock;

/// Table entries per pixel of CoC radius.
pub const TABLE_PER_PX: u32 = 16;
/// CoC radius (px) of the table's last entry; beyond it the spread radius
/// is √(r² − excess) with the excess of the last entry (the box's share,
/// about 1/3 px²).
pub const TABLE_RADIUS_PX: u32 = 16;
/// Entries of the table.
pub const TABLE_ENTRIES: usize = (TABLE_PER_PX * TABLE_RADIUS_PX) as usize + 1;

/// Row `dy` (from the disk's centre, px) of a disk of radius `r` as the
/// spread draws it: the part of the row's height inside the disk's
/// vertical extent, and the disk's half-width there (its chord halfway
/// through that part), at least half a pixel. Mirrors `disk_row` in
/// `glsl/layered_spread.comp`.
pub fn disk_row(r: f32, dy: i32) -> (f32, f32) {
    let ady = dy.unsigned_abs() as f32;
    let height = (r + 0.5 - ady).clamp(0.0, 1.0);
    let y = if height < 1.0 {
        0.5 * (ady - 0.5 + r)
    } else {
        ady
    };
    (height, (r * r - y * y).max(0.0).sqrt().max(0.5))
}

/// Rows above and below the centre row that a disk of radius `r` reaches
/// with a height above zero. Mirrors `glsl/layered_spread.comp`.
pub fn disk_rows(r: f32) -> i32 {
    ((r - 0.5).ceil() as i32).max(0)
}

/// The share of a fragment's color each pixel receives when it spreads
/// with radius `r` from a pixel centre: (dx, dy, weight), the weights
/// summing to 1. Per row, each pixel takes its overlap with the row's span
/// times the row's height; the sum of those normalises.
pub fn weights(r: f32) -> Vec<(i32, i32, f64)> {
    let rows = disk_rows(r);
    let mut area = 0.0f32;
    for dy in -rows..=rows {
        let (height, h) = disk_row(r, dy);
        area += 2.0 * h * height;
    }
    let mut out = Vec::new();
    for dy in -rows..=rows {
        let (height, h) = disk_row(r, dy);
        let row = height / area;
        let (a, b) = (0.5 - h, 0.5 + h);
        let (x0, x1) = (a.floor() as i32, b.floor() as i32);
        for x in x0..=x1 {
            let overlap = b.min(x as f32 + 1.0) - a.max(x as f32);
            if overlap > 0.0 && row > 0.0 {
                out.push((x, dy, row as f64 * overlap as f64));
            }
        }
    }
    out
}

/// Second moment per axis (px²) of the disk the spread draws with radius
/// `r`: the mean of the two axes' variances.
pub fn drawn_variance(r: f32) -> f64 {
    let w = weights(r);
    let total: f64 = w.iter().map(|&(_, _, w)| w).sum();
    w.iter()
        .map(|&(x, y, w)| w * (x * x + y * y) as f64)
        .sum::<f64>()
        / (2.0 * total)
}

/// The lens's blur per axis (px²) for a CoC of radius `coc_radius_px`: a
/// uniform disk's second moment, r²/4.
pub fn lens_variance(coc_radius_px: f32) -> f64 {
    let r = coc_radius_px as f64;
    r * r / 4.0
}

/// The spread radius whose drawn disk has the lens disk's variance for CoC
/// radius `coc_radius_px`: bisection (the drawn variance grows with the
/// radius: 0 up to half a pixel, one pixel alone, then the box's 1/12 and
/// the row steps above r²/4).
fn matched_radius(coc_radius_px: f32) -> f32 {
    let target = lens_variance(coc_radius_px);
    let (mut lo, mut hi) = (0.5f32, coc_radius_px.max(0.5) + 0.5);
    if target <= 0.0 {
        return lo;
    }
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if drawn_variance(mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The table `glsl/layered_prepare.comp` reads (binding 8), as 32-bit
/// words: the number of entries, entries per pixel (f32), the excess (f32,
/// px²) beyond the last, a pad, then the spread radius (f32, px) for CoC
/// radii 0, 1/16, ... 16 px.
pub fn radius_table_words() -> &'static [u32] {
    static TABLE: OnceLock<Vec<u32>> = OnceLock::new();
    TABLE.get_or_init(|| {
        let radii: Vec<f32> = (0..TABLE_ENTRIES)
            .map(|i| matched_radius(i as f32 / TABLE_PER_PX as f32))
            .collect();
        let last = radii[TABLE_ENTRIES - 1];
        let excess = (TABLE_RADIUS_PX * TABLE_RADIUS_PX) as f32 - last * last;
        let mut words = vec![
            TABLE_ENTRIES as u32,
            (TABLE_PER_PX as f32).to_bits(),
            excess.to_bits(),
            0,
        ];
        words.extend(radii.iter().map(|r| r.to_bits()));
        words
    })
}

/// The radius (px) the spread draws a fragment of CoC diameter `coc_px`
/// with: the table, interpolated linearly. Mirrors `spread_radius_px` in
/// `glsl/layered_prepare.comp`.
pub fn spread_radius_px(coc_px: f32) -> f32 {
    let words = radius_table_words();
    let entries = words[0] as usize;
    let per_px = f32::from_bits(words[1]);
    let excess = f32::from_bits(words[2]);
    let radius = |i: usize| f32::from_bits(words[4 + i]);
    let r = 0.5 * coc_px.abs();
    let u = r * per_px;
    if u < (entries - 1) as f32 {
        let i = u as usize;
        let f = u - i as f32;
        radius(i) + (radius(i + 1) - radius(i)) * f
    } else {
        (r * r - excess).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_sum_to_one_and_a_small_disk_is_one_pixel() {
        for r in [0.0f32, 0.3, 0.5, 0.55, 0.8, 1.0, 1.7, 3.2, 9.9, 40.0] {
            let sum: f64 = weights(r).iter().map(|w| w.2).sum();
            assert!((sum - 1.0).abs() < 1e-5, "r {r}: weights sum to {sum}");
        }
        assert_eq!(weights(0.5), vec![(0, 0, 1.0)]);
        assert_eq!(drawn_variance(0.5), 0.0);
    }

    #[test]
    fn the_drawn_disk_has_the_lens_disks_variance() {
        // The table's entries match to the bisection's precision; between
        // them and beyond the table, within 2 % of r²/4 (and 0.01 px² for
        // small CoCs).
        for i in 0..=400 {
            let coc = i as f32 * 0.1;
            let drawn = drawn_variance(spread_radius_px(coc));
            let lens = lens_variance(0.5 * coc);
            assert!(
                (drawn - lens).abs() <= 0.01 + 0.02 * lens,
                "CoC {coc} px: the spread's variance {drawn:.4}, the lens's {lens:.4}"
            );
        }
        // Without the correction, a CoC of 2 px blurs by half as much
        // again (the test can fail).
        let plain = drawn_variance(1.0);
        assert!(plain > 1.4 * lens_variance(1.0), "{plain}");
    }

    #[test]
    fn the_spread_radius_grows_with_the_coc_and_stays_below_it_past_a_pixel() {
        let mut last = 0.0;
        for i in 0..=600 {
            let coc = i as f32 * 0.1;
            let r = spread_radius_px(coc);
            assert!(r >= last, "CoC {coc}: radius {r} after {last}");
            if coc >= 2.0 {
                assert!(r < 0.5 * coc, "CoC {coc}: radius {r}");
            }
            last = r;
        }
        assert_eq!(spread_radius_px(0.0), 0.5);
    }
}
