//! The frame, as one readable chain: upload → G-buffer (K×K raster samples,
//! resolved) → DOF method → readback.

use std::str::FromStr;
use std::sync::Arc;

use ash::vk;
use glam::Vec3;
use gpu_allocator::MemoryLocation;

use crate::camera::lens_samples;
use crate::camera::Camera;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::gbuffer::{clip_range, depth_range, pinhole_samples, GBuffer, RasterView, Sample};
use crate::image_io::{f16_to_f32, LinearImage};
use crate::passes::fast::{Fast, FastImages, FastWeights, GatherWindow};
use crate::passes::gbuffer_resolve::GBufferResolve;
use crate::passes::rdb::{Rdb, RdbImages, RdbMode};
use crate::passes::splat_raster::{SplatRaster, SplatVertex};
use crate::vk::{
    image_barriers, memory_barrier, slice_as_bytes, Access, Buffer, Context, Frame, FrameTimings,
    Image,
};

/// A splat's default world diameter is this multiple of its local point
/// spacing (mean distance to its 8 nearest neighbours): it closes the bunny's
/// surface without fattening edges. Scans with depth-quantised rows (the
/// PCL stereo scan) keep some holes; `--splat-size` / `--splat-px` cover them.
pub const SPACING_TO_DIAMETER: f32 = 1.0;

/// The depth-of-field methods of DESIGN §8.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// No depth of field: the resolved G-buffer color.
    Pinhole,
    /// Zhao's fast approximation: a z-tested gather bounded by tile CoCs
    /// (DESIGN §4).
    Fast(FastWeights, GatherWindow),
    /// The ray distribution buffer (DESIGN §5): N×N lens bins per pixel.
    Rdb(u32, RdbMode),
    /// The accumulation-buffer reference (DESIGN §7): the splats rendered
    /// through `samples` lens positions with the sheared projection, each
    /// sample anti-aliased like the G-buffer, averaged in linear light.
    Accum,
}

/// The method names DESIGN §8 lists that this build does not implement yet.
const PLANNED_METHODS: [&str; 1] = ["layered"];

impl Method {
    /// The names of the methods this build implements.
    pub const AVAILABLE: [&'static str; 4] = ["pinhole", "fast", "rdb", "accum"];
}

impl FromStr for Method {
    type Err = Error;
    fn from_str(s: &str) -> Result<Method> {
        let available = Method::AVAILABLE.join(", ");
        match s {
            "pinhole" => Ok(Method::Pinhole),
            "accum" => Ok(Method::Accum),
            "fast" => Ok(Method::Fast(FastWeights::Area, GatherWindow::Tiles)),
            "rdb" => Ok(Method::Rdb(9, RdbMode::Centre)),
            s if PLANNED_METHODS.contains(&s) => Err(Error::InvalidArgument(format!(
                "method '{s}' is not implemented yet; available methods: {available}"
            ))),
            s => Err(Error::InvalidArgument(format!(
                "unknown method '{s}'; available methods: {available}"
            ))),
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
    pub method: Method,
    /// K: the G-buffer takes K×K samples per pixel.
    pub ssaa: u32,
    /// Linear-light background color.
    pub background: Vec3,
    /// Lens samples of `accum` (DESIGN §7; default 256).
    pub samples: u32,
    /// Memory for the bins of `rdb`, bytes; above it the frame is processed
    /// in tiles. None: a quarter of the largest device-local heap.
    pub rdb_memory_bytes: Option<u64>,
}

/// A cloud on the GPU: its splats, and what the CPU needs to frame them.
pub struct Scene {
    vertices: Buffer,
    count: u32,
    positions: Vec<Vec3>,
    /// World diameters (unused when `splat` is `Pixels`).
    diameters: Vec<f32>,
    splat: SplatSize,
    /// GPU time of the upload copy.
    pub upload_timings: FrameTimings,
    /// Wall time of computing the splat sizes on the CPU (the k-nearest
    /// neighbour spacing for `SplatSize::Spacing`), milliseconds.
    pub splat_sizes_ms: f64,
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
}

/// The result of a frame: the image without guard band, and its timings.
pub struct Rendered {
    pub image: LinearImage,
    pub timings: FrameTimings,
    /// The guard band the frame was rendered with, pixels.
    pub guard: u32,
}

/// The largest CoC a G-buffer pixel can have: a point's in `range`, or the
/// background's (the surface at infinity).
fn max_gbuffer_coc(camera: &Camera, range: Option<(f32, f32)>) -> f32 {
    let background = camera.coc_px(f32::INFINITY);
    range.map_or(background, |(lo, hi)| {
        camera.max_coc_px(lo, hi).max(background)
    })
}

/// Owns the pipelines; renders any number of frames of any scene.
pub struct Renderer {
    ctx: Arc<Context>,
    raster: SplatRaster,
    resolve: GBufferResolve,
    fast: Fast,
    rdb: Rdb,
}

fn unorm16(c: f32) -> u16 {
    (c.clamp(0.0, 1.0) * 65535.0 + 0.5) as u16
}

impl Renderer {
    pub fn new(ctx: &Arc<Context>) -> Result<Renderer> {
        Ok(Renderer {
            ctx: ctx.clone(),
            raster: SplatRaster::new(ctx)?,
            resolve: GBufferResolve::new(ctx)?,
            fast: Fast::new(ctx)?,
            rdb: Rdb::new(ctx)?,
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
        let started = std::time::Instant::now();
        let diameters: Vec<f32> = match splat {
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
        };
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
        let bytes = slice_as_bytes(&vertices);
        let size = bytes.len() as u64;
        let mut staging = Buffer::new(
            &self.ctx,
            "splat staging",
            size,
            vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::CpuToGpu,
        )?;
        staging
            .mapped_mut()
            .ok_or_else(|| Error::Allocation("splat staging buffer is not host-visible".into()))?
            .copy_from_slice(bytes);
        let vertex_buffer = Buffer::new(
            &self.ctx,
            "splats",
            size,
            vk::BufferUsageFlags::VERTEX_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuOnly,
        )?;
        let mut frame = Frame::begin(&self.ctx, "upload")?;
        frame.pass("upload", |ctx, cmd| {
            let region = vk::BufferCopy {
                src_offset: 0,
                dst_offset: 0,
                size,
            };
            // SAFETY: both buffers are `size` bytes and alive until the
            // frame completes (submit_and_wait below).
            unsafe {
                ctx.device
                    .cmd_copy_buffer(cmd, staging.raw, vertex_buffer.raw, &[region])
            };
            // Makes the copy visible to every later vertex fetch, in this
            // and later submissions.
            memory_barrier(
                ctx,
                cmd,
                (
                    vk::PipelineStageFlags2::COPY,
                    vk::AccessFlags2::TRANSFER_WRITE,
                ),
                (
                    vk::PipelineStageFlags2::VERTEX_ATTRIBUTE_INPUT,
                    vk::AccessFlags2::VERTEX_ATTRIBUTE_READ,
                ),
            );
        });
        let upload_timings = frame.submit_and_wait()?;
        drop(staging);
        Ok(Scene {
            vertices: vertex_buffer,
            count,
            positions: cloud.positions.clone(),
            diameters,
            splat,
            upload_timings,
            splat_sizes_ms,
        })
    }

    /// The raster view of `scene` through `camera`: depth range, splat rule
    /// and a guard band for the blur of `method` (DESIGN §3).
    pub fn raster_view(&self, scene: &Scene, camera: &Camera, method: Method) -> RasterView {
        let range = depth_range(camera, &scene.positions);
        let (near, far) = clip_range(range);
        // Background pixels are a uniform color and do not move with the
        // lens, so only the points' CoCs widen the guard band.
        let max_coc_px = match method {
            Method::Pinhole => 0.0,
            Method::Accum => range.map_or(0.0, |(lo, hi)| camera.max_coc_px(lo, hi)),
            Method::Fast(..) | Method::Rdb(..) => max_gbuffer_coc(camera, range),
        };
        let max_point = self.ctx.info.point_size_max;
        let f_px = camera.f_px();
        let (splat_px, max_splat_px) = match scene.splat {
            SplatSize::Pixels(p) => (p, p.min(max_point)),
            _ => {
                let mut m = 1.0f32;
                for (p, d) in scene.positions.iter().zip(&scene.diameters) {
                    let z = camera.eye_from_world(*p).z;
                    if z >= near {
                        m = m.max(f_px * d / z);
                    }
                }
                (0.0, m.min(max_point))
            }
        };
        RasterView {
            camera: *camera,
            guard: Camera::guard_band_px(max_coc_px, max_splat_px),
            max_coc_px,
            near,
            far,
            splat_px,
            max_point_size: max_point,
        }
    }

    /// Renders one frame of `scene`.
    pub fn render(&self, scene: &Scene, options: &RenderOptions) -> Result<Rendered> {
        self.render_frame(scene, options, false).map(|(r, _)| r)
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
            background: Vec3::ZERO,
            samples: 1,
            rdb_memory_bytes: None,
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
        let (rendered, gbuffer) = self.render_frame(scene, options, true)?;
        Ok((rendered, gbuffer.expect("asked for")))
    }

    fn render_frame(
        &self,
        scene: &Scene,
        options: &RenderOptions,
        keep_gbuffer: bool,
    ) -> Result<(Rendered, Option<HostGBuffer>)> {
        if options.ssaa == 0 || options.ssaa > 16 {
            return Err(Error::InvalidArgument(format!(
                "--ssaa must be between 1 and 16, not {}",
                options.ssaa
            )));
        }
        if options.method == Method::Accum && options.samples == 0 {
            return Err(Error::InvalidArgument(
                "--samples must be at least 1".to_string(),
            ));
        }
        let camera = &options.camera;
        let view = self.raster_view(scene, camera, options.method);
        let gbuffer = GBuffer::new(&self.ctx, &view)?;
        let (w, h) = (camera.width, camera.height);
        let host = |name: &str, width: u32, height: u32, texel: u64| {
            Buffer::new(
                &self.ctx,
                name,
                width as u64 * height as u64 * texel,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
            )
        };
        // rgba16f result; the G-buffer's rgba16f color and rgba32f eye position.
        let readback = host("readback", w, h, 8)?;
        let (gw, gh) = (gbuffer.color.width, gbuffer.color.height);
        let gbuffer_readback = match keep_gbuffer {
            true => Some((
                host("gbuffer color readback", gw, gh, 8)?,
                host("gbuffer eye readback", gw, gh, 16)?,
            )),
            false => None,
        };

        // The method's images too are made before recording starts, so that
        // a frame's wall time (recording to readable result) excludes every
        // allocation, whatever the method.
        let fast_images = match options.method {
            Method::Fast(..) => Some(FastImages::new(&self.ctx, &gbuffer)?),
            _ => None,
        };
        let rdb_images = match options.method {
            Method::Rdb(bins, _) => {
                let budget = options
                    .rdb_memory_bytes
                    .unwrap_or(self.ctx.info.device_local_heap_bytes / 4);
                Some(RdbImages::new(&self.ctx, &gbuffer, bins, budget)?)
            }
            _ => None,
        };

        let mut frame = Frame::begin(&self.ctx, "frame")?;
        let (samples, label) = match options.method {
            Method::Pinhole | Method::Fast(..) | Method::Rdb(..) => {
                (pinhole_samples(options.ssaa), "gbuffer")
            }
            Method::Accum => {
                let jitters = pinhole_samples(options.ssaa);
                let samples: Vec<Sample> = lens_samples(options.samples)
                    .into_iter()
                    .flat_map(|u| {
                        jitters.iter().map(move |j| Sample {
                            jitter: j.jitter,
                            lens_u: u,
                        })
                    })
                    .collect();
                (samples, "accum")
            }
        };
        gbuffer.record(
            &mut frame,
            &self.raster,
            &self.resolve,
            &scene.vertices,
            scene.count,
            &samples,
            options.background,
            label,
        );
        if let (Method::Fast(weights, window), Some(images)) = (options.method, &fast_images) {
            let max_coc = view.max_coc_px;
            self.fast.record(
                &mut frame, &gbuffer, images, camera, weights, window, max_coc,
            );
        }
        if let (Method::Rdb(_, mode), Some(images)) = (options.method, &rdb_images) {
            self.rdb.record(&mut frame, &gbuffer, images, camera, mode);
        }
        // Pinhole and accum: the color the samples resolved to.
        let result = match (&fast_images, &rdb_images) {
            (Some(f), _) => &f.result,
            (_, Some(r)) => &r.result,
            _ => &gbuffer.color,
        };
        frame.pass("readback", |ctx, cmd| {
            let mut images = vec![result];
            if gbuffer_readback.is_some() && !std::ptr::eq(result, &gbuffer.color) {
                images.push(&gbuffer.color);
            }
            if gbuffer_readback.is_some() {
                images.push(&gbuffer.eye);
            }
            let list: Vec<_> = images
                .iter()
                .map(|i| (*i, Access::COMPUTE_READ_WRITE, Access::COPY_SRC))
                .collect();
            image_barriers(ctx, cmd, &list);
            let g = view.guard;
            copy_to_host(ctx, cmd, result, [g, g], [w, h], &readback);
            if let Some((color, eye)) = &gbuffer_readback {
                copy_to_host(ctx, cmd, &gbuffer.color, [0, 0], [gw, gh], color);
                copy_to_host(ctx, cmd, &gbuffer.eye, [0, 0], [gw, gh], eye);
            }
            memory_barrier(
                ctx,
                cmd,
                (
                    vk::PipelineStageFlags2::COPY,
                    vk::AccessFlags2::TRANSFER_WRITE,
                ),
                (vk::PipelineStageFlags2::HOST, vk::AccessFlags2::HOST_READ),
            );
        });
        let mut timings = frame.submit_and_wait()?;

        let started = std::time::Instant::now();
        let pixels = rgba16f_texels(host_bytes(&readback)?);
        timings.wall_ms += started.elapsed().as_secs_f64() * 1e3;
        let rendered = Rendered {
            image: LinearImage {
                width: w,
                height: h,
                pixels,
            },
            timings,
            guard: view.guard,
        };
        let host_gbuffer = match &gbuffer_readback {
            Some((color, eye)) => Some(HostGBuffer {
                width: gw,
                height: gh,
                guard: view.guard,
                color: rgba16f_texels(host_bytes(color)?),
                eye: host_bytes(eye)?
                    .chunks_exact(16)
                    .map(|t| {
                        std::array::from_fn(|i| {
                            f32::from_le_bytes([t[4 * i], t[4 * i + 1], t[4 * i + 2], t[4 * i + 3]])
                        })
                    })
                    .collect(),
            }),
            None => None,
        };
        Ok((rendered, host_gbuffer))
    }
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
    /// Eye position (DESIGN §2's eye space; z = +inf for background),
    /// w = coverage.
    pub eye: Vec<[f32; 4]>,
}

/// The bytes of a host-visible readback buffer.
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

/// Records a copy of the `extent` region at `offset` of a color image in
/// `TRANSFER_SRC_OPTIMAL` layout into `buffer`, tightly packed.
fn copy_to_host(
    ctx: &Context,
    cmd: vk::CommandBuffer,
    image: &Image,
    offset: [u32; 2],
    extent: [u32; 2],
    buffer: &Buffer,
) {
    let region = vk::BufferImageCopy {
        buffer_offset: 0,
        buffer_row_length: 0,
        buffer_image_height: 0,
        image_subresource: vk::ImageSubresourceLayers {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            mip_level: 0,
            base_array_layer: 0,
            layer_count: 1,
        },
        image_offset: vk::Offset3D {
            x: offset[0] as i32,
            y: offset[1] as i32,
            z: 0,
        },
        image_extent: vk::Extent3D {
            width: extent[0],
            height: extent[1],
            depth: 1,
        },
    };
    // SAFETY: the caller's region lies inside the image and the buffer holds
    // extent[0]·extent[1] texels of the image's format.
    unsafe {
        ctx.device.cmd_copy_image_to_buffer(
            cmd,
            image.raw,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            buffer.raw,
            &[region],
        )
    };
}
