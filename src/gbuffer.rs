//! The anti-aliased G-buffer (DESIGN §3): K×K raster samples at the output
//! size plus a guard band, the sub-pixel jitter in the projection, each
//! resolved as it is drawn into color (rgba16f, mean in linear light) and
//! eye position (rgba32f, of the nearest sample; w = coverage fraction).

use std::sync::Arc;

use ash::vk;
use glam::{Vec2, Vec3};

use crate::camera::{Camera, EyeFromWorld};
use crate::error::{Error, Result};
use crate::passes::gbuffer_resolve::{GBufferResolve, ResolveImages};
use crate::passes::splat_raster::{
    Sample, SampleTargets, SplatPush, SplatRaster, COLOR_FORMAT, EYE_FORMAT,
};
use crate::passes::{DofInput, FrameView};
use crate::vk::{Buffer, Context, Frame, Image};

/// Everything the raster needs to place splats for one view: the frame's
/// view (camera, guard band), the depth range and the splat size rule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RasterView {
    pub frame: FrameView,
    /// Eye-depth range mapped to the depth buffer; points outside are dropped.
    pub near: f32,
    pub far: f32,
    /// > 0: every splat is this many output pixels wide; 0: world diameters.
    pub splat_px: f32,
    /// The device's largest point size.
    pub max_point_size: f32,
}

impl RasterView {
    /// Push constants for one raster sample: sub-pixel `jitter` (pixels) and
    /// normalised lens position `lens_u` (zero for a pinhole view).
    pub fn push(&self, jitter: Vec2, lens_u: Vec2) -> SplatPush {
        let c = &self.frame.camera;
        let (right, up, forward) = c.basis();
        let g = self.frame.guard as f32;
        SplatPush {
            eye: c.eye.extend(0.0).to_array(),
            right: right.extend(0.0).to_array(),
            up: up.extend(0.0).to_array(),
            forward: forward.extend(0.0).to_array(),
            center: [c.width as f32 / 2.0 + g, c.height as f32 / 2.0 + g],
            extent: [
                self.frame.full_width() as f32,
                self.frame.full_height() as f32,
            ],
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

/// The eye-depth range (z_min, z_max) of the `positions` in front of
/// `camera`; None when no point is in front.
pub fn depth_range(camera: &Camera, positions: &[Vec3]) -> Option<(f32, f32)> {
    let eye_from_world = camera.eye_from_world_transform();
    depth_range_with(&eye_from_world, positions)
}

/// [`depth_range`] with the camera's transform made once.
pub fn depth_range_with(eye_from_world: &EyeFromWorld, positions: &[Vec3]) -> Option<(f32, f32)> {
    let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
    for p in positions {
        let z = eye_from_world.apply(*p).z;
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

/// The pipelines of the G-buffer: the splat raster and the resolve.
pub struct GBufferPasses {
    raster: SplatRaster,
    resolve: GBufferResolve,
}

impl GBufferPasses {
    pub fn new(ctx: &Arc<Context>) -> Result<GBufferPasses> {
        Ok(GBufferPasses {
            raster: SplatRaster::new(ctx)?,
            resolve: GBufferResolve::new(ctx)?,
        })
    }
}

/// The G-buffer images (with guard band), in `GENERAL` layout after the
/// last compute write once `record` has run.
pub struct GBuffer {
    color: Image,
    eye: Image,
    color_sum: Image,
    targets: SampleTargets,
    view: RasterView,
}

impl GBuffer {
    /// Allocates the G-buffer for `view`.
    pub fn new(ctx: &Arc<Context>, view: &RasterView) -> Result<GBuffer> {
        let frame = &view.frame;
        let (w, h) = (frame.full_width(), frame.full_height());
        let max = ctx.info.max_image_dimension_2d;
        if w > max || h > max {
            return Err(Error::InvalidArgument(format!(
                "image {}x{} with a {} px guard band is {w}x{h}, beyond the device limit of {max} px",
                frame.camera.width, frame.camera.height, frame.guard
            )));
        }
        let storage = vk::ImageUsageFlags::STORAGE;
        let readable = storage | vk::ImageUsageFlags::TRANSFER_SRC;
        Ok(GBuffer {
            color: Image::new_2d(ctx, "gbuffer color", COLOR_FORMAT, w, h, 1, readable)?,
            eye: Image::new_2d(ctx, "gbuffer eye", EYE_FORMAT, w, h, 1, readable)?,
            color_sum: Image::new_2d(ctx, "gbuffer color sum", EYE_FORMAT, w, h, 1, storage)?,
            targets: SampleTargets::new(ctx, w, h)?,
            view: *view,
        })
    }

    /// Records one raster per sample, each followed by its resolve, as
    /// passes `{label}.raster` and `{label}.resolve`. The color is the mean
    /// over all samples; the eye position is the nearest sample's.
    #[allow(clippy::too_many_arguments)]
    pub fn record<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        passes: &'r GBufferPasses,
        splats: &'r Buffer,
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
            passes.raster.record(
                frame,
                &raster_name,
                t,
                splats,
                count,
                background.to_array(),
                &push,
                s == 0,
            );
            passes
                .resolve
                .record(frame, &resolve_name, &resolve_images, s, n);
        }
    }

    /// The resolved G-buffer, as the depth-of-field methods read it.
    pub fn output(&self) -> DofInput<'_> {
        DofInput {
            color: &self.color,
            eye: &self.eye,
            view: self.view.frame,
        }
    }
}
