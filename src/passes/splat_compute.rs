//! The compute rasteriser (`glsl/splat_compute.comp`, issue 28 item 2,
//! `--raster compute`): the splats of one raster pass drawn by compute
//! shaders into a 64-bit visibility buffer — per target pixel, the eye
//! depth's bits above the splat index, kept by `atomicMin` — instead of
//! lavapipe's point path, which costs per splat whatever its size. The
//! resolve reads the words (`glsl/gbuffer_resolve_vis.comp`). The sprite
//! path stays the reference: the two place and size splats with the same
//! code (`glsl/splat_project.glsl`) and cover a pixel by the same rule, its
//! sample inside the square. At K = 1 the sample is the pixel centre for
//! both, and they differ where the sprite path rounds a position to its
//! sub-pixel steps or a size to the point-size granularity; at K ≥ 2 the
//! compute rasteriser samples a rotated grid, whose K² samples of a pixel
//! see a square's edges in steps of 1/K², where the sprites' K×K grid of
//! cell centres sees them in steps of 1/K (tests/compute_raster.rs states
//! by how much the images differ, and that the rotated grid's are closer
//! to the converged image).

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::splat_raster::{SplatComputePush, SplatPush, SplatVertex};
use crate::error::Result;
use crate::options::SplatShape;
use crate::vk::{Access, Bind, Binding, Buffer, ComputePipeline, Context, Frame, Image};

static SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_compute.comp.spv"));
static DISC_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_compute_disc.comp.spv"));
static PEEL_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_compute_peel.comp.spv"));
static PEEL_DISC_SPIRV: &[u8] = include_bytes!(concat!(
    env!("OUT_DIR"),
    "/splat_compute_peel_disc.comp.spv"
));

/// Invocations per workgroup (the shader's `local_size_x`).
const GROUP: u32 = 64;
/// A splat covering more target pixels is drawn by a workgroup of its own
/// (mirrors `LARGE_PIXELS` in the shader). 4,096, measured against 256
/// (docs/BENCHMARKS.md, "The compute raster's large splats"): a splat of
/// a few hundred pixels costs less in one invocation; an invocation's
/// loop stays far below llvmpipe's 65,535 iterations.
pub const LARGE_PIXELS: u32 = 4096;
/// Target pixels of a large splat per workgroup of the second stage
/// (mirrors `CHUNK_PIXELS` in the shader): 16,384 loop iterations per
/// invocation at most, a quarter of llvmpipe's 65,535 per invocation.
pub const CHUNK_PIXELS: u32 = 1 << 20;

/// The workgroups (y) of the second stage per large splat: as many chunks
/// as the largest square of `max_point_size` target pixels holds (its
/// pixel centres cover at most one more pixel per axis). 1 at SSAA 4 with
/// a 255 px point size.
pub fn large_chunks(max_point_size: f32) -> u32 {
    let side = max_point_size.max(0.0).ceil() as u64 + 1;
    (side * side).div_ceil(CHUNK_PIXELS as u64).max(1) as u32
}

/// Bytes of one visibility word: a target pixel.
pub const WORD_BYTES: u64 = 8;
/// Bytes of one splat's square in [`Visibility::squares`].
pub const SQUARE_BYTES: u64 = 16;
/// G-buffer pixels a side of a tile of [`Visibility::touched`] (mirrors
/// `glsl/area_tiles.glsl`).
pub const AREA_TILE_PX: u32 = 8;

/// Tiles of [`Visibility::touched`] of a target of `width` × `height`
/// G-buffer pixels.
fn area_tiles(width: u32, height: u32) -> u64 {
    width.div_ceil(AREA_TILE_PX) as u64 * height.div_ceil(AREA_TILE_PX) as u64
}

pub struct ComputeRaster {
    pipeline: ComputePipeline<SplatComputePush>,
    /// The depth peel of the layered method's later layers (the shader
    /// with `SPLAT_PEEL`).
    peel: ComputePipeline<SplatComputePush>,
    /// Whether the marking resolve skips the tiles no splat reaches (the
    /// default): else every tile starts flagged, as the test that they
    /// give the same bytes renders.
    skips_untouched: bool,
}

/// The buffers of one target of `width` × `height` pixels: its visibility
/// words and the list of large splats (with the dispatch that draws them).
pub struct Visibility {
    /// One per target pixel (a sample).
    pub words: Buffer,
    /// What a first layer's pass writes for the area coverage; none in a
    /// depth peel's target (the peel writes none).
    area: Option<Box<AreaBuffers>>,
    /// Whether the pass writes the squares (the area resolve reads them).
    writes_squares: bool,
    large: Buffer,
    width: u32,
    height: u32,
}

/// What the compute raster writes for the area coverage: one of each where
/// the G-buffer resolves by its samples (never written).
struct AreaBuffers {
    /// Per splat index, the square the pass drew (centre and edge in
    /// target pixels, eye depth: 4 floats), for the area pass.
    squares: Buffer,
    /// Per tile of [`AREA_TILE_PX`]² G-buffer pixels, 1 where a drawn
    /// splat's box, one target pixel past it, reaches it, else 0: read by
    /// the marking resolve, which reads no word in a tile no splat
    /// reaches.
    touched: Buffer,
}

impl Visibility {
    /// The buffers of a first layer's `width` × `height` target of `cells`
    /// target pixels per G-buffer pixel along each axis, for up to
    /// `splats` splats, with their squares and the tiles they reach where
    /// `squares` (the area resolve reads them; else the pass writes none
    /// and holds one of each).
    pub fn new(
        ctx: &Arc<Context>,
        (width, height): (u32, u32),
        cells: u32,
        splats: u32,
        squares: bool,
    ) -> Result<Visibility> {
        let mut target = Visibility::peel(ctx, width, height, splats)?;
        let (held, tiles) = match squares {
            true => (splats.max(1), area_tiles(width / cells, height / cells)),
            false => (1, 1),
        };
        target.area = Some(Box::new(AreaBuffers {
            squares: Buffer::new(
                ctx,
                "raster squares",
                SQUARE_BYTES * held as u64,
                vk::BufferUsageFlags::STORAGE_BUFFER,
                MemoryLocation::GpuOnly,
            )?,
            touched: Buffer::new(
                ctx,
                "raster touched tiles",
                4 * tiles,
                vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuOnly,
            )?,
        }));
        target.writes_squares = squares;
        Ok(target)
    }

    /// The buffers of a depth peel's `width` × `height` target for up to
    /// `splats` splats: no squares.
    pub fn peel(ctx: &Arc<Context>, width: u32, height: u32, splats: u32) -> Result<Visibility> {
        let bytes = width as u64 * height as u64 * WORD_BYTES;
        assert!(
            bytes <= ctx.info.max_storage_buffer_range,
            "the plan's bands keep the words within the storage buffer range"
        );
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_DST;
        Ok(Visibility {
            words: Buffer::new(ctx, "visibility", bytes, usage, MemoryLocation::GpuOnly)?,
            area: None,
            writes_squares: false,
            large: Buffer::new(
                ctx,
                "large splats",
                16 + 4 * splats.max(1) as u64,
                usage | vk::BufferUsageFlags::INDIRECT_BUFFER,
                MemoryLocation::GpuOnly,
            )?,
            width,
            height,
        })
    }

    /// Visibility words per row.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Rows of visibility words.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The squares of a first layer's target that writes them
    /// ([`Visibility::new`]).
    pub fn squares(&self) -> &Buffer {
        assert!(self.writes_squares, "a target without squares");
        self.squares_bind()
    }

    /// The buffer bound as the first layer's squares: written where
    /// [`Visibility::writes_squares`], else one square never written.
    fn squares_bind(&self) -> &Buffer {
        &self.area_bind().squares
    }

    /// The tiles the splats reach, of a first layer's target that writes
    /// its squares ([`Visibility::touched`]).
    pub fn touched(&self) -> &Buffer {
        assert!(self.writes_squares, "a target without squares");
        self.touched_bind()
    }

    /// The buffer bound as the first layer's touched tiles (as the squares).
    fn touched_bind(&self) -> &Buffer {
        &self.area_bind().touched
    }

    fn area_bind(&self) -> &AreaBuffers {
        let area = self.area.as_deref();
        area.expect("a first layer's target holds the area's buffers")
    }
}

impl ComputeRaster {
    /// The pipeline, on a device with 64-bit buffer atomics (the caller
    /// checks: `GBufferPasses` makes it only there).
    pub fn new(ctx: &Arc<Context>, shape: SplatShape) -> Result<ComputeRaster> {
        assert!(ctx.info.buffer_int64_atomics, "64-bit buffer atomics");
        let b = Binding::StorageBuffer;
        let (spirv, peel) = match shape {
            SplatShape::Square => (SPIRV, PEEL_SPIRV),
            SplatShape::Disc => (DISC_SPIRV, PEEL_DISC_SPIRV),
        };
        let image = Binding::StorageImage;
        Ok(ComputeRaster {
            pipeline: ComputePipeline::new(ctx, "splat_compute", spirv, &[b, b, b, b, b])?,
            peel: ComputePipeline::new(ctx, "splat_compute_peel", peel, &[b, b, b, image])?,
            skips_untouched: true,
        })
    }

    /// Whether the marking resolve skips the tiles no splat reaches
    /// (default true; the same image bit for bit: false only to compare).
    pub fn set_skips_untouched(&mut self, on: bool) {
        self.skips_untouched = on;
    }

    /// Records one raster pass as pass `name`: `count` splats of `splats`
    /// through `push` (the sprite path's, its jitter in the centre, for a target of the
    /// visibility's size) into `target`, cleared first, after `before`
    /// (the last access to its words: a resolve's read, or none), and the
    /// barrier that hands the words to the resolve's compute reads.
    /// `cells` is the target pixels per G-buffer pixel along each axis:
    /// each G-buffer pixel's block of cells² target pixels samples it at
    /// the points of a rotated grid (`glsl/splat_compute_main.glsl`).
    ///
    /// With `previous` (the previous layer's resolved eye image, last
    /// written by its resolve), the depth peel of a later layer: at each
    /// target pixel only the splats beyond it by their thickness, as the
    /// sprite path's peel keeps them; `target` is then the whole G-buffer,
    /// a whole number of times its size along each axis.
    #[allow(clippy::too_many_arguments)]
    pub fn record<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        name: &str,
        target: &'r Visibility,
        before: Access,
        splats: &'r Buffer,
        count: u32,
        push: &SplatPush,
        cells: u32,
        previous: Option<&'r Image>,
    ) {
        assert!(
            cells >= 1 && target.width.is_multiple_of(cells),
            "whole G-buffer pixels"
        );
        if let Some(image) = previous {
            let (w, h) = (image.width(), image.height());
            assert!(
                target.width == cells * w && target.height == cells * h,
                "the peel's target is the G-buffer's size times its cells"
            );
        }
        assert_eq!(
            push.extent,
            [target.width as f32, target.height as f32],
            "the projection is the target's"
        );
        assert!(
            count as u64 * std::mem::size_of::<SplatVertex>() as u64 <= splats.size(),
            "the splats are in the buffer"
        );
        let base = push.for_compute(count);
        let mut binds = vec![
            Bind::StorageBuffer(splats),
            Bind::StorageBuffer(&target.words),
            Bind::StorageBuffer(&target.large),
        ];
        let pipeline = match previous {
            Some(image) => {
                binds.push(Bind::StorageImage(image));
                &self.peel
            }
            None => {
                binds.push(Bind::StorageBuffer(target.squares_bind()));
                binds.push(Bind::StorageBuffer(target.touched_bind()));
                &self.pipeline
            }
        };
        frame.pass(name, |rec| {
            // The words and the large list were last read by the previous
            // pass's resolve and large-splat dispatch.
            rec.memory_barrier(before, Access::FILL);
            rec.memory_barrier(Access::INDIRECT_READ, Access::FILL);
            if let Some(image) = previous {
                // Written by the previous layer's resolve.
                rec.barriers(&[(image, Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ)]);
            }
            rec.fill_u32(&target.words, u32::MAX);
            if let (None, Some(area)) = (previous, &target.area) {
                rec.fill_u32(&area.touched, !self.skips_untouched as u32);
            }
            rec.update_u32(&target.large, &[0, large_chunks(push.max_point_size), 1, 0]);
            rec.memory_barrier(Access::FILL, Access::COMPUTE_READ_WRITE);
            let small = base
                .with_stage(0, cells)
                .with_squares(target.writes_squares);
            rec.dispatch(pipeline, &binds, &small, [count.div_ceil(GROUP), 1, 1]);
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::INDIRECT_READ);
            let large = base.with_stage(1, cells);
            rec.dispatch_indirect(pipeline, &binds, &large, &target.large, 0);
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ);
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;
    use crate::vk::LLVMPIPE_LOOP_ITERATIONS;

    #[test]
    fn large_splats_take_enough_chunks() {
        // SSAA 4, 255 px: 1021² = 1,042,441 pixels, one chunk.
        assert_eq!(large_chunks(255.0 * 4.0), 1);
        assert_eq!(large_chunks(255.0 * 8.0), 4);
        assert_eq!(large_chunks(255.0 * 16.0), 16);
        assert_eq!(large_chunks(0.0), 1);
        for size in [1.0f32, 100.0, 1023.0, 1024.0, 5000.5] {
            let side = size.ceil() as u64 + 1;
            assert!(large_chunks(size) as u64 * CHUNK_PIXELS as u64 >= side * side);
        }
    }

    #[test]
    fn a_first_stage_square_stays_within_llvmpipes_loop_limit() {
        // The first stage draws a box of at most LARGE_PIXELS target
        // pixels in one invocation: its loop iterations (per target pixel
        // at most one of each nested loop: the peel's G-buffer rows and
        // pixels, then the target's rows and pixels; and the mask of cell
        // columns, K ≤ 16 iterations, on the square's first and last
        // rows, once per G-buffer pixel of them in the peel: at most two
        // per target pixel), and before them the tiles of the area's
        // marking its box reaches (at most 34 a side: a square of 255
        // pixels, lavapipe's largest, dilated by a target pixel, over
        // tiles of 8; a larger box than LARGE_PIXELS draws nothing in
        // this stage) within half of llvmpipe's per-invocation limit.
        let tiles_a_side = (255u64 + 2).div_ceil(AREA_TILE_PX as u64) + 1;
        let worst = 6 * LARGE_PIXELS as u64 + 2 * 16 + tiles_a_side * (tiles_a_side + 1);
        assert!(worst <= LLVMPIPE_LOOP_ITERATIONS / 2, "{worst}");
    }

    #[test]
    fn push_constants_match_the_glsl_block() {
        check_push_layout::<SplatComputePush>("splat_compute", SPIRV).unwrap();
        check_push_layout::<SplatComputePush>("splat_compute_disc", DISC_SPIRV).unwrap();
        check_push_layout::<SplatComputePush>("splat_compute_peel", PEEL_SPIRV).unwrap();
        check_push_layout::<SplatComputePush>("splat_compute_peel_disc", PEEL_DISC_SPIRV).unwrap();
        assert_eq!(std::mem::size_of::<SplatComputePush>(), 128);
        assert!(include_str!("../../glsl/splat_compute_disc.comp").contains("#define SPLAT_DISC"));
        let peel = include_str!("../../glsl/splat_compute_peel.comp");
        assert!(peel.contains("#define SPLAT_PEEL") && !peel.contains("SPLAT_DISC"));
        let peel_disc = include_str!("../../glsl/splat_compute_peel_disc.comp");
        assert!(
            peel_disc.contains("#define SPLAT_PEEL") && peel_disc.contains("#define SPLAT_DISC")
        );
        let tiles = include_str!("../../glsl/area_tiles.glsl");
        assert!(tiles.contains(&format!("const int AREA_TILE_PX = {AREA_TILE_PX};")));
        let shader = include_str!("../../glsl/splat_compute_main.glsl");
        assert!(shader.contains(&format!("const uint LARGE_PIXELS = {LARGE_PIXELS}u;")));
        assert!(shader.contains(&format!("const uint CHUNK_PIXELS = {CHUNK_PIXELS}u;")));
        assert!(shader.contains(&format!("layout(local_size_x = {GROUP}) in;")));
    }
}
