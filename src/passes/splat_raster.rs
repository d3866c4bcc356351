//! The splat raster pass (`glsl/splat_raster.{vert,frag}`): every splat as
//! a hardware point sprite (POINT_LIST + `gl_PointSize`), depth-tested
//! (strict LESS), into one pass's sample target — (r, g, b, z): linear
//! color and eye depth, rgba32f — and depth target.

use std::sync::Arc;

use ash::vk;

use crate::error::Result;
use crate::options::SplatShape;
use crate::push_constants;
use crate::vk::{
    Access, Bind, Binding, Buffer, Context, DrawCount, Frame, Image, PointPipeline,
    PointPipelineDesc, VertexAttribute,
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
    /// Linear RGB, 16-bit UNORM; the fourth channel is not read (the
    /// splat hierarchy keeps a normal there: `tree::Splat`).
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
        pub min_point_size: f32,
    }
}

push_constants! {
    /// The push constants of the compute passes over the splats
    /// (`glsl/splat_compute_push.glsl`: the compute rasteriser and the
    /// peel's cull): [`SplatPush`] without its jitter, with the splat
    /// count and the pass's stage (128 bytes).
    ///
    /// `stage_cells` is the pass's stage in bits 0–14, whether the compute
    /// rasteriser writes the squares in bit 15 and, for the compute
    /// rasteriser, its target pixels per G-buffer pixel along each axis
    /// (the cells of its rotated sample grid) in bits 16–31:
    /// [`SplatComputePush::with_stage`].
    pub struct SplatComputePush {
        pub eye: [f32; 4],
        pub right: [f32; 4],
        pub up: [f32; 4],
        pub forward: [f32; 4],
        pub center: [f32; 2],
        pub extent: [f32; 2],
        pub lens_u: [f32; 2],
        pub f_px: f32,
        pub near: f32,
        pub far: f32,
        pub splat_px: f32,
        pub aperture_radius: f32,
        pub focus_distance: f32,
        pub max_point_size: f32,
        pub min_point_size: f32,
        pub count: u32,
        pub stage_cells: u32,
    }
}

impl SplatPush {
    /// The same projection for a compute pass over `count` splats, whose
    /// push has no jitter of its own: the jitter moves the centre, which
    /// moves every splat's position alike (`splat_project.glsl` adds both).
    pub fn for_compute(&self, count: u32) -> SplatComputePush {
        SplatComputePush {
            eye: self.eye,
            right: self.right,
            up: self.up,
            forward: self.forward,
            center: [
                self.center[0] + self.jitter[0],
                self.center[1] + self.jitter[1],
            ],
            extent: self.extent,
            lens_u: self.lens_u,
            f_px: self.f_px,
            near: self.near,
            far: self.far,
            splat_px: self.splat_px,
            aperture_radius: self.aperture_radius,
            focus_distance: self.focus_distance,
            max_point_size: self.max_point_size,
            min_point_size: self.min_point_size,
            count,
            stage_cells: 0,
        }
    }
}

impl SplatComputePush {
    /// The same push for stage `stage` of a pass whose sample grid has
    /// `cells` cells per axis (0 where the pass draws nothing: the peel's
    /// cull).
    pub fn with_stage(self, stage: u32, cells: u32) -> SplatComputePush {
        assert!(
            stage <= 0x7fff && cells <= 0xffff,
            "stage {stage}, cells {cells}"
        );
        SplatComputePush {
            stage_cells: stage | cells << 16,
            ..self
        }
    }

    /// The same push, the compute rasteriser writing each splat's square
    /// (for the area resolve) where `squares`.
    pub fn with_squares(self, squares: bool) -> SplatComputePush {
        SplatComputePush {
            stage_cells: (self.stage_cells & !0x8000) | (u32::from(squares) << 15),
            ..self
        }
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

    /// Whether targets of `samples` samples for `pixels` pixels may be
    /// made within `budget_bytes` (one sample always may: the fallback).
    pub fn fit(samples: u32, pixels: u64, budget_bytes: u64) -> bool {
        samples == 1 || pixels * SampleTargets::bytes_per_pixel(samples) <= budget_bytes
    }
}

/// The graphics pipeline of the pass, for targets of one sample count:
/// the plain raster, or the depth peel of a layer after the first, which
/// reads the previous layer's resolved eye depth (`glsl/splat_peel.frag`).
pub struct SplatRaster {
    pipeline: PointPipeline<SplatPush>,
    peel: bool,
}

static VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_raster.vert.spv"));
static FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_raster.frag.spv"));
static PEEL_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_peel.frag.spv"));
static DISC_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_raster_disc.frag.spv"));
static DISC_PEEL_FRAG: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/splat_peel_disc.frag.spv"));

/// How thick a surface is for the depth peel, in splat diameters: a layer
/// keeps only splats beyond the previous layer's sample by more than this
/// (mirrors `PEEL_THICKNESS` in `glsl/splat_peel.frag`).
pub const PEEL_THICKNESS_DIAMETERS: f32 = 1.0;

/// Where a raster pass's targets were last used, for its barriers.
#[derive(Debug, Clone, Copy)]
pub struct TargetsBefore {
    pub sample: Access,
    pub depth: Access,
    /// The previous layer's G-buffer eye image, read by a peel.
    pub previous: Access,
}

impl SplatRaster {
    /// The pipeline for targets of `samples` samples per pixel; the depth
    /// peel's when `peel` (shaded once per pixel, whatever the samples).
    pub fn new(
        ctx: &Arc<Context>,
        samples: u32,
        peel: bool,
        shape: SplatShape,
    ) -> Result<SplatRaster> {
        let (name, fragment_spirv, fragment_bindings): (_, _, &[Binding]) = match (peel, shape) {
            (false, SplatShape::Square) => ("splat_raster", FRAG, &[]),
            (false, SplatShape::Disc) => ("splat_raster", DISC_FRAG, &[]),
            (true, SplatShape::Square) => ("splat_peel", PEEL_FRAG, &[Binding::StorageImage]),
            (true, SplatShape::Disc) => ("splat_peel", DISC_PEEL_FRAG, &[Binding::StorageImage]),
        };
        let pipeline = PointPipeline::new(
            ctx,
            &PointPipelineDesc {
                name,
                vertex_spirv: VERT,
                fragment_spirv,
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
                fragment_bindings,
            },
        )?;
        Ok(SplatRaster { pipeline, peel })
    }

    /// Records one raster pass as pass `name` into `sample` and `depth`:
    /// the barriers from their last uses (`before`), a clear (the sample to
    /// (`background`, +∞), depth to 1), the draw of `count` splats (or as
    /// many as a compute pass wrote; a peel reads `previous`, the previous
    /// layer's G-buffer eye image), and the
    /// barrier that hands the sample to the resolve's
    /// compute reads.
    #[allow(clippy::too_many_arguments)]
    pub fn record<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        name: &str,
        sample: &'r Image,
        depth: &'r Image,
        previous: Option<&'r Image>,
        before: TargetsBefore,
        splats: &'r Buffer,
        count: DrawCount<'r>,
        background: [f32; 3],
        push: &SplatPush,
    ) {
        assert_eq!(
            previous.is_some(),
            self.peel,
            "a peel reads the previous layer"
        );
        frame.pass(name, |rec| {
            let mut list = vec![
                (sample, before.sample, Access::COLOR_WRITE),
                (depth, before.depth, Access::DEPTH_WRITE),
            ];
            if let Some(p) = previous {
                list.push((p, before.previous, Access::FRAGMENT_READ));
            }
            rec.barriers(&list);
            let binds: Vec<Bind<'r>> = previous.map(Bind::StorageImage).into_iter().collect();
            let [r, g, b] = background;
            rec.draw_points(
                &self.pipeline,
                &[(sample, [r, g, b, f32::INFINITY])],
                depth,
                &binds,
                splats,
                count,
                push,
            );
            rec.barriers(&[(sample, Access::COLOR_WRITE, Access::COMPUTE_READ)]);
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
        // Every shader that takes the peel's test states one thickness.
        let thickness = format!("const float PEEL_THICKNESS = {PEEL_THICKNESS_DIAMETERS:?};");
        for (file, text) in [
            (
                "splat_peel_frag.glsl",
                include_str!("../../glsl/splat_peel_frag.glsl"),
            ),
            ("peel_cull.comp", include_str!("../../glsl/peel_cull.comp")),
            (
                "splat_compute_main.glsl",
                include_str!("../../glsl/splat_compute_main.glsl"),
            ),
        ] {
            assert!(text.contains(&thickness), "glsl/{file}: {thickness}");
        }
        // Both shapes' shaders are the one body, the disc's with SPLAT_DISC.
        for (file, text, disc) in [
            (
                "splat_raster.frag",
                include_str!("../../glsl/splat_raster.frag"),
                false,
            ),
            (
                "splat_raster_disc.frag",
                include_str!("../../glsl/splat_raster_disc.frag"),
                true,
            ),
            (
                "splat_peel.frag",
                include_str!("../../glsl/splat_peel.frag"),
                false,
            ),
            (
                "splat_peel_disc.frag",
                include_str!("../../glsl/splat_peel_disc.frag"),
                true,
            ),
        ] {
            assert!(text.contains("_frag.glsl\""), "{file} includes its body");
            assert_eq!(text.contains("#define SPLAT_DISC"), disc, "{file}");
        }
        assert_eq!(std::mem::size_of::<SplatPush>(), 128);
    }
}
