//! What a frame is asked to compute: the depth-of-field method and its
//! options, with the one parser of their names and the one range check of
//! each number. Plain data: the GPU passes (`crate::passes`), the CPU
//! references (`crate::reference`), `render` and `bench` all read these
//! types, and none of them depends on another for it.

use clap::ValueEnum;

use crate::error::{Error, Result};

/// How each pixel's contribution to the fast gather is weighted
/// (`--fast-weights`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ValueEnum)]
pub enum FastWeights {
    /// By the inverse of the number of pixel centres inside its CoC disk
    /// (DESIGN §4's default: a point spreads its light over its disk).
    #[default]
    Area,
    /// Every contributor alike: the paper's plain mean.
    Uniform,
}

/// How far the fast gather looks (`--fast-window`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ValueEnum)]
pub enum GatherWindow {
    /// Each tile's dilated maximum CoC (DESIGN §4).
    #[default]
    Tiles,
    /// The frame's largest CoC everywhere: the fixed worst-case window, kept
    /// only as the benchmark baseline.
    Fixed,
}

/// How the fast method gathers (`--fast-gather`): the bounded two-field
/// gather (the default), or DESIGN §4's rule, the paper's, by a block
/// tree or pixel by pixel (the same pixels contribute either way, the
/// float sums round differently).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ValueEnum)]
pub enum FastGather {
    /// Not DESIGN §4's rule but the bounded two-field gather (issue 28,
    /// item 5; `crate::fields`): a surface's front (the near field's
    /// bands, the far field's taps in front of it) as alpha over its
    /// normalised back, a bounded number of taps whatever the CoC. The
    /// default: 7–12 dB closer to Mitsuba's references than the paper's
    /// rule, 2.3–8.6× faster than Mitsuba at its own PSNR where the rule
    /// is 0.06–0.79× (docs/BENCHMARKS.md). `--fast-weights` and
    /// `--fast-window` do not apply.
    #[default]
    Fields,
    /// DESIGN §4's rule by blocks of a tree of 2^l-pixel blocks, each
    /// taken whole where every pixel of it passes the gather's tests and
    /// opened where only some may: the cost follows the disk's rim, not
    /// its area (docs/BENCHMARKS.md).
    Tree,
    /// DESIGN §4's rule pixel by pixel over the window: the paper's loop.
    Pixels,
}

/// How the G-buffer's splats are rasterised (`--raster`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ValueEnum)]
pub enum Raster {
    /// Compute where the device has 64-bit buffer atomics, else sprites
    /// (docs/BENCHMARKS.md, "The compute rasteriser").
    #[default]
    Auto,
    /// Hardware point sprites (the reference).
    Sprites,
    /// Compute shaders into a 64-bit visibility buffer (every sample of a
    /// pixel in one pass, any splat size).
    Compute,
}

/// How the G-buffer weighs the splats within a pixel (`--coverage`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ValueEnum)]
pub enum Coverage {
    /// By area: a pixel whose samples do not all see one splat is made of
    /// the nearest splats its samples and its neighbours' found, each by
    /// the part of the pixel it covers in front of the others (exact for
    /// square splats). Where it cannot act (the sprite raster, disc
    /// splats, several lens positions: `accum`), the samples' mean.
    #[default]
    Area,
    /// The mean of the pixel's K×K samples.
    Samples,
}

/// The shape of a splat in the image (`--splat-shape`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ValueEnum)]
pub enum SplatShape {
    /// A screen-aligned square (DESIGN §3).
    #[default]
    Square,
    /// The disc inscribed in that square: a screen-aligned circle of the
    /// same diameter, anti-aliased through the G-buffer's samples alike.
    Disc,
}

/// Which rays an RDB bin receives (`--rdb-mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ValueEnum)]
pub enum RdbMode {
    /// Each bin sampled by the ray through its lens cell's centre.
    #[default]
    Centre,
    /// The paper's literal pair-to-bin assignment.
    Pairs,
}

/// Which atomics the RDB's scatter uses (`--rdb-atomics`); both give the
/// same image, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ValueEnum)]
pub enum RdbAtomics {
    /// 64-bit where the device has 64-bit buffer atomics, else 32-bit.
    #[default]
    Auto,
    /// One scatter pass of 64-bit (tag, depth, source) words into a buffer
    /// that is never cleared per frame.
    #[value(name = "64")]
    Int64,
    /// Two scatter passes (depth, then source) of 32-bit image atomics
    /// into images cleared for every tile.
    #[value(name = "32")]
    Int32,
}

/// Options of the fast method: its gather and, for DESIGN §4's rule, the
/// rule's weights and window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FastOptions {
    pub weights: FastWeights,
    pub window: GatherWindow,
    pub gather: FastGather,
}

impl FastOptions {
    /// DESIGN §4's rule as the paper gives it (area weights, the tiles'
    /// windows), by the block tree.
    pub const PAPER: FastOptions = FastOptions {
        weights: FastWeights::Area,
        window: GatherWindow::Tiles,
        gather: FastGather::Tree,
    };

    /// The one check of the options: the rule's weights and window are not
    /// the two-field gather's, which would ignore them.
    pub fn check(self) -> Result<()> {
        let fields = self.gather == FastGather::Fields;
        if fields && (self.weights != FastWeights::Area || self.window != GatherWindow::Tiles) {
            return Err(Error::InvalidArgument(
                "--fast-weights uniform and --fast-window fixed are options of the paper's rule \
                 (--fast-gather tree or pixels), not of the two-field gather (--fast-gather \
                 fields, the default)"
                    .into(),
            ));
        }
        Ok(())
    }
}

/// Options of the ray distribution buffer (DESIGN §5).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RdbOptions {
    /// N: N×N lens bins per pixel, 2 to 16 ([`check_rdb_bins`]).
    pub bins: u32,
    pub mode: RdbMode,
    /// Memory for the bins, bytes; above it the frame is processed in
    /// tiles. None: a quarter of the largest device-local heap.
    pub memory_bytes: Option<u64>,
    pub atomics: RdbAtomics,
}

impl Default for RdbOptions {
    fn default() -> Self {
        RdbOptions {
            bins: DEFAULT_RDB_BINS,
            mode: RdbMode::Centre,
            memory_bytes: None,
            atomics: RdbAtomics::Auto,
        }
    }
}

/// Options of the accumulation reference (DESIGN §7).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AccumOptions {
    /// Lens samples, at least 1.
    pub samples: u32,
}

impl Default for AccumOptions {
    fn default() -> Self {
        AccumOptions {
            samples: DEFAULT_SAMPLES,
        }
    }
}

/// Eye-dome lighting (`--edl STRENGTH[,RADIUS_PX]`, `passes::edl`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdlOptions {
    /// 0 changes nothing; 1 is Potree's default.
    pub strength: f32,
    /// How far the neighbours are, output pixels.
    pub radius_px: f32,
}

/// The default neighbour distance of eye-dome lighting (Potree's).
pub const DEFAULT_EDL_RADIUS_PX: f32 = 1.4;

impl EdlOptions {
    /// Parses `STRENGTH[,RADIUS_PX]`: strength finite in [0, 100], radius
    /// in [1, 32] pixels (default [`DEFAULT_EDL_RADIUS_PX`]).
    pub fn parse(s: &str) -> std::result::Result<EdlOptions, String> {
        let bad = || format!("--edl takes STRENGTH[,RADIUS_PX] (e.g. 1 or 1,2), not '{s}'");
        let mut parts = s.split(',');
        let strength: f32 = parts
            .next()
            .and_then(|v| v.trim().parse().ok())
            .ok_or_else(bad)?;
        let radius_px: f32 = match parts.next() {
            Some(v) => v.trim().parse().map_err(|_| bad())?,
            None => DEFAULT_EDL_RADIUS_PX,
        };
        if parts.next().is_some() {
            return Err(bad());
        }
        if !(0.0..=100.0).contains(&strength) {
            return Err(format!(
                "--edl strength must be in [0, 100], not {strength}"
            ));
        }
        if !(1.0..=32.0).contains(&radius_px) {
            return Err(format!(
                "--edl radius must be in [1, 32] pixels, not {radius_px}"
            ));
        }
        Ok(EdlOptions {
            strength,
            radius_px,
        })
    }
}

/// Options of the layered method (DESIGN §6).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LayeredOptions {
    /// K: depth-peeled G-buffer layers, in 1..=8 ([`check_layers`]).
    pub layers: u32,
    /// Keep every occluded pixel of the later layers (the plain peel)
    /// instead of only those that can be seen through the lens (the
    /// paper's modified peel, the default): for comparisons.
    pub keep_occluded: bool,
}

impl Default for LayeredOptions {
    fn default() -> Self {
        LayeredOptions {
            layers: DEFAULT_LAYERS,
            keep_occluded: false,
        }
    }
}

/// The depth-of-field methods of DESIGN §8, each with its options.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// No depth of field: the resolved G-buffer color.
    Pinhole,
    /// The fast method: the bounded two-field gather by default, or Zhao's
    /// rule (a z-tested gather bounded by tile CoCs; [`FastGather`]).
    Fast(FastOptions),
    /// The ray distribution buffer: N×N lens bins per pixel.
    Rdb(RdbOptions),
    /// The accumulation-buffer reference: the splats rendered through
    /// `samples` lens positions with the sheared projection, averaged.
    Accum(AccumOptions),
    /// Yu et al.'s layered method: K depth-peeled layers, each pixel's
    /// color spread over its CoC, composited back to front.
    Layered(LayeredOptions),
}

/// A method's name alone (`--method`), without its options.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MethodKind {
    Pinhole,
    Fast,
    Rdb,
    Accum,
    Layered,
}

impl MethodKind {
    /// Every method this build implements, in the order help texts list them.
    pub const ALL: [MethodKind; 5] = [
        MethodKind::Pinhole,
        MethodKind::Fast,
        MethodKind::Rdb,
        MethodKind::Layered,
        MethodKind::Accum,
    ];

    pub fn name(self) -> &'static str {
        match self {
            MethodKind::Pinhole => "pinhole",
            MethodKind::Fast => "fast",
            MethodKind::Rdb => "rdb",
            MethodKind::Accum => "accum",
            MethodKind::Layered => "layered",
        }
    }

    /// Parses a method name; the error names the methods that exist.
    pub fn parse(name: &str) -> Result<MethodKind> {
        if let Some(kind) = Self::ALL.into_iter().find(|k| k.name() == name) {
            return Ok(kind);
        }
        let available = Self::ALL.map(MethodKind::name).join(", ");
        Err(Error::InvalidArgument(format!(
            "unknown method '{name}'; available methods: {available}"
        )))
    }

    /// The method with the options `flags` give, each other option at its
    /// default. A flag given that this method does not read is refused in
    /// one line ([`METHOD_FLAGS`]): it cannot act on the frame.
    pub fn with_flags(self, flags: &MethodFlags) -> Result<Method> {
        if let Some(f) = METHOD_FLAGS
            .iter()
            .find(|f| (f.given)(flags) && !f.kinds.contains(&self))
        {
            let names: Vec<&str> = f.kinds.iter().map(|k| k.name()).collect();
            return Err(Error::InvalidArgument(format!(
                "{} acts on --method {} only, not {}",
                f.flag,
                names.join(" or "),
                self.name()
            )));
        }
        let fast = FastOptions::default();
        let rdb = RdbOptions::default();
        Ok(match self {
            MethodKind::Pinhole => Method::Pinhole,
            MethodKind::Fast => Method::Fast(FastOptions {
                weights: flags.fast_weights.unwrap_or(fast.weights),
                window: flags.fast_window.unwrap_or(fast.window),
                gather: flags.fast_gather.unwrap_or(fast.gather),
            }),
            MethodKind::Rdb => Method::Rdb(RdbOptions {
                bins: flags.rdb_bins.unwrap_or(rdb.bins),
                mode: flags.rdb_mode.unwrap_or(rdb.mode),
                memory_bytes: flags.rdb_memory_mb.map(|mb| mb << 20),
                atomics: flags.rdb_atomics.unwrap_or(rdb.atomics),
            }),
            MethodKind::Accum => Method::Accum(AccumOptions {
                samples: flags.samples.unwrap_or(DEFAULT_SAMPLES),
            }),
            MethodKind::Layered => Method::Layered(LayeredOptions {
                layers: flags.layers.unwrap_or(DEFAULT_LAYERS),
                ..LayeredOptions::default()
            }),
        })
    }
}

/// Refuses eye-dome lighting (`--edl`) with `method` where it cannot act:
/// `accum` averages a G-buffer per lens position and has none to shade.
pub fn check_edl_with(method: &Method) -> Result<()> {
    match method {
        Method::Accum(_) => Err(Error::InvalidArgument(
            "--edl shades the one G-buffer a depth-of-field method blurs; accum averages \
             a G-buffer per lens position and has none to shade (use --method layered)"
                .into(),
        )),
        _ => Ok(()),
    }
}

/// The raster a frame draws with: `auto` is the compute raster where the
/// device has 64-bit buffer atomics (`int64_atomics`; None: not known yet,
/// and `auto` stays), except that a limit on the samples per pass asks for
/// the sprite path's plans (the compute raster takes every sample in one
/// pass, and refuses the limit).
pub fn frame_raster(
    raster: Raster,
    samples_per_pass: Option<u32>,
    int64_atomics: Option<bool>,
) -> Result<Raster> {
    Ok(match (raster, samples_per_pass, int64_atomics) {
        (Raster::Auto, Some(_), _) => Raster::Sprites,
        (Raster::Auto, None, Some(true)) => Raster::Compute,
        (Raster::Auto, None, Some(false)) => Raster::Sprites,
        (Raster::Compute, Some(_), _) => {
            return Err(Error::InvalidArgument(
                "--samples-per-pass limits the sprite raster's passes; the compute raster \
                 takes every sample in one pass (use --raster sprites)"
                    .into(),
            ))
        }
        (chosen, _, _) => chosen,
    })
}

/// What keeps area coverage from acting on a frame of `method` drawn by
/// `raster` with `shape` splats (None: nothing): it weighs the compute
/// raster's square splats seen from one lens position, so not `accum`'s
/// G-buffers (one per lens position), the sprite raster's samples (they
/// name no splat) or disc splats. `raster` and `shape` as far as they are
/// known (None, or [`Raster::Auto`]: not yet). The one rule: the renderer
/// resolves by area where this is None, and [`check_coverage_with`]
/// refuses an explicit `--coverage area` where it is not.
pub fn area_coverage_blocker(
    method: &Method,
    raster: Option<Raster>,
    shape: Option<SplatShape>,
) -> Option<&'static str> {
    match (method, raster, shape) {
        (Method::Accum(_), _, _) => Some("accum, which averages a G-buffer per lens position"),
        (_, Some(Raster::Sprites), _) => Some(
            "the sprite raster (--raster sprites, --samples-per-pass, or a device without \
             64-bit buffer atomics), whose samples name no splat",
        ),
        (_, _, Some(SplatShape::Disc)) => Some("--splat-shape disc"),
        _ => None,
    }
}

/// The one check of an explicit `--coverage area`: refused where
/// [`area_coverage_blocker`] finds it cannot act (the default, not given,
/// falls back on the samples there). Run before the file is read, with
/// what the command line says (`--samples-per-pass` asks for the sprite
/// raster), and again on each frame with the raster the device gives.
pub fn check_coverage_with(
    coverage: Option<Coverage>,
    method: &Method,
    raster: Option<Raster>,
    shape: Option<SplatShape>,
) -> Result<()> {
    if coverage != Some(Coverage::Area) {
        return Ok(());
    }
    match area_coverage_blocker(method, raster, shape) {
        None => Ok(()),
        Some(why) => Err(Error::InvalidArgument(format!(
            "--coverage area weighs the compute raster's square splats seen from one lens \
             position, not {why} (leave --coverage out, or give samples)"
        ))),
    }
}

/// The options of the methods as the command line gives them: None where
/// a flag is not given ([`MethodKind::with_flags`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MethodFlags {
    pub fast_weights: Option<FastWeights>,
    pub fast_window: Option<GatherWindow>,
    pub fast_gather: Option<FastGather>,
    pub rdb_bins: Option<u32>,
    pub rdb_mode: Option<RdbMode>,
    pub rdb_memory_mb: Option<u64>,
    pub rdb_atomics: Option<RdbAtomics>,
    pub layers: Option<u32>,
    pub samples: Option<u32>,
}

/// A flag of one method's options.
pub struct MethodFlag {
    /// As the command line spells it.
    pub flag: &'static str,
    /// Whether it is given.
    pub given: fn(&MethodFlags) -> bool,
    /// The methods that read it; with any other it is refused.
    pub kinds: &'static [MethodKind],
}

/// Every flag of a method's options and the methods that read it: the one
/// table [`MethodKind::with_flags`] refuses by.
pub const METHOD_FLAGS: &[MethodFlag] = &[
    MethodFlag {
        flag: "--fast-weights",
        given: |f| f.fast_weights.is_some(),
        kinds: &[MethodKind::Fast],
    },
    MethodFlag {
        flag: "--fast-window",
        given: |f| f.fast_window.is_some(),
        kinds: &[MethodKind::Fast],
    },
    MethodFlag {
        flag: "--fast-gather",
        given: |f| f.fast_gather.is_some(),
        kinds: &[MethodKind::Fast],
    },
    MethodFlag {
        flag: "--rdb-bins",
        given: |f| f.rdb_bins.is_some(),
        kinds: &[MethodKind::Rdb],
    },
    MethodFlag {
        flag: "--rdb-mode",
        given: |f| f.rdb_mode.is_some(),
        kinds: &[MethodKind::Rdb],
    },
    MethodFlag {
        flag: "--rdb-memory-mb",
        given: |f| f.rdb_memory_mb.is_some(),
        kinds: &[MethodKind::Rdb],
    },
    MethodFlag {
        flag: "--rdb-atomics",
        given: |f| f.rdb_atomics.is_some(),
        kinds: &[MethodKind::Rdb],
    },
    MethodFlag {
        flag: "--layers",
        given: |f| f.layers.is_some(),
        kinds: &[MethodKind::Layered],
    },
    MethodFlag {
        flag: "--samples",
        given: |f| f.samples.is_some(),
        kinds: &[MethodKind::Accum],
    },
];

impl Method {
    /// The fast method by DESIGN §4's rule (the paper's) with these
    /// weights and window, by the block tree.
    pub const fn paper_fast(weights: FastWeights, window: GatherWindow) -> Method {
        Method::Fast(FastOptions {
            weights,
            window,
            gather: FastGather::Tree,
        })
    }

    /// The RDB with N×N bins in `mode`, the default memory budget.
    pub const fn rdb(bins: u32, mode: RdbMode) -> Method {
        Method::Rdb(RdbOptions {
            bins,
            mode,
            memory_bytes: None,
            atomics: RdbAtomics::Auto,
        })
    }

    /// The accumulation reference with `samples` lens samples.
    pub const fn accum(samples: u32) -> Method {
        Method::Accum(AccumOptions { samples })
    }

    /// The layered method with `layers` depth-peeled layers.
    pub const fn layered(layers: u32) -> Method {
        Method::Layered(LayeredOptions {
            layers,
            keep_occluded: false,
        })
    }

    /// Syntax of [`Method::parse_short`], for error messages and help.
    pub const SHORT_SYNTAX: &'static str = "pinhole, fast (the two-field gather), fast-tree or fast-pixels (the paper's rule; after -uniform, -fixed or both), rdbN or rdbN-pairs (N in 2..=16), layeredK (K in 1..=8), accumS (S ≥ 1)";

    /// Parses a method with its options in one word, as `bench --methods`
    /// names them: `pinhole`, `fast` (the two-field gather; `fast-fields`
    /// too), `fast-tree` and `fast-pixels` (the paper's rule) after
    /// `-uniform`, `-fixed` or both (in that order), `rdbN`,
    /// `rdbN-pairs`, `layeredK`, `accumS`. N and S are required and go through the same
    /// range checks as `--rdb-bins` and `--samples`. [`Method::short_name`]
    /// is the inverse.
    pub fn parse_short(name: &str) -> Result<Method> {
        let bad = || {
            Error::InvalidArgument(format!(
                "unknown method '{name}' (known: {})",
                Self::SHORT_SYNTAX
            ))
        };
        let (head, option) = match name.split_once('-') {
            Some((h, o)) => (h, Some(o)),
            None => (name, None),
        };
        // The number starts at the first digit (or its sign: `u32` parsing
        // takes "+9" too).
        let digits_at = head
            .find(|c: char| c.is_ascii_digit() || c == '+')
            .unwrap_or(head.len());
        let (word, digits) = head.split_at(digits_at);
        let kind = MethodKind::parse(word).map_err(|_| bad())?;
        // The number after rdb / accum: required, range-checked.
        let number = |check: fn(u32) -> Result<u32>| -> Result<u32> {
            let n = digits.parse::<u32>().map_err(|_| bad())?;
            check(n).map_err(|e| Error::InvalidArgument(format!("'{name}' is out of range: {e}")))
        };
        match kind {
            MethodKind::Pinhole => {
                if !digits.is_empty() || option.is_some() {
                    return Err(bad());
                }
                Ok(Method::Pinhole)
            }
            MethodKind::Fast => {
                if !digits.is_empty() {
                    return Err(bad());
                }
                // Weights, window, gather: each at most once, in that
                // order (one name per method: short_name's).
                let mut fast = FastOptions::default();
                let mut next = 0;
                for o in option.into_iter().flat_map(|o| o.split('-')) {
                    let stage = if let Ok(w) = FastWeights::from_str(o, false) {
                        fast.weights = w;
                        0
                    } else if let Ok(w) = GatherWindow::from_str(o, false) {
                        fast.window = w;
                        1
                    } else if let Ok(g) = FastGather::from_str(o, false) {
                        fast.gather = g;
                        2
                    } else {
                        return Err(bad());
                    };
                    if stage < next {
                        return Err(bad());
                    }
                    next = stage + 1;
                }
                fast.check().map_err(|_| {
                    Error::InvalidArgument(format!(
                        "'{name}': uniform and fixed are options of the paper's rule, which \
                         the name must then give: fast-uniform-tree, fast-fixed-pixels, …"
                    ))
                })?;
                Ok(Method::Fast(fast))
            }
            MethodKind::Rdb => {
                let mut rdb = RdbOptions {
                    bins: number(check_rdb_bins)?,
                    ..RdbOptions::default()
                };
                if let Some(o) = option {
                    rdb.mode = RdbMode::from_str(o, false).map_err(|_| bad())?;
                }
                Ok(Method::Rdb(rdb))
            }
            MethodKind::Accum => {
                if option.is_some() {
                    return Err(bad());
                }
                let samples = number(check_samples)?;
                Ok(Method::Accum(AccumOptions { samples }))
            }
            MethodKind::Layered => {
                if option.is_some() {
                    return Err(bad());
                }
                Ok(Method::layered(number(check_layers)?))
            }
        }
    }
}

impl Method {
    /// The method's name alone.
    pub fn kind(&self) -> MethodKind {
        match self {
            Method::Pinhole => MethodKind::Pinhole,
            Method::Fast(_) => MethodKind::Fast,
            Method::Rdb(_) => MethodKind::Rdb,
            Method::Accum(_) => MethodKind::Accum,
            Method::Layered(_) => MethodKind::Layered,
        }
    }

    /// The method in one word, as [`Method::parse_short`] reads it
    /// (options other than those the word can say are left out).
    pub fn short_name(&self) -> String {
        match self {
            Method::Pinhole => "pinhole".into(),
            Method::Fast(o) => {
                let mut name = String::from("fast");
                if o.weights == FastWeights::Uniform {
                    name += "-uniform";
                }
                if o.window == GatherWindow::Fixed {
                    name += "-fixed";
                }
                match o.gather {
                    FastGather::Fields => {}
                    FastGather::Tree => name += "-tree",
                    FastGather::Pixels => name += "-pixels",
                }
                name
            }
            Method::Rdb(o) => match o.mode {
                RdbMode::Centre => format!("rdb{}", o.bins),
                RdbMode::Pairs => format!("rdb{}-pairs", o.bins),
            },
            Method::Accum(o) => format!("accum{}", o.samples),
            Method::Layered(o) => format!("layered{}", o.layers),
        }
    }
}

/// Default N of the RDB's N×N bins.
pub const DEFAULT_RDB_BINS: u32 = 9;
/// Default lens samples of `accum`.
pub const DEFAULT_SAMPLES: u32 = 256;
/// Default K of the layered method's depth-peeled layers: 2, by the
/// quality-per-time table of docs/BENCHMARKS.md (issue 28): 3 and 4 layers
/// gained nothing on the bunny and the mug and 0.8–0.9 dB on the LiDAR
/// tile, for 1.15–1.75 times the frame; 1 layer lost 2.5 dB on the tile
/// (within 0.14 dB on the bunny and the mug, at 0.47–0.66 of the frame).
pub const DEFAULT_LAYERS: u32 = 2;
/// Default K of the G-buffer's K×K samples a pixel on the sprites' K×K
/// grid of cell centres (DESIGN §3).
pub const DEFAULT_SSAA_SPRITES: u32 = 4;
/// Default K on the compute raster's rotated grid: 3, by the comparison
/// with Mitsuba 3 in docs/BENCHMARKS.md (issue 28). Its K² samples lie in
/// K² distinct rows and columns, so K = 3 sees a splat's edges more finely
/// than the sprites' K = 4 (pinhole images 2.7–3.0 dB closer to
/// Mitsuba's reference); against K = 4 on the same grid it loses 0.02–0.63 dB for a
/// frame up to 1.8× faster, and was faster at equal PSNR in 29 of 36 cells.
pub const DEFAULT_SSAA_COMPUTE: u32 = 3;

/// Default K of a scene of 3D Gaussians: 1, the pixel centres, as trained.
pub const DEFAULT_SSAA_GAUSSIANS: u32 = 1;

/// Default K of `accum` with at least as many lens positions as the
/// raster's default K² (S ≥ 9 on the compute raster, 16 on the sprites;
/// fewer keep the raster's K): 1, where each lens position also moves the
/// pixel's one sample (`camera::pixel_jitters`), so that S lens positions
/// are S samples of the pixel, no fewer than the raster's. Against Mitsuba 3 in the
/// same runs (docs/BENCHMARKS.md, "accum's default K"), accum 16 and 64 at
/// K = 1 were faster at equal PSNR than at K = 3 in 9 of 12 cells (bunny,
/// mug, LiDAR tile; 640×480 and 1920×1080) and at 1.5× Mitsuba or more in
/// all 12, where K = 3 fell to 0.74–0.88× with 64 samples on the bunny;
/// K = 3 stays ahead where the blur is small and the splats fine (the
/// tile at 640×480).
pub const DEFAULT_SSAA_ACCUM: u32 = 1;

/// The default K of `--ssaa` for frames of `method` rasterised by
/// `raster` (resolved: sprites or compute; see [`DEFAULT_SSAA_COMPUTE`]
/// and [`DEFAULT_SSAA_ACCUM`]).
pub fn default_ssaa(raster: Raster, method: &Method) -> u32 {
    let k = match raster {
        Raster::Compute => DEFAULT_SSAA_COMPUTE,
        Raster::Sprites | Raster::Auto => DEFAULT_SSAA_SPRITES,
    };
    match method {
        Method::Accum(a) if a.samples >= k * k => DEFAULT_SSAA_ACCUM,
        _ => k,
    }
}

/// K of `--ssaa` (K×K samples per pixel): 1 to 16.
pub fn check_ssaa(k: u32) -> Result<u32> {
    in_range("--ssaa", k, 1, 16)
}

/// S of `--samples-per-pass` (the most samples one G-buffer raster pass
/// takes; 1 = one pass per sample): 1 to 64.
pub fn check_samples_per_pass(s: u32) -> Result<u32> {
    in_range("--samples-per-pass", s, 1, 64)
}

/// N of `--rdb-bins` (N×N lens bins, DESIGN §5): 2 to 16.
pub fn check_rdb_bins(n: u32) -> Result<u32> {
    in_range("--rdb-bins", n, 2, 16)
}

/// K of `--layers` (depth-peeled layers of `layered`, DESIGN §6): 1 to 8.
pub fn check_layers(k: u32) -> Result<u32> {
    in_range("--layers", k, 1, 8)
}

/// The most lens samples of `accum`: with K² ≤ 256 sub-pixel samples each,
/// every sample's index stays exact in the resolve's f32 (< 2^24).
pub const MAX_SAMPLES: u32 = 65_536;

/// S of `--samples` (lens samples of `accum`): 1 to [`MAX_SAMPLES`].
pub fn check_samples(s: u32) -> Result<u32> {
    in_range("--samples", s, 1, MAX_SAMPLES)
}

/// P of `--lod-px` (emit a node of the splat hierarchy when it projects to
/// at most P pixels; 0: every point): finite, 0 to 1024.
pub fn check_lod_px(p: f32) -> Result<f32> {
    if !(p.is_finite() && (0.0..=1024.0).contains(&p)) {
        return Err(Error::InvalidArgument(format!(
            "--lod-px must be between 0 and 1024, not {p}"
        )));
    }
    Ok(p)
}

/// F of `--lod-blur` (a node may also stop where it projects to at most F
/// times its CoC): finite, above 0 and at most 16.
pub fn check_lod_blur(f: f32) -> Result<f32> {
    if !(f.is_finite() && f > 0.0 && f <= 16.0) {
        return Err(Error::InvalidArgument(format!(
            "--lod-blur must be above 0 and at most 16, not {f}"
        )));
    }
    Ok(f)
}

/// A frame's level of detail: each number in range, and `--lod-blur` and
/// `--cull-back-faces` only with a traversal (`--lod-px` above 0).
pub fn check_lod(lod: &Lod) -> Result<()> {
    check_lod_px(lod.px)?;
    if lod.cull_back_faces && lod.draws_all() {
        return Err(Error::InvalidArgument(
            "--cull-back-faces needs --lod-px above 0 (--lod-px 0 draws every point)".into(),
        ));
    }
    if let Some(f) = lod.blur {
        check_lod_blur(f)?;
        if lod.draws_all() {
            return Err(Error::InvalidArgument(
                "--lod-blur needs --lod-px above 0 (--lod-px 0 draws every point)".into(),
            ));
        }
    }
    Ok(())
}

fn in_range(flag: &str, v: u32, lo: u32, hi: u32) -> Result<u32> {
    if !(lo..=hi).contains(&v) {
        return Err(Error::InvalidArgument(format!(
            "{flag} must be between {lo} and {hi}, not {v}"
        )));
    }
    Ok(v)
}

/// What a frame asks of the splat hierarchy's traversal (DESIGN §3,
/// `--lod-px`, `--lod-blur`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lod {
    /// Emit an inner node when its projected diameter is at most this many
    /// pixels. 0: no traversal, every point is drawn.
    pub px: f32,
    /// Also emit it when its projected diameter is at most this multiple
    /// of the smallest CoC over its depth range (None: off).
    pub blur: Option<f32>,
    /// `--cull-back-faces`: drop the nodes whose normals face away from
    /// every point of the lens. The splats are squares facing the camera,
    /// which the path tracer draws whatever their normals, so this changes
    /// the image (the silhouettes, and what shows through a scan's holes):
    /// off by default (docs/decisions/back-face-culling.md).
    pub cull_back_faces: bool,
}

/// `--lod-px`'s default: a node of the hierarchy drawn as one splat where
/// it projects to at most a pixel.
pub const DEFAULT_LOD_PX: f32 = 1.0;

impl Default for Lod {
    fn default() -> Lod {
        Lod {
            px: DEFAULT_LOD_PX,
            blur: None,
            cull_back_faces: false,
        }
    }
}

impl Lod {
    /// Every point, no culling (`--lod-px 0`).
    pub const ALL: Lod = Lod {
        px: 0.0,
        blur: None,
        cull_back_faces: false,
    };

    /// Whether the frame draws every point without a traversal.
    pub fn draws_all(&self) -> bool {
        self.px == 0.0
    }
}
