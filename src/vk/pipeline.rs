//! Shader modules, typed push constants, and the two kinds of pipeline the
//! passes use: compute pipelines whose resources are bound with push
//! descriptors (so every dispatch states its inputs and outputs) and the
//! point-sprite graphics pipeline of the splat raster.

use std::marker::PhantomData;
use std::sync::Arc;

use ash::vk;

use super::reflect::{push_constant_block, BlockMember};
use super::{Buffer, Context, Image};
use crate::error::{Error, Result, VkContext};

/// A push-constant block: a `#[repr(C)]` plain-old-data struct whose fields
/// mirror a GLSL `push_constant` block member by member. Declare one with
/// [`push_constants!`](crate::push_constants); a pipeline checks the
/// struct against its shader's block when it is created.
pub trait PushConstants: bytemuck::Pod {
    /// (name, byte offset, byte size) of every field, in declaration order.
    const FIELDS: &'static [(&'static str, usize, usize)];
}

/// Declares a push-constant struct: `#[repr(C)]`, `Pod` (so it has no
/// padding and goes to the GPU through `bytemuck`), and its field table
/// for the layout check against the GLSL block.
#[macro_export]
macro_rules! push_constants {
    ($(#[$meta:meta])* $vis:vis struct $name:ident {
        $($(#[$fmeta:meta])* $fvis:vis $field:ident : $ty:ty),* $(,)?
    }) => {
        $(#[$meta])*
        #[repr(C)]
        #[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        $vis struct $name {
            $($(#[$fmeta])* $fvis $field: $ty),*
        }
        impl $crate::vk::PushConstants for $name {
            const FIELDS: &'static [(&'static str, usize, usize)] = &[
                $((stringify!($field), ::std::mem::offset_of!($name, $field), ::std::mem::size_of::<$ty>())),*
            ];
        }
    };
}

/// Checks that `P` and the push-constant block of the SPIR-V module
/// `spirv` agree member by member (name, offset, size): an error names
/// the shader and both layouts.
pub fn check_push_layout<P: PushConstants>(shader: &str, spirv: &[u8]) -> Result<()> {
    let glsl = push_constant_block(spirv)
        .map_err(|e| Error::VulkanSetup(format!("shader {shader}: {e}")))?;
    let rust: Vec<BlockMember> = P::FIELDS
        .iter()
        .map(|&(name, offset, size)| BlockMember {
            name: name.to_string(),
            offset: offset as u32,
            size: size as u32,
        })
        .collect();
    let end = rust.last().map_or(0, |m| m.offset + m.size) as usize;
    if glsl != rust || end != std::mem::size_of::<P>() {
        let show = |members: &[BlockMember]| {
            members
                .iter()
                .map(|m| format!("{}@{}+{}", m.name, m.offset, m.size))
                .collect::<Vec<_>>()
                .join(" ")
        };
        return Err(Error::VulkanSetup(format!(
            "shader {shader}: push constants differ: GLSL [{}], Rust {} [{}] ({} bytes)",
            show(&glsl),
            std::any::type_name::<P>(),
            show(&rust),
            std::mem::size_of::<P>()
        )));
    }
    Ok(())
}

/// Creates a shader module from SPIR-V bytes (as `build.rs` writes them).
fn shader_module<'c>(ctx: &'c Context, name: &str, spirv: &[u8]) -> Result<ShaderModule<'c>> {
    let words = ash::util::read_spv(&mut std::io::Cursor::new(spirv))
        .map_err(|e| Error::VulkanSetup(format!("shader {name}: invalid SPIR-V: {e}")))?;
    let info = vk::ShaderModuleCreateInfo::default().code(&words);
    // SAFETY: `words` is SPIR-V produced by shaderc at build time; the
    // module is destroyed by `ShaderModule::drop`.
    let raw = unsafe { ctx.device.create_shader_module(&info, None) }.vk("vkCreateShaderModule")?;
    ctx.set_name(raw, name);
    Ok(ShaderModule { ctx, raw })
}

/// A shader module, destroyed when dropped (after pipeline creation).
struct ShaderModule<'a> {
    ctx: &'a Context,
    raw: vk::ShaderModule,
}

impl Drop for ShaderModule<'_> {
    fn drop(&mut self) {
        // SAFETY: a module may be destroyed once the pipelines created from
        // it exist; nothing else holds it.
        unsafe { self.ctx.device.destroy_shader_module(self.raw, None) };
    }
}

/// A pipeline layout (and its push-descriptor set layout, for compute),
/// destroyed with the pipeline that owns it.
struct Layout {
    ctx: Arc<Context>,
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
}

impl Layout {
    fn new(
        ctx: &Arc<Context>,
        name: &str,
        bindings: &[vk::DescriptorType],
        binding_stages: vk::ShaderStageFlags,
        push_stages: vk::ShaderStageFlags,
        push_size: u32,
    ) -> Result<Layout> {
        let mut l = Layout {
            ctx: ctx.clone(),
            set_layout: vk::DescriptorSetLayout::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
        };
        let mut set_layouts = Vec::new();
        if !bindings.is_empty() {
            let layout_bindings: Vec<_> = bindings
                .iter()
                .enumerate()
                .map(|(i, t)| {
                    vk::DescriptorSetLayoutBinding::default()
                        .binding(i as u32)
                        .descriptor_type(*t)
                        .descriptor_count(1)
                        .stage_flags(binding_stages)
                })
                .collect();
            let set_info = vk::DescriptorSetLayoutCreateInfo::default()
                .flags(vk::DescriptorSetLayoutCreateFlags::PUSH_DESCRIPTOR_KHR)
                .bindings(&layout_bindings);
            // SAFETY: plain object creation; `l` owns every handle from here
            // on and its Drop destroys them (null handles are ignored).
            l.set_layout = unsafe { ctx.device.create_descriptor_set_layout(&set_info, None) }
                .vk("vkCreateDescriptorSetLayout")?;
            ctx.set_name(l.set_layout, name);
            set_layouts.push(l.set_layout);
        }
        let ranges = [vk::PushConstantRange {
            stage_flags: push_stages,
            offset: 0,
            size: push_size,
        }];
        let layout_info = vk::PipelineLayoutCreateInfo::default()
            .set_layouts(&set_layouts)
            .push_constant_ranges(&ranges);
        // SAFETY: as above.
        l.layout = unsafe { ctx.device.create_pipeline_layout(&layout_info, None) }
            .vk("vkCreatePipelineLayout")?;
        ctx.set_name(l.layout, name);
        Ok(l)
    }
}

impl Layout {
    /// Whether the pipeline was made on `ctx`.
    fn made_on(&self, ctx: &Context) -> bool {
        std::ptr::eq(&*self.ctx, ctx)
    }
}

impl Drop for Layout {
    fn drop(&mut self) {
        // SAFETY: no pending submission uses the pipeline (every frame waits
        // for its fence); pipeline before layouts; null handles are ignored.
        unsafe {
            self.ctx.device.destroy_pipeline(self.pipeline, None);
            self.ctx.device.destroy_pipeline_layout(self.layout, None);
            self.ctx
                .device
                .destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// One resource bound to a compute pass, in binding order.
pub enum Bind<'a> {
    /// A storage image in `GENERAL` layout.
    StorageImage(&'a Image),
    /// A whole storage buffer.
    StorageBuffer(&'a Buffer),
}

impl Bind<'_> {
    fn descriptor_type(&self) -> vk::DescriptorType {
        match self {
            Bind::StorageImage(_) => vk::DescriptorType::STORAGE_IMAGE,
            Bind::StorageBuffer(_) => vk::DescriptorType::STORAGE_BUFFER,
        }
    }
}

/// What a binding holds, for [`ComputePipeline::new`] and a
/// [`PointPipelineDesc`]'s fragment bindings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Binding {
    StorageImage,
    StorageBuffer,
}

impl Binding {
    fn descriptor_type(self) -> vk::DescriptorType {
        match self {
            Binding::StorageImage => vk::DescriptorType::STORAGE_IMAGE,
            Binding::StorageBuffer => vk::DescriptorType::STORAGE_BUFFER,
        }
    }
}

/// Records `binds` as the push descriptors of set 0 of `layout` at
/// `bind_point`, after checking them against the layout's `expected` types.
///
/// # Safety
/// `cmd` is recording; `layout` was made with a push-descriptor set of the
/// `expected` types; the bound resources outlive the command buffer's
/// execution.
unsafe fn push_descriptors(
    ctx: &Context,
    cmd: vk::CommandBuffer,
    bind_point: vk::PipelineBindPoint,
    layout: vk::PipelineLayout,
    name: &str,
    expected: &[vk::DescriptorType],
    binds: &[Bind<'_>],
) {
    assert_eq!(
        binds.len(),
        expected.len(),
        "{name}: wrong number of bindings"
    );
    if binds.is_empty() {
        return;
    }
    let image_infos: Vec<[vk::DescriptorImageInfo; 1]> = binds
        .iter()
        .map(|b| match b {
            Bind::StorageImage(img) => [vk::DescriptorImageInfo {
                sampler: vk::Sampler::null(),
                image_view: img.view,
                image_layout: vk::ImageLayout::GENERAL,
            }],
            Bind::StorageBuffer(_) => [vk::DescriptorImageInfo::default()],
        })
        .collect();
    let buffer_infos: Vec<[vk::DescriptorBufferInfo; 1]> = binds
        .iter()
        .map(|b| match b {
            Bind::StorageBuffer(buf) => [vk::DescriptorBufferInfo {
                buffer: buf.raw,
                offset: 0,
                range: vk::WHOLE_SIZE,
            }],
            Bind::StorageImage(_) => [vk::DescriptorBufferInfo::default()],
        })
        .collect();
    let writes: Vec<_> = binds
        .iter()
        .enumerate()
        .map(|(i, b)| {
            assert_eq!(b.descriptor_type(), expected[i], "{name}: binding {i}");
            let w = vk::WriteDescriptorSet::default()
                .dst_binding(i as u32)
                .descriptor_type(b.descriptor_type());
            match b {
                Bind::StorageImage(_) => w.image_info(&image_infos[i]),
                Bind::StorageBuffer(_) => w.buffer_info(&buffer_infos[i]),
            }
        })
        .collect();
    // SAFETY: the caller's contract; the writes match the set layout
    // (checked above) and point at locals alive for the call.
    unsafe {
        ctx.push_descriptor
            .cmd_push_descriptor_set(cmd, bind_point, layout, 0, &writes)
    };
}

/// A compute pipeline with a push-descriptor set layout and push constants
/// of type `P`.
pub struct ComputePipeline<P: PushConstants> {
    name: String,
    layout: Layout,
    bindings: Vec<vk::DescriptorType>,
    push: PhantomData<fn(P)>,
}

impl<P: PushConstants> ComputePipeline<P> {
    /// `bindings` lists what binding 0, 1, … holds. Fails when `P` and the
    /// shader's push-constant block disagree.
    pub fn new(
        ctx: &Arc<Context>,
        name: &str,
        spirv: &[u8],
        bindings: &[Binding],
    ) -> Result<ComputePipeline<P>> {
        Self::specialized(ctx, name, spirv, bindings, &[])
    }

    /// As [`ComputePipeline::new`], with the shader's specialization
    /// constants `constants` (constant id, value: a 32-bit `uint`, `int`
    /// or `bool` in GLSL) set; the others keep their defaults.
    pub fn specialized(
        ctx: &Arc<Context>,
        name: &str,
        spirv: &[u8],
        bindings: &[Binding],
        constants: &[(u32, u32)],
    ) -> Result<ComputePipeline<P>> {
        check_push_layout::<P>(name, spirv)?;
        let types: Vec<vk::DescriptorType> = bindings.iter().map(|b| b.descriptor_type()).collect();
        let mut layout = Layout::new(
            ctx,
            name,
            &types,
            vk::ShaderStageFlags::COMPUTE,
            vk::ShaderStageFlags::COMPUTE,
            std::mem::size_of::<P>() as u32,
        )?;
        let module = shader_module(ctx, name, spirv)?;
        let entries: Vec<vk::SpecializationMapEntry> = constants
            .iter()
            .enumerate()
            .map(|(i, &(id, _))| vk::SpecializationMapEntry {
                constant_id: id,
                offset: 4 * i as u32,
                size: 4,
            })
            .collect();
        let values: Vec<u32> = constants.iter().map(|&(_, v)| v).collect();
        let specialization = vk::SpecializationInfo::default()
            .map_entries(&entries)
            .data(bytemuck::cast_slice(&values));
        let mut stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module.raw)
            .name(c"main");
        if !constants.is_empty() {
            stage = stage.specialization_info(&specialization);
        }
        let info = vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(layout.layout);
        // SAFETY: module and layout are valid for the call; the pipeline is
        // owned by `layout` and destroyed by its Drop.
        let created = unsafe {
            ctx.device
                .create_compute_pipelines(vk::PipelineCache::null(), &[info], None)
        };
        layout.pipeline = created.map_err(|(_, e)| e).vk("vkCreateComputePipelines")?[0];
        ctx.set_name(layout.pipeline, name);
        Ok(ComputePipeline {
            name: name.to_string(),
            layout,
            bindings: types,
            push: PhantomData,
        })
    }

    pub(super) fn made_on(&self, ctx: &Context) -> bool {
        self.layout.made_on(ctx)
    }

    /// Records bind, descriptors, push constants and dispatch into `cmd`.
    pub(super) fn record_dispatch(
        &self,
        cmd: vk::CommandBuffer,
        binds: &[Bind<'_>],
        push: &P,
        groups: Groups<'_>,
    ) {
        let ctx = &self.layout.ctx;
        // SAFETY: `cmd` is recording outside a render pass (the recorder's
        // contract); the writes match the set layout (checked above), the
        // push range is `size_of::<P>()` bytes, and the bound resources are
        // borrowed for the frame's lifetime (see `Recorder`); an indirect
        // dispatch's 12 bytes lie inside its buffer (asserted by
        // `Recorder::dispatch_indirect`), which outlives the frame too.
        unsafe {
            ctx.device
                .cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.layout.pipeline);
            push_descriptors(
                ctx,
                cmd,
                vk::PipelineBindPoint::COMPUTE,
                self.layout.layout,
                &self.name,
                &self.bindings,
                binds,
            );
            ctx.device.cmd_push_constants(
                cmd,
                self.layout.layout,
                vk::ShaderStageFlags::COMPUTE,
                0,
                bytemuck::bytes_of(push),
            );
            match groups {
                Groups::Direct([x, y, z]) => ctx.device.cmd_dispatch(cmd, x, y, z),
                Groups::Indirect(args, offset) => {
                    ctx.device.cmd_dispatch_indirect(cmd, args.raw, offset)
                }
            }
        }
    }
}

/// The workgroups of a dispatch: counts, or where the GPU wrote them.
pub(super) enum Groups<'a> {
    Direct([u32; 3]),
    Indirect(&'a Buffer, u64),
}

/// One vertex attribute of a [`PointPipeline`]: location i is entry i.
#[derive(Debug, Clone, Copy)]
pub struct VertexAttribute {
    pub format: vk::Format,
    pub offset: u32,
}

/// What a [`PointPipeline`] draws: shaders, vertex layout, targets.
pub struct PointPipelineDesc<'a> {
    pub name: &'a str,
    pub vertex_spirv: &'a [u8],
    pub fragment_spirv: &'a [u8],
    /// Bytes per vertex.
    pub stride: u32,
    pub attributes: &'a [VertexAttribute],
    pub color_formats: &'a [vk::Format],
    pub depth_format: vk::Format,
    /// Rasterization samples per pixel: the targets' sample count.
    pub samples: u32,
    /// What the fragment shader's bindings 0, 1, … hold (push descriptors).
    pub fragment_bindings: &'a [Binding],
}

/// A graphics pipeline that draws a vertex buffer as hardware point sprites
/// (POINT_LIST, `gl_PointSize` from the vertex shader) with a strict LESS
/// depth test and no blending, for dynamic rendering; push constants of
/// type `P` go to the vertex stage.
pub struct PointPipeline<P: PushConstants> {
    name: String,
    layout: Layout,
    bindings: Vec<vk::DescriptorType>,
    pub(super) color_formats: Vec<vk::Format>,
    pub(super) depth_format: vk::Format,
    pub(super) samples: u32,
    /// Bytes per vertex.
    pub(super) stride: u32,
    push: PhantomData<fn(P)>,
}

impl<P: PushConstants> PointPipeline<P> {
    pub fn new(ctx: &Arc<Context>, desc: &PointPipelineDesc<'_>) -> Result<PointPipeline<P>> {
        assert!(
            desc.samples.is_power_of_two() && desc.samples <= 64,
            "{} samples per pixel",
            desc.samples
        );
        check_push_layout::<P>(desc.name, desc.vertex_spirv)?;
        let types: Vec<vk::DescriptorType> = desc
            .fragment_bindings
            .iter()
            .map(|b| b.descriptor_type())
            .collect();
        let mut layout = Layout::new(
            ctx,
            desc.name,
            &types,
            vk::ShaderStageFlags::FRAGMENT,
            vk::ShaderStageFlags::VERTEX,
            std::mem::size_of::<P>() as u32,
        )?;
        let vert = shader_module(ctx, &format!("{}.vert", desc.name), desc.vertex_spirv)?;
        let frag = shader_module(ctx, &format!("{}.frag", desc.name), desc.fragment_spirv)?;
        let stages = [
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::VERTEX)
                .module(vert.raw)
                .name(c"main"),
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::FRAGMENT)
                .module(frag.raw)
                .name(c"main"),
        ];
        let bindings = [vk::VertexInputBindingDescription {
            binding: 0,
            stride: desc.stride,
            input_rate: vk::VertexInputRate::VERTEX,
        }];
        let attributes: Vec<_> = desc
            .attributes
            .iter()
            .enumerate()
            .map(|(i, a)| vk::VertexInputAttributeDescription {
                location: i as u32,
                binding: 0,
                format: a.format,
                offset: a.offset,
            })
            .collect();
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
            .rasterization_samples(vk::SampleCountFlags::from_raw(desc.samples));
        let depth = vk::PipelineDepthStencilStateCreateInfo::default()
            .depth_test_enable(true)
            .depth_write_enable(true)
            .depth_compare_op(vk::CompareOp::LESS);
        let blend_attachments: Vec<_> = desc
            .color_formats
            .iter()
            .map(|_| {
                vk::PipelineColorBlendAttachmentState::default()
                    .color_write_mask(vk::ColorComponentFlags::RGBA)
            })
            .collect();
        let blend =
            vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
        let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
        let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
        let mut rendering = vk::PipelineRenderingCreateInfo::default()
            .color_attachment_formats(desc.color_formats)
            .depth_attachment_format(desc.depth_format);
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
            .layout(layout.layout)
            .push_next(&mut rendering);
        // SAFETY: every state struct is a local alive for the call; the
        // pipeline is owned by `layout` and destroyed by its Drop.
        let created = unsafe {
            ctx.device
                .create_graphics_pipelines(vk::PipelineCache::null(), &[info], None)
        };
        layout.pipeline = created
            .map_err(|(_, e)| e)
            .vk("vkCreateGraphicsPipelines")?[0];
        ctx.set_name(layout.pipeline, desc.name);
        Ok(PointPipeline {
            name: desc.name.to_string(),
            layout,
            bindings: types,
            color_formats: desc.color_formats.to_vec(),
            depth_format: desc.depth_format,
            samples: desc.samples,
            stride: desc.stride,
            push: PhantomData,
        })
    }

    pub(super) fn made_on(&self, ctx: &Context) -> bool {
        self.layout.made_on(ctx)
    }

    pub(super) fn raw(&self) -> (vk::Pipeline, vk::PipelineLayout) {
        (self.layout.pipeline, self.layout.layout)
    }

    /// Records `binds` as the fragment shader's descriptors.
    ///
    /// # Safety
    /// `cmd` is recording with this pipeline bound; the bound resources
    /// outlive the command buffer's execution.
    pub(super) unsafe fn push_fragment_descriptors(
        &self,
        cmd: vk::CommandBuffer,
        binds: &[Bind<'_>],
    ) {
        // SAFETY: the caller's contract; the layout has a push-descriptor
        // set of `self.bindings`.
        unsafe {
            push_descriptors(
                &self.layout.ctx,
                cmd,
                vk::PipelineBindPoint::GRAPHICS,
                self.layout.layout,
                &self.name,
                &self.bindings,
                binds,
            )
        }
    }
}

/// Workgroup count covering `n` items with groups of `local`.
pub fn groups(n: u32, local: u32) -> u32 {
    n.div_ceil(local)
}

#[cfg(test)]
mod tests {
    use super::*;

    static FAST_COC: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_coc.comp.spv"));

    crate::push_constants! {
        struct Right {
            extent: [i32; 2],
            f_px: f32,
            aperture_radius: f32,
            focus_distance: f32,
            area_weights: u32,
            shaped: u32,
            tap_count: i32,
            reach_max: f32,
            background_only: u32,
        }
    }

    crate::push_constants! {
        /// Two fields swapped.
        struct Swapped {
            extent: [i32; 2],
            aperture_radius: f32,
            f_px: f32,
            focus_distance: f32,
            area_weights: u32,
            shaped: u32,
            tap_count: i32,
            reach_max: f32,
            background_only: u32,
        }
    }

    crate::push_constants! {
        /// One field too few.
        struct Short {
            extent: [i32; 2],
            f_px: f32,
            aperture_radius: f32,
            focus_distance: f32,
            area_weights: u32,
            shaped: u32,
            tap_count: i32,
            reach_max: f32,
        }
    }

    crate::push_constants! {
        /// A field of another size (an i64 where GLSL has a uint, after
        /// a pad that aligns it).
        struct Wide {
            extent: [i32; 2],
            f_px: f32,
            aperture_radius: f32,
            focus_distance: f32,
            pad: f32,
            area_weights: u64,
            shaped: u32,
            tap_count: i32,
            reach_max: f32,
            background_only: u32,
        }
    }

    #[test]
    fn the_push_layout_check_fails_when_either_side_changes() {
        check_push_layout::<Right>("fast_coc", FAST_COC).unwrap();
        for (what, result) in [
            (
                "swapped",
                check_push_layout::<Swapped>("fast_coc", FAST_COC),
            ),
            ("short", check_push_layout::<Short>("fast_coc", FAST_COC)),
            ("wide", check_push_layout::<Wide>("fast_coc", FAST_COC)),
        ] {
            let err = result.expect_err(what).to_string();
            assert!(
                err.contains("fast_coc") && err.contains("background_only@36+4"),
                "{what}: {err}"
            );
        }
    }
}
