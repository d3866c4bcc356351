//! The anti-aliased G-buffer (DESIGN §3): K×K raster samples at the output
//! size plus a guard band, the sub-pixel jitter in the projection, each
//! resolved as it is drawn into color (rgba16f, mean in linear light) and
//! eye position (rgba32f, of the nearest sample; w = coverage fraction).

use std::sync::Arc;

use ash::vk;
use glam::{Vec2, Vec3};

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::passes::gbuffer_resolve::{GBufferResolve, ResolveImages};
use crate::passes::splat_raster::{
    SampleTargets, SplatPush, SplatRaster, COLOR_FORMAT, EYE_FORMAT,
};
use crate::vk::{image_barriers, Access, Buffer, Context, Frame, Image};

/// Everything the raster needs to place splats for one view: the camera,
/// the guard band, the depth range and the splat size rule.
#[derive(Debug, Clone, Copy)]
pub struct RasterView {
    pub camera: Camera,
    /// Pixels added on every side of the frame (DESIGN §3).
    pub guard: u32,
    /// The largest CoC (pixels) the view's method can meet, which the guard
    /// band was sized for.
    pub max_coc_px: f32,
    /// Eye-depth range mapped to the depth buffer; points outside are dropped.
    pub near: f32,
    pub far: f32,
    /// > 0: every splat is this many output pixels wide; 0: world diameters.
    pub splat_px: f32,
    /// The device's largest point size.
    pub max_point_size: f32,
}

impl RasterView {
    /// Width of the G-buffer including the guard band.
    pub fn full_width(&self) -> u32 {
        self.camera.width + 2 * self.guard
    }

    /// Height of the G-buffer including the guard band.
    pub fn full_height(&self) -> u32 {
        self.camera.height + 2 * self.guard
    }

    /// Push constants for one raster sample: sub-pixel `jitter` (pixels) and
    /// normalised lens position `lens_u` (zero for a pinhole view).
    pub fn push(&self, jitter: Vec2, lens_u: Vec2) -> SplatPush {
        let c = &self.camera;
        let (right, up, forward) = c.basis();
        let g = self.guard as f32;
        SplatPush {
            eye: c.eye.extend(0.0).to_array(),
            right: right.extend(0.0).to_array(),
            up: up.extend(0.0).to_array(),
            forward: forward.extend(0.0).to_array(),
            center: [c.width as f32 / 2.0 + g, c.height as f32 / 2.0 + g],
            extent: [self.full_width() as f32, self.full_height() as f32],
            jitter: jitter.to_array(),
            lens_u: lens_u.to_array(),
            f_px: c.f_px(),
            near: self.near,
            far: self.far,
            splat_px: self.splat_px,
            aperture_radius: c.aperture_radius,
            focus_distance: c.focus_distance,
            max_point_size: self.max_point_size,
            pad: 0.0,
        }
    }
}

/// Sub-pixel offset of sample `index` of a K×K grid: cell centres of the
/// pixel, row by row, relative to the pixel centre.
pub fn ssaa_jitter(index: u32, k: u32) -> Vec2 {
    let (i, j) = (index % k, index / k);
    Vec2::new(
        (i as f32 + 0.5) / k as f32 - 0.5,
        (j as f32 + 0.5) / k as f32 - 0.5,
    )
}

/// The eye-depth range (z_min, z_max) of the `positions` in front of
/// `camera`; None when no point is in front.
pub fn depth_range(camera: &Camera, positions: &[Vec3]) -> Option<(f32, f32)> {
    let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
    for p in positions {
        let z = camera.eye_from_world(*p).z;
        if z > 0.0 {
            lo = lo.min(z);
            hi = hi.max(z);
        }
    }
    (hi > 0.0).then_some((lo, hi))
}

/// The depth-buffer range for points in (z_min, z_max), widened so that
/// none of them is clipped: (near, far), 0 < near < z_min.
pub fn clip_range(range: Option<(f32, f32)>) -> (f32, f32) {
    match range {
        Some((lo, hi)) => {
            let near = (lo * 0.5).max(hi * 1e-6);
            (near, hi * 1.5 + near)
        }
        // Nothing in front of the camera: any valid range draws nothing.
        None => (1.0, 2.0),
    }
}

/// One raster sample: sub-pixel jitter and normalised lens position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub jitter: Vec2,
    pub lens_u: Vec2,
}

/// The K×K SSAA samples of a pinhole G-buffer.
pub fn pinhole_samples(ssaa: u32) -> Vec<Sample> {
    (0..ssaa * ssaa)
        .map(|s| Sample {
            jitter: ssaa_jitter(s, ssaa),
            lens_u: Vec2::ZERO,
        })
        .collect()
}

/// The G-buffer images (with guard band), in `GENERAL` layout after the
/// last compute write once `record` has run.
pub struct GBuffer {
    pub color: Image,
    pub eye: Image,
    color_sum: Image,
    targets: SampleTargets,
    pub view: RasterView,
}

impl GBuffer {
    /// Allocates the G-buffer for `view`.
    pub fn new(ctx: &Arc<Context>, view: &RasterView) -> Result<GBuffer> {
        let (w, h) = (view.full_width(), view.full_height());
        let max = ctx.info.max_image_dimension_2d;
        if w > max || h > max {
            return Err(Error::InvalidArgument(format!(
                "image {}x{} with a {} px guard band is {w}x{h}, beyond the device limit of {max} px",
                view.camera.width, view.camera.height, view.guard
            )));
        }
        let storage = vk::ImageUsageFlags::STORAGE;
        Ok(GBuffer {
            color: Image::new_2d(
                ctx,
                "gbuffer color",
                COLOR_FORMAT,
                w,
                h,
                1,
                storage | vk::ImageUsageFlags::TRANSFER_SRC,
            )?,
            eye: Image::new_2d(
                ctx,
                "gbuffer eye",
                EYE_FORMAT,
                w,
                h,
                1,
                storage | vk::ImageUsageFlags::TRANSFER_SRC,
            )?,
            color_sum: Image::new_2d(ctx, "gbuffer color sum", EYE_FORMAT, w, h, 1, storage)?,
            targets: SampleTargets::new(ctx, w, h)?,
            view: *view,
        })
    }

    /// Records one raster per sample, each followed by its resolve, as
    /// passes `{label}.raster` and `{label}.resolve`. The color is the mean
    /// over all samples; the eye position is the nearest sample's.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        frame: &mut Frame,
        raster: &SplatRaster,
        resolve: &GBufferResolve,
        splats: &Buffer,
        count: u32,
        samples: &[Sample],
        background: Vec3,
        label: &str,
    ) {
        let n = samples.len() as u32;
        let (raster_name, resolve_name) = (format!("{label}.raster"), format!("{label}.resolve"));
        let t = &self.targets;
        let resolve_images = ResolveImages {
            sample_color: &t.color,
            sample_eye: &t.eye,
            color_sum: &self.color_sum,
            gbuffer_eye: &self.eye,
            gbuffer_color: &self.color,
        };
        for (s, sample) in (0..n).zip(samples) {
            let push = self.view.push(sample.jitter, sample.lens_u);
            frame.pass(&raster_name, |ctx, cmd| {
                let (color_src, depth_src) = if s == 0 {
                    (Access::NONE, Access::NONE)
                } else {
                    (Access::COMPUTE_READ, Access::DEPTH_WRITE)
                };
                image_barriers(
                    ctx,
                    cmd,
                    &[
                        (&t.color, color_src, Access::COLOR_WRITE),
                        (&t.eye, color_src, Access::COLOR_WRITE),
                        (&t.depth, depth_src, Access::DEPTH_WRITE),
                    ],
                );
                raster.record(cmd, t, splats, count, background.to_array(), &push);
                image_barriers(
                    ctx,
                    cmd,
                    &[
                        (&t.color, Access::COLOR_WRITE, Access::COMPUTE_READ),
                        (&t.eye, Access::COLOR_WRITE, Access::COMPUTE_READ),
                    ],
                );
            });
            frame.pass(&resolve_name, |ctx, cmd| {
                let src = if s == 0 {
                    Access::NONE
                } else {
                    Access::COMPUTE_READ_WRITE
                };
                let mut list = vec![
                    (&self.color_sum, src, Access::COMPUTE_READ_WRITE),
                    (&self.eye, src, Access::COMPUTE_READ_WRITE),
                ];
                if s == 0 {
                    list.push((&self.color, Access::NONE, Access::COMPUTE_WRITE));
                }
                image_barriers(ctx, cmd, &list);
                resolve.record(cmd, &resolve_images, s, n);
            });
        }
    }
}
