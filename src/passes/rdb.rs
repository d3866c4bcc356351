//! The ray distribution buffer (Zhao §3.2, DESIGN §5): `rdb_scatter` (two
//! passes: depth, then source index, by R32_UINT image atomics into 2D array
//! images with one layer per lens bin) and `rdb_resolve` (mean of the filled
//! bins).

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::{Configured, DofFrame, DofInput, DofMethod, FrameView};
use crate::camera::rdb_lens_table;
use crate::error::{Error, Result};
use crate::options::{check_rdb_bins, RdbMode, RdbOptions};
use crate::push_constants;
use crate::vk::{groups, Access, Bind, Binding, Buffer, ComputePipeline, Context, Frame, Image};

static SCATTER: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/rdb_scatter.comp.spv"));
static RESOLVE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/rdb_resolve.comp.spv"));

push_constants! {
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
}

push_constants! {
    struct ResolvePush {
        extent: [i32; 2],
        origin: [i32; 2],
        tile_origin: [i32; 2],
        tile_size: [i32; 2],
        bins: i32,
    }
}

/// The two pipelines of the method.
pub struct Rdb {
    scatter: ComputePipeline<ScatterPush>,
    resolve: ComputePipeline<ResolvePush>,
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
struct RdbImages {
    depth: Image,
    source: Image,
    lens: Buffer,
    bins: u32,
    /// The tiles the frame is processed in.
    plan: TilePlan,
    /// The result: G-buffer sized, written inside the guard band only.
    result: Image,
}

impl RdbImages {
    /// Allocates an N×N-bin buffer for the output size of `view`, or for
    /// one tile of it when the whole would exceed `budget_bytes`.
    fn new(
        ctx: &Arc<Context>,
        view: &FrameView,
        bins: u32,
        budget_bytes: u64,
    ) -> Result<RdbImages> {
        check_rdb_bins(bins)?;
        let layers = bins * bins;
        if layers > ctx.info.max_image_array_layers {
            return Err(Error::InvalidArgument(format!(
                "--rdb-bins {bins} needs {layers} image layers; the device has {}",
                ctx.info.max_image_array_layers
            )));
        }
        let (w, h) = (view.camera.width, view.camera.height);
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
        let bytes: &[u8] = bytemuck::cast_slice(&table);
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
        let bin_image =
            |name| Image::new_2d(ctx, name, vk::Format::R32_UINT, tw, th, layers, usage);
        Ok(RdbImages {
            depth: bin_image("rdb depth")?,
            source: bin_image("rdb source")?,
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
    pub fn new(ctx: &Arc<Context>) -> Result<Rdb> {
        let img = Binding::StorageImage;
        Ok(Rdb {
            scatter: ComputePipeline::new(
                ctx,
                "rdb_scatter",
                SCATTER,
                &[img, img, img, Binding::StorageBuffer],
            )?,
            resolve: ComputePipeline::new(ctx, "rdb_resolve", RESOLVE, &[img; 3])?,
        })
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
        let images = RdbImages::new(ctx, view, self.options.bins, budget(&self.options, ctx))?;
        Ok(Box::new(RdbFrame {
            method: self,
            images,
        }))
    }
}

struct RdbFrame<'m> {
    method: &'m Configured<'m, Rdb, RdbOptions>,
    images: RdbImages,
}

impl DofFrame for RdbFrame<'_> {
    /// Records, tile by tile, the clear, the two scatter passes and the
    /// resolve. A tile's scatter visits the G-buffer pixels within an apron
    /// of half the frame's largest CoC around it: every ray that can reach
    /// the tile. Each bin's winner is a minimum over the same candidates
    /// tiled or not, so the tiled result is bitwise the untiled one.
    fn record<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>) -> &'r Image {
        let p = self.method.pipelines;
        let mode = self.method.options.mode;
        let images = &self.images;
        let camera = &input.view.camera;
        let (gw, gh) = (input.color.width() as i32, input.color.height() as i32);
        let g = input.view.guard as i32;
        // |lens offset| ≤ c/2, plus the rounding to a pixel and a pixel for
        // the GPU's CoC rounding above the CPU's bound.
        let apron = (0.5 * input.view.max_coc_px).ceil() as i32 + 2;
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
            frame.pass("rdb.clear", |rec| {
                // The previous tile's scatter read and wrote `depth`; its
                // resolve read `source`.
                let (depth_before, source_before) = match first {
                    true => (Access::NONE, Access::NONE),
                    false => (Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ),
                };
                rec.barriers(&[
                    (&images.depth, depth_before, Access::CLEAR),
                    (&images.source, source_before, Access::CLEAR),
                ]);
                rec.clear_u32(&images.depth, u32::MAX);
                rec.clear_u32(&images.source, u32::MAX);
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
                frame.pass(name, |rec| {
                    if pass_index == 0 {
                        let mut list = vec![
                            (&images.depth, Access::CLEAR, Access::COMPUTE_READ_WRITE),
                            (&images.source, Access::CLEAR, Access::COMPUTE_READ_WRITE),
                        ];
                        if first {
                            list.push((
                                input.eye,
                                Access::COMPUTE_READ_WRITE,
                                Access::COMPUTE_READ,
                            ));
                        }
                        rec.barriers(&list);
                    } else {
                        rec.barriers(&[(
                            &images.depth,
                            Access::COMPUTE_READ_WRITE,
                            Access::COMPUTE_READ_WRITE,
                        )]);
                    }
                    rec.dispatch(
                        &p.scatter,
                        &[
                            Bind::StorageImage(input.eye),
                            Bind::StorageImage(&images.depth),
                            Bind::StorageImage(&images.source),
                            Bind::StorageBuffer(&images.lens),
                        ],
                        &ScatterPush {
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
                        },
                        [
                            groups((hi[0] - lo[0]) as u32, 8),
                            groups((hi[1] - lo[1]) as u32, 8),
                            1,
                        ],
                    );
                });
            }
            frame.pass("rdb.resolve", |rec| {
                let mut list = vec![(
                    &images.source,
                    Access::COMPUTE_READ_WRITE,
                    Access::COMPUTE_READ,
                )];
                if first {
                    list.push((input.color, Access::COMPUTE_WRITE, Access::COMPUTE_READ));
                    list.push((&images.result, Access::NONE, Access::COMPUTE_WRITE));
                } else {
                    // Tiles write disjoint texels, but the image is one
                    // subresource to the hazard tracking: order the writes.
                    list.push((&images.result, Access::COMPUTE_WRITE, Access::COMPUTE_WRITE));
                }
                rec.barriers(&list);
                rec.dispatch(
                    &p.resolve,
                    &[
                        Bind::StorageImage(input.color),
                        Bind::StorageImage(&images.source),
                        Bind::StorageImage(&images.result),
                    ],
                    &ResolvePush {
                        extent: [gw, gh],
                        origin: [g, g],
                        tile_origin,
                        tile_size,
                        bins: images.bins as i32,
                    },
                    [groups(tile.size[0], 8), groups(tile.size[1], 8), 1],
                );
            });
        }
        &images.result
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
    }
}
