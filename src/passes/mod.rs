//! GPU passes: one Rust file per pass beside its GLSL file of the same name
//! in `glsl/`. Each pass owns its pipeline and records with explicit inputs
//! and outputs; `crate::gbuffer` and `crate::render` chain them into a frame.

pub mod fast;
pub mod gbuffer_resolve;
pub mod rdb;
pub mod splat_raster;
