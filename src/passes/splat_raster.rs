//! The splat raster pass (`glsl/splat_raster.{vert,frag}`): every splat as
//! a hardware point sprite (POINT_LIST + `gl_PointSize`), depth-tested
//! (strict LESS), into one sample's color, eye-position and depth targets.

use std::sync::Arc;

use ash::vk;

use crate::error::{Result, VkContext};
use crate::vk::{as_bytes, shader_module, Buffer, Context, Image};

pub const COLOR_FORMAT: vk::Format = vk::Format::R16G16B16A16_SFLOAT;
pub const EYE_FORMAT: vk::Format = vk::Format::R32G32B32A32_SFLOAT;
pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

/// One splat as the vertex shader reads it (24 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplatVertex {
    /// World position (xyz) and world diameter (w).
    pub position_size: [f32; 4],
    /// Linear RGB, 16-bit UNORM; alpha unused.
    pub color: [u16; 4],
}

/// Push constants of the pass; mirrors `glsl/splat_raster.glsl` (128 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
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

const _: () = assert!(std::mem::size_of::<SplatPush>() == 128);
const _: () = assert!(std::mem::size_of::<SplatVertex>() == 24);

/// The render targets of one raster sample.
pub struct SampleTargets {
    pub color: Image,
    pub eye: Image,
    pub depth: Image,
}

impl SampleTargets {
    /// Color (rgba16f), eye position (rgba32f) and depth (D32) targets,
    /// the color and eye targets also readable as storage images.
    pub fn new(ctx: &Arc<Context>, width: u32, height: u32) -> Result<SampleTargets> {
        let attach = vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::STORAGE;
        Ok(SampleTargets {
            color: Image::new_2d(ctx, "sample color", COLOR_FORMAT, width, height, 1, attach)?,
            eye: Image::new_2d(ctx, "sample eye", EYE_FORMAT, width, height, 1, attach)?,
            depth: Image::new_2d(
                ctx,
                "sample depth",
                DEPTH_FORMAT,
                width,
                height,
                1,
                vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
            )?,
        })
    }
}

/// The graphics pipeline of the pass.
pub struct SplatRaster {
    ctx: Arc<Context>,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
}

static VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_raster.vert.spv"));
static FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/splat_raster.frag.spv"));

impl SplatRaster {
    pub fn new(ctx: &Arc<Context>) -> Result<SplatRaster> {
        let mut pass = SplatRaster {
            ctx: ctx.clone(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
        };
        let ranges = [vk::PushConstantRange {
            stage_flags: vk::ShaderStageFlags::VERTEX,
            offset: 0,
            size: std::mem::size_of::<SplatPush>() as u32,
        }];
        let layout_info = vk::PipelineLayoutCreateInfo::default().push_constant_ranges(&ranges);
        // SAFETY: plain object creation; `pass` owns it and its Drop destroys it.
        pass.layout = unsafe { ctx.device.create_pipeline_layout(&layout_info, None) }
            .vk("vkCreatePipelineLayout")?;

        let vert = shader_module(ctx, "splat_raster.vert", VERT)?;
        let frag = match shader_module(ctx, "splat_raster.frag", FRAG) {
            Ok(f) => f,
            Err(e) => {
                // SAFETY: the module is unused.
                unsafe { ctx.device.destroy_shader_module(vert, None) };
                return Err(e);
            }
        };
        let stages = [
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::VERTEX)
                .module(vert)
                .name(c"main"),
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::FRAGMENT)
                .module(frag)
                .name(c"main"),
        ];
        let bindings = [vk::VertexInputBindingDescription {
            binding: 0,
            stride: std::mem::size_of::<SplatVertex>() as u32,
            input_rate: vk::VertexInputRate::VERTEX,
        }];
        let attributes = [
            vk::VertexInputAttributeDescription {
                location: 0,
                binding: 0,
                format: vk::Format::R32G32B32A32_SFLOAT,
                offset: 0,
            },
            vk::VertexInputAttributeDescription {
                location: 1,
                binding: 0,
                format: vk::Format::R16G16B16A16_UNORM,
                offset: 16,
            },
        ];
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default()
            .vertex_binding_descriptions(&bindings)
            .vertex_attribute_descriptions(&attributes);
        let input_assembly = vk::PipelineInputAssemblyStateCreateInfo::default()
            .topology(vk::PrimitiveTopology::POINT_LIST);
        let viewport = vk::PipelineViewportStateCreateInfo::default()
            .viewport_count(1)
            .scissor_count(1);
        let raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(vk::PolygonMode::FILL)
            .cull_mode(vk::CullModeFlags::NONE)
            .line_width(1.0);
        let multisample = vk::PipelineMultisampleStateCreateInfo::default()
            .rasterization_samples(vk::SampleCountFlags::TYPE_1);
        let depth = vk::PipelineDepthStencilStateCreateInfo::default()
            .depth_test_enable(true)
            .depth_write_enable(true)
            .depth_compare_op(vk::CompareOp::LESS);
        let blend_attachments = [vk::PipelineColorBlendAttachmentState::default()
            .color_write_mask(vk::ColorComponentFlags::RGBA); 2];
        let blend =
            vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
        let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
        let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
        let color_formats = [COLOR_FORMAT, EYE_FORMAT];
        let mut rendering = vk::PipelineRenderingCreateInfo::default()
            .color_attachment_formats(&color_formats)
            .depth_attachment_format(DEPTH_FORMAT);
        let info = vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&input_assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .depth_stencil_state(&depth)
            .color_blend_state(&blend)
            .dynamic_state(&dynamic)
            .layout(pass.layout)
            .push_next(&mut rendering);
        // SAFETY: all state structs are locals alive for the call; the
        // modules may be destroyed once the pipeline exists.
        let created = unsafe {
            let r = ctx
                .device
                .create_graphics_pipelines(vk::PipelineCache::null(), &[info], None);
            ctx.device.destroy_shader_module(vert, None);
            ctx.device.destroy_shader_module(frag, None);
            r
        };
        pass.pipeline = created
            .map_err(|(_, e)| e)
            .vk("vkCreateGraphicsPipelines")?[0];
        ctx.set_name(pass.pipeline, "splat_raster");
        ctx.set_name(pass.layout, "splat_raster");
        Ok(pass)
    }

    /// Records one raster sample: clears the targets (color to `background`
    /// with alpha 0, eye to 0, depth to 1) and draws `count` splats. The
    /// targets must be in attachment layouts (see `gbuffer.rs`).
    pub fn record(
        &self,
        cmd: vk::CommandBuffer,
        targets: &SampleTargets,
        splats: &Buffer,
        count: u32,
        background: [f32; 3],
        push: &SplatPush,
    ) {
        let (w, h) = (targets.color.width, targets.color.height);
        let area = vk::Rect2D {
            offset: vk::Offset2D { x: 0, y: 0 },
            extent: vk::Extent2D {
                width: w,
                height: h,
            },
        };
        let color_attachment = |image: &Image, clear: [f32; 4]| {
            vk::RenderingAttachmentInfo::default()
                .image_view(image.view)
                .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)
                .clear_value(vk::ClearValue {
                    color: vk::ClearColorValue { float32: clear },
                })
        };
        let colors = [
            color_attachment(
                &targets.color,
                [background[0], background[1], background[2], 0.0],
            ),
            color_attachment(&targets.eye, [0.0; 4]),
        ];
        let depth = vk::RenderingAttachmentInfo::default()
            .image_view(targets.depth.view)
            .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::DONT_CARE)
            .clear_value(vk::ClearValue {
                depth_stencil: vk::ClearDepthStencilValue {
                    depth: 1.0,
                    stencil: 0,
                },
            });
        let rendering = vk::RenderingInfo::default()
            .render_area(area)
            .layer_count(1)
            .color_attachments(&colors)
            .depth_attachment(&depth);
        let viewport = vk::Viewport {
            x: 0.0,
            y: 0.0,
            width: w as f32,
            height: h as f32,
            min_depth: 0.0,
            max_depth: 1.0,
        };
        let device = &self.ctx.device;
        // SAFETY: `cmd` is recording; the targets are in the layouts named
        // above (the caller's barriers) and `splats` holds `count` vertices
        // made visible to vertex input by the upload's barrier.
        unsafe {
            device.cmd_begin_rendering(cmd, &rendering);
            device.cmd_set_viewport(cmd, 0, &[viewport]);
            device.cmd_set_scissor(cmd, 0, &[area]);
            device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, self.pipeline);
            device.cmd_bind_vertex_buffers(cmd, 0, &[splats.raw], &[0]);
            device.cmd_push_constants(
                cmd,
                self.layout,
                vk::ShaderStageFlags::VERTEX,
                0,
                as_bytes(push),
            );
            device.cmd_draw(cmd, count, 1, 0, 0);
            device.cmd_end_rendering(cmd);
        }
    }
}

impl Drop for SplatRaster {
    fn drop(&mut self) {
        // SAFETY: no pending submission uses the pipeline (frames wait).
        unsafe {
            self.ctx.device.destroy_pipeline(self.pipeline, None);
            self.ctx.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}
