//! The Vulkan layer: context, resources, pipelines, barriers and frames.
//! Every `unsafe` block of pointlens lives under this module (the crate
//! denies `unsafe_code` elsewhere, see `src/lib.rs`); each states the
//! invariant it relies on. Raw Vulkan handles stay inside it: passes record
//! through [`Recorder`] with references to [`Image`]s, [`Buffer`]s and
//! pipelines.

mod context;
mod frame;
mod pipeline;
mod pool;
mod reflect;
mod resources;
mod sync;

pub use context::{
    Context, ContextOptions, DeviceInfo, DeviceListing, MessageLog, ValidationMessage,
    LLVMPIPE_LOOP_ITERATIONS,
};
pub use frame::{texel_bytes, DrawCount, Frame, FrameTimings, PassTiming, Recorder};
pub use pipeline::{
    check_push_layout, groups, Bind, Binding, ComputePipeline, PointPipeline, PointPipelineDesc,
    PushConstants, VertexAttribute,
};
pub use resources::{Buffer, Image};
pub use sync::Access;
