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
//! The file: LAS 1.4, point format 6 (7 with colors), the input's scale and
//! offset (a LAS input's integer codes are kept as they are); the COPC info
//! VLR first, the laszip VLR (variable-size chunks: one chunk per node,
//! compressed on every core), the input's WKT CRS; after the points the
//! chunk table and the hierarchy as one page (root entry first) in an
//! extended VLR. Written to a temporary file beside the output and renamed
//! into place when complete.
//!
//! A LAS, LAZ or COPC input is converted out of core ([`convert_las`]:
//! parts of the octree spilled to files beside the output, built apart);
//! an in-memory cloud (PLY) by [`write_copc`].

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::Path;

use glam::DVec3;
use las::point::Format;
use las::{Point, Transform};
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
        }
    }

    /// A record's position in file coordinates.
    fn position_of(&self, r: &[u8]) -> DVec3 {
        let c = |k: usize| i32::from_le_bytes(r[4 * k..4 * k + 4].try_into().expect("4 bytes"));
        let t = &self.transforms;
        DVec3::new(t.x.direct(c(0)), t.y.direct(c(1)), t.z.direct(c(2)))
    }

    /// Point `i` in file coordinates.
    fn position(&self, i: usize) -> DVec3 {
        self.position_of(&self.bytes[i * self.record_len()..])
    }

    /// The output's format (6, or 7 where the input has colors), grid,
    /// WKT and GPS time type for a LAS file of `header`.
    fn meta_of(header: &las::Header, path: &Path) -> Result<Records> {
        let fail = |msg: String| Error::Las {
            path: path.to_path_buf(),
            msg,
        };
        let format = match header.point_format().has_color {
            true => Format::new(7).expect("format 7"),
            false => Format::new(6).expect("format 6"),
        };
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
                "{}: its CRS is GeoTIFF keys, which COPC (LAS 1.4, point format 6 and 7) \
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
        })
    }

    /// The records of an in-memory cloud (a PLY file's): format 7 with its
    /// colors as 16-bit sRGB, positions on a grid of 10^k units fine enough
    /// for f32 (7 digits over the largest extent), centred on its bounds.
    pub fn of_cloud(cloud: &PointCloud, path: &Path) -> Result<Records> {
        let (lo, hi) = cloud.bounds();
        let (lo, hi) = (lo.as_dvec3() + cloud.origin, hi.as_dvec3() + cloud.origin);
        // A single point (or one place) still gets a grid.
        let extent = (hi - lo).max_element().max(1e-6);
        let scale = 10f64.powf((extent * 1e-7).log10().floor());
        let centre = (lo + hi) / 2.0;
        let offset = (centre / scale).round() * scale;
        let transforms = las::Vector {
            x: Transform {
                scale,
                offset: offset.x,
            },
            y: Transform {
                scale,
                offset: offset.y,
            },
            z: Transform {
                scale,
                offset: offset.z,
            },
        };
        let format = Format::new(7).expect("format 7");
        let mut bytes = Vec::with_capacity(cloud.len() * usize::from(format.len()));
        for (p, c) in cloud.positions.iter().zip(&cloud.colors) {
            let p = p.as_dvec3() + cloud.origin;
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
            write_record(&mut bytes, point, &format, &transforms, path)?;
        }
        Ok(Records {
            format,
            transforms,
            bytes,
            wkt: None,
            standard_gps_time: false,
        })
    }
}

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
    point.nir = None;
    point.waveform = None;
    point.extra_bytes.clear();
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
    let all: Vec<u32> = (0..records.len() as u32).collect();
    let mut out = Vec::new();
    build_node(records, NodeKey::ROOT, cube, all, threads, &mut out);
    out
}

fn build_node(
    records: &Records,
    key: NodeKey,
    (min, width): (DVec3, f64),
    points: Vec<u32>,
    threads: usize,
    out: &mut Vec<Node>,
) {
    if points.len() <= MAX_NODE_POINTS || key.level >= crate::input::copc::MAX_LEVEL {
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
/// centre, ties to the lower index), sorted, and the rest by octant.
fn sample(records: &Records, points: &[u32], min: DVec3, width: f64) -> (Vec<u32>, [Vec<u32>; 8]) {
    // The points sorted by (cell, distance², index), the first of each
    // cell kept.
    let cell = width / f64::from(GRID_CELLS);
    let last = f64::from(GRID_CELLS - 1);
    let mut keyed: Vec<(u64, u32)> = points
        .iter()
        .map(|&i| {
            let p = records.position(i as usize);
            let c = ((p - min) / cell)
                .floor()
                .clamp(DVec3::ZERO, DVec3::splat(last));
            let centre = min + (c + 0.5) * cell;
            let i3 = c.as_uvec3();
            let id = (i3.z * GRID_CELLS + i3.y) * GRID_CELLS + i3.x;
            // A non-negative f32's bits order as the value does.
            let d = ((p - centre) / cell).length_squared() as f32;
            ((u64::from(id) << 32) | u64::from(d.to_bits()), i)
        })
        .collect();
    keyed.sort_unstable();
    let mut kept: Vec<u32> = Vec::new();
    let mut previous = u64::MAX;
    for &(k, i) in &keyed {
        if k >> 32 != previous {
            kept.push(i);
            previous = k >> 32;
        }
    }
    drop(keyed);
    kept.sort_unstable();
    let mut children: [Vec<u32>; 8] = Default::default();
    let mid = min + DVec3::splat(width / 2.0);
    let mut k = 0;
    for &i in points {
        if k < kept.len() && kept[k] == i {
            k += 1;
            continue;
        }
        let p = records.position(i as usize);
        children[octant(p, mid)].push(i);
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
    let items = LazItemRecordBuilder::default_for_point_format_id(
        records.format.to_u8().expect("6 or 7"),
        0,
    )
    .map_err(|e| fail(e.to_string()))?;
    let laz_vlr = LazVlrBuilder::new(items).with_variable_chunk_size().build();
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

/// Each node's points as one LAZ chunk, compressed on every core.
fn compress_nodes(
    records: &Records,
    nodes: &[Node],
    vlr: &LazVlr,
    threads: usize,
) -> std::io::Result<Vec<Vec<u8>>> {
    crate::parallel_map(nodes, threads, |node| {
        let raw = gather_records(records, &node.points);
        let mut c = LayeredPointRecordCompressor::new(Vec::new());
        c.set_fields_from(vlr.items())
            .map_err(std::io::Error::other)?;
        c.compress_many(&raw)?;
        c.done()?;
        Ok(c.into_inner())
    })
    .into_iter()
    .collect()
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

    /// Adds one record (format 6 or 7) at file position `p`.
    fn add(&mut self, p: DVec3, r: &[u8]) {
        self.lo = self.lo.min(p);
        self.hi = self.hi.max(p);
        let ret = usize::from(r[14] & 0x0F);
        if (1..=15).contains(&ret) {
            self.by_return[ret - 1] += 1;
        }
        let gps = f64::from_le_bytes(r[22..30].try_into().expect("8 bytes"));
        self.gps = (self.gps.0.min(gps), self.gps.1.max(gps));
        self.points += 1;
    }
}

/// What a COPC file's header and VLRs take from its points' source.
struct Layout<'a> {
    format: Format,
    transforms: &'a las::Vector<Transform>,
    wkt: Option<&'a [u8]>,
    standard_gps_time: bool,
    laz_vlr: &'a LazVlr,
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
            point_data_record_format: l.format.to_u8().expect("6 or 7") | 0x80,
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
/// (docs/ARCHITECTURE.md, "Converting to COPC"):
///
/// 1. One pass over the input's points puts each record (in format 6 or
///    7) into a file for its octree cell at a level where the parts are
///    about `part_points` each (the header's count spread over a surface),
///    beside the output; a part that came out larger is split into its
///    eight children, again, until none is.
/// 2. Each part is built as an octree in memory ([`build_node`]), on every
///    core a part each; its nodes below the part's own go to the file as
///    they are made, and the part's own node's points stay as candidates.
/// 3. The candidates are sampled from the root down to the parts' cells,
///    each node keeping a point per cell of its 128³ grid; what reaches a
///    part's cell is that node's points.
///
/// Memory: the parts being built, the candidates, and the write buffers
/// of the distribution (bounded); disk: the input's records once more.
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
    let mut reader = las::Reader::from_path(input).map_err(|e| fail(e.to_string()))?;
    let header = reader.header().clone();
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
    let cube = root_cube(lo, hi);
    let total = header.number_of_points();
    let mut level = 0;
    while level < 6 && 4u64.pow(level as u32) * part_points < total {
        level += 1;
    }
    let parts = Parts::new(output, meta.record_len())?;

    // 1. Distribution.
    let mut stats = Stats::new();
    let mut data = las::PointDataBuilder::new().for_header(&header).build();
    let same_records = header.point_format().to_u8().ok() == meta.format.to_u8().ok()
        && header.point_format().len() == meta.format.len();
    let slack = DVec3::new(
        meta.transforms.x.scale,
        meta.transforms.y.scale,
        meta.transforms.z.scale,
    );
    let mut converted = Vec::new();
    loop {
        let got = reader
            .fill_points(crate::input::las::CHUNK_POINTS, &mut data)
            .map_err(|e| fail(e.to_string().replace('\n', " ")))?;
        if got == 0 {
            break;
        }
        let records: &[u8] = if same_records {
            data.raw_bytes()
        } else {
            converted.clear();
            for point in data.points() {
                let point = point.map_err(|e| fail(e.to_string()))?;
                write_record(&mut converted, point, &meta.format, &meta.transforms, input)?;
            }
            &converted
        };
        for r in records.chunks_exact(meta.record_len()) {
            let p = meta.position_of(r);
            if (p - lo).min_element() < -slack.max_element()
                || (p - hi).max_element() > slack.max_element()
            {
                return Err(fail(format!(
                    "a point at {p} lies outside the header's bounds ({lo} to {hi}): \
                     fix the header's bounds first"
                )));
            }
            stats.add(p, r);
            parts.put(cell_of(p, cube, level), r)?;
        }
    }
    if stats.points != total {
        return Err(fail(format!(
            "the header declares {total} points, the file holds {}",
            stats.points
        )));
    }
    // Too large a part splits into its children, until none is.
    let mut queue = parts.flush_all()?;
    let mut ready = Vec::new();
    while let Some((key, count)) = queue.pop() {
        if count <= part_points || key.level >= crate::input::copc::MAX_LEVEL {
            ready.push(key);
            continue;
        }
        let bytes = parts.take(key)?;
        for r in bytes.chunks_exact(meta.record_len()) {
            parts.put(cell_of(meta.position_of(r), cube, key.level + 1), r)?;
        }
        drop(bytes);
        queue.extend(parts.flush_all()?);
    }
    ready.sort();

    // 2. The parts, on every core.
    let items =
        LazItemRecordBuilder::default_for_point_format_id(meta.format.to_u8().expect("6 or 7"), 0)
            .map_err(|e| fail(e.to_string()))?;
    let laz_vlr = LazVlrBuilder::new(items).with_variable_chunk_size().build();
    let mut length = 0;
    let mut counted = (0usize, 0i32);
    crate::image_io::write_atomically(output, |file| {
        let layout = Layout {
            format: meta.format,
            transforms: &meta.transforms,
            wkt: meta.wkt.as_deref(),
            standard_gps_time: meta.standard_gps_time,
            laz_vlr: &laz_vlr,
        };
        let out = std::sync::Mutex::new(CopcOut::begin(file, output, layout)?);
        // A failed part stops the others from starting.
        let failed = std::sync::atomic::AtomicBool::new(false);
        let built = crate::parallel_map(&ready, threads, |&key| {
            if failed.load(std::sync::atomic::Ordering::Relaxed) {
                return Ok(None);
            }
            let result = (|| -> Result<(NodeKey, Vec<u8>)> {
                let part = Records {
                    bytes: parts.take(key)?,
                    ..meta.clone_meta()
                };
                let mut nodes = Vec::new();
                let all: Vec<u32> = (0..part.len() as u32).collect();
                build_node(&part, key, node_cube(cube, key), all, 1, &mut nodes);
                let own = nodes
                    .iter()
                    .position(|n| n.key == key)
                    .expect("the part's node");
                let own = nodes.swap_remove(own);
                let chunks =
                    compress_nodes(&part, &nodes, &laz_vlr, 1).map_err(|e| fail(e.to_string()))?;
                let mut out = out.lock().unwrap_or_else(|e| e.into_inner());
                for (node, chunk) in nodes.iter().zip(&chunks) {
                    out.node(node.key, node.points.len() as u64, chunk)?;
                }
                // The part's own node's points: candidates for the levels
                // above.
                Ok((key, gather_records(&part, &own.points)))
            })();
            if result.is_err() {
                failed.store(true, std::sync::atomic::Ordering::Relaxed);
            }
            result.map(Some)
        });
        let candidates: Vec<(NodeKey, Vec<u8>)> = built
            .into_iter()
            .collect::<Result<Vec<_>>>()?
            .into_iter()
            .flatten()
            .collect();

        // 3. The levels above the parts, from their nodes' points (the
        // parts in key order).
        let mut top = Records {
            bytes: Vec::new(),
            ..meta.clone_meta()
        };
        for (_, bytes) in &candidates {
            top.bytes.extend_from_slice(bytes);
        }
        drop(candidates);
        let part_keys: std::collections::HashSet<NodeKey> = ready.iter().copied().collect();
        let mut nodes = Vec::new();
        let all: Vec<u32> = (0..top.len() as u32).collect();
        build_top(&top, all, NodeKey::ROOT, cube, &part_keys, &mut nodes);
        let chunks =
            compress_nodes(&top, &nodes, &laz_vlr, threads).map_err(|e| fail(e.to_string()))?;
        let mut out = out.into_inner().unwrap_or_else(|e| e.into_inner());
        let mut written: std::collections::HashSet<NodeKey> = std::collections::HashSet::new();
        for (node, chunk) in nodes.iter().zip(&chunks) {
            written.insert(node.key);
            match node.points.is_empty() {
                true => out.empty(node.key),
                false => out.node(node.key, node.points.len() as u64, chunk)?,
            }
        }
        // A part whose points all went up is a node without points.
        for key in &ready {
            if !written.contains(key) {
                out.empty(*key);
            }
        }
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

/// The octree's top, from the parts' own nodes' points (`records`): each
/// node above the parts keeps a point per cell of its grid; at a part's
/// cell, what is left is that node's points.
fn build_top(
    records: &Records,
    points: Vec<u32>,
    key: NodeKey,
    root: (DVec3, f64),
    parts: &std::collections::HashSet<NodeKey>,
    out: &mut Vec<Node>,
) {
    if parts.contains(&key) {
        out.push(Node { key, points });
        return;
    }
    let (min, width) = node_cube(root, key);
    let (kept, children) = sample(records, &points, min, width);
    drop(points);
    out.push(Node { key, points: kept });
    for (child, points) in key.children().zip(children) {
        if !points.is_empty() {
            build_top(records, points, child, root, parts, out);
        }
    }
}

/// The cube of node `key` in the octree whose root is `root`.
fn node_cube((min, width): (DVec3, f64), key: NodeKey) -> (DVec3, f64) {
    let w = width / f64::from(1u32 << key.level);
    (
        min + w * DVec3::new(f64::from(key.x), f64::from(key.y), f64::from(key.z)),
        w,
    )
}

/// The cell at `level` of the octree `root` that holds `p`.
fn cell_of(p: DVec3, (min, width): (DVec3, f64), level: i32) -> NodeKey {
    let n = f64::from(1u32 << level);
    let c = ((p - min) / width * n)
        .floor()
        .clamp(DVec3::ZERO, DVec3::splat(n - 1.0));
    NodeKey {
        level,
        x: c.x as i32,
        y: c.y as i32,
        z: c.z as i32,
    }
}

/// The records of `points`, one after another.
fn gather_records(records: &Records, points: &[u32]) -> Vec<u8> {
    let len = records.record_len();
    let mut out = Vec::with_capacity(points.len() * len);
    for &p in points {
        out.extend_from_slice(&records.bytes[p as usize * len..(p as usize + 1) * len]);
    }
    out
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
        std::fs::create_dir_all(&dir).map_err(|e| Error::Io {
            path: dir.clone(),
            source: e,
        })?;
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

    /// Adds a record to part `key`.
    fn put(&self, key: NodeKey, record: &[u8]) -> Result<()> {
        let mut s = self.state.lock().unwrap_or_else(|e| e.into_inner());
        s.buffers.entry(key).or_default().extend_from_slice(record);
        *s.counts.entry(key).or_default() += 1;
        s.buffered += record.len();
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
    }
}
