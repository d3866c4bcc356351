//! The anti-aliased G-buffer (DESIGN §3): K×K raster samples at the output
//! size plus a guard band, taken in the passes of a [`SamplePlan`] (one
//! sample per pass with the sub-pixel jitter in the projection, or S
//! samples per multisampled pass), each pass resolved as it is drawn into
//! color (rgba16f, mean in linear light) and eye depth (rgba32f
//! (0, 0, z, coverage): z of the nearest sample, w the covered fraction).
//! A raster pass writes one rgba32f target per sample, (r, g, b, z): the
//! DOF methods read only the eye depth of DESIGN §3's eye position, so its
//! x and y are neither drawn nor kept.

use std::sync::Arc;

use ash::vk;
use glam::{Vec2, Vec3};

use crate::camera::{Camera, EyeFromWorld};
use crate::error::{Error, Result};
use crate::passes::gbuffer_resolve::{GBufferResolve, ResolveImages, ResolvePass};
use crate::passes::sample_plan::SamplePlan;
use crate::passes::splat_raster::{
    SampleTargets, SplatPush, SplatRaster, TargetsBefore, COLOR_FORMAT, EYE_FORMAT, SAMPLE_FORMAT,
};
use crate::passes::{DofInput, FrameView, GBufferLayer};
use crate::vk::{Access, Buffer, Context, Frame, Image};

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
    /// Push constants for one raster pass: sub-pixel `jitter` (pixels),
    /// normalised lens position `lens_u` (zero for a pinhole view) and the
    /// render targets' size (the G-buffer's, or one pixel more each way
    /// when the pass's samples are read from the next pixel).
    pub fn push(&self, jitter: Vec2, lens_u: Vec2, targets: [u32; 2]) -> SplatPush {
        let c = &self.frame.camera;
        let (right, up, forward) = c.basis();
        let g = self.frame.guard as f32;
        SplatPush {
            eye: c.eye.extend(0.0).to_array(),
            right: right.extend(0.0).to_array(),
            up: up.extend(0.0).to_array(),
            forward: forward.extend(0.0).to_array(),
            center: [c.width as f32 / 2.0 + g, c.height as f32 / 2.0 + g],
            extent: [targets[0] as f32, targets[1] as f32],
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

/// The pipelines of the G-buffer: the splat raster and the depth peel (one
/// each per sample count the device offers) and the resolve.
pub struct GBufferPasses {
    /// By samples per pixel: 1, then the device's multisampled counts.
    rasters: Vec<(u32, SplatRaster)>,
    /// The depth peel of layers after the first, by samples per pixel: 1,
    /// and the multisampled counts where the device shades per sample.
    peels: Vec<(u32, SplatRaster)>,
    resolve: GBufferResolve,
}

/// The sample counts a plan may use (DESIGN §3 takes S up to 8: the
/// standard locations beyond are optional in Vulkan).
const PLANNED_COUNTS: [u32; 4] = [1, 2, 4, 8];

impl GBufferPasses {
    pub fn new(ctx: &Arc<Context>) -> Result<GBufferPasses> {
        let supported = ctx.info.gbuffer_sample_counts.as_raw();
        let rasters = PLANNED_COUNTS
            .into_iter()
            .filter(|s| supported & s != 0)
            .map(|s| SplatRaster::new(ctx, s, false).map(|r| (s, r)))
            .collect::<Result<Vec<_>>>()?;
        let peels = rasters
            .iter()
            .map(|(s, _)| *s)
            .filter(|&s| s == 1 || ctx.info.sample_rate_shading)
            .map(|s| SplatRaster::new(ctx, s, true).map(|r| (s, r)))
            .collect::<Result<Vec<_>>>()?;
        Ok(GBufferPasses {
            resolve: GBufferResolve::new(ctx, rasters.len() > 1)?,
            rasters,
            peels,
        })
    }

    /// The plan for K×K samples of `layers` depth-peeled layers with at
    /// most `max_samples_per_pass` samples per pass (None: no limit) whose
    /// sample targets for `pixels` pixels take at most `budget_bytes`: the
    /// fewest passes the device's sample counts (those it can peel, for
    /// more than one layer) allow ([`SamplePlan::best`]).
    pub fn plan(
        &self,
        ssaa: u32,
        layers: u32,
        max_samples_per_pass: Option<u32>,
        pixels: u64,
        budget_bytes: u64,
    ) -> SamplePlan {
        let max = max_samples_per_pass.unwrap_or(u32::MAX);
        let usable = if layers > 1 {
            &self.peels
        } else {
            &self.rasters
        };
        let mut counts: Vec<u32> = usable
            .iter()
            .map(|(s, _)| *s)
            .filter(|&s| s <= max)
            .collect();
        // A peel keeps the previous layer's sample target beside its own.
        let targets = if layers > 1 { 2 } else { 1 };
        loop {
            let plan = SamplePlan::best(ssaa, counts.iter().fold(0, |m, s| m | s));
            let s = plan.samples_per_pass;
            if s == 1 || targets * pixels * SampleTargets::bytes_per_pixel(s) <= budget_bytes {
                return plan;
            }
            counts.retain(|&c| c < s);
        }
    }

    fn raster(&self, samples: u32, peel: bool) -> &SplatRaster {
        let list = if peel { &self.peels } else { &self.rasters };
        let found = list.iter().find(|(s, _)| *s == samples);
        &found.expect("a plan of the device's sample counts").1
    }
}

/// The G-buffer images (with guard band) of every layer, in `GENERAL`
/// layout after the last compute write once `record` has run.
pub struct GBuffer {
    layers: Vec<GBufferLayer>,
    /// Each layer's running color sum.
    color_sums: Vec<Image>,
    targets: SampleTargets,
    /// The second sample target of a depth peel: layer l draws into
    /// `targets.sample` for even l and here for odd l, reading the other.
    peel_sample: Option<Image>,
    view: RasterView,
    plan: SamplePlan,
    background: Vec3,
}

impl GBuffer {
    /// Allocates `layers` G-buffer layers for `view` (1: the pinhole
    /// G-buffer), and the sample targets for the passes of `plan`.
    pub fn new(
        ctx: &Arc<Context>,
        view: &RasterView,
        plan: &SamplePlan,
        layers: u32,
        background: Vec3,
    ) -> Result<GBuffer> {
        let frame = &view.frame;
        let (w, h) = (frame.full_width(), frame.full_height());
        let max = ctx.info.max_image_dimension_2d;
        if w > max || h > max {
            return Err(Error::InvalidArgument(format!(
                "image {}x{} with a {} px guard band is {w}x{h}, beyond the device limit of {max} px",
                frame.camera.width, frame.camera.height, frame.guard
            )));
        }
        assert!(layers >= 1, "a G-buffer has at least one layer");
        // Passes whose samples are read from the next pixel draw one more.
        let margin = u32::from(plan.reads_neighbours());
        let storage = vk::ImageUsageFlags::STORAGE;
        let readable = storage | vk::ImageUsageFlags::TRANSFER_SRC;
        let mut images = Vec::new();
        let mut color_sums = Vec::new();
        for l in 0..layers {
            let name = |what: &str| match l {
                0 => format!("gbuffer {what}"),
                _ => format!("gbuffer layer {l} {what}"),
            };
            images.push(GBufferLayer {
                color: Image::new_2d(ctx, &name("color"), COLOR_FORMAT, w, h, 1, readable)?,
                eye: Image::new_2d(ctx, &name("eye"), EYE_FORMAT, w, h, 1, readable)?,
            });
            color_sums.push(Image::new_2d(
                ctx,
                &name("color sum"),
                EYE_FORMAT,
                w,
                h,
                1,
                storage,
            )?);
        }
        let (tw, th, s) = (w + margin, h + margin, plan.samples_per_pass);
        let attach = vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::STORAGE;
        let peel_sample = match layers {
            1 => None,
            _ => Some(Image::new_multisampled(
                ctx,
                "peel sample",
                SAMPLE_FORMAT,
                tw,
                th,
                s,
                attach,
            )?),
        };
        Ok(GBuffer {
            layers: images,
            color_sums,
            targets: SampleTargets::new(ctx, tw, th, s)?,
            peel_sample,
            view: *view,
            plan: plan.clone(),
            background,
        })
    }

    /// Records the plan's passes through every lens position of `lens`
    /// (lens outer, passes, then layers inner), each raster followed by
    /// its resolve, as passes `{label}.raster` and `{label}.resolve` (the
    /// first layer) and `peel.raster` and `peel.resolve` (the depth peel
    /// of the others: the layered method's work, which `bench` counts as
    /// depth of field). Per layer, the color is the mean over
    /// all samples; the eye depth is the nearest sample's, ties to the
    /// lowest index in the one-sample form (lens position, then sample),
    /// whatever the plan.
    pub fn record<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        passes: &'r GBufferPasses,
        splats: &'r Buffer,
        count: u32,
        lens: &[Vec2],
        label: &str,
    ) {
        let names = [
            (format!("{label}.raster"), format!("{label}.resolve")),
            ("peel.raster".to_string(), "peel.resolve".to_string()),
        ];
        let t = &self.targets;
        let samples = self.plan.samples_per_pass;
        let per_lens = self.plan.passes.len() as u32 * samples;
        let sample_count = lens.len() as u32 * per_lens;
        let extent = [t.sample.width(), t.sample.height()];
        // The sample targets a layer draws into and reads, and where each
        // was last used.
        let buffers: [&'r Image; 2] = [&t.sample, self.peel_sample.as_ref().unwrap_or(&t.sample)];
        let mut last = [Access::NONE; 2];
        let mut depth_last = Access::NONE;
        for (i, (l, lens_u, planned)) in self.plan.with_lens(lens).enumerate() {
            let push = self.view.push(planned.jitter, lens_u, extent);
            for (layer, images) in self.layers.iter().enumerate() {
                let (target, previous) = (layer % 2, (layer + 1) % 2);
                let peel = layer > 0;
                let (raster_name, resolve_name) = &names[usize::from(peel)];
                passes.raster(samples, peel).record(
                    frame,
                    raster_name,
                    buffers[target],
                    &t.depth,
                    peel.then_some(buffers[previous]),
                    TargetsBefore {
                        sample: last[target],
                        depth: depth_last,
                        previous: last[previous],
                    },
                    splats,
                    count,
                    self.background.to_array(),
                    &push,
                );
                if peel {
                    last[previous] = Access::FRAGMENT_READ;
                }
                last[target] = Access::COMPUTE_READ;
                depth_last = Access::DEPTH_WRITE;
                let pass = ResolvePass {
                    first_sample: i as u32 * samples,
                    sample_count,
                    read_offsets: planned.read_offsets,
                    index_base: l * per_lens,
                    indices: planned.packed_indices(),
                };
                let resolve_images = ResolveImages {
                    sample: buffers[target],
                    color_sum: &self.color_sums[layer],
                    gbuffer_eye: &images.eye,
                    gbuffer_color: &images.color,
                };
                passes
                    .resolve
                    .record(frame, resolve_name, &resolve_images, &pass);
            }
        }
    }

    /// The resolved G-buffer, as the depth-of-field methods read it.
    pub fn output(&self) -> DofInput<'_> {
        DofInput {
            color: &self.layers[0].color,
            eye: &self.layers[0].eye,
            layers: &self.layers,
            background: self.background,
            view: self.view.frame,
        }
    }
}
