//! What a frame draws from: one interface over the three kinds of scene —
//! a cloud read whole with its splat hierarchy, a COPC file read node by
//! node, a set of 3D Gaussians (docs/ARCHITECTURE.md, "The scene
//! interface").
//!
//! A scene lives in stages. [`HostScene::open`] reads the file (its
//! kind chosen by [`input::kind_of`], the one place
//! that looks at magic bytes) and answers what the job needs before a
//! device exists: the points the default camera is framed on
//! ([`HostScene::framing`]). [`HostScene::build`] does the rest of the
//! host's work (a cloud's splat hierarchy), while [`DeviceSetup::open`],
//! which needs nothing of the file, opens the device for the kind and
//! makes its pipelines. [`BuiltScene::upload`] then makes a
//! [`DeviceScene`]: the kind's renderer and its data on the device, which
//! renders and writes one frame at a time ([`DeviceScene::render_frame`]).
//! Which flags a kind refuses is one table, [`FLAGS`], checked by
//! [`check_flags`] before anything is read.
//!
//! A new kind of scene is a variant of [`SceneKind`], of [`HostScene`],
//! [`BuiltScene`], [`DeviceSetup`] and [`DeviceScene`], a column of
//! [`FLAGS`] (the kinds that accept each flag) and its magic bytes in
//! `input::kind_of`.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{DVec3, Vec3};

use crate::camera::Camera;
use crate::cloud::PointCloud;
use crate::color::{ColorMode, ColorRanges};
use crate::error::{Error, Result};
use crate::gaussian_render::{GaussianRenderer, GpuGaussians};
use crate::input::copc::CopcClouds;
use crate::input::copc::NodeEntry;
use crate::input::gaussians::GaussianScene;
use crate::input::{self, InputKind};
use crate::job::{FrameJob, JobEvent, RenderJob};
use crate::options::Lod;
use crate::options::{
    Coverage, EdlOptions, Method, Raster, SplatShape, DEFAULT_LAYERS, DEFAULT_LOD_PX,
};
use crate::render::{BuiltTree, Renderer, Scene, SplatSize};
use crate::tree::Widening;
use crate::vk::{Context, ContextOptions};

/// The kind of a scene: what its file holds.
pub type SceneKind = InputKind;

/// How a scene is read and drawn: the flags of `pointlens render` about
/// the input rather than the frames (None: not given, the default).
#[derive(Debug, Clone)]
pub struct SceneSpec {
    /// The file: PLY, LAS, LAZ, COPC, or 3D Gaussians in PLY.
    pub input: PathBuf,
    /// `--origin`: re-centre on this point (file coordinates).
    pub origin: Option<DVec3>,
    /// `--memory-mb`: host memory for the points, MiB.
    pub memory_mb: u64,
    /// `--point-budget`: the most points of a COPC file one frame takes.
    pub point_budget: Option<u64>,
    /// `--splat-size` / `--splat-px`, else sizes from the spacing.
    pub splat: SplatSize,
    /// `--color`: what a point's color shows.
    pub color: Option<ColorMode>,
    /// `--edl`: eye-dome lighting.
    pub edl: Option<EdlOptions>,
    /// `--tile-px`: render each frame in tiles of at most this size.
    pub tile_px: Option<u32>,
    /// `--raster`: how the G-buffer's splats are rasterised.
    pub raster: Option<Raster>,
    /// `--splat-shape`: square or disc.
    pub splat_shape: Option<SplatShape>,
    /// `--coverage`: how the G-buffer weighs the splats within a pixel.
    pub coverage: Option<Coverage>,
}

impl SceneSpec {
    /// The scene of `input` with every flag at its default.
    pub fn of(input: impl Into<PathBuf>) -> SceneSpec {
        SceneSpec {
            input: input.into(),
            origin: None,
            memory_mb: input::default_memory_mb(),
            point_budget: None,
            splat: SplatSize::Spacing,
            color: None,
            edl: None,
            tile_px: None,
            raster: None,
            splat_shape: None,
            coverage: None,
        }
    }
}

/// A flag that some kinds of scene cannot act on.
pub struct SceneFlag {
    /// As the command line spells it.
    pub flag: &'static str,
    /// Whether the job or the scene asks for it. A flag held as a plain
    /// value counts as given where it differs from its default.
    pub given: fn(&crate::job::JobSpec, &SceneSpec) -> bool,
    /// The kinds that act on it; the others refuse it in one line.
    pub kinds: &'static [SceneKind],
    /// Why the others refuse it.
    pub why: Why,
}

/// Why a kind of scene refuses a flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Why {
    /// The flag is about points (splats, their hierarchy, their reading),
    /// and the scene has none.
    AboutPoints,
    /// The scene's renderer does not do it yet; the text names what.
    NotYet(&'static str),
}

const POINTS: &[SceneKind] = &[SceneKind::Cloud, SceneKind::Copc];

/// Every flag a kind of scene may refuse, and the kinds that take it: the
/// one table of refusals, checked by [`check_flags`] in this order.
pub const FLAGS: &[SceneFlag] = &[
    SceneFlag {
        flag: "--splat-size",
        given: |_, s| matches!(s.splat, SplatSize::World(_)),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--splat-px",
        given: |_, s| matches!(s.splat, SplatSize::Pixels(_)),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--color",
        given: |_, s| s.color.is_some(),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--edl",
        given: |_, s| s.edl.is_some(),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--lod-blur",
        given: |j, _| j.lod.blur.is_some(),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--cull-back-faces",
        given: |j, _| j.lod.cull_back_faces,
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--tile-px",
        given: |_, s| s.tile_px.is_some(),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--origin",
        given: |_, s| s.origin.is_some(),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--samples-per-pass",
        given: |j, _| j.samples_per_pass.is_some(),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--raster",
        given: |_, s| s.raster.is_some(),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--lod-px",
        given: |j, _| j.lod.px != DEFAULT_LOD_PX,
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--point-budget",
        given: |_, s| s.point_budget.is_some(),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--splat-shape",
        given: |_, s| s.splat_shape.is_some(),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--coverage",
        given: |_, s| s.coverage.is_some(),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--layers",
        given: |j, _| matches!(j.method, Method::Layered(l) if l.layers != DEFAULT_LAYERS),
        kinds: POINTS,
        why: Why::AboutPoints,
    },
    SceneFlag {
        flag: "--focus-pixel",
        given: |j, _| j.focus_pixel.is_some(),
        kinds: POINTS,
        why: Why::NotYet("--focus-pixel"),
    },
    SceneFlag {
        flag: "--passes",
        given: |j, _| j.written.passes.z || j.written.passes.coc,
        kinds: POINTS,
        why: Why::NotYet("--passes (its depth and CoC are not one surface's)"),
    },
    SceneFlag {
        flag: "--background transparent",
        given: |j, _| j.written.transparent,
        kinds: POINTS,
        why: Why::NotYet("a transparent --background"),
    },
    SceneFlag {
        flag: "--ssaa",
        given: |j, _| {
            matches!(j.method, Method::Layered(_))
                && j.ssaa.unwrap_or(crate::options::DEFAULT_SSAA_GAUSSIANS) > 1
        },
        kinds: POINTS,
        why: Why::NotYet("--ssaa above 1 with --method layered"),
    },
];

/// Refuses, in one line, the first flag of [`FLAGS`] given that a scene of
/// `kind` cannot act on.
pub fn check_flags(kind: SceneKind, job: &crate::job::JobSpec, scene: &SceneSpec) -> Result<()> {
    let refused = FLAGS
        .iter()
        .find(|f| !f.kinds.contains(&kind) && (f.given)(job, scene));
    match refused {
        None => Ok(()),
        Some(f) => Err(Error::InvalidArgument(match f.why {
            Why::AboutPoints => format!(
                "{}: {} is about points, and the file holds 3D Gaussians",
                scene.input.display(),
                f.flag
            ),
            Why::NotYet(what) => {
                format!("a scene of 3D Gaussians renders without {what} in this version")
            }
        })),
    }
}

/// Refuses `--cull-back-faces` (in `lod`) before the file is read where
/// its kind or its header says its points have no normals (a COPC, LAS or
/// LAZ file; a PLY file without `nx ny nz`); [`HostScene::check_lod`]
/// checks again once it is read.
pub fn check_lod_before_reading(kind: SceneKind, lod: &Lod, spec: &SceneSpec) -> Result<()> {
    if !lod.cull_back_faces {
        return Ok(());
    }
    let may = match kind {
        SceneKind::Cloud => input::may_have_normals(&spec.input)?,
        SceneKind::Copc | SceneKind::Gaussians => false,
    };
    match may {
        true => Ok(()),
        false => Err(no_normals(spec)),
    }
}

/// `--cull-back-faces` refused: the points of `spec`'s file have no normals.
fn no_normals(spec: &SceneSpec) -> Error {
    Error::InvalidArgument(format!(
        "{}: --cull-back-faces needs the points' normals, and the file has none",
        spec.input.display()
    ))
}

/// A scene read from its file, on the host.
// One a job, held once: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
pub enum HostScene {
    /// A cloud read whole (colored by `--color`).
    Cloud(PointCloud),
    /// A COPC file opened to be read by node; `preview` is its root node's
    /// points (colored), on which cameras are framed, and `ranges` what
    /// `--color` stretches over in every frame (the whole file's; None
    /// without `--color`).
    Copc {
        clouds: CopcClouds,
        preview: PointCloud,
        ranges: Option<ColorRanges>,
    },
    /// 3D Gaussians, and their centres as a cloud to frame cameras on.
    Gaussians {
        scene: GaussianScene,
        centres: PointCloud,
    },
}

impl HostScene {
    /// Reads `spec.input` as its magic bytes say, within `spec.memory_mb`;
    /// `progress(done, total)` follows a LAS/LAZ file read whole.
    pub fn open(spec: &SceneSpec, progress: &mut dyn FnMut(u64, u64)) -> Result<HostScene> {
        let path = &spec.input;
        let colored = |mut cloud: PointCloud, ranges: &ColorRanges| -> Result<PointCloud> {
            if let Some(mode) = spec.color {
                crate::color::apply_over(&mut cloud, mode, ranges)
                    .map_err(|e| e.within(path.display().to_string()))?;
            }
            Ok(cloud)
        };
        match input::kind_of(path) {
            InputKind::Gaussians => {
                input::gaussians::check_fits(path, spec.memory_mb)?;
                let scene = input::gaussians::load_gaussians(path)?;
                let centres = PointCloud {
                    colors: vec![Vec3::ZERO; scene.positions.len()],
                    positions: scene.positions.clone(),
                    ..PointCloud::default()
                };
                Ok(HostScene::Gaussians { scene, centres })
            }
            InputKind::Copc => {
                let clouds = CopcClouds::open(
                    path,
                    spec.origin,
                    spec.point_budget
                        .unwrap_or(input::copc::DEFAULT_POINT_BUDGET),
                    spec.memory_mb,
                )?;
                let ranges = match spec.color {
                    Some(_) => Some(clouds.color_ranges()?),
                    None => None,
                };
                let preview = clouds.preview()?;
                let preview = match &ranges {
                    Some(ranges) => colored(preview, ranges)?,
                    None => preview,
                };
                Ok(HostScene::Copc {
                    clouds,
                    preview,
                    ranges,
                })
            }
            InputKind::Cloud => {
                let cloud = read_whole(path, spec.origin, spec.memory_mb, progress)?;
                let ranges = ColorRanges::of(&cloud);
                Ok(HostScene::Cloud(colored(cloud, &ranges)?))
            }
        }
    }

    /// Refuses `--cull-back-faces` (in `lod`) where the points have no
    /// normals to cull by: a cloud read without them, a COPC file (its
    /// points carry none).
    pub fn check_lod(&self, lod: &Lod, spec: &SceneSpec) -> Result<()> {
        let has_normals = match self {
            HostScene::Cloud(cloud) => cloud.normals.is_some(),
            HostScene::Copc { .. } | HostScene::Gaussians { .. } => false,
        };
        match lod.cull_back_faces && !has_normals {
            true => Err(no_normals(spec)),
            false => Ok(()),
        }
    }

    /// The kind of this scene.
    pub fn kind(&self) -> SceneKind {
        match self {
            HostScene::Cloud(_) => SceneKind::Cloud,
            HostScene::Copc { .. } => SceneKind::Copc,
            HostScene::Gaussians { .. } => SceneKind::Gaussians,
        }
    }

    /// The points the default camera is framed on, with the origin and
    /// up axis cameras are placed by: the cloud, the COPC root node's
    /// points, the Gaussians' centres.
    pub fn framing(&self) -> &PointCloud {
        match self {
            HostScene::Cloud(cloud) => cloud,
            HostScene::Copc { preview, .. } => preview,
            HostScene::Gaussians { centres, .. } => centres,
        }
    }

    /// The host's work before the device: a cloud read whole gets its
    /// splat hierarchy (the cloud dropped as soon as the hierarchy holds
    /// its points); a COPC file and 3D Gaussians are ready as read.
    pub fn build(self, spec: &SceneSpec) -> Result<BuiltScene> {
        Ok(match self {
            HostScene::Cloud(cloud) => {
                BuiltScene::Cloud(BuiltTree::build_owned(cloud, spec.splat)?)
            }
            HostScene::Copc { clouds, ranges, .. } => BuiltScene::Copc { clouds, ranges },
            HostScene::Gaussians { scene, .. } => BuiltScene::Gaussians(scene),
        })
    }
}

/// A scene built on the host and ready for a device
/// ([`HostScene::build`]).
// One a job, held once: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
pub enum BuiltScene {
    /// A cloud read whole, as its splat hierarchy.
    Cloud(BuiltTree),
    /// A COPC file read by node; `--color`'s ranges over the whole file.
    Copc {
        clouds: CopcClouds,
        ranges: Option<ColorRanges>,
    },
    /// 3D Gaussians.
    Gaussians(GaussianScene),
}

impl BuiltScene {
    /// The scene on the device `setup` opened for its kind; the host's
    /// copy is dropped once the device holds it.
    pub fn upload(self, setup: DeviceSetup, spec: &SceneSpec) -> Result<DeviceScene> {
        match (self, setup) {
            (BuiltScene::Cloud(tree), DeviceSetup::Points(renderer)) => {
                let scene = renderer.upload_built(tree);
                Ok(DeviceScene::Cloud { renderer, scene })
            }
            (BuiltScene::Copc { clouds, ranges }, DeviceSetup::Points(renderer)) => {
                let color = spec.color.zip(ranges);
                let copc = CopcScenes::new(clouds, spec.splat, color);
                Ok(DeviceScene::Copc { renderer, copc })
            }
            (BuiltScene::Gaussians(scene), DeviceSetup::Gaussians(renderer)) => {
                let gpu = renderer.upload(&scene)?;
                Ok(DeviceScene::Gaussians { renderer, gpu })
            }
            // The device was opened for the kind the file's magic bytes
            // showed before it was read: only a file replaced meanwhile
            // differs.
            _ => Err(Error::InvalidArgument(format!(
                "{}: the file changed while it was read",
                spec.input.display()
            ))),
        }
    }
}

/// A device opened for a kind of scene, its renderer's pipelines made:
/// what [`DeviceSetup::open`] makes while the file is read and built
/// (`pointlens render` opens it on a thread of its own).
// One a job, held once: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
pub enum DeviceSetup {
    /// Points (a cloud, a COPC file): the renderer set as the scene's
    /// flags ask, with the pipelines of the job's method.
    Points(Renderer),
    /// 3D Gaussians.
    Gaussians(GaussianRenderer),
}

impl DeviceSetup {
    /// Opens the device of `options` for a scene of `kind` read with
    /// `spec`, and makes the renderer's pipelines; for points also those
    /// of `method`, which its first frame would make.
    pub fn open(
        options: &ContextOptions,
        kind: SceneKind,
        spec: &SceneSpec,
        method: &Method,
    ) -> Result<DeviceSetup> {
        let t_device = std::time::Instant::now();
        let ctx = Context::new(options)?;
        log::info!(
            "device: {} (opened in {:.0} ms)",
            ctx.info.describe(),
            t_device.elapsed().as_secs_f64() * 1e3
        );
        if kind == SceneKind::Gaussians {
            return Ok(DeviceSetup::Gaussians(GaussianRenderer::new(&ctx)?));
        }
        let t_pipelines = std::time::Instant::now();
        let mut renderer = Renderer::new(&ctx)?;
        log::info!(
            "renderer's pipelines made in {:.0} ms",
            t_pipelines.elapsed().as_secs_f64() * 1e3
        );
        renderer.set_raster(spec.raster.unwrap_or_default());
        renderer.set_edl(spec.edl);
        renderer.set_tile_px(spec.tile_px);
        renderer.set_splat_shape(spec.splat_shape.unwrap_or_default())?;
        renderer.set_coverage(spec.coverage);
        renderer.make_pipelines_for(method)?;
        Ok(DeviceSetup::Points(renderer))
    }

    /// The device opened.
    pub fn ctx(&self) -> &Arc<Context> {
        match self {
            DeviceSetup::Points(renderer) => renderer.ctx(),
            DeviceSetup::Gaussians(renderer) => renderer.ctx(),
        }
    }
}

/// A cloud read whole from `path`, refused in one line where it would
/// not fit `memory_mb` (naming the `convert` command that makes it COPC).
pub fn read_whole(
    path: &Path,
    origin: Option<DVec3>,
    memory_mb: u64,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<PointCloud> {
    input::check_whole_read_fits(path, memory_mb, false, input::convert_advice)?;
    load_logged(path, origin, progress)
}

/// [`input::load_cloud`], its count and time logged.
fn load_logged(
    path: &Path,
    origin: Option<DVec3>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<PointCloud> {
    let started = std::time::Instant::now();
    let cloud = input::load_cloud(path, origin, progress)?;
    log::info!(
        "{}: {} points loaded in {:.2} s",
        path.display(),
        cloud.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(cloud)
}

/// A scene on the device with the renderer of its kind.
// One a job, held once: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
pub enum DeviceScene {
    Cloud {
        renderer: Renderer,
        scene: Scene,
    },
    Copc {
        renderer: Renderer,
        copc: CopcScenes,
    },
    Gaussians {
        renderer: GaussianRenderer,
        gpu: GpuGaussians,
    },
}

impl DeviceScene {
    /// The device the scene is on.
    pub fn ctx(&self) -> &Arc<Context> {
        match self {
            DeviceScene::Cloud { renderer, .. } | DeviceScene::Copc { renderer, .. } => {
                renderer.ctx()
            }
            DeviceScene::Gaussians { renderer, .. } => renderer.ctx(),
        }
    }

    /// Renders frame `frame` of `job`, telling `events` its camera first
    /// (`load_ms`: the file's reading, for the report): the camera as
    /// rendered (in the plan's coordinates), the frame's report and the
    /// write of its file.
    pub fn render_frame(
        &self,
        job: &RenderJob,
        frame: &FrameJob,
        plan: &crate::job::Plan,
        load_ms: f64,
        events: &mut dyn FnMut(JobEvent) -> Result<()>,
    ) -> Result<crate::job::RenderedFrame> {
        match self {
            DeviceScene::Cloud { renderer, scene } => {
                job.point_frame(renderer, Scenes::One(scene), frame, plan, load_ms, events)
            }
            DeviceScene::Copc { renderer, copc } => {
                job.point_frame(renderer, Scenes::ByNode(copc), frame, plan, load_ms, events)
            }
            DeviceScene::Gaussians { renderer, gpu } => {
                job.gaussian_frame(renderer, gpu, frame, plan, load_ms, events)
            }
        }
    }
}

/// What `pointlens info` prints of the file at `path`, read whole (a COPC
/// file too) within `memory_mb`: a scene of 3D Gaussians by its count, SH
/// degree and bounds, a cloud by its points, attributes and spacing.
pub fn info_text(
    path: &Path,
    origin: Option<DVec3>,
    memory_mb: u64,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<String> {
    let kind = input::kind_of(path);
    let advice = match kind {
        InputKind::Copc => |_: &Path| "render reads a COPC file by node, at any size".to_string(),
        _ => input::convert_advice,
    };
    input::check_whole_read_fits(path, memory_mb, false, advice)?;
    if kind == InputKind::Gaussians {
        let scene = input::gaussians::load_gaussians(path)?;
        let (lo, hi) = scene.positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let v = |v: Vec3| format!("{} {} {}", v.x, v.y, v.z);
        return Ok(format!(
            "file: {}\ngaussians: {}\nsh_degree: {}\nbounds_min: {}\nbounds_max: {}\nextent: {}\n",
            path.display(),
            scene.len(),
            scene.sh_degree,
            v(lo),
            v(hi),
            v(hi - lo)
        ));
    }
    let cloud = load_logged(path, origin, progress)?;
    let (spacing, limited) =
        crate::tree::spacing_summary(&cloud.positions, crate::available_threads());
    Ok(format!(
        "{}isolated_points: {limited} (splats limited to {} times their neighbours' median spacing)\n",
        cloud.info_text(path, spacing),
        crate::tree::ISOLATED_LIMIT
    ))
}

/// Where each frame's scene comes from.
#[derive(Clone, Copy)]
pub enum Scenes<'a> {
    /// One scene for every frame (a cloud read whole).
    One(&'a Scene),
    /// A COPC file rendered by node: each frame's scene holds the nodes
    /// its camera needs.
    ByNode(&'a CopcScenes),
}

/// A frame's scene: the one scene, or the scene of a frame's nodes.
pub enum SceneRef<'a> {
    Borrowed(&'a Scene),
    Shared(Arc<Scene>),
}

impl std::ops::Deref for SceneRef<'_> {
    type Target = Scene;

    fn deref(&self) -> &Scene {
        match self {
            SceneRef::Borrowed(s) => s,
            SceneRef::Shared(s) => s,
        }
    }
}

impl<'a> Scenes<'a> {
    /// The scene of a frame through `camera` at level of detail `lod`.
    pub fn for_camera(
        self,
        renderer: &Renderer,
        camera: &Camera,
        lod: Lod,
    ) -> Result<SceneRef<'a>> {
        match self {
            Scenes::One(scene) => Ok(SceneRef::Borrowed(scene)),
            Scenes::ByNode(copc) => Ok(SceneRef::Shared(copc.scene_for(renderer, camera, lod)?)),
        }
    }
}

/// A splat of a frame of some of a COPC file's nodes is at most this many
/// times its node's spacing wide: its spacing from its neighbours in the
/// frame where that is less (a surface's one point per cell of the node's
/// grid sits about 1.2 spacings from its 8 nearest), and the limit of
/// isolated points ([`crate::tree::ISOLATED_LIMIT`]) where the frame holds
/// few of its neighbours.
pub const NODE_SPLAT_SPACINGS: f32 = crate::tree::ISOLATED_LIMIT;

/// The scenes of a COPC file rendered by node
/// ([`crate::input::copc::CopcClouds`]): a frame's nodes become a cloud,
/// colored as the whole file is, and a splat hierarchy, kept while the
/// next frame needs the same nodes.
pub struct CopcScenes {
    pub clouds: CopcClouds,
    pub splat: SplatSize,
    /// `--color` and the ranges it stretches over (the whole file's).
    pub color: Option<(ColorMode, ColorRanges)>,
    last: std::sync::Mutex<Option<(Vec<NodeEntry>, Arc<Scene>)>>,
}

impl CopcScenes {
    pub fn new(
        clouds: CopcClouds,
        splat: SplatSize,
        color: Option<(ColorMode, ColorRanges)>,
    ) -> CopcScenes {
        CopcScenes {
            clouds,
            splat,
            color,
            last: std::sync::Mutex::new(None),
        }
    }

    /// The scene of the nodes a frame through `camera` needs. The frustum
    /// is widened by the background's CoC (what the blurring methods'
    /// guard bands hold) and `--splat-px`.
    pub fn scene_for(&self, renderer: &Renderer, camera: &Camera, lod: Lod) -> Result<Arc<Scene>> {
        let widening = Widening {
            background_coc_px: camera.coc_px(f32::INFINITY),
            splat_px: match self.splat {
                SplatSize::Pixels(p) => p,
                _ => 0.0,
            },
        };
        let decide = |centre, r, spacing| {
            crate::tree::sphere_decision(camera, lod, widening, centre, r, spacing)
        };
        let selection = self.clouds.select(camera, lod, &decide)?;
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        let same = last.as_ref().filter(|(nodes, _)| *nodes == selection.nodes);
        log::info!(
            "COPC: {} nodes, {} of {} points{}{}",
            selection.nodes.len(),
            selection.points,
            self.clouds.total_points(),
            if selection.capped {
                " (stopped by --point-budget)"
            } else {
                ""
            },
            if same.is_some() {
                " (the last frame's)"
            } else {
                ""
            }
        );
        if let Some((_, scene)) = same {
            return Ok(scene.clone());
        }
        // The last frame's scene goes before this one is built.
        *last = None;
        let (mut cloud, spacing) = self.clouds.cloud_with_spacing(&selection.nodes)?;
        if let Some((mode, ranges)) = &self.color {
            crate::color::apply_over(&mut cloud, *mode, ranges)?;
        }
        // A frame of every node is the file read whole; in a frame of fewer,
        // a point is no wider than its node's spacing allows (a coarse node's
        // few points are far from each other: issue 47, defect 8).
        let scene = if selection.points == self.clouds.total_points() {
            renderer.upload(&cloud, self.splat)?
        } else {
            let most: Vec<f32> = spacing.iter().map(|s| NODE_SPLAT_SPACINGS * s).collect();
            renderer.upload_bounded(&cloud, self.splat, &most)?
        };
        let scene = Arc::new(scene);
        *last = Some((selection.nodes, scene.clone()));
        Ok(scene)
    }
}
