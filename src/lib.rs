//! pointlens: an offline point-cloud renderer with physically based depth of
//! field on Vulkan. See `docs/ARCHITECTURE.md` for the pipeline.
//!
//! The frame is one chain: [`ply`] → [`cloud::PointCloud`] → [`render::Renderer::upload`]
//! → [`gbuffer`] (K×K splat raster samples, resolved) → DOF method → readback
//! → [`image_io`].

pub mod bench;
pub mod camera;
pub mod chart;
pub mod cloud;
pub mod error;
pub mod gbuffer;
pub mod image_io;
pub mod metrics;
pub mod passes;
pub mod ply;
pub mod reference;
pub mod render;
pub mod vk;

pub use cloud::PointCloud;
pub use error::{Error, Result};
