//! Recycling of a frame's images and buffers: a dropped [`Image`] or
//! [`Buffer`] hands its Vulkan objects and memory to the context's pool, and
//! the next one created with the same name, format, size and usage takes
//! them back instead of being made anew. The frames of a sequence (or of a
//! benchmark) therefore build their images once: frame 2 gets frame 1's.
//!
//! What comes back is exactly what creation would give: an object of the
//! same create info, its contents undefined (every pass starts from
//! `UNDEFINED` or writes before it reads), its debug name unchanged. The
//! pool holds what the last frame dropped and no more: [`Context::next_frame`]
//! frees what two frames in a row did not take, and an allocation that
//! fails empties the pool and tries again, so memory stays at about one
//! frame's worth.
//!
//! [`Image`]: super::Image
//! [`Buffer`]: super::Buffer
//! [`Context::next_frame`]: super::Context::next_frame

use ash::vk;
use gpu_allocator::vulkan::Allocation;
use gpu_allocator::MemoryLocation;

/// What a pooled object was created with: equal keys, interchangeable
/// objects.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Key {
    Image {
        name: String,
        format: vk::Format,
        extent: [u32; 3],
        samples: u32,
        usage: vk::ImageUsageFlags,
    },
    Buffer {
        name: String,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: Location,
    },
}

/// `MemoryLocation` as a comparable value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Location {
    GpuOnly,
    CpuToGpu,
    GpuToCpu,
    Unknown,
}

impl From<MemoryLocation> for Location {
    fn from(l: MemoryLocation) -> Location {
        match l {
            MemoryLocation::GpuOnly => Location::GpuOnly,
            MemoryLocation::CpuToGpu => Location::CpuToGpu,
            MemoryLocation::GpuToCpu => Location::GpuToCpu,
            MemoryLocation::Unknown => Location::Unknown,
        }
    }
}

/// The Vulkan objects and memory of a dropped image or buffer.
pub(super) enum Parts {
    Image {
        raw: vk::Image,
        view: vk::ImageView,
        allocation: Allocation,
    },
    Buffer {
        raw: vk::Buffer,
        allocation: Allocation,
    },
}

/// The pooled objects, each with the frame it was dropped in.
#[derive(Default)]
pub(super) struct Pool {
    /// Off: dropped objects are destroyed at once (for measurements).
    pub(super) disabled: bool,
    entries: Vec<(Key, Parts, u64)>,
    frame: u64,
    /// Objects taken from the pool since the context was made.
    pub(super) reused: u64,
    /// Objects created anew (not from the pool).
    pub(super) created: u64,
}

impl Pool {
    /// The first pooled object made with `key`.
    pub(super) fn take(&mut self, key: &Key) -> Option<Parts> {
        let at = self.entries.iter().position(|(k, _, _)| k == key)?;
        self.reused += 1;
        Some(self.entries.swap_remove(at).1)
    }

    /// Keeps a dropped object for the next frame; gives it back to be
    /// destroyed when the pool is disabled.
    pub(super) fn give(&mut self, key: Key, parts: Parts) -> Option<Parts> {
        if self.disabled {
            return Some(parts);
        }
        self.entries.push((key, parts, self.frame));
        None
    }

    /// Starts the next frame: returns what neither the frame that dropped
    /// it nor the one after took, to be destroyed.
    pub(super) fn next_frame(&mut self) -> Vec<Parts> {
        self.frame += 1;
        let keep_from = self.frame.saturating_sub(1);
        let (stale, kept): (Vec<_>, Vec<_>) = std::mem::take(&mut self.entries)
            .into_iter()
            .partition(|(_, _, dropped_in)| *dropped_in < keep_from);
        self.entries = kept;
        stale.into_iter().map(|(_, parts, _)| parts).collect()
    }

    /// Everything pooled, to be destroyed.
    pub(super) fn drain(&mut self) -> Vec<Parts> {
        std::mem::take(&mut self.entries)
            .into_iter()
            .map(|(_, parts, _)| parts)
            .collect()
    }

    /// Number of pooled objects.
    pub(super) fn len(&self) -> usize {
        self.entries.len()
    }
}
