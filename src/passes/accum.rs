//! The accumulation-buffer reference (DESIGN §7, Haeberli & Akeley 1990):
//! the G-buffer chain itself, rasterised through every lens sample × SSAA
//! jitter with the sheared projection and averaged by the resolve. It adds
//! no pass after the G-buffer.

use std::sync::Arc;

use super::{DofFrame, DofInput, DofMethod, FrameView, GBufferLens, VeilRule};
use crate::camera::Camera;
use crate::error::Result;
use crate::options::{check_samples, AccumOptions};
use crate::vk::{Context, Frame, Image};

/// The accumulation reference with its options.
pub struct Accum(pub AccumOptions);

impl DofMethod for Accum {
    fn gbuffer_label(&self) -> &'static str {
        "accum"
    }

    /// Every lens sample (a Fibonacci lattice through the concentric map,
    /// taken to the aperture's shape: [`crate::camera::Aperture::lens_samples`]),
    /// each with every K×K sub-pixel sample: S·K² raster samples, each
    /// receiving pixel weighing them by its cat's eye.
    fn gbuffer_lens(&self, camera: &Camera) -> GBufferLens {
        GBufferLens {
            positions: camera.aperture.lens_samples(self.0.samples),
            cat_eye: camera.aperture.cat_eye,
            blurred_after: false,
        }
    }

    /// None: each lens sample's own (sheared) projection places every
    /// point, so the band holds only the splats' squares (a sprite whose
    /// centre is outside the target is not drawn).
    fn guard_coc_px(&self, _: &Camera, _: Option<(f32, f32)>) -> f32 {
        0.0
    }

    /// Only what no raster draws: splats nearer than the near plane.
    fn veil_rule(&self) -> VeilRule {
        VeilRule::BeyondNear
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
