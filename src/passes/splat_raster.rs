//! The splat raster pass (`glsl/splat_raster.{vert,frag}`): every splat as
//! a hardware point sprite (POINT_LIST + `gl_PointSize`), depth-tested
//! (strict LESS), into one pass's sample target — (r, g, b, z): linear
//! color and eye depth, rgba32f — and depth target.

use std::sync::Arc;

use ash::vk;

use crate::error::Result;
use crate::push_constants;
use crate::vk::{
    Access, Buffer, Context, Frame, Image, PointPipeline, PointPipelineDesc, VertexAttribute,
};

pub const COLOR_FORMAT: vk::Format = vk::Format::R16G16B16A16_SFLOAT;
pub const EYE_FORMAT: vk::Format = vk::Format::R32G32B32A32_SFLOAT;
/// A raster sample: linear color and eye depth.
pub const SAMPLE_FORMAT: vk::Format = vk::Format::R32G32B32A32_SFLOAT;
pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

/// One splat as the vertex shader reads it (24 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SplatVertex {
    /// World position (xyz) and world diameter (w).
    pub position_size: [f32; 4],
    /// Linear RGB, 16-bit UNORM; alpha unused.
    pub color: [u16; 4],
}

const _: () = assert!(std::mem::size_of::<SplatVertex>() == 24);

push_constants! {
    /// Push constants of the pass; mirrors `glsl/splat_raster.glsl` (128 bytes).
    pub struct SplatPush {
        pub eye: [f32; 4],
        pub right: [f32; 4],
        pub up: [f32; 4],
        pub forward: [f32; 4],
        pub center: [f32; 2],
        pub extent: [f32; 2],
        pub jitter: [f32; 2],
        pub lens_u: [f32; 2],
        pub f_px: f32,
        pub near: f32,
        pub far: f32,
        pub splat_px: f32,
        pub aperture_radius: f32,
        pub focus_distance: f32,
        pub max_point_size: f32,
        pub pad: f32,
    }
}

/// The render targets of one raster pass.
pub struct SampleTargets {
    /// (r, g, b, z) per sample; uncovered: (background, +∞).
    pub sample: Image,
    pub depth: Image,
}

impl SampleTargets {
    /// The sample (rgba32f, also a storage image) and depth (D32) targets
    /// of `samples` samples per pixel.
    pub fn new(ctx: &Arc<Context>, width: u32, height: u32, samples: u32) -> Result<SampleTargets> {
        let attach = vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::STORAGE;
        let image = |name: &str, format: vk::Format, usage: vk::ImageUsageFlags| {
            Image::new_multisampled(ctx, name, format, width, height, samples, usage)
        };
        Ok(SampleTargets {
            sample: image("sample", SAMPLE_FORMAT, attach)?,
            depth: image(
                "sample depth",
                DEPTH_FORMAT,
                vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
            )?,
        })
    }

    /// Bytes of device memory per pixel of `samples` samples.
    pub fn bytes_per_pixel(samples: u32) -> u64 {
        use crate::vk::texel_bytes;
        samples as u64 * (texel_bytes(SAMPLE_FORMAT) + texel_bytes(DEPTH_FORMAT))
    }
}

/// The graphics pipeline of the pass, for targets of one sample count.
pub struct SplatRaster {
    pipeline: PointPipeline<SplatPush>,
}

static VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_raster.vert.spv"));
static FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_raster.frag.spv"));

impl SplatRaster {
    /// The pipeline for targets of `samples` samples per pixel.
    pub fn new(ctx: &Arc<Context>, samples: u32) -> Result<SplatRaster> {
        let pipeline = PointPipeline::new(
            ctx,
            &PointPipelineDesc {
                name: "splat_raster",
                vertex_spirv: VERT,
                fragment_spirv: FRAG,
                stride: std::mem::size_of::<SplatVertex>() as u32,
                attributes: &[
                    VertexAttribute {
                        format: vk::Format::R32G32B32A32_SFLOAT,
                        offset: std::mem::offset_of!(SplatVertex, position_size) as u32,
                    },
                    VertexAttribute {
                        format: vk::Format::R16G16B16A16_UNORM,
                        offset: std::mem::offset_of!(SplatVertex, color) as u32,
                    },
                ],
                color_formats: &[SAMPLE_FORMAT],
                depth_format: DEPTH_FORMAT,
                samples,
            },
        )?;
        Ok(SplatRaster { pipeline })
    }

    /// Records one raster pass as pass `name`: the targets' barriers
    /// (`first`: nothing before; otherwise the previous pass's resolve
    /// read them), a clear (the sample to (`background`, +∞), depth to 1),
    /// the draw of `count` splats, and the barrier that hands the sample to
    /// the resolve's compute reads.
    #[allow(clippy::too_many_arguments)]
    pub fn record<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        name: &str,
        targets: &'r SampleTargets,
        splats: &'r Buffer,
        count: u32,
        background: [f32; 3],
        push: &SplatPush,
        first: bool,
    ) {
        frame.pass(name, |rec| {
            let (color_src, depth_src) = if first {
                (Access::NONE, Access::NONE)
            } else {
                (Access::COMPUTE_READ, Access::DEPTH_WRITE)
            };
            rec.barriers(&[
                (&targets.sample, color_src, Access::COLOR_WRITE),
                (&targets.depth, depth_src, Access::DEPTH_WRITE),
            ]);
            let [r, g, b] = background;
            rec.draw_points(
                &self.pipeline,
                &[(&targets.sample, [r, g, b, f32::INFINITY])],
                &targets.depth,
                splats,
                count,
                push,
            );
            rec.barriers(&[(&targets.sample, Access::COLOR_WRITE, Access::COMPUTE_READ)]);
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    #[test]
    fn push_constants_match_the_glsl_block() {
        check_push_layout::<SplatPush>("splat_raster.vert", VERT).unwrap();
        assert_eq!(std::mem::size_of::<SplatPush>(), 128);
    }
}
