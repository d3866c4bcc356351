//! Shader modules, and compute pipelines whose resources are bound with push
//! descriptors, so that every dispatch states its inputs and outputs.

use std::sync::Arc;

use ash::vk;

use super::{Buffer, Context, Image};
use crate::error::{Error, Result, VkContext};

/// Creates a shader module from SPIR-V bytes (as `build.rs` writes them).
pub fn shader_module(ctx: &Context, name: &str, spirv: &[u8]) -> Result<vk::ShaderModule> {
    let words = ash::util::read_spv(&mut std::io::Cursor::new(spirv))
        .map_err(|e| Error::VulkanSetup(format!("shader {name}: invalid SPIR-V: {e}")))?;
    let info = vk::ShaderModuleCreateInfo::default().code(&words);
    // SAFETY: `words` is SPIR-V produced by shaderc at build time.
    let module =
        unsafe { ctx.device.create_shader_module(&info, None) }.vk("vkCreateShaderModule")?;
    ctx.set_name(module, name);
    Ok(module)
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

/// A compute pipeline with a push-descriptor set layout and push constants.
pub struct ComputePipeline {
    ctx: Arc<Context>,
    name: String,
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    bindings: Vec<vk::DescriptorType>,
    push_size: u32,
}

impl ComputePipeline {
    /// `bindings` lists the descriptor type of binding 0, 1, …; `push_size`
    /// is the size of the push-constant block in bytes (0 for none).
    pub fn new(
        ctx: &Arc<Context>,
        name: &str,
        spirv: &[u8],
        bindings: &[vk::DescriptorType],
        push_size: u32,
    ) -> Result<ComputePipeline> {
        let mut p = ComputePipeline {
            ctx: ctx.clone(),
            name: name.to_string(),
            set_layout: vk::DescriptorSetLayout::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            bindings: bindings.to_vec(),
            push_size,
        };
        let layout_bindings: Vec<_> = bindings
            .iter()
            .enumerate()
            .map(|(i, t)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(i as u32)
                    .descriptor_type(*t)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let set_info = vk::DescriptorSetLayoutCreateInfo::default()
            .flags(vk::DescriptorSetLayoutCreateFlags::PUSH_DESCRIPTOR_KHR)
            .bindings(&layout_bindings);
        // SAFETY: plain object creation; `p` owns every handle from here on
        // and its Drop destroys them (null handles are ignored).
        p.set_layout = unsafe { ctx.device.create_descriptor_set_layout(&set_info, None) }
            .vk("vkCreateDescriptorSetLayout")?;
        let ranges = [vk::PushConstantRange {
            stage_flags: vk::ShaderStageFlags::COMPUTE,
            offset: 0,
            size: push_size,
        }];
        let set_layouts = [p.set_layout];
        let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
        if push_size > 0 {
            layout_info = layout_info.push_constant_ranges(&ranges);
        }
        // SAFETY: as above.
        p.layout = unsafe { ctx.device.create_pipeline_layout(&layout_info, None) }
            .vk("vkCreatePipelineLayout")?;
        let module = shader_module(ctx, name, spirv)?;
        let stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(c"main");
        let info = vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(p.layout);
        // SAFETY: module and layout are valid; the module is destroyed right
        // after pipeline creation, which Vulkan allows.
        let created = unsafe {
            let r = ctx
                .device
                .create_compute_pipelines(vk::PipelineCache::null(), &[info], None);
            ctx.device.destroy_shader_module(module, None);
            r
        };
        p.pipeline = created.map_err(|(_, e)| e).vk("vkCreateComputePipelines")?[0];
        ctx.set_name(p.pipeline, name);
        ctx.set_name(p.layout, name);
        ctx.set_name(p.set_layout, name);
        Ok(p)
    }

    /// Binds the pipeline, pushes `binds` and `push` constants, dispatches
    /// `groups` workgroups.
    pub fn dispatch(
        &self,
        cmd: vk::CommandBuffer,
        binds: &[Bind<'_>],
        push: &[u8],
        groups: [u32; 3],
    ) {
        assert_eq!(
            binds.len(),
            self.bindings.len(),
            "{}: wrong number of bindings",
            self.name
        );
        assert_eq!(
            push.len() as u32,
            self.push_size,
            "{}: push size",
            self.name
        );
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
                assert_eq!(
                    b.descriptor_type(),
                    self.bindings[i],
                    "{}: binding {i}",
                    self.name
                );
                let w = vk::WriteDescriptorSet::default()
                    .dst_binding(i as u32)
                    .descriptor_type(b.descriptor_type());
                match b {
                    Bind::StorageImage(_) => w.image_info(&image_infos[i]),
                    Bind::StorageBuffer(_) => w.buffer_info(&buffer_infos[i]),
                }
            })
            .collect();
        let device = &self.ctx.device;
        // SAFETY: `cmd` is recording outside a render pass; the writes match
        // the set layout (checked above) and the push range matches `push`.
        unsafe {
            device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline);
            self.ctx.push_descriptor.cmd_push_descriptor_set(
                cmd,
                vk::PipelineBindPoint::COMPUTE,
                self.layout,
                0,
                &writes,
            );
            if !push.is_empty() {
                device.cmd_push_constants(cmd, self.layout, vk::ShaderStageFlags::COMPUTE, 0, push);
            }
            device.cmd_dispatch(cmd, groups[0], groups[1], groups[2]);
        }
    }
}

impl Drop for ComputePipeline {
    fn drop(&mut self) {
        // SAFETY: no submission using the pipeline is pending (frames wait).
        unsafe {
            self.ctx.device.destroy_pipeline(self.pipeline, None);
            self.ctx.device.destroy_pipeline_layout(self.layout, None);
            self.ctx
                .device
                .destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// Workgroup count covering `n` items with groups of `local`.
pub fn groups(n: u32, local: u32) -> u32 {
    n.div_ceil(local)
}

/// Views a plain-old-data value as bytes, for push constants and uploads.
pub fn as_bytes<T: Copy>(v: &T) -> &[u8] {
    // SAFETY: `T: Copy` push-constant structs in pointlens are `#[repr(C)]`
    // with only f32/u32/i32 fields and explicit padding, so every byte is
    // initialised; the slice borrows `v`.
    unsafe { std::slice::from_raw_parts(v as *const T as *const u8, std::mem::size_of::<T>()) }
}

/// Views a slice of plain-old-data values as bytes.
pub fn slice_as_bytes<T: Copy>(v: &[T]) -> &[u8] {
    // SAFETY: as for `as_bytes`, element by element.
    unsafe { std::slice::from_raw_parts(v.as_ptr() as *const u8, std::mem::size_of_val(v)) }
}
