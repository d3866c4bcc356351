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
pub use error::{Error, Result};
