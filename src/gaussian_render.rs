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
use crate::passes::radix_sort::{
    words_buffer, RadixSort, ScanScratch, SortScratch, SortedIn, NONE,
};
use crate::passes::sample_plan::ssaa_jitter;
use crate::push_constants;
use crate::vk::{Access, Bind, Binding, Buffer, ComputePipeline, Context, Frame, FrameTimings};

static PROJECT_SPIRV: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/gaussian_project.comp.spv"));
static TILES_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gaussian_tiles.comp.spv"));
static BLEND_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/gaussian_blend.comp.spv"));

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
    }
}

/// Words of the `counts` buffer: the Gaussians; this lens point's tile
/// entries; the most entries of any lens point so far.
const COUNT_GAUSSIANS: u32 = 0;
const COUNT_ENTRIES: u32 = 1;
const COUNT_WORDS: u64 = 4;

/// A Gaussian scene on the device.
pub struct GpuGaussians {
    gaussians: Buffer,
    sh: Buffer,
    count: u32,
    sh_degree: u32,
    sh_stride: u32,
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
}

/// A frame's result: linear-light RGBA (alpha 1: the background is
/// composited), its timings, and the longest tile list of its lens points.
pub struct GaussianFrame {
    pub image: LinearImage,
    pub timings: FrameTimings,
    pub entries: u32,
    /// Frames rendered again because a tile list outgrew its buffer.
    pub retries: u32,
}

/// The pipelines, and the tile list's capacity learnt from past frames.
pub struct GaussianRenderer {
    ctx: Arc<Context>,
    project: ComputePipeline<ProjectPush>,
    tiles: ComputePipeline<TilesPush>,
    blend: ComputePipeline<BlendPush>,
    sort: RadixSort,
    capacity: std::sync::atomic::AtomicU32,
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
            project: ComputePipeline::new(ctx, "gaussian_project", PROJECT_SPIRV, &[b; 6])?,
            tiles: ComputePipeline::new(ctx, "gaussian_tiles", TILES_SPIRV, &[b; 8])?,
            blend: ComputePipeline::new(ctx, "gaussian_blend", BLEND_SPIRV, &[b; 5])?,
            sort: RadixSort::new(ctx)?,
            capacity: std::sync::atomic::AtomicU32::new(0),
        })
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
        if sh_bytes > ctx.info.max_storage_buffer_range {
            return Err(too_many("SH coefficients", sh_bytes));
        }
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
            gaussians: upload("gaussians", bytemuck::cast_slice(&gaussians))?,
            sh: upload("gaussian sh", bytemuck::cast_slice(&scene.sh))?,
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
    /// mean of their images in linear light.
    pub fn render(
        &self,
        scene: &GpuGaussians,
        camera: &Camera,
        lens: &[Vec2],
        ssaa: u32,
        background: Vec3,
    ) -> Result<GaussianFrame> {
        assert!(ssaa >= 1, "at least one sample a pixel");
        let samples: Vec<(Vec2, Vec2)> = lens
            .iter()
            .flat_map(|&u| (0..ssaa * ssaa).map(move |s| (u, ssaa_jitter(s, ssaa))))
            .collect();
        use std::sync::atomic::Ordering::Relaxed;
        assert!(!lens.is_empty(), "at least one lens point");
        let limit = max_words(&self.ctx).min(u32::MAX as u64 / 2) as u32;
        let mut capacity = self
            .capacity
            .load(Relaxed)
            .max(4 * scene.count)
            .clamp(1 << 16, limit);
        let mut retries = 0;
        loop {
            let (frame, entries) =
                self.render_with(scene, camera, &samples, background, capacity)?;
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

    /// One try with a tile list of `capacity` entries, a chain per (lens
    /// point, jitter) of `samples`: the frame and the most entries any
    /// chain needed.
    fn render_with(
        &self,
        scene: &GpuGaussians,
        camera: &Camera,
        samples: &[(Vec2, Vec2)],
        background: Vec3,
        capacity: u32,
    ) -> Result<(GaussianFrame, u32)> {
        let ctx = &self.ctx;
        let n = scene.count;
        let (width, height) = (camera.width, camera.height);
        let grid = (
            width.div_ceil(TILE_PX as u32),
            height.div_ceil(TILE_PX as u32),
        );
        let tiles = grid.0 * grid.1;
        let pixels = width as u64 * height as u64;
        if 16 * pixels > ctx.info.max_storage_buffer_range {
            return Err(Error::InvalidArgument(format!(
                "a {width} × {height} image of Gaussians is more than this device binds in one buffer"
            )));
        }
        let tile_bits = 32 - (tiles.max(2) - 1).leading_zeros();
        let gpu_words = |name: &str, words: u64| words_buffer(ctx, name, words);
        let projected = gpu_words("gaussians projected", n as u64 * PROJECTED_BYTES / 4)?;
        let depth_keys = gpu_words("gaussian depth keys", n as u64)?;
        let order = gpu_words("gaussian order", n as u64)?;
        let touched = gpu_words("gaussian tiles touched", n as u64)?;
        let offsets = gpu_words("gaussian tile offsets", n as u64)?;
        let depth_scratch = SortScratch::new(ctx, "gaussian depth sort", n)?;
        let scan_scratch = ScanScratch::new(ctx, "gaussian tile offset blocks", n)?;
        let tile_keys = gpu_words("gaussian tile keys", capacity as u64)?;
        let tile_values = gpu_words("gaussian tile values", capacity as u64)?;
        let tile_scratch = SortScratch::new(ctx, "gaussian tile sort", capacity)?;
        let ranges = gpu_words("gaussian tile ranges", 2 * tiles as u64)?;
        let counts = gpu_words("gaussian counts", COUNT_WORDS)?;
        let sum = gpu_words("gaussian sum", 4 * pixels)?;
        let host = |name: &str, bytes: u64| {
            Buffer::new(
                ctx,
                name,
                bytes,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
            )
        };
        let sum_readback = host("gaussian sum readback", 16 * pixels)?;
        let counts_readback = host("gaussian counts readback", 4 * COUNT_WORDS)?;

        let (right, up, forward) = camera.basis();
        let eye = camera.eye;
        let background_encoded = background.to_array().map(linear_to_srgb);
        let mut frame = Frame::begin(ctx, "gaussians")?;
        frame.pass("clear", |rec| {
            rec.update_u32(&counts, &[n, 0, 0, 0]);
            rec.fill_u32(&sum, 0);
            rec.memory_barrier(Access::FILL, Access::COMPUTE_READ_WRITE);
        });
        let sorted_order = |at: SortedIn| match at {
            SortedIn::Input => &order,
            SortedIn::Scratch => &depth_scratch.values,
        };
        let sorted_tiles = |at: SortedIn| match at {
            SortedIn::Input => (&tile_keys, &tile_values),
            SortedIn::Scratch => (&tile_scratch.keys, &tile_scratch.values),
        };
        for &(u, jitter) in samples {
            let l = camera.aperture_radius * u;
            let lens_world = eye + right * l.x + up * l.y;
            let push = ProjectPush {
                right: right.extend(eye.x).to_array(),
                up: up.extend(eye.y).to_array(),
                forward: forward.extend(eye.z).to_array(),
                lens_world: lens_world.extend(camera.focus_distance).to_array(),
                lens: l.to_array(),
                f_px: camera.f_px(),
                count: n,
                width,
                height,
                sh_degree: scene.sh_degree,
                sh_stride: scene.sh_stride,
            };
            frame.pass("gaussians: project", |rec| {
                let binds = [
                    Bind::StorageBuffer(&scene.gaussians),
                    Bind::StorageBuffer(&scene.sh),
                    Bind::StorageBuffer(&projected),
                    Bind::StorageBuffer(&depth_keys),
                    Bind::StorageBuffer(&order),
                    Bind::StorageBuffer(&touched),
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
                    &depth_keys,
                    &order,
                    &depth_scratch,
                    &counts,
                    COUNT_GAUSSIANS,
                    n,
                    32,
                )
            });
            let depth_order = sorted_order(at);
            frame.pass("gaussians: tile list", |rec| {
                self.sort.record_scan(
                    rec,
                    &touched,
                    Some(depth_order),
                    &offsets,
                    &scan_scratch,
                    &counts,
                    n,
                    NONE,
                    COUNT_ENTRIES,
                );
                let binds = [
                    Bind::StorageBuffer(&projected),
                    Bind::StorageBuffer(depth_order),
                    Bind::StorageBuffer(&touched),
                    Bind::StorageBuffer(&offsets),
                    Bind::StorageBuffer(&tile_keys),
                    Bind::StorageBuffer(&tile_values),
                    Bind::StorageBuffer(&ranges),
                    Bind::StorageBuffer(&counts),
                ];
                let push = TilesPush {
                    stage: 0,
                    count: n,
                    capacity,
                    grid_x: grid.0,
                    entries_index: COUNT_ENTRIES,
                };
                rec.dispatch(&self.tiles, &binds, &push, [n.div_ceil(GROUP).max(1), 1, 1]);
                rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
            });
            let at = frame.pass("gaussians: tile sort", |rec| {
                self.sort.record_sort(
                    rec,
                    &tile_keys,
                    &tile_values,
                    &tile_scratch,
                    &counts,
                    COUNT_ENTRIES,
                    capacity,
                    tile_bits,
                )
            });
            let (keys, values) = sorted_tiles(at);
            frame.pass("gaussians: blend", |rec| {
                // The previous lens point's blend read the ranges.
                rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::FILL);
                rec.fill_u32(&ranges, 0);
                rec.memory_barrier(Access::FILL, Access::COMPUTE_READ_WRITE);
                let binds = [
                    Bind::StorageBuffer(&projected),
                    Bind::StorageBuffer(depth_order),
                    Bind::StorageBuffer(&touched),
                    Bind::StorageBuffer(&offsets),
                    Bind::StorageBuffer(keys),
                    Bind::StorageBuffer(values),
                    Bind::StorageBuffer(&ranges),
                    Bind::StorageBuffer(&counts),
                ];
                let push = TilesPush {
                    stage: 1,
                    count: n,
                    capacity,
                    grid_x: grid.0,
                    entries_index: COUNT_ENTRIES,
                };
                let groups = capacity.div_ceil(GROUP).clamp(1, 65535);
                rec.dispatch(&self.tiles, &binds, &push, [groups, 1, 1]);
                rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ_WRITE);
                let binds = [
                    Bind::StorageBuffer(&projected),
                    Bind::StorageBuffer(values),
                    Bind::StorageBuffer(&ranges),
                    Bind::StorageBuffer(&counts),
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
                };
                rec.dispatch(&self.blend, &binds, &push, [grid.0, grid.1, 1]);
            });
        }
        frame.pass("readback", |rec| {
            rec.memory_barrier(Access::COMPUTE_READ_WRITE, Access::COPY_SRC);
            rec.copy_buffer(&sum, &sum_readback);
            rec.copy_buffer(&counts, &counts_readback);
            rec.memory_barrier(Access::COPY_WRITE, Access::HOST_READ);
        });
        let timings = frame.submit_and_wait()?;
        let mapped = |b: &Buffer| {
            b.mapped()
                .map(|m| m.to_vec())
                .ok_or_else(|| Error::Allocation("readback buffer is not host-visible".into()))
        };
        let counts: Vec<u32> = bytemuck::pod_collect_to_vec(&mapped(&counts_readback)?);
        let sums: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&mapped(&sum_readback)?);
        let scale = 1.0 / samples.len() as f32;
        let image = LinearImage {
            width,
            height,
            pixels: sums
                .iter()
                .map(|s| [s[0] * scale, s[1] * scale, s[2] * scale, 1.0])
                .collect(),
        };
        let entries = counts[COUNT_ENTRIES as usize + 1];
        Ok((
            GaussianFrame {
                image,
                timings,
                entries,
                retries: 0,
            },
            entries,
        ))
    }
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
