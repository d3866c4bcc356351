//! The frame, as one readable chain (docs/ARCHITECTURE.md, "The frame"):
//! view → G-buffer (K×K raster samples, resolved) → depth-of-field method →
//! readback, in `Renderer::render_frame`.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use ash::vk;
use glam::Vec3;
use gpu_allocator::MemoryLocation;

use crate::camera::Camera;
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::gbuffer::{clip_range, depth_range_with, GBuffer, GBufferPasses, PeelPlan, RasterView};
use crate::host_gbuffer::HostGBuffer;
use crate::image_io::{f16_to_f32, LinearImage, Srgb8Image};
use crate::options::{
    check_lod, check_samples_per_pass, check_ssaa, Coverage, EdlOptions, Lod, Method, Raster,
    SplatShape,
};
use crate::passes::edl::Edl;
use crate::passes::output::{OutputBuffers, OutputConvert, OutputFormat};
use crate::passes::sample_plan::SamplePlan;
use crate::passes::splat_raster::{SplatVertex, COLOR_FORMAT, EYE_FORMAT};
use crate::passes::{DofInput, DofMethod, FrameView, Methods, VeilRule, Window};
use crate::report::{LodReport, Upload};
use crate::tree::{self, LeafSize, Points, Splat, SplatTree, Widening};
use crate::veil::{Veil, VeilSplat};
use crate::vk::{texel_bytes, Access, Buffer, Context, Frame, FrameTimings};

/// A splat's default world diameter is this multiple of its local point
/// spacing (mean distance to its 8 nearest neighbours): it closes the bunny's
/// surface without fattening edges. Scans with depth-quantised rows (the
/// PCL stereo scan) keep some holes; `--splat-size` / `--splat-px` cover them.
pub const SPACING_TO_DIAMETER: f32 = 1.0;

/// Every point's world diameter under `splat` (DESIGN §3) from the exact
/// k-nearest-neighbour spacing ([`tree::exact_spacing`]):
/// `SPACING_TO_DIAMETER` × local spacing (the cloud's median spacing where
/// a point's is 0), W for `World(W)`, and 0 for `Pixels` (sized on the
/// GPU). The renderer sizes splats from the tree ([`SplatTree`]); this is
/// the reference the tests compare it with ([`Renderer::upload_sized`]).
pub fn splat_diameters(cloud: &PointCloud, splat: SplatSize) -> Vec<f32> {
    match splat {
        SplatSize::World(w) => vec![w; cloud.len()],
        SplatSize::Pixels(_) => vec![0.0; cloud.len()],
        SplatSize::Spacing => {
            let spacing = tree::exact_spacing(&cloud.positions, crate::available_threads());
            let fallback = tree::median(spacing.clone());
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

impl SplatSize {
    /// The splat hierarchy's rule for its leaves' world diameters:
    /// `SPACING_TO_DIAMETER` × the tree's local spacing, W, or 0 (splats
    /// sized in pixels on the GPU).
    pub fn leaf_size(self) -> LeafSize<'static> {
        match self {
            SplatSize::Spacing => LeafSize::SpacingTimes(SPACING_TO_DIAMETER),
            SplatSize::World(w) => LeafSize::World(w),
            SplatSize::Pixels(_) => LeafSize::Zero,
        }
    }
}

/// The splat hierarchy [`Renderer::upload`] builds for `cloud` under
/// `splat`, on `threads` threads (e.g. to export the splats it draws).
pub fn splat_tree(cloud: &PointCloud, splat: SplatSize, threads: usize) -> SplatTree {
    SplatTree::build(points_of(cloud), splat.leaf_size(), threads)
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
    /// Level of detail of the splat hierarchy (`--lod-px`, `--lod-blur`).
    pub lod: Lod,
}

/// What the CPU knows about a scene seen through one camera: the eye-depth
/// range of its splats and its largest splat in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SceneView {
    depths: Option<(f32, f32)>,
    max_splat_px: f32,
}

/// The splats of one camera on the GPU (what the traversal emitted) and
/// what the CPU measured of them.
struct FrameSplats {
    /// At least one vertex long (an empty frame draws none of it).
    vertices: Buffer,
    count: u32,
    view: SceneView,
    lod: LodReport,
    /// The splats too near the lens for the G-buffer ([`crate::veil`]),
    /// composited by the output pass: at least one long (the pass reads
    /// `veil.splats_in_view.len()` of them).
    veil_splats: Buffer,
    veil: Veil,
}

/// What selected a frame's splats: the camera, the LOD rule, what the
/// frustum is widened by, and the point-size limit.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SplatsKey {
    camera: Camera,
    lod: Lod,
    widening: Widening,
    point_size_max: f32,
    /// Which splats the method takes out of its G-buffer into the veil.
    veil: VeilRule,
}

/// A cloud ready to render: its splat hierarchy (DESIGN §3) on the host;
/// each frame's splats go to the GPU after the traversal.
pub struct Scene {
    tree: SplatTree,
    splat: SplatSize,
    ctx: Arc<Context>,
    /// The last frame's splats: frames of one camera traverse once.
    last: Mutex<Option<(SplatsKey, Arc<FrameSplats>)>>,
    /// The tree's build (splat sizes included). Not part of any frame.
    pub upload: Upload,
}

/// A cloud's splat hierarchy built on the host, before any device
/// exists; [`Renderer::upload_built`] makes it a [`Scene`].
pub struct BuiltTree {
    tree: SplatTree,
    splat: SplatSize,
}

impl BuiltTree {
    /// The hierarchy of a cloud it takes, splats sized by `splat`: the
    /// cloud is dropped as soon as the hierarchy holds its points (the
    /// peak memory of a cloud read whole).
    pub fn build_owned(cloud: PointCloud, splat: SplatSize) -> Result<BuiltTree> {
        check_point_count(cloud.len())?;
        let threads = crate::available_threads();
        let tree = SplatTree::build_owned(cloud, points_of, splat.leaf_size(), threads);
        Ok(BuiltTree { tree, splat })
    }
}

/// Refuses a cloud of more points than a splat's 32-bit index holds.
fn check_point_count(points: usize) -> Result<()> {
    u32::try_from(points)
        .map(drop)
        .map_err(|_| Error::InvalidArgument(format!("{points} points exceed 2^32")))
}

impl Scene {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.tree.len()
    }

    /// Whether the scene has no points.
    pub fn is_empty(&self) -> bool {
        self.tree.is_empty()
    }

    /// The splat hierarchy.
    pub fn tree(&self) -> &SplatTree {
        &self.tree
    }

    /// The splats of a frame through `key.camera`: the traversal's, with
    /// their depth range and largest splat (splats nearer than the clip
    /// range's near plane do not count towards the size), on the GPU; from
    /// the cache when the key is the last one.
    fn splats(&self, key: SplatsKey) -> Result<(Arc<FrameSplats>, LodReport)> {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((k, s)) = &*last {
            if *k == key {
                let lod = LodReport {
                    traversal_ms: 0.0,
                    splats_upload_ms: 0.0,
                    cached: true,
                    ..s.lod
                };
                return Ok((s.clone(), lod));
            }
        }
        // Free the last camera's buffer before making the next one.
        *last = None;
        let camera = &key.camera;
        let threads = crate::available_threads();
        let mut traversal = self.tree.traverse(camera, key.lod, key.widening, threads);
        let started = Instant::now();
        let splat_px = match self.splat {
            SplatSize::Pixels(p) => Some(p),
            _ => None,
        };
        let (drawn, veil) = crate::veil::split(
            camera,
            std::mem::take(&mut traversal.splats),
            key.veil,
            splat_px,
            self.tree.color_scale(),
        );
        traversal.splats = drawn;
        let view = self.scene_view(camera, &traversal.splats, key.point_size_max);
        let (vertices, count) = self.upload_vertices(&traversal.splats)?;
        let veiled_splats = veil.splats;
        let veil_splats = self.upload_veil(&veil)?;
        let splats = Arc::new(FrameSplats {
            vertices,
            count,
            veil_splats,
            veil,
            view,
            lod: LodReport {
                lod_px: key.lod.px,
                lod_blur: key.lod.blur,
                cull_back_faces: key.lod.cull_back_faces,
                nodes_visited: traversal.nodes_visited,
                splats_emitted: count as u64,
                inner_emitted: traversal.inner_emitted,
                veiled: veiled_splats,
                traversal_ms: traversal.ms,
                splats_upload_ms: started.elapsed().as_secs_f64() * 1e3,
                cached: false,
            },
        });
        *last = Some((key, splats.clone()));
        let lod = splats.lod;
        Ok((splats, lod))
    }

    /// The eye-depth range of `splats` through `camera` and their largest
    /// splat in pixels (those nearer than the clip range's near plane do
    /// not count), at most `point_size_max`: each a least or a greatest,
    /// taken over runs of the splats on every core (the same values in
    /// any order).
    fn scene_view(&self, camera: &Camera, splats: &[Splat], point_size_max: f32) -> SceneView {
        let eye_from_world = camera.eye_from_world_transform();
        let runs: Vec<&[Splat]> = splats.chunks(SCENE_VIEW_RUN).collect();
        let threads = crate::available_threads();
        let depths = crate::parallel_map(&runs, threads, |run| {
            depth_range_with(&eye_from_world, run.iter().map(Splat::centre))
        })
        .into_iter()
        .flatten()
        .reduce(|(lo, hi), (l, h)| (lo.min(l), hi.max(h)));
        let (near, _) = clip_range(depths);
        let max_splat_px = match self.splat {
            SplatSize::Pixels(p) => p.min(point_size_max),
            _ => {
                let f_px = camera.f_px();
                let widest = |run: &&[Splat]| {
                    let mut m = 1.0f32;
                    for v in *run {
                        let z = eye_from_world.apply(v.centre()).z;
                        if z >= near {
                            m = m.max(f_px * v.position_size[3] / z);
                        }
                    }
                    m
                };
                let m = crate::parallel_map(&runs, threads, widest)
                    .into_iter()
                    .fold(1.0f32, f32::max);
                warn_of_splats_wider_than(camera, m);
                m.min(point_size_max)
            }
        };
        SceneView {
            depths,
            max_splat_px,
        }
    }

    /// The frame's `splats` in a vertex buffer on the GPU (one empty
    /// vertex where there is none), and their count; an error where they
    /// are more than a buffer of the device holds.
    fn upload_vertices(&self, splats: &[Splat]) -> Result<(Buffer, u32)> {
        let count = u32::try_from(splats.len()).map_err(|_| {
            Error::InvalidArgument(format!(
                "{} splats in one frame exceed 2^32; raise --lod-px",
                splats.len()
            ))
        })?;
        let bytes: &[u8] = if splats.is_empty() {
            bytemuck::bytes_of(&EMPTY_VERTEX)
        } else {
            bytemuck::cast_slice(vertices_of(splats))
        };
        // A buffer larger than one allocation or than the device's memory
        // may not be made (lavapipe crashed on 2.4 GB in a 2 GiB heap
        // instead of failing).
        let info = &self.ctx.info;
        let limit = info
            .max_memory_allocation_bytes
            .min(info.device_local_heap_bytes);
        if bytes.len() as u64 > limit {
            return Err(Error::Allocation(format!(
                "{count} splats ({} MiB) exceed what the device can hold in one buffer \
                 ({} MiB); raise --lod-px (0 draws every point)",
                bytes.len() >> 20,
                limit >> 20
            )));
        }
        let vertices = Buffer::with_bytes(
            &self.ctx,
            "splats",
            bytes,
            // Also read as a storage buffer by the peel's cull.
            vk::BufferUsageFlags::VERTEX_BUFFER | vk::BufferUsageFlags::STORAGE_BUFFER,
        )
        .map_err(|e| {
            Error::Allocation(format!(
                "{count} splats ({} MiB) do not fit in device-visible memory ({e}); \
                 raise --lod-px",
                bytes.len() >> 20
            ))
        })?;
        Ok((vertices, count))
    }

    /// The veil's splats in a storage buffer on the GPU (one empty splat
    /// where there is none); an error where they are more than the
    /// device's largest storage buffer.
    fn upload_veil(&self, veil: &Veil) -> Result<Buffer> {
        let info = &self.ctx.info;
        let veil_bytes = std::mem::size_of_val(veil.splats_in_view.as_slice()) as u64;
        if veil_bytes > info.max_storage_buffer_range {
            return Err(Error::InvalidArgument(format!(
                "{} splats at the lens ({} MiB) exceed the device's largest storage buffer \
                 ({} MiB); raise --lod-px or --lod-blur",
                veil.splats_in_view.len(),
                veil_bytes >> 20,
                info.max_storage_buffer_range >> 20
            )));
        }
        Buffer::with_bytes(
            &self.ctx,
            "veil",
            match veil.is_empty() {
                true => bytemuck::bytes_of(&EMPTY_VEIL),
                false => bytemuck::cast_slice(&veil.splats_in_view),
            },
            vk::BufferUsageFlags::STORAGE_BUFFER,
        )
    }
}

/// The points of `cloud` as the splat hierarchy takes them.
fn points_of(cloud: &PointCloud) -> Points<'_> {
    Points {
        positions: &cloud.positions,
        colors: &cloud.colors,
        normals: cloud.normals.as_deref(),
    }
}

/// The hierarchy's splats as the raster's vertices: the same 24 bytes
/// (position and diameter as 4 × f32, color and normal as 4 × u16; a test
/// checks every field's offset), so the frame's splats reach the vertex
/// buffer without a conversion.
pub fn vertices_of(splats: &[Splat]) -> &[SplatVertex] {
    bytemuck::cast_slice(splats)
}

/// The veil of a frame without one (a buffer is never empty; the output
/// pass reads none of it).
const EMPTY_VEIL: VeilSplat = VeilSplat {
    centre_px: [0.0; 2],
    lens_per_px: 0.0,
    half_side: 0.0,
    color: [0.0; 4],
};

/// The vertex of a frame that emits none (a buffer is never empty).
const EMPTY_VERTEX: SplatVertex = SplatVertex {
    position_size: [0.0; 4],
    color: [0; 4],
};

/// The result of a frame: the image without guard band, and its timings.
pub struct Rendered<I = LinearImage> {
    /// The output pixels: linear f32 ([`Renderer::render`]) or 8-bit sRGB
    /// ([`Renderer::render_srgb8`]).
    pub image: I,
    pub timings: FrameTimings,
    /// The guard band the frame was rendered with, pixels.
    pub guard: u32,
    /// Samples of a pixel per G-buffer raster pass (K² for the upscaled
    /// plan, S for multisampled passes, 1 for the one-sample form).
    pub samples_per_pass: u32,
    /// What the method counted ([`crate::passes::DofFrame::counts`]), e.g.
    /// the layered method's kept and discarded pixels per layer.
    pub counts: Vec<(String, u64)>,
    /// The splat hierarchy's work for the frame (zero times when the
    /// frame's splats came from the cache).
    pub lod: LodReport,
}

/// Owns the pipelines; renders any number of frames of any scene.
pub struct Renderer {
    ctx: Arc<Context>,
    gbuffer: GBufferPasses,
    methods: Methods,
    output: OutputConvert,
    /// The most bytes a frame's G-buffer sample targets may take.
    sample_budget_bytes: u64,
    /// Whether a depth peel draws only the splats it can keep
    /// ([`crate::passes::peel_cull`]).
    peel_cull: bool,
    /// How the G-buffer's first layer is rasterised.
    raster: Raster,
    /// The shape the G-buffer's pipelines draw.
    splat_shape: SplatShape,
    /// How the G-buffer weighs the splats within a pixel, if asked
    /// (None: the default, [`Coverage::Area`] where it can act).
    coverage: Option<Coverage>,
    /// Eye-dome lighting of the G-buffer (`--edl`), if asked for.
    edl: Option<EdlOptions>,
    edl_pass: Edl,
    /// At most this many output pixels a side per G-buffer (`--tile-px`).
    tile_px: Option<u32>,
    /// Whether the output pass writes a device-local buffer copied to the
    /// host's (None: where the host's buffer is not device-local).
    staged_output: Option<bool>,
    /// Whether frames take the pipelines made without code they do not
    /// run ([`Renderer::set_specialized_pipelines`]).
    specialized_pipelines: bool,
    /// Whether the marking resolve skips the tiles no splat reaches
    /// ([`Renderer::set_untouched_tiles_skipped`]).
    untouched_tiles_skipped: bool,
}

impl Renderer {
    pub fn new(ctx: &Arc<Context>) -> Result<Renderer> {
        let splat_shape = SplatShape::default();
        Ok(Renderer {
            ctx: ctx.clone(),
            gbuffer: GBufferPasses::new(ctx, splat_shape)?,
            methods: Methods::new(ctx)?,
            output: OutputConvert::new(ctx)?,
            sample_budget_bytes: ctx.info.device_local_heap_bytes / 4,
            peel_cull: true,
            raster: Raster::default(),
            splat_shape,
            coverage: None,
            edl: None,
            edl_pass: Edl::new(ctx)?,
            tile_px: None,
            staged_output: None,
            specialized_pipelines: true,
            untouched_tiles_skipped: true,
        })
    }

    /// The shape splats are drawn with (`--splat-shape`; default square):
    /// remakes the G-buffer's raster pipelines for a new one.
    pub fn set_splat_shape(&mut self, shape: SplatShape) -> Result<()> {
        if shape == self.splat_shape {
            return Ok(());
        }
        if shape == SplatShape::Disc && !self.ctx.info.sample_rate_shading {
            return Err(Error::VulkanSetup(
                "disc splats need per-sample shading (sampleRateShading), which this device lacks"
                    .into(),
            ));
        }
        self.gbuffer = GBufferPasses::new(&self.ctx, shape)?;
        self.gbuffer.set_whole_passes(self.specialized_pipelines);
        self.gbuffer
            .set_untouched_tiles_skipped(self.untouched_tiles_skipped);
        self.splat_shape = shape;
        Ok(())
    }

    /// How the G-buffer weighs the splats within a pixel (`--coverage`;
    /// None: the default, [`Coverage::Area`] where it can act). A frame
    /// where an asked-for area coverage cannot act is an error
    /// ([`crate::options::check_coverage_with`]).
    pub fn set_coverage(&mut self, coverage: Option<Coverage>) {
        self.coverage = coverage;
    }

    /// Whether a G-buffer of `method` drawn by `raster` resolves by area:
    /// asked for (or left to the default) and able to act
    /// ([`crate::options::area_coverage_blocker`]).
    fn area_coverage(&self, raster: Raster, method: &Method) -> bool {
        self.coverage.unwrap_or_default() == Coverage::Area
            && crate::options::area_coverage_blocker(method, Some(raster), Some(self.splat_shape))
                .is_none()
    }

    /// Whether frames take the pipelines made without code they do not
    /// run (the default, true): the round aperture's
    /// ([`crate::passes::Specialized`]), the G-buffer resolve's of a
    /// pass that holds every sample, and the output's without a veil;
    /// false renders every frame with the general pipelines. The same
    /// images, byte for byte, as `tests/aperture.rs` and `tests/output.rs`
    /// check.
    pub fn set_specialized_pipelines(&mut self, enabled: bool) {
        self.specialized_pipelines = enabled;
        self.methods.set_round_pipelines(enabled);
        self.gbuffer.set_whole_passes(enabled);
        self.output.set_unveiled(enabled);
    }

    /// The passes with more than one cut of their work in the form of
    /// `sizes` instead of the device's own
    /// ([`crate::passes::kernel_sizes::KernelSizes::for_device`]): the
    /// same images, as the test that says so renders. A method's
    /// pipelines are made again on its next frame.
    pub fn set_kernel_sizes(&mut self, sizes: crate::passes::kernel_sizes::KernelSizes) {
        self.methods.set_kernel_sizes(sizes);
    }

    /// Eye-dome lighting of the G-buffer's first layer before the
    /// depth-of-field method (`--edl`; None: off). `accum` refuses it: it
    /// averages a G-buffer per lens position and has no one image to shade.
    pub fn set_edl(&mut self, edl: Option<EdlOptions>) {
        self.edl = edl;
    }

    /// How the G-buffer's first layer is rasterised (`--raster`; default
    /// [`Raster::default`]). The compute rasteriser needs 64-bit buffer
    /// atomics: a frame on a device without them is an error.
    pub fn set_raster(&mut self, raster: Raster) {
        self.raster = raster;
    }

    /// The raster of a frame with `samples_per_pass`
    /// ([`crate::options::frame_raster`] on this device).
    fn raster_with(&self, samples_per_pass: Option<u32>) -> Result<Raster> {
        crate::options::frame_raster(
            self.raster,
            samples_per_pass,
            Some(self.ctx.info.buffer_int64_atomics),
        )
    }

    /// K of a frame of `method` with `--ssaa` `ssaa` and
    /// `samples_per_pass`: `ssaa` as given, else the default of the method
    /// and the raster the frame gets ([`crate::options::default_ssaa`]: 1
    /// for accum, else 3 on the compute raster's rotated grid, 4 on the
    /// sprites' grid).
    pub fn ssaa(
        &self,
        ssaa: Option<u32>,
        samples_per_pass: Option<u32>,
        method: &Method,
    ) -> Result<u32> {
        match ssaa {
            Some(k) => Ok(k),
            None => Ok(crate::options::default_ssaa(
                self.raster_with(samples_per_pass)?,
                method,
            )),
        }
    }

    /// Whether each depth peel of `layered` first culls the splats it
    /// cannot keep (default on; the same image bit for bit, fewer splats
    /// drawn: off only to compare).
    pub fn set_peel_cull(&mut self, on: bool) {
        self.peel_cull = on;
    }

    /// Whether the area coverage's marking resolve skips the tiles of
    /// 8 × 8 pixels that no splat reaches, whose windows hold background
    /// alone (default on; the same image bit for bit: off only to compare).
    pub fn set_untouched_tiles_skipped(&mut self, on: bool) {
        self.untouched_tiles_skipped = on;
        self.gbuffer.set_untouched_tiles_skipped(on);
    }

    /// Whether the output pass writes a device-local buffer that a copy
    /// moves into the host-visible one (`Some(true)`), or writes the
    /// host-visible one itself (`Some(false)`); None, the default: staged
    /// where the host-visible buffer is not device-local (a discrete GPU),
    /// direct on lavapipe. The same bytes either way (tested).
    pub fn set_staged_output(&mut self, staged: Option<bool>) {
        self.staged_output = staged;
    }

    /// At most `bytes` for a frame's G-buffer sample
    /// targets (default: a quarter of the device-local heap): a plan whose
    /// targets would be larger takes fewer samples per pass, or bands
    /// (docs/ARCHITECTURE.md, "All K² samples in one pass").
    pub fn set_sample_budget(&mut self, bytes: u64) {
        self.sample_budget_bytes = bytes;
    }

    /// Renders frames in tiles of at most `tile_px` × `tile_px` output
    /// pixels (`--tile-px`; None: the whole frame, or tiles of
    /// [`AUTO_TILE_PX`] where it would not fit the device's images). The
    /// tiles of a frame share its splats, depth range and guard band: the
    /// image is the whole frame's (docs/ARCHITECTURE.md, "Posters in
    /// tiles").
    pub fn set_tile_px(&mut self, tile_px: Option<u32>) {
        self.tile_px = tile_px;
    }

    /// The context the renderer draws with.
    pub fn ctx(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// Builds the cloud's splat hierarchy (splat sizes from the tree's
    /// local spacing under `splat`, DESIGN §3). The splats reach the GPU
    /// per frame, after the traversal.
    pub fn upload(&self, cloud: &PointCloud, splat: SplatSize) -> Result<Scene> {
        self.upload_with(cloud, splat, splat.leaf_size())
    }

    /// [`Renderer::upload`] with each point's world diameter given (in the
    /// cloud's order), e.g. the exact k-nearest-neighbour sizes of
    /// [`splat_diameters`].
    pub fn upload_sized(&self, cloud: &PointCloud, diameters: &[f32]) -> Result<Scene> {
        if diameters.len() != cloud.len() {
            return Err(Error::InvalidArgument(format!(
                "{} diameters for {} points",
                diameters.len(),
                cloud.len()
            )));
        }
        self.upload_with(cloud, SplatSize::Spacing, LeafSize::PerPoint(diameters))
    }

    /// [`Renderer::upload`] with each splat sized from the spacing at most
    /// `max_diameters` (world units, in the cloud's order); sizes `splat`
    /// gives otherwise (`--splat-size`, `--splat-px`) are taken as given.
    pub fn upload_bounded(
        &self,
        cloud: &PointCloud,
        splat: SplatSize,
        max_diameters: &[f32],
    ) -> Result<Scene> {
        if max_diameters.len() != cloud.len() {
            return Err(Error::InvalidArgument(format!(
                "{} diameters for {} points",
                max_diameters.len(),
                cloud.len()
            )));
        }
        let size = match splat {
            SplatSize::Spacing => LeafSize::SpacingTimesAtMost(SPACING_TO_DIAMETER, max_diameters),
            _ => splat.leaf_size(),
        };
        self.upload_with(cloud, splat, size)
    }

    /// [`Renderer::upload`] drawing every point in the cloud's order, no
    /// hierarchy ([`SplatTree::build_in_input_order`]): to measure what
    /// Morton order gains the raster.
    pub fn upload_in_input_order(&self, cloud: &PointCloud) -> Result<Scene> {
        self.upload_tree(cloud.len(), SplatSize::Spacing, |threads| {
            SplatTree::build_in_input_order(
                points_of(cloud),
                SplatSize::Spacing.leaf_size(),
                threads,
            )
        })
    }

    fn upload_with(&self, cloud: &PointCloud, splat: SplatSize, size: LeafSize) -> Result<Scene> {
        self.upload_tree(cloud.len(), splat, |threads| {
            SplatTree::build(points_of(cloud), size, threads)
        })
    }

    /// The scene of a hierarchy built on the host ([`BuiltTree`]).
    pub fn upload_built(&self, built: BuiltTree) -> Scene {
        self.scene_of(built.tree, built.splat)
    }

    fn upload_tree(
        &self,
        points: usize,
        splat: SplatSize,
        build: impl FnOnce(usize) -> SplatTree,
    ) -> Result<Scene> {
        check_point_count(points)?;
        Ok(self.scene_of(build(crate::available_threads()), splat))
    }

    fn scene_of(&self, tree: SplatTree, splat: SplatSize) -> Scene {
        let upload = Upload {
            splat_sizes_ms: tree.build.spacing_ms,
            tree_ms: tree.build.total_ms,
            tree_bytes: tree.bytes() as u64,
            gpu_ms: 0.0,
            wall_ms: tree.build.total_ms,
        };
        Scene {
            tree,
            splat,
            ctx: self.ctx.clone(),
            last: Mutex::new(None),
            upload,
        }
    }

    /// Makes the pipelines of `method` now, as its first frame would: a
    /// process that knows its method makes them while it reads its file.
    pub fn make_pipelines_for(&self, method: &Method) -> Result<()> {
        self.methods.get(method).map(drop)
    }

    /// The splats and raster view of `scene` through `camera`: depth
    /// range, splat rule and a guard band for the blur of `method` (DESIGN
    /// §3).
    fn raster_view(
        &self,
        scene: &Scene,
        camera: &Camera,
        lod: Lod,
        method: &dyn DofMethod,
    ) -> Result<(Arc<FrameSplats>, LodReport, RasterView)> {
        let max_point = self.ctx.info.point_size_max;
        let (splats, lod_report) = scene.splats(SplatsKey {
            camera: *camera,
            lod,
            widening: Widening {
                // What the method's guard band holds besides the points' blur.
                background_coc_px: method.guard_coc_px(camera, None),
                splat_px: match scene.splat {
                    SplatSize::Pixels(p) => p.min(max_point),
                    _ => 0.0,
                },
            },
            point_size_max: max_point,
            veil: method.veil_rule(),
        })?;
        let seen = splats.view;
        let max_coc_px = method.guard_coc_px(camera, seen.depths);
        let (near, far) = clip_range(seen.depths);
        // Eye-dome lighting reads depths its radius away: the band holds
        // them, so that a tile's border shades as the whole frame's does.
        let edl_px = self.edl.map_or(0, |e| e.radius_px.ceil() as u32);
        let view = RasterView {
            frame: FrameView {
                camera: *camera,
                window: Window::whole(camera),
                guard: camera.guard_band_px(max_coc_px, seen.max_splat_px) + edl_px,
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
            max_splat_px: seen.max_splat_px,
            color_scale: scene.tree.color_scale(),
        };
        Ok((splats, lod_report, view))
    }

    /// Renders one frame of `scene`.
    pub fn render(&self, scene: &Scene, options: &RenderOptions) -> Result<Rendered> {
        let (r, _) = self.render_frame(scene, options, OutputFormat::LinearF32, false, None)?;
        Ok(r.map(|pixels| pixels.linear().expect("asked for")))
    }

    /// Renders one frame of `scene` as a PNG's pixels, encoded on the
    /// device: the same bytes as [`Srgb8Image::of`] the linear frame.
    pub fn render_srgb8(
        &self,
        scene: &Scene,
        options: &RenderOptions,
    ) -> Result<Rendered<Srgb8Image>> {
        let (r, _) = self.render_frame(scene, options, OutputFormat::Srgb8, false, None)?;
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
        lod: Lod,
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
            lod,
        };
        // The G-buffer of that one pixel (and its guard band).
        let pixel = Window {
            x,
            y,
            width: 1,
            height: 1,
        };
        let (_, gbuffer) =
            self.render_frame(scene, &options, OutputFormat::LinearF32, true, Some(pixel))?;
        let gbuffer = gbuffer.expect("asked for");
        let g = gbuffer.guard;
        let z = gbuffer.eye[(g * gbuffer.width + g) as usize][2];
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
            self.render_frame(scene, options, OutputFormat::LinearF32, true, None)?;
        let rendered = rendered.map(|pixels| pixels.linear().expect("asked for"));
        Ok((rendered, gbuffer.expect("asked for")))
    }

    /// The frame: view → G-buffer → method → readback, for the whole
    /// frame or, where its G-buffer would not fit the device (or
    /// `--tile-px` asks), tile by tile ([`Renderer::windows`]), with the
    /// splats, depth range and guard band of the whole frame; `only`
    /// renders one window of it. Everything is allocated before recording
    /// starts; the frame's wall time runs from the view (the CPU's look at
    /// the points) to the output pixels copied to the host.
    fn render_frame(
        &self,
        scene: &Scene,
        options: &RenderOptions,
        format: OutputFormat,
        keep_gbuffer: bool,
        only: Option<Window>,
    ) -> Result<(Rendered<Pixels>, Option<HostGBuffer>)> {
        self.check_frame(scene, options)?;
        // What the frame before last left and the last one did not take is
        // freed; the rest is this frame's to take (`vk::pool`).
        // The method's pipelines, made on the first frame that asks for
        // them, before the frame's time starts.
        let method = self.methods.get(&options.method)?;
        self.ctx.next_frame();
        let started = Instant::now();
        let (splats, lod_report, view) =
            self.raster_view(scene, &options.camera, options.lod, method.as_ref())?;
        let view_ms = started.elapsed().as_secs_f64() * 1e3;

        let windows = match only {
            Some(window) => vec![window],
            None => self.windows(&view.frame)?,
        };
        let (raster, plan, peel) = self.tile_plans(&view, &windows, options)?;
        let tile = |window: Window| {
            let view = RasterView {
                frame: FrameView {
                    window,
                    ..view.frame
                },
                ..view
            };
            let tile = TileRender {
                splats: &splats,
                view,
                method: method.as_ref(),
                plan: &plan,
                raster,
                peel,
            };
            self.render_window(&tile, options, format, keep_gbuffer)
        };
        let rendered = Rendered {
            image: Pixels::empty(format, &options.camera, windows.len()),
            timings: FrameTimings {
                passes: Vec::new(),
                wall_ms: view_ms,
                readback_ms: 0.0,
            },
            guard: view.frame.guard,
            samples_per_pass: plan.samples_per_pixel_per_pass(),
            counts: Vec::new(),
            lod: lod_report,
        };
        self.assemble_tiles(rendered, &windows, &options.camera, keep_gbuffer, tile)
    }

    /// The checks of a frame's options against each other and the
    /// renderer, and that `scene` is this renderer's.
    fn check_frame(&self, scene: &Scene, options: &RenderOptions) -> Result<()> {
        check_ssaa(options.ssaa)?;
        if let Some(s) = options.samples_per_pass {
            check_samples_per_pass(s)?;
        }
        if !Arc::ptr_eq(&scene.ctx, &self.ctx) {
            return Err(Error::InvalidArgument(
                "the scene was uploaded by a renderer on another device".into(),
            ));
        }
        check_lod(&options.lod)?;
        if let Method::Fast(fast) = options.method {
            fast.check()?;
        }
        if self.edl.is_some() {
            crate::options::check_edl_with(&options.method)?;
        }
        Ok(())
    }

    /// The raster, sample plan and peel plan every tile of a frame (`view`
    /// of the whole frame, rendered in `windows`) shares: the largest
    /// tile's (the tiles of a row or column differ by at most a pixel).
    fn tile_plans(
        &self,
        view: &RasterView,
        windows: &[Window],
        options: &RenderOptions,
    ) -> Result<(Raster, SamplePlan, PeelPlan)> {
        let largest = Window {
            x: 0,
            y: 0,
            width: windows.iter().map(|w| w.width).max().unwrap_or(0),
            height: windows.iter().map(|w| w.height).max().unwrap_or(0),
        };
        let raster = self.raster_with(options.samples_per_pass)?;
        crate::options::check_coverage_with(
            self.coverage,
            &options.method,
            Some(raster),
            Some(self.splat_shape),
        )?;
        let plan_view = RasterView {
            frame: FrameView {
                window: largest,
                ..view.frame
            },
            ..*view
        };
        let plan = self.gbuffer.plan(
            raster,
            options.ssaa,
            options.samples_per_pass,
            &plan_view,
            self.sample_budget_bytes,
            self.ctx.info.max_image_dimension_2d,
        )?;
        let pixels = plan_view.frame.full_width() as u64 * plan_view.frame.full_height() as u64;
        let peel = self.gbuffer.peel_plan(
            raster,
            options.ssaa,
            options.samples_per_pass,
            pixels,
            self.sample_budget_bytes,
        );
        Ok((raster, plan, peel))
    }

    /// The frame `rendered` (its view's time, no pixels yet) with the
    /// results of `tile` for each of `windows` (of a frame of `camera`):
    /// the one window's own, or each window's pixels, timings, counts and,
    /// with `keep_gbuffer`, its G-buffer's interior put in place, tile by
    /// tile.
    fn assemble_tiles(
        &self,
        mut rendered: Rendered<Pixels>,
        windows: &[Window],
        camera: &Camera,
        keep_gbuffer: bool,
        tile: impl Fn(Window) -> Result<WindowResult>,
    ) -> Result<(Rendered<Pixels>, Option<HostGBuffer>)> {
        if let [window] = windows[..] {
            let mut part = tile(window)?;
            part.timings.wall_ms += rendered.timings.wall_ms;
            rendered.image = part.image;
            rendered.timings = part.timings;
            rendered.counts = part.counts;
            return Ok((rendered, part.gbuffer));
        }
        let (width, height) = (camera.width, camera.height);
        let mut assembled = keep_gbuffer.then(|| HostGBuffer::zeroed(width, height));
        for (i, &window) in windows.iter().enumerate() {
            if i > 0 {
                // The last tile's images go back to the pool for this one.
                self.ctx.next_frame();
            }
            let part = tile(window)?;
            rendered.image.paste(&part.image, window);
            rendered.timings.merge(&part.timings);
            for (name, n) in part.counts {
                match rendered.counts.iter_mut().find(|(m, _)| *m == name) {
                    Some((_, total)) => *total += n,
                    None => rendered.counts.push((name, n)),
                }
            }
            if let (Some(whole), Some(gbuffer)) = (&mut assembled, &part.gbuffer) {
                whole.paste_interior(gbuffer, window.x, window.y);
            }
        }
        Ok((rendered, assembled))
    }

    /// The windows a frame renders in (`view` of the whole frame): the
    /// whole frame when its G-buffer fits the device's images and no
    /// `--tile-px` is set; else tiles of at most `--tile-px` (default
    /// [`AUTO_TILE_PX`]) pixels a side, made smaller where the guard band
    /// would not leave them room within the device's images.
    fn windows(&self, view: &FrameView) -> Result<Vec<Window>> {
        let max = self.ctx.info.max_image_dimension_2d;
        let camera = &view.camera;
        let band = 2 * view.guard;
        let tile_px = match self.tile_px {
            None if camera.width.max(camera.height) + band <= max => {
                return Ok(vec![Window::whole(camera)]);
            }
            Some(t) => t,
            None => AUTO_TILE_PX,
        };
        let room = max.saturating_sub(band);
        if room == 0 {
            return Err(Error::InvalidArgument(format!(
                "a {} px guard band leaves no room for a tile within the device's {max} px images",
                view.guard
            )));
        }
        Ok(Window::tiles(
            camera.width,
            camera.height,
            tile_px.min(room),
        ))
    }

    /// One window of a frame: G-buffer → method → output → readback. Its
    /// image, timings, the method's counts and, when asked for, its
    /// G-buffer (guard band included).
    fn render_window(
        &self,
        tile: &TileRender,
        options: &RenderOptions,
        format: OutputFormat,
        keep_gbuffer: bool,
    ) -> Result<WindowResult> {
        let (splats, view, method) = (tile.splats, &tile.view, tile.method);
        let lens = method.gbuffer_lens(&view.frame.camera);
        let gbuffer = GBuffer::new(
            &self.ctx,
            view,
            tile.plan,
            tile.raster,
            splats.count,
            method.gbuffer_layers(),
            tile.peel,
            self.peel_cull.then_some(splats.count),
            options.background,
            self.area_coverage(tile.raster, &options.method),
        )?;
        let dof = method.prepare(&self.ctx, &view.frame)?;
        let readback = Readback::new(
            &self.ctx,
            &view.frame,
            format,
            keep_gbuffer,
            self.staged_output,
        )?;

        let mut frame = Frame::begin(&self.ctx, "frame")?;
        gbuffer.record(
            &mut frame,
            &self.gbuffer,
            &splats.vertices,
            splats.count,
            &lens,
            method.gbuffer_label(),
        );
        let input = gbuffer.output();
        if let Some(edl) = self.edl {
            self.edl_pass.record(&mut frame, &input, edl);
        }
        let result = dof.record(&mut frame, &input);
        self.output.record(
            &mut frame,
            result,
            &view.frame,
            (&splats.veil_splats, splats.veil.splats_in_view.len() as u32),
            format,
            OutputBuffers {
                host: &readback.result,
                staging: readback.staging.as_ref(),
            },
        );
        readback.record(&mut frame, &input);
        let mut timings = frame.submit_and_wait()?;

        let copying = Instant::now();
        let (image, host_gbuffer) = readback.read()?;
        timings.readback_ms = copying.elapsed().as_secs_f64() * 1e3;
        timings.wall_ms += timings.readback_ms;
        Ok(WindowResult {
            image,
            timings,
            counts: dof.counts(),
            gbuffer: host_gbuffer,
        })
    }
}

/// Output pixels a side of the tiles of a frame whose G-buffer would not
/// fit the device's images, when `--tile-px` is not given: 2048² pixels
/// and their guard band keep a tile's images within lavapipe's 2 GiB
/// (docs/ARCHITECTURE.md, "Posters in tiles").
pub const AUTO_TILE_PX: u32 = 2048;

/// What one window of a frame gave: its output pixels, timings, the
/// method's counts and, when asked for, its G-buffer (guard band
/// included).
struct WindowResult {
    image: Pixels,
    timings: FrameTimings,
    counts: Vec<(String, u64)>,
    gbuffer: Option<HostGBuffer>,
}

/// What every window of one frame shares: the frame's splats and view
/// (the window set), its method, sample plan and raster.
struct TileRender<'a> {
    splats: &'a FrameSplats,
    view: RasterView,
    method: &'a dyn DofMethod,
    plan: &'a SamplePlan,
    raster: Raster,
    peel: PeelPlan,
}

/// The host-visible buffers a frame's results land in: the output pixels
/// (written by the output pass in the file's format, guard band cropped)
/// and, when asked for, the whole G-buffer.
struct Readback {
    view: FrameView,
    format: OutputFormat,
    /// Written by the output pass ([`OutputConvert`]).
    result: Buffer,
    /// Device-local, where the output pass writes when staged
    /// ([`Renderer::set_staged_output`]).
    staging: Option<Buffer>,
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

impl Pixels {
    /// The pixels of a frame of `camera` to paste `tiles` windows into
    /// (none allocated for a frame of one window: it is the window's).
    fn empty(format: OutputFormat, camera: &Camera, tiles: usize) -> Pixels {
        let (width, height) = match tiles {
            1 => (0, 0),
            _ => (camera.width, camera.height),
        };
        let pixels = width as usize * height as usize;
        match format {
            OutputFormat::LinearF32 => Pixels::Linear(LinearImage {
                width,
                height,
                pixels: vec![[0.0; 4]; pixels],
            }),
            OutputFormat::Srgb8 => Pixels::Srgb8(Srgb8Image {
                width,
                height,
                rgb: vec![0; 3 * pixels],
            }),
        }
    }

    /// Copies `part`, the pixels of `window`, into place.
    fn paste(&mut self, part: &Pixels, window: Window) {
        let (x, y) = (window.x as usize, window.y as usize);
        let (w, h) = (window.width as usize, window.height as usize);
        match (self, part) {
            (Pixels::Linear(whole), Pixels::Linear(part)) => {
                let stride = whole.width as usize;
                for row in 0..h {
                    let to = (y + row) * stride + x;
                    whole.pixels[to..to + w].copy_from_slice(&part.pixels[row * w..(row + 1) * w]);
                }
            }
            (Pixels::Srgb8(whole), Pixels::Srgb8(part)) => {
                let stride = 3 * whole.width as usize;
                for row in 0..h {
                    let to = (y + row) * stride + 3 * x;
                    whole.rgb[to..to + 3 * w]
                        .copy_from_slice(&part.rgb[3 * row * w..3 * (row + 1) * w]);
                }
            }
            _ => unreachable!("every tile of a frame is in the frame's format"),
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
            lod: self.lod,
        }
    }
}

impl Readback {
    fn new(
        ctx: &Arc<Context>,
        view: &FrameView,
        format: OutputFormat,
        keep_gbuffer: bool,
        staged: Option<bool>,
    ) -> Result<Readback> {
        let host = |name: &str, bytes: u64, usage: vk::BufferUsageFlags| {
            Buffer::new(ctx, name, bytes, usage, MemoryLocation::GpuToCpu)
        };
        let texels = |format: vk::Format| {
            view.full_width() as u64 * view.full_height() as u64 * texel_bytes(format)
        };
        let copied = vk::BufferUsageFlags::TRANSFER_DST;
        let pixels = view.window.pixels();
        let bytes = format.buffer_bytes(pixels);
        let result = host(
            "output",
            bytes,
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
        )?;
        let staging = match staged.unwrap_or(!result.device_local()) {
            true => Some(Buffer::new(
                ctx,
                "output staging",
                bytes,
                vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC,
                MemoryLocation::GpuOnly,
            )?),
            false => None,
        };
        Ok(Readback {
            view: *view,
            format,
            result,
            staging,
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
            // The method's passes read the G-buffer in compute shaders, and
            // the layered method's depth peel in fragment shaders too.
            rec.barriers(&[
                (input.color, Access::SHADER_READ_WRITE, Access::COPY_SRC),
                (input.eye, Access::SHADER_READ_WRITE, Access::COPY_SRC),
            ]);
            let full = [self.view.full_width(), self.view.full_height()];
            rec.copy_image_to_buffer(input.color, [0, 0], full, color);
            rec.copy_image_to_buffer(input.eye, [0, 0], full, eye);
            rec.memory_barrier(Access::COPY_WRITE, Access::HOST_READ);
        });
    }

    /// Copies the pixels out once the frame has completed.
    fn read(&self) -> Result<(Pixels, Option<HostGBuffer>)> {
        let (width, height) = (self.view.window.width, self.view.window.height);
        let pixels = width as usize * height as usize;
        let bytes = host_bytes(&self.result)?;
        let image = match self.format {
            OutputFormat::LinearF32 => Pixels::Linear(LinearImage {
                width,
                height,
                pixels: collect_in_parallel(&bytes[..16 * pixels]),
            }),
            OutputFormat::Srgb8 => Pixels::Srgb8(Srgb8Image {
                width,
                height,
                rgb: collect_in_parallel(&bytes[..3 * pixels]),
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

/// `bytes` (a whole number of `T`) as a vector of `T`, copied by
/// [`crate::copy_in_parallel`] into one allocation of zeros (the kernel's
/// fresh zero pages, first touched by the copy).
fn collect_in_parallel<T: bytemuck::Pod + Send>(bytes: &[u8]) -> Vec<T> {
    let mut out = vec![T::zeroed(); bytes.len() / std::mem::size_of::<T>()];
    crate::copy_in_parallel(
        &[bytes],
        bytemuck::cast_slice_mut(&mut out),
        crate::available_threads(),
    );
    out
}

/// Splats per run of [`Scene::scene_view`]'s threads.
const SCENE_VIEW_RUN: usize = 1 << 16;

/// The mapped bytes of a readback buffer.
pub(crate) fn host_bytes(buffer: &Buffer) -> Result<&[u8]> {
    buffer
        .mapped()
        .ok_or_else(|| Error::Allocation("readback buffer is not host-visible".into()))
}

/// Decodes tightly packed rgba16f texels.
pub(crate) fn rgba16f_texels(bytes: &[u8]) -> Vec<[f32; 4]> {
    bytes
        .chunks_exact(8)
        .map(|t| std::array::from_fn(|i| f16_to_f32(u16::from_le_bytes([t[2 * i], t[2 * i + 1]]))))
        .collect()
}

/// Warns, once a process, where a frame's widest splat (`widest_px`, in
/// the pinhole image) is wider than the frame: every such splat is
/// rasterised over the whole frame, which takes long and shows little but
/// those splats (`--splat-size` far above the points' spacing).
fn warn_of_splats_wider_than(camera: &Camera, widest_px: f32) {
    static WARNED: std::sync::Once = std::sync::Once::new();
    let frame_px = camera.width.max(camera.height) as f32;
    if widest_px > frame_px {
        WARNED.call_once(|| {
            log::warn!(
                "splats up to {widest_px:.0} px wide in a {}×{} frame: each covers the whole \
                 frame, which is slow and hides what lies behind (a --splat-size far above the \
                 points' spacing?)",
                camera.width,
                camera.height
            )
        });
    }
}

#[cfg(test)]
mod tests {
    use std::mem::{align_of, offset_of, size_of};

    use super::*;

    /// [`vertices_of`] reads the hierarchy's splats as the raster's
    /// vertices: every field at the same offset, of the same size.
    #[test]
    fn a_tree_splat_is_laid_out_as_the_raster_vertex() {
        assert_eq!(size_of::<Splat>(), size_of::<SplatVertex>());
        assert_eq!(align_of::<Splat>(), align_of::<SplatVertex>());
        assert_eq!(
            offset_of!(Splat, position_size),
            offset_of!(SplatVertex, position_size)
        );
        assert_eq!(offset_of!(Splat, color), offset_of!(SplatVertex, color));
        let splat = Splat {
            position_size: [1.0, -2.0, 3.5, 0.25],
            color: [1, 65535, 300, 0xBEEF],
        };
        let vertex = vertices_of(std::slice::from_ref(&splat))[0];
        assert_eq!(vertex.position_size, splat.position_size);
        assert_eq!(vertex.color, splat.color);
    }
}
