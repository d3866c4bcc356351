//! Eye-dome lighting (`--edl`, issue 29 item 5; `glsl/edl.comp`): shading
//! from depth alone, for clouds whose colors do not show their shape
//! (intensity-only scans), applied to the G-buffer's first layer before
//! the depth-of-field method so that the blur acts on the shaded image.

use std::sync::Arc;

use super::DofInput;
use crate::error::Result;
use crate::options::EdlOptions;
use crate::push_constants;
use crate::vk::{groups, Access, Bind, Binding, ComputePipeline, Context, Frame};

static SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/edl.comp.spv"));

push_constants! {
    struct Push {
        extent: [i32; 2],
        strength: f32,
        radius_px: f32,
    }
}

/// The pass's pipeline, made once per renderer.
pub struct Edl {
    pipeline: ComputePipeline<Push>,
}

impl Edl {
    pub fn new(ctx: &Arc<Context>) -> Result<Edl> {
        Ok(Edl {
            pipeline: ComputePipeline::new(
                ctx,
                "edl",
                SPIRV,
                &[Binding::StorageImage, Binding::StorageImage],
            )?,
        })
    }

    /// Records, as pass `edl`, the shading of `input.color` in place from
    /// `input.eye` (both G-buffer sized, last written by compute).
    pub fn record<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>, edl: EdlOptions) {
        let (w, h) = (input.color.width(), input.color.height());
        frame.pass("edl", |rec| {
            rec.barriers(&[
                (input.eye, Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ),
                (
                    input.color,
                    Access::COMPUTE_READ_WRITE,
                    Access::COMPUTE_READ_WRITE,
                ),
            ]);
            rec.dispatch(
                &self.pipeline,
                &[
                    Bind::StorageImage(input.color),
                    Bind::StorageImage(input.eye),
                ],
                &Push {
                    extent: [w as i32, h as i32],
                    strength: edl.strength,
                    radius_px: edl.radius_px,
                },
                [groups(w, 8), groups(h, 8), 1],
            );
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    #[test]
    fn push_constants_match_the_glsl_block() {
        check_push_layout::<Push>("edl", SPIRV).unwrap();
    }
}
