//! How the passes whose best shape of work differs between a CPU and a GPU
//! cut it, chosen once from the device's properties
//! (docs/decisions/kernel-sizes.md). Each form of a pass gives the same
//! bits; the choice moves only its time.

use ash::vk::PhysicalDeviceType;

use crate::vk::DeviceInfo;

/// The specialization constant of `glsl/layered_composite.comp` that sets
/// its workgroup's size (`local_size_x_id`).
pub const COMPOSITE_GROUP_ID: u32 = 4;
/// Its constant `SHARED_ROWS`: whether a workgroup shares one row.
pub const COMPOSITE_SHARED_ROWS_ID: u32 = 5;
/// The composite's workgroup in the form of a row per invocation: rows.
pub const ROWS_PER_GROUP: u32 = 64;
/// The constant `BIN_MAJOR` of `glsl/rdb_bins64.glsl`: the layout of the
/// RDB's 64-bit bins.
pub const RDB_BIN_MAJOR_ID: u32 = 6;
/// The constant `BANDS_SHARED` of `glsl/fields_bands.comp`: a workgroup
/// per texel; ids 8 and 9 set its workgroup's size.
pub const BANDS_SHARED_ID: u32 = 7;
/// The workgroup of a shared band texel (a power of two).
pub const BANDS_GROUP: u32 = 64;
/// The first band level a GPU's cut shares: texels of 8×8 pixels, one a
/// workgroup's invocation.
pub const BANDS_SHARED_LEVEL: u32 = 3;
/// The constant `WORKGROUP_STREAMS` of `glsl/layered_spread.comp`.
pub const SPREAD_STREAMS_ID: u32 = 12;
/// The most threads llvmpipe runs (its `LP_MAX_THREADS`).
pub const CPU_THREADS_MAX: u32 = 16;

/// The cut of each pass that has more than one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KernelSizes {
    /// Invocations that share one row of `layered.composite`'s prefix
    /// sums: 1, each invocation a row of its own (64 rows a workgroup);
    /// else a workgroup of this many takes a row.
    pub row_threads: u32,
    /// The RDB's 64-bit bins a plane of the tile's pixels per bin (a GPU:
    /// neighbouring invocations offer to and read neighbouring words),
    /// else a pixel's bins side by side (a CPU: one invocation's bins in
    /// a few cache lines).
    pub rdb_bin_major: bool,
    /// The first level of the two-field gather's bands whose texels a
    /// workgroup each sums (`fast.fields_bands`; None: an invocation per
    /// texel at every level). The shared sums add in another order: the
    /// images differ in their floats' last bits.
    pub bands_shared_level: Option<u32>,
    /// The workgroups the device runs at once in dispatch order, from
    /// whose as many parts of its list `layered.spread` takes its
    /// workgroups in turn (`glsl/workgroup_order.glsl`): a CPU device's
    /// threads, so that its workgroups running at once spread tiles far
    /// apart and their atomic adds do not fight over the same cache lines;
    /// 1 (the list's order) on a GPU. The same bits whatever the count:
    /// the sums are integers.
    pub workgroup_streams: u32,
}

impl KernelSizes {
    /// Every pass in the form of lanes that each take a whole row or
    /// item: a CPU device's choice.
    pub const ALONE: KernelSizes = KernelSizes {
        row_threads: 1,
        rdb_bin_major: false,
        bands_shared_level: None,
        workgroup_streams: 1,
    };

    /// The sizes for `device`. A CPU device runs a workgroup's invocations
    /// in a few SIMD lanes on each of a few cores, so a frame's rows, one
    /// per invocation, already fill it, and a row shared by a workgroup
    /// only adds its barriers. A GPU runs tens of thousands of invocations
    /// at once, which a frame's thousand rows would leave all but idle
    /// (`layered.composite`, a thread per row: 3.7 ms of `layered2`'s
    /// 8.6 ms at 1080p on an H200): there a row takes eight subgroups,
    /// between 64 and 256 invocations and within the device's limit. The
    /// RDB's bins are laid out pixel by pixel for a CPU's caches (bin by
    /// bin costs lavapipe 1.5× in its scatter), bin by bin for a GPU's
    /// coalesced atomics (`rdb.scatter`: 6.4 of `rdb9`'s 10.2 ms there).
    /// The two-field gather's coarse band texels (8×8 to 64×64 pixels)
    /// take a workgroup each on a GPU (`fast.fields_bands`: 3.1-3.8 of
    /// `fast`'s 7.1-8.7 ms there).
    /// A CPU device's workgroups run on as many threads as it has cores
    /// (llvmpipe's, up to 16): [`KernelSizes::workgroup_streams`].
    pub fn for_device(device: &DeviceInfo) -> KernelSizes {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get() as u32);
        KernelSizes::for_limits(
            device.device_type,
            device.subgroup_size,
            device.max_compute_workgroup_invocations,
            cores.min(CPU_THREADS_MAX),
        )
    }

    /// [`KernelSizes::for_device`] from the device's type, subgroup size
    /// and most invocations of a workgroup, and a CPU device's threads.
    fn for_limits(
        device_type: PhysicalDeviceType,
        subgroup_size: u32,
        max_invocations: u32,
        cpu_threads: u32,
    ) -> KernelSizes {
        match device_type {
            PhysicalDeviceType::CPU => KernelSizes {
                workgroup_streams: cpu_threads.max(1),
                ..KernelSizes::ALONE
            },
            _ => KernelSizes::for_gpu(subgroup_size, max_invocations),
        }
    }

    /// A GPU's cut for a device of this subgroup size and most invocations
    /// of a workgroup (on a CPU device too, to measure it there).
    pub fn for_gpu(subgroup_size: u32, max_invocations: u32) -> KernelSizes {
        KernelSizes {
            row_threads: (subgroup_size.max(1) * 8)
                .clamp(64, 256)
                .min(max_invocations.max(1)),
            rdb_bin_major: true,
            bands_shared_level: Some(BANDS_SHARED_LEVEL),
            workgroup_streams: 1,
        }
    }

    /// The composite's specialization constants (id, value).
    pub fn composite_constants(&self) -> [(u32, u32); 2] {
        match self.row_threads {
            0 | 1 => [
                (COMPOSITE_GROUP_ID, ROWS_PER_GROUP),
                (COMPOSITE_SHARED_ROWS_ID, 0),
            ],
            n => [(COMPOSITE_GROUP_ID, n), (COMPOSITE_SHARED_ROWS_ID, 1)],
        }
    }

    /// The RDB's 64-bit passes' specialization constants (id, value).
    pub fn rdb_constants(&self) -> [(u32, u32); 1] {
        [(RDB_BIN_MAJOR_ID, self.rdb_bin_major as u32)]
    }

    /// The spread's specialization constants (id, value).
    pub fn spread_constants(&self) -> [(u32, u32); 1] {
        [(SPREAD_STREAMS_ID, self.workgroup_streams)]
    }

    /// The specialization constants (id, value) of the bands' pipeline
    /// for shared texels.
    pub fn bands_shared_constants() -> [(u32, u32); 3] {
        [
            (BANDS_SHARED_ID, 1),
            (BANDS_SHARED_ID + 1, BANDS_GROUP),
            (BANDS_SHARED_ID + 2, 1),
        ]
    }

    /// The composite's workgroups for `rows` rows.
    pub fn composite_groups(&self, rows: u32) -> u32 {
        match self.row_threads {
            0 | 1 => rows.div_ceil(ROWS_PER_GROUP),
            _ => rows,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cpu_keeps_rows_alone_and_a_gpu_shares_them_by_its_subgroups() {
        let sizes = |t, subgroup, most| KernelSizes::for_limits(t, subgroup, most, 2).row_threads;
        // lavapipe: a row per invocation, 64 rows a workgroup.
        assert_eq!(sizes(PhysicalDeviceType::CPU, 8, 1024), 1);
        assert_eq!(KernelSizes::ALONE.composite_groups(1080), 17);
        assert_eq!(
            KernelSizes::ALONE.composite_constants(),
            [(COMPOSITE_GROUP_ID, 64), (COMPOSITE_SHARED_ROWS_ID, 0)]
        );
        // NVIDIA (32), AMD (64), Intel (16), a GPU of 8-wide subgroups.
        assert_eq!(sizes(PhysicalDeviceType::DISCRETE_GPU, 32, 1024), 256);
        assert_eq!(sizes(PhysicalDeviceType::DISCRETE_GPU, 64, 1024), 256);
        assert_eq!(sizes(PhysicalDeviceType::INTEGRATED_GPU, 16, 1024), 128);
        assert_eq!(sizes(PhysicalDeviceType::INTEGRATED_GPU, 8, 1024), 64);
        // Never past the device's workgroup.
        assert_eq!(sizes(PhysicalDeviceType::DISCRETE_GPU, 64, 128), 128);
        let cpu = KernelSizes::for_limits(PhysicalDeviceType::CPU, 8, 1024, 2);
        assert!(!cpu.rdb_bin_major);
        let gpu = KernelSizes::for_limits(PhysicalDeviceType::DISCRETE_GPU, 32, 1024, 2);
        assert!(gpu.rdb_bin_major);
        // A CPU's threads take the spread's list in as many parts; a GPU
        // keeps its order.
        assert_eq!(cpu.workgroup_streams, 2);
        assert_eq!(gpu.workgroup_streams, 1);
        let one_core = KernelSizes::for_limits(PhysicalDeviceType::CPU, 8, 1024, 0);
        assert_eq!(one_core.workgroup_streams, 1);
        let nvidia = KernelSizes {
            row_threads: 256,
            rdb_bin_major: true,
            bands_shared_level: Some(3),
            workgroup_streams: 1,
        };
        assert_eq!(KernelSizes::for_gpu(32, 1024), nvidia);
        assert_eq!(nvidia.composite_groups(1080), 1080);
        assert_eq!(
            nvidia.composite_constants(),
            [(COMPOSITE_GROUP_ID, 256), (COMPOSITE_SHARED_ROWS_ID, 1)]
        );
    }

    #[test]
    fn the_constants_are_the_shader_s() {
        let glsl = include_str!("../../glsl/layered_composite.comp");
        assert!(glsl.contains(&format!(
            "layout(local_size_x = {ROWS_PER_GROUP}, local_size_x_id = {COMPOSITE_GROUP_ID}) in;"
        )));
        assert!(glsl.contains(&format!(
            "layout(constant_id = {COMPOSITE_SHARED_ROWS_ID}) const bool SHARED_ROWS = false;"
        )));
        let bands = include_str!("../../glsl/fields_bands.comp");
        assert!(bands.contains(&format!(
            "layout(constant_id = {BANDS_SHARED_ID}) const bool BANDS_SHARED = false;"
        )));
        assert!(bands.contains(&format!(
            "local_size_x_id = {}, local_size_y_id = {}) in;",
            BANDS_SHARED_ID + 1,
            BANDS_SHARED_ID + 2
        )));
        let spread = include_str!("../../glsl/layered_spread.comp");
        assert!(spread.contains(&format!(
            "layout(constant_id = {SPREAD_STREAMS_ID}) const uint WORKGROUP_STREAMS = 1u;"
        )));
        let bins = include_str!("../../glsl/rdb_bins64.glsl");
        assert!(bins.contains(&format!(
            "layout(constant_id = {RDB_BIN_MAJOR_ID}) const bool BIN_MAJOR = false;"
        )));
    }
}
