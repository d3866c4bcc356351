//! GPU passes and the depth-of-field methods built from them. One Rust file
//! per pass or method beside its GLSL files of the same name in `glsl/`.
//! Each records from explicit inputs to outputs: a method reads the
//! resolved G-buffer ([`DofInput`]) and the view's facts ([`FrameView`]),
//! never the G-buffer module itself.
//!
//! Adding a method: see "Adding a method" in docs/ARCHITECTURE.md — a module
//! here implementing [`DofMethod`], a variant of [`crate::options::Method`],
//! and its line in [`Methods`].

use std::sync::{Arc, OnceLock};

use glam::{Vec2, Vec3};

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::options::Method;
use crate::vk::{Context, Frame, Image};

/// The specialization constant `APERTURE_CODE` of `glsl/aperture.glsl`:
/// whether a pipeline carries the code of shaped apertures and of the
/// cat's eye.
pub const APERTURE_CODE_ID: u32 = 0;

/// A pass's pipeline in two forms made from one shader: the general one,
/// and one made with a specialization constant that compiles away code
/// some frames never run (docs/decisions/specialized-pipelines.md): the
/// round aperture's ([`Specialized::round`]), a resolve's of a pass
/// that holds every sample, the output's without a veil. A frame takes the
/// special form where its own facts say the code would not run, so its
/// images are the general form's byte for byte.
pub struct Specialized<P: crate::vk::PushConstants> {
    general: crate::vk::ComputePipeline<P>,
    special: crate::vk::ComputePipeline<P>,
    /// Every frame takes `general` ([`Specialized::set_enabled`]).
    general_only: bool,
}

impl<P: crate::vk::PushConstants> Specialized<P> {
    /// The two forms of `spirv`, the special one (named `name (form)`)
    /// made with specialization constant `constant` (id, value).
    pub fn new(
        ctx: &Arc<Context>,
        name: &str,
        spirv: &[u8],
        bindings: &[crate::vk::Binding],
        form: &str,
        constant: (u32, u32),
    ) -> Result<Specialized<P>> {
        Self::with_base(ctx, name, spirv, bindings, &[], form, constant)
    }

    /// As [`Specialized::new`], both forms made with the constants `base`
    /// (id, value) too: a cut of the pass's work ([`kernel_sizes`]).
    pub fn with_base(
        ctx: &Arc<Context>,
        name: &str,
        spirv: &[u8],
        bindings: &[crate::vk::Binding],
        base: &[(u32, u32)],
        form: &str,
        constant: (u32, u32),
    ) -> Result<Specialized<P>> {
        let special: Vec<(u32, u32)> = base.iter().copied().chain([constant]).collect();
        Ok(Specialized {
            general: crate::vk::ComputePipeline::specialized(ctx, name, spirv, bindings, base)?,
            special: crate::vk::ComputePipeline::specialized(
                ctx,
                &format!("{name} ({form})"),
                spirv,
                bindings,
                &special,
            )?,
            general_only: false,
        })
    }

    /// The pipeline of a frame: the special form where `special` (the
    /// frame never runs the code it leaves out) and the form is enabled.
    pub fn pick(&self, special: bool) -> &crate::vk::ComputePipeline<P> {
        match special && !self.general_only {
            true => &self.special,
            false => &self.general,
        }
    }

    /// Whether frames may take the special form (the default, true), or
    /// every frame the general one, as the tests that they agree render
    /// (`Renderer::set_specialized_pipelines`).
    pub fn set_enabled(&mut self, enabled: bool) {
        self.general_only = !enabled;
    }

    /// The general form and the one without the code of shaped apertures
    /// and of the cat's eye (`APERTURE_CODE` false): on llvmpipe `fast`'s
    /// round gathers take about half the time, `layered`'s spread a fifth
    /// to a third less (docs/decisions/aperture-shape.md).
    pub fn round(
        ctx: &Arc<Context>,
        name: &str,
        spirv: &[u8],
        bindings: &[crate::vk::Binding],
    ) -> Result<Specialized<P>> {
        Self::new(ctx, name, spirv, bindings, "round", (APERTURE_CODE_ID, 0))
    }

    /// The pipeline for a frame through `aperture`, of a pair made by
    /// [`Specialized::round`]: the round one where it is the round
    /// aperture (no shape, image or cat's eye: the one rule).
    pub fn for_aperture(
        &self,
        aperture: &crate::camera::Aperture,
    ) -> &crate::vk::ComputePipeline<P> {
        self.pick(aperture.is_round())
    }
}

/// Rows of a shaped aperture's chord table (`Aperture::shape_rows`): a
/// row per pixel of a CoC up to 512 px across.
pub const SHAPE_ROWS: u32 = 512;

/// The chords of the camera's aperture where it is shaped (not an image)
/// or has a cat's eye (None: the round disk or an image), and their buffer
/// on the device (one unused entry for the disk), named after the method
/// `label`.
pub fn shape_chords(
    ctx: &Arc<Context>,
    camera: &Camera,
    label: &str,
) -> Result<(Option<crate::camera::ShapeRows>, crate::vk::Buffer)> {
    let aperture = &camera.aperture;
    // An image's rows are spans, not chords (`shape_spans`).
    let shape = (aperture.image.is_none() && (aperture.is_shaped() || aperture.cat_eye > 0.0))
        .then(|| aperture.shape_rows(SHAPE_ROWS));
    let chords: Vec<[f32; 2]> = shape.as_ref().map_or(vec![[0.0; 2]], |s| s.chords.clone());
    let buffer = crate::vk::Buffer::with_bytes(
        ctx,
        &format!("{label} shape chords"),
        bytemuck::cast_slice(&chords),
        ash::vk::BufferUsageFlags::STORAGE_BUFFER,
    )?;
    Ok((shape, buffer))
}

/// An aperture image's rows of spans (`Aperture::shape_spans`, None
/// without an image) and their buffers on the device: the rows' offsets
/// and the spans (one unused entry each without).
pub fn shape_spans(
    ctx: &Arc<Context>,
    camera: &Camera,
    label: &str,
) -> Result<(
    Option<crate::camera::ShapeSpans>,
    crate::vk::Buffer,
    crate::vk::Buffer,
)> {
    let aperture = &camera.aperture;
    let spans = aperture.image.map(|_| aperture.shape_spans(SHAPE_ROWS));
    let (offsets, list) = match &spans {
        Some(s) => (s.offsets.clone(), s.spans.clone()),
        None => (vec![0], vec![[0.0; 3]]),
    };
    let list = if list.is_empty() {
        vec![[0.0; 3]]
    } else {
        list
    };
    let usage = ash::vk::BufferUsageFlags::STORAGE_BUFFER;
    let offsets = crate::vk::Buffer::with_bytes(
        ctx,
        &format!("{label} span offsets"),
        bytemuck::cast_slice(&offsets),
        usage,
    )?;
    let flat: Vec<f32> = list.iter().flatten().copied().collect();
    let list = crate::vk::Buffer::with_bytes(
        ctx,
        &format!("{label} spans"),
        bytemuck::cast_slice(&flat),
        usage,
    )?;
    Ok((spans, offsets, list))
}

pub mod accum;
pub mod edl;
pub mod fast;
pub mod fields;
pub mod gbuffer_area;
pub mod gbuffer_resolve;
pub mod kernel_sizes;
pub mod layered;
pub mod output;
pub mod peel_cull;
pub mod pinhole;
pub mod radix_sort;
pub mod rdb;
pub mod sample_plan;
pub mod splat_compute;
pub mod splat_raster;
pub mod spread_disk;

/// A rectangle of a frame's output pixels: columns `x .. x + width`, rows
/// `y .. y + height` (origin top-left). A frame beyond the device's image
/// size renders as tiles, each a window of the whole frame
/// (docs/ARCHITECTURE.md, "Posters in tiles").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl Window {
    /// The whole frame of `camera`.
    pub fn whole(camera: &Camera) -> Window {
        Window {
            x: 0,
            y: 0,
            width: camera.width,
            height: camera.height,
        }
    }

    /// Number of pixels.
    pub fn pixels(&self) -> u64 {
        self.width as u64 * self.height as u64
    }

    /// The windows of at most `tile_px` × `tile_px` pixels that cover a
    /// `width` × `height` frame, row by row; the tiles of a row or column
    /// differ in size by at most a pixel.
    pub fn tiles(width: u32, height: u32, tile_px: u32) -> Vec<Window> {
        assert!(tile_px >= 1, "a tile has at least one pixel");
        let split = |n: u32| {
            let count = n.div_ceil(tile_px);
            (0..count)
                .map(move |i| {
                    let start = (n as u64 * i as u64 / count as u64) as u32;
                    let end = (n as u64 * (i as u64 + 1) / count as u64) as u32;
                    (start, end - start)
                })
                .collect::<Vec<_>>()
        };
        let columns = split(width);
        split(height)
            .into_iter()
            .flat_map(|(y, height)| {
                columns.iter().map(move |&(x, width)| Window {
                    x,
                    y,
                    width,
                    height,
                })
            })
            .collect()
    }
}

/// Which splats a method takes out of its G-buffer into the veil
/// ([`DofMethod::veil_rule`]; `crate::veil` splits them by it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VeilRule {
    /// None (the pinhole image, which has no blur).
    None,
    /// Those in front of the focus plane with a CoC above
    /// [`Camera::veil_coc_px`] (the methods that blur a G-buffer).
    Blurred,
    /// Those nearer than the near plane of the splats' depth range, which
    /// no raster draws (`accum`).
    BeyondNear,
}

/// What every pass of one frame may know about its view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameView {
    /// The camera of the whole frame.
    pub camera: Camera,
    /// The output pixels this view renders: the whole frame, or a tile.
    pub window: Window,
    /// Pixels added on every side of the window (DESIGN §3).
    pub guard: u32,
    /// The largest CoC (pixels) the method meets in this view, which the
    /// guard band was sized for.
    pub max_coc_px: f32,
    /// The eye-depth range of the points in front of the camera (None: no
    /// point), which the depth buffer and the CoC bound were made for.
    pub depths: Option<(f32, f32)>,
}

impl FrameView {
    /// Width of the G-buffer: the window plus the guard band.
    pub fn full_width(&self) -> u32 {
        self.window.width + 2 * self.guard
    }

    /// Height of the G-buffer: the window plus the guard band.
    pub fn full_height(&self) -> u32 {
        self.window.height + 2 * self.guard
    }
}

/// One resolved G-buffer layer (guard band included).
pub struct GBufferLayer {
    /// Linear color (rgba16f): the mean over the pixel's samples (each
    /// lens sample weighed by the cat's eye in accum's), the background's
    /// color where a sample saw nothing; alpha = coverage.
    pub color: Image,
    /// (0, 0, z, coverage) (rgba32f): the eye depth of the nearest sample
    /// (+∞ for background) and the covered fraction; x and y are not kept
    /// (no method reads them).
    pub eye: Image,
}

/// What a method reads: the resolved G-buffer (guard band included), every
/// image in `GENERAL` layout and last written by compute.
#[derive(Clone, Copy)]
pub struct DofInput<'r> {
    /// Linear color (rgba16f) of the first (pinhole) layer, alpha = coverage.
    pub color: &'r Image,
    /// (0, 0, z, coverage) (rgba32f) of the first layer.
    pub eye: &'r Image,
    /// Every layer, the first included: one unless the method asked for
    /// depth-peeled layers ([`DofMethod::gbuffer_layers`]).
    pub layers: &'r [GBufferLayer],
    /// The background's linear color (what an uncovered sample holds).
    pub background: Vec3,
    pub view: FrameView,
}

/// The lens positions a G-buffer is rasterised through (each with all K×K
/// sub-pixel samples) and the cat's eye S by which each receiving pixel
/// weighs them (`glsl/gbuffer_lens_weight.glsl`; 0: every position
/// alike, the plain mean).
#[derive(Debug, Clone, PartialEq)]
pub struct GBufferLens {
    pub positions: Vec<Vec2>,
    pub cat_eye: f32,
    /// Whether the method blurs the G-buffer through the camera's lens
    /// after it: its area coverage then leaves the pixels whose every
    /// splat blurs past [`gbuffer_area::AREA_BLUR_LIMIT_PX`].
    pub blurred_after: bool,
}

impl GBufferLens {
    /// The lens centre alone: a pinhole G-buffer, the image itself.
    pub fn centre() -> GBufferLens {
        GBufferLens {
            positions: vec![Vec2::ZERO],
            cat_eye: 0.0,
            blurred_after: false,
        }
    }

    /// The lens centre, a G-buffer the method then blurs through the lens.
    pub fn centre_blurred_after() -> GBufferLens {
        GBufferLens {
            blurred_after: true,
            ..GBufferLens::centre()
        }
    }
}

/// A depth-of-field method: what it needs of the G-buffer and the guard
/// band, and the images and passes of one frame.
pub trait DofMethod {
    /// Name of the G-buffer's passes in the timings (`gbuffer.raster`, …).
    fn gbuffer_label(&self) -> &'static str {
        "gbuffer"
    }

    /// The normalised lens positions the G-buffer is rasterised through,
    /// each with all K×K sub-pixel samples, for the camera's aperture, and
    /// how each receiving pixel weighs them: by default the lens centre,
    /// a G-buffer the method blurs through the lens after it.
    fn gbuffer_lens(&self, _camera: &Camera) -> GBufferLens {
        GBufferLens::centre_blurred_after()
    }

    /// How many depth-peeled G-buffer layers the method reads (DESIGN §6):
    /// 1, the pinhole G-buffer, by default.
    fn gbuffer_layers(&self) -> u32 {
        1
    }

    /// Which splats the method takes out of its G-buffer into the veil
    /// (`crate::veil`): by default those whose blur the guard band cannot
    /// hold.
    fn veil_rule(&self) -> VeilRule {
        VeilRule::Blurred
    }

    /// The largest CoC (pixels) the guard band must hold, given the eye
    /// depth range of the points in front of the camera (None: no point).
    /// By default every G-buffer pixel's, the background's included
    /// ([`max_gbuffer_coc`]).
    fn guard_coc_px(&self, camera: &Camera, depths: Option<(f32, f32)>) -> f32 {
        max_gbuffer_coc(camera, depths)
    }

    /// Allocates the images of one frame of `view`. Called before recording
    /// starts, so that a frame's wall time excludes allocation.
    fn prepare<'m>(
        &'m self,
        ctx: &Arc<Context>,
        view: &FrameView,
    ) -> Result<Box<dyn DofFrame + 'm>>;
}

/// One frame of a method: its images, ready to record.
pub trait DofFrame {
    /// Records the method's passes after the G-buffer and returns the image
    /// holding the result: rgba16f (`splat_raster::COLOR_FORMAT`, what the
    /// readback decodes), G-buffer sized, the output inside the guard band,
    /// in `GENERAL` layout, last written by compute.
    fn record<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>) -> &'r Image;

    /// What the method counted in the frame, (name, value), read after the
    /// frame has completed (`--timings` prints them): none by default.
    fn counts(&self) -> Vec<(String, u64)> {
        Vec::new()
    }
}

/// A pass that loops over a square of side 2r + 1 in one shader invocation
/// (rows, and per row its columns and one more test: (2r + 1)(2r + 2)
/// iterations), against the device's loop limit
/// (`DeviceInfo::loop_iterations_limit`, llvmpipe's 65,535 per
/// invocation, past which the loops stop without a word): an error in one
/// line naming `what` loops and the `way_out`, where it would pass it.
pub fn check_square_loop(ctx: &Context, r: u64, what: &str, way_out: &str) -> Result<()> {
    let Some(limit) = ctx.info.loop_iterations_limit() else {
        return Ok(());
    };
    let iterations = (2 * r + 1) * (2 * r + 2);
    if iterations > limit {
        return Err(Error::InvalidArgument(format!(
            "{what} up to {} px wide ({iterations} loop iterations) would pass {}'s {limit} per shader invocation and drop part of each; {way_out}",
            2 * r + 1,
            ctx.info.name
        )));
    }
    Ok(())
}

/// The largest CoC a G-buffer pixel can have: a point's in `depths`, or the
/// background's (the surface at infinity), for methods that blur the
/// background too.
pub fn max_gbuffer_coc(camera: &Camera, depths: Option<(f32, f32)>) -> f32 {
    let background = camera.coc_px(f32::INFINITY);
    depths.map_or(background, |(lo, hi)| {
        camera.max_coc_px(lo, hi).max(background)
    })
}

/// A method's pipelines (made once per renderer) with one frame's options:
/// what [`Methods::get`] hands out for methods that have pipelines.
pub struct Configured<'p, P, O> {
    pub pipelines: &'p P,
    pub options: O,
}

/// The registry of methods: their pipelines, made when a frame first asks
/// for the method (a one-frame process makes only its own: the three
/// methods' took lavapipe 91 ms, of 0.29 s for a small frame), and the one
/// dispatch from a [`Method`] to its implementation.
pub struct Methods {
    ctx: Arc<Context>,
    fast: OnceLock<fast::Fast>,
    rdb: OnceLock<rdb::Rdb>,
    layered: OnceLock<layered::Layered>,
    /// [`Methods::set_round_pipelines`], for pipelines made later too.
    round_pipelines: bool,
    /// How the methods' passes are cut ([`kernel_sizes`]).
    sizes: kernel_sizes::KernelSizes,
}

/// The value in `cell`, made by `make` if it holds none yet; its time
/// logged under `name`.
fn made<'a, T>(
    cell: &'a OnceLock<T>,
    name: &str,
    make: impl FnOnce() -> Result<T>,
) -> Result<&'a T> {
    if let Some(made) = cell.get() {
        return Ok(made);
    }
    let started = std::time::Instant::now();
    let made = make()?;
    log::info!(
        "{name} pipelines made in {:.0} ms",
        started.elapsed().as_secs_f64() * 1e3
    );
    Ok(cell.get_or_init(|| made))
}

impl Methods {
    pub fn new(ctx: &Arc<Context>) -> Result<Methods> {
        Ok(Methods {
            ctx: ctx.clone(),
            fast: OnceLock::new(),
            rdb: OnceLock::new(),
            layered: OnceLock::new(),
            round_pipelines: true,
            sizes: kernel_sizes::KernelSizes::for_device(&ctx.info),
        })
    }

    /// Whether the frames of the round aperture take the pipelines made
    /// without the aperture's code ([`Specialized::round`]; the default,
    /// true), or the general ones, as the test that they agree renders.
    pub fn set_round_pipelines(&mut self, enabled: bool) {
        self.round_pipelines = enabled;
        if let Some(m) = self.fast.get_mut() {
            m.set_round_pipelines(enabled);
        }
        if let Some(m) = self.rdb.get_mut() {
            m.set_round_pipelines(enabled);
        }
        if let Some(m) = self.layered.get_mut() {
            m.set_round_pipelines(enabled);
        }
    }

    /// The passes that have more than one cut of their work
    /// ([`kernel_sizes`]) in the form of `sizes`, in place of the
    /// device's own, as the test that the forms agree renders: the
    /// methods made so far are made again on their next frame.
    pub fn set_kernel_sizes(&mut self, sizes: kernel_sizes::KernelSizes) {
        self.sizes = sizes;
        self.fast.take();
        self.rdb.take();
        self.layered.take();
    }

    /// The implementation of `method` with its options (its pipelines made
    /// on the first frame that asks).
    pub fn get(&self, method: &Method) -> Result<Box<dyn DofMethod + '_>> {
        Ok(match *method {
            Method::Pinhole => Box::new(pinhole::Pinhole),
            Method::Fast(options) => Box::new(Configured {
                pipelines: made(&self.fast, "fast", || {
                    let mut m = fast::Fast::new(&self.ctx, self.sizes)?;
                    m.set_round_pipelines(self.round_pipelines);
                    Ok(m)
                })?,
                options,
            }),
            Method::Rdb(options) => Box::new(Configured {
                pipelines: made(&self.rdb, "rdb", || {
                    let mut m = rdb::Rdb::new(&self.ctx, self.sizes)?;
                    m.set_round_pipelines(self.round_pipelines);
                    Ok(m)
                })?,
                options,
            }),
            Method::Accum(options) => Box::new(accum::Accum(options)),
            Method::Layered(options) => Box::new(Configured {
                pipelines: made(&self.layered, "layered", || {
                    let mut m = layered::Layered::new(&self.ctx, self.sizes)?;
                    m.set_round_pipelines(self.round_pipelines);
                    Ok(m)
                })?,
                options,
            }),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::APERTURE_CODE_ID;

    /// The round pipelines set the constant the shaders declare: its id,
    /// and its default (true: a pipeline made without specialization is
    /// the general one).
    #[test]
    fn the_aperture_code_constant_is_the_shaders() {
        let aperture = include_str!("../../glsl/aperture.glsl");
        let declaration =
            format!("layout(constant_id = {APERTURE_CODE_ID}) const bool APERTURE_CODE = true;");
        assert!(
            aperture.contains(&declaration),
            "glsl/aperture.glsl: {declaration}"
        );
        assert_eq!(aperture.matches("constant_id").count(), 1);
    }
}
