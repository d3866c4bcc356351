//! 3D Gaussian scenes on the device (issue 31): the reference rasterizer's
//! image (crate::gaussians is its CPU reference) through each point of a
//! thin lens, averaged in linear light. Per lens point, one chain of
//! compute passes (docs/ARCHITECTURE.md, "3D Gaussian scenes"):
//!
//! 1. `project` — every Gaussian through the lens point's sheared
//!    projection: 2D centre, conic, colour, depth key, tiles covered;
//! 2. `depth sort` — a stable radix sort of the Gaussians by eye depth;
//! 3. `tile list` — the prefix sum of tiles covered in depth order, then
//!    an entry (tile, Gaussian) per tile covered;
//! 4. `tile sort` — a stable radix sort of the entries by tile (depth
//!    order holds within a tile), then each tile's range;
//! 5. `blend` — a workgroup per 16 × 16 tile composites front to back and
//!    adds the decoded result to the pixel's sum.
//!
//! `pinhole` is one lens point at the centre; `accum` the lens samples of
//! the point methods. The tile list's length is known only on the device:
//! the host sizes it, and when a lens point needs more, the frame is
//! rendered again with room for the most any needed.

use std::sync::Arc;

use ash::vk;
use glam::{Vec2, Vec3};
use gpu_allocator::MemoryLocation;

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gaussians::{covariance, TILE_PX};
use crate::image_io::{linear_to_srgb, LinearImage};
use crate::input::gaussians::GaussianScene;
use crate::passes::layered::{Layered, Slices};
use crate::passes::radix_sort::{
    words_buffer, RadixSort, ScanScratch, SortScratch, SortedIn, NONE,
};
use crate::passes::sample_plan::ssaa_jitter;
use crate::passes::{DofInput, FrameView, GBufferLayer, Window};
use crate::push_constants;
use crate::render::{host_bytes, rgba16f_texels};
use crate::vk::{
    Access, Bind, Binding, Buffer, ComputePipeline, Context, Frame, FrameTimings, Image,
};

static PROJECT_SPIRV: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/gaussian_project.comp.spv"));
static TILES_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gaussian_tiles.comp.spv"));
static BLEND_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gaussian_blend.comp.spv"));
static LAYERS_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gaussian_layers.comp.spv"));

/// Invocations per workgroup of `project` and `tile list` (their
/// `local_size_x`).
const GROUP: u32 = 256;

/// A Gaussian as uploaded (`Gaussian` in `glsl/gaussian.glsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuGaussian {
    /// Centre, activated opacity.
    pub position_opacity: [f32; 4],
    /// Σ: xx, xy, xz, yy.
    pub cov_a: [f32; 4],
    /// Σ: yz, zz, and two unused.
    pub cov_b: [f32; 4],
}

/// Bytes of a projected Gaussian (`Projected` in `glsl/gaussian.glsl`:
/// four 16-byte vectors).
pub const PROJECTED_BYTES: u64 = 64;

push_constants! {
    pub struct ProjectPush {
        pub right: [f32; 4],
        pub up: [f32; 4],
        pub forward: [f32; 4],
        pub lens_world: [f32; 4],
        pub lens: [f32; 2],
        pub f_px: f32,
        pub count: u32,
        pub width: u32,
        pub height: u32,
        pub sh_degree: u32,
        pub sh_stride: u32,
        pub sh_split: u32,
        pub near_z: f32,
    }
}

push_constants! {
    pub struct TilesPush {
        pub stage: u32,
        pub count: u32,
        pub capacity: u32,
        pub grid_x: u32,
        pub entries_index: u32,
    }
}

push_constants! {
    pub struct BlendPush {
        pub background: [f32; 4],
        pub jitter: [f32; 2],
        pub width: u32,
        pub height: u32,
        pub capacity: u32,
        pub entries_index: u32,
        pub lens_u: [f32; 2],
        pub window_origin: [i32; 2],
        pub frame_size: [i32; 2],
        pub cat_eye: f32,
        pub half_cell: f32,
    }
}

push_constants! {
    pub struct LayersPush {
        pub background: [f32; 4],
        pub background_encoded: [f32; 4],
        pub width: u32,
        pub height: u32,
        pub capacity: u32,
        pub entries_index: u32,
        pub layers: u32,
        pub layer_lo: f32,
        pub layer_width: f32,
        pub f_px: f32,
        pub aperture_radius: f32,
        pub focus_distance: f32,
    }
}

/// Chains (lens point × jitter) recorded in one submission.
const CHAINS_PER_SUBMIT: usize = 32;

/// Words of the `counts` buffer: the Gaussians; this lens point's tile
/// entries; the most entries of any lens point so far.
const COUNT_GAUSSIANS: u32 = 0;
const COUNT_ENTRIES: u32 = 1;
const COUNT_WORDS: u64 = 4;

/// A Gaussian scene on the device.
pub struct GpuGaussians {
    /// The centres, for the depth range of a frame.
    centres: Vec<Vec3>,
    gaussians: Buffer,
    /// The SH of Gaussians `..sh_split`, and of the rest: two buffers,
    /// each within the device's binding range.
    sh: Buffer,
    sh_rest: Buffer,
    sh_split: u32,
    count: u32,
    sh_degree: u32,
    sh_stride: u32,
    /// The eye depth at which a centre is culled ([`crate::gaussians::near_z`]).
    near_z: f32,
}

impl GpuGaussians {
    /// Gaussians in the scene.
    pub fn len(&self) -> u32 {
        self.count
    }

    /// Whether the scene has none.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The eye depth at which a centre is culled.
    pub fn near_z(&self) -> f32 {
        self.near_z
    }

    /// How many centres `camera` sees in front of the near plane.
    pub fn in_front(&self, camera: &Camera) -> usize {
        self.front_depths(camera).count()
    }

    /// The eye-depth range of the centres `camera` does not cull (eye
    /// depth above [`GpuGaussians::near_z`], as the projection), None when
    /// it culls all.
    pub fn depths(&self, camera: &Camera) -> Option<(f32, f32)> {
        self.front_depths(camera)
            .fold(None, |range, z| match range {
                None => Some((z, z)),
                Some((lo, hi)) => Some((f32::min(lo, z), f32::max(hi, z))),
            })
    }

    /// The eye depths of the centres `camera` does not cull.
    fn front_depths<'a>(&'a self, camera: &Camera) -> impl Iterator<Item = f32> + 'a {
        let eye_from_world = camera.eye_from_world_transform();
        let near_z = self.near_z;
        self.centres
            .iter()
            .map(move |p| eye_from_world.apply(*p).z)
            .filter(move |z| *z > near_z)
    }
}

/// A frame's result: linear-light RGBA (alpha 1: the background is
/// composited), its timings, and the longest tile list of its lens points.
pub struct GaussianFrame {
    pub image: LinearImage,
    pub timings: FrameTimings,
    pub entries: u32,
    /// Frames rendered again because a tile list outgrew its buffer.
    pub retries: u32,
    /// Pixels rendered beyond each side of the image (`layered`'s guard
    /// band; 0 for the others).
    pub guard: u32,
}

/// The pipelines, and the tile list's capacity learnt from past frames.
pub struct GaussianRenderer {
    ctx: Arc<Context>,
    project: ComputePipeline<ProjectPush>,
    tiles: ComputePipeline<TilesPush>,
    blend: ComputePipeline<BlendPush>,
    layers: ComputePipeline<LayersPush>,
    layered: Layered,
    sort: RadixSort,
    capacity: std::sync::atomic::AtomicU32,
    /// At most this many Gaussians' SH in the first buffer (tests of the
    /// split; None: as many as the device binds).
    sh_split_limit: Option<usize>,
    /// `layered`'s depth layers, where a test sets them.
    layer_count: Option<u32>,
}

/// The largest buffer a shader may bind, in 32-bit words.
fn max_words(ctx: &Context) -> u64 {
    ctx.info.max_storage_buffer_range / 4
}

impl GaussianRenderer {
    pub fn new(ctx: &Arc<Context>) -> Result<GaussianRenderer> {
        let b = Binding::StorageBuffer;
        Ok(GaussianRenderer {
            ctx: ctx.clone(),
            project: ComputePipeline::new(ctx, "gaussian_project", PROJECT_SPIRV, &[b; 7])?,
            tiles: ComputePipeline::new(ctx, "gaussian_tiles", TILES_SPIRV, &[b; 8])?,
            blend: ComputePipeline::new(ctx, "gaussian_blend", BLEND_SPIRV, &[b; 5])?,
            layers: ComputePipeline::new(ctx, "gaussian_layers", LAYERS_SPIRV, &{
                let mut bindings = [Binding::StorageImage; 4 + 2 * MAX_LAYERS as usize];
                bindings[..4].fill(b);
                bindings
            })?,
            layered: Layered::new(
                ctx,
                crate::passes::kernel_sizes::KernelSizes::for_device(&ctx.info),
            )?,
            sort: RadixSort::new(ctx)?,
            capacity: std::sync::atomic::AtomicU32::new(0),
            sh_split_limit: None,
            layer_count: None,
        })
    }

    /// `layered`'s passes with more than one cut of their work in the form
    /// of `sizes` instead of the device's own
    /// ([`crate::passes::kernel_sizes::KernelSizes::for_device`]), as the
    /// test that the forms agree renders.
    pub fn set_kernel_sizes(
        &mut self,
        sizes: crate::passes::kernel_sizes::KernelSizes,
    ) -> Result<()> {
        self.layered = Layered::new(&self.ctx, sizes)?;
        Ok(())
    }

    /// Puts the SH of at most `limit` Gaussians in the first of the two
    /// SH buffers (where the device's binding range does not already): to
    /// test the split on small scenes.
    pub fn set_sh_split_limit(&mut self, limit: usize) {
        self.sh_split_limit = Some(limit);
    }

    /// Makes `layered` take `count` depth layers over the frame's CoC
    /// range (at most [`MAX_LAYERS`]): to test many layers without blur.
    pub fn set_layer_count(&mut self, count: u32) {
        self.layer_count = Some(count);
    }

    /// The device it renders on.
    pub fn ctx(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// Uploads `scene`: its centres, opacities and covariances (computed
    /// here, as the CPU reference computes them), and its SH coefficients.
    /// An error names what does not fit the device's buffers.
    pub fn upload(&self, scene: &GaussianScene) -> Result<GpuGaussians> {
        let ctx = &self.ctx;
        let n = scene.len() as u64;
        let too_many = |what: &str, bytes: u64| {
            Error::InvalidArgument(format!(
                "{n} Gaussians need {what} of {} MiB, more than this device binds ({} MiB)",
                bytes >> 20,
                ctx.info.max_storage_buffer_range >> 20
            ))
        };
        // The largest per-Gaussian buffer: a projected Gaussian.
        if n * PROJECTED_BYTES > ctx.info.max_storage_buffer_range {
            return Err(too_many("a buffer", n * PROJECTED_BYTES));
        }
        if n > (u32::MAX / 2) as u64 || n.div_ceil(GROUP as u64) > 65535 {
            return Err(Error::InvalidArgument(format!(
                "{n} Gaussians are more than one frame dispatches"
            )));
        }
        let gaussians: Vec<GpuGaussian> = (0..scene.len())
            .map(|g| {
                let s = covariance(scene, g);
                let p = scene.positions[g];
                GpuGaussian {
                    position_opacity: [p.x, p.y, p.z, scene.opacities[g]],
                    cov_a: [s.x_axis.x, s.y_axis.x, s.z_axis.x, s.y_axis.y],
                    cov_b: [s.z_axis.y, s.z_axis.z, 0.0, 0.0],
                }
            })
            .collect();
        let sh_bytes = 4 * scene.sh.len() as u64;
        let stride = 3 * scene.coefficients();
        let per_buffer = (ctx.info.max_storage_buffer_range / (4 * stride as u64)) as usize;
        if sh_bytes > 2 * per_buffer as u64 * 4 * stride as u64 {
            return Err(too_many("SH coefficients", sh_bytes));
        }
        let split = scene
            .len()
            .min(per_buffer)
            .min(self.sh_split_limit.unwrap_or(usize::MAX));
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let upload = |name: &str, bytes: &[u8]| -> Result<Buffer> {
            // A buffer is never empty.
            let bytes = if bytes.is_empty() {
                &[0u8; 16][..]
            } else {
                bytes
            };
            Buffer::with_bytes(ctx, name, bytes, usage)
        };
        Ok(GpuGaussians {
            near_z: crate::gaussians::near_z(&scene.positions),
            centres: scene.positions.clone(),
            gaussians: upload("gaussians", bytemuck::cast_slice(&gaussians))?,
            sh: upload(
                "gaussian sh",
                bytemuck::cast_slice(&scene.sh[..split * stride]),
            )?,
            sh_rest: upload(
                "gaussian sh rest",
                bytemuck::cast_slice(&scene.sh[split * stride..]),
            )?,
            sh_split: split as u32,
            count: n as u32,
            sh_degree: scene.sh_degree,
            sh_stride: 3 * scene.coefficients() as u32,
        })
    }

    /// Renders `scene` through `camera` from the lens points `R · u` for
    /// each `u` of `lens` (points of the unit disk; `[0, 0]` alone is the
    /// pinhole image), each at the K × K sub-pixel positions of `ssaa`
    /// (the cell centres of [`ssaa_jitter`]; 1: the pixel centre, as the
    /// reference rasterizer samples) over `background` (linear light): the
    /// mean of their images in linear light, each lens point weighed per
    /// pixel by the camera's cat's eye ([`crate::camera::Aperture::cat_eye_weight`]).
    pub fn render(
        &self,
        scene: &GpuGaussians,
        camera: &Camera,
        lens: &[Vec2],
        ssaa: u32,
        background: Vec3,
    ) -> Result<GaussianFrame> {
        assert!(ssaa >= 1, "at least one sample a pixel");
        assert!(!lens.is_empty(), "at least one lens point");
        // The lens cell each lens point stands for (its cat's-eye weight).
        let half_cell = crate::camera::Aperture::lens_cell_half_width(lens.len() as u32);
        let samples: Vec<(Vec2, Vec2)> = lens
            .iter()
            .flat_map(|&u| (0..ssaa * ssaa).map(move |s| (u, ssaa_jitter(s, ssaa))))
            .collect();
        self.with_room(scene, |capacity| {
            self.render_with(scene, camera, &samples, half_cell, background, capacity)
        })
    }

    /// Runs `render` with a tile list of the capacity learnt so far, and
    /// again with more room while a chain needed more (`render` returns
    /// the frame and the most entries any chain needed).
    fn with_room(
        &self,
        scene: &GpuGaussians,
        mut render: impl FnMut(u32) -> Result<(GaussianFrame, u32)>,
    ) -> Result<GaussianFrame> {
        use std::sync::atomic::Ordering::Relaxed;
        // Entries: what a buffer binds, and what the sort dispatches in the
        // fewest workgroups any device allows (65,535 blocks of 4,096).
        let limit = max_words(&self.ctx)
            .min(u32::MAX as u64 / 2)
            .min(65_535 * crate::passes::radix_sort::BLOCK as u64) as u32;
        let mut capacity = self
            .capacity
            .load(Relaxed)
            .max(4 * scene.count)
            .clamp(1 << 16, limit);
        let mut retries = 0;
        loop {
            let (frame, entries) = render(capacity)?;
            self.capacity.fetch_max(entries.min(limit), Relaxed);
            if entries <= capacity {
                return Ok(GaussianFrame { retries, ..frame });
            }
            if entries > limit {
                return Err(Error::InvalidArgument(format!(
                    "the Gaussians cover {entries} tiles of {TILE_PX} × {TILE_PX} pixels, \
                     more than this device's buffers hold ({limit}); render fewer pixels"
                )));
            }
            // Room for the most any lens point needed, and an eighth more.
            capacity = (entries + entries / 8).min(limit);
            retries += 1;
        }
    }

    /// Records the chain of one lens point `u` (unit disk) through
    /// `camera` into `chain`'s buffers, up to the sorted tile list: the
    /// projected Gaussians and each tile's range of the returned values.
    fn record_chain<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        scene: &'r GpuGaussians,
        chain: &'r Chain,
        camera: &Camera,
        u: Vec2,
    ) -> &'r Buffer {
        let n = scene.count;
        let push = project_push(scene, chain, camera, u);
        frame.pass("gaussians: project", |rec| {
            let binds = [
                Bind::StorageBuffer(&scene.gaussians),
                Bind::StorageBuffer(&scene.sh),
                Bind::StorageBuffer(&chain.projected),
                Bind::StorageBuffer(&chain.depth_keys),
                Bind::StorageBuffer(&chain.order),
                Bind::StorageBuffer(&chain.touched),
                Bind::StorageBuffer(&scene.sh_rest),
            ];
            // The previous lens point's passes read what this writes.
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
            rec.dispatch(
                &self.project,
                &binds,
                &push,
                [n.div_ceil(GROUP).max(1), 1, 1],
            );
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
        });
        let at = frame.pass("gaussians: depth sort", |rec| {
            self.sort.record_sort(
                rec,
                &chain.depth_keys,
                &chain.order,
                &chain.depth_scratch,
                &chain.counts,
                COUNT_GAUSSIANS,
                n,
                32,
            )
        });
        let depth_order = match at {
            SortedIn::Input => &chain.order,
            SortedIn::Scratch => &chain.depth_scratch.values,
        };
        self.record_tiles(frame, chain, depth_order, n)
    }

    /// Records the tile stages of a chain of `n` Gaussians whose depth
    /// order is in `depth_order`: the tile list, its sort and each tile's
    /// range. The buffer that holds the sorted entries' values.
    fn record_tiles<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        chain: &'r Chain,
        depth_order: &'r Buffer,
        n: u32,
    ) -> &'r Buffer {
        let tiles_push = |stage| TilesPush {
            stage,
            count: n,
            capacity: chain.capacity,
            grid_x: chain.grid.0,
            entries_index: COUNT_ENTRIES,
        };
        frame.pass("gaussians: tile list", |rec| {
            self.sort.record_scan(
                rec,
                &chain.touched,
                Some(depth_order),
                &chain.offsets,
                &chain.scan_scratch,
                &chain.counts,
                n,
                NONE,
                COUNT_ENTRIES,
            );
            let binds = [
                Bind::StorageBuffer(&chain.projected),
                Bind::StorageBuffer(depth_order),
                Bind::StorageBuffer(&chain.touched),
                Bind::StorageBuffer(&chain.offsets),
                Bind::StorageBuffer(&chain.tile_keys),
                Bind::StorageBuffer(&chain.tile_values),
                Bind::StorageBuffer(&chain.ranges),
                Bind::StorageBuffer(&chain.counts),
            ];
            rec.dispatch(
                &self.tiles,
                &binds,
                &tiles_push(0),
                [n.div_ceil(GROUP).max(1), 1, 1],
            );
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
        });
        let at = frame.pass("gaussians: tile sort", |rec| {
            self.sort.record_sort(
                rec,
                &chain.tile_keys,
                &chain.tile_values,
                &chain.tile_scratch,
                &chain.counts,
                COUNT_ENTRIES,
                chain.capacity,
                chain.tile_bits,
            )
        });
        let (keys, values) = match at {
            SortedIn::Input => (&chain.tile_keys, &chain.tile_values),
            SortedIn::Scratch => (&chain.tile_scratch.keys, &chain.tile_scratch.values),
        };
        frame.pass("gaussians: tile ranges", |rec| {
            // The previous lens point's blend read the ranges.
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::FILL);
            rec.fill_u32(&chain.ranges, 0);
            rec.memory_barrier(Access::FILL, Access::COMPUTE_READ_WRITE);
            let binds = [
                Bind::StorageBuffer(&chain.projected),
                Bind::StorageBuffer(depth_order),
                Bind::StorageBuffer(&chain.touched),
                Bind::StorageBuffer(&chain.offsets),
                Bind::StorageBuffer(keys),
                Bind::StorageBuffer(values),
                Bind::StorageBuffer(&chain.ranges),
                Bind::StorageBuffer(&chain.counts),
            ];
            let groups = chain.capacity.div_ceil(GROUP).clamp(1, 65535);
            rec.dispatch(&self.tiles, &binds, &tiles_push(1), [groups, 1, 1]);
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
        });
        values
    }

    /// One try with a tile list of `capacity` entries, a chain per (lens
    /// point, jitter) of `samples` (each lens point a lens cell of
    /// half-width `half_cell`): the frame and the most entries any chain
    /// needed.
    fn render_with(
        &self,
        scene: &GpuGaussians,
        camera: &Camera,
        samples: &[(Vec2, Vec2)],
        half_cell: f32,
        background: Vec3,
        capacity: u32,
    ) -> Result<(GaussianFrame, u32)> {
        let ctx = &self.ctx;
        let (width, height) = (camera.width, camera.height);
        let chain = Chain::new(ctx, scene.count, capacity, width, height)?;
        let pixels = width as u64 * height as u64;
        let sum = words_buffer(ctx, "gaussian sum", 4 * pixels)?;
        let sum_readback = readback(ctx, "gaussian sum readback", 16 * pixels)?;
        let background_encoded = background.to_array().map(linear_to_srgb);
        // A submission per CHAINS_PER_SUBMIT chains (any --samples and
        // --ssaa stay within one command buffer's reach), the sums and
        // counts carried from one to the next.
        let mut timings = FrameTimings::default();
        let batches: Vec<&[(Vec2, Vec2)]> = samples.chunks(CHAINS_PER_SUBMIT).collect();
        for (k, batch) in batches.iter().enumerate() {
            let mut frame = Frame::begin(ctx, "gaussians")?;
            if k == 0 {
                frame.pass("clear", |rec| {
                    rec.update_u32(&chain.counts, &[scene.count, 0, 0, 0]);
                    rec.fill_u32(&sum, 0);
                    rec.memory_barrier(Access::FILL, Access::COMPUTE_READ_WRITE);
                });
            }
            for &(u, jitter) in batch.iter() {
                let values = self.record_chain(&mut frame, scene, &chain, camera, u);
                frame.pass("gaussians: blend", |rec| {
                    let binds = [
                        Bind::StorageBuffer(&chain.projected),
                        Bind::StorageBuffer(values),
                        Bind::StorageBuffer(&chain.ranges),
                        Bind::StorageBuffer(&chain.counts),
                        Bind::StorageBuffer(&sum),
                    ];
                    let push = BlendPush {
                        background: [
                            background_encoded[0],
                            background_encoded[1],
                            background_encoded[2],
                            0.0,
                        ],
                        jitter: jitter.to_array(),
                        width,
                        height,
                        capacity,
                        entries_index: COUNT_ENTRIES,
                        // The lens point in pixel axes: y turns over.
                        lens_u: [u.x, -u.y],
                        window_origin: [0, 0],
                        frame_size: [width as i32, height as i32],
                        cat_eye: camera.aperture.cat_eye,
                        half_cell,
                    };
                    rec.dispatch(&self.blend, &binds, &push, [chain.grid.0, chain.grid.1, 1]);
                });
            }
            if k + 1 == batches.len() {
                frame.pass("readback", |rec| {
                    rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COPY_SRC);
                    rec.copy_buffer(&sum, &sum_readback);
                    rec.copy_buffer(&chain.counts, &chain.counts_readback);
                    rec.memory_barrier(Access::COPY_WRITE, Access::HOST_READ);
                });
            }
            timings.merge(&frame.submit_and_wait()?);
        }
        let sums: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(host_bytes(&sum_readback)?);
        // Alpha: the sum of the lens points' weights (their count, exactly,
        // where each weighs 1).
        let image = LinearImage {
            width,
            height,
            pixels: sums
                .iter()
                .map(|s| {
                    let scale = 1.0 / s[3];
                    [s[0] * scale, s[1] * scale, s[2] * scale, 1.0]
                })
                .collect(),
        };
        let entries = chain.most_entries()?;
        Ok((
            GaussianFrame {
                image,
                timings,
                entries,
                retries: 0,
                guard: 0,
            },
            entries,
        ))
    }

    /// Renders `scene` through `camera` with the layered method (issue 31;
    /// docs/ARCHITECTURE.md, "3D Gaussian scenes"): the pinhole chain over
    /// the frame and a guard band, its Gaussians composited in depth
    /// layers of equal signed-CoC width (at most [`MAX_LAYERS`]), each layer
    /// as a G-buffer layer of premultiplied colour, coverage and depth, then
    /// the point method's spreading and back-to-front composite.
    pub fn render_layered(
        &self,
        scene: &GpuGaussians,
        camera: &Camera,
        background: Vec3,
    ) -> Result<GaussianFrame> {
        let depths = scene.depths(camera);
        self.with_room(scene, |capacity| {
            self.render_layered_with(scene, depths, camera, background, capacity)
        })
    }

    fn render_layered_with(
        &self,
        scene: &GpuGaussians,
        depths: Option<(f32, f32)>,
        camera: &Camera,
        background: Vec3,
        capacity: u32,
    ) -> Result<(GaussianFrame, u32)> {
        let ctx = &self.ctx;
        let max_coc_px = depths.map_or(0.0, |(lo, hi)| camera.max_coc_px(lo, hi));
        let guard = camera.guard_band_px(max_coc_px, 0.0);
        let view = FrameView {
            camera: *camera,
            window: Window::whole(camera),
            guard,
            max_coc_px,
            depths,
        };
        let (width, height) = (view.full_width(), view.full_height());
        // The frame with its guard band: the same focal length in pixels.
        let big = Camera {
            width,
            height,
            fovy_deg: 2.0 * (height as f32 / (2.0 * camera.f_px())).atan().to_degrees(),
            ..*camera
        };
        let chain = Chain::new(ctx, scene.count, capacity, width, height)?;
        let layers = gaussian_layers(camera, depths, self.layer_count);
        let gbuffer = layer_images(ctx, layers.count, width, height)?;
        let dof = self.layered.prepare_gaussian_layers(ctx, &view, layers)?;
        let result_readback = readback(
            ctx,
            "gaussian layered readback",
            8 * camera.width as u64 * camera.height as u64,
        )?;
        let mut frame = Frame::begin(ctx, "gaussians layered")?;
        frame.pass("clear", |rec| {
            rec.update_u32(&chain.counts, &[scene.count, 0, 0, 0]);
            rec.memory_barrier(Access::FILL, Access::COMPUTE_READ_WRITE);
        });
        let values = self.record_chain(&mut frame, scene, &chain, &big, Vec2::ZERO);
        frame.pass("gaussians: layers", |rec| {
            let images: Vec<_> = gbuffer
                .iter()
                .flat_map(|l| {
                    [
                        (&l.color, Access::NONE, Access::COMPUTE_WRITE),
                        (&l.eye, Access::NONE, Access::COMPUTE_WRITE),
                    ]
                })
                .collect();
            rec.barriers(&images);
            let mut binds = vec![
                Bind::StorageBuffer(&chain.projected),
                Bind::StorageBuffer(values),
                Bind::StorageBuffer(&chain.ranges),
                Bind::StorageBuffer(&chain.counts),
            ];
            // Layers past the last bound to the first's images, unwritten.
            let layer = |l: usize| &gbuffer[if l < gbuffer.len() { l } else { 0 }];
            binds.extend((0..MAX_LAYERS as usize).map(|l| Bind::StorageImage(&layer(l).color)));
            binds.extend((0..MAX_LAYERS as usize).map(|l| Bind::StorageImage(&layer(l).eye)));
            let push = layers_push(camera, background, &layers, (width, height), capacity);
            rec.dispatch(&self.layers, &binds, &push, [chain.grid.0, chain.grid.1, 1]);
        });
        let input = DofInput {
            color: &gbuffer[0].color,
            eye: &gbuffer[0].eye,
            layers: &gbuffer,
            background,
            view,
        };
        let result = dof.record(&mut frame, &input);
        frame.pass("readback", |rec| {
            rec.barriers(&[(result, Access::COMPUTE_READ_WRITE, Access::COPY_SRC)]);
            rec.copy_image_to_buffer(
                result,
                [guard, guard],
                [camera.width, camera.height],
                &result_readback,
            );
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COPY_SRC);
            rec.copy_buffer(&chain.counts, &chain.counts_readback);
            rec.memory_barrier(Access::COPY_WRITE, Access::HOST_READ);
        });
        let timings = frame.submit_and_wait()?;
        let bytes = host_bytes(&result_readback)?;
        let image = LinearImage {
            width: camera.width,
            height: camera.height,
            pixels: rgba16f_texels(bytes)
                .into_iter()
                // Signed layers may leave a rounding below zero.
                .map(|c| [c[0].max(0.0), c[1].max(0.0), c[2].max(0.0), 1.0])
                .collect(),
        };
        let entries = chain.most_entries()?;
        Ok((
            GaussianFrame {
                image,
                timings,
                entries,
                retries: 0,
                guard,
            },
            entries,
        ))
    }
}

/// The push constants of `project` for lens point `u` (unit disk) of
/// `camera`: its basis and eye, the lens point in the world, and the
/// scene's count and SH layout.
fn project_push(scene: &GpuGaussians, chain: &Chain, camera: &Camera, u: Vec2) -> ProjectPush {
    let (right, up, forward) = camera.basis();
    let eye = camera.eye;
    let l = camera.aperture_radius * u;
    let lens_world = eye + right * l.x + up * l.y;
    ProjectPush {
        right: right.extend(eye.x).to_array(),
        up: up.extend(eye.y).to_array(),
        forward: forward.extend(eye.z).to_array(),
        lens_world: lens_world.extend(camera.focus_distance).to_array(),
        lens: l.to_array(),
        f_px: camera.f_px(),
        count: scene.count,
        width: chain.width,
        height: chain.height,
        sh_degree: scene.sh_degree,
        sh_stride: scene.sh_stride,
        sh_split: scene.sh_split,
        near_z: scene.near_z,
    }
}

/// The images of `count` G-buffer layers of `width` × `height` (the
/// frame with its guard band): premultiplied colour and coverage, and eye
/// position.
fn layer_images(
    ctx: &Arc<Context>,
    count: u32,
    width: u32,
    height: u32,
) -> Result<Vec<GBufferLayer>> {
    let storage = vk::ImageUsageFlags::STORAGE;
    (0..count)
        .map(|_| {
            Ok(GBufferLayer {
                color: Image::new_2d(
                    ctx,
                    "gaussian layer",
                    vk::Format::R16G16B16A16_SFLOAT,
                    width,
                    height,
                    1,
                    storage,
                )?,
                eye: Image::new_2d(
                    ctx,
                    "gaussian layer eye",
                    vk::Format::R32G32B32A32_SFLOAT,
                    width,
                    height,
                    1,
                    storage,
                )?,
            })
        })
        .collect()
}

/// The push constants of the `layers` pass (the Gaussians composited
/// into depth layers): `camera`'s lens, `background`, the layers' signed
/// CoC range, the frame's size with its guard band and a tile list of
/// `capacity` entries.
fn layers_push(
    camera: &Camera,
    background: Vec3,
    layers: &Slices,
    (width, height): (u32, u32),
    capacity: u32,
) -> LayersPush {
    LayersPush {
        background: background.extend(0.0).to_array(),
        background_encoded: [
            linear_to_srgb(background.x),
            linear_to_srgb(background.y),
            linear_to_srgb(background.z),
            0.0,
        ],
        width,
        height,
        capacity,
        entries_index: COUNT_ENTRIES,
        layers: layers.count,
        layer_lo: layers.lo,
        layer_width: layers.width,
        f_px: camera.f_px(),
        aperture_radius: camera.aperture_radius,
        focus_distance: camera.focus_distance,
    }
}

/// The most depth layers of the layered method on Gaussians: the point
/// method's most peeled layers ([`crate::options::check_layers`]).
pub const MAX_LAYERS: u32 = 8;

/// The depth layers of a frame of Gaussians centred at eye depths
/// `depths`: layers of equal signed-CoC width, nearest first, as the point
/// method's slices ([`Slices::of`]) but at most [`MAX_LAYERS`]; each is one
/// slice of the layered method; `count` layers over the same range instead
/// where given (tests).
pub fn gaussian_layers(camera: &Camera, depths: Option<(f32, f32)>, count: Option<u32>) -> Slices {
    let slices = Slices::of(camera, depths);
    let count = count.unwrap_or(slices.count).clamp(1, MAX_LAYERS);
    Slices {
        count,
        lo: slices.lo,
        width: slices.width * slices.count as f32 / count as f32,
    }
}

/// The buffers of one chain (per lens point) of `count` Gaussians into a
/// `width` × `height` frame with a tile list of `capacity` entries.
struct Chain {
    width: u32,
    height: u32,
    grid: (u32, u32),
    tile_bits: u32,
    capacity: u32,
    projected: Buffer,
    depth_keys: Buffer,
    order: Buffer,
    touched: Buffer,
    offsets: Buffer,
    depth_scratch: SortScratch,
    scan_scratch: ScanScratch,
    tile_keys: Buffer,
    tile_values: Buffer,
    tile_scratch: SortScratch,
    ranges: Buffer,
    counts: Buffer,
    counts_readback: Buffer,
}

impl Chain {
    fn new(ctx: &Arc<Context>, n: u32, capacity: u32, width: u32, height: u32) -> Result<Chain> {
        let grid = (
            width.div_ceil(TILE_PX as u32),
            height.div_ceil(TILE_PX as u32),
        );
        let tiles = grid.0 * grid.1;
        if 16 * width as u64 * height as u64 > ctx.info.max_storage_buffer_range {
            return Err(Error::InvalidArgument(format!(
                "a {width} × {height} image of Gaussians is more than this device binds in one buffer"
            )));
        }
        let gpu_words = |name: &str, words: u64| words_buffer(ctx, name, words);
        Ok(Chain {
            width,
            height,
            grid,
            tile_bits: 32 - (tiles.max(2) - 1).leading_zeros(),
            capacity,
            projected: gpu_words("gaussians projected", n as u64 * PROJECTED_BYTES / 4)?,
            depth_keys: gpu_words("gaussian depth keys", n as u64)?,
            order: gpu_words("gaussian order", n as u64)?,
            touched: gpu_words("gaussian tiles touched", n as u64)?,
            offsets: gpu_words("gaussian tile offsets", n as u64)?,
            depth_scratch: SortScratch::new(ctx, "gaussian depth sort", n)?,
            scan_scratch: ScanScratch::new(ctx, "gaussian tile offset blocks", n)?,
            tile_keys: gpu_words("gaussian tile keys", capacity as u64)?,
            tile_values: gpu_words("gaussian tile values", capacity as u64)?,
            tile_scratch: SortScratch::new(ctx, "gaussian tile sort", capacity)?,
            ranges: gpu_words("gaussian tile ranges", 2 * tiles as u64)?,
            counts: gpu_words("gaussian counts", COUNT_WORDS)?,
            counts_readback: readback(ctx, "gaussian counts readback", 4 * COUNT_WORDS)?,
        })
    }

    /// After the frame: the most tile entries any lens point needed.
    fn most_entries(&self) -> Result<u32> {
        let counts: Vec<u32> = bytemuck::pod_collect_to_vec(host_bytes(&self.counts_readback)?);
        Ok(counts[COUNT_ENTRIES as usize + 1])
    }
}

/// A host-visible buffer of `bytes` that copies write.
fn readback(ctx: &Arc<Context>, name: &str, bytes: u64) -> Result<Buffer> {
    Buffer::new(
        ctx,
        name,
        bytes,
        vk::BufferUsageFlags::TRANSFER_DST,
        MemoryLocation::GpuToCpu,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    #[test]
    fn layouts_match_the_glsl() {
        check_push_layout::<ProjectPush>("gaussian_project", PROJECT_SPIRV).unwrap();
        check_push_layout::<TilesPush>("gaussian_tiles", TILES_SPIRV).unwrap();
        check_push_layout::<BlendPush>("gaussian_blend", BLEND_SPIRV).unwrap();
        check_push_layout::<LayersPush>("gaussian_layers", LAYERS_SPIRV).unwrap();
        assert!(include_str!("../glsl/gaussian_layers.comp")
            .contains(&format!("const uint MAX_LAYERS = {MAX_LAYERS}u;")));
        assert!(crate::options::check_layers(MAX_LAYERS).is_ok());
        assert!(crate::options::check_layers(MAX_LAYERS + 1).is_err());
        assert_eq!(std::mem::size_of::<GpuGaussian>(), 48);
        let glsl = include_str!("../glsl/gaussian.glsl");
        assert!(glsl.contains("vec4 position_opacity;\n    vec4 cov_a;"));
        assert!(glsl.contains(&format!("const int TILE_PX = {TILE_PX};")));
        // Projected: four 16-byte members.
        let members = [
            "vec4 centre_depth;",
            "vec4 conic_opacity;",
            "vec4 color;",
            "ivec4 tiles;",
        ];
        assert!(members.iter().all(|m| glsl.contains(m)));
        assert_eq!(PROJECTED_BYTES, 16 * members.len() as u64);
        for shader in [
            include_str!("../glsl/gaussian_project.comp"),
            include_str!("../glsl/gaussian_tiles.comp"),
        ] {
            assert!(shader.contains(&format!("layout(local_size_x = {GROUP}) in;")));
        }
    }
}
