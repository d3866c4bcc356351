//! Synchronization2 scopes: one side of a dependency as (stages, accesses,
//! layout), named for what the pass does. Barriers are recorded through
//! [`Recorder::barriers`](super::Recorder::barriers) and
//! [`Recorder::memory_barrier`](super::Recorder::memory_barrier).

use ash::vk;

/// One side of a dependency: pipeline stages, the accesses they make, and
/// the image layout they need (ignored by memory barriers).
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
        // The combined layout: DEPTH_ATTACHMENT_OPTIMAL would need the
        // separateDepthStencilLayouts feature, which the device does not enable.
        layout: vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
    };
    pub const COMPUTE_READ: Access = Access {
        stage: vk::PipelineStageFlags2::COMPUTE_SHADER,
        access: vk::AccessFlags2::SHADER_STORAGE_READ,
        layout: vk::ImageLayout::GENERAL,
    };
    /// An image read as a storage image by fragment shaders.
    pub const FRAGMENT_READ: Access = Access {
        stage: vk::PipelineStageFlags2::FRAGMENT_SHADER,
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
    /// Any storage access by compute or fragment shaders: the source scope
    /// for an image whose last users differ by method (the G-buffer before
    /// its readback: compute for most, the depth peel's fragment shader
    /// reads it for `layered`).
    pub const SHADER_READ_WRITE: Access = Access {
        stage: vk::PipelineStageFlags2::from_raw(
            vk::PipelineStageFlags2::COMPUTE_SHADER.as_raw()
                | vk::PipelineStageFlags2::FRAGMENT_SHADER.as_raw(),
        ),
        access: vk::AccessFlags2::from_raw(
            vk::AccessFlags2::SHADER_STORAGE_READ.as_raw()
                | vk::AccessFlags2::SHADER_STORAGE_WRITE.as_raw(),
        ),
        layout: vk::ImageLayout::GENERAL,
    };
    /// An image filled by [`Recorder::clear_u32`](super::Recorder::clear_u32).
    pub const CLEAR: Access = Access {
        stage: vk::PipelineStageFlags2::CLEAR,
        access: vk::AccessFlags2::TRANSFER_WRITE,
        layout: vk::ImageLayout::TRANSFER_DST_OPTIMAL,
    };
    /// A buffer filled by [`Recorder::fill_u32`](super::Recorder::fill_u32):
    /// all transfer stages, since the specification counts a fill among
    /// the clear commands and validation layer 1.3.239 among the copies.
    pub const FILL: Access = Access {
        stage: vk::PipelineStageFlags2::ALL_TRANSFER,
        access: vk::AccessFlags2::TRANSFER_WRITE,
        layout: vk::ImageLayout::UNDEFINED,
    };
    /// An image read by a copy.
    pub const COPY_SRC: Access = Access {
        stage: vk::PipelineStageFlags2::COPY,
        access: vk::AccessFlags2::TRANSFER_READ,
        layout: vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
    };
    /// A buffer written by a copy.
    pub const COPY_WRITE: Access = Access {
        stage: vk::PipelineStageFlags2::COPY,
        access: vk::AccessFlags2::TRANSFER_WRITE,
        layout: vk::ImageLayout::UNDEFINED,
    };
    /// A vertex buffer read by a draw.
    pub const VERTEX_READ: Access = Access {
        stage: vk::PipelineStageFlags2::VERTEX_ATTRIBUTE_INPUT,
        access: vk::AccessFlags2::VERTEX_ATTRIBUTE_READ,
        layout: vk::ImageLayout::UNDEFINED,
    };
    /// A buffer of dispatch sizes read by
    /// [`Recorder::dispatch_indirect`](super::Recorder::dispatch_indirect).
    pub const INDIRECT_READ: Access = Access {
        stage: vk::PipelineStageFlags2::DRAW_INDIRECT,
        access: vk::AccessFlags2::INDIRECT_COMMAND_READ,
        layout: vk::ImageLayout::UNDEFINED,
    };
    /// Host reads of mapped memory after the frame.
    pub const HOST_READ: Access = Access {
        stage: vk::PipelineStageFlags2::HOST,
        access: vk::AccessFlags2::HOST_READ,
        layout: vk::ImageLayout::UNDEFINED,
    };
}
