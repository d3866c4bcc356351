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
pub mod convert;
pub mod error;
pub mod gbuffer;
pub mod image_io;
pub mod input;
pub mod job;
pub mod metrics;
pub mod options;
pub mod passes;
pub mod reference;
pub mod render;
pub mod report;
pub mod sequence;
pub mod synth;
pub mod tree;
pub mod veil;
#[allow(unsafe_code)]
pub mod vk;

pub use cloud::PointCloud;

/// The threads the CPU work (PLY conversion, splat sizes, the splat
/// hierarchy, its traversal) is split over: every core the process may use.
pub fn available_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |t| t.get())
}
pub use error::{Error, Result};
