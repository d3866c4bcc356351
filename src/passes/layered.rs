//! Yu et al.'s layered depth of field (DESIGN §6) as four compute passes
//! after a depth-peeled G-buffer (`GBuffer` with K layers; the peel is
//! `glsl/splat_peel.frag`):
//!
//! 1. `layered.tiles`: per tile of the first layer, the farthest depth and
//!    the largest CoC of its points (the occluders);
//! 2. `layered.prepare`, per layer: each covered pixel as a fragment
//!    (premultiplied color, coverage, signed CoC, and the radius it
//!    spreads with: `spread_disk`); layers after the first
//!    keep only the pixels the modified peel finds visible through the
//!    lens, and count kept and discarded pixels;
//! 3. `layered.spread`, per depth slice, over the tiles prepare listed for
//!    it (an indirect dispatch): Kosloff et al.'s spreading, the
//!    fragments' row spans as signed differences in fixed point;
//! 4. `layered.composite`, per slice, back to front: the prefix sums along
//!    the rows (over the columns the spread touched), each slice
//!    normalised and laid over what is behind it with its spread coverage
//!    as alpha.
//!
//! Fragments go to depth slices of equal signed-CoC width rather than
//! spreading within their peel layer: a peel layer holds surfaces of any
//! depth side by side (the first holds everything the pinhole sees), and
//! normalising a blurred background with a sharp foreground in one layer
//! is the intensity leakage the method must avoid. See docs/ARCHITECTURE.md.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::kernel_sizes::KernelSizes;
use super::{
    spread_disk, Configured, DofFrame, DofInput, DofMethod, FrameView, Specialized,
    APERTURE_CODE_ID,
};
use crate::camera::{Camera, ShapeRows};
use crate::error::{Error, Result};
use crate::options::{check_layers, LayeredOptions};
use crate::push_constants;
use crate::vk::{groups, Access, Bind, Binding, Buffer, ComputePipeline, Context, Frame, Image};

/// Tile edge of the occluder tiles, pixels.
pub const TILE: u32 = 16;
/// Signed-CoC width of a depth slice, pixels: two fragments in one slice
/// differ in CoC by at most this, so what one smears over the other is at
/// most half of it.
pub const SLICE_COC_PX: f32 = 4.0;
/// The most depth slices of a frame (wider slices beyond).
pub const MAX_SLICES: u32 = 16;
/// Fractional bits of the spreading's fixed-point sums (mirrors
/// `glsl/layered_fixed.glsl`): a channel's sum at a pixel must stay below
/// 2^(31 − 22) = 512.
pub const FRACTION_BITS: u32 = 22;
/// The part of a slice, from its near edge, whose fragments also go to
/// the next nearer slice with a falling weight (mirrors
/// `glsl/layered_slices.glsl`).
pub const RAMP: f32 = 0.5;

static TILES: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layered_tiles.comp.spv"));
static PREPARE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layered_prepare.comp.spv"));
static SPREAD: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layered_spread.comp.spv"));
static COMPOSITE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/layered_composite.comp.spv"));

push_constants! {
    /// Push constants of every pass; mirrors `glsl/layered_push.glsl`.
    struct LayeredPush {
        background: [f32; 4],
        extent: [i32; 2],
        tiles: [i32; 2],
        tile: i32,
        layer: i32,
        layers: i32,
        slice: i32,
        slices: i32,
        band_y0: i32,
        band_rows: i32,
        keep_occluded: u32,
        f_px: f32,
        aperture_radius: f32,
        focus_distance: f32,
        max_coc_px: f32,
        slice_lo: f32,
        slice_width: f32,
        gaussian_layers: u32,
        shaped: u32,
        shape_y_min: f32,
        shape_y_max: f32,
        shape_rows: i32,
        cat_eye: f32,
        frame_offset: [i32; 2],
        frame_size: [i32; 2],
    }
}

/// The four pipelines of the method.
pub struct Layered {
    tiles: ComputePipeline<LayeredPush>,
    prepare: ComputePipeline<LayeredPush>,
    spread: Option<Specialized<LayeredPush>>,
    /// In the form `sizes` chooses.
    composite: Option<ComputePipeline<LayeredPush>>,
    sizes: KernelSizes,
}

/// The composite in the form of `sizes` (None without 64-bit atomics).
fn composite_pipeline(
    ctx: &Arc<Context>,
    sizes: KernelSizes,
) -> Result<Option<ComputePipeline<LayeredPush>>> {
    use Binding::{StorageBuffer as B, StorageImage as I};
    match ctx.info.buffer_int64_atomics {
        true => Ok(Some(ComputePipeline::specialized(
            ctx,
            "layered_composite",
            COMPOSITE,
            &[B, I, I, B],
            &sizes.composite_constants(),
        )?)),
        false => Ok(None),
    }
}

impl Layered {
    /// [`super::Methods::set_round_pipelines`] for the spread.
    pub(super) fn set_round_pipelines(&mut self, enabled: bool) {
        if let Some(spread) = &mut self.spread {
            spread.set_enabled(enabled);
        }
    }

    /// The method's pipelines, its passes cut as `sizes` says
    /// ([`KernelSizes::for_device`], or another cut for the test that the
    /// cuts agree).
    pub fn new(ctx: &Arc<Context>, sizes: KernelSizes) -> Result<Layered> {
        use Binding::{StorageBuffer as B, StorageImage as I};
        // The spreading sums in 64-bit integers: without 64-bit buffer
        // atomics the method reports that it cannot run (`prepare`).
        let int64 = ctx.info.buffer_int64_atomics;
        Ok(Layered {
            tiles: ComputePipeline::new(ctx, "layered_tiles", TILES, &[I, I])?,
            prepare: ComputePipeline::new(
                ctx,
                "layered_prepare",
                PREPARE,
                &[I, I, I, I, I, I, B, B, B, B],
            )?,
            spread: match int64 {
                true => Some(Specialized::with_base(
                    ctx,
                    "layered_spread",
                    SPREAD,
                    &[I, I, B, B, B, B, B, B],
                    &sizes.spread_constants(),
                    "round",
                    (APERTURE_CODE_ID, 0),
                )?),
                false => None,
            },
            composite: composite_pipeline(ctx, sizes)?,
            sizes,
        })
    }
}

/// The depth slices of a view: M slices of equal signed-CoC width over the
/// points' signed-CoC range, nearest first (`glsl/layered_spread.comp`
/// places the fragments in them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slices {
    pub count: u32,
    /// Signed CoC (px) of slice 0's near edge.
    pub lo: f32,
    /// Signed CoC (px) per slice.
    pub width: f32,
}

impl Slices {
    /// The slices for points at eye depths `depths` (None: no point).
    pub fn of(camera: &Camera, depths: Option<(f32, f32)>) -> Slices {
        let Some((near, far)) = depths else {
            return Slices {
                count: 1,
                lo: 0.0,
                width: 1.0,
            };
        };
        let (lo, hi) = (camera.signed_coc_px(near), camera.signed_coc_px(far));
        let count = (((hi - lo) / SLICE_COC_PX).ceil() as u32).clamp(1, MAX_SLICES);
        // A little wider than the range, so that its far end falls inside
        // the last slice.
        let width = ((hi - lo) / count as f32 * (1.0 + 1e-4)).max(1e-3);
        Slices { count, lo, width }
    }
}

impl DofMethod for Configured<'_, Layered, LayeredOptions> {
    fn gbuffer_layers(&self) -> u32 {
        self.options.layers
    }

    /// The points' largest CoC: the background is a uniform color that no
    /// pass spreads.
    fn guard_coc_px(&self, camera: &Camera, depths: Option<(f32, f32)>) -> f32 {
        depths.map_or(0.0, |(lo, hi)| camera.max_coc_px(lo, hi))
    }

    fn prepare<'m>(
        &'m self,
        ctx: &Arc<Context>,
        view: &FrameView,
    ) -> Result<Box<dyn DofFrame + 'm>> {
        check_layers(self.options.layers)?;
        let slices = Slices::of(&view.camera, view.depths);
        self.pipelines.frame(ctx, view, self.options, slices, false)
    }
}

impl Layered {
    /// The frame of the method over `layers` depth layers of 3D Gaussians
    /// (`crate::gaussian_render`): one slice each (`slices`, as many as
    /// the layers), no ramp between slices, signed light, every pixel kept.
    pub fn prepare_gaussian_layers<'m>(
        &'m self,
        ctx: &Arc<Context>,
        view: &FrameView,
        slices: Slices,
    ) -> Result<Box<dyn DofFrame + 'm>> {
        let options = LayeredOptions {
            layers: slices.count,
            keep_occluded: true,
        };
        check_layers(options.layers)?;
        self.frame(ctx, view, options, slices, true)
    }

    /// The frame's images and passes over `slices`; an error where the
    /// device lacks 64-bit buffer atomics.
    fn frame<'m>(
        &'m self,
        ctx: &Arc<Context>,
        view: &FrameView,
        options: LayeredOptions,
        slices: Slices,
        gaussian_layers: bool,
    ) -> Result<Box<dyn DofFrame + 'm>> {
        let (Some(spread), Some(composite)) = (&self.spread, &self.composite) else {
            return Err(Error::VulkanSetup(
                "the layered method needs 64-bit integer atomics on storage buffers \
                 (shaderBufferInt64Atomics), which this device lacks"
                    .into(),
            ));
        };
        Ok(Box::new(LayeredFrame {
            gaussian_layers,
            pipelines: self,
            spread: spread.for_aperture(&view.camera.aperture),
            composite,
            options,
            slices,
            images: LayeredImages::new(ctx, view, options.layers, slices.count)?,
        }))
    }
}

/// The images and buffers of one frame.
struct LayeredImages {
    occluder_tiles: Image,
    /// Per layer (array layer): premultiplied color and coverage.
    fragment_color: Image,
    /// Per layer: signed CoC and the spread radius (`spread_disk`), both
    /// px; a radius of 0 where the pixel has no surface.
    fragment_coc: Image,
    /// The spread radius per CoC (`spread_disk::radius_table_words`).
    spread_radius: Buffer,
    /// An aperture image's spans and their buffers (offsets, spans).
    spans: Option<crate::camera::ShapeSpans>,
    span_offsets: Buffer,
    span_list: Buffer,
    /// A shaped aperture's chords (None: the round disk).
    shape: Option<ShapeRows>,
    /// The chords on the device (one unused entry for the disk).
    shape_chords: Buffer,
    /// Two 64-bit words per pixel of one band of rows.
    differences: Buffer,
    /// Per row of the band, the columns a slice's differences touch (two
    /// words, 0 for none): the composite skips the rest.
    row_spans: Buffer,
    band_rows: u32,
    /// What lies behind the slices composited so far.
    behind: Image,
    result: Image,
    /// Kept and discarded pixels per layer (host-visible).
    counts: Buffer,
    /// Per slice, the 8×8 tiles of pixels (workgroups of prepare and of
    /// the spread) with kept fragments in it, as layer × tiles + tile:
    /// room for every tile of every layer.
    slice_lists: Buffer,
    /// Per slice, the spread's workgroup counts (`VkDispatchIndirectCommand`:
    /// the length of its list, 1, 1).
    slice_dispatch: Buffer,
}

/// Bytes of the row differences per pixel.
const DIFFERENCE_BYTES: u64 = 16;

impl LayeredImages {
    fn new(
        ctx: &Arc<Context>,
        view: &FrameView,
        layers: u32,
        slices: u32,
    ) -> Result<LayeredImages> {
        let (w, h) = (view.full_width(), view.full_height());
        let (tw, th) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let storage = vk::ImageUsageFlags::STORAGE;
        // The fragment images are read as arrays: two layers at least, so
        // that their views are arrays for one layer too.
        let image = |name, format, l: u32| Image::new_2d(ctx, name, format, w, h, l, storage);
        let array_layers = layers.max(2);
        // The differences of as many rows as one binding and a quarter of
        // the heap hold; a frame of more rows runs in bands.
        let info = &ctx.info;
        let limit = info
            .largest_storage_buffer_bytes()
            .min(info.device_local_heap_bytes / 4);
        let row_bytes = w as u64 * DIFFERENCE_BYTES;
        let band_rows = (limit / row_bytes).min(h as u64) as u32;
        if band_rows == 0 {
            return Err(Error::InvalidArgument(format!(
                "the layered method's row differences for a {w} px wide G-buffer ({row_bytes} bytes a row) exceed the device's {limit}-byte buffer limit"
            )));
        }
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_DST;
        let list_bytes =
            4 * slices as u64 * groups(w, 8) as u64 * groups(h, 8) as u64 * layers as u64;
        if list_bytes > limit {
            return Err(Error::InvalidArgument(format!(
                "the layered method's tile lists for a {w}×{h} G-buffer, {layers} layers and {slices} slices ({list_bytes} bytes) exceed the device's {limit}-byte buffer limit; use fewer --layers"
            )));
        }
        let table: &[u8] = bytemuck::cast_slice(spread_disk::radius_table_words());
        let spread_radius = Buffer::with_bytes(
            ctx,
            "layered spread radius",
            table,
            vk::BufferUsageFlags::STORAGE_BUFFER,
        )?;
        let (shape, shape_chords) = super::shape_chords(ctx, &view.camera, "layered")?;
        let (spans, span_offsets, span_list) = super::shape_spans(ctx, &view.camera, "layered")?;
        Ok(LayeredImages {
            spread_radius,
            shape,
            shape_chords,
            spans,
            span_offsets,
            span_list,
            occluder_tiles: Image::new_2d(
                ctx,
                "layered occluder tiles",
                vk::Format::R32G32_SFLOAT,
                tw,
                th,
                1,
                storage,
            )?,
            fragment_color: image(
                "layered fragment color",
                vk::Format::R32G32B32A32_SFLOAT,
                array_layers,
            )?,
            fragment_coc: image(
                "layered fragment coc",
                vk::Format::R32G32_SFLOAT,
                array_layers,
            )?,
            differences: Buffer::new(
                ctx,
                "layered differences",
                band_rows as u64 * row_bytes,
                usage,
                MemoryLocation::GpuOnly,
            )?,
            row_spans: Buffer::new(
                ctx,
                "layered row spans",
                8 * band_rows as u64,
                usage,
                MemoryLocation::GpuOnly,
            )?,
            band_rows,
            behind: image("layered behind", vk::Format::R32G32B32A32_SFLOAT, 1)?,
            // Read by the output pass, or copied (Gaussians' readback).
            result: Image::new_2d(
                ctx,
                "layered result",
                vk::Format::R16G16B16A16_SFLOAT,
                w,
                h,
                1,
                storage | vk::ImageUsageFlags::TRANSFER_SRC,
            )?,
            counts: Buffer::new(
                ctx,
                "layered counts",
                2 * 4 * layers as u64,
                usage,
                MemoryLocation::GpuToCpu,
            )?,
            slice_lists: Buffer::new(
                ctx,
                "layered slice lists",
                list_bytes,
                usage,
                MemoryLocation::GpuOnly,
            )?,
            slice_dispatch: Buffer::new(
                ctx,
                "layered slice dispatch",
                12 * slices as u64,
                usage | vk::BufferUsageFlags::INDIRECT_BUFFER,
                MemoryLocation::GpuOnly,
            )?,
        })
    }
}

struct LayeredFrame<'m> {
    pipelines: &'m Layered,
    spread: &'m ComputePipeline<LayeredPush>,
    composite: &'m ComputePipeline<LayeredPush>,
    options: LayeredOptions,
    slices: Slices,
    /// The layers are Gaussians' (`LayeredPush::gaussian_layers`).
    gaussian_layers: bool,
    images: LayeredImages,
}

impl LayeredFrame<'_> {
    /// The push constants every pass of the frame starts from (layer,
    /// slice and band 0), for the G-buffer of `input`.
    fn base_push(&self, input: &DofInput) -> LayeredPush {
        let images = &self.images;
        let view = &input.view;
        let camera = &view.camera;
        let (w, h) = (input.color.width(), input.color.height());
        let layers = input.layers.len() as u32;
        let tiles = [
            images.occluder_tiles.width() as i32,
            images.occluder_tiles.height() as i32,
        ];
        let b = input.background;
        // The aperture: 0 the disk, 1 a shape's chords, 2 an image's spans.
        let (shaped, shape_y_min, shape_y_max, shape_rows) = match (&images.shape, &images.spans) {
            (_, Some(s)) => (2, s.y_min, s.y_max, s.offsets.len() as i32 - 1),
            (Some(s), None) => (1, s.y_min, s.y_max, s.chords.len() as i32),
            (None, None) => (0, 0.0, 0.0, 1),
        };
        LayeredPush {
            background: [b.x, b.y, b.z, 0.0],
            extent: [w as i32, h as i32],
            tiles,
            tile: TILE as i32,
            layer: 0,
            layers: layers as i32,
            slice: 0,
            slices: self.slices.count as i32,
            band_y0: 0,
            band_rows: images.band_rows as i32,
            keep_occluded: u32::from(self.options.keep_occluded),
            f_px: camera.f_px(),
            aperture_radius: camera.aperture_radius,
            focus_distance: camera.focus_distance,
            max_coc_px: view.max_coc_px,
            slice_lo: self.slices.lo,
            slice_width: self.slices.width,
            gaussian_layers: u32::from(self.gaussian_layers),
            shaped,
            shape_y_min,
            shape_y_max,
            shape_rows,
            cat_eye: camera.aperture.cat_eye,
            frame_offset: [
                view.window.x as i32 - view.guard as i32,
                view.window.y as i32 - view.guard as i32,
            ],
            frame_size: [camera.width as i32, camera.height as i32],
        }
    }

    /// Passes `layered.tiles`, `layered.prepare` and `layered.clear`: the
    /// occluder tiles of the first layer; every layer's covered pixels as
    /// fragments, each tile listed for the depth slices it spreads in
    /// (kept and discarded pixels counted for [`DofFrame::counts`]); the
    /// spread's buffers cleared.
    fn record_fragments<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        input: &DofInput<'r>,
        base: &LayeredPush,
    ) {
        let p = self.pipelines;
        let images = &self.images;
        let (w, h) = (input.color.width(), input.color.height());
        let tiles = base.tiles;
        let pixels = [groups(w, 8), groups(h, 8), 1];
        let first = &input.layers[0];
        frame.pass("layered.tiles", |rec| {
            let mut list = vec![(&images.occluder_tiles, Access::NONE, Access::COMPUTE_WRITE)];
            for l in input.layers {
                list.push((&l.eye, Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ));
                list.push((&l.color, Access::COMPUTE_WRITE, Access::COMPUTE_READ));
            }
            rec.barriers(&list);
            rec.dispatch(
                &p.tiles,
                &[
                    Bind::StorageImage(&first.eye),
                    Bind::StorageImage(&images.occluder_tiles),
                ],
                base,
                [groups(tiles[0] as u32, 8), groups(tiles[1] as u32, 8), 1],
            );
        });
        frame.pass("layered.prepare", |rec| {
            rec.fill_u32(&images.counts, 0);
            let dispatch: Vec<u32> = (0..self.slices.count).flat_map(|_| [0, 1, 1]).collect();
            rec.update_u32(&images.slice_dispatch, &dispatch);
            rec.memory_barrier(Access::FILL, Access::COMPUTE_READ_WRITE);
            rec.barriers(&[
                (
                    &images.occluder_tiles,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_READ,
                ),
                (&images.fragment_color, Access::NONE, Access::COMPUTE_WRITE),
                (&images.fragment_coc, Access::NONE, Access::COMPUTE_WRITE),
            ]);
            for (l, layer) in input.layers.iter().enumerate() {
                rec.dispatch(
                    &p.prepare,
                    &[
                        Bind::StorageImage(&layer.color),
                        Bind::StorageImage(&layer.eye),
                        Bind::StorageImage(&first.eye),
                        Bind::StorageImage(&images.occluder_tiles),
                        Bind::StorageImage(&images.fragment_color),
                        Bind::StorageImage(&images.fragment_coc),
                        Bind::StorageBuffer(&images.counts),
                        Bind::StorageBuffer(&images.slice_lists),
                        Bind::StorageBuffer(&images.spread_radius),
                        Bind::StorageBuffer(&images.slice_dispatch),
                    ],
                    &LayeredPush {
                        layer: l as i32,
                        ..*base
                    },
                    pixels,
                );
            }
            // Every layer writes its own array layer; the counts are read
            // on the host after the frame.
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::HOST_READ);
        });
        frame.pass("layered.clear", |rec| {
            rec.fill_u32(&images.differences, 0);
            rec.fill_u32(&images.row_spans, 0);
            rec.memory_barrier(Access::FILL, Access::COMPUTE_READ_WRITE);
            // The slices' workgroup counts, from prepare's atomics.
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::INDIRECT_READ);
            rec.barriers(&[
                (
                    &images.fragment_color,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_READ,
                ),
                (
                    &images.fragment_coc,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_READ,
                ),
                (&images.behind, Access::NONE, Access::COMPUTE_READ_WRITE),
                (&images.result, Access::NONE, Access::COMPUTE_WRITE),
            ]);
        });
    }

    /// Passes `layered.spread` and `layered.composite` of each band of
    /// rows of a G-buffer `h` rows high, slice by slice, back to front.
    fn record_slices<'r>(&'r self, frame: &mut Frame<'r>, base: &LayeredPush, h: u32) {
        let images = &self.images;
        for band_y0 in (0..h).step_by(images.band_rows as usize) {
            for slice in (0..self.slices.count).rev() {
                let push = LayeredPush {
                    slice: slice as i32,
                    band_y0: band_y0 as i32,
                    ..*base
                };
                // Each pass starts with the barrier on what it reads: the
                // slice lists, the cleared differences and row spans
                // (prepare, clear, the last composite), then the spread's
                // differences and row spans.
                // (On lavapipe, a timestamp at a pass's start is also only
                // taken after the work before it when a barrier follows.)
                frame.pass("layered.spread", |rec| {
                    rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
                    rec.dispatch_indirect(
                        self.spread,
                        &[
                            Bind::StorageImage(&images.fragment_color),
                            Bind::StorageImage(&images.fragment_coc),
                            Bind::StorageBuffer(&images.differences),
                            Bind::StorageBuffer(&images.slice_lists),
                            Bind::StorageBuffer(&images.row_spans),
                            Bind::StorageBuffer(&images.shape_chords),
                            Bind::StorageBuffer(&images.span_offsets),
                            Bind::StorageBuffer(&images.span_list),
                        ],
                        &push,
                        &images.slice_dispatch,
                        12 * slice as u64,
                    );
                });
                frame.pass("layered.composite", |rec| {
                    rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
                    rec.dispatch(
                        self.composite,
                        &[
                            Bind::StorageBuffer(&images.differences),
                            Bind::StorageImage(&images.behind),
                            Bind::StorageImage(&images.result),
                            Bind::StorageBuffer(&images.row_spans),
                        ],
                        &push,
                        [
                            self.pipelines
                                .sizes
                                .composite_groups(images.band_rows.min(h - band_y0)),
                            1,
                            1,
                        ],
                    );
                });
            }
        }
    }
}

impl DofFrame for LayeredFrame<'_> {
    fn record<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>) -> &'r Image {
        let layers = input.layers.len() as u32;
        assert_eq!(layers, self.options.layers, "the G-buffer's layers");
        let base = self.base_push(input);
        self.record_fragments(frame, input, &base);
        self.record_slices(frame, &base, input.color.height());
        &self.images.result
    }

    fn counts(&self) -> Vec<(String, u64)> {
        let Some(bytes) = self.images.counts.mapped() else {
            return Vec::new();
        };
        let words: Vec<u32> = bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let mut out = vec![("layered.slices".to_string(), self.slices.count as u64)];
        for l in 0..self.options.layers as usize {
            out.push((format!("layered.layer{l}.kept_px"), words[2 * l] as u64));
            out.push((
                format!("layered.layer{l}.discarded_px"),
                words[2 * l + 1] as u64,
            ));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    #[test]
    fn push_constants_match_the_glsl_blocks() {
        for (name, spirv) in [
            ("layered_tiles", TILES),
            ("layered_prepare", PREPARE),
            ("layered_spread", SPREAD),
            ("layered_composite", COMPOSITE),
        ] {
            check_push_layout::<LayeredPush>(name, spirv).unwrap();
        }
    }

    #[test]
    fn constants_match_the_glsl() {
        let fixed = include_str!("../../glsl/layered_fixed.glsl");
        assert!(fixed.contains(&format!("const int FRACTION_BITS = {FRACTION_BITS};")));
        let slices = include_str!("../../glsl/layered_slices.glsl");
        assert!(slices.contains(&format!("const float RAMP = {RAMP:?};")));
    }
}
