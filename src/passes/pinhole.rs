//! No depth of field: the resolved G-buffer color is the image.

use std::sync::Arc;

use super::{DofFrame, DofInput, DofMethod, FrameView, GBufferLens, VeilRule};
use crate::camera::Camera;
use crate::error::Result;
use crate::vk::{Context, Frame, Image};

/// The pinhole method: no pass of its own.
pub struct Pinhole;

impl DofMethod for Pinhole {
    /// The G-buffer is the image: no blur hides its error.
    fn gbuffer_lens(&self, _: &Camera) -> GBufferLens {
        GBufferLens::centre()
    }

    fn guard_coc_px(&self, _: &Camera, _: Option<(f32, f32)>) -> f32 {
        0.0
    }

    /// No blur, no veil: the pinhole image draws what it can.
    fn veil_rule(&self) -> VeilRule {
        VeilRule::None
    }

    fn prepare<'m>(&'m self, _: &Arc<Context>, _: &FrameView) -> Result<Box<dyn DofFrame + 'm>> {
        Ok(Box::new(Pinhole))
    }
}

impl DofFrame for Pinhole {
    fn record<'r>(&'r self, _: &mut Frame<'r>, input: &DofInput<'r>) -> &'r Image {
        input.color
    }
}
