//! LAS, LAZ and COPC input (the `las` crate; LAZ chunks decompressed on
//! every core by the `laz` crate's decompressors, their GPS times by
//! [`super::laz_gps`]): point data record formats 0–10, read in chunks
//! straight into the cloud, with real-world coordinates re-centred in
//! double precision.
//!
//! Positions: a record's coordinate is the integer code `c` with the
//! header's scale `s` and offset `o`, `x = c·s + o` (double precision). The
//! cloud is re-centred on an origin before it becomes f32: by default the
//! centre of the header's bounding box, snapped to the file's integer grid,
//! so that a point's scene coordinate is `(c − c_origin)·s` — an exact
//! integer difference, one rounding — and the same cloud shifted by any
//! multiple of the scale gives bitwise the same scene. A user's origin
//! (`--origin`) is taken as given. `PointCloud::origin` is the origin in the
//! file's coordinates.
//!
//! Colors: the 16-bit RGB of formats 2, 3, 5, 7, 8 and 10, taken as sRGB;
//! a file whose every channel is at most 255 stores 8-bit values in the
//! 16-bit fields (as many writers do) and is scaled by 255, any other by
//! 65535. Without RGB, or with RGB all zero, the intensity becomes grey,
//! normalised over the file's actual range (min to max) and taken as sRGB;
//! without either, the default color. Classification codes are kept.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use glam::{DVec3, Vec3};
use las::{PointData, PointDataBuilder, Reader};

use super::{linear_from_code, DEFAULT_COLOR};
use crate::cloud::{display_coord, PointCloud};
use crate::error::{Error, Result};

/// Points read from the file at a time: ten LAZ chunks of the usual 50,000
/// points, so that the parallel decompressor has work for every core.
pub const CHUNK_POINTS: u64 = 500_000;

/// The four bytes every LAS and LAZ file starts with.
pub const MAGIC: &[u8; 4] = b"LASF";

/// Whether `bytes` (a file's first bytes) start a LAS or LAZ file.
pub fn has_magic(bytes: &[u8]) -> bool {
    bytes.starts_with(MAGIC)
}

/// Whether a path names a LAS or LAZ file by its extension (`.las`, `.laz`,
/// and so `.copc.laz`), whatever the case.
pub fn has_las_extension(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("las") || e.eq_ignore_ascii_case("laz"))
}

/// One axis of the conversion from a record's integer code to an f32 scene
/// coordinate: `((code − origin_code)·scale + residual) as f32`.
#[derive(Debug, Clone, Copy)]
struct Axis {
    scale: f64,
    offset: f64,
    /// The origin's code on the file's grid (an integer, as f64).
    origin_code: f64,
    /// The origin's distance from that grid point (0 for the default origin).
    residual: f64,
    /// The origin in file coordinates.
    origin: f64,
}

impl Axis {
    fn new(scale: f64, offset: f64, origin_code: f64, origin: f64) -> Axis {
        Axis {
            scale,
            offset,
            origin_code,
            residual: (origin_code * scale + offset) - origin,
            origin,
        }
    }

    fn local(&self, code: i32) -> f32 {
        ((f64::from(code) - self.origin_code) * self.scale + self.residual) as f32
    }

    fn file(&self, code: i32) -> f64 {
        f64::from(code) * self.scale + self.offset
    }

    /// The grid code nearest the file coordinate `x`.
    fn code_of(&self, x: f64) -> f64 {
        ((x - self.offset) / self.scale).round()
    }
}

/// The scene coordinate of `code` on an axis of `scale` and `offset`
/// re-centred on `origin` (file coordinates; a grid point for the default
/// origin): the f32 [`Gather::finish`] gives a point of that code.
pub(super) fn local_coord(scale: f64, offset: f64, origin: f64, code: i32) -> f32 {
    let probe = Axis::new(scale, offset, 0.0, offset);
    Axis::new(scale, offset, probe.code_of(origin), origin).local(code)
}

/// The origin on one axis: the user's, or the centre of the codes'
/// range `[lo, hi]` snapped to the grid (an integer midpoint).
fn axis(scale: f64, offset: f64, user: Option<f64>, range: (f64, f64)) -> Result<Axis, String> {
    let probe = Axis::new(scale, offset, 0.0, offset);
    match user {
        Some(origin) => {
            let code = probe.code_of(origin);
            // Beyond 2^52 the grid's integers are no longer exact in f64.
            if code.is_nan() || code.abs() >= (1u64 << 52) as f64 {
                return Err(format!(
                    "--origin {origin} is too far from the file's coordinates (scale {scale}, offset {offset})"
                ));
            }
            Ok(Axis::new(scale, offset, code, origin))
        }
        None => {
            let code = ((range.0 + range.1) / 2.0).floor();
            Ok(Axis::new(scale, offset, code, code * scale + offset))
        }
    }
}

/// The header, VLRs and EVLRs, checked against the file before any point
/// is read: the checks the `las` and `laz` crates leave to the read, where
/// a lying field would otherwise abort the process on a huge allocation
/// or read garbage.
pub(super) struct Preflight {
    pub(super) header: las::Header,
    record_len: u64,
    /// A LAZ file's chunks (None for LAS).
    chunks: Option<LazChunks>,
}

/// A LAZ file's chunks, from its checked chunk table: what
/// [`LazStream`] decompresses.
#[derive(Debug, Clone)]
struct LazChunks {
    items: Vec<laz::LazItem>,
    chunks: Vec<LazChunk>,
}

/// One LAZ chunk: its bytes in the file and its points.
#[derive(Debug, Clone, Copy)]
struct LazChunk {
    offset: u64,
    bytes: u64,
    /// The index of its first point in the file.
    first: u64,
    points: u64,
}

pub(super) fn preflight(path: &Path, file: &mut File, file_len: u64) -> Result<Preflight> {
    let (fail, io) = (las_fail(path), io_fail(path));
    file.rewind().map_err(io)?;
    let raw =
        las::raw::Header::read_from(BufReader::new(&mut *file)).map_err(|e| las_error(path, e))?;
    let record_len = u64::from(raw.point_data_record_length);
    let offset = u64::from(raw.offset_to_point_data);
    if offset > file_len {
        return Err(fail(format!(
            "truncated: the point data should start at byte {offset}, the file has {file_len} bytes"
        )));
    }
    // The first EVLR's length (a u64 the `las` crate allocates as given).
    let mut data_end = file_len;
    if let Some(evlr) = raw.evlr.filter(|e| e.number_of_evlrs > 0) {
        let start = evlr.start_of_first_evlr;
        let mut head = [0u8; 60];
        let room = file_len.saturating_sub(start.saturating_add(60));
        if start < offset || start > file_len - 60.min(file_len) {
            return Err(fail(format!(
                "the first extended VLR should start at byte {start}, outside the file's {file_len} bytes after the point data"
            )));
        }
        file.seek(SeekFrom::Start(start)).map_err(io)?;
        file.read_exact(&mut head).map_err(io)?;
        let len = u64::from_le_bytes(head[20..28].try_into().expect("8 bytes"));
        if len > room {
            return Err(fail(format!(
                "an extended VLR declares {len} bytes, the file has {room} after it: truncated or corrupt"
            )));
        }
        data_end = start;
    }
    // Waveform packets stored in the file (LAS 1.3+) follow the points.
    if let Some(w) = raw
        .start_of_waveform_data_packet_record
        .filter(|&w| w > offset && w < data_end)
    {
        data_end = w;
    }
    // The count as declared (LAS 1.4's 64-bit field, else the legacy
    // one): the `las` crate seeks past that many records, which fails with
    // the OS's "Invalid argument" far beyond any file.
    let declared = raw
        .large_file
        .map_or(u64::from(raw.number_of_point_records), |l| {
            l.number_of_point_records
        });
    let declared_bytes = declared.saturating_mul(record_len);
    file.rewind().map_err(io)?;
    let header = las::Header::new(BufReader::new(&mut *file)).map_err(|e| {
        let seek_beyond = matches!(&e, las::Error::Io(io)
            if io.kind() == std::io::ErrorKind::InvalidInput);
        if seek_beyond && declared_bytes > file_len {
            fail(format!(
                "the header declares {declared} points ({declared_bytes} bytes of records), \
                 which this {file_len}-byte file cannot hold: a wrong point count"
            ))
        } else {
            las_error(path, e)
        }
    })?;
    let points = header.number_of_points();
    let mut chunks = None;
    if header.point_format().is_compressed {
        chunks = Some(check_chunk_table(
            path,
            file,
            (offset, data_end, file_len),
            points,
            &header,
            record_len,
        )?);
    } else {
        let room = data_end - offset;
        let need = points.saturating_mul(record_len);
        if need > room {
            return Err(fail(format!(
                "the header declares {points} points of {record_len} bytes ({need} bytes), \
                 the file holds {room} bytes of point data: truncated, or a wrong point count or record length"
            )));
        }
        if record_len > 0 && room - need >= record_len {
            return Err(fail(format!(
                "the header declares {points} points of {record_len} bytes ({need} bytes), \
                 the file holds {room} bytes of point data: a wrong point count or record length"
            )));
        }
    }
    let t = header.transforms();
    for (name, tr) in [("x", t.x), ("y", t.y), ("z", t.z)] {
        if !(tr.scale.is_finite() && tr.scale != 0.0 && tr.offset.is_finite()) {
            return Err(fail(format!(
                "the {name} scale ({}) must be finite and non-zero and the offset ({}) finite",
                tr.scale, tr.offset
            )));
        }
    }
    Ok(Preflight {
        header,
        record_len,
        chunks,
    })
}

/// Checks a LAZ file's chunk table against the file and the header: its
/// offset (the first 8 bytes of the point data, or the file's last 8 where
/// those are −1; `data_end` is where the points end: the first EVLR or the
/// file's end) inside the data, version 0, no more chunks than bytes of
/// compressed data or points, and, for chunks of a fixed size, a point
/// count the chunks can hold. The chunks, with their points.
fn check_chunk_table(
    path: &Path,
    file: &mut File,
    (data_start, data_end, file_len): (u64, u64, u64),
    points: u64,
    header: &las::Header,
    record_len: u64,
) -> Result<LazChunks> {
    let fail = |msg: String| Error::Las {
        path: path.to_path_buf(),
        msg: format!("corrupt LAZ chunk table: {msg}"),
    };
    let io = io_fail(path);
    let mut read_u64_at = |at: u64| -> Result<u64> {
        let mut b = [0u8; 8];
        file.seek(SeekFrom::Start(at)).map_err(io)?;
        file.read_exact(&mut b).map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                Error::Las {
                    path: path.to_path_buf(),
                    msg: "truncated: the file ends inside the LAZ chunk table".to_string(),
                }
            } else {
                io(e)
            }
        })?;
        Ok(u64::from_le_bytes(b))
    };
    if data_end < data_start + 8 {
        return Err(fail("no room for its offset after the header".to_string()));
    }
    let mut table = read_u64_at(data_start)?;
    if table as i64 == -1 {
        // Written last, as LASzip does when it cannot seek back.
        table = read_u64_at(file_len - 8)?;
    }
    if table < data_start + 8 || table > data_end.saturating_sub(8) {
        return Err(fail(format!(
            "its offset {} is outside the point data (bytes {data_start} to {data_end})",
            table as i64
        )));
    }
    let words = read_u64_at(table)?;
    let (version, chunks) = (words as u32, (words >> 32) as u32);
    if version != 0 {
        return Err(fail(format!("version {version}, not 0")));
    }
    let data_bytes = table - data_start - 8;
    if u64::from(chunks) > data_bytes || u64::from(chunks) > points.max(1) {
        return Err(fail(format!(
            "{chunks} chunks for {points} points in {data_bytes} bytes of compressed data"
        )));
    }
    let vlr = header.laz_vlr().map_err(|e| las_error(path, e))?;
    check_laz_vlr(path, header, &vlr, record_len)?;
    // The entries: their byte counts must fit in the compressed data, and
    // variable-size chunks' point counts add up to the header's (else the
    // decompressor sizes its buffers from them: a fuzzed table made it
    // overflow a capacity and abort).
    file.seek(SeekFrom::Start(data_start)).map_err(io)?;
    let entries = laz::laszip::ChunkTable::read_from(&mut *file, &vlr)
        .map_err(|e| fail(format!("its entries cannot be read ({e})")))?;
    let mut bytes_sum = 0u64;
    let mut points_sum = 0u64;
    for entry in &entries {
        bytes_sum = bytes_sum.saturating_add(entry.byte_count);
        points_sum = points_sum.saturating_add(entry.point_count);
    }
    if bytes_sum > data_bytes {
        return Err(fail(format!(
            "its chunks hold {bytes_sum} bytes, the compressed data {data_bytes}"
        )));
    }
    if vlr.uses_variable_size_chunks() && points_sum != points {
        return Err(Error::Las {
            path: path.to_path_buf(),
            msg: format!(
                "the header declares {points} points, the LAZ chunk table's chunks hold {points_sum}: \
                 a wrong point count or a corrupt chunk table"
            ),
        });
    }
    if !vlr.uses_variable_size_chunks() {
        let size = u64::from(vlr.chunk_size());
        // The decompressor makes room for a whole last chunk: a chunk size
        // far beyond the file's points (fuzzing found 4 billion, 111 GB)
        // would exhaust the memory before any point is read.
        if size > points && size.saturating_mul(record_len) > 1 << 30 {
            return Err(fail(format!(
                "chunks of {size} points ({} MiB each) for a file of {points} points",
                size.saturating_mul(record_len) >> 20
            )));
        }
        let chunks = u64::from(chunks);
        if points > chunks * size || (chunks > 0 && points <= (chunks - 1) * size) {
            return Err(Error::Las {
                path: path.to_path_buf(),
                msg: format!(
                    "the header declares {points} points, the LAZ chunk table holds {chunks} chunks of {size}: \
                     a wrong point count or a corrupt chunk table"
                ),
            });
        }
    }
    check_chunk_layers(path, file, data_start, &entries, vlr.items(), record_len)?;
    Ok(LazChunks::of_table(&entries, &vlr, data_start, points))
}

impl LazChunks {
    /// The chunks of a checked chunk table (`entries`, of a file of
    /// `points` points whose LAZ VLR is `vlr`): they follow the table's
    /// offset (8 bytes from `data_start`); chunks of a fixed size hold that
    /// many points each, the last the rest.
    fn of_table(
        entries: &laz::laszip::ChunkTable,
        vlr: &laz::LazVlr,
        data_start: u64,
        points: u64,
    ) -> LazChunks {
        let mut chunks = Vec::with_capacity(entries.len());
        let (mut offset, mut first) = (data_start + 8, 0u64);
        for entry in entries {
            let count = if vlr.uses_variable_size_chunks() {
                entry.point_count
            } else {
                u64::from(vlr.chunk_size()).min(points - first)
            };
            chunks.push(LazChunk {
                offset,
                bytes: entry.byte_count,
                first,
                points: count,
            });
            offset += entry.byte_count;
            first += count;
        }
        LazChunks {
            items: vlr.items().clone(),
            chunks,
        }
    }
}

/// Checks a LAZ file's LAZ VLR (`vlr`, of `header`): chunked compression
/// (its first u16: 2 point by point, 3 layered), as the chunks are read
/// one by one, and items that make the header's records of `record_len`
/// bytes (the decompressor asserts so; summed here in u64, as the items'
/// u16 sizes may overflow in the `laz` crate's own sum).
fn check_laz_vlr(
    path: &Path,
    header: &las::Header,
    vlr: &laz::LazVlr,
    record_len: u64,
) -> Result<()> {
    let fail = las_fail(path);
    let compressor = header
        .vlrs()
        .iter()
        .find(|v| las::laz::is_laszip_vlr(v))
        .and_then(|v| v.data.get(..2))
        .map(|b| u16::from_le_bytes([b[0], b[1]]));
    if !matches!(compressor, Some(2 | 3)) {
        return Err(fail(format!(
            "its LAZ compressor ({}) is not chunked: not supported",
            compressor.map_or("none".to_string(), |c| c.to_string())
        )));
    }
    let items: u64 = vlr.items().iter().map(|i| u64::from(i.size())).sum();
    if items != record_len {
        return Err(fail(format!(
            "the LAZ items make records of {items} bytes, the header declares {record_len}: \
             a corrupt LAZ description or point record length"
        )));
    }
    Ok(())
}

/// Checks that each layered chunk's (point formats 6–10) layer byte
/// counts, from which the decompressor sizes its buffers before reading,
/// fit in the chunk (`entries`: the chunk table; the chunks start 8 bytes
/// after `data_start`).
fn check_chunk_layers(
    path: &Path,
    file: &mut File,
    data_start: u64,
    entries: &laz::laszip::ChunkTable,
    items: &[laz::LazItem],
    record_len: u64,
) -> Result<()> {
    if !items
        .iter()
        .any(|i| matches!(i.item_type(), laz::LazItemType::Point14))
    {
        return Ok(());
    }
    let io = io_fail(path);
    let head_len = layered_head_len(items, record_len);
    let mut start = data_start + 8;
    for (i, entry) in entries.into_iter().enumerate() {
        let len = (head_len as u64).min(entry.byte_count) as usize;
        let mut head = vec![0u8; len];
        file.seek(SeekFrom::Start(start)).map_err(io)?;
        file.read_exact(&mut head).map_err(io)?;
        check_layers(items, record_len, &head, entry.byte_count).map_err(|e| Error::Las {
            path: path.to_path_buf(),
            msg: format!("corrupt LAZ chunk table: chunk {i}: {e}"),
        })?;
        start += entry.byte_count;
    }
    Ok(())
}

/// Bytes before a layered LAZ chunk's layers (point formats 6–10): each
/// field's first point raw (`record_len` in all), the chunk's point count,
/// and a u32 byte count for each layer.
pub(super) fn layered_head_len(items: &[laz::LazItem], record_len: u64) -> usize {
    let layers: usize = items
        .iter()
        .map(|item| match item.item_type() {
            laz::LazItemType::Point14 => 9,
            laz::LazItemType::RGBNIR14 => 2,
            laz::LazItemType::Byte14(n) => usize::from(n),
            _ => 1,
        })
        .sum();
    record_len as usize + 4 + 4 * layers
}

/// Checks the start (`head`) of a layered LAZ chunk of `chunk_len` bytes:
/// its layers' byte counts must fit in the chunk after them. The `laz`
/// crate sizes each layer's buffer from its u32 count before reading it,
/// so a corrupt count asked for up to 4 GiB a layer. A head shorter than
/// [`layered_head_len`] is left to the decompressor (it fails reading it).
pub(super) fn check_layers(
    items: &[laz::LazItem],
    record_len: u64,
    head: &[u8],
    chunk_len: u64,
) -> std::result::Result<(), String> {
    let head_len = layered_head_len(items, record_len);
    let sizes_at = record_len as usize + 4;
    let Some(words) = head.get(sizes_at..head_len) else {
        return Ok(());
    };
    let declared: u64 = words
        .chunks_exact(4)
        .map(|w| u64::from(u32::from_le_bytes(w.try_into().expect("4 bytes"))))
        .sum();
    let room = chunk_len.saturating_sub(head_len as u64);
    if declared > room {
        return Err(format!(
            "its layers declare {declared} bytes, {room} follow them"
        ));
    }
    Ok(())
}

/// The error of a LAS file that cannot be read, naming it.
fn las_fail(path: &Path) -> impl Fn(String) -> Error + Copy + '_ {
    move |msg| Error::Las {
        path: path.to_path_buf(),
        msg,
    }
}

/// An I/O error on the file, naming it.
fn io_fail(path: &Path) -> impl Fn(std::io::Error) -> Error + Copy + '_ {
    move |source| Error::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A `las` crate error as one line: the reader's I/O end-of-file becomes
/// "truncated".
fn las_error(path: &Path, e: las::Error) -> Error {
    let msg = if ends_early(&e) {
        "truncated: the file ends inside the data its header declares".to_string()
    } else {
        e.to_string().replace('\n', " ")
    };
    Error::Las {
        path: path.to_path_buf(),
        msg,
    }
}

/// Whether an error is, or was caused by, an I/O end of file (the `laz`
/// crate wraps it in its own error).
fn ends_early(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cause: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(c) = cause {
        if c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::UnexpectedEof)
            || c.to_string().contains("failed to fill whole buffer")
        {
            return true;
        }
        cause = c.source();
    }
    false
}

/// Loads a LAS or LAZ (or COPC) file, re-centred on `origin` (file
/// coordinates; the default is the centre of the header's bounds, see the
/// module's notes). `progress(done, total)` is called after each chunk.
///
/// Errors name the file and say what is wrong: not a LAS file, truncated,
/// a point count or record length that does not match the file, a corrupt
/// LAZ chunk table, a coordinate that does not fit in f32 after
/// re-centring.
pub fn load_las(
    path: &Path,
    origin: Option<DVec3>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<PointCloud> {
    load_las_with(path, origin, progress, true)
}

/// Checks a LAS/LAZ/COPC file's header, VLRs and chunk table against the
/// file without reading its points (what [`load_las`] checks first);
/// returns the points its header declares.
pub fn check_las(path: &Path) -> Result<u64> {
    let io = io_fail(path);
    let mut file = File::open(path).map_err(io)?;
    let file_len = file.metadata().map_err(io)?.len();
    let mut magic = Vec::with_capacity(4);
    (&mut file).take(4).read_to_end(&mut magic).map_err(io)?;
    if !has_magic(&magic) {
        return Err(las_fail(path)(format!(
            "not a LAS or LAZ file: it starts with {:?}, not \"LASF\"",
            String::from_utf8_lossy(&magic)
        )));
    }
    preflight(path, &mut file, file_len).map(|p| p.header.number_of_points())
}

/// [`load_las`] reading a COPC file as the LAZ stream it also is (its
/// chunks in file order, its hierarchy ignored): what the by-node read is
/// tested against.
pub fn load_las_stream(
    path: &Path,
    origin: Option<DVec3>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<PointCloud> {
    load_las_with(path, origin, progress, false)
}

fn load_las_with(
    path: &Path,
    origin: Option<DVec3>,
    progress: &mut dyn FnMut(u64, u64),
    copc_by_node: bool,
) -> Result<PointCloud> {
    let (fail, io) = (las_fail(path), io_fail(path));
    let mut file = File::open(path).map_err(io)?;
    let file_len = file.metadata().map_err(io)?.len();
    let mut magic = Vec::with_capacity(4);
    (&mut file).take(4).read_to_end(&mut magic).map_err(io)?;
    if !has_magic(&magic) {
        return Err(fail(format!(
            "not a LAS or LAZ file: it starts with {:?}, not \"LASF\"",
            String::from_utf8_lossy(&magic)
        )));
    }
    let facts = preflight(path, &mut file, file_len)?;
    if copc_by_node && facts.header.vlrs().iter().any(|v| v.is_copc_info()) {
        return load_copc(path, facts, origin, progress);
    }
    let header = facts.header.clone();
    let total = header.number_of_points();
    if total == 0 {
        return Err(fail("the cloud is empty (0 points)".to_string()));
    }
    let n = usize::try_from(total).map_err(|_| fail(format!("{total} points is too many")))?;
    let mut gather = Gather::with_capacity(n, path)?;
    let mut done = 0u64;
    let mut data: PointData = PointDataBuilder::new().for_header(&header).build();
    if let Some(chunks) = facts.chunks.clone() {
        // LAZ: chunks decompressed on every core, without their GPS times.
        let mut stream = LazStream::new(path, file, chunks, &facts, false);
        loop {
            let points = stream.next_points();
            if points == 0 {
                break;
            }
            let records = stream.reserve(points)?;
            stream.decode_next(data.resize_for(records))?;
            gather.add(&data);
            done += points;
            progress(done, total);
        }
        return gather.finish(path, &facts, origin);
    }
    file.rewind().map_err(io)?;
    let mut reader =
        Reader::new(BufReader::with_capacity(1 << 20, file)).map_err(|e| las_error(path, e))?;
    while done < total {
        let got = reader
            .fill_points(CHUNK_POINTS.min(total - done), &mut data)
            .map_err(|e| las_error(path, e))?;
        if got == 0 {
            return Err(fail(format!(
                "truncated: the header declares {total} points, the data ends after {done}"
            )));
        }
        gather.add(&data);
        done += got;
        progress(done, total);
    }
    gather.finish(path, &facts, origin)
}

/// A LAZ file's points, decompressed chunk by chunk on every core,
/// about [`CHUNK_POINTS`] at a time: the chunks of the checked chunk
/// table ([`preflight`]), each decompressed by [`decompress_chunk`].
pub(crate) struct LazStream<'a> {
    path: &'a Path,
    file: File,
    chunks: LazChunks,
    record_len: usize,
    total: u64,
    /// The next chunk.
    next: usize,
    gps: bool,
}

impl<'a> LazStream<'a> {
    /// The stream of `file` (`path`, checked as `facts`, its `chunks`),
    /// with the GPS times of point formats 6–10 where `gps` (formats 1, 3,
    /// 4, 5 always have theirs).
    fn new(
        path: &'a Path,
        file: File,
        chunks: LazChunks,
        facts: &Preflight,
        gps: bool,
    ) -> LazStream<'a> {
        LazStream {
            path,
            file,
            chunks,
            record_len: facts.record_len as usize,
            total: facts.header.number_of_points(),
            next: 0,
            gps,
        }
    }

    /// Opens a LAS or LAZ file (`path`), checked as [`load_las`] checks
    /// it: its header, and where it is LAZ its stream, with every point's
    /// GPS time (`convert`).
    pub(crate) fn open(path: &'a Path) -> Result<(las::Header, Option<LazStream<'a>>)> {
        let io = io_fail(path);
        let mut file = File::open(path).map_err(io)?;
        let file_len = file.metadata().map_err(io)?.len();
        let facts = preflight(path, &mut file, file_len)?;
        let stream = facts
            .chunks
            .clone()
            .map(|chunks| LazStream::new(path, file, chunks, &facts, true));
        Ok((facts.header, stream))
    }

    /// The points of the next chunks, about [`CHUNK_POINTS`] in all,
    /// that [`LazStream::decode_next`] decompresses: 0 after the last.
    pub(crate) fn next_points(&self) -> u64 {
        self.next_chunks().iter().map(|c| c.points).sum()
    }

    fn next_chunks(&self) -> &[LazChunk] {
        let rest = &self.chunks.chunks[self.next..];
        let mut points = 0;
        let len = rest
            .iter()
            .take_while(|c| {
                let take = points < CHUNK_POINTS;
                points += c.points;
                take
            })
            .count();
        &rest[..len]
    }

    /// Checks that the records of `points` points fit in memory (an
    /// error naming the file where not): their count, for the buffer
    /// [`LazStream::decode_next`] fills.
    pub(crate) fn reserve(&self, points: u64) -> Result<usize> {
        let n = usize::try_from(points).unwrap_or(usize::MAX);
        let bytes = n.checked_mul(self.record_len);
        let mut probe = Vec::<u8>::new();
        if bytes.is_none_or(|b| probe.try_reserve_exact(b).is_err()) {
            return Err(las_fail(self.path)(format!(
                "{points} points of {} bytes in one LAZ chunk need more memory than there is",
                self.record_len
            )));
        }
        Ok(n)
    }

    /// Decompresses the next chunks ([`LazStream::next_points`] points)
    /// into `out`, their records (the file's point format) in file order,
    /// each chunk on one thread, every core taking the next.
    pub(crate) fn decode_next(&mut self, out: &mut [u8]) -> Result<()> {
        let batch = self.next_chunks();
        let mut rest = out;
        let mut slots = Vec::with_capacity(batch.len());
        for chunk in batch {
            let (head, tail) = rest.split_at_mut(chunk.points as usize * self.record_len);
            slots.push((chunk, std::sync::Mutex::new(head)));
            rest = tail;
        }
        assert!(rest.is_empty(), "a buffer of the batch's records");
        let decoded = crate::parallel_map(&slots, crate::available_threads(), |(chunk, out)| {
            let mut out = out.lock().unwrap_or_else(|e| e.into_inner());
            self.read_chunk(chunk, &mut out)
        });
        self.next += batch.len();
        decoded.into_iter().collect()
    }

    /// Reads and decompresses one chunk into `out`; errors name the file
    /// and the points.
    fn read_chunk(&self, chunk: &LazChunk, out: &mut [u8]) -> Result<()> {
        use std::os::unix::fs::FileExt;
        let fail = las_fail(self.path);
        let mut bytes = Vec::new();
        let len = usize::try_from(chunk.bytes).unwrap_or(usize::MAX);
        bytes.try_reserve_exact(len).map_err(|_| {
            fail(format!(
                "the LAZ chunk of points {} to {} ({len} bytes) needs more memory than there is",
                chunk.first,
                chunk.first + chunk.points
            ))
        })?;
        bytes.resize(len, 0);
        self.file
            .read_exact_at(&mut bytes, chunk.offset)
            .map_err(io_fail(self.path))?;
        let items = &self.chunks.items;
        decompress_chunk(items, self.record_len, &bytes, chunk.points, self.gps, out).map_err(
            |fault| match fault {
                ChunkFault::Ends => fail(format!(
                    "the compressed data ends before the {} points its header declares \
                     (after {}): corrupt data or a wrong point count",
                    self.total, chunk.first
                )),
                ChunkFault::Corrupt(e) => {
                    fail(format!("corrupt LAZ data after point {}: {e}", chunk.first))
                }
            },
        )
    }
}

/// Why a LAZ chunk was not decompressed.
#[derive(Debug)]
pub enum ChunkFault {
    /// Its data ends before its points.
    Ends,
    /// Anything else, in words.
    Corrupt(String),
}

/// Decompresses a LAZ chunk (`bytes`, of `points` points of `record_len`
/// bytes, items `items`) into `out` (`points` records), through the `laz`
/// crate with the GPS times of [`super::laz_gps`]: point formats 1, 3, 4,
/// 5 by its loop (`GpsTimeV2`) in place of the crate's recursion; 6–10
/// without their GPS-time layer, or, where `gps`, with it once
/// [`super::laz_gps::check_point14_gps`] has found no point switching
/// sequences too often.
pub fn decompress_chunk(
    items: &[laz::LazItem],
    record_len: usize,
    bytes: &[u8],
    points: u64,
    gps: bool,
    out: &mut [u8],
) -> std::result::Result<(), ChunkFault> {
    use laz::record::{
        LayeredPointRecordDecompressor, RecordDecompressor, SequentialPointRecordDecompressor,
    };
    use std::io::Cursor;
    let corrupt = |e: laz::LasZipError| ChunkFault::Corrupt(e.to_string().replace('\n', " "));
    assert!(
        Some(out.len() as u64) == points.checked_mul(record_len as u64),
        "a buffer of the chunk's records"
    );
    let Some(first) = items.first() else {
        return Err(ChunkFault::Corrupt("no LAZ items".to_string()));
    };
    let decoded = match first.version() {
        1 | 2 => {
            let mut d = SequentialPointRecordDecompressor::new(Cursor::new(bytes));
            for item in items {
                if matches!(item.item_type(), laz::LazItemType::GpsTime) && item.version() == 2 {
                    d.add_field_decompressor(super::laz_gps::GpsTimeV2::default());
                } else {
                    d.set_fields_from(&vec![*item]).map_err(corrupt)?;
                }
            }
            d.decompress_many(out)
        }
        _ => {
            let mut d = LayeredPointRecordDecompressor::new(Cursor::new(bytes));
            d.set_fields_from(&items.to_vec()).map_err(corrupt)?;
            if gps {
                super::laz_gps::check_point14_gps(items, record_len, bytes, points)
                    .map_err(|e| ChunkFault::Corrupt(e.to_string()))?;
            } else {
                d.set_selection(laz::DecompressionSelection::all().skip_gps_time());
            }
            d.decompress_many(out)
        }
    };
    match decoded {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Err(ChunkFault::Ends),
        Err(e) => Err(ChunkFault::Corrupt(e.to_string().replace('\n', " "))),
    }
}

/// Loads a COPC file (`facts`: its checked header) node by node
/// ([`super::copc`]): every node of its hierarchy, decompressed on every
/// core, added in file order: the cloud [`load_las_stream`] reads.
fn load_copc(
    path: &Path,
    facts: Preflight,
    origin: Option<DVec3>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<PointCloud> {
    let fail = las_fail(path);
    let copc = super::copc::CopcFile::open(path, facts.header.clone())?;
    let nodes = copc.all_nodes()?;
    let total: u64 = nodes.iter().map(|n| n.point_count).sum();
    if total != facts.header.number_of_points() {
        return Err(fail(format!(
            "the COPC hierarchy's nodes hold {total} points, the header declares {}: \
             counts that lie",
            facts.header.number_of_points()
        )));
    }
    if total == 0 {
        return Err(fail("the cloud is empty (0 points)".to_string()));
    }
    let n = usize::try_from(total).map_err(|_| fail(format!("{total} points is too many")))?;
    let mut gather = Gather::with_capacity(n, path)?;
    let threads = crate::available_threads().max(1);
    let mut done = 0u64;
    // Batches of about CHUNK_POINTS points, their nodes decompressed by
    // every thread (each takes the next node), added in file order.
    let mut rest = &nodes[..];
    while !rest.is_empty() {
        let mut points = 0;
        let len = rest
            .iter()
            .take_while(|n| {
                let take = points < CHUNK_POINTS;
                points += n.point_count;
                take
            })
            .count();
        let (batch, after) = rest.split_at(len);
        rest = after;
        for data in crate::parallel_map(batch, threads, |node| copc.read_node(node)) {
            let data = data?;
            done += data.len() as u64;
            gather.add(&data);
        }
        progress(done, total);
    }
    gather.finish(path, &facts, origin)
}

/// The points of a LAS file as they are read, chunk by chunk: integer
/// codes and their ranges, colors, intensities, classes and returns;
/// [`Gather::finish`] makes the cloud once the ranges are known.
pub(super) struct Gather {
    positions: Vec<Vec3>,
    colors: Vec<Vec3>,
    classes: Vec<u8>,
    intensities: Vec<u16>,
    returns: Vec<u8>,
    code_lo: [i32; 3],
    code_hi: [i32; 3],
    rgb_max: u16,
    int_lo: u16,
    int_hi: u16,
}

impl Gather {
    pub(super) fn with_capacity(n: usize, path: &Path) -> Result<Gather> {
        let mut g = Gather {
            positions: Vec::new(),
            colors: Vec::new(),
            classes: Vec::new(),
            intensities: Vec::new(),
            returns: Vec::new(),
            code_lo: [i32::MAX; 3],
            code_hi: [i32::MIN; 3],
            rgb_max: 0,
            int_lo: u16::MAX,
            int_hi: 0,
        };
        reserve(&mut g.positions, n, path)?;
        reserve(&mut g.colors, n, path)?;
        reserve(&mut g.classes, n, path)?;
        reserve(&mut g.intensities, n, path)?;
        reserve(&mut g.returns, n, path)?;
        Ok(g)
    }

    /// Adds one chunk of points. The positions hold each point's integer
    /// codes (through bytemuck, in place) until the whole file is read:
    /// then the codes' exact range gives the origin, and one pass turns
    /// them into f32.
    pub(super) fn add(&mut self, data: &PointData) {
        let at = self.positions.len();
        self.positions.resize(at + data.len(), Vec3::ZERO);
        let codes: &mut [[i32; 3]] = bytemuck::cast_slice_mut(&mut self.positions[at..]);
        fill_axis(
            codes,
            0,
            data.x_raw(),
            &mut self.code_lo[0],
            &mut self.code_hi[0],
        );
        fill_axis(
            codes,
            1,
            data.y_raw(),
            &mut self.code_lo[1],
            &mut self.code_hi[1],
        );
        fill_axis(
            codes,
            2,
            data.z_raw(),
            &mut self.code_lo[2],
            &mut self.code_hi[2],
        );
        self.classes.extend(data.classification());
        self.returns.extend(
            data.return_number()
                .zip(data.number_of_returns())
                .map(|(r, n)| crate::color::pack_return(r, n)),
        );
        for i in data.intensity() {
            (self.int_lo, self.int_hi) = (self.int_lo.min(i), self.int_hi.max(i));
            self.intensities.push(i);
        }
        match data.rgb() {
            Some(rgb) => {
                for (r, g, b) in rgb {
                    self.rgb_max = self.rgb_max.max(r).max(g).max(b);
                    self.colors
                        .push(Vec3::new(f32::from(r), f32::from(g), f32::from(b)));
                }
            }
            None => self
                .colors
                .resize(self.colors.len() + data.len(), Vec3::ZERO),
        }
    }

    /// The cloud of every chunk added, re-centred on `origin` (default:
    /// the centre of the codes' range), its colors scaled by the ranges of
    /// what was added, or by `norms` where given (a cloud read in parts
    /// that must agree with the others).
    pub(super) fn finish_with(
        mut self,
        path: &Path,
        facts: &Preflight,
        origin: Option<DVec3>,
        norms: Norms,
    ) -> Result<PointCloud> {
        (self.code_lo, self.code_hi) = (norms.code_lo, norms.code_hi);
        (self.rgb_max, self.int_lo, self.int_hi) = (norms.rgb_max, norms.int_lo, norms.int_hi);
        self.finish(path, facts, origin)
    }

    fn finish(self, path: &Path, facts: &Preflight, origin: Option<DVec3>) -> Result<PointCloud> {
        let fail = las_fail(path);
        let header = &facts.header;
        let format = *header.point_format();
        let total = self.positions.len() as u64;
        let t = header.transforms();
        let Gather {
            positions,
            colors,
            classes,
            intensities,
            returns,
            code_lo,
            code_hi,
            rgb_max,
            int_lo,
            int_hi,
        } = self;
        let mut cloud = PointCloud {
            positions,
            colors,
            ..PointCloud::default()
        };
        // Colors, now that the file's ranges are known: a table per code.
        let table = |f: &dyn Fn(u16) -> f32| -> Vec<f32> { (0..=u16::MAX).map(f).collect() };
        let grey = |lo: u16, hi: u16| {
            move |i: u16| linear_from_code(f64::from(i.saturating_sub(lo)), f64::from(hi - lo))
        };
        let color_source;
        if format.has_color && rgb_max > 0 {
            let max_code = if rgb_max <= 255 { 255.0 } else { 65535.0 };
            color_source = if rgb_max <= 255 {
                "rgb (8-bit values in 16-bit fields)"
            } else {
                "rgb (16-bit)"
            };
            let lut = table(&|v| linear_from_code(f64::from(v), max_code));
            map_colors(&mut cloud.colors, &|c| {
                Vec3::new(lut[c.x as usize], lut[c.y as usize], lut[c.z as usize])
            });
            cloud.has_colors = true;
        } else if int_lo < int_hi && total > 0 {
            color_source = if format.has_color {
                "intensity as grey (the rgb is all zero)"
            } else {
                "intensity as grey"
            };
            let lut = table(&grey(int_lo, int_hi));
            for (c, &i) in cloud.colors.iter_mut().zip(&intensities) {
                *c = Vec3::splat(lut[usize::from(i)]);
            }
            cloud.has_colors = true;
        } else {
            color_source = "none (no rgb, constant intensity)";
            cloud.colors.fill(DEFAULT_COLOR);
        }
        cloud.has_rgb = format.has_color && rgb_max > 0;
        cloud.intensities = Some(intensities);
        cloud.returns = Some(returns);

        let tr = [t.x, t.y, t.z];
        let mut axes = [Axis::new(1.0, 0.0, 0.0, 0.0); 3];
        for k in 0..3 {
            let range = if total > 0 {
                (f64::from(code_lo[k]), f64::from(code_hi[k]))
            } else {
                (0.0, 0.0)
            };
            axes[k] = axis(tr[k].scale, tr[k].offset, origin.map(|o| o[k]), range).map_err(fail)?;
        }
        to_scene(&mut cloud.positions, &axes).map_err(fail)?;
        cloud.origin = DVec3::new(axes[0].origin, axes[1].origin, axes[2].origin);
        cloud.classifications = Some(classes);
        cloud.z_up = true;
        cloud.attributes = attributes(&format);
        cloud.file_info = file_info(
            header,
            facts,
            &axes,
            (total > 0).then_some((code_lo, code_hi)),
            color_source,
        );
        Ok(cloud)
    }
}

/// The ranges a cloud's positions and colors are scaled by: the codes'
/// range per axis (whose centre is the default origin), the largest RGB
/// code (8- or 16-bit colors) and the intensities' range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Norms {
    pub(super) code_lo: [i32; 3],
    pub(super) code_hi: [i32; 3],
    pub(super) rgb_max: u16,
    pub(super) int_lo: u16,
    pub(super) int_hi: u16,
}

/// Reserves room for exactly `n` more elements, or a clear error (a lying
/// point count must not abort the process).
fn reserve<T>(v: &mut Vec<T>, n: usize, path: &Path) -> Result<()> {
    v.try_reserve_exact(n).map_err(|_| Error::Las {
        path: path.to_path_buf(),
        msg: format!(
            "cannot allocate memory for the {n} points its header declares ({:.1} GB)",
            (n as f64) * std::mem::size_of::<T>() as f64 / 1e9
        ),
    })
}

/// Writes axis `k` of the codes and widens its range.
fn fill_axis(
    codes: &mut [[i32; 3]],
    k: usize,
    column: impl Iterator<Item = i32>,
    lo: &mut i32,
    hi: &mut i32,
) {
    for (slot, c) in codes.iter_mut().zip(column) {
        slot[k] = c;
        (*lo, *hi) = ((*lo).min(c), (*hi).max(c));
    }
}

/// Turns the integer codes that `positions` hold (bit for bit) into scene
/// coordinates, split over the cores; an error when one does not fit f32.
fn to_scene(positions: &mut [Vec3], axes: &[Axis; 3]) -> Result<(), String> {
    let chunk = positions
        .len()
        .div_ceil(crate::available_threads())
        .max(1 << 16);
    let failures: Vec<Option<String>> = std::thread::scope(|scope| {
        let parts: Vec<_> = positions
            .chunks_mut(chunk)
            .map(|part| {
                scope.spawn(move || {
                    let slots: &mut [[u32; 3]] = bytemuck::cast_slice_mut(part);
                    for slot in slots {
                        let code = slot.map(|b| b as i32);
                        let p: [f32; 3] = std::array::from_fn(|k| axes[k].local(code[k]));
                        if !p.iter().all(|v| v.is_finite()) {
                            let file: [f64; 3] = std::array::from_fn(|k| axes[k].file(code[k]));
                            return Some(format!(
                                "a point at {file:?} does not fit in f32 after re-centring on the origin"
                            ));
                        }
                        *slot = p.map(f32::to_bits);
                    }
                    None
                })
            })
            .collect();
        parts
            .into_iter()
            .map(|h| h.join().expect("no panic"))
            .collect()
    });
    match failures.into_iter().flatten().next() {
        Some(msg) => Err(msg),
        None => Ok(()),
    }
}

/// Applies `f` to every color, split over the cores.
fn map_colors(colors: &mut [Vec3], f: &(dyn Fn(Vec3) -> Vec3 + Sync)) {
    let chunk = colors
        .len()
        .div_ceil(crate::available_threads())
        .max(1 << 16);
    std::thread::scope(|scope| {
        for part in colors.chunks_mut(chunk) {
            scope.spawn(move || part.iter_mut().for_each(|c| *c = f(*c)));
        }
    });
}

/// The dimensions a point format holds, in record order, as `info` lists them.
fn attributes(format: &las::point::Format) -> Vec<String> {
    let mut names: Vec<&str> = vec![
        "x",
        "y",
        "z",
        "intensity",
        "return_number",
        "number_of_returns",
        "classification",
        "scan_angle",
        "user_data",
        "point_source_id",
    ];
    if format.has_gps_time {
        names.push("gps_time");
    }
    if format.has_color {
        names.extend(["red", "green", "blue"]);
    }
    if format.has_nir {
        names.push("nir");
    }
    if format.has_waveform {
        names.push("waveform_packet");
    }
    let mut names: Vec<String> = names.into_iter().map(String::from).collect();
    if format.extra_bytes > 0 {
        names.push(format!("extra_bytes({})", format.extra_bytes));
    }
    names
}

/// What `info` prints about a LAS file beyond the cloud's own lines.
fn file_info(
    header: &las::Header,
    facts: &Preflight,
    axes: &[Axis; 3],
    codes: Option<([i32; 3], [i32; 3])>,
    color_source: &str,
) -> Vec<(String, String)> {
    let format = header.point_format();
    let is_copc = header.vlrs().iter().any(|v| v.is_copc_info());
    let kind = match (format.is_compressed, is_copc) {
        (true, true) => "COPC (LAZ)",
        (true, false) => "LAZ",
        (false, _) => "LAS",
    };
    let version = header.version();
    let number = format.to_u8().map_or("?".to_string(), |n| n.to_string());
    let v3 = |f: &dyn Fn(&Axis) -> f64| format!("{} {} {}", f(&axes[0]), f(&axes[1]), f(&axes[2]));
    let mut lines = vec![
        ("format".to_string(), kind.to_string()),
        (
            "las_version".to_string(),
            format!("{}.{}", version.major, version.minor),
        ),
        (
            "point_format".to_string(),
            format!("{number} ({} bytes per record)", facts.record_len),
        ),
        ("scale".to_string(), v3(&|a| a.scale)),
        ("offset".to_string(), v3(&|a| a.offset)),
    ];
    if let Some((lo, hi)) = codes {
        let corner = |c: [i32; 3]| {
            let v: Vec<String> = (0..3).map(|k| display_coord(axes[k].file(c[k]))).collect();
            v.join(" ")
        };
        lines.push(("file_bounds_min".to_string(), corner(lo)));
        lines.push(("file_bounds_max".to_string(), corner(hi)));
    }
    lines.push(("crs".to_string(), crs_text(header)));
    lines.push(("color_source".to_string(), color_source.to_string()));
    let software = header
        .generating_software()
        .trim_matches(char::from(0))
        .trim();
    if !software.is_empty() {
        lines.push(("generating_software".to_string(), software.to_string()));
    }
    lines
}

/// The file's coordinate reference system as one line: the WKT when the
/// file carries one, else the GeoTIFF keys' EPSG codes, else "none".
fn crs_text(header: &las::Header) -> String {
    if let Some(wkt) = header.get_wkt_crs_bytes() {
        let text = String::from_utf8_lossy(wkt);
        let text = text.trim_matches(char::from(0)).trim();
        if !text.is_empty() {
            return format!(
                "WKT {}",
                text.split_whitespace().collect::<Vec<_>>().join(" ")
            );
        }
    }
    match header.get_geotiff_crs() {
        Ok(Some(geo)) => {
            let mut parts = Vec::new();
            if let Some(code) = geo.get_projected_crs_geo_key_value() {
                parts.push(format!("projected EPSG:{code}"));
            }
            if let Some(code) = geo.get_geodetic_crs_geo_key_value() {
                parts.push(format!("geographic EPSG:{code}"));
            }
            if let Some(code) = geo.get_vertical_crs_geo_key_value() {
                parts.push(format!("vertical EPSG:{code}"));
            }
            if parts.is_empty() {
                format!("GeoTIFF keys ({} entries, no EPSG code)", geo.entries.len())
            } else {
                format!("GeoTIFF {}", parts.join(", "))
            }
        }
        Ok(None) => "none".to_string(),
        Err(e) => format!("unreadable GeoTIFF keys ({e})"),
    }
}
