//! The ray distribution buffer (Zhao §3.2, DESIGN §5): `rdb_scatter` (two
//! passes: depth, then source index, by R32_UINT image atomics into 2D array
//! images with one layer per lens bin) and `rdb_resolve` (mean of the filled
//! bins).

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use crate::camera::{rdb_lens_table, Camera};
use crate::error::{Error, Result};
use crate::gbuffer::GBuffer;
use crate::vk::{
    as_bytes, groups, image_barriers, slice_as_bytes, Access, Bind, Buffer, ComputePipeline,
    Context, Frame, Image,
};

/// Which rays a bin receives (`--rdb-mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RdbMode {
    /// Each bin sampled by the ray through its lens cell's centre.
    #[default]
    Centre,
    /// The paper's literal pair-to-bin assignment.
    Pairs,
}

static SCATTER: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/rdb_scatter.comp.spv"));
static RESOLVE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/rdb_resolve.comp.spv"));

#[repr(C)]
#[derive(Clone, Copy)]
struct ScatterPush {
    extent: [i32; 2],
    origin: [i32; 2],
    size: [i32; 2],
    bins: i32,
    pairs: u32,
    pass_index: u32,
    f_px: f32,
    aperture_radius: f32,
    focus_distance: f32,
}

#[repr(C)]
#[derive(Clone, Copy)]
struct ResolvePush {
    extent: [i32; 2],
    origin: [i32; 2],
    size: [i32; 2],
    bins: i32,
}

/// The two pipelines of the method.
pub struct Rdb {
    scatter: ComputePipeline,
    resolve: ComputePipeline,
}

/// The buffers of one frame: the bins (two R32_UINT array images, a layer
/// per bin), the lens table and the result.
pub struct RdbImages {
    depth: Image,
    source: Image,
    lens: Buffer,
    bins: u32,
    /// The result: G-buffer sized, written inside the guard band only.
    pub result: Image,
}

impl RdbImages {
    /// Allocates an N×N-bin buffer for the output size of `gbuffer`.
    pub fn new(ctx: &Arc<Context>, gbuffer: &GBuffer, bins: u32) -> Result<RdbImages> {
        if !(2..=16).contains(&bins) {
            return Err(Error::InvalidArgument(format!(
                "--rdb-bins must be between 2 and 16, not {bins}"
            )));
        }
        let (w, h) = (gbuffer.view.camera.width, gbuffer.view.camera.height);
        let usage = vk::ImageUsageFlags::STORAGE | vk::ImageUsageFlags::TRANSFER_DST;
        let layers = bins * bins;
        let table = rdb_lens_table(bins);
        let bytes = slice_as_bytes(&table);
        let mut lens = Buffer::new(
            ctx,
            "rdb lens table",
            bytes.len() as u64,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            MemoryLocation::CpuToGpu,
        )?;
        lens.mapped_mut()
            .ok_or_else(|| Error::Allocation("rdb lens table is not host-visible".into()))?
            .copy_from_slice(bytes);
        Ok(RdbImages {
            depth: Image::new_2d(ctx, "rdb depth", vk::Format::R32_UINT, w, h, layers, usage)?,
            source: Image::new_2d(ctx, "rdb source", vk::Format::R32_UINT, w, h, layers, usage)?,
            lens,
            bins,
            result: Image::new_2d(
                ctx,
                "rdb result",
                vk::Format::R16G16B16A16_SFLOAT,
                gbuffer.color.width,
                gbuffer.color.height,
                1,
                vk::ImageUsageFlags::STORAGE | vk::ImageUsageFlags::TRANSFER_SRC,
            )?,
        })
    }
}

const CLEARED: Access = Access {
    stage: vk::PipelineStageFlags2::CLEAR,
    access: vk::AccessFlags2::TRANSFER_WRITE,
    layout: vk::ImageLayout::TRANSFER_DST_OPTIMAL,
};

impl Rdb {
    pub fn new(ctx: &Arc<Context>) -> Result<Rdb> {
        let img = vk::DescriptorType::STORAGE_IMAGE;
        let buf = vk::DescriptorType::STORAGE_BUFFER;
        Ok(Rdb {
            scatter: ComputePipeline::new(
                ctx,
                "rdb_scatter",
                SCATTER,
                &[img, img, img, buf],
                std::mem::size_of::<ScatterPush>() as u32,
            )?,
            resolve: ComputePipeline::new(
                ctx,
                "rdb_resolve",
                RESOLVE,
                &[img, img, img],
                std::mem::size_of::<ResolvePush>() as u32,
            )?,
        })
    }

    /// Records clear, the two scatter passes and the resolve after the
    /// G-buffer (last written by compute).
    pub fn record(
        &self,
        frame: &mut Frame,
        gbuffer: &GBuffer,
        images: &RdbImages,
        camera: &Camera,
        mode: RdbMode,
    ) {
        let (gw, gh) = (gbuffer.color.width, gbuffer.color.height);
        let (w, h) = (camera.width, camera.height);
        let g = gbuffer.view.guard as i32;
        frame.pass("rdb.clear", |ctx, cmd| {
            image_barriers(
                ctx,
                cmd,
                &[
                    (&images.depth, Access::NONE, CLEARED),
                    (&images.source, Access::NONE, CLEARED),
                ],
            );
            let clear = vk::ClearColorValue {
                uint32: [u32::MAX; 4],
            };
            // SAFETY: both images are in TRANSFER_DST_OPTIMAL (barrier above)
            // and the ranges cover them.
            unsafe {
                for image in [&images.depth, &images.source] {
                    ctx.device.cmd_clear_color_image(
                        cmd,
                        image.raw,
                        vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                        &clear,
                        &[image.full_range()],
                    );
                }
            }
            // The lens table, written by the host before the submission, is
            // visible to it by the submission's own host-write guarantee.
        });
        for pass_index in 0..2u32 {
            let name = if pass_index == 0 {
                "rdb.depth"
            } else {
                "rdb.source"
            };
            frame.pass(name, |ctx, cmd| {
                if pass_index == 0 {
                    image_barriers(
                        ctx,
                        cmd,
                        &[
                            (
                                &gbuffer.eye,
                                Access::COMPUTE_READ_WRITE,
                                Access::COMPUTE_READ,
                            ),
                            (&images.depth, CLEARED, Access::COMPUTE_READ_WRITE),
                            (&images.source, CLEARED, Access::COMPUTE_READ_WRITE),
                        ],
                    );
                } else {
                    image_barriers(
                        ctx,
                        cmd,
                        &[(
                            &images.depth,
                            Access::COMPUTE_READ_WRITE,
                            Access::COMPUTE_READ_WRITE,
                        )],
                    );
                }
                let push = ScatterPush {
                    extent: [gw as i32, gh as i32],
                    origin: [g, g],
                    size: [w as i32, h as i32],
                    bins: images.bins as i32,
                    pairs: (mode == RdbMode::Pairs) as u32,
                    pass_index,
                    f_px: camera.f_px(),
                    aperture_radius: camera.aperture_radius,
                    focus_distance: camera.focus_distance,
                };
                self.scatter.dispatch(
                    cmd,
                    &[
                        Bind::StorageImage(&gbuffer.eye),
                        Bind::StorageImage(&images.depth),
                        Bind::StorageImage(&images.source),
                        Bind::StorageBuffer(&images.lens),
                    ],
                    as_bytes(&push),
                    [groups(gw, 8), groups(gh, 8), 1],
                );
            });
        }
        frame.pass("rdb.resolve", |ctx, cmd| {
            image_barriers(
                ctx,
                cmd,
                &[
                    (&gbuffer.color, Access::COMPUTE_WRITE, Access::COMPUTE_READ),
                    (
                        &images.source,
                        Access::COMPUTE_READ_WRITE,
                        Access::COMPUTE_READ,
                    ),
                    (&images.result, Access::NONE, Access::COMPUTE_WRITE),
                ],
            );
            let push = ResolvePush {
                extent: [gw as i32, gh as i32],
                origin: [g, g],
                size: [w as i32, h as i32],
                bins: images.bins as i32,
            };
            self.resolve.dispatch(
                cmd,
                &[
                    Bind::StorageImage(&gbuffer.color),
                    Bind::StorageImage(&images.source),
                    Bind::StorageImage(&images.result),
                ],
                as_bytes(&push),
                [groups(w, 8), groups(h, 8), 1],
            );
        });
    }
}
