//! The ray distribution buffer (Zhao §3.2, DESIGN §5): `rdb_scatter` (two
//! passes: depth, then source index, by R32_UINT image atomics into 2D array
//! images with one layer per lens bin) and `rdb_resolve` (mean of the filled
//! bins).

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use crate::camera::{rdb_lens_table, Camera};
use crate::error::{Error, Result};
use crate::gbuffer::GBuffer;
use crate::vk::{
    as_bytes, groups, image_barriers, slice_as_bytes, Access, Bind, Buffer, ComputePipeline,
    Context, Frame, Image,
};

/// Which rays a bin receives (`--rdb-mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RdbMode {
    /// Each bin sampled by the ray through its lens cell's centre.
    #[default]
    Centre,
    /// The paper's literal pair-to-bin assignment.
    Pairs,
}

static SCATTER: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/rdb_scatter.comp.spv"));
static RESOLVE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/rdb_resolve.comp.spv"));

#[repr(C)]
#[derive(Clone, Copy)]
struct ScatterPush {
    extent: [i32; 2],
    origin: [i32; 2],
    scan_origin: [i32; 2],
    tile_origin: [i32; 2],
    tile_size: [i32; 2],
    bins: i32,
    pairs: u32,
    pass_index: u32,
    f_px: f32,
    aperture_radius: f32,
    focus_distance: f32,
}

#[repr(C)]
#[derive(Clone, Copy)]
struct ResolvePush {
    extent: [i32; 2],
    origin: [i32; 2],
    tile_origin: [i32; 2],
    tile_size: [i32; 2],
    bins: i32,
}

/// The two pipelines of the method.
pub struct Rdb {
    scatter: ComputePipeline,
    resolve: ComputePipeline,
}

/// Bytes of the bins of one output pixel: N² bins of two R32_UINT words.
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

/// The buffers of one frame: the bins of one tile (two R32_UINT array
/// images, a layer per bin), the lens table and the result.
pub struct RdbImages {
    depth: Image,
    source: Image,
    lens: Buffer,
    bins: u32,
    /// The tiles the frame is processed in.
    pub plan: TilePlan,
    /// The result: G-buffer sized, written inside the guard band only.
    pub result: Image,
}

impl RdbImages {
    /// Allocates an N×N-bin buffer for the output size of `gbuffer`, or for
    /// one tile of it when the whole would exceed `budget_bytes`.
    pub fn new(
        ctx: &Arc<Context>,
        gbuffer: &GBuffer,
        bins: u32,
        budget_bytes: u64,
    ) -> Result<RdbImages> {
        if !(2..=16).contains(&bins) {
            return Err(Error::InvalidArgument(format!(
                "--rdb-bins must be between 2 and 16, not {bins}"
            )));
        }
        let layers = bins * bins;
        if layers > ctx.info.max_image_array_layers {
            return Err(Error::InvalidArgument(format!(
                "--rdb-bins {bins} needs {layers} image layers; the device has {}",
                ctx.info.max_image_array_layers
            )));
        }
        let (w, h) = (gbuffer.view.camera.width, gbuffer.view.camera.height);
        let plan = TilePlan::new(
            w,
            h,
            bins,
            budget_bytes,
            ctx.info.max_memory_allocation_bytes,
        )?;
        let [tw, th] = plan.tile_size;
        let usage = vk::ImageUsageFlags::STORAGE | vk::ImageUsageFlags::TRANSFER_DST;
        let table = rdb_lens_table(bins);
        let bytes = slice_as_bytes(&table);
        let mut lens = Buffer::new(
            ctx,
            "rdb lens table",
            bytes.len() as u64,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            MemoryLocation::CpuToGpu,
        )?;
        lens.mapped_mut()
            .ok_or_else(|| Error::Allocation("rdb lens table is not host-visible".into()))?
            .copy_from_slice(bytes);
        Ok(RdbImages {
            depth: Image::new_2d(
                ctx,
                "rdb depth",
                vk::Format::R32_UINT,
                tw,
                th,
                layers,
                usage,
            )?,
            source: Image::new_2d(
                ctx,
                "rdb source",
                vk::Format::R32_UINT,
                tw,
                th,
                layers,
                usage,
            )?,
            lens,
            bins,
            plan,
            result: Image::new_2d(
                ctx,
                "rdb result",
                vk::Format::R16G16B16A16_SFLOAT,
                gbuffer.color.width,
                gbuffer.color.height,
                1,
                vk::ImageUsageFlags::STORAGE | vk::ImageUsageFlags::TRANSFER_SRC,
            )?,
        })
    }
}

const CLEARED: Access = Access {
    stage: vk::PipelineStageFlags2::CLEAR,
    access: vk::AccessFlags2::TRANSFER_WRITE,
    layout: vk::ImageLayout::TRANSFER_DST_OPTIMAL,
};

impl Rdb {
    pub fn new(ctx: &Arc<Context>) -> Result<Rdb> {
        let img = vk::DescriptorType::STORAGE_IMAGE;
        let buf = vk::DescriptorType::STORAGE_BUFFER;
        Ok(Rdb {
            scatter: ComputePipeline::new(
                ctx,
                "rdb_scatter",
                SCATTER,
                &[img, img, img, buf],
                std::mem::size_of::<ScatterPush>() as u32,
            )?,
            resolve: ComputePipeline::new(
                ctx,
                "rdb_resolve",
                RESOLVE,
                &[img, img, img],
                std::mem::size_of::<ResolvePush>() as u32,
            )?,
        })
    }

    /// Records, tile by tile, the clear, the two scatter passes and the
    /// resolve after the G-buffer (last written by compute). A tile's
    /// scatter visits the G-buffer pixels within an apron of half the
    /// frame's largest CoC around it: every ray that can reach the tile.
    /// Each bin's winner is a minimum over the same candidates tiled or not,
    /// so the tiled result is bitwise the untiled one.
    pub fn record(
        &self,
        frame: &mut Frame,
        gbuffer: &GBuffer,
        images: &RdbImages,
        camera: &Camera,
        mode: RdbMode,
    ) {
        let (gw, gh) = (gbuffer.color.width as i32, gbuffer.color.height as i32);
        let g = gbuffer.view.guard as i32;
        // |lens offset| ≤ c/2, plus the rounding to a pixel and a pixel for
        // the GPU's CoC rounding above the CPU's bound.
        let apron = (0.5 * gbuffer.view.max_coc_px).ceil() as i32 + 2;
        for (index, tile) in images.plan.tiles.iter().enumerate() {
            let first = index == 0;
            let tile_origin = [tile.origin[0] as i32, tile.origin[1] as i32];
            let tile_size = [tile.size[0] as i32, tile.size[1] as i32];
            // The scanned G-buffer pixels: the tile and its apron, clipped.
            let lo = [
                (tile_origin[0] + g - apron).max(0),
                (tile_origin[1] + g - apron).max(0),
            ];
            let hi = [
                (tile_origin[0] + tile_size[0] + g + apron).min(gw),
                (tile_origin[1] + tile_size[1] + g + apron).min(gh),
            ];
            frame.pass("rdb.clear", |ctx, cmd| {
                // The previous tile's scatter read and wrote `depth`; its
                // resolve read `source`.
                let (depth_before, source_before) = match first {
                    true => (Access::NONE, Access::NONE),
                    false => (Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ),
                };
                image_barriers(
                    ctx,
                    cmd,
                    &[
                        (&images.depth, depth_before, CLEARED),
                        (&images.source, source_before, CLEARED),
                    ],
                );
                let clear = vk::ClearColorValue {
                    uint32: [u32::MAX; 4],
                };
                // SAFETY: both images are in TRANSFER_DST_OPTIMAL (barrier
                // above) and the ranges cover them.
                unsafe {
                    for image in [&images.depth, &images.source] {
                        ctx.device.cmd_clear_color_image(
                            cmd,
                            image.raw,
                            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                            &clear,
                            &[image.full_range()],
                        );
                    }
                }
                // The lens table, written by the host before the submission,
                // is visible to it by the submission's own host-write
                // guarantee.
            });
            for pass_index in 0..2u32 {
                let name = if pass_index == 0 {
                    "rdb.depth"
                } else {
                    "rdb.source"
                };
                frame.pass(name, |ctx, cmd| {
                    if pass_index == 0 {
                        let mut list = vec![
                            (&images.depth, CLEARED, Access::COMPUTE_READ_WRITE),
                            (&images.source, CLEARED, Access::COMPUTE_READ_WRITE),
                        ];
                        if first {
                            list.push((
                                &gbuffer.eye,
                                Access::COMPUTE_READ_WRITE,
                                Access::COMPUTE_READ,
                            ));
                        }
                        image_barriers(ctx, cmd, &list);
                    } else {
                        image_barriers(
                            ctx,
                            cmd,
                            &[(
                                &images.depth,
                                Access::COMPUTE_READ_WRITE,
                                Access::COMPUTE_READ_WRITE,
                            )],
                        );
                    }
                    let push = ScatterPush {
                        extent: [gw, gh],
                        origin: [g, g],
                        scan_origin: lo,
                        tile_origin,
                        tile_size,
                        bins: images.bins as i32,
                        pairs: (mode == RdbMode::Pairs) as u32,
                        pass_index,
                        f_px: camera.f_px(),
                        aperture_radius: camera.aperture_radius,
                        focus_distance: camera.focus_distance,
                    };
                    self.scatter.dispatch(
                        cmd,
                        &[
                            Bind::StorageImage(&gbuffer.eye),
                            Bind::StorageImage(&images.depth),
                            Bind::StorageImage(&images.source),
                            Bind::StorageBuffer(&images.lens),
                        ],
                        as_bytes(&push),
                        [
                            groups((hi[0] - lo[0]) as u32, 8),
                            groups((hi[1] - lo[1]) as u32, 8),
                            1,
                        ],
                    );
                });
            }
            frame.pass("rdb.resolve", |ctx, cmd| {
                let mut list = vec![(
                    &images.source,
                    Access::COMPUTE_READ_WRITE,
                    Access::COMPUTE_READ,
                )];
                if first {
                    list.push((&gbuffer.color, Access::COMPUTE_WRITE, Access::COMPUTE_READ));
                    list.push((&images.result, Access::NONE, Access::COMPUTE_WRITE));
                } else {
                    // Tiles write disjoint texels, but the image is one
                    // subresource to the hazard tracking: order the writes.
                    list.push((&images.result, Access::COMPUTE_WRITE, Access::COMPUTE_WRITE));
                }
                image_barriers(ctx, cmd, &list);
                let push = ResolvePush {
                    extent: [gw, gh],
                    origin: [g, g],
                    tile_origin,
                    tile_size,
                    bins: images.bins as i32,
                };
                self.resolve.dispatch(
                    cmd,
                    &[
                        Bind::StorageImage(&gbuffer.color),
                        Bind::StorageImage(&images.source),
                        Bind::StorageImage(&images.result),
                    ],
                    as_bytes(&push),
                    [groups(tile.size[0], 8), groups(tile.size[1], 8), 1],
                );
            });
        }
    }
}
