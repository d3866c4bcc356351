//! The depth peel's splats (`glsl/peel_cull.comp`, issue 28): before a
//! peel pass, the splats that can pass the peel's test somewhere (beyond
//! the previous layer's depth by their thickness at a pixel their sprite
//! may touch), kept in their order, and the indirect draw of them. The
//! peel then draws fewer splats — lavapipe's point path costs per splat,
//! even clipped — and gets the same image bit for bit: every splat left out
//! fails `splat_peel.frag`'s test at every sample, and the others keep
//! their order, so depth ties go to the same splat.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::splat_raster::{SplatComputePush, SplatPush, SplatVertex};
use crate::error::Result;
use crate::vk::{Access, Bind, Binding, Buffer, ComputePipeline, Context, Frame, Image};

static SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/peel_cull.comp.spv"));

/// Invocations per workgroup of the shader.
const GROUP: u32 = 256;
/// Tile edge of the nearest depths (mirrors `TILE` in the shader).
const TILE: u32 = 8;
/// Splats per run of the compaction (mirrors `RUN`).
const RUN: u32 = 256;

pub struct PeelCull {
    pipeline: ComputePipeline<SplatComputePush>,
}

/// A frame's buffers for `count` splats: each splat's flag, each run's
/// count and first place, the nearest depth of each tile of the G-buffer,
/// the kept splats (a vertex buffer) and the draw's arguments.
pub struct PeelCullBuffers {
    flags: Buffer,
    runs: Buffer,
    tiles: Buffer,
    tile_count: u32,
    /// The kept splats, in their order: the peel's vertex buffer.
    pub kept: Buffer,
    /// A `VkDrawIndirectCommand`: the peel's draw.
    pub draw: Buffer,
    count: u32,
}

impl PeelCullBuffers {
    /// The buffers for `count` splats and a G-buffer of `width` × `height`.
    pub fn new(ctx: &Arc<Context>, count: u32, width: u32, height: u32) -> Result<PeelCullBuffers> {
        let n = count.max(1) as u64;
        let tile_count = width.div_ceil(TILE) * height.div_ceil(TILE);
        let storage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let buffer = |name: &str, bytes: u64, usage| {
            Buffer::new(ctx, name, bytes, storage | usage, MemoryLocation::GpuOnly)
        };
        Ok(PeelCullBuffers {
            flags: buffer("peel cull flags", 4 * n, vk::BufferUsageFlags::empty())?,
            runs: buffer(
                "peel cull runs",
                4 * n.div_ceil(RUN as u64),
                vk::BufferUsageFlags::empty(),
            )?,
            tiles: buffer(
                "peel cull tiles",
                4 * tile_count as u64,
                vk::BufferUsageFlags::empty(),
            )?,
            tile_count,
            kept: buffer(
                "peel splats",
                n * std::mem::size_of::<SplatVertex>() as u64,
                vk::BufferUsageFlags::VERTEX_BUFFER,
            )?,
            draw: buffer("peel draw", 16, vk::BufferUsageFlags::INDIRECT_BUFFER)?,
            count,
        })
    }
}

impl PeelCull {
    pub fn new(ctx: &Arc<Context>) -> Result<PeelCull> {
        let b = Binding::StorageBuffer;
        Ok(PeelCull {
            pipeline: ComputePipeline::new(
                ctx,
                "peel_cull",
                SPIRV,
                &[b, Binding::StorageImage, b, b, b, b, b],
            )?,
        })
    }

    /// Records pass `peel.cull`: the splats of `splats` (`buffers`' count
    /// of them) that the peel through `push` (unjittered) against
    /// `previous` (the previous layer's G-buffer eye image, last written
    /// by its resolve) can keep, into `buffers.kept`, and their number
    /// into `buffers.draw`, both ready for the peel's draw.
    pub fn record<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        splats: &'r Buffer,
        previous: &'r Image,
        buffers: &'r PeelCullBuffers,
        push: &SplatPush,
    ) {
        let base = push.for_compute(buffers.count);
        let binds = [
            Bind::StorageBuffer(splats),
            Bind::StorageImage(previous),
            Bind::StorageBuffer(&buffers.flags),
            Bind::StorageBuffer(&buffers.runs),
            Bind::StorageBuffer(&buffers.kept),
            Bind::StorageBuffer(&buffers.draw),
            Bind::StorageBuffer(&buffers.tiles),
        ];
        let groups = buffers.count.div_ceil(GROUP);
        let runs = buffers.count.div_ceil(RUN).div_ceil(GROUP);
        frame.pass("peel.cull", |rec| {
            rec.barriers(&[(previous, Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ)]);
            // An earlier peel's draw read the kept splats and the draw.
            rec.memory_barrier(Access::VERTEX_READ, Access::COMPUTE_READ_WRITE);
            rec.memory_barrier(Access::INDIRECT_READ, Access::COMPUTE_READ_WRITE);
            for stage in 0..5u32 {
                if stage > 0 {
                    rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
                }
                let size = match stage {
                    0 => buffers.tile_count.div_ceil(GROUP),
                    1 => groups,
                    3 => 1,
                    _ => runs,
                };
                let push = base.with_stage(stage, 0);
                rec.dispatch(&self.pipeline, &binds, &push, [size, 1, 1]);
            }
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::VERTEX_READ);
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::INDIRECT_READ);
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    #[test]
    fn push_constants_match_the_glsl_block() {
        check_push_layout::<SplatComputePush>("peel_cull", SPIRV).unwrap();
        let cull = include_str!("../../glsl/peel_cull.comp");
        assert!(cull.contains(&format!("const int TILE = {TILE};")));
        assert!(cull.contains(&format!("const uint RUN = {RUN}u;")));
    }
}
