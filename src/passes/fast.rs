//! The fast method: its default gather is the bounded two-field gather
//! (`passes::fields`); Zhao's rule (DESIGN §4, `--fast-gather tree` or
//! `pixels`) is here as compute passes, each beside its GLSL file:
//! `fast_coc` (CoC and weight per pixel), `fast_tile_max` (largest CoC per
//! tile), `fast_tile_dilate` (each tile's gather radius), with
//! `--fast-gather tree` `fast_tree` (the block tree, one dispatch per
//! level), and `fast_gather` / `fast_gather_tree` (the z-tested, weighted
//! gather, pixel by pixel or by blocks: the same contributors,
//! docs/ARCHITECTURE.md).

use std::sync::{Arc, Mutex, OnceLock};

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::{check_square_loop, Configured, DofFrame, DofInput, DofMethod, FrameView, Specialized};
use crate::camera::{Aperture, ShapeRows};
use crate::error::{Error, Result};
use crate::options::{FastGather, FastOptions, FastWeights, GatherWindow};
use crate::push_constants;
use crate::vk::{groups, Access, Bind, Binding, Buffer, ComputePipeline, Context, Frame, Image};

/// Tile edge in pixels for the CoC bound.
pub const TILE: u32 = 16;
/// The most levels of the gather's block tree (mirrors
/// `glsl/fast_tree.glsl`): blocks of up to 2^14 px.
pub const TREE_LEVELS_MAX: u32 = 14;
/// The smallest gather radius (px) the tree takes by blocks (mirrors
/// `glsl/fast_tree.glsl`); smaller windows go pixel by pixel, which is
/// faster there (docs/BENCHMARKS.md).
pub const TREE_MIN_RADIUS_PX: u32 = 16;
/// The lowest level of the tree (mirrors `glsl/fast_tree.glsl`): blocks of
/// 4×4 px; one the gather can neither take nor leave whole it gathers pixel
/// by pixel (cheaper on llvmpipe than opening 2×2 blocks, docs/BENCHMARKS.md).
pub const TREE_LEAF_LEVEL: u32 = 2;

static COC: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_coc.comp.spv"));
static TILE_MAX: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_tile_max.comp.spv"));
static TILE_DILATE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_tile_dilate.comp.spv"));
static GATHER: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_gather.comp.spv"));
static GATHER_TREE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_gather_tree.comp.spv"));
static TREE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fast_tree.comp.spv"));

push_constants! {
    struct CocPush {
        extent: [i32; 2],
        f_px: f32,
        aperture_radius: f32,
        focus_distance: f32,
        area_weights: u32,
        shaped: u32,
        tap_count: i32,
        reach_max: f32,
        background_only: u32,
    }
}

push_constants! {
    struct TileMaxPush {
        extent: [i32; 2],
        tiles: [i32; 2],
        tile: i32,
    }
}

push_constants! {
    struct DilatePush {
        tiles: [i32; 2],
        tile: i32,
        reach: i32,
        fixed_radius: f32,
    }
}

push_constants! {
    struct GatherPush {
        extent: [i32; 2],
        origin: [i32; 2],
        size: [i32; 2],
        tile: i32,
        levels: i32,
        padded: [i32; 2],
        shaped: u32,
        focus_distance: f32,
        shape_inner_box: [f32; 2],
        shape_inner: f32,
        blade_cos: f32,
        shape_box: [f32; 4],
        base_from_lens: [f32; 4],
        curvature: f32,
    }
}

push_constants! {
    struct TreePush {
        extent: [i32; 2],
        padded: [i32; 2],
        level: i32,
    }
}

/// A gather per blade count N (0 to 16), made as a frame first needs it.
type BladeGathers = [OnceLock<ComputePipeline<GatherPush>>; 17];

/// The pipelines of the method.
pub struct Fast {
    coc: ComputePipeline<CocPush>,
    tile_max: ComputePipeline<TileMaxPush>,
    tile_dilate: ComputePipeline<DilatePush>,
    gather: Specialized<GatherPush>,
    tree: ComputePipeline<TreePush>,
    gather_tree: Specialized<GatherPush>,
    /// The gathers of shaped frames, made for one blade count N each
    /// (`BLADES` of `glsl/fast_gather.glsl`; 0 the squeezed circle, else
    /// 3 to 16) as a frame first needs them, at
    /// `[shaped only][tree][straight][N]`: made for shaped frames alone
    /// (`SHAPED_ONLY`, the disk's code compiled away) unless the
    /// specialized pipelines are off, and for straight blades or curved
    /// ones (`STRAIGHT`: no circle to test).
    shaped_gathers: [[[BladeGathers; 2]; 2]; 2],
    /// Whether frames take the pipelines made for them (the default), or
    /// the general ones ([`Fast::set_round_pipelines`]).
    specialized: bool,
    /// `--fast-gather fields`.
    fields: super::fields::Fields,
    /// The last shaped frame's reach thresholds, which the frames after it
    /// through the same aperture take while they reach far enough.
    tap_table: Mutex<Option<TapTable>>,
}

/// A shaped aperture's reach thresholds ([`Aperture::tap_thresholds`])
/// up to `reach_max` px of half-CoC.
#[derive(Clone)]
struct TapTable {
    aperture: Aperture,
    reach_max: f32,
    thresholds: Arc<Vec<f32>>,
}

impl TapTable {
    /// The table for a frame through `aperture` whose widest CoC is
    /// `max_coc_px`: `last` where it is that aperture's and reaches as far,
    /// else one made up to the next power of two of the half-CoC (at most
    /// [`MAX_TABLE_REACH_PX`]), so that an orbit's frames share it.
    fn for_frame(last: Option<&TapTable>, aperture: &Aperture, max_coc_px: f32) -> TapTable {
        // An unbounded scene's widest CoC (infinite or NaN): the cap.
        let half = 0.5 * max_coc_px + 1.0;
        let needed = match half.is_nan() {
            true => MAX_TABLE_REACH_PX,
            false => half.clamp(1.0, MAX_TABLE_REACH_PX),
        };
        if let Some(last) = last.filter(|t| t.aperture == *aperture && t.reach_max >= needed) {
            return last.clone();
        }
        let reach_max = needed.log2().ceil().exp2().min(MAX_TABLE_REACH_PX);
        TapTable {
            aperture: *aperture,
            reach_max,
            thresholds: Arc::new(aperture.tap_thresholds(reach_max)),
        }
    }
}

impl Fast {
    /// [`super::Methods::set_round_pipelines`] for both gathers.
    pub(super) fn set_round_pipelines(&mut self, enabled: bool) {
        self.gather.set_enabled(enabled);
        self.gather_tree.set_enabled(enabled);
        self.specialized = enabled;
    }

    /// The method's pipelines, the two-field gather's cut as `sizes` says.
    pub fn new(ctx: &Arc<Context>, sizes: super::kernel_sizes::KernelSizes) -> Result<Fast> {
        use Binding::{StorageBuffer as B, StorageImage as I};
        Ok(Fast {
            coc: ComputePipeline::new(ctx, "fast_coc", COC, &[I, I, B, B])?,
            tile_max: ComputePipeline::new(ctx, "fast_tile_max", TILE_MAX, &[I; 3])?,
            tile_dilate: ComputePipeline::new(ctx, "fast_tile_dilate", TILE_DILATE, &[I; 2])?,
            gather: Specialized::round(ctx, "fast_gather", GATHER, GATHER_BINDINGS)?,
            tree: ComputePipeline::new(ctx, "fast_tree", TREE, &[I, I, I, B, B, B])?,
            gather_tree: Specialized::round(
                ctx,
                "fast_gather_tree",
                GATHER_TREE,
                GATHER_TREE_BINDINGS,
            )?,
            fields: super::fields::Fields::new(ctx, sizes)?,
            shaped_gathers: Default::default(),
            tap_table: Mutex::new(None),
            specialized: true,
        })
    }

    /// The gather of a frame through `aperture`, by the tree where `tree`:
    /// through the round aperture, `gather`'s or `gather_tree`'s round
    /// pipeline; through a shape, the one made for its blade count and
    /// for shaped frames alone (made now if no frame has needed it yet).
    /// With the specialized pipelines off, the general pipeline, or for N
    /// blades one made for N alone. Either way a shape of blades takes a
    /// pipeline made for straight blades or for curved ones
    /// ([`Aperture::has_straight_blades`]). `fast` renders no image or cat's eye
    /// (`camera::APERTURE_FEATURES`).
    fn gather_for(
        &self,
        ctx: &Arc<Context>,
        aperture: &Aperture,
        tree: bool,
    ) -> Result<&ComputePipeline<GatherPush>> {
        let variants = if tree {
            &self.gather_tree
        } else {
            &self.gather
        };
        if aperture.is_round() || (aperture.blades == 0 && !self.specialized) {
            return Ok(variants.for_aperture(aperture));
        }
        let straight = aperture.has_straight_blades();
        let slot = &self.shaped_gathers[usize::from(self.specialized)][usize::from(tree)]
            [usize::from(straight)][aperture.blades as usize];
        if let Some(pipeline) = slot.get() {
            return Ok(pipeline);
        }
        let (name, spirv, bindings) = match tree {
            true => ("fast_gather_tree", GATHER_TREE, GATHER_TREE_BINDINGS),
            false => ("fast_gather", GATHER, GATHER_BINDINGS),
        };
        let mut constants = vec![
            (BLADES_ID, aperture.blades),
            (STRAIGHT_ID, u32::from(straight)),
        ];
        if self.specialized {
            constants.push((SHAPED_ONLY_ID, 1));
        }
        let pipeline = ComputePipeline::specialized(
            ctx,
            &format!(
                "{name} ({} blades, straight: {straight}, shaped only: {})",
                aperture.blades, self.specialized
            ),
            spirv,
            bindings,
            &constants,
        )?;
        Ok(slot.get_or_init(|| pipeline))
    }
}

/// The specialization constant `BLADES` of `glsl/fast_gather.glsl`.
const BLADES_ID: u32 = 1;

/// The specialization constant `SHAPED_ONLY` of `glsl/fast_gather.glsl`.
const SHAPED_ONLY_ID: u32 = 10;

/// The specialization constant `STRAIGHT` of `glsl/fast_gather.glsl`.
const STRAIGHT_ID: u32 = 11;

/// What the gathers bind: the G-buffer's color and eye, the CoCs and
/// weights, the tiles' radii and the result; the tree's sums, weights and
/// bounds after them.
const GATHER_BINDINGS: &[Binding] = &[Binding::StorageImage; 5];
const GATHER_TREE_BINDINGS: &[Binding] = &[
    Binding::StorageImage,
    Binding::StorageImage,
    Binding::StorageImage,
    Binding::StorageImage,
    Binding::StorageImage,
    Binding::StorageBuffer,
    Binding::StorageBuffer,
    Binding::StorageBuffer,
];

/// The levels of the block tree for gather radii up to `max_radius_px` in a
/// `width`×`height` G-buffer: the gather's largest blocks are no wider than
/// its radius, and no wider than the G-buffer (0: no tree; every window is
/// under [`TREE_MIN_RADIUS_PX`] and gathered pixel by pixel).
pub fn tree_levels(max_radius_px: f32, width: u32, height: u32) -> u32 {
    let radius = widest_window_px(max_radius_px, width, height);
    if radius < TREE_MIN_RADIUS_PX {
        return 0;
    }
    radius.ilog2().min(TREE_LEVELS_MAX)
}

/// The widest window radius the gather takes for tile radii up to
/// `max_radius_px` in a `width`×`height` G-buffer: whole pixels, clipped to
/// the G-buffer as `glsl/fast_gather.glsl` clips it.
fn widest_window_px(max_radius_px: f32, width: u32, height: u32) -> u32 {
    max_radius_px.floor().min(width.max(height) as f32) as u32
}

/// The pixel loop over the widest window it can get, against the device's
/// loop limit (`passes::check_square_loop`): refused where llvmpipe would
/// drop the rest of the window (the tree has no such loop).
fn check_pixel_loop(ctx: &Context, max_radius_px: f32, width: u32, height: u32) -> Result<()> {
    let r = widest_window_px(max_radius_px, width, height) as u64;
    check_square_loop(
        ctx,
        r,
        "the fast gather's pixel loop over windows",
        "use --fast-gather tree, the same rule by blocks (or the default two-field gather)",
    )
}

/// The G-buffer size the tree's levels are laid out for: `width`×`height`
/// rounded up to a multiple of 2^levels (`glsl/fast_tree.glsl`).
pub fn tree_padded(levels: u32, width: u32, height: u32) -> [u32; 2] {
    let block = 1 << levels;
    [
        width.next_multiple_of(block),
        height.next_multiple_of(block),
    ]
}

/// Blocks of the tree's levels together (`TREE_LEAF_LEVEL` to `levels`),
/// in its padded layout.
pub fn tree_blocks(levels: u32, width: u32, height: u32) -> u64 {
    let [pw, ph] = tree_padded(levels, width, height);
    (TREE_LEAF_LEVEL..=levels)
        .map(|l| (pw >> l) as u64 * (ph >> l) as u64)
        .sum()
}

/// The index of block (x, y) of level `level` in the padded layout (mirrors
/// `tree_index` in `glsl/fast_tree.glsl`, which sums the levels before it
/// as a geometric series).
pub fn tree_index(padded: [u32; 2], level: u32, x: u32, y: u32) -> u64 {
    let pixels = padded[0] as u64 * padded[1] as u64;
    let before = ((pixels >> (2 * (TREE_LEAF_LEVEL - 1))) - (pixels >> (2 * (level - 1)))) / 3;
    before + y as u64 * (padded[0] >> level) as u64 + x as u64
}

/// Every pixel blurs, the background too: the default guard band.
impl DofMethod for Configured<'_, Fast, FastOptions> {
    fn prepare<'m>(
        &'m self,
        ctx: &Arc<Context>,
        view: &FrameView,
    ) -> Result<Box<dyn DofFrame + 'm>> {
        if view.camera.aperture.is_shaped() && self.options.gather == FastGather::Fields {
            return Err(Error::InvalidArgument(
                "--method fast renders a shaped aperture with --fast-gather tree or pixels (the fields gather sums disks)".into(),
            ));
        }
        if self.options.gather == FastGather::Fields {
            return Ok(Box::new(super::fields::FieldsFrame::new(
                ctx,
                &self.pipelines.fields,
                view,
            )?));
        }
        let images = FastImages::new(ctx, view, self.options, &self.pipelines.tap_table)?;
        let gather =
            self.pipelines
                .gather_for(ctx, &view.camera.aperture, images.tree.is_some())?;
        Ok(Box::new(FastFrame {
            method: self,
            images,
            gather,
        }))
    }
}

/// The widest half-CoC (px) of a table of reach thresholds
/// (`Aperture::tap_thresholds`): some 170,000 pixel offsets, sorted on the
/// host in 15–25 ms, then kept for the frames after it.
const MAX_TABLE_REACH_PX: f32 = 256.0;

/// What the passes push of a shaped aperture (the disk's defaults where
/// there is no shape).
struct ShapeTerms {
    shaped: u32,
    /// [`ShapeRows::inner_radius`].
    inner: f32,
    /// [`ShapeRows::inner_box`].
    inner_box: [f32; 2],
    /// [`Aperture::lens_bounding_box`]: of the shape itself, which the
    /// gathers' taps test, not of its chords.
    bounding_box: [f32; 4],
}

impl ShapeTerms {
    fn of(aperture: &Aperture, shape: Option<&ShapeRows>) -> ShapeTerms {
        match shape {
            Some(s) => ShapeTerms {
                shaped: 1,
                inner: s.inner_radius(),
                inner_box: s.inner_box(),
                bounding_box: aperture.lens_bounding_box(),
            },
            None => ShapeTerms {
                shaped: 0,
                inner: 1.0,
                inner_box: [0.0; 2],
                bounding_box: [-1.0, 1.0, -1.0, 1.0],
            },
        }
    }
}

/// The images of one frame of the method.
struct FastImages {
    /// A shaped aperture's terms.
    shape: ShapeTerms,
    /// Its reach thresholds up to `reach_max` px of half-CoC, `tap_count`
    /// of them ([`Aperture::tap_thresholds`]; one unused entry for the
    /// disk).
    tap_thresholds: Buffer,
    tap_count: i32,
    reach_max: f32,
    /// The background's pixel count (`fast_coc.comp`), one float.
    background_count: Buffer,
    coc_weight: Image,
    tile_max: Image,
    tile_radius: Image,
    /// The result: G-buffer sized, written inside the guard band only.
    result: Image,
    /// The block tree (`--fast-gather tree`; none where no window is wide
    /// enough for a block).
    tree: Option<FastTree>,
}

/// The gather's block tree (`glsl/fast_tree.glsl`): per block of levels
/// `TREE_LEAF_LEVEL` to `levels`, its pixels' weighted colors and weights
/// summed, and the bounds of their depths and CoCs.
struct FastTree {
    levels: u32,
    /// Blocks of all levels, the padding's included.
    blocks: u64,
    padded: [u32; 2],
    /// Σ w · rgba per block (4 floats).
    sums: Buffer,
    /// Σ w per block.
    weights: Buffer,
    /// z min, z max, c min, c max per block.
    bounds: Buffer,
}

impl FastTree {
    fn new(ctx: &Arc<Context>, levels: u32, w: u32, h: u32) -> Result<FastTree> {
        let blocks = tree_blocks(levels, w, h);
        let limit = ctx.info.largest_storage_buffer_bytes();
        // The shader's indices are 32-bit.
        if 16 * blocks > limit || blocks > u32::MAX as u64 {
            return Err(Error::InvalidArgument(format!(
                "the fast gather's block tree for a {w}×{h} G-buffer ({} bytes) exceeds the device's {limit}-byte buffer limit; use --fast-gather pixels",
                16 * blocks
            )));
        }
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let buffer = |name, bytes| Buffer::new(ctx, name, bytes, usage, MemoryLocation::GpuOnly);
        Ok(FastTree {
            levels,
            blocks,
            padded: tree_padded(levels, w, h),
            sums: buffer("fast tree sums", 16 * blocks)?,
            weights: buffer("fast tree weights", 4 * blocks)?,
            bounds: buffer("fast tree bounds", 16 * blocks)?,
        })
    }
}

impl FastImages {
    fn new(
        ctx: &Arc<Context>,
        view: &FrameView,
        options: FastOptions,
        tap_table: &Mutex<Option<TapTable>>,
    ) -> Result<FastImages> {
        let (w, h) = (view.full_width(), view.full_height());
        // The widest window a tile can get (tile_dilate's radius, at most
        // the frame's largest CoC / 2; the fixed window's at least 0.5).
        let max_radius_px = (view.max_coc_px / 2.0).max(0.5);
        let levels = match options.gather {
            FastGather::Tree => tree_levels(max_radius_px, w, h),
            // `prepare` makes a fields frame instead.
            FastGather::Fields => 0,
            FastGather::Pixels => {
                check_pixel_loop(ctx, max_radius_px, w, h)?;
                0
            }
        };
        let tree = match levels {
            0 => None,
            _ => Some(FastTree::new(ctx, levels, w, h)?),
        };
        let (tw, th) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let storage = vk::ImageUsageFlags::STORAGE;
        let image = |name, format, w, h, usage| Image::new_2d(ctx, name, format, w, h, 1, usage);
        let aperture = &view.camera.aperture;
        let shape = aperture
            .is_shaped()
            .then(|| aperture.shape_rows(super::SHAPE_ROWS));
        // The thresholds up to the frame's widest CoC (past the table's
        // reach the count grows with the area).
        let (reach_max, thresholds) = match shape {
            Some(_) => {
                let mut last = tap_table.lock().unwrap_or_else(|e| e.into_inner());
                let table = TapTable::for_frame(last.as_ref(), aperture, view.max_coc_px);
                *last = Some(table.clone());
                (table.reach_max, table.thresholds)
            }
            None => (1.0, Arc::new(vec![0.0])),
        };
        Ok(FastImages {
            shape: ShapeTerms::of(aperture, shape.as_ref()),
            tap_thresholds: Buffer::with_bytes(
                ctx,
                "fast tap thresholds",
                bytemuck::cast_slice(thresholds.as_slice()),
                vk::BufferUsageFlags::STORAGE_BUFFER,
            )?,
            tap_count: thresholds.len() as i32,
            reach_max,
            background_count: Buffer::new(
                ctx,
                "fast background count",
                4,
                vk::BufferUsageFlags::STORAGE_BUFFER,
                MemoryLocation::GpuOnly,
            )?,
            coc_weight: image("fast coc", vk::Format::R32G32_SFLOAT, w, h, storage)?,
            tile_max: image("fast tile max", vk::Format::R32G32_SFLOAT, tw, th, storage)?,
            tile_radius: image(
                "fast tile radius",
                vk::Format::R32G32_SFLOAT,
                tw,
                th,
                storage,
            )?,
            result: image(
                "fast result",
                vk::Format::R16G16B16A16_SFLOAT,
                w,
                h,
                storage | vk::ImageUsageFlags::TRANSFER_SRC,
            )?,
            tree,
        })
    }
}

struct FastFrame<'m> {
    method: &'m Configured<'m, Fast, FastOptions>,
    images: FastImages,
    /// The gather for the frame's aperture ([`Fast::gather_for`]).
    gather: &'m ComputePipeline<GatherPush>,
}

impl FastFrame<'_> {
    /// Pass `fast.coc`: each G-buffer pixel's CoC and weight from its eye
    /// depth. `extent`: the G-buffer's size.
    fn record_coc<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>, extent: [i32; 2]) {
        let p = self.method.pipelines;
        let options = self.method.options;
        let images = &self.images;
        let camera = &input.view.camera;
        let [w, h] = extent;
        frame.pass("fast.coc", |rec| {
            rec.barriers(&[
                (input.eye, Access::COMPUTE_READ_WRITE, Access::COMPUTE_READ),
                (&images.coc_weight, Access::NONE, Access::COMPUTE_WRITE),
            ]);
            let binds = [
                Bind::StorageImage(input.eye),
                Bind::StorageImage(&images.coc_weight),
                Bind::StorageBuffer(&images.tap_thresholds),
                Bind::StorageBuffer(&images.background_count),
            ];
            let push = |background_only: bool| CocPush {
                extent: [w, h],
                f_px: camera.f_px(),
                aperture_radius: camera.aperture_radius,
                focus_distance: camera.focus_distance,
                area_weights: (options.weights == FastWeights::Area) as u32,
                shaped: images.shape.shaped,
                tap_count: images.tap_count,
                reach_max: images.reach_max,
                background_only: background_only as u32,
            };
            // The background's count, once; then every pixel's, the
            // background's read from it.
            rec.memory_barrier(Access::COMPUTE_READ, Access::COMPUTE_WRITE);
            rec.dispatch(&p.coc, &binds, &push(true), [1, 1, 1]);
            rec.memory_barrier(Access::COMPUTE_WRITE, Access::COMPUTE_READ);
            rec.dispatch(
                &p.coc,
                &binds,
                &push(false),
                [groups(w as u32, 8), groups(h as u32, 8), 1],
            );
        });
    }

    /// Passes `fast.tile_max` and `fast.tile_dilate`: each tile's largest
    /// CoC, then the radius its gather reaches from its neighbours'.
    fn record_tiles<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>, extent: [i32; 2]) {
        let p = self.method.pipelines;
        let options = self.method.options;
        let images = &self.images;
        let view = &input.view;
        let [w, h] = extent;
        let tiles = [
            images.tile_max.width() as i32,
            images.tile_max.height() as i32,
        ];
        frame.pass("fast.tile_max", |rec| {
            rec.barriers(&[
                (
                    &images.coc_weight,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_READ,
                ),
                (&images.tile_max, Access::NONE, Access::COMPUTE_WRITE),
            ]);
            rec.dispatch(
                &p.tile_max,
                &[
                    Bind::StorageImage(&images.coc_weight),
                    Bind::StorageImage(&images.tile_max),
                    Bind::StorageImage(input.eye),
                ],
                &TileMaxPush {
                    extent: [w, h],
                    tiles,
                    tile: TILE as i32,
                },
                [groups(tiles[0] as u32, 8), groups(tiles[1] as u32, 8), 1],
            );
        });
        frame.pass("fast.tile_dilate", |rec| {
            rec.barriers(&[
                (
                    &images.tile_max,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_READ,
                ),
                (&images.tile_radius, Access::NONE, Access::COMPUTE_WRITE),
            ]);
            rec.dispatch(
                &p.tile_dilate,
                &[
                    Bind::StorageImage(&images.tile_max),
                    Bind::StorageImage(&images.tile_radius),
                ],
                &DilatePush {
                    tiles,
                    tile: TILE as i32,
                    // No farther than the grid of tiles reaches.
                    reach: ((view.max_coc_px / 2.0 / TILE as f32).ceil() as i32)
                        .min(tiles[0].max(tiles[1]))
                        + 1,
                    fixed_radius: match options.window {
                        GatherWindow::Tiles => 0.0,
                        GatherWindow::Fixed => (view.max_coc_px / 2.0).max(0.5),
                    },
                },
                [groups(tiles[0] as u32, 8), groups(tiles[1] as u32, 8), 1],
            );
        });
    }

    /// Pass `fast.tree`: the gather's tree of block sums, level by level
    /// from the leaves.
    fn record_tree<'r>(
        &'r self,
        frame: &mut Frame<'r>,
        input: &DofInput<'r>,
        tree: &'r FastTree,
        extent: [i32; 2],
    ) {
        let p = self.method.pipelines;
        let images = &self.images;
        let [w, h] = extent;
        frame.pass("fast.tree", |rec| {
            rec.barriers(&[
                (input.color, Access::COMPUTE_WRITE, Access::COMPUTE_READ),
                (
                    &images.coc_weight,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_READ,
                ),
            ]);
            // The previous frame's gather read the buffers.
            rec.memory_barrier(Access::COMPUTE_READ, Access::COMPUTE_WRITE);
            for level in TREE_LEAF_LEVEL..=tree.levels {
                if level > TREE_LEAF_LEVEL {
                    rec.memory_barrier(Access::COMPUTE_WRITE, Access::COMPUTE_READ_WRITE);
                }
                let (bw, bh) = (
                    (w as u32).div_ceil(1 << level),
                    (h as u32).div_ceil(1 << level),
                );
                rec.dispatch(
                    &p.tree,
                    &[
                        Bind::StorageImage(input.color),
                        Bind::StorageImage(input.eye),
                        Bind::StorageImage(&images.coc_weight),
                        Bind::StorageBuffer(&tree.sums),
                        Bind::StorageBuffer(&tree.weights),
                        Bind::StorageBuffer(&tree.bounds),
                    ],
                    &TreePush {
                        extent: [w, h],
                        padded: tree.padded.map(|v| v as i32),
                        level: level as i32,
                    },
                    [groups(bw, 8), groups(bh, 8), 1],
                );
            }
        });
    }

    /// Pass `fast.gather`: each output pixel's gather, through the tree
    /// where there is one.
    fn record_gather<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>, extent: [i32; 2]) {
        let images = &self.images;
        let view = &input.view;
        let [w, h] = extent;
        let g = view.guard as i32;
        frame.pass("fast.gather", |rec| {
            rec.barriers(&[
                (input.color, Access::COMPUTE_WRITE, Access::COMPUTE_READ),
                (
                    &images.tile_radius,
                    Access::COMPUTE_WRITE,
                    Access::COMPUTE_READ,
                ),
                (&images.result, Access::NONE, Access::COMPUTE_WRITE),
            ]);
            let (ow, oh) = (view.window.width, view.window.height);
            let mut binds = vec![
                Bind::StorageImage(input.color),
                Bind::StorageImage(input.eye),
                Bind::StorageImage(&images.coc_weight),
                Bind::StorageImage(&images.tile_radius),
                Bind::StorageImage(&images.result),
            ];
            let camera = &view.camera;
            if let Some(tree) = &images.tree {
                rec.memory_barrier(Access::COMPUTE_WRITE, Access::COMPUTE_READ);
                binds.extend([
                    Bind::StorageBuffer(&tree.sums),
                    Bind::StorageBuffer(&tree.weights),
                    Bind::StorageBuffer(&tree.bounds),
                ]);
            }
            let aperture = &camera.aperture;
            rec.dispatch(
                self.gather,
                &binds,
                &GatherPush {
                    extent: [w, h],
                    origin: [g, g],
                    size: [ow as i32, oh as i32],
                    tile: TILE as i32,
                    levels: images.tree.as_ref().map_or(0, |t| t.levels as i32),
                    padded: images
                        .tree
                        .as_ref()
                        .map_or([w, h], |t| t.padded.map(|v| v as i32)),
                    shaped: images.shape.shaped,
                    focus_distance: camera.focus_distance,
                    shape_inner_box: images.shape.inner_box,
                    shape_inner: images.shape.inner,
                    blade_cos: aperture.blade_cos(),
                    shape_box: images.shape.bounding_box,
                    base_from_lens: aperture.base_from_lens(),
                    curvature: aperture.curvature,
                },
                [groups(ow, 8), groups(oh, 8), 1],
            );
        });
    }
}

impl DofFrame for FastFrame<'_> {
    /// The passes. `view.max_coc_px` bounds every pixel's CoC, the
    /// background's included.
    fn record<'r>(&'r self, frame: &mut Frame<'r>, input: &DofInput<'r>) -> &'r Image {
        let extent = [input.color.width() as i32, input.color.height() as i32];
        self.record_coc(frame, input, extent);
        self.record_tiles(frame, input, extent);
        if let Some(tree) = &self.images.tree {
            self.record_tree(frame, input, tree, extent);
        }
        self.record_gather(frame, input, extent);
        &self.images.result
    }

    /// The blocks of the gather's tree, all levels (0: every window pixel
    /// by pixel).
    fn counts(&self) -> Vec<(String, u64)> {
        let blocks = self.images.tree.as_ref().map_or(0, |t| t.blocks);
        vec![("fast.tree_blocks".to_string(), blocks)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::check_push_layout;

    /// A shaped frame's table of reach thresholds is the last one where
    /// the aperture is the same and it reaches as far, else one made to the
    /// next power of two of the half-CoC: the same counts either way.
    #[test]
    fn frames_share_a_table_that_reaches_far_enough() {
        let six = Aperture {
            blades: 6,
            ..Aperture::ROUND
        };
        let first = TapTable::for_frame(None, &six, 30.0);
        assert_eq!(first.reach_max, 16.0);
        let again = TapTable::for_frame(Some(&first), &six, 20.0);
        assert!(Arc::ptr_eq(&first.thresholds, &again.thresholds));
        let wider = TapTable::for_frame(Some(&first), &six, 100.0);
        assert_eq!(wider.reach_max, 64.0);
        let five = Aperture { blades: 5, ..six };
        let other = TapTable::for_frame(Some(&first), &five, 20.0);
        assert!(!Arc::ptr_eq(&first.thresholds, &other.thresholds));
        assert_eq!(other.thresholds.len(), five.tap_thresholds(16.0).len());
        // The wider table counts the narrower one's reach alike.
        let count = |t: &TapTable, h: f32| t.thresholds.partition_point(|&x| x <= h);
        for h in [0.5, 3.3, 9.9, 15.7] {
            assert_eq!(count(&first, h), count(&wider, h));
        }
        for widest in [5000.0, f32::INFINITY, f32::NAN] {
            let huge = TapTable::for_frame(None, &six, widest);
            assert_eq!(huge.reach_max, MAX_TABLE_REACH_PX, "{widest}");
        }
    }

    #[test]
    fn push_constants_match_the_glsl_blocks() {
        check_push_layout::<CocPush>("fast_coc", COC).unwrap();
        check_push_layout::<TileMaxPush>("fast_tile_max", TILE_MAX).unwrap();
        check_push_layout::<DilatePush>("fast_tile_dilate", TILE_DILATE).unwrap();
        check_push_layout::<GatherPush>("fast_gather", GATHER).unwrap();
        check_push_layout::<GatherPush>("fast_gather_tree", GATHER_TREE).unwrap();
        check_push_layout::<TreePush>("fast_tree", TREE).unwrap();
    }

    #[test]
    fn tree_constants_match_the_glsl() {
        let glsl = include_str!("../../glsl/fast_tree.glsl");
        assert!(glsl.contains(&format!("const int TREE_LEVELS_MAX = {TREE_LEVELS_MAX};")));
        assert!(glsl.contains(&format!(
            "const int TREE_MIN_RADIUS = {TREE_MIN_RADIUS_PX};"
        )));
        assert!(glsl.contains(&format!("const int TREE_LEAF_LEVEL = {TREE_LEAF_LEVEL};")));
    }

    #[test]
    fn tree_levels_keep_blocks_within_the_radius_and_the_frame() {
        assert_eq!(tree_levels(15.9, 100, 100), 0);
        assert_eq!(tree_levels(16.0, 100, 100), 4);
        assert_eq!(tree_levels(35.5, 640, 480), 5);
        assert_eq!(tree_levels(300.0, 64, 40), 6);
        assert_eq!(tree_levels(300.0, 12, 12), 0);
        assert_eq!(tree_levels(1e9, 1 << 20, 4), TREE_LEVELS_MAX);
        // The smallest tree has levels above its leaves.
        assert!(tree_levels(TREE_MIN_RADIUS_PX as f32, 1000, 1000) > TREE_LEAF_LEVEL);
        // 17×3 padded to 32×16: 8×4 blocks of 4 px (level 2), 4×2 of 8 px,
        // 2×1 of 16 px.
        assert_eq!(tree_padded(3, 5, 3), [8, 8]);
        assert_eq!(tree_padded(4, 17, 3), [32, 16]);
        assert_eq!(tree_blocks(4, 17, 3), 8 * 4 + 4 * 2 + 2);
    }

    #[test]
    fn tree_index_is_the_levels_laid_one_after_another() {
        for (levels, w, h) in [(2, 7, 5), (4, 33, 17), (5, 640, 480), (7, 1000, 3)] {
            let padded = tree_padded(levels, w, h);
            let mut next = 0;
            for l in TREE_LEAF_LEVEL..=levels {
                for y in 0..padded[1] >> l {
                    for x in 0..padded[0] >> l {
                        assert_eq!(tree_index(padded, l, x, y), next, "{levels} {w}×{h} {l}");
                        next += 1;
                    }
                }
            }
            assert_eq!(next, tree_blocks(levels, w, h));
        }
        let glsl = include_str!("../../glsl/fast_tree.glsl");
        assert!(glsl.contains(
            "uint before = ((pixels >> (2 * (TREE_LEAF_LEVEL - 1))) - (pixels >> (2 * (l - 1)))) / 3u;"
        ));
    }
}
