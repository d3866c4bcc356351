//! Zhao's fast approximation (DESIGN §4) as four compute passes, each beside
//! its GLSL file: `fast_coc` (CoC and weight per pixel), `fast_tile_max`
//! (largest CoC per tile), `fast_tile_dilate` (each tile's gather radius)
//! and `fast_gather` (the z-tested, weighted gather).

use std::sync::Arc;

use ash::vk;

use super::{Configured, DofFrame, DofInput, DofMethod, FrameView};
use crate::error::Result;
use crate::options::{FastOptions, FastWeights, GatherWindow};
use crate::push_constants;
use crate::vk::{groups, Access, Bind, Binding, ComputePipeline, Context, Frame, Image};

/// Tile edge in pixels for the CoC bound.
pub const TILE: u32 = 16;

static COC: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_coc.comp.spv"));
static TILE_MAX: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_tile_max.comp.spv"));
static TILE_DILATE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_tile_dilate.comp.spv"));
static GATHER: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_gather.comp.spv"));

push_constants! {
    struct CocPush {
        extent: [i32; 2],
        f_px: f32,
        aperture_radius: f32,
        focus_distance: f32,
        area_weights: u32,
    }
}

push_constants! {
    struct TileMaxPush {
        extent: [i32; 2],
        tiles: [i32; 2],
        tile: i32,
    }
}

push_constants! {
    struct DilatePush {
        tiles: [i32; 2],
        tile: i32,
        reach: i32,
        fixed_radius: f32,
    }
}

push_constants! {
    struct GatherPush {
        extent: [i32; 2],
        origin: [i32; 2],
        size: [i32; 2],
        tile: i32,
    }
}

/// The four pipelines of the method.
pub struct Fast {
    coc: ComputePipeline<CocPush>,
    tile_max: ComputePipeline<TileMaxPush>,
    tile_dilate: ComputePipeline<DilatePush>,
    gather: ComputePipeline<GatherPush>,
}

impl Fast {
    pub fn new(ctx: &Arc<Context>) -> Result<Fast> {
        let img = Binding::StorageImage;
        Ok(Fast {
            coc: ComputePipeline::new(ctx, "fast_coc", COC, &[img; 2])?,
            tile_max: ComputePipeline::new(ctx, "fast_tile_max", TILE_MAX, &[img; 3])?,
            tile_dilate: ComputePipeline::new(ctx, "fast_tile_dilate", TILE_DILATE, &[img; 2])?,
            gather: ComputePipeline::new(ctx, "fast_gather", GATHER, &[img; 5])?,
        })
    }
}

/// Every pixel blurs, the background too: the default guard band.
impl DofMethod for Configured<'_, Fast, FastOptions> {
    fn prepare<'m>(
        &'m self,
        ctx: &Arc<Context>,
        view: &FrameView,
    ) -> Result<Box<dyn DofFrame + 'm>> {
        Ok(Box::new(FastFrame {
            method: self,
            images: FastImages::new(ctx, view)?,
        }))
    }
}

/// The images of one frame of the method.
struct FastImages {
    coc_weight: Image,
    tile_max: Image,
    tile_radius: Image,
    /// The result: G-buffer sized, written inside the guard band only.
    result: Image,
}

impl FastImages {
    fn new(ctx: &Arc<Context>, view: &FrameView) -> Result<FastImages> {
        let (w, h) = (view.full_width(), view.full_height());
        let (tw, th) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let storage = vk::ImageUsageFlags::STORAGE;
        let image = |name, format, w, h, usage| Image::new_2d(ctx, name, format, w, h, 1, usage);
        Ok(FastImages {
            coc_weight: image("fast coc", vk::Format::R32G32_SFLOAT, w, h, storage)?,
            tile_max: image("fast tile max", vk::Format::R32G32_SFLOAT, tw, th, storage)?,
            tile_radius: image(
                "fast tile radius",
                vk::Format::R32G32_SFLOAT,
                tw,
                th,
                storage,
            )?,
            result: image(
                "fast result",
                vk::Format::R16G16B16A16_SFLOAT,
                w,
                h,
                storage | vk::ImageUsageFlags::TRANSFER_SRC,
            )?,
        })
    }
}

struct FastFrame<'m> {
    method: &'m Configured<'m, Fast, FastOptions>,
    images: FastImages,
}

impl DofFrame for FastFrame<'_> {
    /// The four passes. `view.max_coc_px` bounds every pixel's CoC, the
    /// background's included.
    fn record<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>) -> &'r Image {
        let p = self.method.pipelines;
        let options = self.method.options;
        let images = &self.images;
        let view = &input.view;
        let camera = &view.camera;
        let (w, h) = (input.color.width() as i32, input.color.height() as i32);
        let tiles = [
            images.tile_max.width() as i32,
            images.tile_max.height() as i32,
        ];
        let g = view.guard as i32;
        frame.pass("fast.coc", |rec| {
            rec.barriers(&[
                (input.eye, Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ),
                (&images.coc_weight, Access::NONE, Access::COMPUTE_WRITE),
            ]);
            rec.dispatch(
                &p.coc,
                &[
                    Bind::StorageImage(input.eye),
                    Bind::StorageImage(&images.coc_weight),
                ],
                &CocPush {
                    extent: [w, h],
                    f_px: camera.f_px(),
                    aperture_radius: camera.aperture_radius,
                    focus_distance: camera.focus_distance,
                    area_weights: (options.weights == FastWeights::Area) as u32,
                },
                [groups(w as u32, 8), groups(h as u32, 8), 1],
            );
        });
        frame.pass("fast.tile_max", |rec| {
            rec.barriers(&[
                (
                    &images.coc_weight,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_READ,
                ),
                (&images.tile_max, Access::NONE, Access::COMPUTE_WRITE),
            ]);
            rec.dispatch(
                &p.tile_max,
                &[
                    Bind::StorageImage(&images.coc_weight),
                    Bind::StorageImage(&images.tile_max),
                    Bind::StorageImage(input.eye),
                ],
                &TileMaxPush {
                    extent: [w, h],
                    tiles,
                    tile: TILE as i32,
                },
                [groups(tiles[0] as u32, 8), groups(tiles[1] as u32, 8), 1],
            );
        });
        frame.pass("fast.tile_dilate", |rec| {
            rec.barriers(&[
                (
                    &images.tile_max,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_READ,
                ),
                (&images.tile_radius, Access::NONE, Access::COMPUTE_WRITE),
            ]);
            rec.dispatch(
                &p.tile_dilate,
                &[
                    Bind::StorageImage(&images.tile_max),
                    Bind::StorageImage(&images.tile_radius),
                ],
                &DilatePush {
                    tiles,
                    tile: TILE as i32,
                    // No farther than the grid of tiles reaches.
                    reach: ((view.max_coc_px / 2.0 / TILE as f32).ceil() as i32)
                        .min(tiles[0].max(tiles[1]))
                        + 1,
                    fixed_radius: match options.window {
                        GatherWindow::Tiles => 0.0,
                        GatherWindow::Fixed => (view.max_coc_px / 2.0).max(0.5),
                    },
                },
                [groups(tiles[0] as u32, 8), groups(tiles[1] as u32, 8), 1],
            );
        });
        frame.pass("fast.gather", |rec| {
            rec.barriers(&[
                (input.color, Access::COMPUTE_WRITE, Access::COMPUTE_READ),
                (
                    &images.tile_radius,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_READ,
                ),
                (&images.result, Access::NONE, Access::COMPUTE_WRITE),
            ]);
            let (ow, oh) = (view.window.width, view.window.height);
            rec.dispatch(
                &p.gather,
                &[
                    Bind::StorageImage(input.color),
                    Bind::StorageImage(input.eye),
                    Bind::StorageImage(&images.coc_weight),
                    Bind::StorageImage(&images.tile_radius),
                    Bind::StorageImage(&images.result),
                ],
                &GatherPush {
                    extent: [w, h],
                    origin: [g, g],
                    size: [ow as i32, oh as i32],
                    tile: TILE as i32,
                },
                [groups(ow, 8), groups(oh, 8), 1],
            );
        });
        &images.result
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    #[test]
    fn push_constants_match_the_glsl_blocks() {
        check_push_layout::<CocPush>("fast_coc", COC).unwrap();
        check_push_layout::<TileMaxPush>("fast_tile_max", TILE_MAX).unwrap();
        check_push_layout::<DilatePush>("fast_tile_dilate", TILE_DILATE).unwrap();
        check_push_layout::<GatherPush>("fast_gather", GATHER).unwrap();
    }
}
