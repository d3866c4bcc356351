//! The G-buffer resolve pass: folds one raster pass's samples into the
//! running color sum and nearest eye depth, and after the last pass
//! writes the G-buffer (the mean color, each lens position weighed by
//! [`LensWeight`]; the coverage fraction). One sample per pass,
//! or every sample in the upscaled plan's K×K blocks:
//! `glsl/gbuffer_resolve.comp`; the compute rasteriser's visibility
//! words: `glsl/gbuffer_resolve_vis.comp` (both through
//! `gbuffer_resolve_blocks.glsl`); multisampled passes:
//! `glsl/gbuffer_resolve_ms.comp`; all fold through `gbuffer_fold.glsl`.

use std::sync::Arc;

use glam::Vec2;

use super::gbuffer_area::Marked;
use super::splat_compute::Visibility;
use super::Specialized;
use crate::error::Result;
use crate::push_constants;
use crate::vk::{
    groups, Access, Bind, Binding, Buffer, ComputePipeline, Context, Frame, Image, Recorder,
};

push_constants! {
    struct Push {
        extent: [i32; 2],
        sample_index: u32,
        sample_count: u32,
        scale: u32,
        first_row: i32,
        lens_u: [f32; 2],
        window_origin: [i32; 2],
        frame_size: [i32; 2],
        cat_eye: f32,
        half_cell: f32,
        color_scale: f32,
    }
}

push_constants! {
    struct VisPush {
        extent: [i32; 2],
        sample_index: u32,
        sample_count: u32,
        scale: u32,
        first_row: i32,
        target_width: u32,
        target_first_row: i32,
        background: [f32; 4],
        lens_u: [f32; 2],
        window_origin: [i32; 2],
        frame_size: [i32; 2],
        cat_eye: f32,
        half_cell: f32,
        color_scale: f32,
        target_end_row: i32,
        area_blur: [f32; 6],
    }
}

push_constants! {
    struct MsPush {
        extent: [i32; 2],
        sample_base: u32,
        sample_count: u32,
        samples: u32,
        read_offsets: u32,
        index_base: u32,
        indices: [u32; 2],
        pad: u32,
        lens_u: [f32; 2],
        window_origin: [i32; 2],
        frame_size: [i32; 2],
        cat_eye: f32,
        half_cell: f32,
        color_scale: f32,
    }
}

static SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gbuffer_resolve.comp.spv"));
static VIS_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gbuffer_resolve_vis.comp.spv"));
static VIS_MARKS_SPIRV: &[u8] = include_bytes!(concat!(
    env!("OUT_DIR"),
    "/gbuffer_resolve_vis_marks.comp.spv"
));
static MS_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gbuffer_resolve_ms.comp.spv"));

pub struct GBufferResolve {
    /// Each one-sample-target resolve in two forms: the general one and
    /// one for a whole pass ([`ResolvePass::is_whole`]; `WHOLE_PASS`), the
    /// first and only pass of a G-buffer without accum's cat's eye, which
    /// is every compute raster's but accum's (a 1080p frame's resolve
    /// about 30 % shorter on llvmpipe).
    pipeline: Specialized<Push>,
    /// For the compute rasteriser's visibility words (on devices with
    /// 64-bit buffer atomics): plain, and marking the pixels that
    /// resolve by area.
    visibility: Option<(Specialized<VisPush>, Specialized<VisPush>)>,
    /// For multisampled passes, on devices that have them.
    multisampled: Option<ComputePipeline<MsPush>>,
}

/// The specialization constant `WHOLE_PASS` of
/// `glsl/gbuffer_resolve_blocks.glsl`.
const WHOLE_PASS_ID: u32 = 3;

/// The general resolve of `spirv` and its whole pass's.
fn resolve_pair<P: crate::vk::PushConstants>(
    ctx: &Arc<Context>,
    name: &str,
    spirv: &[u8],
    bindings: &[Binding],
) -> Result<Specialized<P>> {
    Specialized::new(ctx, name, spirv, bindings, "whole pass", (WHOLE_PASS_ID, 1))
}

/// Which samples of the G-buffer one resolve folds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResolvePass {
    /// Samples folded by the passes before this one.
    pub first_sample: u32,
    /// Samples of the whole G-buffer.
    pub sample_count: u32,
    /// Read offsets of this pass's samples ([`super::sample_plan::PlannedPass`]).
    pub read_offsets: u32,
    /// Index of the lens position's first sample in the one-sample form.
    pub index_base: u32,
    /// Packed indices of this pass's samples within the lens position
    /// ([`super::sample_plan::PlannedPass::packed_indices`]).
    pub indices: [u32; 2],
    /// Target pixels per output pixel along each axis (one-sample targets
    /// only): 1, or K for the upscaled plan's K×K blocks
    /// ([`super::sample_plan::SamplePlan::upscaled`]).
    pub scale: u32,
    /// The G-buffer rows (first, end) the pass's samples are of: every
    /// row, or a band's ([`super::sample_plan::SamplePlan::band_rows`];
    /// one-sample targets only), whose target holds only its rows.
    pub rows: (u32, u32),
    /// The G-buffer rows (first, end) the pass's target holds: `rows`,
    /// or (visibility words only) those with a row of the neighbouring
    /// bands on each side, which the area resolve reads
    /// ([`super::gbuffer_area`]).
    pub target_rows: (u32, u32),
    /// How each receiving pixel weighs the pass's lens position.
    pub lens_weight: LensWeight,
    /// The linear colour of a splat's code 65535 (1: white): a covered
    /// sample's color is multiplied by it.
    pub color_scale: f32,
    /// The lens that blurs the G-buffer after it (f_px, aperture radius,
    /// focus distance), the CoC (px) past which the area resolve does
    /// not mark a pixel ([`super::gbuffer_area::AREA_BLUR_LIMIT_PX`]),
    /// and with the cat's eye its S and the shape's least reach, by which
    /// each pixel's limit grows ([`crate::camera::Aperture::cat_eye_blur_reach`];
    /// else 0, 0); zeros: every pixel its words mark.
    pub area_blur: [f32; 6],
}

impl ResolvePass {
    /// Whether the pass holds every sample of its pixels (from the first,
    /// K² of K²) and weighs them alike (no cat's eye): the whole pass of
    /// `WHOLE_PASS` (`glsl/gbuffer_resolve_blocks.glsl`).
    pub fn is_whole(&self) -> bool {
        self.first_sample == 0
            && self.sample_count == self.scale * self.scale
            && self.lens_weight.cat_eye == 0.0
    }
}

/// How each receiving pixel weighs one pass's lens position in its fold
/// (`glsl/gbuffer_lens_weight.glsl`): by accum's cat's eye, or alike.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LensWeight {
    /// The pass's normalised lens position.
    pub lens_u: Vec2,
    /// The frame pixel of G-buffer pixel (0, 0) (a tile's window less the
    /// guard band).
    pub window_origin: [i32; 2],
    /// The whole frame's size, pixels.
    pub frame_size: [u32; 2],
    /// The cat's eye S; 0: every lens position weighs 1.
    pub cat_eye: f32,
    /// The half-width of the lens cell a position stands for
    /// ([`crate::camera::Aperture::lens_cell_half_width`]).
    pub half_cell: f32,
}

impl LensWeight {
    /// Every lens position alike (the plain mean).
    pub const ONE: LensWeight = LensWeight {
        lens_u: Vec2::ZERO,
        window_origin: [0, 0],
        frame_size: [1, 1],
        cat_eye: 0.0,
        half_cell: 1.0,
    };

    /// The push constants' five fields: lens_u, window_origin,
    /// frame_size, cat_eye, half_cell.
    fn fields(&self) -> ([f32; 2], [i32; 2], [i32; 2], f32, f32) {
        (
            self.lens_u.to_array(),
            self.window_origin,
            self.frame_size.map(|v| v as i32),
            self.cat_eye,
            self.half_cell,
        )
    }
}

/// Where a raster pass left its samples.
#[derive(Clone, Copy)]
pub enum Samples<'a> {
    /// The sprite path's sample target: (r, g, b, z).
    Target(&'a Image),
    /// The compute rasteriser's words, the splats they index, the
    /// color of a sample no splat covers and, where the G-buffer resolves
    /// by area, the list the resolve marks pixels in (cleared by the
    /// resolve pass first; [`super::gbuffer_area`]).
    Visibility {
        target: &'a Visibility,
        splats: &'a Buffer,
        background: [f32; 3],
        marked: Option<&'a Marked>,
    },
}

impl Samples<'_> {
    /// Samples per pixel of the target.
    fn per_pixel(&self) -> u32 {
        match self {
            Samples::Target(image) => image.samples(),
            Samples::Visibility { .. } => 1,
        }
    }
}

/// The images the pass reads and writes, all in `GENERAL` layout.
pub struct ResolveImages<'a> {
    /// The pass's samples.
    pub sample: Samples<'a>,
    pub color_sum: &'a Image,
    pub gbuffer_eye: &'a Image,
    pub gbuffer_color: &'a Image,
}

impl GBufferResolve {
    /// The pipelines; the multisampled one when `multisampled` (the device
    /// reads multisampled storage images).
    pub fn new(ctx: &Arc<Context>, multisampled: bool) -> Result<GBufferResolve> {
        let bindings = [Binding::StorageImage; 4];
        let image = Binding::StorageImage;
        let buffer = Binding::StorageBuffer;
        let vis_bindings = [buffer, image, image, image, buffer];
        Ok(GBufferResolve {
            pipeline: resolve_pair(ctx, "gbuffer_resolve", SPIRV, &bindings)?,
            visibility: match ctx.info.buffer_int64_atomics {
                true => Some((
                    resolve_pair(ctx, "gbuffer_resolve_vis", VIS_SPIRV, &vis_bindings)?,
                    resolve_pair(
                        ctx,
                        "gbuffer_resolve_vis_marks",
                        VIS_MARKS_SPIRV,
                        &[buffer, image, image, image, buffer, buffer, buffer],
                    )?,
                )),
                false => None,
            },
            multisampled: match multisampled {
                true => Some(ComputePipeline::new(
                    ctx,
                    "gbuffer_resolve_ms",
                    MS_SPIRV,
                    &bindings,
                )?),
                false => None,
            },
        })
    }

    /// Whether the passes that hold every sample of their pixels take the
    /// pipelines made for them (the default, true) or the general ones,
    /// as the test that they agree renders.
    pub fn set_whole_passes(&mut self, enabled: bool) {
        self.pipeline.set_enabled(enabled);
        if let Some((plain, marks)) = &mut self.visibility {
            plain.set_enabled(enabled);
            marks.set_enabled(enabled);
        }
    }

    /// Records, as pass `name`, the fold of the samples of one raster pass
    /// (as many as the sample targets have per pixel) into the G-buffer,
    /// with the barriers on the running images (the sample targets' barrier
    /// is the raster's).
    pub fn record<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        name: &str,
        images: &ResolveImages<'r>,
        pass: &ResolvePass,
    ) {
        let samples = images.sample.per_pixel();
        assert!(
            pass.scale == 1 || samples == 1,
            "upscaled targets have one sample"
        );
        assert!(
            pass.first_sample + samples * pass.scale * pass.scale <= pass.sample_count,
            "more samples than the G-buffer's"
        );
        let (w, h) = (images.gbuffer_color.width(), images.gbuffer_color.height());
        let (first_row, end_row) = pass.rows;
        assert!(
            first_row < end_row && end_row <= h,
            "rows within the G-buffer"
        );
        assert!(
            pass.rows == (0, h) || (samples == 1 && pass.read_offsets == 0),
            "bands of one-sample targets only"
        );
        assert!(
            pass.target_rows.0 <= first_row && end_row <= pass.target_rows.1,
            "the target holds the pass's rows"
        );
        // The first resolve into the G-buffer images this frame: before it
        // they hold nothing; after it, a later pass's or band's resolve
        // reads or writes what the earlier ones wrote.
        let fresh = pass.first_sample == 0 && first_row == 0;
        frame.pass(name, |rec| {
            let src = if fresh {
                Access::NONE
            } else {
                Access::COMPUTE_READ_WRITE
            };
            let mut list = vec![
                (images.color_sum, src, Access::COMPUTE_READ_WRITE),
                (images.gbuffer_eye, src, Access::COMPUTE_READ_WRITE),
            ];
            if fresh {
                list.push((images.gbuffer_color, Access::NONE, Access::COMPUTE_WRITE));
            } else if pass.first_sample == 0 {
                // A later band's first pass: the earlier bands' last
                // resolves wrote the color image (other rows).
                list.push((
                    images.gbuffer_color,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_WRITE,
                ));
            }
            rec.barriers(&list);
            self.dispatch(rec, images, pass, w);
        });
    }

    /// Records the dispatch of the pass's pipeline for its kind of samples
    /// (visibility words, one sample or several per pixel) over the rows of
    /// `pass` of a G-buffer `w` pixels wide.
    fn dispatch<'r>(
        &'r self,
        rec: &mut Recorder<'_, 'r>,
        images: &ResolveImages<'r>,
        pass: &ResolvePass,
        w: u32,
    ) {
        let samples = images.sample.per_pixel();
        let (first_row, end_row) = pass.rows;
        let (lens_u, window_origin, frame_size, cat_eye, half_cell) = pass.lens_weight.fields();
        let extent = [w as i32, end_row as i32];
        let size = [groups(w, 16), groups(end_row - first_row, 16), 1];
        let image = match images.sample {
            Samples::Target(image) => image,
            Samples::Visibility {
                target,
                splats,
                background,
                marked,
            } => {
                let mut binds = vec![
                    Bind::StorageBuffer(&target.words),
                    Bind::StorageImage(images.color_sum),
                    Bind::StorageImage(images.gbuffer_eye),
                    Bind::StorageImage(images.gbuffer_color),
                    Bind::StorageBuffer(splats),
                ];
                let [r, g, b] = background;
                let push = VisPush {
                    extent,
                    sample_index: pass.first_sample,
                    sample_count: pass.sample_count,
                    scale: pass.scale,
                    first_row: first_row as i32,
                    target_width: target.width(),
                    target_first_row: pass.target_rows.0 as i32,
                    background: [r, g, b, 0.0],
                    lens_u,
                    window_origin,
                    frame_size,
                    cat_eye,
                    half_cell,
                    color_scale: pass.color_scale,
                    target_end_row: pass.target_rows.1 as i32,
                    area_blur: pass.area_blur,
                };
                let (plain, marks) = self
                    .visibility
                    .as_ref()
                    .expect("visibility words on a device with 64-bit atomics");
                let pipeline = match marked {
                    Some(marked) => {
                        assert!(
                            pass.is_whole(),
                            "a G-buffer resolved by area has one pass of every sample"
                        );
                        marked.record_clear(rec);
                        binds.push(Bind::StorageBuffer(marked.buffer()));
                        binds.push(Bind::StorageBuffer(target.touched()));
                        marks
                    }
                    None => plain,
                };
                let pipeline = pipeline.pick(pass.is_whole());
                rec.dispatch(pipeline, &binds, &push, size);
                return;
            }
        };
        let binds = [
            Bind::StorageImage(image),
            Bind::StorageImage(images.color_sum),
            Bind::StorageImage(images.gbuffer_eye),
            Bind::StorageImage(images.gbuffer_color),
        ];
        if samples == 1 {
            assert_eq!(pass.read_offsets, 0, "one-sample passes read in place");
            assert_eq!(
                pass.index_base + pass.indices[0],
                pass.first_sample,
                "one-sample passes fold in index order"
            );
            let push = Push {
                extent,
                sample_index: pass.first_sample,
                sample_count: pass.sample_count,
                scale: pass.scale,
                first_row: first_row as i32,
                lens_u,
                window_origin,
                frame_size,
                cat_eye,
                half_cell,
                color_scale: pass.color_scale,
            };
            let pipeline = self.pipeline.pick(pass.is_whole());
            rec.dispatch(pipeline, &binds, &push, size);
        } else {
            let pipeline = self
                .multisampled
                .as_ref()
                .expect("multisampled targets on a device that resolves them");
            let push = MsPush {
                extent,
                sample_base: pass.first_sample,
                sample_count: pass.sample_count,
                samples,
                read_offsets: pass.read_offsets,
                index_base: pass.index_base,
                indices: pass.indices,
                pad: 0,
                lens_u,
                window_origin,
                frame_size,
                cat_eye,
                half_cell,
                color_scale: pass.color_scale,
            };
            rec.dispatch(pipeline, &binds, &push, size);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    #[test]
    fn push_constants_match_the_glsl_block() {
        check_push_layout::<Push>("gbuffer_resolve", SPIRV).unwrap();
        check_push_layout::<VisPush>("gbuffer_resolve_vis", VIS_SPIRV).unwrap();
        check_push_layout::<VisPush>("gbuffer_resolve_vis_marks", VIS_MARKS_SPIRV).unwrap();
        check_push_layout::<MsPush>("gbuffer_resolve_ms", MS_SPIRV).unwrap();
    }
}
