//! The bokeh scene of `pointlens synth --lights N`: a card in focus among
//! lights brighter than white, the scene a shaped aperture shows (README,
//! "The aperture's shape"). The card (three points in four, on a grid) is
//! 0.6 × 0.4 at z = 0 facing +z, a checker of 5 cm squares in two colours
//! within white; the lights are 48 spheres of 2.5 cm (36 behind the card, 2.5 to
//! 4.5 away, and 12 of 1 cm in front of it, 0.45 to 0.75 towards the
//! camera) of four hues, 50 times white behind and 10 in front. Seen from
//! (0, 0, 1.2) focused at 1.2, the card is sharp and the lights are bokeh.
//!
//! The file is a binary little-endian PLY of float positions and float
//! colours, sRGB-encoded as 8-bit ones are, above 1 for the lights (the
//! sRGB curve extended: 5.33 is 50 times white). Point `i` is a function
//! of `i` and N alone, from the synthetic scene's SplitMix64 stream (`synth::draw`).

use std::path::Path;

use glam::Vec3;

use crate::error::Result;
use crate::image_io::linear_to_srgb_extended;

/// The lights: 36 behind the card, then 12 in front of it.
const LIGHTS: u64 = 48;
const LIGHTS_BEHIND: u64 = 36;

/// The lights' hues (linear, brightest channel 1): warm white, amber,
/// cool blue, rose.
const HUES: [Vec3; 4] = [
    Vec3::new(1.0, 0.75, 0.45),
    Vec3::new(1.0, 0.5, 0.15),
    Vec3::new(0.5, 0.75, 1.0),
    Vec3::new(1.0, 0.35, 0.6),
];

/// Where the lights' draws start in the stream (after any scene's points).
const LIGHT_DRAWS: u64 = 1 << 48;

/// Draw `k` of light `b`'s own three.
fn light_draw(b: u64, k: u64) -> f32 {
    super::draw(LIGHT_DRAWS + 3 * b + k)
}

/// Light `b`'s centre, radius and linear colour.
fn light(b: u64) -> (Vec3, f32, Vec3) {
    let (u, v, w) = (light_draw(b, 0), light_draw(b, 1), light_draw(b, 2));
    let hue = HUES[(b % HUES.len() as u64) as usize];
    if b < LIGHTS_BEHIND {
        let centre = Vec3::new(6.0 * u - 3.0, 3.2 * v - 1.4, -2.5 - 2.0 * w);
        (centre, 0.025, 50.0 * hue)
    } else {
        let centre = Vec3::new(0.7 * u - 0.35, 0.4 * v - 0.2, 0.45 + 0.3 * w);
        (centre, 0.01, 10.0 * hue)
    }
}

/// Point `i` of a scene of `count` points: its position and linear colour.
pub fn point(i: u64, count: u64) -> (Vec3, Vec3) {
    if i % 4 != 3 || count < 4 {
        // A grid of 3:2 cells over the card, row by row from the bottom:
        // no gap for the lights behind to shine through.
        let (j, cards) = (i - i / 4, count - count / 4);
        let columns = (cards as f64 * 1.5).sqrt().ceil() as u64;
        let rows = cards.div_ceil(columns);
        let (x, y) = ((j % columns) as f32 + 0.5, (j / columns) as f32 + 0.5);
        let p = Vec3::new(
            0.6 * x / columns as f32 - 0.3,
            0.4 * y / rows as f32 - 0.2,
            0.0,
        );
        let cell = |v: f32| (v / 0.05).floor() as i32;
        let color = match (cell(p.x) + cell(p.y)).rem_euclid(2) {
            0 => Vec3::new(0.6, 0.55, 0.5),
            _ => Vec3::new(0.05, 0.08, 0.15),
        };
        return (p, color);
    }
    let (a, b) = (super::draw(2 * i), super::draw(2 * i + 1));
    let (centre, radius, color) = light(i / 4 % LIGHTS);
    // Uniform on the sphere: z uniform in [−1, 1], angle uniform.
    let z = 2.0 * a - 1.0;
    let phi = std::f32::consts::TAU * b;
    let r = (1.0 - z * z).sqrt();
    (
        centre + radius * Vec3::new(r * phi.cos(), r * phi.sin(), z),
        color,
    )
}

/// Bytes of one vertex record of the file: x, y, z, red, green, blue, all
/// float.
pub const RECORD_BYTES: u64 = 24;

/// The PLY header of a scene of `count` points.
fn header(count: u64) -> String {
    format!(
        "ply\nformat binary_little_endian 1.0\n\
         comment pointlens synth --lights: a card in focus at z = 0 among 48 lights\n\
         comment colours are sRGB-encoded; above 1 brighter than white\n\
         element vertex {count}\n\
         property float x\nproperty float y\nproperty float z\n\
         property float red\nproperty float green\nproperty float blue\n\
         end_header\n"
    )
}

/// Writes the scene of `count` points to `path`, atomically, a chunk of
/// [`super::CHUNK_POINTS`] at a time, telling `progress` the points
/// written.
pub fn write(path: &Path, count: u64, progress: &mut dyn FnMut(u64)) -> Result<()> {
    let record = |i| {
        let (p, c) = point(i, count);
        let c = c.to_array().map(linear_to_srgb_extended);
        [p.x, p.y, p.z, c[0], c[1], c[2]]
    };
    super::write_float_records(path, &header(count), count, record, progress)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image_io::srgb_to_linear;

    #[test]
    fn the_encoding_is_the_readers_inverse_above_white_too() {
        for c in [0.0, 0.002, 0.2, 0.5, 1.0, 2.0, 40.0, 120.0] {
            let back = srgb_to_linear(linear_to_srgb_extended(c));
            assert!((back - c).abs() <= 1e-5 * c.max(1.0), "{c} → {back}");
        }
        let fifty = linear_to_srgb_extended(50.0);
        assert!((fifty - 5.33).abs() < 0.01, "{fifty}");
    }

    #[test]
    fn a_quarter_of_the_points_are_the_lights_brighter_than_white() {
        let count = 4000;
        let bright = (0..count)
            .filter(|&i| point(i, count).1.max_element() > 1.0)
            .count();
        assert_eq!(bright, 1000);
        // Light k of the 1,000 light points is light k mod 48, 36 of which
        // are behind the card: 20 × 36 + 36.
        let behind = (0..count)
            .map(|i| point(i, count))
            .filter(|(p, c)| c.max_element() > 1.0 && p.z < -2.0)
            .count();
        assert_eq!(behind, 756);
    }
}
