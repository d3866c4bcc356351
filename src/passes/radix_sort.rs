//! Sorting and prefix sums on the device (issue 31: the Gaussians' depth
//! order and tile lists): a stable least-significant-digit radix sort of
//! 32-bit keys with 32-bit values (`glsl/radix_sort.comp`, 4-bit digits)
//! and an exclusive prefix sum (`glsl/scan.comp`). Both count their input
//! from a word of a `counts` buffer, which the device may have written
//! (the length of a tile list), clamped to a capacity the host sized.
//! Neither needs subgroup operations: within a block each invocation takes
//! a run of consecutive keys, so the order within a block is the
//! invocations' order, and a workgroup prefix sum ranks them.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use crate::error::Result;
use crate::push_constants;
use crate::vk::{Access, Bind, Binding, Buffer, ComputePipeline, Context, Recorder};

static SORT_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/radix_sort.comp.spv"));
static SCAN_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/scan.comp.spv"));

/// Keys (or values) a workgroup of either shader takes: 256 invocations ×
/// 16 (mirrors `BLOCK` in both shaders).
pub const BLOCK: u32 = 4096;
/// Bits of a digit (the shader's `RADIX` is 2^4).
pub const DIGIT_BITS: u32 = 4;
/// `counts` index meaning "the push constant's count".
pub const NONE: u32 = u32::MAX;

push_constants! {
    pub struct SortPush {
        pub stage: u32,
        pub shift: u32,
        pub count_index: u32,
        pub capacity: u32,
    }
}

push_constants! {
    pub struct ScanPush {
        pub stage: u32,
        pub n: u32,
        pub count_index: u32,
        pub total_index: u32,
        pub gather: u32,
    }
}

/// Blocks of `n` keys.
pub fn blocks(n: u32) -> u32 {
    n.div_ceil(BLOCK)
}

/// The pipelines of both.
pub struct RadixSort {
    sort: ComputePipeline<SortPush>,
    scan: ComputePipeline<ScanPush>,
}

/// The scratch of a sort of up to `capacity` pairs: the second key and
/// value buffers (the passes alternate) and the digit counts.
pub struct SortScratch {
    pub keys: Buffer,
    pub values: Buffer,
    hist: Buffer,
    capacity: u32,
}

/// Which buffers hold a sort's result.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SortedIn {
    /// The buffers sorted.
    Input,
    /// The scratch's.
    Scratch,
}

/// A device buffer of `words` 32-bit words (at least one) that compute
/// shaders read and write and the host may fill or copy.
pub fn words_buffer(ctx: &Arc<Context>, name: &str, words: u64) -> Result<Buffer> {
    let usage = vk::BufferUsageFlags::STORAGE_BUFFER
        | vk::BufferUsageFlags::TRANSFER_DST
        | vk::BufferUsageFlags::TRANSFER_SRC;
    Buffer::new(ctx, name, 4 * words.max(1), usage, MemoryLocation::GpuOnly)
}

impl SortScratch {
    pub fn new(ctx: &Arc<Context>, name: &str, capacity: u32) -> Result<SortScratch> {
        Ok(SortScratch {
            keys: words_buffer(ctx, &format!("{name} keys"), capacity as u64)?,
            values: words_buffer(ctx, &format!("{name} values"), capacity as u64)?,
            hist: words_buffer(ctx, &format!("{name} digits"), 16 * blocks(capacity) as u64)?,
            capacity,
        })
    }

    /// Pairs it sorts at most.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }
}

/// An exclusive prefix sum's scratch: one word per block.
pub struct ScanScratch {
    sums: Buffer,
    capacity: u32,
}

impl ScanScratch {
    pub fn new(ctx: &Arc<Context>, name: &str, capacity: u32) -> Result<ScanScratch> {
        Ok(ScanScratch {
            sums: words_buffer(ctx, name, blocks(capacity) as u64)?,
            capacity,
        })
    }
}

impl RadixSort {
    pub fn new(ctx: &Arc<Context>) -> Result<RadixSort> {
        let b = Binding::StorageBuffer;
        Ok(RadixSort {
            sort: ComputePipeline::new(ctx, "radix_sort", SORT_SPIRV, &[b; 6])?,
            scan: ComputePipeline::new(ctx, "scan", SCAN_SPIRV, &[b; 5])?,
        })
    }

    /// Records a stable sort of the pairs (`keys[i]`, `values[i]`), `i <
    /// min(counts[count_index], capacity)`, by the low `bits` bits of the
    /// keys (higher bits must be zero, or equal), after the compute writes
    /// that made them. Returns where the result is (the passes alternate
    /// between the input and the scratch); it is ready for compute reads.
    #[allow(clippy::too_many_arguments)]
    pub fn record_sort<'r>(
        &'r self,
        rec: &mut Recorder<'_, 'r>,
        keys: &'r Buffer,
        values: &'r Buffer,
        scratch: &'r SortScratch,
        counts: &'r Buffer,
        count_index: u32,
        capacity: u32,
        bits: u32,
    ) -> SortedIn {
        assert!(capacity <= scratch.capacity, "the scratch holds the pairs");
        assert!(4 * capacity as u64 <= keys.size().min(values.size()));
        let groups = [blocks(capacity).max(1), 1, 1];
        let passes = bits.div_ceil(DIGIT_BITS);
        for pass in 0..passes {
            let (from, to) = match pass % 2 {
                0 => ((keys, values), (&scratch.keys, &scratch.values)),
                _ => ((&scratch.keys, &scratch.values), (keys, values)),
            };
            let binds = [
                Bind::StorageBuffer(from.0),
                Bind::StorageBuffer(from.1),
                Bind::StorageBuffer(to.0),
                Bind::StorageBuffer(to.1),
                Bind::StorageBuffer(&scratch.hist),
                Bind::StorageBuffer(counts),
            ];
            let push = |stage| SortPush {
                stage,
                shift: pass * DIGIT_BITS,
                count_index,
                capacity,
            };
            rec.dispatch(&self.sort, &binds, &push(0), groups);
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
            rec.dispatch(&self.sort, &binds, &push(1), [1, 1, 1]);
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
            rec.dispatch(&self.sort, &binds, &push(2), groups);
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
        }
        match passes % 2 {
            0 => SortedIn::Input,
            _ => SortedIn::Scratch,
        }
    }

    /// Records `out[i] = Σ_{j<i} values[index[j]]` (or `values[j]` when
    /// `index` is None) for `i < n` (or `min(counts[count_index], n)`),
    /// and, unless `total_index` is [`NONE`], the total to
    /// `counts[total_index]` and the largest total so far to
    /// `counts[total_index + 1]`; after the compute writes that made the
    /// values, and ready for compute reads.
    #[allow(clippy::too_many_arguments)]
    pub fn record_scan<'r>(
        &'r self,
        rec: &mut Recorder<'_, 'r>,
        values: &'r Buffer,
        index: Option<&'r Buffer>,
        out: &'r Buffer,
        scratch: &'r ScanScratch,
        counts: &'r Buffer,
        n: u32,
        count_index: u32,
        total_index: u32,
    ) {
        assert!(n <= scratch.capacity, "the scratch holds the blocks");
        assert!(4 * n as u64 <= out.size());
        let binds = [
            Bind::StorageBuffer(values),
            Bind::StorageBuffer(index.unwrap_or(values)),
            Bind::StorageBuffer(out),
            Bind::StorageBuffer(&scratch.sums),
            Bind::StorageBuffer(counts),
        ];
        let push = |stage| ScanPush {
            stage,
            n,
            count_index,
            total_index,
            gather: index.is_some() as u32,
        };
        let groups = [blocks(n).max(1), 1, 1];
        rec.dispatch(&self.scan, &binds, &push(0), groups);
        rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
        rec.dispatch(&self.scan, &binds, &push(1), [1, 1, 1]);
        rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
        rec.dispatch(&self.scan, &binds, &push(2), groups);
        rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    #[test]
    fn push_constants_match_the_glsl_blocks() {
        check_push_layout::<SortPush>("radix_sort", SORT_SPIRV).unwrap();
        check_push_layout::<ScanPush>("scan", SCAN_SPIRV).unwrap();
        for shader in [
            include_str!("../../glsl/radix_sort.comp"),
            include_str!("../../glsl/scan.comp"),
        ] {
            assert!(shader.contains("const uint GROUP = 256u;"));
            assert!(shader.contains("const uint ITEMS = 16u;"));
            assert_eq!(256 * 16, BLOCK);
        }
        assert!(include_str!("../../glsl/radix_sort.comp").contains("const uint RADIX = 16u;"));
        assert_eq!(1 << DIGIT_BITS, 16);
    }
}
