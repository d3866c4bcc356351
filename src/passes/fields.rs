//! The bounded two-field gather (`--fast-gather fields`; issue 28, item 5;
//! `crate::fields` has its constants, tables and CPU reference) as compute
//! passes, each beside its GLSL file: `fields_far` (the far field's mip,
//! one dispatch per level), `fields_bands` (each band texel's sources),
//! `fields_spread` (the bands' spread) and `fields_resolve` (per output
//! pixel: bands, rings, composite).

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::kernel_sizes::KernelSizes;
use super::{DofFrame, DofInput, FrameView, Window};
use crate::error::{Error, Result};
use crate::fields::{tables, LEVELS};
use crate::push_constants;
use crate::vk::{groups, Access, Bind, Binding, Buffer, ComputePipeline, Context, Frame, Image};

static FAR: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fields_far.comp.spv"));
static BANDS: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fields_bands.comp.spv"));
static SPREAD: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fields_spread.comp.spv"));
static RESOLVE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fields_resolve.comp.spv"));

push_constants! {
    /// The push block of every pass (`glsl/fields.glsl`).
    pub struct FieldsPush {
        extent: [i32; 2],
        origin: [i32; 2],
        size: [i32; 2],
        anchor: [i32; 2],
        f_px: f32,
        aperture_radius: f32,
        focus_distance: f32,
        level: i32,
    }
}

/// The pipelines of the gather, and its tables (`fields::tables`, built
/// once).
pub struct Fields {
    far: ComputePipeline<FieldsPush>,
    bands: ComputePipeline<FieldsPush>,
    /// The bands' coarse levels a workgroup per texel, from this level
    /// ([`KernelSizes::bands_shared_level`]).
    bands_shared: Option<(u32, ComputePipeline<FieldsPush>)>,
    spread: ComputePipeline<FieldsPush>,
    resolve: ComputePipeline<FieldsPush>,
    tables: Buffer,
}

impl Fields {
    /// The gather's pipelines, its bands cut as `sizes` says.
    pub fn new(ctx: &Arc<Context>, sizes: KernelSizes) -> Result<Fields> {
        use Binding::{StorageBuffer as B, StorageImage as I};
        Ok(Fields {
            far: ComputePipeline::new(ctx, "fields_far", FAR, &[I, I, B, B])?,
            bands: ComputePipeline::new(ctx, "fields_bands", BANDS, &[I, I, B])?,
            bands_shared: bands_shared(ctx, sizes)?,
            spread: ComputePipeline::new(ctx, "fields_spread", SPREAD, &[B, B])?,
            resolve: ComputePipeline::new(ctx, "fields_resolve", RESOLVE, &[I, I, B, B, B, B, I])?,
            tables: Buffer::with_bytes(
                ctx,
                "fields tables",
                bytemuck::cast_slice(&tables()),
                vk::BufferUsageFlags::STORAGE_BUFFER,
            )?,
        })
    }
}

/// The bands' pipeline for shared texels and its first level, where
/// `sizes` shares any.
fn bands_shared(
    ctx: &Arc<Context>,
    sizes: KernelSizes,
) -> Result<Option<(u32, ComputePipeline<FieldsPush>)>> {
    use Binding::{StorageBuffer as B, StorageImage as I};
    let Some(level) = sizes.bands_shared_level else {
        return Ok(None);
    };
    let pipeline = ComputePipeline::specialized(
        ctx,
        "fields_bands (shared)",
        BANDS,
        &[I, I, B],
        &KernelSizes::bands_shared_constants(),
    )?;
    Ok(Some((level.clamp(1, LEVELS), pipeline)))
}

/// Texels of levels `from..=to` of a `w`×`h` G-buffer (level l: 2^l px a
/// texel, the last partial texel included).
fn texels(w: u32, h: u32, from: u32, to: u32) -> u64 {
    (from..=to)
        .map(|l| w.div_ceil(1 << l) as u64 * h.div_ceil(1 << l) as u64)
        .sum()
}

/// The anchor of a window's texels: G-buffer pixel g lies in texel
/// (g + anchor) >> l of level l, so that a tile's texels are the whole
/// frame's. A window's G-buffer starts `window.x` pixels (less the guard
/// band, the same for every window) right of the whole frame's; the
/// largest texel is 2^LEVELS pixels.
pub fn anchor(window: &Window) -> [u32; 2] {
    let top = 1 << LEVELS;
    [window.x % top, window.y % top]
}

/// The buffers and the result of one frame, with the pipelines that
/// record it.
pub struct FieldsFrame<'m> {
    pipelines: &'m Fields,
    /// [`anchor`] of the frame's window.
    anchor: [u32; 2],
    /// The far mip's c · far per texel, levels 0..=LEVELS end to end.
    far_color: Buffer,
    /// The far mip's (far, r · far, far / z, 0).
    far_rest: Buffer,
    /// Per band texel (levels 1..=LEVELS): per set, colour and
    /// (weight, rho, centroid), divided by its spread.
    band_sources: Buffer,
    /// Per band texel: near colour, all colour, (near, all weight).
    bands: Buffer,
    /// The result: G-buffer sized, written inside the guard band only.
    result: Image,
}

impl<'m> FieldsFrame<'m> {
    pub fn new(ctx: &Arc<Context>, pipelines: &'m Fields, view: &FrameView) -> Result<Self> {
        let (w, h) = (view.full_width(), view.full_height());
        let anchor = anchor(&view.window);
        // The texels cover the G-buffer and the anchor's pixels before it.
        let (tw, th) = (w + anchor[0], h + anchor[1]);
        let far = texels(tw, th, 0, LEVELS);
        let band = texels(tw, th, 1, LEVELS);
        let largest = [16 * far, 64 * band, 48 * band]
            .into_iter()
            .max()
            .unwrap_or(0);
        let limit = ctx.info.largest_storage_buffer_bytes();
        // The shaders' indices are 32-bit.
        if largest > limit || 4 * far > u32::MAX as u64 {
            return Err(Error::InvalidArgument(format!(
                "the two-field gather's buffers for a {w}×{h} G-buffer ({largest} bytes) exceed the device's {limit}-byte buffer limit; use --tile-px (smaller tiles) or --fast-gather tree"
            )));
        }
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let buffer = |name, bytes| Buffer::new(ctx, name, bytes, usage, MemoryLocation::GpuOnly);
        Ok(FieldsFrame {
            pipelines,
            anchor,
            far_color: buffer("fields far colour", 16 * far)?,
            far_rest: buffer("fields far rest", 16 * far)?,
            band_sources: buffer("fields band sources", 64 * band)?,
            bands: buffer("fields bands", 48 * band)?,
            result: Image::new_2d(
                ctx,
                "fields result",
                vk::Format::R16G16B16A16_SFLOAT,
                w,
                h,
                1,
                vk::ImageUsageFlags::STORAGE | vk::ImageUsageFlags::TRANSFER_SRC,
            )?,
        })
    }
}

impl DofFrame for FieldsFrame<'_> {
    fn record<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>) -> &'r Image {
        let p = self.pipelines;
        let view = &input.view;
        let camera = &view.camera;
        let (w, h) = (input.color.width(), input.color.height());
        let g = view.guard as i32;
        // The texels' extent: the G-buffer and the anchor's pixels.
        let (tw, th) = (w + self.anchor[0], h + self.anchor[1]);
        let push = |level: u32| FieldsPush {
            extent: [w as i32, h as i32],
            origin: [g, g],
            size: [view.window.width as i32, view.window.height as i32],
            anchor: self.anchor.map(|a| a as i32),
            f_px: camera.f_px(),
            aperture_radius: camera.aperture_radius,
            focus_distance: camera.focus_distance,
            level: level as i32,
        };
        let gbuffer = [
            (input.color, Access::COMPUTE_WRITE, Access::COMPUTE_READ),
            (input.eye, Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ),
        ];
        frame.pass("fast.fields_far", |rec| {
            rec.barriers(&gbuffer);
            // Buffers a pool may hand on from a previous frame's reads.
            rec.memory_barrier(Access::COMPUTE_READ, Access::COMPUTE_WRITE);
            for level in 0..=LEVELS {
                if level > 0 {
                    rec.memory_barrier(Access::COMPUTE_WRITE, Access::COMPUTE_READ_WRITE);
                }
                rec.dispatch(
                    &p.far,
                    &[
                        Bind::StorageImage(input.color),
                        Bind::StorageImage(input.eye),
                        Bind::StorageBuffer(&self.far_color),
                        Bind::StorageBuffer(&self.far_rest),
                    ],
                    &push(level),
                    [
                        groups(tw.div_ceil(1 << level), 8),
                        groups(th.div_ceil(1 << level), 8),
                        1,
                    ],
                );
            }
        });
        frame.pass("fast.fields_bands", |rec| {
            let binds = [
                Bind::StorageImage(input.color),
                Bind::StorageImage(input.eye),
                Bind::StorageBuffer(&self.band_sources),
            ];
            // Levels 1 to `alone` an invocation per texel, the rest (a
            // GPU's) a workgroup per texel: their own parts of the buffer.
            let alone = p.bands_shared.as_ref().map_or(LEVELS, |(from, _)| from - 1);
            if alone > 0 {
                let texels = |n: u32| groups(n.div_ceil(2), 8);
                rec.dispatch(&p.bands, &binds, &push(1), [texels(tw), texels(th), alone]);
            }
            if let Some((from, shared)) = &p.bands_shared {
                rec.memory_barrier(Access::COMPUTE_WRITE, Access::COMPUTE_WRITE);
                let texels = |n: u32| n.div_ceil(1 << from);
                rec.dispatch(
                    shared,
                    &binds,
                    &push(*from),
                    [texels(tw), texels(th), LEVELS - from + 1],
                );
            }
        });
        frame.pass("fast.fields_spread", |rec| {
            rec.memory_barrier(Access::COMPUTE_WRITE, Access::COMPUTE_READ);
            rec.dispatch(
                &p.spread,
                &[
                    Bind::StorageBuffer(&self.band_sources),
                    Bind::StorageBuffer(&self.bands),
                ],
                &push(1),
                [groups(tw.div_ceil(2), 8), groups(th.div_ceil(2), 8), LEVELS],
            );
        });
        frame.pass("fast.fields_resolve", |rec| {
            rec.memory_barrier(Access::COMPUTE_WRITE, Access::COMPUTE_READ);
            rec.barriers(&[(&self.result, Access::NONE, Access::COMPUTE_WRITE)]);
            rec.dispatch(
                &p.resolve,
                &[
                    Bind::StorageImage(input.color),
                    Bind::StorageImage(input.eye),
                    Bind::StorageBuffer(&self.far_color),
                    Bind::StorageBuffer(&self.far_rest),
                    Bind::StorageBuffer(&self.bands),
                    Bind::StorageBuffer(&p.tables),
                    Bind::StorageImage(&self.result),
                ],
                &push(0),
                [
                    groups(view.window.width, 8),
                    groups(view.window.height, 8),
                    1,
                ],
            );
        });
        &self.result
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fields::{
        band_offsets, ring_taps, small_radius, OverlapTable, B0, BAND, DISK_COUNT_MAX,
        HALF_DIAGONAL, RINGS, TABLE_STEPS,
    };
    use crate::vk::check_push_layout;

    #[test]
    fn push_constants_match_the_glsl_blocks() {
        check_push_layout::<FieldsPush>("fields_far", FAR).unwrap();
        check_push_layout::<FieldsPush>("fields_bands", BANDS).unwrap();
        check_push_layout::<FieldsPush>("fields_spread", SPREAD).unwrap();
        check_push_layout::<FieldsPush>("fields_resolve", RESOLVE).unwrap();
    }

    #[test]
    fn constants_match_the_glsl() {
        let glsl = include_str!("../../glsl/fields.glsl");
        let has = |line: String| assert!(glsl.contains(&line), "glsl/fields.glsl lacks `{line}`");
        has(format!("const float FIELDS_B0 = {B0:?};"));
        has(format!("const float FIELDS_BAND = {BAND:?};"));
        has(format!("const int FIELDS_RINGS = {RINGS};"));
        has(format!("const int FIELDS_LEVELS = {LEVELS};"));
        has(format!("const int FIELDS_STEPS = {TABLE_STEPS};"));
        has(format!(
            "const float FIELDS_HALF_DIAGONAL = {HALF_DIAGONAL};"
        ));
        has(format!("const int FIELDS_COUNT_MAX = {DISK_COUNT_MAX};"));
        let rows = |r| OverlapTable::new(r).offsets.len();
        has(format!("const int FIELDS_T0_ROWS = {};", rows(B0)));
        has(format!(
            "const int FIELDS_T1_ROWS = {};",
            rows(small_radius())
        ));
        let reach = (BAND + 0.5 + HALF_DIAGONAL).ceil() as i32;
        has(format!("const int FIELDS_BAND_REACH = {reach};"));
        assert!(band_offsets()
            .iter()
            .all(|d| d[0].abs() <= reach && d[1].abs() <= reach));
        assert_eq!(ring_taps().len() as u32, 1 + 4 * RINGS * (RINGS + 1));
    }
}
