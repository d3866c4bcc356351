//! The G-buffer resolve pass (`glsl/gbuffer_resolve.comp`): folds one raster
//! sample into the running color sum and nearest eye position, and after the
//! last sample writes the G-buffer (mean color, coverage fraction).

use std::sync::Arc;

use ash::vk;

use crate::error::Result;
use crate::vk::{as_bytes, groups, Bind, ComputePipeline, Context, Image};

#[repr(C)]
#[derive(Debug, Clone, Copy)]
struct Push {
    extent: [i32; 2],
    sample_index: u32,
    sample_count: u32,
}

static SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gbuffer_resolve.comp.spv"));

pub struct GBufferResolve {
    pipeline: ComputePipeline,
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
        let image = vk::DescriptorType::STORAGE_IMAGE;
        Ok(GBufferResolve {
            pipeline: ComputePipeline::new(
                ctx,
                "gbuffer_resolve",
                SPIRV,
                &[image; 5],
                std::mem::size_of::<Push>() as u32,
            )?,
        })
    }

    /// Folds sample `index` of `count` into the G-buffer.
    pub fn record(
        &self,
        cmd: vk::CommandBuffer,
        images: &ResolveImages<'_>,
        index: u32,
        count: u32,
    ) {
        let (w, h) = (images.gbuffer_color.width, images.gbuffer_color.height);
        let push = Push {
            extent: [w as i32, h as i32],
            sample_index: index,
            sample_count: count,
        };
        self.pipeline.dispatch(
            cmd,
            &[
                Bind::StorageImage(images.sample_color),
                Bind::StorageImage(images.sample_eye),
                Bind::StorageImage(images.color_sum),
                Bind::StorageImage(images.gbuffer_eye),
                Bind::StorageImage(images.gbuffer_color),
            ],
            as_bytes(&push),
            [groups(w, 8), groups(h, 8), 1],
        );
    }
}
