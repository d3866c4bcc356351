//! The ray distribution buffer (Zhao §3.2, DESIGN §5): a scatter of every
//! G-buffer pixel into the lens bins of the pixels its rays reach
//! (`glsl/rdb_offers.glsl`), and a resolve (mean of the filled bins). Two
//! forms, bit for bit the same image:
//! - 64-bit (`rdb_scatter64`, `rdb_resolve64`): one scatter pass of
//!   atomicMin on (tag, depth, source) words in a buffer kept from frame to
//!   frame; each use of the bins has its own tag, so they are filled (with
//!   ones) only when made and after every 31 uses, never per frame;
//! - 32-bit (`rdb_scatter`, `rdb_resolve`): two passes (depth, then source
//!   index) of R32_UINT image atomics into 2D array images with one layer
//!   per bin, cleared for every tile.

use std::cell::Cell;
use std::sync::{Arc, Mutex, MutexGuard};

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::kernel_sizes::KernelSizes;
use super::{check_square_loop, Configured, DofFrame, DofInput, DofMethod, FrameView, Specialized};
use crate::error::{Error, Result};
use crate::options::{check_rdb_bins, RdbAtomics, RdbMode, RdbOptions};
use crate::push_constants;
use crate::vk::{groups, Access, Bind, Binding, Buffer, Context, Frame, Image};

static SCATTER: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/rdb_scatter.comp.spv"));
static RESOLVE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/rdb_resolve.comp.spv"));
static SCATTER64: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/rdb_scatter64.comp.spv"));
static RESOLVE64: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/rdb_resolve64.comp.spv"));

push_constants! {
    /// Mirrors `glsl/rdb_push.glsl` (scatter), for both forms.
    struct ScatterPush {
        extent: [i32; 2],
        origin: [i32; 2],
        scan_origin: [i32; 2],
        tile_origin: [i32; 2],
        tile_size: [i32; 2],
        bins: i32,
        pairs: u32,
        /// 32-bit form: the pass (0 depth, 1 source); 64-bit: the use's tag.
        step: u32,
        f_px: f32,
        aperture_radius: f32,
        focus_distance: f32,
        window_origin: [i32; 2],
        frame_size: [i32; 2],
        cat_eye: f32,
        /// 1: the bins' lens positions pressed into each pixel's cat's eye
        /// ([`crate::camera::Aperture::cat_eye_lens`]; a round aperture's).
        cat_lens: u32,
    }
}

push_constants! {
    /// Mirrors `glsl/rdb_push.glsl` (resolve), for both forms.
    struct ResolvePush {
        extent: [i32; 2],
        origin: [i32; 2],
        tile_origin: [i32; 2],
        tile_size: [i32; 2],
        bins: i32,
        /// 64-bit form: the use's tag (unused by the 32-bit one).
        step: u32,
        window_origin: [i32; 2],
        frame_size: [i32; 2],
        cat_eye: f32,
        /// As the scatter's.
        cat_lens: u32,
    }
}

/// The pipelines of the method, and the 64-bit bins kept between frames.
pub struct Rdb {
    scatter: Specialized<ScatterPush>,
    resolve: Specialized<ResolvePush>,
    /// The 64-bit form, on devices with 64-bit buffer atomics.
    packed: Option<Packed>,
}

/// The 64-bit form: its pipelines and its bins.
struct Packed {
    scatter: Specialized<ScatterPush>,
    resolve: Specialized<ResolvePush>,
    /// Made by the first frame that needs them (or a bigger one), then kept;
    /// a frame holds the lock from `prepare` until it is dropped, after its
    /// submission completed.
    bins: Mutex<Option<PackedBins>>,
}

/// The 64-bit form's scatter and resolve in the bins' layout of `sizes`.
fn packed_pipelines(
    ctx: &Arc<Context>,
    sizes: KernelSizes,
) -> Result<(Specialized<ScatterPush>, Specialized<ResolvePush>)> {
    let (img, buf) = (Binding::StorageImage, Binding::StorageBuffer);
    let layout = sizes.rdb_constants();
    Ok((
        Specialized::with_base(
            ctx,
            "rdb_scatter64",
            SCATTER64,
            &[img, buf, buf],
            &layout,
            "round",
            (super::APERTURE_CODE_ID, 0),
        )?,
        Specialized::with_base(
            ctx,
            "rdb_resolve64",
            RESOLVE64,
            &[img, buf, img, buf],
            &layout,
            "round",
            (super::APERTURE_CODE_ID, 0),
        )?,
    ))
}

/// The tag of a word that no use filled (the buffer's fill value's).
const FILL_TAG: u32 = 31;

/// The 64-bit bins (`glsl/rdb_bins64.glsl`) and the tag of their next use.
struct PackedBins {
    buffer: Buffer,
    /// 30 down to 0, then [`FILL_TAG`]: fill before the next use.
    next_tag: Cell<u32>,
}

impl PackedBins {
    /// The tag of the next use, and whether the buffer must be filled
    /// before it.
    fn take_tag(&self) -> (u32, bool) {
        let next = self.next_tag.get();
        let (tag, fill) = match next {
            FILL_TAG => (FILL_TAG - 1, true),
            t => (t, false),
        };
        self.next_tag.set(if tag == 0 { FILL_TAG } else { tag - 1 });
        (tag, fill)
    }
}

/// Bytes of the bins of one output pixel: N² bins of two 32-bit words (the
/// 32-bit form's depth and source images; one 64-bit word in the other).
pub fn bytes_per_pixel(bins: u32) -> u64 {
    bins as u64 * bins as u64 * 8
}

/// A screen tile of output pixels `[origin, origin + size)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tile {
    pub origin: [u32; 2],
    pub size: [u32; 2],
}

/// How a frame's RDB is processed: the size the bins are allocated for and
/// the tiles, row by row, that cover the frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TilePlan {
    pub tile_size: [u32; 2],
    pub tiles: Vec<Tile>,
}

impl TilePlan {
    /// Splits a `width`×`height` frame into a grid of equal tiles (the last
    /// row and column cut short) whose bins fit in `budget_bytes`, each of
    /// the two images within `max_image_bytes`: the grid gains a column or
    /// a row, whichever shortens the tile's longer side, until a tile fits.
    pub fn new(
        width: u32,
        height: u32,
        bins: u32,
        budget_bytes: u64,
        max_image_bytes: u64,
    ) -> Result<TilePlan> {
        let per_pixel = bytes_per_pixel(bins);
        let max_pixels = (budget_bytes / per_pixel).min(max_image_bytes / (per_pixel / 2));
        if max_pixels == 0 {
            return Err(Error::InvalidArgument(format!(
                "--rdb-memory-mb is too small: one pixel of {bins}×{bins} bins needs {per_pixel} bytes"
            )));
        }
        let (mut cols, mut rows) = (1u32, 1u32);
        let tile = |cols: u32, rows: u32| [width.div_ceil(cols), height.div_ceil(rows)];
        loop {
            let [tw, th] = tile(cols, rows);
            if tw as u64 * th as u64 <= max_pixels {
                break;
            }
            if tw >= th {
                cols += 1;
            } else {
                rows += 1;
            }
        }
        let tile_size = tile(cols, rows);
        let mut tiles = Vec::new();
        for y in (0..height).step_by(tile_size[1] as usize) {
            for x in (0..width).step_by(tile_size[0] as usize) {
                tiles.push(Tile {
                    origin: [x, y],
                    size: [tile_size[0].min(width - x), tile_size[1].min(height - y)],
                });
            }
        }
        Ok(TilePlan { tile_size, tiles })
    }
}

/// Where a frame's bins are.
enum Bins<'m> {
    /// Two R32_UINT array images, a layer per bin, for one tile.
    Images {
        depth: Box<Image>,
        source: Box<Image>,
    },
    /// The method's 64-bit buffer, locked for the frame.
    Packed(MutexGuard<'m, Option<PackedBins>>),
}

/// The buffers of one frame: the bins of one tile, the lens table and the
/// result.
struct RdbImages<'m> {
    bins_of: Bins<'m>,
    lens: Buffer,
    bins: u32,
    /// The tiles the frame is processed in.
    plan: TilePlan,
    /// The result: G-buffer sized, written inside the guard band only.
    result: Image,
}

impl<'m> RdbImages<'m> {
    /// Allocates N×N bins for the output size of `view`, or for one tile
    /// of it when the whole would exceed `budget_bytes`: in the method's
    /// kept 64-bit buffer (`packed`, grown if too small) or in two images.
    fn new(
        ctx: &Arc<Context>,
        view: &FrameView,
        bins: u32,
        budget_bytes: u64,
        packed: Option<&'m Packed>,
    ) -> Result<RdbImages<'m>> {
        check_rdb_bins(bins)?;
        let layers = bins * bins;
        if packed.is_none() && layers > ctx.info.max_image_array_layers {
            return Err(Error::InvalidArgument(format!(
                "--rdb-bins {bins} needs {layers} image layers; the device has {}",
                ctx.info.max_image_array_layers
            )));
        }
        let (w, h) = (view.window.width, view.window.height);
        let max_allocation = ctx.info.max_memory_allocation_bytes;
        // TilePlan bounds each 32-bit word array; the 64-bit buffer is one
        // array of twice the bytes, within one storage-buffer binding.
        let max_words_bytes = match packed {
            Some(_) => ctx.info.largest_storage_buffer_bytes() / 2,
            None => max_allocation,
        };
        let plan = TilePlan::new(w, h, bins, budget_bytes, max_words_bytes)?;
        let [tw, th] = plan.tile_size;
        let bins_of = match packed {
            Some(packed) => {
                let bytes = tw as u64 * th as u64 * bytes_per_pixel(bins);
                let mut kept = packed
                    .bins
                    .lock()
                    .unwrap_or_else(|poisoned| poisoned.into_inner());
                if kept.as_ref().is_none_or(|b| b.buffer.size() < bytes) {
                    // Drop the old one first: it may not fit beside the new.
                    *kept = None;
                    *kept = Some(PackedBins {
                        buffer: Buffer::new(
                            ctx,
                            "rdb bins",
                            bytes,
                            vk::BufferUsageFlags::STORAGE_BUFFER
                                | vk::BufferUsageFlags::TRANSFER_DST,
                            MemoryLocation::GpuOnly,
                        )?,
                        next_tag: Cell::new(FILL_TAG),
                    });
                }
                Bins::Packed(kept)
            }
            None => {
                let usage = vk::ImageUsageFlags::STORAGE | vk::ImageUsageFlags::TRANSFER_DST;
                let bin_image =
                    |name| Image::new_2d(ctx, name, vk::Format::R32_UINT, tw, th, layers, usage);
                Bins::Images {
                    depth: Box::new(bin_image("rdb depth")?),
                    source: Box::new(bin_image("rdb source")?),
                }
            }
        };
        let table = view.camera.aperture.rdb_lens_table(bins);
        let bytes: &[u8] = bytemuck::cast_slice(&table);
        let lens = Buffer::with_bytes(
            ctx,
            "rdb lens table",
            bytes,
            vk::BufferUsageFlags::STORAGE_BUFFER,
        )?;
        Ok(RdbImages {
            bins_of,
            lens,
            bins,
            plan,
            result: Image::new_2d(
                ctx,
                "rdb result",
                vk::Format::R16G16B16A16_SFLOAT,
                view.full_width(),
                view.full_height(),
                1,
                vk::ImageUsageFlags::STORAGE | vk::ImageUsageFlags::TRANSFER_SRC,
            )?,
        })
    }
}

impl Rdb {
    /// [`super::Methods::set_round_pipelines`] for both forms' scatters
    /// and resolves.
    pub(super) fn set_round_pipelines(&mut self, enabled: bool) {
        self.scatter.set_enabled(enabled);
        self.resolve.set_enabled(enabled);
        if let Some(packed) = &mut self.packed {
            packed.scatter.set_enabled(enabled);
            packed.resolve.set_enabled(enabled);
        }
    }

    /// The method's pipelines, the 64-bit bins laid out as `sizes` says.
    pub fn new(ctx: &Arc<Context>, sizes: KernelSizes) -> Result<Rdb> {
        let img = Binding::StorageImage;
        Ok(Rdb {
            scatter: Specialized::round(
                ctx,
                "rdb_scatter",
                SCATTER,
                &[img, img, img, Binding::StorageBuffer],
            )?,
            resolve: Specialized::round(
                ctx,
                "rdb_resolve",
                RESOLVE,
                &[img, img, img, Binding::StorageBuffer],
            )?,
            packed: match ctx.info.buffer_int64_atomics {
                true => {
                    let (scatter, resolve) = packed_pipelines(ctx, sizes)?;
                    Some(Packed {
                        scatter,
                        resolve,
                        bins: Mutex::new(None),
                    })
                }
                false => None,
            },
        })
    }

    /// The 64-bit form if `atomics` asks for it (or allows it) and the
    /// device has it.
    fn packed(&self, atomics: RdbAtomics) -> Result<Option<&Packed>> {
        match (atomics, &self.packed) {
            (RdbAtomics::Int32, _) | (RdbAtomics::Auto, None) => Ok(None),
            (_, Some(p)) => Ok(Some(p)),
            (RdbAtomics::Int64, None) => Err(Error::InvalidArgument(
                "--rdb-atomics 64: the device has no 64-bit buffer atomics (try 32)".into(),
            )),
        }
    }
}

/// The memory budget of the bins: the option, or a quarter of the largest
/// device-local heap.
fn budget(options: &RdbOptions, ctx: &Context) -> u64 {
    options
        .memory_bytes
        .unwrap_or(ctx.info.device_local_heap_bytes / 4)
}

/// Every pixel scatters, the background too: the default guard band.
impl DofMethod for Configured<'_, Rdb, RdbOptions> {
    fn prepare<'m>(
        &'m self,
        ctx: &Arc<Context>,
        view: &FrameView,
    ) -> Result<Box<dyn DofFrame + 'm>> {
        let packed = self.pipelines.packed(self.options.atomics)?;
        check_pairs_loop(ctx, &self.options, view.max_coc_px)?;
        if self.options.mode == RdbMode::Pairs && view.camera.aperture.is_shaped() {
            return Err(Error::InvalidArgument(
                "--rdb-mode pairs bins a disk's pixels by the concentric map; a shaped aperture renders with --rdb-mode centre (the default)".into(),
            ));
        }
        let images = RdbImages::new(
            ctx,
            view,
            self.options.bins,
            budget(&self.options, ctx),
            packed,
        )?;
        Ok(Box::new(RdbFrame {
            method: self,
            images,
        }))
    }
}

/// `--rdb-mode pairs` scans the (2r + 1)² offsets of a source's disk, r =
/// c / 2, in one invocation: past the device's loop limit (llvmpipe) the
/// rest of the disk would be dropped without a word, so such a frame is
/// refused (`centre`, the default, loops over its N² bins only).
fn check_pairs_loop(ctx: &Context, options: &RdbOptions, max_coc_px: f32) -> Result<()> {
    if options.mode != RdbMode::Pairs {
        return Ok(());
    }
    check_square_loop(
        ctx,
        (0.5 * max_coc_px).floor() as u64,
        "--rdb-mode pairs over disks",
        "use --rdb-mode centre (the default) or a smaller aperture",
    )
}

struct RdbFrame<'m> {
    method: &'m Configured<'m, Rdb, RdbOptions>,
    images: RdbImages<'m>,
}

/// One tile's place in the G-buffer and the output.
struct TileScan {
    /// Output pixel of the bins' pixel (0, 0), and the tile's size.
    origin: [i32; 2],
    size: [i32; 2],
    /// The scanned G-buffer pixels: the tile and its apron, clipped.
    lo: [i32; 2],
    hi: [i32; 2],
}

impl TileScan {
    /// Workgroups of a scatter: the scanned pixels.
    fn scatter_groups(&self) -> [u32; 3] {
        [
            groups((self.hi[0] - self.lo[0]) as u32, 8),
            groups((self.hi[1] - self.lo[1]) as u32, 8),
            1,
        ]
    }

    /// Workgroups of a resolve: the tile's pixels.
    fn resolve_groups(&self) -> [u32; 3] {
        [
            groups(self.size[0] as u32, 8),
            groups(self.size[1] as u32, 8),
            1,
        ]
    }
}

impl DofFrame for RdbFrame<'_> {
    /// Records, tile by tile, the scatter and the resolve. A tile's scatter
    /// visits the G-buffer pixels within an apron of half the frame's
    /// largest CoC around it: every ray that can reach the tile. Each bin's
    /// winner is a minimum over the same candidates tiled or not, so the
    /// tiled result is bitwise the untiled one.
    fn record<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>) -> &'r Image {
        let images = &self.images;
        let (gw, gh) = (input.color.width() as i32, input.color.height() as i32);
        let g = input.view.guard as i32;
        // |lens offset| ≤ c/2, plus the rounding to a pixel and a pixel for
        // the GPU's CoC rounding above the CPU's bound.
        let apron = (0.5 * input.view.max_coc_px).ceil() as i32 + 2;
        for (index, tile) in images.plan.tiles.iter().enumerate() {
            let origin = [tile.origin[0] as i32, tile.origin[1] as i32];
            let size = [tile.size[0] as i32, tile.size[1] as i32];
            let scan = TileScan {
                origin,
                size,
                lo: [
                    (origin[0] + g - apron).max(0),
                    (origin[1] + g - apron).max(0),
                ],
                hi: [
                    (origin[0] + size[0] + g + apron).min(gw),
                    (origin[1] + size[1] + g + apron).min(gh),
                ],
            };
            match &images.bins_of {
                Bins::Images { depth, source } => {
                    self.record_tile32(frame, input, &scan, index == 0, depth, source)
                }
                Bins::Packed(kept) => {
                    let bins = kept.as_ref().expect("made by prepare");
                    self.record_tile64(frame, input, &scan, index == 0, bins)
                }
            }
        }
        &images.result
    }
}

impl RdbFrame<'_> {
    /// Whether the bins' lens positions are pressed into each pixel's cat's
    /// eye ([`crate::camera::Aperture::presses_cat_eye_lens`]): in centre mode, whose
    /// bins are lens positions (pairs mode bins a pixel's offset).
    fn presses_cat_eye_lens(&self, camera: &crate::camera::Camera) -> bool {
        self.method.options.mode == RdbMode::Centre && camera.aperture.presses_cat_eye_lens()
    }

    /// The scatter's push constants for `scan`, with `step` (the 32-bit
    /// form's pass, the 64-bit form's tag).
    fn scatter_push(&self, input: &DofInput<'_>, scan: &TileScan, step: u32) -> ScatterPush {
        let camera = &input.view.camera;
        let g = input.view.guard as i32;
        ScatterPush {
            extent: [input.color.width() as i32, input.color.height() as i32],
            origin: [g, g],
            scan_origin: scan.lo,
            tile_origin: scan.origin,
            tile_size: scan.size,
            bins: self.images.bins as i32,
            pairs: (self.method.options.mode == RdbMode::Pairs) as u32,
            step,
            f_px: camera.f_px(),
            aperture_radius: camera.aperture_radius,
            focus_distance: camera.focus_distance,
            window_origin: [input.view.window.x as i32, input.view.window.y as i32],
            frame_size: [camera.width as i32, camera.height as i32],
            cat_eye: camera.aperture.cat_eye,
            cat_lens: u32::from(self.presses_cat_eye_lens(camera)),
        }
    }

    /// The resolve's push constants for `scan`, with `step` (the 64-bit
    /// form's tag; 0 in the 32-bit form).
    fn resolve_push(&self, input: &DofInput<'_>, scan: &TileScan, step: u32) -> ResolvePush {
        let g = input.view.guard as i32;
        ResolvePush {
            extent: [input.color.width() as i32, input.color.height() as i32],
            origin: [g, g],
            tile_origin: scan.origin,
            tile_size: scan.size,
            bins: self.images.bins as i32,
            step,
            window_origin: [input.view.window.x as i32, input.view.window.y as i32],
            frame_size: [
                input.view.camera.width as i32,
                input.view.camera.height as i32,
            ],
            cat_eye: input.view.camera.aperture.cat_eye,
            cat_lens: u32::from(self.presses_cat_eye_lens(&input.view.camera)),
        }
    }

    /// The barriers of a tile's resolve on the G-buffer color and result.
    fn resolve_barriers<'r>(
        &'r self,
        input: &DofInput<'r>,
        first: bool,
    ) -> Vec<(&'r Image, Access, Access)> {
        let result = &self.images.result;
        if first {
            vec![
                (input.color, Access::COMPUTE_WRITE, Access::COMPUTE_READ),
                (result, Access::NONE, Access::COMPUTE_WRITE),
            ]
        } else {
            // Tiles write disjoint texels, but the image is one subresource
            // to the hazard tracking: order the writes.
            vec![(result, Access::COMPUTE_WRITE, Access::COMPUTE_WRITE)]
        }
    }

    /// One tile of the 64-bit form: (a fill when the tags ran out,) one
    /// scatter pass, the resolve.
    fn record_tile64<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        input: &DofInput<'r>,
        scan: &TileScan,
        first: bool,
        bins: &'r PackedBins,
    ) {
        let p = self
            .method
            .pipelines
            .packed
            .as_ref()
            .expect("chosen by prepare");
        let buffer = &bins.buffer;
        let (tag, fill) = bins.take_tag();
        if fill {
            frame.pass("rdb.fill", |rec| {
                // Earlier uses (this frame's or a previous submission's)
                // read and wrote the bins.
                rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::FILL);
                rec.fill_u32(buffer, u32::MAX);
                rec.memory_barrier(Access::FILL, Access::COMPUTE_READ_WRITE);
            });
        }
        frame.pass("rdb.scatter", |rec| {
            if first {
                rec.barriers(&[(input.eye, Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ)]);
            }
            // The previous use's resolve read the bins, its scatter wrote them.
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
            let push = self.scatter_push(input, scan, tag);
            rec.dispatch(
                p.scatter.for_aperture(&input.view.camera.aperture),
                &[
                    Bind::StorageImage(input.eye),
                    Bind::StorageBuffer(buffer),
                    Bind::StorageBuffer(&self.images.lens),
                ],
                &push,
                scan.scatter_groups(),
            );
        });
        frame.pass("rdb.resolve", |rec| {
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ);
            rec.barriers(&self.resolve_barriers(input, first));
            let push = self.resolve_push(input, scan, tag);
            rec.dispatch(
                p.resolve.for_aperture(&input.view.camera.aperture),
                &[
                    Bind::StorageImage(input.color),
                    Bind::StorageBuffer(buffer),
                    Bind::StorageImage(&self.images.result),
                    Bind::StorageBuffer(&self.images.lens),
                ],
                &push,
                scan.resolve_groups(),
            );
        });
    }

    /// One tile of the 32-bit form: the clear, the two scatter passes and
    /// the resolve.
    #[allow(clippy::too_many_arguments)]
    fn record_tile32<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        input: &DofInput<'r>,
        scan: &TileScan,
        first: bool,
        depth: &'r Image,
        source: &'r Image,
    ) {
        let p = self.method.pipelines;
        frame.pass("rdb.clear", |rec| {
            // The previous tile's scatter read and wrote `depth`; its
            // resolve read `source`.
            let (depth_before, source_before) = match first {
                true => (Access::NONE, Access::NONE),
                false => (Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ),
            };
            rec.barriers(&[
                (depth, depth_before, Access::CLEAR),
                (source, source_before, Access::CLEAR),
            ]);
            rec.clear_u32(depth, u32::MAX);
            rec.clear_u32(source, u32::MAX);
            // The lens table, written by the host before the submission, is
            // visible to it by the submission's own host-write guarantee.
        });
        for pass_index in 0..2u32 {
            let name = if pass_index == 0 {
                "rdb.depth"
            } else {
                "rdb.source"
            };
            frame.pass(name, |rec| {
                if pass_index == 0 {
                    let mut list = vec![
                        (depth, Access::CLEAR, Access::COMPUTE_READ_WRITE),
                        (source, Access::CLEAR, Access::COMPUTE_READ_WRITE),
                    ];
                    if first {
                        list.push((input.eye, Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ));
                    }
                    rec.barriers(&list);
                } else {
                    rec.barriers(&[(
                        depth,
                        Access::COMPUTE_READ_WRITE,
                        Access::COMPUTE_READ_WRITE,
                    )]);
                }
                rec.dispatch(
                    p.scatter.for_aperture(&input.view.camera.aperture),
                    &[
                        Bind::StorageImage(input.eye),
                        Bind::StorageImage(depth),
                        Bind::StorageImage(source),
                        Bind::StorageBuffer(&self.images.lens),
                    ],
                    &self.scatter_push(input, scan, pass_index),
                    scan.scatter_groups(),
                );
            });
        }
        frame.pass("rdb.resolve", |rec| {
            let mut list = vec![(source, Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ)];
            list.extend(self.resolve_barriers(input, first));
            rec.barriers(&list);
            rec.dispatch(
                p.resolve.for_aperture(&input.view.camera.aperture),
                &[
                    Bind::StorageImage(input.color),
                    Bind::StorageImage(source),
                    Bind::StorageImage(&self.images.result),
                    Bind::StorageBuffer(&self.images.lens),
                ],
                &self.resolve_push(input, scan, 0),
                scan.resolve_groups(),
            );
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    #[test]
    fn push_constants_match_the_glsl_blocks() {
        check_push_layout::<ScatterPush>("rdb_scatter", SCATTER).unwrap();
        check_push_layout::<ResolvePush>("rdb_resolve", RESOLVE).unwrap();
        check_push_layout::<ScatterPush>("rdb_scatter64", SCATTER64).unwrap();
        check_push_layout::<ResolvePush>("rdb_resolve64", RESOLVE64).unwrap();
    }
}
