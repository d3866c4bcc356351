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
use crate::options::{Raster, SplatShape};
use crate::passes::gbuffer_area::{AreaBand, GBufferArea, Marked};
use crate::passes::gbuffer_resolve::{
    GBufferResolve, LensWeight, ResolveImages, ResolvePass, Samples,
};
use crate::passes::peel_cull::{PeelCull, PeelCullBuffers};
use crate::passes::sample_plan::{PlannedPass, SamplePlan};
use crate::passes::splat_compute::{self, ComputeRaster, Visibility};
use crate::passes::splat_raster::{
    SampleTargets, SplatPush, SplatRaster, TargetsBefore, COLOR_FORMAT, EYE_FORMAT,
};
use crate::passes::{DofInput, FrameView, GBufferLayer, GBufferLens};
use crate::vk::{Access, Buffer, Context, DrawCount, Frame, Image};

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
    /// The largest splat the view draws, output pixels (at most
    /// `max_point_size`).
    pub max_splat_px: f32,
    /// The linear colour of a splat's code 65535
    /// ([`crate::tree::SplatTree::color_scale`]; 1: white).
    pub color_scale: f32,
}

impl RasterView {
    /// Push constants for one raster pass: sub-pixel `jitter` (pixels),
    /// normalised lens position `lens_u` (zero for a pinhole view), the
    /// render targets' size (the G-buffer's, or one pixel more each way
    /// when the pass's samples are read from the next pixel, or `scale`
    /// times the G-buffer's) and `scale`, target pixels per G-buffer pixel
    /// along each axis (1, or K for the upscaled plan: the projection, the
    /// pixel sizes and the smallest sprite scaled by it, so that a sprite
    /// covers the same part of the image), and the first G-buffer row the
    /// targets hold (0, or a band's first row: the image moved up by it).
    pub fn push(
        &self,
        jitter: Vec2,
        lens_u: Vec2,
        targets: [u32; 2],
        scale: u32,
        first_row: u32,
    ) -> SplatPush {
        let c = &self.frame.camera;
        let (right, up, forward) = c.basis();
        let g = self.frame.guard as f32;
        let k = scale as f32;
        let w = &self.frame.window;
        // The whole frame's centre, moved by the window's origin (a tile of
        // a poster sees its part of the one projection).
        let centre = [
            c.width as f32 / 2.0 + g - w.x as f32,
            c.height as f32 / 2.0 + g - (w.y + first_row) as f32,
        ];
        SplatPush {
            eye: c.eye.extend(0.0).to_array(),
            right: right.extend(0.0).to_array(),
            up: up.extend(0.0).to_array(),
            forward: forward.extend(0.0).to_array(),
            // k = 1 multiplies exactly: the one-sample and multisampled
            // plans' projection is unchanged.
            center: centre.map(|v| k * v),
            extent: [targets[0] as f32, targets[1] as f32],
            jitter: jitter.to_array(),
            lens_u: lens_u.to_array(),
            f_px: k * c.f_px(),
            near: self.near,
            far: self.far,
            splat_px: k * self.splat_px,
            aperture_radius: c.aperture_radius,
            focus_distance: c.focus_distance,
            max_point_size: self.max_point_size,
            min_point_size: k,
        }
    }

    /// Whether the upscaled plan of K×K samples ([`SamplePlan::upscaled`])
    /// draws this view's splats as the one-sample form does: its largest
    /// splat, K times wider in the target, within the device's point size.
    fn upscales(&self, ssaa: u32) -> bool {
        ssaa as f32 * self.max_splat_px <= self.max_point_size
    }
}

/// The eye-depth range (z_min, z_max) of the `positions` in front of
/// `camera`; None when no point is in front.
pub fn depth_range(camera: &Camera, positions: &[Vec3]) -> Option<(f32, f32)> {
    let eye_from_world = camera.eye_from_world_transform();
    depth_range_with(&eye_from_world, positions.iter().copied())
}

/// [`depth_range`] with the camera's transform made once.
pub fn depth_range_with(
    eye_from_world: &EyeFromWorld,
    positions: impl IntoIterator<Item = Vec3>,
) -> Option<(f32, f32)> {
    let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
    for p in positions {
        let z = eye_from_world.apply(p).z;
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
    /// The depth peel of layers after the first, by samples per pixel.
    peels: Vec<(u32, SplatRaster)>,
    /// The splats a peel may keep, before each peel pass.
    peel_cull: PeelCull,
    /// The compute rasteriser and its area coverage, on devices with
    /// 64-bit buffer atomics.
    compute: Option<(ComputeRaster, GBufferArea)>,
    /// The device's largest storage buffer binding, bytes: the compute
    /// rasteriser's visibility words of one band.
    max_storage_buffer_bytes: u64,
    resolve: GBufferResolve,
}

/// The sample counts a plan may use (DESIGN §3 takes S up to 8: the
/// standard locations beyond are optional in Vulkan).
const PLANNED_COUNTS: [u32; 4] = [1, 2, 4, 8];

/// The largest scale of the compute rasteriser's depth peel: 2×2 samples
/// per pixel, the sprite peel's 4 on lavapipe (a hidden layer is seen
/// only through a blurred occluder's edge; one sample per pixel lost
/// 5.3 dB on the thin bar of `tests/layered.rs`: docs/BENCHMARKS.md).
pub const COMPUTE_PEEL_SCALE: u32 = 2;

/// How the layered method's later layers are peeled: one raster pass and
/// its resolve per layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PeelPlan {
    /// Point sprites, multisampled: `samples` per pixel at the standard
    /// locations, unjittered.
    Sprites { samples: u32 },
    /// The compute rasteriser into a target `scale` times the G-buffer's
    /// size along each axis (scale² samples per pixel on the upscaled
    /// plan's grid), in one band.
    Compute { scale: u32 },
}

impl GBufferPasses {
    /// Whether the resolves of passes that hold every sample of their
    /// pixels take the pipelines made for them (the default, true):
    /// [`crate::render::Renderer::set_specialized_pipelines`].
    pub fn set_whole_passes(&mut self, enabled: bool) {
        self.resolve.set_whole_passes(enabled);
    }

    /// Whether the marking resolve of the area coverage skips the tiles no
    /// splat reaches: [`crate::render::Renderer::set_untouched_tiles_skipped`].
    pub fn set_untouched_tiles_skipped(&mut self, on: bool) {
        if let Some((raster, _)) = &mut self.compute {
            raster.set_skips_untouched(on);
        }
    }

    /// The passes drawing splats of `shape`.
    pub fn new(ctx: &Arc<Context>, shape: SplatShape) -> Result<GBufferPasses> {
        let supported = ctx.info.gbuffer_sample_counts.as_raw();
        let rasters = PLANNED_COUNTS
            .into_iter()
            .filter(|s| supported & s != 0)
            .map(|s| SplatRaster::new(ctx, s, false, shape).map(|r| (s, r)))
            .collect::<Result<Vec<_>>>()?;
        let peels = rasters
            .iter()
            .map(|(s, _)| SplatRaster::new(ctx, *s, true, shape).map(|r| (*s, r)))
            .collect::<Result<Vec<_>>>()?;
        Ok(GBufferPasses {
            resolve: GBufferResolve::new(ctx, rasters.len() > 1)?,
            peel_cull: PeelCull::new(ctx)?,
            compute: match ctx.info.buffer_int64_atomics {
                true => Some((ComputeRaster::new(ctx, shape)?, GBufferArea::new(ctx)?)),
                false => None,
            },
            max_storage_buffer_bytes: ctx.info.max_storage_buffer_range,
            rasters,
            peels,
        })
    }

    /// The plan for K×K samples of `view` with at most
    /// `max_samples_per_pass` samples of an output pixel per pass (None: no
    /// limit) whose sample targets take at most `budget_bytes`: all K² in
    /// one pass ([`SamplePlan::upscaled`]) where the view's largest splat K
    /// times wider fits the device's point size, in as few horizontal bands
    /// as make the targets, K times the band's size, fit the budget and
    /// `max_dimension`, while the bands are fewer than the passes of the
    /// plan the device's sample counts allow otherwise
    /// ([`SamplePlan::best`]: each band draws every splat, as each pass
    /// does); else that plan.
    ///
    /// The compute rasteriser (`raster`) always takes the upscaled plan
    /// (it has no point-size limit), in as few bands as make each band's
    /// visibility words fit the budget and the device's storage buffer
    /// range; `max_samples_per_pass` does not apply to it.
    pub fn plan(
        &self,
        raster: Raster,
        ssaa: u32,
        max_samples_per_pass: Option<u32>,
        view: &RasterView,
        budget_bytes: u64,
        max_dimension: u32,
    ) -> Result<SamplePlan> {
        let max = max_samples_per_pass.unwrap_or(u32::MAX);
        let (w, h) = (view.frame.full_width(), view.frame.full_height());
        let pixels = w as u64 * h as u64;
        assert_ne!(raster, Raster::Auto, "the renderer resolves --raster auto");
        if raster == Raster::Compute {
            if self.compute.is_none() {
                return Err(Error::InvalidArgument(
                    "--raster compute needs 64-bit atomics on storage buffers, which this device lacks"
                        .into(),
                ));
            }
            let k = ssaa as u64;
            let limit = budget_bytes.min(self.max_storage_buffer_bytes);
            let fits = |bands: u32| {
                let rows = (h.div_ceil(bands) + 2 * band_halo_rows(bands)) as u64;
                w as u64 * k * rows * k * splat_compute::WORD_BYTES <= limit
            };
            let bands = (1..=h).find(|&b| fits(b)).ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "one row of {w} px at {ssaa}x{ssaa} samples does not fit the sample budget"
                ))
            })?;
            return Ok(SamplePlan::upscaled(ssaa).in_bands(bands));
        }
        let mut counts: Vec<u32> = self
            .rasters
            .iter()
            .map(|(s, _)| *s)
            .filter(|&s| s <= max)
            .collect();
        let otherwise = loop {
            let plan = SamplePlan::best(ssaa, counts.iter().fold(0, |m, s| m | s));
            let s = plan.samples_per_pass;
            if SampleTargets::fit(s, pixels, budget_bytes) {
                break plan;
            }
            counts.retain(|&c| c < s);
        };
        if ssaa > 1 && ssaa * ssaa <= max && view.upscales(ssaa) {
            let k = ssaa as u64;
            let fits = |bands: u32| {
                let rows = h.div_ceil(bands) as u64;
                (w as u64 * k).max(rows * k) <= max_dimension as u64
                    && w as u64 * rows * k * k * SampleTargets::bytes_per_pixel(1) <= budget_bytes
            };
            let fewer = (1..otherwise.passes.len() as u32).find(|&b| fits(b));
            if let Some(bands) = fewer {
                return Ok(SamplePlan::upscaled(ssaa).in_bands(bands));
            }
        }
        Ok(otherwise)
    }

    /// The depth peel of each later layer (one pass each) for a G-buffer
    /// of `pixels` pixels whose first layer is drawn with `raster`: with
    /// the compute rasteriser, its peel at the largest scale up to K and
    /// [`COMPUTE_PEEL_SCALE`] whose words fit `budget_bytes` and the
    /// storage buffer range in one band; else (or if none fits) sprites
    /// of [`GBufferPasses::peel_samples`].
    pub fn peel_plan(
        &self,
        raster: Raster,
        ssaa: u32,
        max_samples_per_pass: Option<u32>,
        pixels: u64,
        budget_bytes: u64,
    ) -> PeelPlan {
        if raster == Raster::Compute && self.compute.is_some() {
            let limit = budget_bytes.min(self.max_storage_buffer_bytes);
            let fits = |scale: u64| pixels * scale * scale * splat_compute::WORD_BYTES <= limit;
            if let Some(scale) = (1..=ssaa.min(COMPUTE_PEEL_SCALE))
                .rev()
                .find(|&s| fits(s as u64))
            {
                return PeelPlan::Compute { scale };
            }
        }
        PeelPlan::Sprites {
            samples: self.peel_samples(ssaa, max_samples_per_pass, pixels, budget_bytes),
        }
    }

    /// Samples per pixel of each depth-peel pass of sprites (one per
    /// later layer): the device's largest count up to the first layer's K²
    /// samples and `max_samples_per_pass` whose targets for `pixels` pixels
    /// take at most `budget_bytes`, taken in one pass at the standard
    /// locations.
    pub fn peel_samples(
        &self,
        ssaa: u32,
        max_samples_per_pass: Option<u32>,
        pixels: u64,
        budget_bytes: u64,
    ) -> u32 {
        let max = max_samples_per_pass.unwrap_or(u32::MAX).min(ssaa * ssaa);
        self.peels
            .iter()
            .map(|(s, _)| *s)
            .filter(|&s| s <= max && SampleTargets::fit(s, pixels, budget_bytes))
            .max()
            .unwrap_or(1)
    }

    fn compute(&self) -> &ComputeRaster {
        let compute = self.compute.as_ref();
        &compute
            .expect("a compute plan on a device with 64-bit atomics (checked by plan)")
            .0
    }

    fn area(&self) -> &GBufferArea {
        let compute = self.compute.as_ref();
        &compute
            .expect("area coverage on a device with 64-bit atomics")
            .1
    }

    fn raster(&self, samples: u32, peel: bool) -> &SplatRaster {
        let list = if peel { &self.peels } else { &self.rasters };
        let found = list.iter().find(|(s, _)| *s == samples);
        &found.expect("a plan of the device's sample counts").1
    }
}

/// The targets of the first layer's raster passes.
enum FirstTargets {
    Sprites(SampleTargets),
    Compute(Visibility),
}

/// The targets of the depth peel's passes, where they are not the first
/// layer's.
enum PeelTargets {
    Sprites(SampleTargets),
    /// The whole G-buffer, `scale` times its size along each axis.
    Compute {
        target: Visibility,
        scale: u32,
    },
}

/// The G-buffer images (with guard band) of every layer, in `GENERAL`
/// layout after the last compute write once `record` has run.
pub struct GBuffer {
    layers: Vec<GBufferLayer>,
    /// Each layer's running color sum, for a layer resolved over several
    /// passes; a peeled layer is resolved in one pass, which neither reads
    /// nor writes it, so its image only fills the resolve's binding (1×1).
    color_sums: Vec<Image>,
    /// Where the first layer's raster passes draw.
    targets: FirstTargets,
    /// The depth peel's targets where the first layer's are not the
    /// sprite targets of its samples per pixel (else it draws into them).
    peel_targets: Option<PeelTargets>,
    /// Each peel's splats, culled before it (None: the peel draws every
    /// splat).
    peel_cull: Option<PeelCullBuffers>,
    view: RasterView,
    plan: SamplePlan,
    background: Vec3,
    /// Where the first layer resolves by area
    /// ([`crate::options::Coverage::Area`]): its list of marked pixels.
    marked: Option<Marked>,
}

/// G-buffer rows of the neighbouring bands a compute raster's band target
/// holds on each side of its own: the area resolve reads each pixel's
/// neighbours' samples (none for a plan of one band).
pub fn band_halo_rows(bands: u32) -> u32 {
    if bands > 1 {
        1
    } else {
        0
    }
}

impl GBuffer {
    /// Allocates `layers` G-buffer layers for `view` (1: the pinhole
    /// G-buffer), the sample targets for the passes of `plan` and, for
    /// more than one layer, those of the depth peel's passes of `peel`
    /// ([`GBufferPasses::peel_plan`]) and, with `cull_splats` (the frame's
    /// splat count) and a peel of sprites, the buffers that cull each
    /// peel's splats ([`PeelCull`]; None: every peel draws every splat; the
    /// compute peel's cost per splat is small, and it draws every one).
    /// The first layer's passes draw with `raster` (a compute plan or
    /// peel: `compute_splats`, the frame's splat count); with `area`, the
    /// compute raster's words resolve by area (the caller checks that it
    /// can act: [`crate::options::Coverage`]).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        ctx: &Arc<Context>,
        view: &RasterView,
        plan: &SamplePlan,
        raster: Raster,
        compute_splats: u32,
        layers: u32,
        peel: PeelPlan,
        cull_splats: Option<u32>,
        background: Vec3,
        area: bool,
    ) -> Result<GBuffer> {
        let frame = &view.frame;
        let (w, h) = (frame.full_width(), frame.full_height());
        let max = ctx.info.max_image_dimension_2d;
        if w > max || h > max {
            return Err(Error::InvalidArgument(format!(
                "image {}x{} with a {} px guard band is {w}x{h}, beyond the device limit of {max} px",
                frame.window.width, frame.window.height, frame.guard
            )));
        }
        assert!(layers >= 1, "a G-buffer has at least one layer");
        // Passes whose samples are read from the next pixel draw one more;
        // an upscaled target holds one band's rows.
        let margin = u32::from(plan.reads_neighbours());
        let scale = plan.scale;
        let band = h.div_ceil(plan.bands);
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
            let (sw, sh) = if l == 0 { (w, h) } else { (1, 1) };
            color_sums.push(Image::new_2d(
                ctx,
                &name("color sum"),
                EYE_FORMAT,
                sw,
                sh,
                1,
                storage,
            )?);
        }
        let targets = match raster {
            Raster::Sprites | Raster::Auto => FirstTargets::Sprites(SampleTargets::new(
                ctx,
                scale * w + margin,
                scale * band + margin,
                plan.samples_per_pass,
            )?),
            Raster::Compute => {
                assert_eq!(plan.samples_per_pass, 1, "a compute plan is upscaled");
                FirstTargets::Compute(Visibility::new(
                    ctx,
                    (scale * w, scale * (band + 2 * band_halo_rows(plan.bands))),
                    scale,
                    compute_splats,
                    area,
                )?)
            }
        };
        let peel_targets = match peel {
            _ if layers == 1 => None,
            PeelPlan::Sprites { samples }
                if matches!(targets, FirstTargets::Sprites(_))
                    && samples == plan.samples_per_pass
                    && scale == 1 =>
            {
                None
            }
            // The peel reads in place at the G-buffer's size: its targets
            // need no margin.
            PeelPlan::Sprites { samples } => Some(PeelTargets::Sprites(SampleTargets::new(
                ctx, w, h, samples,
            )?)),
            PeelPlan::Compute { scale } => Some(PeelTargets::Compute {
                target: Visibility::peel(ctx, scale * w, scale * h, compute_splats)?,
                scale,
            }),
        };
        let marked = match (area, &targets) {
            (true, FirstTargets::Compute(_)) => Some(Marked::new(ctx, w, band)?),
            _ => None,
        };
        Ok(GBuffer {
            layers: images,
            color_sums,
            targets,
            peel_targets,
            view: *view,
            peel_cull: match (layers > 1, cull_splats, peel) {
                (true, Some(count), PeelPlan::Sprites { .. }) => {
                    Some(PeelCullBuffers::new(ctx, count, w, h)?)
                }
                _ => None,
            },
            plan: plan.clone(),
            background,
            marked,
        })
    }

    /// Records the first layer: the plan's passes through every lens
    /// position of `lens` (lens outer), each raster followed by its
    /// resolve, as passes `{label}.raster` and `{label}.resolve`; the color
    /// is the mean over all samples, the eye depth the nearest sample's,
    /// ties to the lowest index in the one-sample form (lens position, then
    /// sample), whatever the plan. Where the plan samples a pixel once
    /// (K = 1) and there are several lens positions, lens position i also
    /// moves that sample by [`crate::camera::pixel_jitters`]'s offset i:
    /// the lens positions anti-alias the image together (accum at K = 1).
    /// Then every later layer (of a pinhole
    /// view: one lens position) as one depth peel of the samples the
    /// targets were made for (`peel_samples` of [`GBuffer::new`]) at their
    /// standard locations (unjittered), against the previous
    /// layer's resolved depth, and its resolve: passes `peel.raster` and
    /// `peel.resolve`, the layered method's work, which `bench` counts as
    /// depth of field. A hidden layer is seen only through a blurred
    /// occluder's edge, so it takes fewer samples than the first
    /// (docs/ARCHITECTURE.md, "Layered DOF").
    pub fn record<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        passes: &'r GBufferPasses,
        splats: &'r Buffer,
        count: u32,
        lens: &GBufferLens,
        label: &str,
    ) {
        assert!(
            self.layers.len() == 1 || lens.positions.len() == 1,
            "depth-peeled layers are of one lens position"
        );
        let before = self.record_first_layer(frame, passes, splats, count, lens, label);
        if self.layers.len() == 1 {
            return;
        }
        let lens_u = lens.positions[0];
        if let Some(PeelTargets::Compute { target, scale }) = &self.peel_targets {
            self.record_compute_peel(frame, passes, splats, count, lens_u, target, *scale);
            return;
        }
        self.record_sprite_peel(frame, passes, splats, count, lens_u, before);
    }

    /// Records the first layer's rasters and resolves (band by band, lens
    /// position by lens position, pass by pass of the plan), as
    /// [`GBuffer::record`] tells; returns where its targets were last used.
    fn record_first_layer<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        passes: &'r GBufferPasses,
        splats: &'r Buffer,
        count: u32,
        lens: &GBufferLens,
        label: &str,
    ) -> TargetsBefore {
        let (raster_name, resolve_name) = (format!("{label}.raster"), format!("{label}.resolve"));
        let area_name = format!("{label}.area");
        let samples = self.plan.samples_per_pass;
        let scale = self.plan.scale;
        let per_pass = self.plan.samples_per_pixel_per_pass();
        let per_lens = self.plan.passes.len() as u32 * per_pass;
        let sample_count = lens.positions.len() as u32 * per_lens;
        let extent = match &self.targets {
            FirstTargets::Sprites(t) => [t.sample.width(), t.sample.height()],
            FirstTargets::Compute(v) => [v.width(), v.height()],
        };
        let background = self.background.to_array();
        let mut before = TargetsBefore {
            sample: Access::NONE,
            depth: Access::NONE,
            previous: Access::NONE,
        };
        let height = self.layers[0].color.height();
        let pixel_jitters = match (per_lens, lens.positions.len()) {
            (1, n) if n > 1 => crate::camera::pixel_jitters(n as u32),
            (_, n) => vec![Vec2::ZERO; n],
        };
        // Area coverage resolves the one pass of every sample.
        let marked = self.marked.as_ref().filter(|_| sample_count == per_pass);
        for rows in self.plan.band_rows(height) {
            let target_rows = self.target_rows(rows, height);
            for (i, (l, lens_u, planned)) in self.plan.with_lens(&lens.positions).enumerate() {
                // In target pixels: a one-sample plan's scale is 1.
                let jitter = planned.jitter + pixel_jitters[l as usize];
                let mut push = self.view.push(jitter, lens_u, extent, scale, target_rows.0);
                let sample = match &self.targets {
                    FirstTargets::Sprites(t) => {
                        passes.raster(samples, false).record(
                            frame,
                            &raster_name,
                            &t.sample,
                            &t.depth,
                            None,
                            before,
                            splats,
                            DrawCount::Direct(count),
                            background,
                            &push,
                        );
                        Samples::Target(&t.sample)
                    }
                    FirstTargets::Compute(target) => {
                        // The one-sample form's largest splat, K times
                        // wider: no point-size limit of the target's own.
                        push.max_point_size = self.view.max_point_size * scale as f32;
                        passes.compute().record(
                            frame,
                            &raster_name,
                            target,
                            before.sample,
                            splats,
                            count,
                            &push,
                            scale,
                            None,
                        );
                        Samples::Visibility {
                            target,
                            splats,
                            background,
                            marked,
                        }
                    }
                };
                before.sample = Access::COMPUTE_READ;
                before.depth = Access::DEPTH_WRITE;
                let pass = ResolvePass {
                    first_sample: i as u32 * per_pass,
                    sample_count,
                    read_offsets: planned.read_offsets,
                    index_base: l * per_lens,
                    indices: planned.packed_indices(),
                    scale,
                    rows,
                    target_rows,
                    lens_weight: self.lens_weight(lens_u, lens),
                    color_scale: self.view.color_scale,
                    area_blur: self.area_blur(lens),
                };
                passes
                    .resolve
                    .record(frame, &resolve_name, &self.resolve_images(sample, 0), &pass);
                if let Some(marked) = marked {
                    let rows = (rows, target_rows);
                    self.record_area(frame, passes, splats, marked, rows, &area_name);
                }
            }
        }
        before
    }

    /// The G-buffer rows (first, end) the first layer's target holds for
    /// the band of `rows` of a G-buffer `height` rows tall: a compute
    /// band's holds its neighbours' rows too ([`band_halo_rows`]).
    fn target_rows(&self, rows: (u32, u32), height: u32) -> (u32, u32) {
        match &self.targets {
            FirstTargets::Compute(_) => {
                let halo = band_halo_rows(self.plan.bands);
                (rows.0.saturating_sub(halo), (rows.1 + halo).min(height))
            }
            FirstTargets::Sprites(_) => rows,
        }
    }

    /// Records the area pass of the band of `rows` (its rows, its
    /// target's rows) after its marking resolve, as pass `name`.
    fn record_area<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        passes: &'r GBufferPasses,
        splats: &'r Buffer,
        marked: &'r Marked,
        rows: ((u32, u32), (u32, u32)),
        name: &str,
    ) {
        let FirstTargets::Compute(target) = &self.targets else {
            unreachable!("area coverage is the compute raster's")
        };
        let band = AreaBand {
            target,
            splats,
            marked,
            gbuffer_color: &self.layers[0].color,
            gbuffer_eye: &self.layers[0].eye,
            rows: rows.0,
            target_rows: rows.1,
            scale: self.plan.scale,
            background: self.background.to_array(),
            color_scale: self.view.color_scale,
        };
        passes.area().record(frame, name, &band);
    }

    /// Records every later layer as one depth peel by the sprite raster
    /// (in the peel's own targets, or the first layer's where they have
    /// its samples), culled first where the G-buffer has cull buffers,
    /// and its resolve: passes `peel.raster` and `peel.resolve`. `before`:
    /// where the first layer left its targets.
    fn record_sprite_peel<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        passes: &'r GBufferPasses,
        splats: &'r Buffer,
        count: u32,
        lens_u: Vec2,
        mut before: TargetsBefore,
    ) {
        let peel = match (&self.peel_targets, &self.targets) {
            (Some(PeelTargets::Sprites(p)), _) => p,
            (None, FirstTargets::Sprites(t)) => t,
            _ => unreachable!("a compute plan has peel targets of its own"),
        };
        if self.peel_targets.is_some() {
            before.sample = Access::NONE;
            before.depth = Access::NONE;
        }
        let background = self.background.to_array();
        let height = self.layers[0].color.height();
        let samples = peel.sample.samples();
        let push = self.view.push(
            Vec2::ZERO,
            lens_u,
            [peel.sample.width(), peel.sample.height()],
            1,
            0,
        );
        let mut indices = [0u8; 8];
        for (s, index) in indices.iter_mut().enumerate().take(samples as usize) {
            *index = s as u8;
        }
        for layer in 1..self.layers.len() {
            let previous = &self.layers[layer - 1].eye;
            // The previous layer's depth was last written by its resolve.
            before.previous = Access::COMPUTE_READ_WRITE;
            let (vertices, draw) = match &self.peel_cull {
                Some(cull) => {
                    passes
                        .peel_cull
                        .record(frame, splats, previous, cull, &push);
                    before.previous = Access::COMPUTE_READ;
                    (&cull.kept, DrawCount::Indirect(&cull.draw))
                }
                None => (splats, DrawCount::Direct(count)),
            };
            passes.raster(samples, true).record(
                frame,
                "peel.raster",
                &peel.sample,
                &peel.depth,
                Some(previous),
                before,
                vertices,
                draw,
                background,
                &push,
            );
            let pass = ResolvePass {
                first_sample: 0,
                sample_count: samples,
                read_offsets: 0,
                index_base: 0,
                indices: PlannedPass::pack_indices(indices),
                scale: 1,
                rows: (0, height),
                target_rows: (0, height),
                lens_weight: LensWeight::ONE,
                color_scale: self.view.color_scale,
                area_blur: [0.0; 6],
            };
            passes.resolve.record(
                frame,
                "peel.resolve",
                &self.resolve_images(Samples::Target(&peel.sample), layer),
                &pass,
            );
            before.sample = Access::COMPUTE_READ;
            before.depth = Access::DEPTH_WRITE;
        }
    }

    /// Records every later layer as one depth peel by the compute
    /// rasteriser into `target` (`scale` times the G-buffer's size, the
    /// upscaled plan's grid of scale² samples per pixel, unjittered)
    /// against the previous layer's resolved depth, and its resolve:
    /// passes `peel.raster` and `peel.resolve`.
    #[allow(clippy::too_many_arguments)]
    fn record_compute_peel<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        passes: &'r GBufferPasses,
        splats: &'r Buffer,
        count: u32,
        lens_u: Vec2,
        target: &'r Visibility,
        scale: u32,
    ) {
        let height = self.layers[0].color.height();
        let extent = [target.width(), target.height()];
        let mut push = self.view.push(Vec2::ZERO, lens_u, extent, scale, 0);
        // The one-sample form's largest splat, `scale` times wider.
        push.max_point_size = self.view.max_point_size * scale as f32;
        let background = self.background.to_array();
        let mut before = Access::NONE;
        for layer in 1..self.layers.len() {
            let previous = &self.layers[layer - 1].eye;
            passes.compute().record(
                frame,
                "peel.raster",
                target,
                before,
                splats,
                count,
                &push,
                scale,
                Some(previous),
            );
            let sample = Samples::Visibility {
                target,
                splats,
                background,
                marked: None,
            };
            let pass = ResolvePass {
                first_sample: 0,
                sample_count: scale * scale,
                read_offsets: 0,
                index_base: 0,
                indices: [0, 0],
                scale,
                rows: (0, height),
                target_rows: (0, height),
                lens_weight: LensWeight::ONE,
                color_scale: self.view.color_scale,
                area_blur: [0.0; 6],
            };
            passes.resolve.record(
                frame,
                "peel.resolve",
                &self.resolve_images(sample, layer),
                &pass,
            );
            before = Access::COMPUTE_READ;
        }
    }

    /// The lens that blurs the G-buffer after it and the CoC past which
    /// the area resolve leaves a pixel ([`ResolvePass::area_blur`]): the
    /// camera's, where `lens` says the method blurs through it. A shape
    /// blurs a point less far across than its CoC's disk: the limit grows
    /// by the shape's least reach ([`crate::camera::Aperture::least_reach`]),
    /// and with the cat's eye by what each pixel's clipped lens leaves of
    /// it, which the resolve works out
    /// ([`crate::camera::Aperture::cat_eye_blur_reach`]); an aperture
    /// image may blur a point hardly at all, and its frames mark every
    /// pixel, as the pinhole's do.
    fn area_blur(&self, lens: &GBufferLens) -> [f32; 6] {
        let camera = &self.view.frame.camera;
        let aperture = &camera.aperture;
        let limit_px = crate::passes::gbuffer_area::AREA_BLUR_LIMIT_PX;
        match aperture.least_reach() {
            Some(reach) if lens.blurred_after && camera.aperture_radius > 0.0 => {
                // The limit grows by the shape's reach here, or with the
                // cat's eye by each pixel's in the resolve.
                let (limit_px, cat_eye, shape_reach) = match aperture.cat_eye > 0.0 {
                    true => (limit_px, aperture.cat_eye, reach),
                    false => (limit_px / reach, 0.0, 0.0),
                };
                [
                    camera.f_px(),
                    camera.aperture_radius,
                    camera.focus_distance,
                    limit_px,
                    cat_eye,
                    shape_reach,
                ]
            }
            _ => [0.0; 6],
        }
    }

    /// How the G-buffer's pixels weigh lens position `lens_u`, one of
    /// `lens`'s, by its cat's eye (0: alike).
    fn lens_weight(&self, lens_u: Vec2, lens: &GBufferLens) -> LensWeight {
        let frame = &self.view.frame;
        let guard = frame.guard as i32;
        LensWeight {
            lens_u,
            window_origin: [frame.window.x as i32 - guard, frame.window.y as i32 - guard],
            frame_size: [frame.camera.width, frame.camera.height],
            cat_eye: lens.cat_eye,
            half_cell: crate::camera::Aperture::lens_cell_half_width(lens.positions.len() as u32),
        }
    }

    fn resolve_images<'a>(&'a self, sample: Samples<'a>, layer: usize) -> ResolveImages<'a> {
        ResolveImages {
            sample,
            color_sum: &self.color_sums[layer],
            gbuffer_eye: &self.layers[layer].eye,
            gbuffer_color: &self.layers[layer].color,
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
