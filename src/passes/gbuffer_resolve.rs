//! The G-buffer resolve pass (`glsl/gbuffer_resolve.comp`): folds one raster
//! sample into the running color sum and nearest eye position, and after the
//! last sample writes the G-buffer (mean color, coverage fraction).

use std::sync::Arc;

use crate::error::Result;
use crate::push_constants;
use crate::vk::{groups, Access, Bind, Binding, ComputePipeline, Context, Frame, Image};

push_constants! {
    struct Push {
        extent: [i32; 2],
        sample_index: u32,
        sample_count: u32,
    }
}

static SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gbuffer_resolve.comp.spv"));

pub struct GBufferResolve {
    pipeline: ComputePipeline<Push>,
}

/// The images the pass reads and writes, all in `GENERAL` layout.
pub struct ResolveImages<'a> {
    pub sample_color: &'a Image,
    pub sample_eye: &'a Image,
    pub color_sum: &'a Image,
    pub gbuffer_eye: &'a Image,
    pub gbuffer_color: &'a Image,
}

impl GBufferResolve {
    pub fn new(ctx: &Arc<Context>) -> Result<GBufferResolve> {
        Ok(GBufferResolve {
            pipeline: ComputePipeline::new(
                ctx,
                "gbuffer_resolve",
                SPIRV,
                &[Binding::StorageImage; 5],
            )?,
        })
    }

    /// Records, as pass `name`, the fold of sample `index` of `count` into
    /// the G-buffer, with the barriers on the running images (the sample
    /// targets' barrier is the raster's).
    pub fn record<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        name: &str,
        images: &ResolveImages<'r>,
        index: u32,
        count: u32,
    ) {
        frame.pass(name, |rec| {
            let src = if index == 0 {
                Access::NONE
            } else {
                Access::COMPUTE_READ_WRITE
            };
            let mut list = vec![
                (images.color_sum, src, Access::COMPUTE_READ_WRITE),
                (images.gbuffer_eye, src, Access::COMPUTE_READ_WRITE),
            ];
            if index == 0 {
                list.push((images.gbuffer_color, Access::NONE, Access::COMPUTE_WRITE));
            }
            rec.barriers(&list);
            let (w, h) = (images.gbuffer_color.width(), images.gbuffer_color.height());
            rec.dispatch(
                &self.pipeline,
                &[
                    Bind::StorageImage(images.sample_color),
                    Bind::StorageImage(images.sample_eye),
                    Bind::StorageImage(images.color_sum),
                    Bind::StorageImage(images.gbuffer_eye),
                    Bind::StorageImage(images.gbuffer_color),
                ],
                &Push {
                    extent: [w as i32, h as i32],
                    sample_index: index,
                    sample_count: count,
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
        check_push_layout::<Push>("gbuffer_resolve", SPIRV).unwrap();
    }
}
