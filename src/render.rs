//! The frame, as one readable chain (docs/ARCHITECTURE.md, "The frame"):
//! view → G-buffer (K×K raster samples, resolved) → depth-of-field method →
//! readback, in [`Renderer::render_frame`].

use std::sync::{Arc, Mutex};
use std::time::Instant;

use ash::vk;
use glam::Vec3;
use gpu_allocator::MemoryLocation;

use crate::camera::Camera;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::gbuffer::{clip_range, depth_range_with, GBuffer, GBufferPasses, RasterView};
use crate::image_io::{f16_to_f32, LinearImage, Srgb8Image};
use crate::options::{check_samples_per_pass, check_ssaa, Method};
use crate::passes::output::{OutputConvert, OutputFormat};
use crate::passes::splat_raster::{SplatVertex, COLOR_FORMAT, EYE_FORMAT};
use crate::passes::{DofInput, DofMethod, FrameView, Methods};
use crate::report::Upload;
use crate::vk::{texel_bytes, Access, Buffer, Context, Frame, FrameTimings};

/// A splat's default world diameter is this multiple of its local point
/// spacing (mean distance to its 8 nearest neighbours): it closes the bunny's
/// surface without fattening edges. Scans with depth-quantised rows (the
/// PCL stereo scan) keep some holes; `--splat-size` / `--splat-px` cover them.
pub const SPACING_TO_DIAMETER: f32 = 1.0;

/// Every point's world diameter under `splat` (DESIGN §3), as the upload
/// makes them: `SPACING_TO_DIAMETER` × local spacing (the cloud's median
/// spacing where a point's is 0), W for `World(W)`, and 0 for `Pixels`
/// (sized on the GPU).
pub fn splat_diameters(cloud: &PointCloud, splat: SplatSize) -> Vec<f32> {
    match splat {
        SplatSize::World(w) => vec![w; cloud.len()],
        SplatSize::Pixels(_) => vec![0.0; cloud.len()],
        SplatSize::Spacing => {
            let spacing = cloud.local_spacing();
            let fallback = crate::cloud::median(spacing.clone());
            spacing
                .iter()
                .map(|&s| SPACING_TO_DIAMETER * if s > 0.0 { s } else { fallback })
                .collect()
        }
    }
}

/// How big a splat is (DESIGN §3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SplatSize {
    /// From each point's local spacing (the default).
    Spacing,
    /// Every splat a square of this side in scene units, facing the camera.
    World(f32),
    /// Every splat a square of this many pixels in the pinhole image.
    Pixels(f32),
}

/// Everything a frame needs besides the scene.
#[derive(Debug, Clone, Copy)]
pub struct RenderOptions {
    pub camera: Camera,
    /// The depth-of-field method with its options.
    pub method: Method,
    /// K: the G-buffer takes K×K samples per pixel.
    pub ssaa: u32,
    /// The most samples per raster pass (1: one pass per sample, the
    /// reference form); None: the device's best plan for K (DESIGN §3,
    /// [`SamplePlan::best`]).
    pub samples_per_pass: Option<u32>,
    /// Linear-light background color.
    pub background: Vec3,
}

/// What the CPU knows about a scene seen through one camera: the eye-depth
/// range of its points and its largest splat in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SceneView {
    depths: Option<(f32, f32)>,
    max_splat_px: f32,
}

/// A cloud on the GPU: its splats, and what the CPU needs to frame them.
pub struct Scene {
    vertices: Buffer,
    count: u32,
    positions: Vec<Vec3>,
    /// World diameters (unused when `splat` is `Pixels`).
    diameters: Vec<f32>,
    splat: SplatSize,
    /// The last camera's [`SceneView`] (with the point-size limit it was
    /// clamped to): frames of one camera scan the points once.
    last_view: Mutex<Option<(Camera, f32, SceneView)>>,
    /// The upload's times: splat sizes on the CPU (the k-nearest neighbour
    /// spacing for `SplatSize::Spacing`), the copy's GPU time, and the wall
    /// time of all of it. Not part of any frame.
    pub upload: Upload,
}

impl Scene {
    /// Number of splats.
    pub fn len(&self) -> usize {
        self.count as usize
    }

    /// Whether the scene has no splats.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The depth range and largest splat of the scene through `camera`
    /// (points nearer than the clip range's near plane do not count towards
    /// the splat size), from the cache when the camera is the last one.
    fn view(&self, camera: &Camera, point_size_max: f32) -> SceneView {
        let mut last = self.last_view.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((c, limit, v)) = *last {
            if c == *camera && limit == point_size_max {
                return v;
            }
        }
        let eye_from_world = camera.eye_from_world_transform();
        let depths = depth_range_with(&eye_from_world, &self.positions);
        let (near, _) = clip_range(depths);
        let max_splat_px = match self.splat {
            SplatSize::Pixels(p) => p.min(point_size_max),
            _ => {
                let f_px = camera.f_px();
                let mut m = 1.0f32;
                for (p, d) in self.positions.iter().zip(&self.diameters) {
                    let z = eye_from_world.apply(*p).z;
                    if z >= near {
                        m = m.max(f_px * d / z);
                    }
                }
                m.min(point_size_max)
            }
        };
        let view = SceneView {
            depths,
            max_splat_px,
        };
        *last = Some((*camera, point_size_max, view));
        view
    }
}

/// The result of a frame: the image without guard band, and its timings.
pub struct Rendered<I = LinearImage> {
    /// The output pixels: linear f32 ([`Renderer::render`]) or 8-bit sRGB
    /// ([`Renderer::render_srgb8`]).
    pub image: I,
    pub timings: FrameTimings,
    /// The guard band the frame was rendered with, pixels.
    pub guard: u32,
    /// Samples per G-buffer raster pass.
    pub samples_per_pass: u32,
    /// What the method counted ([`crate::passes::DofFrame::counts`]), e.g.
    /// the layered method's kept and discarded pixels per layer.
    pub counts: Vec<(String, u64)>,
}

/// A G-buffer read back to the host (guard band included), for CPU
/// references and tests.
#[derive(Debug, Clone)]
pub struct HostGBuffer {
    pub width: u32,
    pub height: u32,
    pub guard: u32,
    /// Linear color, alpha = coverage.
    pub color: Vec<[f32; 4]>,
    /// (0, 0, z, coverage): eye depth (DESIGN §2's eye space; +inf for
    /// background) and covered fraction; x and y are not kept.
    pub eye: Vec<[f32; 4]>,
}

/// Owns the pipelines; renders any number of frames of any scene.
pub struct Renderer {
    ctx: Arc<Context>,
    gbuffer: GBufferPasses,
    methods: Methods,
    output: OutputConvert,
}

fn unorm16(c: f32) -> u16 {
    (c.clamp(0.0, 1.0) * 65535.0 + 0.5) as u16
}

impl Renderer {
    pub fn new(ctx: &Arc<Context>) -> Result<Renderer> {
        Ok(Renderer {
            ctx: ctx.clone(),
            gbuffer: GBufferPasses::new(ctx)?,
            methods: Methods::new(ctx)?,
            output: OutputConvert::new(ctx)?,
        })
    }

    /// The context the renderer draws with.
    pub fn ctx(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// Computes splat sizes and copies the splats to device memory.
    pub fn upload(&self, cloud: &PointCloud, splat: SplatSize) -> Result<Scene> {
        let count = u32::try_from(cloud.len())
            .map_err(|_| Error::InvalidArgument(format!("{} points exceed 2^32", cloud.len())))?;
        let started = Instant::now();
        let diameters = splat_diameters(cloud, splat);
        let splat_sizes_ms = started.elapsed().as_secs_f64() * 1e3;
        let vertices: Vec<SplatVertex> = cloud
            .positions
            .iter()
            .zip(&cloud.colors)
            .zip(&diameters)
            .map(|((p, c), d)| SplatVertex {
                position_size: [p.x, p.y, p.z, *d],
                color: [unorm16(c.x), unorm16(c.y), unorm16(c.z), 65535],
            })
            .collect();
        let bytes: &[u8] = bytemuck::cast_slice(&vertices);
        let size = bytes.len() as u64;
        let staging = Buffer::with_bytes(
            &self.ctx,
            "splat staging",
            bytes,
            vk::BufferUsageFlags::TRANSFER_SRC,
        )?;
        let vertex_buffer = Buffer::new(
            &self.ctx,
            "splats",
            size,
            vk::BufferUsageFlags::VERTEX_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuOnly,
        )?;
        let mut frame = Frame::begin(&self.ctx, "upload")?;
        frame.pass("upload", |rec| {
            rec.copy_buffer(&staging, &vertex_buffer);
            // Makes the copy visible to every later vertex fetch, in this
            // and later submissions.
            rec.memory_barrier(Access::COPY_WRITE, Access::VERTEX_READ);
        });
        let copy = frame.submit_and_wait()?;
        drop(staging);
        let upload = Upload {
            splat_sizes_ms,
            gpu_ms: copy.gpu_total_ms(),
            wall_ms: started.elapsed().as_secs_f64() * 1e3,
        };
        Ok(Scene {
            vertices: vertex_buffer,
            count,
            positions: cloud.positions.clone(),
            diameters,
            splat,
            last_view: Mutex::new(None),
            upload,
        })
    }

    /// The raster view of `scene` through `camera`: depth range, splat rule
    /// and a guard band for the blur of `method` (DESIGN §3).
    fn raster_view(&self, scene: &Scene, camera: &Camera, method: &dyn DofMethod) -> RasterView {
        let max_point = self.ctx.info.point_size_max;
        let seen = scene.view(camera, max_point);
        let max_coc_px = method.guard_coc_px(camera, seen.depths);
        let (near, far) = clip_range(seen.depths);
        RasterView {
            frame: FrameView {
                camera: *camera,
                guard: Camera::guard_band_px(max_coc_px, seen.max_splat_px),
                max_coc_px,
                depths: seen.depths,
            },
            near,
            far,
            splat_px: match scene.splat {
                SplatSize::Pixels(p) => p,
                _ => 0.0,
            },
            max_point_size: max_point,
        }
    }

    /// Renders one frame of `scene`.
    pub fn render(&self, scene: &Scene, options: &RenderOptions) -> Result<Rendered> {
        let (r, _) = self.render_frame(scene, options, OutputFormat::LinearF32, false)?;
        Ok(r.map(|pixels| pixels.linear().expect("asked for")))
    }

    /// Renders one frame of `scene` as a PNG's pixels, encoded on the
    /// device: the same bytes as [`Srgb8Image::of`] the linear frame.
    pub fn render_srgb8(
        &self,
        scene: &Scene,
        options: &RenderOptions,
    ) -> Result<Rendered<Srgb8Image>> {
        let (r, _) = self.render_frame(scene, options, OutputFormat::Srgb8, false)?;
        Ok(r.map(|pixels| pixels.srgb8().expect("asked for")))
    }

    /// The eye depth of the nearest surface at output pixel (x, y) of a
    /// pinhole G-buffer (`--focus-pixel`): the focus distance that makes it
    /// sharp. An error names the pixel when it is outside the image or sees
    /// only background.
    pub fn depth_at_pixel(
        &self,
        scene: &Scene,
        camera: &Camera,
        ssaa: u32,
        x: u32,
        y: u32,
    ) -> Result<f32> {
        if x >= camera.width || y >= camera.height {
            return Err(Error::InvalidArgument(format!(
                "--focus-pixel {x},{y} is outside the {}x{} image",
                camera.width, camera.height
            )));
        }
        let options = RenderOptions {
            camera: *camera,
            method: Method::Pinhole,
            ssaa,
            samples_per_pass: None,
            background: Vec3::ZERO,
        };
        let (_, gbuffer) = self.render_with_gbuffer(scene, &options)?;
        let g = gbuffer.guard;
        let z = gbuffer.eye[((y + g) * gbuffer.width + x + g) as usize][2];
        if !z.is_finite() {
            return Err(Error::InvalidArgument(format!(
                "--focus-pixel {x},{y} sees no point (background)"
            )));
        }
        Ok(z)
    }

    /// Renders one frame of `scene` and also reads back its G-buffer.
    pub fn render_with_gbuffer(
        &self,
        scene: &Scene,
        options: &RenderOptions,
    ) -> Result<(Rendered, HostGBuffer)> {
        let (rendered, gbuffer) =
            self.render_frame(scene, options, OutputFormat::LinearF32, true)?;
        let rendered = rendered.map(|pixels| pixels.linear().expect("asked for"));
        Ok((rendered, gbuffer.expect("asked for")))
    }

    /// The frame: view → G-buffer → method → readback. Everything is
    /// allocated before recording starts; the frame's wall time runs from
    /// the view (the CPU's look at the points) to the output pixels copied to the
    /// host.
    fn render_frame(
        &self,
        scene: &Scene,
        options: &RenderOptions,
        format: OutputFormat,
        keep_gbuffer: bool,
    ) -> Result<(Rendered<Pixels>, Option<HostGBuffer>)> {
        check_ssaa(options.ssaa)?;
        if let Some(s) = options.samples_per_pass {
            check_samples_per_pass(s)?;
        }
        if !scene.vertices.made_on(&self.ctx) {
            return Err(Error::InvalidArgument(
                "the scene was uploaded by a renderer on another device".into(),
            ));
        }
        let started = Instant::now();
        let method = self.methods.get(&options.method);
        let view = self.raster_view(scene, &options.camera, method.as_ref());
        let view_ms = started.elapsed().as_secs_f64() * 1e3;

        let pixels = view.frame.full_width() as u64 * view.frame.full_height() as u64;
        let layers = method.gbuffer_layers();
        let plan = self.gbuffer.plan(
            options.ssaa,
            options.samples_per_pass,
            pixels,
            self.ctx.info.device_local_heap_bytes / 4,
        );
        let peel_samples = self.gbuffer.peel_samples(
            options.ssaa,
            options.samples_per_pass,
            pixels,
            self.ctx.info.device_local_heap_bytes / 4,
        );
        let gbuffer = GBuffer::new(
            &self.ctx,
            &view,
            &plan,
            layers,
            peel_samples,
            options.background,
        )?;
        let dof = method.prepare(&self.ctx, &view.frame)?;
        let readback = Readback::new(&self.ctx, &view.frame, format, keep_gbuffer)?;
        let lens = method.gbuffer_lens();

        let mut frame = Frame::begin(&self.ctx, "frame")?;
        gbuffer.record(
            &mut frame,
            &self.gbuffer,
            &scene.vertices,
            scene.count,
            &lens,
            method.gbuffer_label(),
        );
        let input = gbuffer.output();
        let result = dof.record(&mut frame, &input);
        self.output
            .record(&mut frame, result, &view.frame, format, &readback.result);
        readback.record(&mut frame, &input);
        let mut timings = frame.submit_and_wait()?;

        let copying = Instant::now();
        let (image, host_gbuffer) = readback.read()?;
        timings.wall_ms += view_ms + copying.elapsed().as_secs_f64() * 1e3;
        let rendered = Rendered {
            image,
            timings,
            guard: view.frame.guard,
            samples_per_pass: plan.samples_per_pass,
            counts: dof.counts(),
        };
        Ok((rendered, host_gbuffer))
    }
}

/// The host-visible buffers a frame's results land in: the output pixels
/// (written by the output pass in the file's format, guard band cropped)
/// and, when asked for, the whole G-buffer.
struct Readback {
    view: FrameView,
    format: OutputFormat,
    /// Written by the output pass ([`OutputConvert`]).
    result: Buffer,
    /// Color (rgba16f) and eye depth (rgba32f) of the G-buffer.
    gbuffer: Option<(Buffer, Buffer)>,
}

/// A frame's output pixels as read back.
enum Pixels {
    Linear(LinearImage),
    Srgb8(Srgb8Image),
}

impl Pixels {
    fn linear(self) -> Option<LinearImage> {
        match self {
            Pixels::Linear(image) => Some(image),
            Pixels::Srgb8(_) => None,
        }
    }

    fn srgb8(self) -> Option<Srgb8Image> {
        match self {
            Pixels::Srgb8(image) => Some(image),
            Pixels::Linear(_) => None,
        }
    }
}

impl<I> Rendered<I> {
    /// The same frame with its pixels mapped by `f`.
    pub fn map<J>(self, f: impl FnOnce(I) -> J) -> Rendered<J> {
        Rendered {
            image: f(self.image),
            timings: self.timings,
            guard: self.guard,
            samples_per_pass: self.samples_per_pass,
            counts: self.counts,
        }
    }
}

impl Readback {
    fn new(
        ctx: &Arc<Context>,
        view: &FrameView,
        format: OutputFormat,
        keep_gbuffer: bool,
    ) -> Result<Readback> {
        let host = |name: &str, bytes: u64, usage: vk::BufferUsageFlags| {
            Buffer::new(ctx, name, bytes, usage, MemoryLocation::GpuToCpu)
        };
        let texels = |format: vk::Format| {
            view.full_width() as u64 * view.full_height() as u64 * texel_bytes(format)
        };
        let copied = vk::BufferUsageFlags::TRANSFER_DST;
        let pixels = view.camera.width as u64 * view.camera.height as u64;
        Ok(Readback {
            view: *view,
            format,
            result: host(
                "output",
                format.buffer_bytes(pixels),
                vk::BufferUsageFlags::STORAGE_BUFFER,
            )?,
            gbuffer: match keep_gbuffer {
                true => Some((
                    host("gbuffer color readback", texels(COLOR_FORMAT), copied)?,
                    host("gbuffer eye readback", texels(EYE_FORMAT), copied)?,
                )),
                false => None,
            },
        })
    }

    /// Records the copies of the G-buffer of `input`, when asked for, as
    /// pass `readback`, made visible to the host (the output pass writes
    /// the result).
    fn record<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>) {
        let Some((color, eye)) = &self.gbuffer else {
            return;
        };
        frame.pass("readback", |rec| {
            rec.barriers(&[
                (input.color, Access::COMPUTE_READ_WRITE, Access::COPY_SRC),
                (input.eye, Access::COMPUTE_READ_WRITE, Access::COPY_SRC),
            ]);
            let full = [self.view.full_width(), self.view.full_height()];
            rec.copy_image_to_buffer(input.color, [0, 0], full, color);
            rec.copy_image_to_buffer(input.eye, [0, 0], full, eye);
            rec.memory_barrier(Access::COPY_WRITE, Access::HOST_READ);
        });
    }

    /// Copies the pixels out once the frame has completed.
    fn read(&self) -> Result<(Pixels, Option<HostGBuffer>)> {
        let (width, height) = (self.view.camera.width, self.view.camera.height);
        let pixels = width as usize * height as usize;
        let bytes = host_bytes(&self.result)?;
        let image = match self.format {
            OutputFormat::LinearF32 => Pixels::Linear(LinearImage {
                width,
                height,
                pixels: bytemuck::pod_collect_to_vec(&bytes[..16 * pixels]),
            }),
            OutputFormat::Srgb8 => Pixels::Srgb8(Srgb8Image {
                width,
                height,
                rgb: bytes[..3 * pixels].to_vec(),
            }),
        };
        let gbuffer = match &self.gbuffer {
            Some((color, eye)) => Some(HostGBuffer {
                width: self.view.full_width(),
                height: self.view.full_height(),
                guard: self.view.guard,
                color: rgba16f_texels(host_bytes(color)?),
                eye: bytemuck::pod_collect_to_vec(host_bytes(eye)?),
            }),
            None => None,
        };
        Ok((image, gbuffer))
    }
}

fn host_bytes(buffer: &Buffer) -> Result<&[u8]> {
    buffer
        .mapped()
        .ok_or_else(|| Error::Allocation("readback buffer is not host-visible".into()))
}

/// Decodes tightly packed rgba16f texels.
fn rgba16f_texels(bytes: &[u8]) -> Vec<[f32; 4]> {
    bytes
        .chunks_exact(8)
        .map(|t| std::array::from_fn(|i| f16_to_f32(u16::from_le_bytes([t[2 * i], t[2 * i + 1]]))))
        .collect()
}
