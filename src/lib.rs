//! pointlens: an offline point-cloud renderer with physically based depth of
//! field on Vulkan. See `docs/ARCHITECTURE.md` for the pipeline.
//!
//! The frame is one chain ([`render::Renderer`]): [`input`] →
//! [`cloud::PointCloud`] → [`tree`] (the splat hierarchy, per camera) →
//! upload → [`gbuffer`] (K×K splat raster samples,
//! resolved) → a depth-of-field method of [`passes`] (chosen by
//! [`options::Method`]) → readback → [`image_io`].

// `unsafe` lives only in `vk` (which allows it, block by block, each with
// its invariant); everything else is safe Rust.
#![deny(unsafe_code)]
#![deny(unsafe_op_in_unsafe_fn)]
#![warn(clippy::undocumented_unsafe_blocks)]

pub mod bench;
pub mod camera;
pub mod chart;
pub mod cloud;
pub mod color;
pub mod console;
pub mod convert;
pub mod error;
pub mod fields;
pub mod flags;
pub mod gaussian_render;
pub mod gaussians;
pub mod gbuffer;
pub mod host_gbuffer;
pub mod image_io;
pub mod input;
pub mod job;
pub mod metrics;
pub mod options;
pub mod passes;
pub mod reference;
pub mod render;
pub mod report;
pub mod scene;
pub mod sequence;
pub mod synth;
pub mod tree;
pub mod veil;
pub mod video;
#[allow(unsafe_code)]
pub mod vk;

pub use cloud::PointCloud;

/// The threads the CPU work (PLY conversion, splat sizes, the splat
/// hierarchy, its traversal) is split over: every core the process may use.
pub fn available_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |t| t.get())
}

/// `f` of every item, on up to `threads` threads that each take the next
/// item not yet taken (items of uneven cost balance themselves); the
/// results in the items' order.
pub fn parallel_map<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let next = AtomicUsize::new(0);
    let slots: Vec<Mutex<Option<R>>> = items.iter().map(|_| Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..threads.max(1).min(items.len()) {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(item) = items.get(i) else {
                    break;
                };
                let r = f(item);
                *slots[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(r);
            });
        }
    });
    slots
        .into_iter()
        .map(|s| {
            s.into_inner()
                .unwrap_or_else(|e| e.into_inner())
                .expect("every item was mapped")
        })
        .collect()
}

/// Bytes a thread of [`copy_in_parallel`] copies at least: below this a
/// thread's start costs more than the copy it saves.
pub const COPY_CHUNK_BYTES: usize = 1 << 20;

/// The `pieces`, one after another, copied into `to` (exactly as long as
/// they are together) by up to `threads` threads (at most 8: the copy is
/// bound by memory), each taking a contiguous run of `to`. A fresh
/// allocation's pages are faulted in by the copy, so the threads share
/// the page faults as well (a splat buffer's 5 MB took one thread 3 ms on
/// the 2-core machine; a 1080p EXR readback's 33 MB, 9–29 ms on an
/// H200's host).
pub fn copy_in_parallel(pieces: &[&[u8]], to: &mut [u8], threads: usize) {
    let total: usize = pieces.iter().map(|p| p.len()).sum();
    assert_eq!(total, to.len(), "the pieces fill the destination");
    let chunk = total
        .div_ceil(threads.clamp(1, 8))
        .max(COPY_CHUNK_BYTES)
        .max(1);
    // Each run of `to` with the parts of the pieces that fall in it.
    let mut runs: Vec<(&mut [u8], Vec<&[u8]>)> = Vec::new();
    let mut rest = to;
    let mut pending = pieces.iter().copied();
    let mut current: &[u8] = &[];
    while !rest.is_empty() {
        let n = chunk.min(rest.len());
        let (run, tail) = std::mem::take(&mut rest).split_at_mut(n);
        rest = tail;
        let (mut parts, mut need) = (Vec::new(), run.len());
        while need > 0 {
            if current.is_empty() {
                current = pending.next().expect("the pieces fill the destination");
                continue;
            }
            let take = need.min(current.len());
            parts.push(&current[..take]);
            current = &current[take..];
            need -= take;
        }
        runs.push((run, parts));
    }
    let copy = |(run, parts): (&mut [u8], Vec<&[u8]>)| {
        let mut at = 0;
        for p in parts {
            run[at..at + p.len()].copy_from_slice(p);
            at += p.len();
        }
    };
    if runs.len() <= 1 {
        runs.into_iter().for_each(copy);
    } else {
        std::thread::scope(|scope| {
            for r in runs {
                scope.spawn(move || copy(r));
            }
        });
    }
}

pub use error::{Error, Result};

#[cfg(test)]
mod tests {
    use super::*;

    /// The parallel copy of pieces is their concatenation, at sizes around
    /// its chunks' edges (one thread, several, a last chunk shorter by
    /// one), with pieces of every size (empty ones, ones across chunks).
    #[test]
    fn the_parallel_copy_is_the_concatenation() {
        let bytes: Vec<u8> = (0..5 * COPY_CHUNK_BYTES as u32 + 48)
            .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
            .collect();
        for len in [
            0,
            16,
            COPY_CHUNK_BYTES,
            COPY_CHUNK_BYTES + 16,
            3 * COPY_CHUNK_BYTES - 1,
            bytes.len(),
        ] {
            let whole = &bytes[..len];
            // Cut at a few irregular places, empty pieces included.
            let cuts = [0, 0, len / 7, len / 3, len / 3, len / 2 + 1, len];
            let pieces: Vec<&[u8]> = cuts
                .windows(2)
                .map(|w| &whole[w[0].min(len)..w[1].min(len).max(w[0].min(len))])
                .collect();
            for threads in [1, 2, 3, 16] {
                let mut to = vec![0u8; len];
                copy_in_parallel(&pieces, &mut to, threads);
                assert!(to == whole, "{len} bytes, {threads} threads");
            }
        }
    }
}
