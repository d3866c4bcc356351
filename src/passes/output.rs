//! The output pass (`glsl/output_convert.comp`): converts a frame's result
//! (rgba16f, inside the guard band) on the device into the output file's
//! pixels — linear f32 RGBA for EXR, 8-bit sRGB RGB for PNG — written
//! straight into a host-visible buffer, so that the host only copies them.

use std::sync::Arc;

use ash::vk;

use super::{FrameView, Specialized};
use crate::error::Result;
use crate::image_io::{f16_to_f32, linear_to_srgb8};
use crate::push_constants;
use crate::vk::{Access, Bind, Binding, Buffer, Context, Frame, Image};

static SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/output_convert.comp.spv"));

push_constants! {
    struct Push {
        origin: [i32; 2],
        size: [i32; 2],
        window: [i32; 2],
        format: u32,
        count: u32,
        veil_count: u32,
    }
}

/// What the output pass writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFormat {
    /// Linear RGBA, 4 × f32 per pixel (EXR, and every caller that computes
    /// on the image).
    LinearF32,
    /// 8-bit sRGB RGB, 3 bytes per pixel, tightly packed (PNG).
    Srgb8,
}

impl OutputFormat {
    /// Bytes the pass writes for `pixels` pixels (the sRGB form rounded up
    /// to whole 4-pixel groups).
    pub fn buffer_bytes(self, pixels: u64) -> u64 {
        match self {
            OutputFormat::LinearF32 => 16 * pixels,
            OutputFormat::Srgb8 => 12 * pixels.div_ceil(4),
        }
    }
}

/// Where the output pass's pixels go: `host` (host-visible, at least
/// [`OutputFormat::buffer_bytes`]), written by the shader itself or, with
/// `staging` (device-local, as large), copied there from it.
pub struct OutputBuffers<'r> {
    pub host: &'r Buffer,
    pub staging: Option<&'r Buffer>,
}

/// The specialization constant `VEIL_CODE` of `glsl/output_convert.comp`.
const VEIL_CODE_ID: u32 = 2;

/// The pipelines and the sRGB table, made once per renderer.
pub struct OutputConvert {
    /// The general pipeline and the one made without the veil's code
    /// (`VEIL_CODE` false), for the frames without a veil: the same
    /// pixels, in 0.6 of the time on llvmpipe.
    pipeline: Specialized<Push>,
    /// `linear_to_srgb8(f16_to_f32(h))` for every half-float bit pattern h,
    /// four codes per word.
    srgb8_lut: Buffer,
}

impl OutputConvert {
    pub fn new(ctx: &Arc<Context>) -> Result<OutputConvert> {
        let codes: Vec<u8> = (0..=u16::MAX)
            .map(|h| linear_to_srgb8(f16_to_f32(h)))
            .collect();
        let srgb8_lut = Buffer::with_bytes(
            ctx,
            "srgb8 table",
            &codes,
            vk::BufferUsageFlags::STORAGE_BUFFER,
        )?;
        let bindings = [
            Binding::StorageImage,
            Binding::StorageBuffer,
            Binding::StorageBuffer,
            Binding::StorageBuffer,
        ];
        Ok(OutputConvert {
            pipeline: Specialized::new(
                ctx,
                "output_convert",
                SPIRV,
                &bindings,
                "no veil",
                (VEIL_CODE_ID, 0),
            )?,
            srgb8_lut,
        })
    }

    /// Whether the frames without a veil take the pipeline made without
    /// its code (the default, true) or the general one, as the test that
    /// they agree renders.
    pub fn set_unveiled(&mut self, enabled: bool) {
        self.pipeline.set_enabled(enabled);
    }

    /// Records, as pass `output`, the conversion of the output part of
    /// `result` (G-buffer sized, `GENERAL`, last written by compute), under
    /// the first `veil.1` points of `veil.0` (`crate::veil::VeilSplat`,
    /// written by the host), into `out.host`, made visible to the host.
    ///
    /// With `out.staging` the shader writes there and a copy moves the
    /// pixels into `out.host`: on a discrete GPU a shader writing host
    /// memory across the bus is an order of magnitude slower than the copy
    /// engine (H100, a 1080p frame of floats: 12.8 ms written directly,
    /// 0.8 ms staged; docs/BENCHMARKS.md).
    pub fn record<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        result: &'r Image,
        view: &FrameView,
        veil: (&'r Buffer, u32),
        format: OutputFormat,
        out: OutputBuffers<'r>,
    ) {
        let OutputBuffers { host: out, staging } = out;
        let (w, h) = (view.window.width, view.window.height);
        let pixels = w as u64 * h as u64;
        assert!(
            out.size() >= format.buffer_bytes(pixels),
            "output buffer too small"
        );
        // One invocation per pixel in both formats: the veil loops over its
        // splats per pixel, and an invocation's loop iterations are bounded
        // on llvmpipe (`glsl/output_convert.comp`).
        let count = u32::try_from(pixels).expect("fewer than 2^32 pixels");
        // Workgroups of 64 as a 2D grid within the per-dimension limit.
        let groups = count.div_ceil(64);
        let gx = groups.clamp(1, 65_535);
        let g = view.guard as i32;
        let written = staging.unwrap_or(out);
        assert!(written.size() >= out.size(), "staging buffer too small");
        frame.pass("output", |rec| {
            rec.barriers(&[(result, Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ)]);
            rec.dispatch(
                self.pipeline.pick(veil.1 == 0),
                &[
                    Bind::StorageImage(result),
                    Bind::StorageBuffer(&self.srgb8_lut),
                    Bind::StorageBuffer(written),
                    Bind::StorageBuffer(veil.0),
                ],
                &Push {
                    origin: [g, g],
                    size: [w as i32, h as i32],
                    window: [view.window.x as i32, view.window.y as i32],
                    format: match format {
                        OutputFormat::LinearF32 => 0,
                        OutputFormat::Srgb8 => 1,
                    },
                    count,
                    veil_count: veil.1,
                },
                [gx, groups.div_ceil(gx).max(1), 1],
            );
            match staging {
                Some(staging) => {
                    rec.memory_barrier(Access::COMPUTE_WRITE, Access::COPY_SRC);
                    rec.copy_buffer(staging, out);
                    rec.memory_barrier(Access::COPY_WRITE, Access::HOST_READ);
                }
                None => rec.memory_barrier(Access::COMPUTE_WRITE, Access::HOST_READ),
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    #[test]
    fn push_constants_match_the_glsl_block() {
        check_push_layout::<Push>("output_convert", SPIRV).unwrap();
    }

    #[test]
    fn buffer_sizes_round_to_whole_groups() {
        assert_eq!(OutputFormat::Srgb8.buffer_bytes(5), 24);
        assert_eq!(OutputFormat::Srgb8.buffer_bytes(8), 24);
        assert_eq!(OutputFormat::LinearF32.buffer_bytes(5), 80);
    }
}
