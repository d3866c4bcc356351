//! `pointlens convert` (issue 30, item 2): any cloud pointlens reads, as a
//! COPC file (docs/ARCHITECTURE.md, "Converting to COPC").
//!
//! The octree: a cube around the points (the root), and in each node the
//! points of a 128³ grid over its cube, one per occupied cell (the point
//! nearest the cell's centre), so that a node's spacing is its width / 128
//! (the root's written to the info VLR, halved per level, as PotreeConverter
//! and untwine sample); the points a node does not keep go to its eight
//! children. A node of at most [`MAX_NODE_POINTS`] points keeps them all
//! (a leaf).
//!
//! The file: LAS 1.4, point format 6 (7 with colors, 8 with NIR), the
//! input's extra bytes after each record (its Extra Bytes VLR copied), the
//! input's scale and offset (a LAS input's integer codes are kept as they
//! are); the COPC info VLR first, the laszip VLR (variable-size chunks: one
//! chunk per node, compressed on every core), the input's WKT CRS and Extra
//! Bytes VLR; after the points the
//! chunk table and the hierarchy as one page (root entry first) in an
//! extended VLR. Written to a temporary file beside the output and renamed
//! into place when complete.
//!
//! A LAS, LAZ or COPC input ([`convert_las`]) and a binary PLY file
//! ([`convert_ply`]) are converted out of core: parts of the octree
//! spilled to files beside the output, built apart. A cloud read whole
//! (an ASCII PLY file, a pipe) is written by [`write_copc`].

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use glam::{DVec3, IVec3};
use las::point::Format;
use las::Transform;
use laz::laszip::{ChunkTable, ChunkTableEntry, LazItemRecordBuilder, LazVlr, LazVlrBuilder};
use laz::record::{LayeredPointRecordCompressor, RecordCompressor};

use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::input::copc::NodeKey;

/// A node of at most this many points is a leaf.
pub const MAX_NODE_POINTS: usize = 100_000;

/// Cells per axis of a node's sampling grid: its spacing is width / 128.
pub const GRID_CELLS: u32 = 128;

/// The points to write: each point's record in the output format, and
/// the scale and offset of its codes.
pub struct Records {
    pub format: Format,
    pub transforms: las::Vector<Transform>,
    /// `format.len()` bytes per point.
    pub bytes: Vec<u8>,
    /// The file's WKT CRS, kept as it was.
    pub wkt: Option<Vec<u8>>,
    /// GPS times are adjusted standard time (global encoding bit 0), not
    /// GPS week time.
    pub standard_gps_time: bool,
    /// The input's Extra Bytes VLR (`LASF_Spec` 4), which describes the
    /// `format.extra_bytes` at each record's end, kept as it was.
    pub extra_bytes_vlr: Option<Vec<u8>>,
}

impl Records {
    fn record_len(&self) -> usize {
        usize::from(self.format.len())
    }

    pub fn len(&self) -> usize {
        self.bytes.len() / self.record_len()
    }

    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// The same format, grid, CRS and time type, without points.
    fn clone_meta(&self) -> Records {
        Records {
            format: self.format,
            transforms: self.transforms,
            bytes: Vec::new(),
            wkt: self.wkt.clone(),
            standard_gps_time: self.standard_gps_time,
            extra_bytes_vlr: self.extra_bytes_vlr.clone(),
        }
    }

    /// A record's position in file coordinates.
    #[inline]
    fn position_of(&self, r: &[u8]) -> DVec3 {
        self.position_of_codes(codes_of(r))
    }

    /// The position in file coordinates of a record's codes (X, Y, Z).
    #[inline]
    fn position_of_codes(&self, c: [i32; 3]) -> DVec3 {
        let t = &self.transforms;
        DVec3::new(t.x.direct(c[0]), t.y.direct(c[1]), t.z.direct(c[2]))
    }

    /// Every record as a [`Pt`], in order.
    fn all_points(&self) -> Vec<Pt> {
        self.bytes
            .chunks_exact(self.record_len())
            .enumerate()
            .map(|(i, r)| Pt {
                index: i as u32,
                codes: codes_of(r),
            })
            .collect()
    }

    /// The output's format (6; 7 where the input has colors, 8 where it
    /// has NIR; its extra bytes and their VLR kept), grid, WKT and GPS
    /// time type for a LAS file of `header`.
    fn meta_of(header: &las::Header, path: &Path) -> Result<Records> {
        let fail = |msg: String| Error::Las {
            path: path.to_path_buf(),
            msg,
        };
        let input = header.point_format();
        let mut format = match (input.has_nir, input.has_color) {
            (true, _) => Format::new(8).expect("format 8"),
            (false, true) => Format::new(7).expect("format 7"),
            (false, false) => Format::new(6).expect("format 6"),
        };
        format.extra_bytes = input.extra_bytes;
        let extra_bytes_vlr = header
            .all_vlrs()
            .find(|v| v.user_id == "LASF_Spec" && v.record_id == 4)
            .map(|v| v.data.clone())
            .filter(|d| input.extra_bytes > 0 && d.len() <= usize::from(u16::MAX));
        let transforms = *header.transforms();
        let wkt = header
            .all_vlrs()
            .find(|v| v.user_id == "LASF_Projection" && v.record_id == 2112)
            .map(|v| v.data.clone());
        if wkt
            .as_ref()
            .is_some_and(|w| w.len() > usize::from(u16::MAX))
        {
            return Err(fail(
                "its WKT CRS is longer than a VLR holds (65535 bytes)".into(),
            ));
        }
        let geotiff = header
            .all_vlrs()
            .any(|v| v.user_id == "LASF_Projection" && v.record_id == 34735);
        if wkt.is_none() && geotiff {
            log::warn!(
                "{}: its CRS is GeoTIFF keys, which COPC (LAS 1.4, point formats 6 to 8) \
                 cannot hold: the COPC file has no CRS",
                path.display()
            );
        }
        Ok(Records {
            format,
            transforms,
            bytes: Vec::new(),
            wkt,
            standard_gps_time: header.gps_time_type() == las::GpsTimeType::Standard,
            extra_bytes_vlr,
        })
    }

    /// The records of an in-memory cloud (a PLY file's): format 7 with its
    /// colors as 16-bit sRGB where it has RGB, else format 6; its
    /// intensities where it has them (`cloud_record`); on the grid of
    /// `Records::for_cloud_within` its bounds.
    pub fn of_cloud(cloud: &PointCloud, path: &Path) -> Result<Records> {
        let (lo, hi) = cloud.bounds();
        let (lo, hi) = (lo.as_dvec3() + cloud.origin, hi.as_dvec3() + cloud.origin);
        let mut records = Records::for_cloud_within(lo, hi, cloud.has_rgb);
        records.bytes = Vec::with_capacity(cloud.len() * records.record_len());
        for (i, (p, c)) in cloud.positions.iter().zip(&cloud.colors).enumerate() {
            let intensity = cloud.intensities.as_ref().map_or(0, |v| v[i]);
            cloud_record(
                p.as_dvec3() + cloud.origin,
                (cloud.has_rgb.then_some(*c), intensity),
                &records.transforms,
                &mut records.bytes,
            )
            .map_err(|msg| Error::Las {
                path: path.to_path_buf(),
                msg,
            })?;
        }
        warn_brighter_than_white(path, brighter_than_white(cloud.has_rgb, &cloud.colors));
        Ok(records)
    }

    /// No records yet, of a cloud within `lo`..`hi` (file coordinates):
    /// format 7 with `color`, else 6, positions on a grid of 10^k units
    /// fine enough for f32 (7 digits over the largest extent), centred on
    /// the bounds.
    fn for_cloud_within(lo: DVec3, hi: DVec3, color: bool) -> Records {
        // A single point (or one place) still gets a grid.
        let extent = (hi - lo).max_element().max(1e-6);
        let scale = 10f64.powf((extent * 1e-7).log10().floor());
        let centre = (lo + hi) / 2.0;
        let offset = (centre / scale).round() * scale;
        let axis = |offset: f64| Transform { scale, offset };
        Records {
            format: Format::new(if color { 7 } else { 6 }).expect("format 6 or 7"),
            transforms: las::Vector {
                x: axis(offset.x),
                y: axis(offset.y),
                z: axis(offset.z),
            },
            bytes: Vec::new(),
            wkt: None,
            standard_gps_time: false,
            extra_bytes_vlr: None,
        }
    }
}

/// Appends the record of a cloud's point at `p` (file coordinates) of
/// linear color `c` and 16-bit `intensity`: format 7 with a color (as
/// 16-bit sRGB), else 6; its codes under `transforms`, a first return of
/// one, nothing else.
fn cloud_record(
    p: DVec3,
    (c, intensity): (Option<glam::Vec3>, u16),
    transforms: &las::Vector<Transform>,
    out: &mut Vec<u8>,
) -> std::result::Result<(), String> {
    let code = |t: &Transform, v: f64| {
        t.inverse(v)
            .map_err(|e| format!("a point does not fit the output's grid: {e}"))
    };
    let xyz = [
        code(&transforms.x, p.x)?,
        code(&transforms.y, p.y)?,
        code(&transforms.z, p.z)?,
    ];
    let srgb = |v: f32| {
        let s = crate::image_io::linear_to_srgb(v.clamp(0.0, 1.0));
        (s * 65535.0).round() as u16
    };
    let mut r = [0u8; 36];
    for (k, v) in xyz.iter().enumerate() {
        r[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    r[12..14].copy_from_slice(&intensity.to_le_bytes());
    // Return 1 of 1.
    r[14] = 0x11;
    let Some(c) = c else {
        out.extend_from_slice(&r[..30]);
        return Ok(());
    };
    for (k, v) in [srgb(c.x), srgb(c.y), srgb(c.z)].iter().enumerate() {
        r[30 + 2 * k..32 + 2 * k].copy_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&r);
    Ok(())
}

/// Converts records of any LAS point format (0–10, extra bytes after)
/// into format 6, 7 or 8 (the same extra bytes after) byte by byte, as `write_record` does through
/// `las::Point` (a test holds them equal) but without building a point:
/// the distribution's hot loop.
///
/// Legacy formats (0–5): return numbers, flags and classification move
/// to the 1.4 layout; class 12 (overlap) becomes class 1 with the overlap
/// flag; the scan angle rank becomes 0.006° steps; a missing GPS time is
/// 0 and missing colors are black. Extended formats (6–10) keep their
/// first 30 bytes, and NIR (formats 8 and 10) where the output is format
/// 8; a missing NIR is 0. The extra bytes at a record's end are copied to
/// the output record's end. Waveform packets (formats 4, 5, 9, 10) are
/// dropped (named in a warning, `dropped_by_conversion`). Return
/// numbers are at least 1 and a number of returns at least the return's.
#[derive(Debug, Clone, Copy)]
pub struct RecordConverter {
    from: u8,
    from_len: usize,
    /// The output's format: 6, 7 or 8.
    to: u8,
    /// Extra bytes a record, in both formats.
    extra: usize,
}

impl RecordConverter {
    /// From records of `from` (its length with extra bytes) into `to`
    /// (6, 7 or 8, with as many extra bytes as `from`).
    pub fn new(from: &Format, to: &Format) -> Option<RecordConverter> {
        let id = from.to_u8().ok()?;
        let to_id = to.to_u8().ok()?;
        (id <= 10 && (6..=8).contains(&to_id) && from.extra_bytes == to.extra_bytes).then_some(
            RecordConverter {
                from: id,
                from_len: usize::from(from.len()),
                to: to_id,
                extra: usize::from(from.extra_bytes),
            },
        )
    }

    /// Bytes of an output record before its extra bytes.
    fn out_base_len(&self) -> usize {
        match self.to {
            6 => 30,
            7 => 36,
            _ => 38,
        }
    }

    /// Bytes of an input record.
    pub fn from_len(&self) -> usize {
        self.from_len
    }

    /// Bytes of an output record.
    pub fn to_len(&self) -> usize {
        self.out_base_len() + self.extra
    }

    /// Writes the output record of input record `r` into `o` (`to_len`
    /// bytes, zeros).
    #[inline]
    pub fn convert(&self, r: &[u8], o: &mut [u8]) {
        let (r, o) = (&r[..self.from_len], &mut o[..self.to_len()]);
        let to_color = self.to >= 7;
        // Coordinates and intensity.
        o[..14].copy_from_slice(&r[..14]);
        let (ret, returns) = if self.from <= 5 {
            let (a, b) = (r[14], r[15]);
            let class = b & 0x1F;
            let overlap = class == 12;
            // Synthetic, key-point and withheld (bits 5–7) to bits 0–2,
            // overlap bit 3, scan direction and edge of flight line to
            // bits 6 and 7.
            o[15] = (b >> 5) | (u8::from(overlap) << 3) | (a & 0xC0);
            o[16] = if overlap { 1 } else { class };
            o[17] = r[17];
            let degrees = f32::from(r[16] as i8);
            let steps = (degrees / 0.006) as i16;
            o[18..20].copy_from_slice(&steps.to_le_bytes());
            o[20..22].copy_from_slice(&r[18..20]);
            let gps_at = match self.from {
                1 | 3 | 4 | 5 => Some(20),
                _ => None,
            };
            if let Some(g) = gps_at {
                o[22..30].copy_from_slice(&r[g..g + 8]);
            }
            let rgb_at = match self.from {
                2 => Some(20),
                3 | 5 => Some(28),
                _ => None,
            };
            if let (true, Some(c)) = (to_color, rgb_at) {
                o[30..36].copy_from_slice(&r[c..c + 6]);
            }
            (a & 7, (a >> 3) & 7)
        } else {
            o[15..30].copy_from_slice(&r[15..30]);
            if to_color && matches!(self.from, 7 | 8 | 10) {
                o[30..36].copy_from_slice(&r[30..36]);
            }
            if self.to == 8 && matches!(self.from, 8 | 10) {
                o[36..38].copy_from_slice(&r[36..38]);
            }
            (r[14] & 15, r[14] >> 4)
        };
        let ret = ret.max(1);
        o[14] = (returns.max(ret) << 4) | ret;
        if self.extra > 0 {
            let base = self.out_base_len();
            o[base..].copy_from_slice(&r[self.from_len - self.extra..]);
        }
    }
}

/// A record's position codes (X, Y, Z: its first 12 bytes).
#[inline]
fn codes_of(r: &[u8]) -> [i32; 3] {
    let c = |k: usize| i32::from_le_bytes(r[4 * k..4 * k + 4].try_into().expect("4 bytes"));
    [c(0), c(1), c(2)]
}

/// A point on its way down the octree's build: its record's index and
/// position codes, carried so that a level reads its points in order
/// instead of fetching each record at random (which was a fifth of a
/// conversion's time, most of it waiting on memory).
#[derive(Debug, Clone, Copy)]
struct Pt {
    index: u32,
    codes: [i32; 3],
}

/// An octree node's points: indices into the records.
struct Node {
    key: NodeKey,
    points: Vec<u32>,
}

/// The root cube around points within `lo`..`hi` (file coordinates):
/// (min corner, width), a little wider, so that the largest coordinate
/// lies inside.
fn root_cube(lo: DVec3, hi: DVec3) -> (DVec3, f64) {
    let width = (hi - lo).max_element().max(f64::MIN_POSITIVE) * (1.0 + 1e-9) + 1e-9;
    let centre = (lo + hi) / 2.0;
    (centre - DVec3::splat(width / 2.0), width)
}

/// The octree of `records` in `cube`: nodes with their points, in no
/// particular order. Subtrees are built on every core.
fn build_octree(records: &Records, cube: (DVec3, f64), threads: usize) -> Vec<Node> {
    let mut out = Vec::new();
    build_node(
        records,
        NodeKey::ROOT,
        cube,
        records.all_points(),
        threads,
        &mut out,
    );
    out
}

fn build_node(
    records: &Records,
    key: NodeKey,
    (min, width): (DVec3, f64),
    points: Vec<Pt>,
    threads: usize,
    out: &mut Vec<Node>,
) {
    if points.len() <= MAX_NODE_POINTS || key.level >= crate::input::copc::MAX_LEVEL {
        let points = points.iter().map(|p| p.index).collect();
        out.push(Node { key, points });
        return;
    }
    let (kept, children) = sample(records, &points, min, width);
    drop(points);
    out.push(Node { key, points: kept });
    let half = width / 2.0;
    let child_cube = |o: usize| {
        let d = DVec3::new((o & 1) as f64, ((o >> 1) & 1) as f64, ((o >> 2) & 1) as f64);
        (min + d * half, half)
    };
    let keys: Vec<NodeKey> = key.children().collect();
    if threads > 1 {
        let mut outs: Vec<Vec<Node>> = Vec::new();
        std::thread::scope(|scope| {
            let handles: Vec<_> = children
                .into_iter()
                .enumerate()
                .filter(|(_, c)| !c.is_empty())
                .map(|(o, c)| {
                    let key = keys[o];
                    let cube = child_cube(o);
                    scope.spawn(move || {
                        let mut out = Vec::new();
                        build_node(records, key, cube, c, threads / 8 + 1, &mut out);
                        out
                    })
                })
                .collect();
            outs = handles
                .into_iter()
                .map(|h| h.join().expect("a subtree's build panicked"))
                .collect();
        });
        out.extend(outs.into_iter().flatten());
    } else {
        for (o, c) in children.into_iter().enumerate() {
            if !c.is_empty() {
                build_node(records, keys[o], child_cube(o), c, 1, out);
            }
        }
    }
}

/// The points of `points` a node over the cube (`min`, `width`) keeps
/// (of each occupied cell of its 128³ grid, the point nearest the cell's
/// centre, ties to the lower index), and the rest by octant; both in cell
/// order (the grid's rows), which keeps neighbours together for
/// compression.
fn sample(records: &Records, points: &[Pt], min: DVec3, width: f64) -> (Vec<u32>, [Vec<Pt>; 8]) {
    // The points sorted by (cell, distance², index), the first of each
    // cell kept.
    let cell = width / f64::from(GRID_CELLS);
    let last = GRID_CELLS as i32 - 1;
    let mid = min + DVec3::splat(width / 2.0);
    let mut keyed: Vec<(u64, Pt)> = points
        .iter()
        .map(|&pt| {
            let p = records.position_of_codes(pt.codes);
            // Truncation is the floor wherever the clamp lets it matter
            // (and needs no call to libm's floor).
            let i3 = ((p - min) / cell)
                .as_ivec3()
                .clamp(IVec3::ZERO, IVec3::splat(last))
                .as_uvec3();
            let centre = min + (i3.as_dvec3() + 0.5) * cell;
            let id = (i3.z * GRID_CELLS + i3.y) * GRID_CELLS + i3.x;
            // A non-negative f32's bits order as the value does.
            let d = ((p - centre) / cell).length_squared() as f32;
            let key = (u64::from(id) << 32) | u64::from(d.to_bits());
            (key, pt)
        })
        .collect();
    keyed.sort_unstable_by_key(|&(key, pt)| (key, pt.index));
    let mut kept: Vec<u32> = Vec::new();
    let mut children: [Vec<Pt>; 8] = Default::default();
    let mut previous = u64::MAX;
    for &(k, pt) in &keyed {
        if k >> 32 != previous {
            kept.push(pt.index);
            previous = k >> 32;
        } else {
            let o = octant(records.position_of_codes(pt.codes), mid);
            children[o].push(pt);
        }
    }
    (kept, children)
}

/// Which child of a cube centred at `mid` holds `p` (x bit 0, y bit 1,
/// z bit 2, as COPC's keys).
fn octant(p: DVec3, mid: DVec3) -> usize {
    usize::from(p.x >= mid.x) | usize::from(p.y >= mid.y) << 1 | usize::from(p.z >= mid.z) << 2
}

/// What `convert` did.
#[derive(Debug, Clone, Copy)]
pub struct Converted {
    pub points: u64,
    pub nodes: usize,
    pub levels: i32,
    pub bytes: u64,
}

impl Converted {
    /// What `pointlens convert` prints of the file it wrote at `output`
    /// in `elapsed`.
    pub fn summary(&self, output: &Path, elapsed: std::time::Duration) -> String {
        format!(
            "{}: {} points in {} nodes on {} levels, {:.1} MB, {:.2} s",
            output.display(),
            self.points,
            self.nodes,
            self.levels,
            self.bytes as f64 / 1e6,
            elapsed.as_secs_f64()
        )
    }
}

/// Writes `records` as a COPC file at `output` (through a temporary file
/// beside it, renamed when complete).
pub fn write_copc(records: &Records, output: &Path, threads: usize) -> Result<Converted> {
    let fail = |msg: String| Error::Las {
        path: output.to_path_buf(),
        msg,
    };
    if records.is_empty() {
        return Err(fail("nothing to write: the cloud has no points".into()));
    }
    let started = std::time::Instant::now();
    // What the header says of the points, and the cube around them.
    let mut stats = Stats::new();
    let len = records.record_len();
    for r in records.bytes.chunks_exact(len) {
        stats.add(records.position_of(r), r);
    }
    let cube = root_cube(stats.lo, stats.hi);
    let mut nodes = build_octree(records, cube, threads);
    // Parents before children, then by cell: the file order.
    nodes.sort_by_key(|n| n.key);
    log::info!(
        "convert: octree of {} nodes in {:.2} s",
        nodes.len(),
        started.elapsed().as_secs_f64()
    );
    let started = std::time::Instant::now();
    let laz_vlr = laz_vlr_of(&records.format).map_err(fail)?;
    let chunks =
        compress_nodes(records, &nodes, &laz_vlr, threads).map_err(|e| fail(e.to_string()))?;

    log::info!(
        "convert: compressed in {:.2} s",
        started.elapsed().as_secs_f64()
    );
    let mut bytes = 0;
    crate::image_io::write_atomically(output, |file| {
        bytes = write_file(
            records,
            &nodes,
            &chunks,
            &laz_vlr,
            (&stats, cube),
            file,
            output,
        )?;
        Ok(())
    })?;
    Ok(Converted {
        points: records.len() as u64,
        nodes: nodes.len(),
        levels: nodes.iter().map(|n| n.key.level).max().unwrap_or(0) + 1,
        bytes,
    })
}

/// The laszip VLR of records of `format` (6, 7 or 8, with its extra
/// bytes): variable-size chunks.
fn laz_vlr_of(format: &Format) -> std::result::Result<LazVlr, String> {
    let id = format.to_u8().map_err(|e| e.to_string())?;
    let items = LazItemRecordBuilder::default_for_point_format_id(id, format.extra_bytes)
        .map_err(|e| e.to_string())?;
    Ok(LazVlrBuilder::new(items).with_variable_chunk_size().build())
}

/// Each node's points as one LAZ chunk, compressed on every core.
fn compress_nodes(
    records: &Records,
    nodes: &[Node],
    vlr: &LazVlr,
    threads: usize,
) -> std::io::Result<Vec<Vec<u8>>> {
    crate::parallel_map(nodes, threads, |node| {
        compress_records(&gather_records(records, &node.points), vlr)
    })
    .into_iter()
    .collect()
}

/// Records as one LAZ chunk.
fn compress_records(records: &[u8], vlr: &LazVlr) -> std::io::Result<Vec<u8>> {
    let mut c = LayeredPointRecordCompressor::new(Vec::new());
    c.set_fields_from(vlr.items())
        .map_err(std::io::Error::other)?;
    c.compress_many(records)?;
    c.done()?;
    Ok(c.into_inner())
}

/// Bytes of the COPC info VLR's payload.
const INFO_BYTES: usize = 160;

fn vlr(
    user: &str,
    record_id: u16,
    description: &str,
    data: Vec<u8>,
    extended: bool,
) -> las::raw::Vlr {
    let mut user_id = [0u8; 16];
    user_id[..user.len()].copy_from_slice(user.as_bytes());
    let mut desc = [0u8; 32];
    desc[..description.len()].copy_from_slice(description.as_bytes());
    las::raw::Vlr {
        reserved: 0,
        user_id,
        record_id,
        record_length_after_header: match extended {
            true => las::raw::vlr::RecordLength::Evlr(data.len() as u64),
            false => las::raw::vlr::RecordLength::Vlr(data.len() as u16),
        },
        description: desc,
        data,
    }
}

/// The info VLR's payload: the root cube's centre and half-size, the
/// root's spacing, the root page's place, the GPS time range.
fn info_payload(cube: (DVec3, f64), root_page: (u64, u64), gps: (f64, f64)) -> Vec<u8> {
    let (min, width) = cube;
    let centre = min + DVec3::splat(width / 2.0);
    let mut d = Vec::with_capacity(INFO_BYTES);
    for v in [
        centre.x,
        centre.y,
        centre.z,
        width / 2.0,
        width / f64::from(GRID_CELLS),
    ] {
        d.extend_from_slice(&v.to_le_bytes());
    }
    d.extend_from_slice(&root_page.0.to_le_bytes());
    d.extend_from_slice(&root_page.1.to_le_bytes());
    d.extend_from_slice(&gps.0.to_le_bytes());
    d.extend_from_slice(&gps.1.to_le_bytes());
    d.resize(INFO_BYTES, 0);
    d
}

/// What the header says of the points: bounds, counts by return, GPS
/// time range; gathered record by record.
#[derive(Debug, Clone, Copy)]
struct Stats {
    lo: DVec3,
    hi: DVec3,
    by_return: [u64; 15],
    gps: (f64, f64),
    points: u64,
}

impl Stats {
    fn new() -> Stats {
        Stats {
            lo: DVec3::splat(f64::INFINITY),
            hi: DVec3::splat(f64::NEG_INFINITY),
            by_return: [0; 15],
            gps: (f64::INFINITY, f64::NEG_INFINITY),
            points: 0,
        }
    }

    /// Adds one record (format 6, 7 or 8) at file position `p`.
    fn add(&mut self, p: DVec3, r: &[u8]) {
        self.add_position(p);
        self.add_record(r);
    }

    /// The bounds' part of [`Stats::add`].
    fn add_position(&mut self, p: DVec3) {
        self.lo = self.lo.min(p);
        self.hi = self.hi.max(p);
    }

    /// The rest of [`Stats::add`]: counts and GPS times.
    fn add_record(&mut self, r: &[u8]) {
        let ret = usize::from(r[14] & 0x0F);
        if (1..=15).contains(&ret) {
            self.by_return[ret - 1] += 1;
        }
        let gps = f64::from_le_bytes(r[22..30].try_into().expect("8 bytes"));
        self.gps = (self.gps.0.min(gps), self.gps.1.max(gps));
        self.points += 1;
    }

    /// Adds the points of `other`.
    fn merge(&mut self, other: &Stats) {
        self.lo = self.lo.min(other.lo);
        self.hi = self.hi.max(other.hi);
        for (a, b) in self.by_return.iter_mut().zip(other.by_return) {
            *a += b;
        }
        self.gps = (self.gps.0.min(other.gps.0), self.gps.1.max(other.gps.1));
        self.points += other.points;
    }
}

/// What a COPC file's header and VLRs take from its points' source.
struct Layout<'a> {
    format: Format,
    transforms: &'a las::Vector<Transform>,
    wkt: Option<&'a [u8]>,
    standard_gps_time: bool,
    laz_vlr: &'a LazVlr,
    /// The Extra Bytes VLR's payload.
    extra_bytes_vlr: Option<&'a [u8]>,
}

/// A COPC file being written: header and VLRs reserved, node chunks
/// appended as they come, then the chunk table, the hierarchy and the
/// header (`finish`).
struct CopcOut<'a> {
    out: BufWriter<File>,
    path: &'a Path,
    layout: Layout<'a>,
    vlrs: Vec<las::raw::Vlr>,
    offset_to_points: u64,
    at: u64,
    entries: Vec<(NodeKey, u64, u64, u64)>,
    table: ChunkTable,
}

impl<'a> CopcOut<'a> {
    fn io(&self) -> impl Fn(std::io::Error) -> Error + '_ {
        |e| Error::Io {
            path: self.path.to_path_buf(),
            source: e,
        }
    }

    fn begin(file: File, path: &'a Path, layout: Layout<'a>) -> Result<CopcOut<'a>> {
        let io = |e: std::io::Error| Error::Io {
            path: path.to_path_buf(),
            source: e,
        };
        let mut laz_data = Vec::new();
        layout.laz_vlr.write_to(&mut laz_data).map_err(io)?;
        let mut vlrs = vec![
            vlr("copc", 1, "COPC info", vec![0; INFO_BYTES], false),
            vlr("laszip encoded", 22204, "laz", laz_data, false),
        ];
        if let Some(wkt) = layout.wkt {
            vlrs.push(vlr("LASF_Projection", 2112, "WKT", wkt.to_vec(), false));
        }
        if let Some(extra) = layout.extra_bytes_vlr {
            vlrs.push(vlr("LASF_Spec", 4, "Extra Bytes", extra.to_vec(), false));
        }
        let vlr_bytes: u64 = vlrs.iter().map(|v| 54 + v.data.len() as u64).sum();
        let offset_to_points = 375 + vlr_bytes;
        let mut out = BufWriter::with_capacity(1 << 20, file);
        out.seek(SeekFrom::Start(offset_to_points)).map_err(io)?;
        // The chunk table's offset, patched by `finish`.
        out.write_all(&0i64.to_le_bytes()).map_err(io)?;
        Ok(CopcOut {
            out,
            path,
            layout,
            vlrs,
            offset_to_points,
            at: offset_to_points + 8,
            entries: Vec::new(),
            table: ChunkTable::default(),
        })
    }

    /// Records node `key` without points (its children have some).
    fn empty(&mut self, key: NodeKey) {
        self.entries.push((key, 0, 0, 0));
    }

    /// Appends node `key`'s compressed chunk of `count` points.
    fn node(&mut self, key: NodeKey, count: u64, chunk: &[u8]) -> Result<()> {
        let (Ok(size), Ok(_)) = (i32::try_from(chunk.len()), i32::try_from(count)) else {
            return Err(Error::Las {
                path: self.path.to_path_buf(),
                msg: format!(
                    "node {key:?} holds {count} points in {} bytes, more than a COPC entry \
                     counts (2^31): too many points at one place",
                    chunk.len()
                ),
            });
        };
        self.out.write_all(chunk).map_err(self.io())?;
        self.entries.push((key, self.at, size as u64, count));
        self.table.push(ChunkTableEntry {
            point_count: count,
            byte_count: size as u64,
        });
        self.at += size as u64;
        Ok(())
    }

    /// Writes the chunk table, the hierarchy (one page, the root's entry
    /// first) and the header of `stats`' points in `cube`; syncs the file
    /// and returns its length.
    fn finish(mut self, stats: &Stats, cube: (DVec3, f64)) -> Result<u64> {
        let las_err = |e: las::Error| Error::Las {
            path: self.path.to_path_buf(),
            msg: e.to_string(),
        };
        let chunk_table_at = self.at;
        self.table
            .write_to(&mut self.out, self.layout.laz_vlr)
            .map_err(self.io())?;
        self.out.flush().map_err(self.io())?;
        let evlr_at = self.out.stream_position().map_err(self.io())?;
        self.entries.sort_by_key(|e| e.0);
        let mut page = Vec::with_capacity(self.entries.len() * 32);
        for (key, offset, size, count) in &self.entries {
            for v in [key.level, key.x, key.y, key.z] {
                page.extend_from_slice(&v.to_le_bytes());
            }
            page.extend_from_slice(&offset.to_le_bytes());
            page.extend_from_slice(&(*size as i32).to_le_bytes());
            page.extend_from_slice(&(*count as i32).to_le_bytes());
        }
        let page_len = page.len() as u64;
        let hierarchy = vlr("copc", 1000, "EPT hierarchy", page, true);
        hierarchy.write_to(&mut self.out).map_err(las_err)?;
        let end = self.out.stream_position().map_err(self.io())?;
        let root_page = (evlr_at + 60, page_len);

        self.out
            .seek(SeekFrom::Start(self.offset_to_points))
            .map_err(self.io())?;
        self.out
            .write_all(&(chunk_table_at as i64).to_le_bytes())
            .map_err(self.io())?;
        self.vlrs[0].data = info_payload(cube, root_page, stats.gps);
        let l = &self.layout;
        let t = l.transforms;
        let (lo, hi) = (stats.lo, stats.hi);
        let header = las::raw::Header {
            file_signature: *b"LASF",
            global_encoding: 0x10 | u16::from(l.standard_gps_time),
            version: las::Version::new(1, 4),
            system_identifier: *b"pointlens\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0",
            generating_software: *b"pointlens convert\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0",
            header_size: 375,
            offset_to_point_data: self.offset_to_points as u32,
            number_of_variable_length_records: self.vlrs.len() as u32,
            point_data_record_format: l.format.to_u8().expect("6, 7 or 8") | 0x80,
            point_data_record_length: l.format.len(),
            number_of_point_records: 0,
            number_of_points_by_return: [0; 5],
            x_scale_factor: t.x.scale,
            y_scale_factor: t.y.scale,
            z_scale_factor: t.z.scale,
            x_offset: t.x.offset,
            y_offset: t.y.offset,
            z_offset: t.z.offset,
            max_x: hi.x,
            min_x: lo.x,
            max_y: hi.y,
            min_y: lo.y,
            max_z: hi.z,
            min_z: lo.z,
            start_of_waveform_data_packet_record: Some(0),
            evlr: Some(las::raw::header::Evlr {
                start_of_first_evlr: evlr_at,
                number_of_evlrs: 1,
            }),
            large_file: Some(las::raw::header::LargeFile {
                number_of_point_records: stats.points,
                number_of_points_by_return: stats.by_return,
            }),
            ..Default::default()
        };
        self.out.seek(SeekFrom::Start(0)).map_err(self.io())?;
        header.write_to(&mut self.out).map_err(las_err)?;
        for v in &self.vlrs {
            v.write_to(&mut self.out).map_err(las_err)?;
        }
        self.out.flush().map_err(self.io())?;
        self.out.get_ref().sync_all().map_err(self.io())?;
        Ok(end)
    }
}

/// The parts' nodes written in the parts' order whatever order they are
/// built in, so that a conversion's file is the same on any number of
/// cores.
struct InOrder<'a> {
    out: CopcOut<'a>,
    /// The next part to write.
    next: usize,
    /// Parts built before their turn: their nodes (key, points, chunk).
    waiting: std::collections::BTreeMap<usize, Vec<(NodeKey, u64, Vec<u8>)>>,
}

impl InOrder<'_> {
    /// Part `index`'s nodes, written now if their turn has come.
    fn put(&mut self, index: usize, nodes: Vec<(NodeKey, u64, Vec<u8>)>) -> Result<()> {
        self.waiting.insert(index, nodes);
        while let Some(nodes) = self.waiting.remove(&self.next) {
            for (key, count, chunk) in nodes {
                self.out.node(key, count, &chunk)?;
            }
            self.next += 1;
        }
        Ok(())
    }
}

/// Writes `records`' nodes (points of `stats`, in `cube`) into `file`
/// (the temporary of `path`, which errors name) and syncs it; returns its
/// length.
fn write_file(
    records: &Records,
    nodes: &[Node],
    chunks: &[Vec<u8>],
    laz_vlr: &LazVlr,
    (stats, cube): (&Stats, (DVec3, f64)),
    file: File,
    path: &Path,
) -> Result<u64> {
    let layout = Layout {
        format: records.format,
        transforms: &records.transforms,
        wkt: records.wkt.as_deref(),
        standard_gps_time: records.standard_gps_time,
        laz_vlr,
        extra_bytes_vlr: records.extra_bytes_vlr.as_deref(),
    };
    let mut out = CopcOut::begin(file, path, layout)?;
    for (node, chunk) in nodes.iter().zip(chunks) {
        out.node(node.key, node.points.len() as u64, chunk)?;
    }
    out.finish(stats, cube)
}

/// The most points of one part of an out-of-core conversion, built in
/// memory (about 60 bytes each while built: 120 MB a part).
pub const PART_POINTS: u64 = 2_000_000;

/// Converts a LAS, LAZ or COPC file to COPC out of core
/// (docs/ARCHITECTURE.md, "Converting to COPC"), through
/// `convert_source`:
///
/// 1. One pass over the input's points puts each record (in format 6, 7
///    or 8, with its extra bytes) into a file for its octree cell at a level where the parts are
///    about `part_points` each (the header's count spread over a surface),
///    beside the output; a part that came out larger is split into its
///    eight children, a block at a time, until none is.
/// 2. Each part is built as an octree in memory (`build_node`), on every
///    core a part each; its nodes below the part's own are written in the
///    parts' order, and the part's own node's points go to a file.
/// 3. The levels above the parts are sampled from the bottom up (`Top`),
///    each node keeping a point per cell of its 128³ grid from its
///    children's points.
///
/// Memory: the parts being built and those waiting their turn, the path
/// of the top being built, and the distribution's buffers (bounded);
/// disk: the input's records once more.
pub fn convert_las(
    input: &Path,
    output: &Path,
    threads: usize,
    part_points: u64,
) -> Result<Converted> {
    let fail = |msg: String| Error::Las {
        path: input.to_path_buf(),
        msg,
    };
    // LAZ through pointlens's own stream (the GPS times of every point
    // format decoded without the `laz` crate's recursion, input::laz_gps),
    // LAS through the `las` crate.
    let (header, mut stream) = crate::input::las::LazStream::open(input)?;
    let mut reader = match stream {
        Some(_) => None,
        None => Some(las::Reader::from_path(input).map_err(|e| fail(e.to_string()))?),
    };
    let record_len = usize::from(header.point_format().len()).max(1);
    let meta = Records {
        bytes: Vec::new(),
        ..Records::meta_of(&header, input)?
    };
    let b = header.bounds();
    let (lo, hi) = (
        DVec3::new(b.min.x, b.min.y, b.min.z),
        DVec3::new(b.max.x, b.max.y, b.max.z),
    );
    if !(lo.is_finite() && hi.is_finite() && lo.cmple(hi).all()) {
        return Err(fail(format!(
            "the header's bounds ({lo} to {hi}) are not a box: convert needs them"
        )));
    }
    let converter = RecordConverter::new(header.point_format(), &meta.format).ok_or_else(|| {
        fail(format!(
            "its point format {} has no COPC form",
            header.point_format()
        ))
    })?;
    if let Some(lost) = dropped_by_conversion(&header) {
        log::warn!(
            "{}: COPC cannot hold {lost}: they are not converted",
            input.display()
        );
    }
    let mut data = las::PointDataBuilder::new().for_header(&header).build();
    let source = Source {
        meta,
        bounds: (lo, hi),
        total: header.number_of_points(),
        converter,
        fail: &fail,
        fill: &mut |records: &mut Vec<u8>| {
            records.clear();
            if let Some(stream) = stream.as_mut() {
                let points = stream.next_points();
                records.resize(stream.reserve(points)? * record_len, 0);
                stream.decode_next(records)?;
                return Ok(points);
            }
            let reader = reader.as_mut().expect("a LAS reader where no LAZ stream");
            let got = reader
                .fill_points(crate::input::las::CHUNK_POINTS, &mut data)
                .map_err(|e| fail(e.to_string().replace('\n', " ")))?;
            records.extend_from_slice(data.raw_bytes());
            Ok(got)
        },
    };
    convert_source(source, output, threads, part_points)
}

/// What a conversion of `header`'s points ([`RecordConverter`]) leaves
/// out, in words: the waveform packets of point formats 4, 5, 9 and 10,
/// which COPC cannot hold; None where it keeps everything (NIR and extra
/// bytes are kept).
fn dropped_by_conversion(header: &las::Header) -> Option<String> {
    let format = header.point_format();
    format.has_waveform.then(|| {
        format!(
            "the waveform packets of point format {}",
            format.to_u8().unwrap_or(0)
        )
    })
}

/// Converts a binary PLY file to COPC out of core, as [`convert_las`]
/// does a LAS file: one pass for the bounds (the grid and the cube) and
/// the intensities' range, one that turns the vertices into records
/// (format 7 with colors, else 6, as [`Records::of_cloud`] makes them)
/// for the distribution. None where
/// the file does not stream ([`crate::input::ply::VertexChunks::open`]):
/// the caller reads it whole.
pub fn convert_ply(
    input: &Path,
    output: &Path,
    threads: usize,
    part_points: u64,
) -> Result<Option<Converted>> {
    use crate::input::ply::{finite_range, VertexChunks};
    let fail = |msg: String| Error::Ply {
        path: input.to_path_buf(),
        msg,
    };
    let io = |e: std::io::Error| Error::Io {
        path: input.to_path_buf(),
        source: e,
    };
    // 1. The bounds; a file the direct reader declines on the way is read
    // whole, which says what is wrong with it.
    let Some(mut chunks) = VertexChunks::open(input)? else {
        return Ok(None);
    };
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    let mut intensities = (f64::INFINITY, f64::NEG_INFINITY);
    let total = chunks.left() as u64;
    let has_colors = chunks.has_colors();
    let mut brighter = 0;
    while chunks.left() > 0 {
        let Some(chunk) = chunks.next_chunk(PLY_CHUNK_POINTS).map_err(io)? else {
            return Ok(None);
        };
        for p in chunk.positions {
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let (a, b) = finite_range(chunk.intensities.iter().map(|&v| f64::from(v)));
        intensities = (intensities.0.min(a), intensities.1.max(b));
        brighter += brighter_than_white(has_colors, &chunk.colors);
    }
    warn_brighter_than_white(input, brighter);
    let intensity_scale = chunks.intensity_scale(intensities);
    if !chunks.rest_is_well_formed().map_err(io)? {
        return Ok(None);
    }
    // What the whole read refuses (squared distances overflow f32).
    let limit = f64::from(crate::input::MAX_COORDINATE);
    if lo.abs().max_element() > limit || hi.abs().max_element() > limit {
        return Err(fail(format!(
            "a point lies beyond ±{limit:e} units ({lo} to {hi}), where squared distances \
             overflow f32; remove it, or rescale or re-centre the cloud"
        )));
    }
    // 2. The records.
    let meta = Records {
        bytes: Vec::new(),
        ..Records::for_cloud_within(lo, hi, has_colors)
    };
    let transforms = meta.transforms;
    let Some(mut chunks) = VertexChunks::open(input)? else {
        return Err(fail("it changed while being converted".into()));
    };
    let converter = RecordConverter::new(&meta.format, &meta.format).expect("6 or 7 to itself");
    let source = Source {
        meta,
        bounds: (lo, hi),
        total,
        converter,
        fail: &fail,
        fill: &mut |records: &mut Vec<u8>| {
            records.clear();
            if chunks.left() == 0 {
                return Ok(0);
            }
            let Some(chunk) = chunks.next_chunk(PLY_CHUNK_POINTS).map_err(io)? else {
                return Err(fail("it changed while being converted".into()));
            };
            for (i, (p, c)) in chunk.positions.iter().zip(&chunk.colors).enumerate() {
                let intensity =
                    intensity_scale.map_or(0, |s| s.code(f64::from(chunk.intensities[i])));
                let color = has_colors.then_some(*c);
                cloud_record(*p, (color, intensity), &transforms, records).map_err(&fail)?;
            }
            Ok(chunk.positions.len() as u64)
        },
    };
    convert_source(source, output, threads, part_points).map(Some)
}

/// How many of `colors` (linear; none where `has_colors` is false) are
/// brighter than white: LAS's 16-bit RGB holds at most white.
fn brighter_than_white(has_colors: bool, colors: &[glam::Vec3]) -> u64 {
    match has_colors {
        true => colors.iter().filter(|c| c.max_element() > 1.0).count() as u64,
        false => 0,
    }
}

/// Warns, where `count` points of `input` are brighter than white, that
/// their colours are clipped to it.
fn warn_brighter_than_white(input: &Path, count: u64) {
    if count > 0 {
        log::warn!(
            "{}: {count} points are brighter than white (float colours above 1), which \
             LAS's 16-bit RGB cannot hold: their colours are clipped to white",
            input.display()
        );
    }
}

/// Vertices a PLY chunk holds (about 24 MB of positions and colors).
const PLY_CHUNK_POINTS: usize = 1 << 20;

/// Where an out-of-core conversion's records come from.
struct Source<'a> {
    /// The output's format, grid, CRS and time type.
    meta: Records,
    /// The points' bounds (file coordinates), as the input declares them.
    bounds: (DVec3, DVec3),
    /// The points the input declares.
    total: u64,
    /// From the input's records to the output's.
    converter: RecordConverter,
    /// An error about the input.
    fail: &'a (dyn Fn(String) -> Error + Sync),
    /// Replaces the buffer's records with the next chunk's (the
    /// converter's input format); their count, 0 at the end.
    fill: &'a mut dyn FnMut(&mut Vec<u8>) -> Result<u64>,
}

/// The out-of-core conversion of `source`'s records (see
/// [`convert_las`]).
fn convert_source(
    source: Source<'_>,
    output: &Path,
    threads: usize,
    part_points: u64,
) -> Result<Converted> {
    let Source {
        meta,
        bounds: (lo, hi),
        total,
        converter,
        fail,
        fill,
    } = source;
    if total == 0 {
        return Err(fail("nothing to write: the cloud has no points".into()));
    }
    // Points may lie a step of the grid beyond the bounds (a LAS header's
    // are rounded; a PLY cloud's points are put on the grid): the cube
    // holds them.
    let slack = DVec3::new(
        meta.transforms.x.scale,
        meta.transforms.y.scale,
        meta.transforms.z.scale,
    )
    .max_element();
    let cube = root_cube(lo - slack, hi + slack);
    // At most level 6: parts of a 4,096th of the points on a surface.
    let part_points = part_points.max(1);
    let mut level = 0;
    while level < 6 && 4u64.pow(level as u32).saturating_mul(part_points) < total {
        level += 1;
    }
    let parts = Parts::new(output, meta.record_len())?;
    let conversion = Conversion {
        parts: &parts,
        meta: &meta,
        cube,
        threads,
        fail,
    };

    // 1. Distribution.
    let distribution = Distribution {
        converter,
        meta: &meta,
        bounds: (lo - slack, hi + slack),
        cube,
        level,
    };
    let stats = conversion.distribute(&distribution, fill, (lo, hi), total)?;
    // Too large a part splits into its children, until none is.
    let ready = conversion.split(&distribution, part_points)?;
    let started = std::time::Instant::now();

    // 2. The parts, on every core.
    let laz_vlr = laz_vlr_of(&meta.format).map_err(fail)?;
    let mut length = 0;
    let mut counted = (0usize, 0i32);
    crate::image_io::write_atomically(output, |file| {
        let layout = Layout {
            format: meta.format,
            transforms: &meta.transforms,
            wkt: meta.wkt.as_deref(),
            standard_gps_time: meta.standard_gps_time,
            laz_vlr: &laz_vlr,
            extra_bytes_vlr: meta.extra_bytes_vlr.as_deref(),
        };
        let out = CopcOut::begin(file, output, layout)?;
        let (mut out, with_children) = conversion.build_parts(&ready, &laz_vlr, out)?;
        log::info!(
            "convert: parts built in {:.2} s",
            started.elapsed().as_secs_f64()
        );
        let started = std::time::Instant::now();

        // 3. The levels above the parts, from the parts' own nodes' points
        // up.
        conversion.build_top(&ready, &with_children, &laz_vlr, &mut out)?;
        log::info!(
            "convert: the top built in {:.2} s",
            started.elapsed().as_secs_f64()
        );
        counted = (
            out.entries.len(),
            out.entries.iter().map(|e| e.0.level).max().unwrap_or(0) + 1,
        );
        length = out.finish(&stats, cube)?;
        Ok(())
    })?;
    Ok(Converted {
        points: stats.points,
        nodes: counted.0,
        levels: counted.1,
        bytes: length,
    })
}

/// What the phases of an out-of-core conversion share: the parts on
/// disk, the output's format and grid, the root cube, the cores and the
/// input's errors.
struct Conversion<'a> {
    parts: &'a Parts,
    meta: &'a Records,
    cube: (DVec3, f64),
    threads: usize,
    fail: &'a (dyn Fn(String) -> Error + Sync),
}

impl Conversion<'_> {
    /// Phase 1, the distribution: every record `fill` gives, converted
    /// and put into its part's file at `distribution`'s level (grouped on
    /// every core, written on a thread of their own); the points'
    /// statistics, checked against the `total` the input declares.
    /// `bounds` are the header's, which errors name.
    fn distribute(
        &self,
        distribution: &Distribution,
        fill: &mut dyn FnMut(&mut Vec<u8>) -> Result<u64>,
        (lo, hi): (DVec3, DVec3),
        total: u64,
    ) -> Result<Stats> {
        let (parts, threads, fail) = (self.parts, self.threads, self.fail);
        let started = std::time::Instant::now();
        let mut stats = Stats::new();
        // The batches go to the parts' files on a thread of their own while
        // the next chunk decodes.
        let (to_writer, batches) = std::sync::mpsc::sync_channel::<Batch>(threads.max(1) * 4);
        let written = std::thread::scope(|scope| {
            let writer = scope.spawn(|| -> Result<Stats> {
                let mut stats = Stats::new();
                for batch in batches {
                    stats.merge(&batch.stats);
                    parts.put_groups(&batch.records, &batch.groups)?;
                }
                Ok(stats)
            });
            let read = (|| -> Result<()> {
                let mut raw = Vec::new();
                loop {
                    let got = fill(&mut raw)?;
                    if got == 0 {
                        return Ok(());
                    }
                    // Slices of the chunk converted and grouped by part on
                    // every core.
                    let per_slice = (got as usize).div_ceil(threads.max(1) * 4).max(1)
                        * distribution.converter.from_len();
                    let slices: Vec<&[u8]> = raw.chunks(per_slice).collect();
                    for batch in crate::parallel_map(&slices, threads, |r| distribution.batch(r)) {
                        let batch = batch.map_err(|p| {
                            fail(format!(
                                "a point at {p} lies outside the header's bounds ({lo} to \
                                 {hi}): fix the header's bounds first"
                            ))
                        })?;
                        if to_writer.send(batch).is_err() {
                            // The writer failed: its error is the one to tell.
                            return Ok(());
                        }
                    }
                }
            })();
            drop(to_writer);
            let written = writer.join().expect("the parts' writer panicked");
            read.and(written)
        })?;
        stats.merge(&written);
        if stats.points != total {
            return Err(fail(format!(
                "the header declares {total} points, the file holds {}",
                stats.points
            )));
        }
        log::info!(
            "convert: {} points distributed in {:.2} s",
            stats.points,
            started.elapsed().as_secs_f64()
        );
        Ok(stats)
    }

    /// The parts split until each holds at most `part_points` (or is at
    /// the deepest level): too large a part's records regrouped into its
    /// children, a block at a time on every core. The parts' keys, sorted.
    fn split(&self, distribution: &Distribution, part_points: u64) -> Result<Vec<NodeKey>> {
        let (parts, meta, threads, fail) = (self.parts, self.meta, self.threads, self.fail);
        let started = std::time::Instant::now();
        let mut queue = parts.flush_all()?;
        let mut ready = Vec::new();
        while let Some((key, count)) = queue.pop() {
            if count <= part_points || key.level >= crate::input::copc::MAX_LEVEL {
                ready.push(key);
                continue;
            }
            log::debug!("convert: part {key:?} of {count} points splits");
            // Its records regrouped a block at a time, on every core.
            let split = Distribution {
                converter: RecordConverter::new(&meta.format, &meta.format)
                    .expect("6, 7 or 8 to itself"),
                level: key.level + 1,
                ..*distribution
            };
            parts.take_in_blocks(key, PART_BUFFER_BYTES, |block| {
                let per_slice = (block.len() / meta.record_len())
                    .div_ceil(threads.max(1) * 4)
                    .max(1)
                    * meta.record_len();
                let slices: Vec<&[u8]> = block.chunks(per_slice).collect();
                for batch in crate::parallel_map(&slices, threads, |r| split.batch(r)) {
                    let batch =
                        batch.map_err(|p| fail(format!("a point at {p} moved while split")))?;
                    parts.put_groups(&batch.records, &batch.groups)?;
                }
                Ok(())
            })?;
            queue.extend(parts.flush_all()?);
        }
        ready.sort();
        log::info!(
            "convert: {} parts after {:.2} s of splitting",
            ready.len(),
            started.elapsed().as_secs_f64()
        );
        Ok(ready)
    }

    /// Phase 2: the parts `ready` built on every core, each at most a
    /// window ahead of the next to write, their nodes written to `out` in
    /// the parts' order; the first failure stops the parts not yet
    /// started. `out`, and whether each part's node has children.
    fn build_parts<'o>(
        &self,
        ready: &[NodeKey],
        laz_vlr: &LazVlr,
        out: CopcOut<'o>,
    ) -> Result<(CopcOut<'o>, std::collections::HashMap<NodeKey, bool>)> {
        let out = std::sync::Mutex::new(InOrder {
            out,
            next: 0,
            waiting: std::collections::BTreeMap::new(),
        });
        // A failed part stops the others from starting.
        let failed = std::sync::atomic::AtomicBool::new(false);
        // A part starts at most this many parts ahead of the next one to
        // write, so that the built ones waiting their turn stay few.
        let window = 2 * self.threads.max(1);
        let turn = std::sync::Condvar::new();
        let indexed: Vec<(usize, NodeKey)> = ready.iter().copied().enumerate().collect();
        let built = crate::parallel_map(&indexed, self.threads, |&(index, key)| {
            {
                // Parts are handed out in order, so the next to write is
                // being built by another thread.
                let mut o = out.lock().unwrap_or_else(|e| e.into_inner());
                while index >= o.next + window && !failed.load(std::sync::atomic::Ordering::Relaxed)
                {
                    o = turn.wait(o).unwrap_or_else(|e| e.into_inner());
                }
            }
            if failed.load(std::sync::atomic::Ordering::Relaxed) {
                return Ok(None);
            }
            let result = self.build_part(index, key, laz_vlr, &out, &turn);
            if result.is_err() {
                // Under the lock, so that no thread misses the wakeup.
                let _o = out.lock().unwrap_or_else(|e| e.into_inner());
                failed.store(true, std::sync::atomic::Ordering::Relaxed);
                turn.notify_all();
            }
            result.map(Some)
        });
        let with_children: std::collections::HashMap<NodeKey, bool> = built
            .into_iter()
            .collect::<Result<Vec<_>>>()?
            .into_iter()
            .flatten()
            .collect();
        let out = out.into_inner().unwrap_or_else(|e| e.into_inner()).out;
        Ok((out, with_children))
    }

    /// Builds part `key` (the `index`th to write) as an octree in memory:
    /// its nodes below its own compressed and handed to `out` (`turn`
    /// told), its own node's points stored for the levels above. The key,
    /// and whether its node has children.
    fn build_part(
        &self,
        index: usize,
        key: NodeKey,
        laz_vlr: &LazVlr,
        out: &std::sync::Mutex<InOrder<'_>>,
        turn: &std::sync::Condvar,
    ) -> Result<(NodeKey, bool)> {
        let part = Records {
            bytes: self.parts.take(key)?,
            ..self.meta.clone_meta()
        };
        let mut nodes = Vec::new();
        build_node(
            &part,
            key,
            key.cube_in(self.cube),
            part.all_points(),
            1,
            &mut nodes,
        );
        let own = nodes
            .iter()
            .position(|n| n.key == key)
            .expect("the part's node");
        let own = nodes.swap_remove(own);
        let chunks =
            compress_nodes(&part, &nodes, laz_vlr, 1).map_err(|e| (self.fail)(e.to_string()))?;
        let written = nodes
            .iter()
            .zip(chunks)
            .map(|(n, c)| (n.key, n.points.len() as u64, c))
            .collect();
        out.lock()
            .unwrap_or_else(|e| e.into_inner())
            .put(index, written)?;
        turn.notify_all();
        // The part's own node's points: candidates for the levels above,
        // on disk until they are reached.
        self.parts
            .put_own(key, &gather_records(&part, &own.points))?;
        // Whether the part's node has children (its own node is out of
        // `nodes`).
        Ok((key, !nodes.is_empty()))
    }

    /// Phase 3: the levels above the parts `ready`, sampled from the
    /// parts' own nodes' points up ([`Top`]) and written to `out`.
    fn build_top(
        &self,
        ready: &[NodeKey],
        with_children: &std::collections::HashMap<NodeKey, bool>,
        laz_vlr: &LazVlr,
        out: &mut CopcOut<'_>,
    ) -> Result<()> {
        let mut above = std::collections::HashSet::new();
        for key in ready {
            let mut k = *key;
            while k.level > 0 {
                k = k.parent();
                above.insert(k);
            }
        }
        let mut top = Top {
            parts: self.parts,
            meta: self.meta,
            root: self.cube,
            above: &above,
            with_children,
            laz_vlr,
            out,
            threads: self.threads,
        };
        let root = top.node(NodeKey::ROOT)?;
        top.write(vec![(NodeKey::ROOT, root)])
    }
}

/// The octree's levels above the parts, sampled from the bottom up
/// (as PotreeConverter 2 does): a node's points are one per cell of its
/// grid from its children's points, the point nearest the cell's centre;
/// what a child keeps is then final and written. Only the nodes on the
/// path being built hold points: a part's own node's points wait on disk.
struct Top<'a, 'o> {
    parts: &'a Parts,
    meta: &'a Records,
    root: (DVec3, f64),
    /// The nodes above the parts.
    above: &'a std::collections::HashSet<NodeKey>,
    /// Each part, and whether its node has children.
    with_children: &'a std::collections::HashMap<NodeKey, bool>,
    laz_vlr: &'a LazVlr,
    out: &'a mut CopcOut<'o>,
    threads: usize,
}

impl Top<'_, '_> {
    /// Node `key`'s points before its ancestors take theirs: a part's own
    /// node's, or a sample of its children's (the children written).
    fn node(&mut self, key: NodeKey) -> Result<Vec<u8>> {
        if self.with_children.contains_key(&key) {
            return self.parts.take_own(key);
        }
        let mut pooled = Records {
            bytes: Vec::new(),
            ..self.meta.clone_meta()
        };
        let mut owners: Vec<(NodeKey, std::ops::Range<u32>)> = Vec::new();
        for child in key.children() {
            if self.above.contains(&child) || self.with_children.contains_key(&child) {
                let bytes = self.node(child)?;
                let start = pooled.len() as u32;
                pooled.bytes.extend_from_slice(&bytes);
                owners.push((child, start..pooled.len() as u32));
            }
        }
        let (min, width) = key.cube_in(self.root);
        let (mut kept, _) = sample(&pooled, &pooled.all_points(), min, width);
        // What each child keeps: its points the sample did not take.
        let mut taken = vec![false; pooled.len()];
        for &i in &kept {
            taken[i as usize] = true;
        }
        let children = owners
            .into_iter()
            .map(|(child, range)| {
                let left: Vec<u32> = range.filter(|&i| !taken[i as usize]).collect();
                (child, gather_records(&pooled, &left))
            })
            .collect();
        self.write(children)?;
        // The kept points in their order in the pool (children, then
        // input order), for their ancestors.
        kept.sort_unstable();
        Ok(gather_records(&pooled, &kept))
    }

    /// Writes final nodes (key, records), compressed on every core; a node
    /// left without points is an empty entry where it has children, and
    /// no entry where it has none.
    fn write(&mut self, nodes: Vec<(NodeKey, Vec<u8>)>) -> Result<()> {
        let vlr = self.laz_vlr;
        let chunks = crate::parallel_map(&nodes, self.threads, |(_, bytes)| {
            compress_records(bytes, vlr)
        });
        for ((key, bytes), chunk) in nodes.iter().zip(chunks) {
            let chunk = chunk.map_err(|e| Error::Io {
                path: self.out.path.to_path_buf(),
                source: e,
            })?;
            let count = (bytes.len() / self.meta.record_len()) as u64;
            if count > 0 {
                self.out.node(*key, count, &chunk)?;
            } else if self.above.contains(key) || self.with_children.get(key) == Some(&true) {
                self.out.empty(*key);
            }
        }
        Ok(())
    }
}

/// The cell at `level` of the octree `root` that holds `p`.
fn cell_of(p: DVec3, (min, width): (DVec3, f64), level: i32) -> NodeKey {
    let n = 1i32 << level;
    // Truncation is the floor wherever the clamp lets it matter.
    let c = ((p - min) / width * f64::from(n))
        .as_ivec3()
        .clamp(IVec3::ZERO, IVec3::splat(n - 1));
    NodeKey {
        level,
        x: c.x,
        y: c.y,
        z: c.z,
    }
}

/// The records of `points`, one after another.
fn gather_records(records: &Records, points: &[u32]) -> Vec<u8> {
    // The formats' lengths as constants, so that each copy is a few moves
    // instead of a call of memmove (a tenth of a conversion's time).
    match records.record_len() {
        30 => gather_fixed::<30>(&records.bytes, points),
        36 => gather_fixed::<36>(&records.bytes, points),
        len => {
            let mut out = Vec::with_capacity(points.len() * len);
            for &p in points {
                out.extend_from_slice(&records.bytes[p as usize * len..(p as usize + 1) * len]);
            }
            out
        }
    }
}

/// [`gather_records`] for records of `N` bytes.
fn gather_fixed<const N: usize>(bytes: &[u8], points: &[u32]) -> Vec<u8> {
    let (records, _) = bytes.as_chunks::<N>();
    let mut out: Vec<[u8; N]> = Vec::with_capacity(points.len());
    out.extend(points.iter().map(|&p| records[p as usize]));
    out.into_flattened()
}

/// The distribution's work on the input's records: each converted to the
/// output's format, checked against the header's bounds and put in its
/// part's cell at `level`.
#[derive(Clone, Copy)]
struct Distribution<'a> {
    converter: RecordConverter,
    meta: &'a Records,
    /// The header's bounds widened by one step of the grid.
    bounds: (DVec3, DVec3),
    cube: (DVec3, f64),
    level: i32,
}

/// Records in the output's format sorted by part, with the statistics of
/// their points.
struct Batch {
    stats: Stats,
    records: Vec<u8>,
    /// Each part's cell and where its records end.
    groups: Vec<(NodeKey, usize)>,
}

impl Distribution<'_> {
    /// The batch of the input records `raw`, or the position of a point
    /// outside the header's bounds.
    fn batch(&self, raw: &[u8]) -> std::result::Result<Batch, DVec3> {
        // Each record's group (its cell; coordinates are the first 12
        // bytes in every format), groups in order of first appearance;
        // then the records converted into their group's place (a counting
        // sort: reads in order, writes to as many places as groups).
        let from_len = self.converter.from_len();
        let n = raw.len() / from_len;
        let mut stats = Stats::new();
        let mut group_of: Vec<u32> = Vec::with_capacity(n);
        // A group for each cell: a table of the level's cells up to level
        // 6 (64³), a map below (a part's split).
        let side = 1usize << self.level.min(6);
        let mut index = match self.level <= 6 {
            true => vec![u32::MAX; side * side * side],
            false => Vec::new(),
        };
        let mut sparse: std::collections::HashMap<NodeKey, u32> = Default::default();
        let mut groups: Vec<(NodeKey, usize)> = Vec::new();
        for r in raw.chunks_exact(from_len) {
            let p = self.meta.position_of(r);
            if p.cmplt(self.bounds.0).any() || p.cmpgt(self.bounds.1).any() {
                return Err(p);
            }
            stats.add_position(p);
            let key = cell_of(p, self.cube, self.level);
            let slot = match index.is_empty() {
                false => {
                    &mut index[(key.z as usize * side + key.y as usize) * side + key.x as usize]
                }
                true => sparse.entry(key).or_insert(u32::MAX),
            };
            if *slot == u32::MAX {
                *slot = groups.len() as u32;
                groups.push((key, 0));
            }
            let g = *slot;
            groups[g as usize].1 += 1;
            group_of.push(g);
        }
        // Counts to places, then to ends.
        let to_len = self.converter.to_len();
        let mut place: Vec<usize> = Vec::with_capacity(groups.len());
        let mut at = 0;
        for (_, count) in &mut groups {
            place.push(at);
            at += *count * to_len;
            *count = at;
        }
        let mut records = vec![0; n * to_len];
        for (r, &g) in raw.chunks_exact(from_len).zip(&group_of) {
            let o = &mut records[place[g as usize]..][..to_len];
            self.converter.convert(r, o);
            stats.add_record(o);
            place[g as usize] += to_len;
        }
        Ok(Batch {
            stats,
            records,
            groups,
        })
    }
}

/// The parts of an out-of-core conversion: a file per octree cell in a
/// folder beside the output (removed with it), written through bounded
/// buffers.
struct Parts {
    dir: std::path::PathBuf,
    record_len: usize,
    state: std::sync::Mutex<PartsState>,
}

#[derive(Default)]
struct PartsState {
    buffers: std::collections::HashMap<NodeKey, Vec<u8>>,
    buffered: usize,
    counts: std::collections::HashMap<NodeKey, u64>,
}

/// The most bytes the parts' buffers hold before they are written out.
const PART_BUFFER_BYTES: usize = 64 << 20;

impl Parts {
    fn new(output: &Path, record_len: usize) -> Result<Parts> {
        let name = output
            .file_name()
            .map_or("out".into(), |n| n.to_string_lossy());
        let dir = output.with_file_name(format!(".{name}.parts-{}", std::process::id()));
        // Listed before it exists: a signal removes it with the output's
        // temporary, whenever it comes.
        crate::image_io::list_scratch_dir(&dir);
        if let Err(e) = std::fs::create_dir_all(&dir) {
            crate::image_io::unlist_scratch_dir(&dir);
            return Err(Error::Io {
                path: dir.clone(),
                source: e,
            });
        }
        Ok(Parts {
            dir,
            record_len,
            state: std::sync::Mutex::new(PartsState::default()),
        })
    }

    fn file(&self, key: NodeKey) -> std::path::PathBuf {
        self.dir
            .join(format!("{}-{}-{}-{}", key.level, key.x, key.y, key.z))
    }

    fn io(&self, e: std::io::Error) -> Error {
        Error::Io {
            path: self.dir.clone(),
            source: e,
        }
    }

    /// Adds the records of each group (a part's cell and where its
    /// records in `records` end).
    fn put_groups(&self, records: &[u8], groups: &[(NodeKey, usize)]) -> Result<()> {
        let mut s = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let mut start = 0;
        for &(key, end) in groups {
            let bytes = &records[start..end];
            s.buffers.entry(key).or_default().extend_from_slice(bytes);
            *s.counts.entry(key).or_default() += (bytes.len() / self.record_len) as u64;
            s.buffered += bytes.len();
            start = end;
        }
        if s.buffered > PART_BUFFER_BYTES {
            self.write_out(&mut s)?;
        }
        Ok(())
    }

    fn write_out(&self, s: &mut PartsState) -> Result<()> {
        for (key, bytes) in s.buffers.drain() {
            let mut f = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(self.file(key))
                .map_err(|e| self.io(e))?;
            f.write_all(&bytes).map_err(|e| self.io(e))?;
        }
        s.buffered = 0;
        Ok(())
    }

    /// Writes every buffer out; returns the parts made since the last call
    /// and their point counts.
    fn flush_all(&self) -> Result<Vec<(NodeKey, u64)>> {
        let mut s = self.state.lock().unwrap_or_else(|e| e.into_inner());
        self.write_out(&mut s)?;
        Ok(s.counts.drain().collect())
    }

    /// Stores part `key`'s own node's records (written once).
    fn put_own(&self, key: NodeKey, records: &[u8]) -> Result<()> {
        std::fs::write(self.own_file(key), records).map_err(|e| self.io(e))
    }

    /// Part `key`'s own node's records, their file removed.
    fn take_own(&self, key: NodeKey) -> Result<Vec<u8>> {
        let path = self.own_file(key);
        let bytes = std::fs::read(&path).map_err(|e| self.io(e))?;
        std::fs::remove_file(&path).map_err(|e| self.io(e))?;
        Ok(bytes)
    }

    fn own_file(&self, key: NodeKey) -> std::path::PathBuf {
        self.dir
            .join(format!("own-{}-{}-{}-{}", key.level, key.x, key.y, key.z))
    }

    /// Part `key`'s records a block of at most `block_bytes` (whole
    /// records, at least one) at a time, its file removed.
    fn take_in_blocks(
        &self,
        key: NodeKey,
        block_bytes: usize,
        mut f: impl FnMut(&[u8]) -> Result<()>,
    ) -> Result<()> {
        use std::io::Read;
        let path = self.file(key);
        let mut file = File::open(&path).map_err(|e| self.io(e))?;
        let mut block = vec![0u8; (block_bytes / self.record_len).max(1) * self.record_len];
        loop {
            let mut filled = 0;
            while filled < block.len() {
                match file.read(&mut block[filled..]) {
                    Ok(0) => break,
                    Ok(n) => filled += n,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(e) => return Err(self.io(e)),
                }
            }
            if filled > 0 {
                f(&block[..filled - filled % self.record_len])?;
            }
            if filled < block.len() {
                break;
            }
        }
        drop(file);
        std::fs::remove_file(&path).map_err(|e| self.io(e))
    }

    /// Part `key`'s records, its file removed.
    fn take(&self, key: NodeKey) -> Result<Vec<u8>> {
        let path = self.file(key);
        let bytes = std::fs::read(&path).map_err(|e| self.io(e))?;
        std::fs::remove_file(&path).map_err(|e| self.io(e))?;
        debug_assert_eq!(bytes.len() % self.record_len, 0);
        Ok(bytes)
    }
}

impl Drop for Parts {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
        crate::image_io::unlist_scratch_dir(&self.dir);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use las::Point;

    /// Appends `point`'s record in `format` under `transforms`.
    fn write_record(
        bytes: &mut Vec<u8>,
        mut point: Point,
        format: &Format,
        transforms: &las::Vector<Transform>,
        path: &Path,
    ) -> Result<()> {
        if !format.has_color {
            point.color = None;
        } else if point.color.is_none() {
            point.color = Some(las::Color::default());
        }
        if point.gps_time.is_none() {
            point.gps_time = Some(0.0);
        }
        if !format.has_nir {
            point.nir = None;
        } else if point.nir.is_none() {
            point.nir = Some(0);
        }
        point.waveform = None;
        point.return_number = point.return_number.max(1);
        point.number_of_returns = point.number_of_returns.max(point.return_number);
        let raw = point.into_raw(transforms).map_err(|e| Error::Las {
            path: path.to_path_buf(),
            msg: format!("a point does not fit the output's grid: {e}"),
        })?;
        raw.write_to(&mut *bytes, format).map_err(|e| Error::Las {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })?;
        Ok(())
    }

    /// Records of `format` with random codes in a small box (so that cells
    /// hold several points, with exact ties in distance: duplicates), the
    /// other bytes random.
    fn random_records(format: u8, n: usize) -> Records {
        let mut records = Records::for_cloud_within(DVec3::ZERO, DVec3::splat(1.0), true);
        records.format = Format::new(format).expect("6, 7 or 8");
        let axis = Transform {
            scale: 0.001,
            offset: 0.0,
        };
        records.transforms = las::Vector {
            x: axis,
            y: axis,
            z: axis,
        };
        let len = records.record_len();
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for i in 0..n {
            let mut r: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            // Every fifth point a copy of an earlier one's position; the
            // rest in a slab of ±0.2 × ±0.2 × ±0.03 of the cube ±1, about
            // 10 points a cell.
            let codes = if i % 5 == 4 {
                codes_of(&records.bytes[(i / 2) * len..])
            } else {
                let r = next();
                let code =
                    |shift: u64, half: i32| ((r >> shift) % (2 * half as u64 + 1)) as i32 - half;
                [code(0, 200), code(16, 200), code(32, 30)]
            };
            for (k, c) in codes.iter().enumerate() {
                r[4 * k..4 * k + 4].copy_from_slice(&c.to_le_bytes());
            }
            records.bytes.extend_from_slice(&r);
        }
        records
    }

    /// `sample` (its points carried with their codes) keeps and passes on
    /// exactly what the definition says, in its order: of each cell, the
    /// point nearest the centre (ties to the lower index), the rest to
    /// their octants, all in (cell, distance², index) order, positions read
    /// from the records themselves. Also from a shuffled start, as a
    /// child's list arrives.
    #[test]
    fn the_grid_sample_is_its_definition() {
        let records = random_records(7, 20_000);
        let (min, width) = root_cube(DVec3::splat(-1.0), DVec3::splat(1.0));
        let reference = |points: &[u32]| {
            let cell = width / f64::from(GRID_CELLS);
            let mid = min + DVec3::splat(width / 2.0);
            let len = records.record_len();
            let mut keyed: Vec<(u64, u32, usize)> = points
                .iter()
                .map(|&i| {
                    let p = records.position_of(&records.bytes[i as usize * len..]);
                    let c = ((p - min) / cell)
                        .floor()
                        .clamp(DVec3::ZERO, DVec3::splat(127.0));
                    let id = (c.z as u64 * 128 + c.y as u64) * 128 + c.x as u64;
                    let d = ((p - (min + (c + 0.5) * cell)) / cell).length_squared() as f32;
                    ((id << 32) | u64::from(d.to_bits()), i, octant(p, mid))
                })
                .collect();
            keyed.sort();
            let mut kept = Vec::new();
            let mut children: [Vec<u32>; 8] = Default::default();
            for (n, &(k, i, o)) in keyed.iter().enumerate() {
                if n == 0 || keyed[n - 1].0 >> 32 != k >> 32 {
                    kept.push(i);
                } else {
                    children[o].push(i);
                }
            }
            (kept, children)
        };
        let all = records.all_points();
        let mut shuffled = all.clone();
        shuffled.reverse();
        shuffled.rotate_left(7_777);
        for points in [&all, &shuffled] {
            let indices: Vec<u32> = points.iter().map(|p| p.index).collect();
            let (kept, children) = sample(&records, points, min, width);
            let children = children.map(|c| c.iter().map(|p| p.index).collect::<Vec<u32>>());
            let (want_kept, want_children) = reference(&indices);
            assert!(
                kept.len() > 500 && kept.len() < 5_000,
                "{} kept",
                kept.len()
            );
            assert_eq!(kept, want_kept);
            assert_eq!(children, want_children);
        }
    }

    /// Gathering records by index gives each record's bytes, in that
    /// order, for both output formats.
    #[test]
    fn gathered_records_are_the_records() {
        for format in [6, 7, 8] {
            let records = random_records(format, 1_000);
            let len = records.record_len();
            let points: Vec<u32> = (0..3_000).map(|k| (k * 7_919 % 1_000) as u32).collect();
            let want: Vec<u8> = points
                .iter()
                .flat_map(|&p| records.bytes[p as usize * len..][..len].iter().copied())
                .collect();
            assert_eq!(gather_records(&records, &points), want);
        }
    }

    /// The byte-level conversion equals the one through `las::Point`
    /// (`write_record`) for every input format, on random records.
    /// Outside its scope: a legacy class of 28, which las reads as overlap
    /// (its test looks at four bits), and an extended record of class 12,
    /// which las moves to class 1 with the overlap flag and the
    /// conversion keeps as it is, as a 6 → 6 copy does; and an extended
    /// scan angle, which las moves through degrees in an f32 (losing a
    /// step at times) and the conversion copies.
    #[test]
    fn record_conversion_equals_las() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut byte = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 24) as u8
        };
        let transforms = las::Vector {
            x: Transform {
                scale: 0.01,
                offset: 0.0,
            },
            y: Transform {
                scale: 0.01,
                offset: 0.0,
            },
            z: Transform {
                scale: 0.01,
                offset: 0.0,
            },
        };
        let path = Path::new("test");
        let mut checked = 0;
        for id in 0..=10u8 {
            for to_id in [6u8, 7, 8] {
                let mut from = Format::new(id).expect("a format");
                from.extra_bytes = 3;
                let mut to = Format::new(to_id).expect("6, 7 or 8");
                to.extra_bytes = 3;
                let converter = RecordConverter::new(&from, &to).expect("a conversion");
                assert_eq!(converter.to_len(), usize::from(to.len()));
                for _ in 0..2000 {
                    let mut r: Vec<u8> = (0..from.len()).map(|_| byte()).collect();
                    let legacy = id <= 5;
                    if legacy && r[15] & 0x1F == 28 || !legacy && r[16] == 12 {
                        continue;
                    }
                    // Codes within i32 that a f64 round trip keeps.
                    for k in 0..3 {
                        r[4 * k + 3] &= 0x3F;
                    }
                    if !legacy {
                        // A finite GPS time.
                        r[29] &= 0x3F;
                    } else if matches!(id, 1 | 3 | 4 | 5) {
                        r[27] &= 0x3F;
                    }
                    let raw = las::raw::Point::read_from(&r[..], &from).expect("a raw point");
                    let point = Point::new(raw, &transforms);
                    let mut expected = Vec::new();
                    write_record(&mut expected, point, &to, &transforms, path).expect("a record");
                    let mut got = vec![0; converter.to_len()];
                    converter.convert(&r, &mut got);
                    if !legacy {
                        // las's f32 round trip of the angle is lossy.
                        assert_eq!(got[18..20], r[18..20], "format {id}'s scan angle");
                        expected[18..20].copy_from_slice(&r[18..20]);
                    }
                    assert_eq!(got, expected, "format {id} to {to_id}, record {r:?}");
                    checked += 1;
                }
            }
        }
        assert!(checked > 60_000, "{checked} records compared");
    }

    /// A part read back a block at a time gives its records in order, in
    /// whole records, and leaves no file.
    #[test]
    fn a_part_is_read_back_in_blocks() {
        let dir = std::env::temp_dir().join(format!("pointlens-parts-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let parts = Parts::new(&dir.join("out.copc.laz"), 36).unwrap();
        let key = NodeKey::ROOT;
        let records: Vec<u8> = (0..36 * 10).map(|i| (i % 251) as u8).collect();
        parts.put_groups(&records, &[(key, records.len())]).unwrap();
        assert_eq!(parts.flush_all().unwrap(), [(key, 10)]);
        for block_bytes in [1, 36 * 3, 36 * 3 + 5, 36 * 10, 36 * 64] {
            let again = Parts::new(&dir.join(format!("b{block_bytes}.copc.laz")), 36).unwrap();
            again.put_groups(&records, &[(key, records.len())]).unwrap();
            again.flush_all().unwrap();
            let mut read = Vec::new();
            let mut sizes = Vec::new();
            again
                .take_in_blocks(key, block_bytes, |b| {
                    sizes.push(b.len());
                    read.extend_from_slice(b);
                    Ok(())
                })
                .unwrap();
            assert_eq!(read, records, "blocks of {block_bytes}");
            assert!(sizes.iter().all(|s| s % 36 == 0 && *s > 0), "{sizes:?}");
            assert!(!again.file(key).exists());
        }
        drop(parts);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A cloud's record is the one `las::Point` makes of its position and
    /// color.
    #[test]
    fn a_cloud_record_is_las_point_record() {
        let records =
            Records::for_cloud_within(DVec3::splat(-3.0), DVec3::new(5.0, 2.0, 9.0), true);
        let format = Format::new(7).expect("format 7");
        let mut state = 1u32;
        let mut next = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        for _ in 0..10_000 {
            let p = DVec3::new(
                -3.0 + 8.0 * f64::from(next()),
                -3.0 + 5.0 * f64::from(next()),
                -3.0 + 12.0 * f64::from(next()),
            );
            let c = glam::Vec3::new(next() * 1.2 - 0.1, next(), next());
            let mut got = Vec::new();
            cloud_record(p, (Some(c), 0), &records.transforms, &mut got).expect("on the grid");
            let code = |v: f32| {
                let s = crate::image_io::linear_to_srgb(v.clamp(0.0, 1.0));
                (s * 65535.0).round() as u16
            };
            let point = Point {
                x: p.x,
                y: p.y,
                z: p.z,
                color: Some(las::Color::new(code(c.x), code(c.y), code(c.z))),
                return_number: 1,
                number_of_returns: 1,
                ..Point::default()
            };
            let mut expected = Vec::new();
            write_record(
                &mut expected,
                point,
                &format,
                &records.transforms,
                Path::new("t"),
            )
            .expect("a record");
            assert_eq!(got, expected);
        }
    }
}

/// What `pointlens convert` is asked: a cloud to write as COPC.
#[derive(Debug, Clone)]
pub struct ConvertOptions {
    /// PLY, LAS, LAZ or COPC.
    pub input: PathBuf,
    /// The COPC file, `.copc.laz`, replaced atomically.
    pub output: PathBuf,
    /// Memory for a PLY file read whole, MiB (`--memory-mb`).
    pub memory_mb: u64,
    /// Threads that compress (the file is the same on any number).
    pub threads: usize,
    /// Points of one part of the out-of-core sort.
    pub part_points: u64,
}

impl ConvertOptions {
    /// `input` to `output` with the machine's threads and
    /// [`PART_POINTS`]; tests choose them through the environment
    /// (`POINTLENS_CONVERT_THREADS`, `POINTLENS_CONVERT_PART_POINTS`) to
    /// split a small file into many parts.
    pub fn new(input: &Path, output: &Path, memory_mb: u64) -> ConvertOptions {
        let env = |name: &str| std::env::var(name).ok();
        ConvertOptions {
            input: input.to_path_buf(),
            output: output.to_path_buf(),
            memory_mb,
            threads: env("POINTLENS_CONVERT_THREADS")
                .and_then(|v| v.parse::<usize>().ok())
                .unwrap_or_else(crate::available_threads)
                .max(1),
            part_points: env("POINTLENS_CONVERT_PART_POINTS")
                .and_then(|v| v.parse().ok())
                .unwrap_or(PART_POINTS),
        }
    }
}

/// `pointlens convert`: checks the names (a `.copc.laz` output in an
/// existing folder, not the input, which holds no 3D Gaussians), makes
/// SIGINT and SIGTERM remove the parts in writing, and converts:
/// a LAS, LAZ or binary PLY file streamed, any other PLY read whole within
/// `memory_mb` (`progress(done, total)` follows that reading).
pub fn convert_file(
    options: &ConvertOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Converted> {
    let (input, output) = (&options.input, &options.output);
    let invalid = |msg: String| Err(Error::InvalidArgument(msg));
    if !output
        .to_string_lossy()
        .to_lowercase()
        .ends_with(".copc.laz")
    {
        return invalid(format!(
            "{}: convert writes COPC: name the output .copc.laz",
            output.display()
        ));
    }
    crate::image_io::check_parent_dir(output, "-o")?;
    if input.canonicalize().ok() == output.canonicalize().ok() && output.exists() {
        return invalid(format!(
            "{}: the output would replace the input",
            output.display()
        ));
    }
    if crate::input::kind_of(input) == crate::input::InputKind::Gaussians {
        return invalid(format!(
            "{}: it holds 3D Gaussians, which a COPC file of points cannot hold",
            input.display()
        ));
    }
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    crate::job::watch_signals(false, stop)?;
    let (threads, part_points) = (options.threads, options.part_points);
    if crate::input::is_las(input) {
        // Checked as `render` checks it first (one line on a bad file).
        crate::input::las::check_las(input)?;
        return convert_las(input, output, threads, part_points);
    }
    // A binary PLY file streams; an ASCII one, a pipe, or a file the
    // direct reader declines is read whole.
    if let Some(done) = convert_ply(input, output, threads, part_points)? {
        return Ok(done);
    }
    // Perhaps by the general reader, which names what is wrong with the
    // file.
    crate::input::check_whole_read_fits(input, options.memory_mb, true, |_| {
        "convert streams only a regular binary PLY file whose vertices are all \
             well-formed; this one it must read whole"
            .into()
    })?;
    let cloud = crate::input::load_cloud(input, None, progress)?;
    let records = Records::of_cloud(&cloud, input)?;
    write_copc(&records, output, threads)
}
