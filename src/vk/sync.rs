//! Pipeline barriers (synchronization2), stated per image with both scopes.

use ash::vk;

use super::{Context, Image};

/// One side of a dependency: pipeline stages and the accesses they make.
#[derive(Debug, Clone, Copy)]
pub struct Access {
    pub stage: vk::PipelineStageFlags2,
    pub access: vk::AccessFlags2,
    pub layout: vk::ImageLayout,
}

impl Access {
    /// Nothing before: the image's old content is discarded.
    pub const NONE: Access = Access {
        stage: vk::PipelineStageFlags2::NONE,
        access: vk::AccessFlags2::NONE,
        layout: vk::ImageLayout::UNDEFINED,
    };
    pub const COLOR_WRITE: Access = Access {
        stage: vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT,
        access: vk::AccessFlags2::COLOR_ATTACHMENT_WRITE,
        layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
    };
    pub const DEPTH_WRITE: Access = Access {
        stage: vk::PipelineStageFlags2::from_raw(
            vk::PipelineStageFlags2::EARLY_FRAGMENT_TESTS.as_raw()
                | vk::PipelineStageFlags2::LATE_FRAGMENT_TESTS.as_raw(),
        ),
        access: vk::AccessFlags2::from_raw(
            vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_READ.as_raw()
                | vk::AccessFlags2::DEPTH_STENCIL_ATTACHMENT_WRITE.as_raw(),
        ),
        layout: vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
    };
    pub const COMPUTE_READ: Access = Access {
        stage: vk::PipelineStageFlags2::COMPUTE_SHADER,
        access: vk::AccessFlags2::SHADER_STORAGE_READ,
        layout: vk::ImageLayout::GENERAL,
    };
    pub const COMPUTE_WRITE: Access = Access {
        stage: vk::PipelineStageFlags2::COMPUTE_SHADER,
        access: vk::AccessFlags2::SHADER_STORAGE_WRITE,
        layout: vk::ImageLayout::GENERAL,
    };
    pub const COMPUTE_READ_WRITE: Access = Access {
        stage: vk::PipelineStageFlags2::COMPUTE_SHADER,
        access: vk::AccessFlags2::from_raw(
            vk::AccessFlags2::SHADER_STORAGE_READ.as_raw()
                | vk::AccessFlags2::SHADER_STORAGE_WRITE.as_raw(),
        ),
        layout: vk::ImageLayout::GENERAL,
    };
    pub const COPY_SRC: Access = Access {
        stage: vk::PipelineStageFlags2::COPY,
        access: vk::AccessFlags2::TRANSFER_READ,
        layout: vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
    };
}

/// Records an image barrier from `src` to `dst` (layout transition included).
pub fn image_barrier(
    ctx: &Context,
    cmd: vk::CommandBuffer,
    image: &Image,
    src: Access,
    dst: Access,
) {
    image_barriers(ctx, cmd, &[(image, src, dst)]);
}

/// Records several image barriers in one call.
pub fn image_barriers(ctx: &Context, cmd: vk::CommandBuffer, list: &[(&Image, Access, Access)]) {
    let barriers: Vec<_> = list
        .iter()
        .map(|(image, src, dst)| {
            vk::ImageMemoryBarrier2::default()
                .src_stage_mask(src.stage)
                .src_access_mask(src.access)
                .dst_stage_mask(dst.stage)
                .dst_access_mask(dst.access)
                .old_layout(src.layout)
                .new_layout(dst.layout)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(image.raw)
                .subresource_range(image.full_range())
        })
        .collect();
    let dep = vk::DependencyInfo::default().image_memory_barriers(&barriers);
    // SAFETY: `cmd` is recording outside a render pass; images are valid.
    unsafe { ctx.device.cmd_pipeline_barrier2(cmd, &dep) };
}

/// Records a global memory barrier (for buffers).
pub fn memory_barrier(
    ctx: &Context,
    cmd: vk::CommandBuffer,
    src: (vk::PipelineStageFlags2, vk::AccessFlags2),
    dst: (vk::PipelineStageFlags2, vk::AccessFlags2),
) {
    let barriers = [vk::MemoryBarrier2::default()
        .src_stage_mask(src.0)
        .src_access_mask(src.1)
        .dst_stage_mask(dst.0)
        .dst_access_mask(dst.1)];
    let dep = vk::DependencyInfo::default().memory_barriers(&barriers);
    // SAFETY: `cmd` is recording outside a render pass.
    unsafe { ctx.device.cmd_pipeline_barrier2(cmd, &dep) };
}
