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

    /// Point `i`'s integer codes (the first 12 bytes of every format).
    fn codes(&self, i: usize) -> [i32; 3] {
        let r = &self.bytes[i * self.record_len()..];
        let c = |k: usize| i32::from_le_bytes(r[4 * k..4 * k + 4].try_into().expect("4 bytes"));
        [c(0), c(1), c(2)]
    }

    /// Point `i` in file coordinates.
    fn position(&self, i: usize) -> DVec3 {
        let [x, y, z] = self.codes(i);
        let t = &self.transforms;
        DVec3::new(t.x.direct(x), t.y.direct(y), t.z.direct(z))
    }

    /// The records of the points of a LAS, LAZ or COPC file, in point
    /// format 6 or 7 (7 where the input has colors), codes unchanged.
    pub fn of_las(path: &Path) -> Result<Records> {
        let fail = |msg: String| Error::Las {
            path: path.to_path_buf(),
            msg,
        };
        let mut reader = las::Reader::from_path(path).map_err(|e| fail(e.to_string()))?;
        let header = reader.header().clone();
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
        let standard_gps_time = header.gps_time_type() == las::GpsTimeType::Standard;
        let n = usize::try_from(header.number_of_points()).unwrap_or(usize::MAX);
        let mut bytes = Vec::new();
        bytes
            .try_reserve_exact(n.saturating_mul(usize::from(format.len())))
            .map_err(|_| fail(format!("cannot hold the {n} points in memory")))?;
        let mut data = las::PointDataBuilder::new().for_header(&header).build();
        loop {
            let got = reader
                .fill_points(crate::input::las::CHUNK_POINTS, &mut data)
                .map_err(|e| fail(e.to_string()))?;
            if got == 0 {
                break;
            }
            for point in data.points() {
                let point = point.map_err(|e| fail(e.to_string()))?;
                write_record(&mut bytes, point, &format, &transforms, path)?;
            }
        }
        if n > u32::MAX as usize {
            return Err(fail(format!(
                "{n} points: convert takes at most 2^32 points"
            )));
        }
        Ok(Records {
            format,
            transforms,
            bytes,
            wkt,
            standard_gps_time,
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

/// The root cube around `records`: (min corner, width), in file
/// coordinates.
fn root_cube(records: &Records) -> (DVec3, f64) {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for i in 0..records.len() {
        let p = records.position(i);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    // A little wider, so that the largest coordinate lies inside.
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
    // The point nearest each occupied cell's centre stays: the points
    // sorted by (cell, distance², index), the first of each cell kept.
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
    let half = width / 2.0;
    let mid = min + DVec3::splat(half);
    let mut k = 0;
    for &i in &points {
        if k < kept.len() && kept[k] == i {
            k += 1;
            continue;
        }
        let p = records.position(i as usize);
        let o = usize::from(p.x >= mid.x)
            | usize::from(p.y >= mid.y) << 1
            | usize::from(p.z >= mid.z) << 2;
        children[o].push(i);
    }
    drop(points);
    out.push(Node { key, points: kept });
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
    let cube = root_cube(records);
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
        bytes = write_file(records, &nodes, &chunks, &laz_vlr, cube, file, output)?;
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
    let len = records.record_len();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let slots: Vec<std::sync::Mutex<Option<std::io::Result<Vec<u8>>>>> =
        nodes.iter().map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..threads.max(1).min(nodes.len()) {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some(node) = nodes.get(i) else {
                    break;
                };
                let mut raw = Vec::with_capacity(node.points.len() * len);
                for &p in &node.points {
                    let at = p as usize * len;
                    raw.extend_from_slice(&records.bytes[at..at + len]);
                }
                let compressed = (|| {
                    let mut c = LayeredPointRecordCompressor::new(Vec::new());
                    c.set_fields_from(vlr.items())
                        .map_err(std::io::Error::other)?;
                    c.compress_many(&raw)?;
                    c.done()?;
                    Ok(c.into_inner())
                })();
                *slots[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(compressed);
            });
        }
    });
    slots
        .into_iter()
        .map(|s| {
            s.into_inner()
                .unwrap_or_else(|e| e.into_inner())
                .expect("compressed")
        })
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

/// Writes the COPC file into `file` (the temporary of `path`, which
/// errors name) and syncs it; returns its length.
fn write_file(
    records: &Records,
    nodes: &[Node],
    chunks: &[Vec<u8>],
    laz_vlr: &LazVlr,
    cube: (DVec3, f64),
    file: File,
    path: &Path,
) -> Result<u64> {
    let io = |e: std::io::Error| Error::Io {
        path: path.to_path_buf(),
        source: e,
    };
    let las_err = |e: las::Error| Error::Las {
        path: path.to_path_buf(),
        msg: e.to_string(),
    };
    // What the header says of the points: bounds, returns, GPS times.
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    let mut by_return = [0u64; 15];
    let (mut gps_lo, mut gps_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let len = records.record_len();
    for i in 0..records.len() {
        let p = records.position(i);
        lo = lo.min(p);
        hi = hi.max(p);
        let r = &records.bytes[i * len..(i + 1) * len];
        let ret = usize::from(r[14] & 0x0F);
        if (1..=15).contains(&ret) {
            by_return[ret - 1] += 1;
        }
        let gps = f64::from_le_bytes(r[22..30].try_into().expect("8 bytes"));
        gps_lo = gps_lo.min(gps);
        gps_hi = gps_hi.max(gps);
    }
    let mut laz_data = Vec::new();
    laz_vlr.write_to(&mut laz_data).map_err(io)?;
    let mut vlrs = vec![
        vlr(
            "copc",
            1,
            "COPC info",
            info_payload(cube, (0, 0), (gps_lo, gps_hi)),
            false,
        ),
        vlr("laszip encoded", 22204, "laz", laz_data, false),
    ];
    if let Some(wkt) = &records.wkt {
        vlrs.push(vlr("LASF_Projection", 2112, "WKT", wkt.clone(), false));
    }
    let vlr_bytes: u64 = vlrs.iter().map(|v| 54 + v.data.len() as u64).sum();
    let offset_to_points = 375 + vlr_bytes;

    let mut out = BufWriter::with_capacity(1 << 20, file);
    out.seek(SeekFrom::Start(offset_to_points)).map_err(io)?;
    // The chunk table's offset, patched below.
    out.write_all(&0i64.to_le_bytes()).map_err(io)?;
    let mut at = offset_to_points + 8;
    let mut entries = Vec::with_capacity(nodes.len());
    let mut table = ChunkTable::with_capacity(nodes.len());
    for (node, chunk) in nodes.iter().zip(chunks) {
        out.write_all(chunk).map_err(io)?;
        entries.push((node.key, at, chunk.len() as u64, node.points.len() as u64));
        table.push(ChunkTableEntry {
            point_count: node.points.len() as u64,
            byte_count: chunk.len() as u64,
        });
        at += chunk.len() as u64;
    }
    let chunk_table_at = at;
    table.write_to(&mut out, laz_vlr).map_err(io)?;
    out.flush().map_err(io)?;
    let evlr_at = out.stream_position().map_err(io)?;
    // The hierarchy: one page, the root's entry first.
    let mut page = Vec::with_capacity(entries.len() * 32);
    for (key, offset, size, count) in &entries {
        let (Ok(size), Ok(count)) = (i32::try_from(*size), i32::try_from(*count)) else {
            return Err(Error::Las {
                path: path.to_path_buf(),
                msg: format!(
                    "node {key:?} holds {count} points in {size} bytes, more than a COPC \
                     entry counts (2^31): too many points at one place"
                ),
            });
        };
        for v in [key.level, key.x, key.y, key.z] {
            page.extend_from_slice(&v.to_le_bytes());
        }
        page.extend_from_slice(&offset.to_le_bytes());
        page.extend_from_slice(&size.to_le_bytes());
        page.extend_from_slice(&count.to_le_bytes());
    }
    let page_len = page.len() as u64;
    let hierarchy = vlr("copc", 1000, "EPT hierarchy", page, true);
    hierarchy.write_to(&mut out).map_err(las_err)?;
    let end = out.stream_position().map_err(io)?;
    let root_page = (evlr_at + 60, page_len);

    // The header and VLRs, now that every offset is known.
    out.seek(SeekFrom::Start(offset_to_points)).map_err(io)?;
    out.write_all(&(chunk_table_at as i64).to_le_bytes())
        .map_err(io)?;
    vlrs[0].data = info_payload(cube, root_page, (gps_lo, gps_hi));
    let mut format = records.format;
    format.is_compressed = true;
    let t = &records.transforms;
    let total = records.len() as u64;
    let header = las::raw::Header {
        file_signature: *b"LASF",
        global_encoding: 0x10 | u16::from(records.standard_gps_time),
        version: las::Version::new(1, 4),
        system_identifier: *b"pointlens\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0",
        generating_software: *b"pointlens convert\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0",
        header_size: 375,
        offset_to_point_data: offset_to_points as u32,
        number_of_variable_length_records: vlrs.len() as u32,
        point_data_record_format: format.to_u8().expect("6 or 7") | 0x80,
        point_data_record_length: len as u16,
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
            number_of_point_records: total,
            number_of_points_by_return: by_return,
        }),
        ..Default::default()
    };
    out.seek(SeekFrom::Start(0)).map_err(io)?;
    header.write_to(&mut out).map_err(las_err)?;
    for v in &vlrs {
        v.write_to(&mut out).map_err(las_err)?;
    }
    out.flush().map_err(io)?;
    out.get_ref().sync_all().map_err(io)?;
    Ok(end)
}
