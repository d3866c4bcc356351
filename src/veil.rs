//! Points too near the lens for a G-buffer: the veil (docs/ARCHITECTURE.md,
//! "Every camera renders").
//!
//! A point in front of the focus plane whose CoC is wider than the guard
//! band can hold ([`Camera::veil_coc_px`]) cannot take part in a blurred
//! G-buffer: its square would hide everything behind it from the pinhole
//! view, and its blur would need a band wider than the frame. Through a
//! thin lens (DESIGN §2) output pixel q sees such a point (pinhole
//! position p, CoC c, square of side s, pixels) through the lens positions
//! u with |q − p − sign·(c/2)·u|∞ ≤ s/2: an axis-aligned square of the
//! lens, centred on u_q = sign·(q − p)/(c/2), of half-side s/c. The veil
//! divides the lens into [`VEIL_CELLS`]² equal square cells (those whose
//! centre lies in the unit disk: [`VeilGrid`]) and, per output pixel,
//! gives each cell the nearest veil point whose lens square holds the
//! cell's centre — a z-buffer per lens cell, as `accum` would find with one
//! lens sample per cell. The pixel is then the mean over the cells: a
//! covered cell's point color, an uncovered cell's the method's image. So
//! points behind one another along a ray through the lens hide one
//! another (a surface at the lens is one occluder, not a stack of
//! independent ones), and a speck covers the fraction of the lens it
//! should, to the cell.
//!
//! `accum` needs no veil for the points it draws (each lens sample's own
//! projection places them); it veils only those nearer than its depth
//! range's near plane, which no raster can draw.

use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3, Vec4};

use crate::camera::Camera;
use crate::gbuffer::{clip_range, depth_range_with};
use crate::passes::VeilRule;
use crate::tree::Splat;

/// The relative margin over the near plane within which `accum` veils a
/// splat rather than drawing it ([`VeilRule::BeyondNear`]).
pub const NEAR_MARGIN: f32 = 1e-3;

/// Lens cells per axis of the veil's grid (`glsl/output_convert.comp`
/// mirrors it): 16 × 16 cells, 208 of them in the lens disk.
pub const VEIL_CELLS: u32 = 16;

/// One point of the veil as the output pass reads it
/// (`glsl/output_convert.comp`, `VeilSplat`): 32 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct VeilSplat {
    /// The point's pinhole position, output pixels (pixel centres at +0.5).
    pub centre_px: [f32; 2],
    /// sign(z − S) · 2 / c: output pixels → normalised lens position
    /// (u_q = `lens_per_px` · (q − p)).
    pub lens_per_px: f32,
    /// Half the side of its lens square: s / c.
    pub half_side: f32,
    /// Its linear color and coverage (1).
    pub color: [f32; 4],
}

/// The veil of one frame: its points nearest first, and how many splats
/// left the G-buffer for it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Veil {
    pub splats_in_view: Vec<VeilSplat>,
    /// Splats taken out of the G-buffer (in `splats_in_view`, or dropped
    /// where no pixel of the frame sees them through the lens).
    pub splats: u64,
}

/// The lens cells of the veil: for each row of [`VEIL_CELLS`] cells, the
/// bit mask of those whose centre lies in the unit disk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VeilGrid {
    pub rows: [u32; VEIL_CELLS as usize],
    pub cells: u32,
}

impl VeilGrid {
    pub fn new() -> VeilGrid {
        let n = VEIL_CELLS as usize;
        let mut rows = [0u32; VEIL_CELLS as usize];
        for (j, row) in rows.iter_mut().enumerate() {
            for i in 0..n {
                let (x, y) = (cell_centre(i as u32), cell_centre(j as u32));
                if x * x + y * y <= 1.0 {
                    *row |= 1 << i;
                }
            }
        }
        VeilGrid {
            rows,
            cells: rows.iter().map(|r| r.count_ones()).sum(),
        }
    }
}

impl Default for VeilGrid {
    fn default() -> Self {
        VeilGrid::new()
    }
}

/// The centre of cell `i` of a row or column, in [−1, 1].
fn cell_centre(i: u32) -> f32 {
    -1.0 + (2.0 * i as f32 + 1.0) / VEIL_CELLS as f32
}

/// The cells [lo, hi] of one axis whose centres lie in [a − h, a + h]
/// (empty when lo > hi). The output pass makes the same arithmetic.
fn cell_range(a: f32, h: f32) -> (i32, i32) {
    let n = VEIL_CELLS as f32;
    let lo = ((a - h + 1.0) * n / 2.0 - 0.5).ceil().max(0.0);
    let hi = ((a + h + 1.0) * n / 2.0 - 0.5).floor().min(n - 1.0);
    (lo as i32, hi as i32)
}

impl Veil {
    /// Whether the veil changes no pixel.
    pub fn is_empty(&self) -> bool {
        self.splats_in_view.is_empty()
    }

    /// The veiled value of output pixel (x, y) whose method value is
    /// `under` (linear RGBA): the CPU mirror of the output pass.
    pub fn apply(&self, grid: &VeilGrid, x: u32, y: u32, under: Vec4) -> Vec4 {
        let q = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
        let mut marked = [0u32; VEIL_CELLS as usize];
        let (mut count, mut over) = (0u32, Vec4::ZERO);
        for v in &self.splats_in_view {
            let u = v.lens_per_px * (q - Vec2::from(v.centre_px));
            let (i0, i1) = cell_range(u.x, v.half_side);
            let (j0, j1) = cell_range(u.y, v.half_side);
            if i0 > i1 || j0 > j1 {
                continue;
            }
            let span = (u32::MAX >> (31 - (i1 - i0) as u32)) << i0;
            for j in j0..=j1 {
                let new = span & grid.rows[j as usize] & !marked[j as usize];
                marked[j as usize] |= new;
                count += new.count_ones();
                over += new.count_ones() as f32 * Vec4::from(v.color);
            }
            if count == grid.cells {
                break;
            }
        }
        let cells = grid.cells as f32;
        over / cells + ((grid.cells - count) as f32 / cells) * under
    }
}

/// Splits a frame's `splats` into those its G-buffer draws and its veil,
/// under `rule`. `splat_px`: `--splat-px` (every splat that wide in
/// pixels), else each splat's sphere projected. `color_scale`: the linear
/// colour of code 65535 ([`crate::tree::SplatTree::color_scale`]). Keeps
/// the order of the splats drawn.
pub fn split(
    camera: &Camera,
    splats: Vec<Splat>,
    rule: VeilRule,
    splat_px: Option<f32>,
    color_scale: f32,
) -> (Vec<Splat>, Veil) {
    if rule == VeilRule::None || camera.aperture_radius <= 0.0 {
        return (splats, Veil::default());
    }
    let eye_from_world = camera.eye_from_world_transform();
    let near = match rule {
        VeilRule::BeyondNear => {
            clip_range(depth_range_with(
                &eye_from_world,
                splats.iter().map(Splat::centre),
            ))
            .0
        }
        _ => 0.0,
    };
    let veiled = |z: f32| match rule {
        VeilRule::None => false,
        VeilRule::Blurred => {
            z > 0.0 && z < camera.focus_distance && camera.coc_px(z) > camera.veil_coc_px()
        }
        // A margin over the near plane, so that no splat the host keeps
        // falls at it by the GPU's rounding (then neither drawn nor veiled).
        VeilRule::BeyondNear => z > 0.0 && z <= near * (1.0 + NEAR_MARGIN),
    };
    // In place: a frame's splats may be most of the host's memory.
    let mut kept = splats;
    let mut layers = Vec::new();
    kept.retain(|s| {
        let e = eye_from_world.apply(s.centre());
        let out = veiled(e.z);
        if out {
            layers.push((e, *s));
        }
        !out
    });
    let veiled_count = layers.len() as u64;
    // Nearest first; ties keep the splats' order (a stable sort).
    layers.sort_by(|a, b| a.0.z.total_cmp(&b.0.z));
    let f_px = camera.f_px();
    let (w, h) = (camera.width as f32, camera.height as f32);
    // The frame's pixel centres span [0.5, W − 0.5] × [0.5, H − 0.5].
    let (lo, hi) = (Vec2::splat(0.5), Vec2::new(w - 0.5, h - 0.5));
    let mut splats_in_view = Vec::new();
    for (e, s) in layers {
        let z = e.z;
        let centre = camera.pixel_of_eye(e);
        let c = camera.coc_px(z);
        // At least a pixel, as both rasters draw a splat.
        let side = splat_px.unwrap_or(f_px * s.position_size[3] / z).max(1.0);
        if !(centre.is_finite() && c.is_finite() && c > 0.0 && side > 0.0) {
            continue;
        }
        // Seen through the lens only within (c/2)(1 + √2·s/c) of p.
        let reach = c / 2.0 + std::f32::consts::SQRT_2 * side / 2.0;
        if (centre.clamp(lo, hi) - centre).length() > reach {
            continue;
        }
        splats_in_view.push(VeilSplat {
            centre_px: centre.into(),
            lens_per_px: camera.lens_sign(z) * 2.0 / c,
            half_side: side / c,
            color: (Vec3::new(
                s.color[0] as f32 / 65535.0,
                s.color[1] as f32 / 65535.0,
                s.color[2] as f32 / 65535.0,
            ) * color_scale)
                .extend(1.0)
                .into(),
        });
    }
    (
        kept,
        Veil {
            splats_in_view,
            splats: veiled_count,
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    static SHADER: &str = include_str!("../glsl/output_convert.comp");

    /// The hex words between `const uint DISK[CELLS] = uint[](` and `);`.
    fn shader_disk() -> (Vec<u32>, u32, u32) {
        let start = SHADER
            .find("const uint DISK[CELLS] = uint[](")
            .expect("DISK")
            + 32;
        let end = start + SHADER[start..].find(");").expect("end of DISK");
        let rows = SHADER[start..end]
            .split(',')
            .map(|w| {
                u32::from_str_radix(w.trim().trim_start_matches("0x").trim_end_matches('u'), 16)
                    .unwrap()
            })
            .collect();
        let number = |name: &str| -> u32 {
            let at = SHADER.find(name).expect(name) + name.len();
            let rest = &SHADER[at..];
            rest[..rest.find(';').unwrap()]
                .trim()
                .trim_end_matches('u')
                .parse()
                .unwrap()
        };
        (
            rows,
            number("const uint DISK_CELLS ="),
            number("const int CELLS ="),
        )
    }

    #[test]
    fn the_output_pass_has_the_same_lens_cells() {
        let grid = VeilGrid::new();
        let (rows, cells, per_axis) = shader_disk();
        assert_eq!(per_axis, VEIL_CELLS);
        assert_eq!(rows, grid.rows.to_vec());
        assert_eq!(cells, grid.cells);
        // π·8² ≈ 201 of 256: the disk's share of the square, to a cell row.
        assert_eq!(grid.cells, 208);
    }

    #[test]
    fn a_cell_range_holds_the_centres_inside() {
        // Centres at −15/16, −13/16, …, 15/16.
        assert_eq!(cell_range(0.0, 1.0 / 16.0), (7, 8));
        assert_eq!(cell_range(0.0, 0.9 / 16.0), (8, 7)); // none
        assert_eq!(cell_range(1.0 / 16.0, 0.0), (8, 8));
        assert_eq!(cell_range(0.0, 5.0), (0, 15));
        let (lo, hi) = cell_range(3.0, 1.0); // beyond the lens: none
        assert!(lo > hi);
    }

    fn speck(centre: Vec2, half_side: f32, color: Vec3) -> VeilSplat {
        VeilSplat {
            centre_px: centre.into(),
            lens_per_px: -0.01,
            half_side,
            color: color.extend(1.0).into(),
        }
    }

    #[test]
    fn a_speck_covers_its_share_of_the_lens() {
        let grid = VeilGrid::new();
        // A lens square of side 0.5 at the lens centre: 4 × 4 cells of 208.
        let veil = Veil {
            splats_in_view: vec![speck(Vec2::new(10.5, 10.5), 0.25, Vec3::X)],
            splats: 1,
        };
        let under = Vec4::new(0.0, 0.0, 1.0, 1.0);
        let v = veil.apply(&grid, 10, 10, under);
        let share = 16.0 / 208.0;
        assert!(
            (v - (share * Vec4::new(1.0, 0.0, 0.0, 1.0) + (1.0 - share) * under))
                .abs()
                .max_element()
                < 1e-6
        );
        // 150 px away the lens position is u = 1.5: outside the lens.
        assert_eq!(veil.apply(&grid, 160, 10, under), under);
    }

    #[test]
    fn points_in_line_through_the_lens_hide_one_another() {
        let grid = VeilGrid::new();
        let near = speck(Vec2::new(10.5, 10.5), 0.25, Vec3::X);
        let behind = speck(Vec2::new(10.5, 10.5), 0.25, Vec3::Y);
        let one = Veil {
            splats_in_view: vec![near],
            splats: 1,
        };
        let two = Veil {
            splats_in_view: vec![near, behind],
            splats: 2,
        };
        let under = Vec4::new(0.0, 0.0, 1.0, 1.0);
        assert_eq!(
            one.apply(&grid, 10, 10, under),
            two.apply(&grid, 10, 10, under)
        );
        // A point covering the whole lens hides everything behind it.
        let wall = Veil {
            splats_in_view: vec![speck(Vec2::new(10.5, 10.5), 2.0, Vec3::Y), near],
            splats: 2,
        };
        assert_eq!(
            wall.apply(&grid, 10, 10, under),
            Vec4::new(0.0, 1.0, 0.0, 1.0)
        );
    }

    #[test]
    fn pinhole_and_near_plane_rules() {
        let camera = Camera {
            width: 64,
            height: 48,
            eye: Vec3::ZERO,
            target: Vec3::new(0.0, 0.0, -1.0),
            up: Vec3::Y,
            fovy_deg: 40.0,
            aperture_radius: 0.01,
            focus_distance: 1.0,
            aperture: crate::camera::Aperture::ROUND,
        };
        let at = |z: f32| Splat {
            position_size: [0.0, 0.0, -z, 0.001],
            color: [65535, 0, 0, 0],
        };
        let splats = vec![at(0.001), at(0.5), at(2.0)];
        // c(0.001) = 2·0.01·f·0.999/0.001 ≈ 2,600 px > 64: veiled;
        // c(0.5) ≈ 2.6 px, c(2) ≈ 1.3 px: drawn.
        let (kept, veil) = split(&camera, splats.clone(), VeilRule::Blurred, None, 1.0);
        assert_eq!(kept, splats[1..].to_vec());
        assert_eq!(veil.splats, 1);
        assert_eq!(veil.splats_in_view.len(), 1);
        let (kept, veil) = split(&camera, splats.clone(), VeilRule::None, None, 1.0);
        assert_eq!((kept.len(), veil.splats), (3, 0));
        // The near plane of [0.001, 2] is 0.0005: accum draws all three.
        let (kept, veil) = split(&camera, splats.clone(), VeilRule::BeyondNear, None, 1.0);
        assert_eq!((kept.len(), veil.splats), (3, 0));
        // That of [1e-7, 1] is 1e-6 (far · 1e-6): the nearest is veiled,
        // and one just above the plane too (the margin), not one above it.
        let near = vec![at(1e-7), at(1.0005e-6), at(1.1e-6), at(1.0)];
        let (kept, veil) = split(&camera, near.clone(), VeilRule::BeyondNear, None, 1.0);
        assert_eq!(kept, vec![near[2], near[3]]);
        assert_eq!(veil.splats, 2);
        assert_eq!(veil.splats_in_view.len(), 2);
        // A pinhole camera has no veil.
        let pinhole = Camera {
            aperture_radius: 0.0,
            ..camera
        };
        let (kept, _) = split(&pinhole, splats, VeilRule::Blurred, None, 1.0);
        assert_eq!(kept.len(), 3);
    }
}
