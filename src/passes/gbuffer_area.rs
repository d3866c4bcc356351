//! The G-buffer's area coverage ([`crate::options::Coverage::Area`]):
//! the compute raster's resolve of a band (`glsl/gbuffer_resolve_vis_marks.comp`)
//! marks the pixels whose K×K samples and the ring of their neighbours'
//! nearest samples do not all hold one visibility word, and only those
//! take their color from the visible areas of the nearest splats those
//! samples found (`glsl/gbuffer_area.comp`, dispatched over the marked
//! pixels alone). Every other pixel keeps the resolve's color, bit for
//! bit (docs/decisions/area-coverage.md). Where a method blurs the
//! G-buffer through the lens after it, a pixel none of whose window's
//! splats has a CoC under [`AREA_BLUR_LIMIT_PX`] is not marked: the blur
//! hides what the areas would mend.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::splat_compute::Visibility;
use crate::error::Result;
use crate::push_constants;
use crate::vk::{Access, Bind, Binding, Buffer, ComputePipeline, Context, Frame, Image, Recorder};

push_constants! {
    struct AreaPush {
        extent: [i32; 2],
        first_row: i32,
        target_first_row: i32,
        target_end_row: i32,
        target_width: u32,
        scale: u32,
        color_scale: f32,
        background: [f32; 4],
    }
}

/// The CoC (pixels) past which a G-buffer that a method blurs through the
/// lens after it (`fast`, `rdb`, `layered`;
/// [`super::GBufferLens::blurred_after`]) leaves a pixel to its samples'
/// mean: every depth its window's samples see blurs more than this. On the
/// bundled scenes at 640×480 and the methods' defaults it cut the area
/// pass by 30–70 % and moved PSNR against Mitsuba by −0.12 to 0 dB
/// (docs/decisions/area-coverage.md).
pub const AREA_BLUR_LIMIT_PX: f32 = 4.0;

/// The nearest splats an area-resolved pixel is made of, at most (mirrors
/// `AREA_CANDIDATES` in `glsl/gbuffer_area.comp`).
pub const AREA_CANDIDATES: u32 = 8;
/// Invocations per workgroup of the area pass, and its workgroups per
/// row of the dispatch: the least `maxComputeWorkGroupCount` a device has
/// (mirror `AREA_GROUP` and `AREA_ROW_GROUPS` in `glsl/gbuffer_area.glsl`).
const AREA_GROUP: u32 = 64;
const AREA_ROW_GROUPS: u32 = 65535;
/// Words before the marked pixels in [`Marked`]: the area pass's dispatch
/// (x, y, z) and their count.
const MARKED_HEADER_WORDS: u64 = 4;

static AREA_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gbuffer_area.comp.spv"));

pub struct GBufferArea {
    area: ComputePipeline<AreaPush>,
}

/// The list of one band's marked pixels: the area pass's dispatch, their
/// count, then each pixel (x | y << 16).
pub struct Marked {
    buffer: Buffer,
}

impl Marked {
    /// Room for every pixel of a band `width` × `rows` (each below 2^16:
    /// a pixel is packed in one word).
    pub fn new(ctx: &Arc<Context>, width: u32, rows: u32) -> Result<Marked> {
        assert!(
            width <= 1 << 16 && rows <= 1 << 16,
            "a marked pixel's coordinates fit 16 bits each"
        );
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::TRANSFER_DST
            | vk::BufferUsageFlags::INDIRECT_BUFFER;
        let pixels = width as u64 * rows as u64;
        assert!(
            pixels.div_ceil(AREA_GROUP as u64) <= AREA_ROW_GROUPS as u64 * 65535,
            "the area pass's dispatch holds every pixel"
        );
        let words = MARKED_HEADER_WORDS + pixels;
        Ok(Marked {
            buffer: Buffer::new(ctx, "area marks", 4 * words, usage, MemoryLocation::GpuOnly)?,
        })
    }

    /// The buffer the marking resolve appends to.
    pub fn buffer(&self) -> &Buffer {
        &self.buffer
    }

    /// Records the list's clearing (no pixel, no workgroup) after the
    /// last band's area pass read it, before the resolve marks pixels in it.
    pub fn record_clear<'r>(&'r self, rec: &mut Recorder<'_, 'r>) {
        rec.memory_barrier(Access::COMPUTE_READ, Access::FILL);
        rec.memory_barrier(Access::INDIRECT_READ, Access::FILL);
        rec.update_u32(&self.buffer, &[0, 1, 1, 0]);
        rec.memory_barrier(Access::FILL, Access::COMPUTE_READ_WRITE);
    }
}

/// One band of a G-buffer whose first layer resolves by area, after its
/// marking resolve: its rows, the rows its target holds, and what the
/// resolve was given.
pub struct AreaBand<'a> {
    pub target: &'a Visibility,
    pub splats: &'a Buffer,
    pub marked: &'a Marked,
    pub gbuffer_color: &'a Image,
    pub gbuffer_eye: &'a Image,
    /// The G-buffer rows (first, end) of the band.
    pub rows: (u32, u32),
    /// The G-buffer rows (first, end) its target holds.
    pub target_rows: (u32, u32),
    /// Target pixels per G-buffer pixel along each axis (K).
    pub scale: u32,
    pub background: [f32; 3],
    /// The linear colour of a splat's code 65535.
    pub color_scale: f32,
}

impl GBufferArea {
    /// The pipeline, on a device with 64-bit buffer atomics (the compute
    /// raster's).
    pub fn new(ctx: &Arc<Context>) -> Result<GBufferArea> {
        let buffer = Binding::StorageBuffer;
        let image = Binding::StorageImage;
        Ok(GBufferArea {
            area: ComputePipeline::new(
                ctx,
                "gbuffer_area",
                AREA_SPIRV,
                &[buffer, buffer, buffer, buffer, image, image],
            )?,
        })
    }

    /// Records, as pass `name`, the area resolve of the pixels `band`'s
    /// marking resolve listed (it wrote the G-buffer's color and eye
    /// images and the list, and read the words).
    pub fn record<'r>(&'r self, frame: &mut Frame<'r>, name: &str, band: &AreaBand<'r>) {
        let (w, h) = (band.gbuffer_color.width(), band.gbuffer_color.height());
        let (first_row, end_row) = band.rows;
        assert!(
            band.target_rows.0 <= first_row && first_row < end_row && end_row <= band.target_rows.1,
            "the target holds the band's rows"
        );
        assert!(band.target_rows.1 <= h, "rows within the G-buffer");
        assert_eq!(
            band.target.width(),
            band.scale * w,
            "the target is K times wider"
        );
        let [r, g, b] = band.background;
        let push = AreaPush {
            extent: [w as i32, end_row as i32],
            first_row: first_row as i32,
            target_first_row: band.target_rows.0 as i32,
            target_end_row: band.target_rows.1 as i32,
            target_width: band.target.width(),
            scale: band.scale,
            color_scale: band.color_scale,
            background: [r, g, b, 0.0],
        };
        let list = &band.marked.buffer;
        frame.pass(name, |rec| {
            // The marking resolve wrote the list (count, pixels, dispatch).
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::INDIRECT_READ);
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ);
            rec.barriers(&[
                (
                    band.gbuffer_color,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_WRITE,
                ),
                (
                    band.gbuffer_eye,
                    Access::COMPUTE_READ_WRITE,
                    Access::COMPUTE_READ_WRITE,
                ),
            ]);
            let binds = [
                Bind::StorageBuffer(&band.target.words),
                Bind::StorageBuffer(list),
                Bind::StorageBuffer(band.target.squares()),
                Bind::StorageBuffer(band.splats),
                Bind::StorageImage(band.gbuffer_color),
                Bind::StorageImage(band.gbuffer_eye),
            ];
            rec.dispatch_indirect(&self.area, &binds, &push, list, 0);
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    #[test]
    fn push_constants_and_constants_match_the_glsl() {
        check_push_layout::<AreaPush>("gbuffer_area", AREA_SPIRV).unwrap();
        let area = include_str!("../../glsl/gbuffer_area.comp");
        assert!(area.contains(&format!("const int AREA_CANDIDATES = {AREA_CANDIDATES};")));
        let shared = include_str!("../../glsl/gbuffer_area.glsl");
        assert!(shared.contains(&format!("const uint AREA_GROUP = {AREA_GROUP}u;")));
        assert!(shared.contains(&format!("const uint AREA_ROW_GROUPS = {AREA_ROW_GROUPS}u;")));
        assert!(area.contains(&format!("layout(local_size_x = {AREA_GROUP}) in;")));
        assert!(
            shared.contains("uint marked_dispatch[3];\n    uint marked_count;\n    uint marked[];")
        );
        assert_eq!(MARKED_HEADER_WORDS, 4);
    }
}
