//! The Vulkan layer: context, resources, pipelines, barriers and frames.
//! All `unsafe` Vulkan calls outside the passes live here.

mod context;
mod frame;
mod pipeline;
mod resources;
mod sync;

pub use context::{Context, ContextOptions, DeviceInfo, MessageLog, ValidationMessage};
pub use frame::{Frame, FrameTimings, PassTiming};
pub use pipeline::{as_bytes, groups, shader_module, slice_as_bytes, Bind, ComputePipeline};
pub use resources::{Buffer, Image};
pub use sync::{image_barrier, image_barriers, memory_barrier, Access};
