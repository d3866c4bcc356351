//! The lens sample and bin tables: the Shirley–Chiu concentric map between
//! the square [−1, 1]² and the lens disk, the ray distribution buffer's lens
//! cells (DESIGN §5) and the stratified lens samples of the accumulation
//! reference.

use glam::Vec2;

/// Shirley–Chiu concentric map: the square [−1, 1]² onto the unit disk,
/// area-preserving (equal areas of the square map to equal areas of the
/// disk) and continuous, so stratified square samples stay stratified.
pub fn concentric_disk(a: Vec2) -> Vec2 {
    if a == Vec2::ZERO {
        return Vec2::ZERO;
    }
    let quarter = std::f32::consts::FRAC_PI_4;
    let (r, theta) = if a.x.abs() > a.y.abs() {
        (a.x, quarter * (a.y / a.x))
    } else {
        (a.y, 2.0 * quarter - quarter * (a.x / a.y))
    };
    r * Vec2::new(theta.cos(), theta.sin())
}

/// The inverse of [`concentric_disk`]: a point of the unit disk back to the
/// square [−1, 1]².
pub fn concentric_square(u: Vec2) -> Vec2 {
    let r = u.length();
    if r == 0.0 {
        return Vec2::ZERO;
    }
    let four_over_pi = 4.0 / std::f32::consts::PI;
    if u.x.abs() >= u.y.abs() {
        let s = if u.x >= 0.0 { 1.0 } else { -1.0 };
        let theta = (s * u.y).atan2(s * u.x);
        Vec2::new(s * r, s * r * theta * four_over_pi)
    } else {
        let s = if u.y >= 0.0 { 1.0 } else { -1.0 };
        let theta = (s * u.y).atan2(s * u.x);
        Vec2::new(
            s * r * (std::f32::consts::FRAC_PI_2 - theta) * four_over_pi,
            s * r,
        )
    }
}

/// The ray distribution buffer's lens bins (DESIGN §5): bin b = j·N + i is
/// cell (i, j) of an N×N grid on [−1, 1]² (half-open cells), and its lens
/// position u_b is the concentric map of the cell's centre.
pub fn rdb_lens_table(n: u32) -> Vec<Vec2> {
    (0..n * n)
        .map(|b| {
            let (i, j) = ((b % n) as f32, (b / n) as f32);
            let cell = |k: f32| -1.0 + (2.0 * k + 1.0) / n as f32;
            concentric_disk(Vec2::new(cell(i), cell(j)))
        })
        .collect()
}

/// The bin of an N×N ray distribution buffer whose lens cell holds the
/// normalised lens position `u`.
pub fn rdb_bin(u: Vec2, n: u32) -> u32 {
    let a = concentric_square(u);
    square_cell(a.y, n) * n + square_cell(a.x, n)
}

/// Which of `n` equal half-open cells of [−1, 1] holds `v` (clamped to the
/// first and last): the RDB's lens cells, an aperture image's pixels.
pub fn square_cell(v: f32, n: u32) -> u32 {
    (((v + 1.0) * 0.5 * n as f32).floor() as i64).clamp(0, n as i64 - 1) as u32
}

/// `count` offsets of a pixel's one sample from its centre, in pixels, in
/// [−½, ½)²: the R2 sequence (frac(½ + i·(1/g, 1/g²)), g the plastic
/// number) less ½, a low-discrepancy set for every count, the first at the
/// centre. At K = 1 lens position i of [`lens_samples`] moves the pixel's
/// sample by offset i, so that S lens positions anti-alias the image as
/// S samples of the pixel would (Haeberli & Akeley's jittered
/// accumulation; `GBuffer::record`).
pub fn pixel_jitters(count: u32) -> Vec<Vec2> {
    let g = 1.324_717_957_244_746_f64;
    let (a1, a2) = (1.0 / g, 1.0 / (g * g));
    (0..count)
        .map(|i| {
            let x = (0.5 + i as f64 * a1).fract() - 0.5;
            let y = (0.5 + i as f64 * a2).fract() - 0.5;
            Vec2::new(x as f32, y as f32)
        })
        .collect()
}

/// `count` normalised lens positions stratified over the unit disk: a
/// Fibonacci lattice on the square ((i + ½)/S, frac(i/φ + ½)), mapped by
/// [`concentric_disk`]. Deterministic; `lens_samples(1)` is the lens centre
/// (for S > 1 no sample need be).
pub fn lens_samples(count: u32) -> Vec<Vec2> {
    let inv_phi = (5f64.sqrt() - 1.0) / 2.0;
    (0..count)
        .map(|i| {
            let x = (i as f64 + 0.5) / count as f64;
            let y = (i as f64 * inv_phi + 0.5).fract();
            concentric_disk(Vec2::new(2.0 * x as f32 - 1.0, 2.0 * y as f32 - 1.0))
        })
        .collect()
}
