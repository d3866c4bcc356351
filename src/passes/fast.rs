//! Zhao's fast approximation (DESIGN §4) as four compute passes, each beside
//! its GLSL file: `fast_coc` (CoC and weight per pixel), `fast_tile_max`
//! (largest CoC per tile), `fast_tile_dilate` (each tile's gather radius)
//! and `fast_gather` (the z-tested, weighted gather).

use std::sync::Arc;

use ash::vk;

use crate::camera::Camera;
use crate::error::Result;
use crate::gbuffer::GBuffer;
use crate::vk::{
    as_bytes, groups, image_barriers, Access, Bind, ComputePipeline, Context, Frame, Image,
};

/// Tile edge in pixels for the CoC bound.
pub const TILE: u32 = 16;

/// How each pixel's contribution is weighted (`--fast-weights`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FastWeights {
    /// By the inverse of the number of pixel centres inside its CoC disk
    /// (DESIGN §4's default: a point spreads its light over its disk).
    #[default]
    Area,
    /// Every contributor alike: the paper's plain mean.
    Uniform,
}

static COC: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_coc.comp.spv"));
static TILE_MAX: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_tile_max.comp.spv"));
static TILE_DILATE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_tile_dilate.comp.spv"));
static GATHER: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_gather.comp.spv"));

#[repr(C)]
#[derive(Clone, Copy)]
struct CocPush {
    extent: [i32; 2],
    f_px: f32,
    aperture_radius: f32,
    focus_distance: f32,
    area_weights: u32,
}

#[repr(C)]
#[derive(Clone, Copy)]
struct TileMaxPush {
    extent: [i32; 2],
    tiles: [i32; 2],
    tile: i32,
}

#[repr(C)]
#[derive(Clone, Copy)]
struct DilatePush {
    tiles: [i32; 2],
    tile: i32,
    reach: i32,
    fixed_radius: f32,
}

#[repr(C)]
#[derive(Clone, Copy)]
struct GatherPush {
    extent: [i32; 2],
    origin: [i32; 2],
    size: [i32; 2],
    tile: i32,
}

/// How far the gather looks (`--fast-window`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GatherWindow {
    /// Each tile's dilated maximum CoC (DESIGN §4).
    #[default]
    Tiles,
    /// The frame's largest CoC everywhere: the fixed worst-case window, kept
    /// only as the benchmark baseline.
    Fixed,
}

/// The four pipelines of the method.
pub struct Fast {
    coc: ComputePipeline,
    tile_max: ComputePipeline,
    tile_dilate: ComputePipeline,
    gather: ComputePipeline,
}

/// The images of one frame of the method.
pub struct FastImages {
    coc_weight: Image,
    tile_max: Image,
    tile_radius: Image,
    /// The result: G-buffer sized, written inside the guard band only.
    pub result: Image,
}

impl FastImages {
    pub fn new(ctx: &Arc<Context>, gbuffer: &GBuffer) -> Result<FastImages> {
        let (w, h) = (gbuffer.color.width, gbuffer.color.height);
        let (tw, th) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let storage = vk::ImageUsageFlags::STORAGE;
        Ok(FastImages {
            coc_weight: Image::new_2d(
                ctx,
                "fast coc",
                vk::Format::R32G32_SFLOAT,
                w,
                h,
                1,
                storage,
            )?,
            tile_max: Image::new_2d(
                ctx,
                "fast tile max",
                vk::Format::R32_SFLOAT,
                tw,
                th,
                1,
                storage,
            )?,
            tile_radius: Image::new_2d(
                ctx,
                "fast tile radius",
                vk::Format::R32_SFLOAT,
                tw,
                th,
                1,
                storage,
            )?,
            result: Image::new_2d(
                ctx,
                "fast result",
                vk::Format::R16G16B16A16_SFLOAT,
                w,
                h,
                1,
                storage | vk::ImageUsageFlags::TRANSFER_SRC,
            )?,
        })
    }
}

impl Fast {
    pub fn new(ctx: &Arc<Context>) -> Result<Fast> {
        let img = vk::DescriptorType::STORAGE_IMAGE;
        let size = |n: usize| n as u32;
        Ok(Fast {
            coc: ComputePipeline::new(
                ctx,
                "fast_coc",
                COC,
                &[img; 2],
                size(std::mem::size_of::<CocPush>()),
            )?,
            tile_max: ComputePipeline::new(
                ctx,
                "fast_tile_max",
                TILE_MAX,
                &[img; 2],
                size(std::mem::size_of::<TileMaxPush>()),
            )?,
            tile_dilate: ComputePipeline::new(
                ctx,
                "fast_tile_dilate",
                TILE_DILATE,
                &[img; 2],
                size(std::mem::size_of::<DilatePush>()),
            )?,
            gather: ComputePipeline::new(
                ctx,
                "fast_gather",
                GATHER,
                &[img; 5],
                size(std::mem::size_of::<GatherPush>()),
            )?,
        })
    }

    /// Records the four passes after the G-buffer (whose color and eye
    /// images were last written by compute). `max_coc_px` bounds every
    /// pixel's CoC, the background's included.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        frame: &mut Frame,
        gbuffer: &GBuffer,
        images: &FastImages,
        camera: &Camera,
        weights: FastWeights,
        window: GatherWindow,
        max_coc_px: f32,
    ) {
        let (w, h) = (gbuffer.color.width as i32, gbuffer.color.height as i32);
        let tiles = [images.tile_max.width as i32, images.tile_max.height as i32];
        let g = gbuffer.view.guard as i32;
        frame.pass("fast.coc", |ctx, cmd| {
            image_barriers(
                ctx,
                cmd,
                &[
                    (
                        &gbuffer.eye,
                        Access::COMPUTE_READ_WRITE,
                        Access::COMPUTE_READ,
                    ),
                    (&images.coc_weight, Access::NONE, Access::COMPUTE_WRITE),
                ],
            );
            let push = CocPush {
                extent: [w, h],
                f_px: camera.f_px(),
                aperture_radius: camera.aperture_radius,
                focus_distance: camera.focus_distance,
                area_weights: (weights == FastWeights::Area) as u32,
            };
            self.coc.dispatch(
                cmd,
                &[
                    Bind::StorageImage(&gbuffer.eye),
                    Bind::StorageImage(&images.coc_weight),
                ],
                as_bytes(&push),
                [groups(w as u32, 8), groups(h as u32, 8), 1],
            );
        });
        frame.pass("fast.tile_max", |ctx, cmd| {
            image_barriers(
                ctx,
                cmd,
                &[
                    (
                        &images.coc_weight,
                        Access::COMPUTE_WRITE,
                        Access::COMPUTE_READ,
                    ),
                    (&images.tile_max, Access::NONE, Access::COMPUTE_WRITE),
                ],
            );
            let push = TileMaxPush {
                extent: [w, h],
                tiles,
                tile: TILE as i32,
            };
            self.tile_max.dispatch(
                cmd,
                &[
                    Bind::StorageImage(&images.coc_weight),
                    Bind::StorageImage(&images.tile_max),
                ],
                as_bytes(&push),
                [groups(tiles[0] as u32, 8), groups(tiles[1] as u32, 8), 1],
            );
        });
        frame.pass("fast.tile_dilate", |ctx, cmd| {
            image_barriers(
                ctx,
                cmd,
                &[
                    (
                        &images.tile_max,
                        Access::COMPUTE_WRITE,
                        Access::COMPUTE_READ,
                    ),
                    (&images.tile_radius, Access::NONE, Access::COMPUTE_WRITE),
                ],
            );
            let push = DilatePush {
                tiles,
                tile: TILE as i32,
                reach: (max_coc_px / 2.0 / TILE as f32).ceil() as i32 + 1,
                fixed_radius: match window {
                    GatherWindow::Tiles => 0.0,
                    GatherWindow::Fixed => (max_coc_px / 2.0).max(0.5),
                },
            };
            self.tile_dilate.dispatch(
                cmd,
                &[
                    Bind::StorageImage(&images.tile_max),
                    Bind::StorageImage(&images.tile_radius),
                ],
                as_bytes(&push),
                [groups(tiles[0] as u32, 8), groups(tiles[1] as u32, 8), 1],
            );
        });
        frame.pass("fast.gather", |ctx, cmd| {
            image_barriers(
                ctx,
                cmd,
                &[
                    (&gbuffer.color, Access::COMPUTE_WRITE, Access::COMPUTE_READ),
                    (
                        &images.tile_radius,
                        Access::COMPUTE_WRITE,
                        Access::COMPUTE_READ,
                    ),
                    (&images.result, Access::NONE, Access::COMPUTE_WRITE),
                ],
            );
            let (ow, oh) = (gbuffer.view.camera.width, gbuffer.view.camera.height);
            let push = GatherPush {
                extent: [w, h],
                origin: [g, g],
                size: [ow as i32, oh as i32],
                tile: TILE as i32,
            };
            self.gather.dispatch(
                cmd,
                &[
                    Bind::StorageImage(&gbuffer.color),
                    Bind::StorageImage(&gbuffer.eye),
                    Bind::StorageImage(&images.coc_weight),
                    Bind::StorageImage(&images.tile_radius),
                    Bind::StorageImage(&images.result),
                ],
                as_bytes(&push),
                [groups(ow, 8), groups(oh, 8), 1],
            );
        });
    }
}
