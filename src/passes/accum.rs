//! The accumulation-buffer reference (DESIGN §7, Haeberli & Akeley 1990):
//! the G-buffer chain itself, rasterised through every lens sample × SSAA
//! jitter with the sheared projection and averaged by the resolve. It adds
//! no pass after the G-buffer.

use std::sync::Arc;

use glam::Vec2;

use super::{DofFrame, DofInput, DofMethod, FrameView};
use crate::camera::{lens_samples, Camera};
use crate::error::Result;
use crate::options::{check_samples, AccumOptions};
use crate::vk::{Context, Frame, Image};

/// The accumulation reference with its options.
pub struct Accum(pub AccumOptions);

impl DofMethod for Accum {
    fn gbuffer_label(&self) -> &'static str {
        "accum"
    }

    /// Every lens sample (a Fibonacci lattice through the concentric map),
    /// each with every K×K sub-pixel sample: S·K² raster samples.
    fn gbuffer_lens(&self) -> Vec<Vec2> {
        lens_samples(self.0.samples)
    }

    /// The points' CoCs only: the uniform background does not move with
    /// the lens.
    fn guard_coc_px(&self, camera: &Camera, depths: Option<(f32, f32)>) -> f32 {
        depths.map_or(0.0, |(lo, hi)| camera.max_coc_px(lo, hi))
    }

    fn prepare<'m>(&'m self, _: &Arc<Context>, _: &FrameView) -> Result<Box<dyn DofFrame + 'm>> {
        check_samples(self.0.samples)?;
        Ok(Box::new(Resolved))
    }
}

/// The average of the samples is the G-buffer's color.
struct Resolved;

impl DofFrame for Resolved {
    fn record<'r>(&'r self, _: &mut Frame<'r>, input: &DofInput<'r>) -> &'r Image {
        input.color
    }
}
