//! PLY input: ASCII and binary (either endianness), float or double
//! coordinates, 8/16-bit integer or float colors, optional normals. Faces,
//! other elements and unknown properties are ignored.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Cursor, Read, Seek};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::OnceLock;

use glam::{DVec3, Vec3};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    DefaultElement, ElementDef, Encoding, Header, Property, PropertyType, ScalarType,
};

use super::{linear_from_code, DEFAULT_COLOR};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::image_io::srgb_to_linear;

/// The accepted names of the red, green and blue properties, in order of preference.
const COLOR_NAMES: [[&str; 3]; 3] = [
    ["red", "green", "blue"],
    ["r", "g", "b"],
    ["diffuse_red", "diffuse_green", "diffuse_blue"],
];

/// Bytes of a binary vertex block that [`load_ply`] reads and converts at a
/// time (rounded down to whole records): its peak memory is the cloud plus
/// about one such chunk.
pub const CHUNK_BYTES: usize = 16 << 20;

/// Loads a point cloud from a PLY file. Colors are taken as sRGB-encoded
/// values scaled to [0, 1] (by the integer type's maximum) and converted to
/// linear light; normals are normalised.
///
/// The vertex block is read directly, split over every core: a binary one
/// streamed from the file [`CHUNK_BYTES`] at a time into the cloud's
/// vectors, an ASCII one from the whole file in memory. Anything the direct
/// reader does not take as well-formed — a malformed number, a truncated
/// file, a list property in the way, a non-finite coordinate — goes through
/// the general reader ([`load_ply_general`]), which gives the same cloud
/// for every file the direct one reads and the error messages for the rest.
pub fn load_ply(path: &Path) -> Result<PointCloud> {
    load_ply_at(path, None)
}

/// [`load_ply`] re-centred on `origin` (file coordinates), or on the
/// default origin where None (`origin_to_read_at`): positions are
/// `(file coordinate − origin)` computed in f64, then made f32.
pub fn load_ply_at(path: &Path, origin: Option<DVec3>) -> Result<PointCloud> {
    load_with_chunk(path, CHUNK_BYTES, origin)
}

/// [`load_ply`] reading a binary vertex block `chunk_bytes` at a time
/// (at least one record).
pub fn load_ply_with_chunk(path: &Path, chunk_bytes: usize) -> Result<PointCloud> {
    load_with_chunk(path, chunk_bytes, None)
}

fn load_with_chunk(path: &Path, chunk_bytes: usize, origin: Option<DVec3>) -> Result<PointCloud> {
    match load_direct(path, chunk_bytes, origin)? {
        Direct::Read(cloud) => Ok(cloud),
        Direct::Declined(Some(bytes)) => load_parsed(&bytes, path, origin),
        Direct::Declined(None) => load_parsed(&read_file(path)?, path, origin),
    }
}

/// Coordinates of this magnitude or more (on some axis) are far from
/// zero: f32 keeps less than a thousandth of a unit there (a millimetre
/// for metres: its step at 10^4 is 2^-10).
pub const FAR_COORDINATE: f64 = 1e4;

/// The origin a PLY file's vertices are read against (converted as
/// `(value − origin) as f32`, in f64): `given` where there is one; else,
/// for coordinates of more precision than f32 holds (`wide`: double or
/// 32-bit integer) whose first vertex, at `first`, lies
/// [`FAR_COORDINATE`] or more from zero (and within
/// [`super::MAX_COORDINATE`]), that vertex (the cloud is then
/// re-centred on its bounds' centre, [`settle_origin`]); else zero, the
/// file's coordinates, as for a float file, whose coordinates f32 holds
/// as they are.
fn origin_to_read_at(given: Option<DVec3>, wide: bool, first: impl FnOnce() -> DVec3) -> DVec3 {
    match given {
        Some(origin) => origin,
        None if wide => {
            let first = first();
            // A vertex beyond what a scene holds is left to the checks
            // of the file's coordinates, whose errors name it.
            let far = first.abs().max_element();
            match (FAR_COORDINATE..=f64::from(super::MAX_COORDINATE)).contains(&far) {
                true => first,
                false => DVec3::ZERO,
            }
        }
        None => DVec3::ZERO,
    }
}

/// Whether a coordinate of type `ty` may hold more precision than f32.
fn is_wide(ty: &ScalarType) -> bool {
    matches!(ty, ScalarType::Double | ScalarType::Int | ScalarType::UInt)
}

/// A cloud read against `cloud.origin` ([`origin_to_read_at`]) without
/// a `given` origin: where that was a far vertex, re-centred on the centre
/// of its bounds in f64 (as a LAS file is by default).
fn settle_origin(mut cloud: PointCloud, given: Option<DVec3>, path: &Path) -> Result<PointCloud> {
    if given.is_none() && cloud.origin != DVec3::ZERO {
        let (lo, hi) = cloud.bounds();
        let centre = cloud.origin + (lo.as_dvec3() + hi.as_dvec3()) / 2.0;
        cloud.recentre(centre).map_err(|msg| ply_error(path, msg))?;
    }
    Ok(cloud)
}

/// The direct reader alone: None when it declines the file (which
/// [`load_ply`] then hands to the general reader). For tests.
pub fn load_ply_direct(path: &Path) -> Result<Option<PointCloud>> {
    load_ply_direct_with_chunk(path, CHUNK_BYTES)
}

/// [`load_ply_direct`] reading a binary vertex block `chunk_bytes` at a
/// time (at least one record). For tests.
pub fn load_ply_direct_with_chunk(path: &Path, chunk_bytes: usize) -> Result<Option<PointCloud>> {
    Ok(match load_direct(path, chunk_bytes, None)? {
        Direct::Read(cloud) => Some(cloud),
        Direct::Declined(_) => None,
    })
}

/// A PLY file opened: a regular file with its header parsed (the reader
/// left at the payload, of `payload_len` bytes), or anything else (a pipe,
/// a device) as opened, to be read whole: its size is known at its end.
pub(super) enum Opened {
    Regular {
        input: BufReader<File>,
        header: Header,
        payload_len: u64,
    },
    Stream(File),
}

/// Opens `path` as [`Opened`], its magic bytes checked where it is a
/// regular file, its header read through a buffer of `buffer_bytes`.
pub(super) fn open_ply(path: &Path, buffer_bytes: usize) -> Result<Opened> {
    let io = |source| Error::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut file = File::open(path).map_err(io)?;
    let metadata = file.metadata().map_err(io)?;
    if !metadata.is_file() {
        return Ok(Opened::Stream(file));
    }
    let mut magic = Vec::with_capacity(5);
    (&mut file).take(5).read_to_end(&mut magic).map_err(io)?;
    check_magic(&magic, path)?;
    file.rewind().map_err(io)?;
    let mut input = BufReader::with_capacity(buffer_bytes, file);
    let header = parse_header(&mut input, path)?;
    let payload_len = metadata
        .len()
        .saturating_sub(input.stream_position().map_err(io)?);
    Ok(Opened::Regular {
        input,
        header,
        payload_len,
    })
}

/// The vertex count a PLY file's header declares, whether it is ASCII,
/// and the length of its payload, read without the payload; None for
/// what is not a regular file (a pipe is read once).
pub fn declared_points(path: &Path) -> Result<Option<(u64, bool, u64)>> {
    let Opened::Regular {
        header,
        payload_len,
        ..
    } = open_ply(path, 64 << 10)?
    else {
        return Ok(None);
    };
    let (vertex, _) = vertex_element(&header, path)?;
    let ascii = matches!(header.encoding, Encoding::Ascii);
    Ok(Some((vertex.count as u64, ascii, payload_len)))
}

/// Whether a PLY file's header declares vertex normals (`nx ny nz`), read
/// without the payload; None for what is not a regular file.
pub fn declares_normals(path: &Path) -> Result<Option<bool>> {
    let Opened::Regular { header, .. } = open_ply(path, 64 << 10)? else {
        return Ok(None);
    };
    let (_, layout) = vertex_element(&header, path)?;
    Ok(Some(layout.normals))
}

/// Vertices of a [`VertexChunks`] chunk.
pub struct Chunk {
    /// File coordinates, as the file holds them.
    pub positions: Vec<DVec3>,
    /// Linear colors (the whole read's default without colors).
    pub colors: Vec<Vec3>,
    /// The `intensity` values as stored, made f32 (empty without one).
    pub intensities: Vec<f32>,
}

/// A binary PLY file's vertices, read a chunk at a time in bounded memory
/// (for `convert`): each chunk's positions and linear colors are the ones
/// the whole read gives (the direct reader's conversion).
pub struct VertexChunks {
    input: Counted<BufReader<File>>,
    header: Header,
    fields: Fields,
    converter: Converter,
    big_endian: bool,
    left: usize,
    has_colors: bool,
}

impl VertexChunks {
    /// The file's vertices at the start of their block; None where the
    /// direct reader would not take the file as it streams (ASCII, not a
    /// regular file, a list property among the vertex's, an element before
    /// the vertices it would not take, or a vertex block longer than the
    /// file): [`load_ply`] then reads it, or says what is wrong.
    pub fn open(path: &Path) -> Result<Option<VertexChunks>> {
        let io = |source| Error::Io {
            path: path.to_path_buf(),
            source,
        };
        let Opened::Regular {
            input: reader,
            header,
            payload_len,
        } = open_ply(path, 1 << 20)?
        else {
            return Ok(None);
        };
        let (vertex, layout) = vertex_element(&header, path)?;
        if matches!(header.encoding, Encoding::Ascii) {
            return Ok(None);
        }
        let Some(fields) = Fields::of(vertex, &layout, true) else {
            return Ok(None);
        };
        let big_endian = matches!(header.encoding, Encoding::BinaryBigEndian);
        let mut input = Counted {
            inner: reader,
            taken: 0,
        };
        for element in header.elements.values() {
            if element.name == vertex.name {
                break;
            }
            if element.properties.is_empty() {
                continue;
            }
            for _ in 0..element.count {
                if !skip_binary_element(&mut input, element, big_endian).map_err(io)? {
                    return Ok(None);
                }
            }
        }
        let left = payload_len.saturating_sub(input.taken);
        match (vertex.count as u64).checked_mul(fields.stride as u64) {
            Some(bytes) if bytes <= left => {}
            _ => return Ok(None),
        }
        let converter = Converter::new(&fields, DVec3::ZERO);
        Ok(Some(VertexChunks {
            left: vertex.count,
            has_colors: layout.colors.is_some(),
            input,
            fields,
            converter,
            big_endian,
            header,
        }))
    }

    /// Whether the vertices have colors (else the whole read's default).
    pub fn has_colors(&self) -> bool {
        self.has_colors
    }

    /// The scale of the vertices' `intensity` whose stored values (as
    /// [`Chunk::intensities`] gives them) lie in `range`
    /// ([`finite_range`]); None without one.
    pub fn intensity_scale(&self, range: (f64, f64)) -> Option<IntensityScale> {
        Some(IntensityScale::of(
            &self.fields.intensity.as_ref()?.ty,
            range,
        ))
    }

    /// Vertices not yet read.
    pub fn left(&self) -> usize {
        self.left
    }

    /// The next at most `max` vertices' positions (file coordinates, in
    /// f64, as the file holds them) and linear colors (an empty chunk at
    /// the end); None where the direct reader would decline them (a
    /// coordinate not finite in f32).
    pub fn next_chunk(&mut self, max: usize) -> io::Result<Option<Chunk>> {
        let n = max.max(1).min(self.left);
        let mut block = vec![0u8; n * self.fields.stride];
        if !read_or_end(&mut self.input, &mut block)? {
            return Ok(None);
        }
        let mut part: Part = (Vec::new(), Vec::new(), Vec::new());
        if !append_binary(
            &block,
            &self.fields,
            &self.converter,
            self.big_endian,
            &mut part,
        ) {
            return Ok(None);
        }
        self.left -= n;
        let positions = block
            .chunks_exact(self.fields.stride)
            .map(|r| self.fields.binary_position(r, self.big_endian))
            .collect();
        Ok(Some(Chunk {
            positions,
            colors: part.1,
            intensities: self.fields.binary_intensities(&block, self.big_endian),
        }))
    }

    /// After the last chunk: whether the elements after the vertices are
    /// as the direct reader takes them.
    pub fn rest_is_well_formed(mut self) -> io::Result<bool> {
        let mut after = false;
        for element in self.header.elements.values() {
            if after && !element.properties.is_empty() {
                for _ in 0..element.count {
                    if !skip_binary_element(&mut self.input, element, self.big_endian)? {
                        return Ok(false);
                    }
                }
            }
            after |= element.name == "vertex";
        }
        Ok(true)
    }
}

/// What the direct reader made of a file.
enum Direct {
    Read(PointCloud),
    /// Left to the general reader, with the file's bytes where they were
    /// read whole (ASCII).
    Declined(Option<Vec<u8>>),
}

fn load_direct(path: &Path, chunk_bytes: usize, origin: Option<DVec3>) -> Result<Direct> {
    let io = |source| Error::Io {
        path: path.to_path_buf(),
        source,
    };
    let bytes = match open_ply(path, 64 << 10)? {
        Opened::Regular {
            mut input,
            header,
            payload_len,
        } => {
            let (vertex, layout) = vertex_element(&header, path)?;
            if !matches!(header.encoding, Encoding::Ascii) {
                let cloud = read_binary(
                    &mut input,
                    payload_len,
                    &header,
                    vertex,
                    &layout,
                    (chunk_bytes, origin),
                )
                .map_err(io)?;
                let z_up = declares_z_up(&header);
                return Ok(match cloud {
                    Some(c) => Direct::Read(settle_origin(PointCloud { z_up, ..c }, origin, path)?),
                    None => Direct::Declined(None),
                });
            }
            // ASCII is read whole: its lines are found in memory.
            drop(input);
            read_file(path)?
        }
        // A pipe or a device, whose size is known at its end: read whole,
        // from the handle already open.
        Opened::Stream(mut file) => {
            let mut bytes = Vec::new();
            file.read_to_end(&mut bytes).map_err(io)?;
            check_magic(&bytes, path)?;
            bytes
        }
    };
    let (header, payload_at) = read_header(&bytes, path)?;
    let (vertex, layout) = vertex_element(&header, path)?;
    let payload = &bytes[payload_at..];
    let cloud = if matches!(header.encoding, Encoding::Ascii) {
        read_ascii(payload, &header, vertex, &layout, origin)
    } else {
        let mut input = payload;
        read_binary(
            &mut input,
            payload.len() as u64,
            &header,
            vertex,
            &layout,
            (chunk_bytes, origin),
        )
        .map_err(io)?
    };
    Ok(match cloud {
        Some(cloud) => Direct::Read(settle_origin(
            PointCloud {
                z_up: declares_z_up(&header),
                ..cloud
            },
            origin,
            path,
        )?),
        None => Direct::Declined(Some(bytes)),
    })
}

/// Whether the header says the cloud is z-up: a `comment` or `obj_info`
/// line reading `up z` (also `up: z`, `up = +z`, any case), as pointlens
/// documents for PLY files (LAS is z-up by specification).
pub fn declares_z_up(header: &ply_rs_bw::ply::Header) -> bool {
    header
        .comments
        .iter()
        .chain(&header.obj_infos)
        .any(|line| says_z_up(line))
}

/// `up z`, `up: z`, `up = +z` (any case, any spaces).
pub fn says_z_up(line: &str) -> bool {
    let squeezed: String = line
        .chars()
        .filter(|c| !c.is_whitespace() && *c != ':' && *c != '=' && *c != '+')
        .flat_map(char::to_lowercase)
        .collect();
    squeezed == "upz"
}

/// [`load_ply`] through the general reader alone (ply-rs, a map per
/// vertex): the reference the direct reader is tested against.
pub fn load_ply_general(path: &Path) -> Result<PointCloud> {
    load_parsed(&read_file(path)?, path, None)
}

pub(super) fn ply_error(path: &Path, msg: String) -> Error {
    Error::Ply {
        path: path.to_path_buf(),
        msg,
    }
}

pub(super) fn read_file(path: &Path) -> Result<Vec<u8>> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    check_magic(&bytes, path)?;
    Ok(bytes)
}

/// Whether the file starts as a PLY file does.
fn check_magic(start: &[u8], path: &Path) -> Result<()> {
    if !start.starts_with(b"ply\n") && !start.starts_with(b"ply\r\n") {
        return Err(ply_error(
            path,
            "not a PLY file (it does not start with 'ply')".into(),
        ));
    }
    Ok(())
}

/// Reads the header from `input`, which is left where the payload starts:
/// ply-rs reads it line by line and stops right after the `end_header`
/// line.
fn parse_header(input: &mut impl BufRead, path: &Path) -> Result<Header> {
    let parser = Parser::<DefaultElement>::new();
    let mut reader = Reader::new(input);
    guarded(|| parser.read_header(&mut reader))
        .map_err(|e| ply_error(path, format!("malformed header: {e}")))
}

/// The header and the offset of the payload after it.
pub(super) fn read_header(bytes: &[u8], path: &Path) -> Result<(Header, usize)> {
    let mut cursor = Cursor::new(bytes);
    let header = parse_header(&mut cursor, path)?;
    Ok((header, cursor.position() as usize))
}

/// The vertex element and its layout, or the header's error.
fn vertex_element<'h>(header: &'h Header, path: &Path) -> Result<(&'h ElementDef, Layout)> {
    let vertex = header
        .elements
        .get("vertex")
        .ok_or_else(|| ply_error(path, "no 'vertex' element in the header".into()))?;
    let layout = Layout::of(vertex).map_err(|msg| ply_error(path, msg))?;
    if vertex.count == 0 {
        return Err(ply_error(path, "the cloud is empty (0 vertices)".into()));
    }
    Ok((vertex, layout))
}

/// The general reader: ply-rs parses the whole payload into a map per
/// element, then the vertices are converted one by one.
fn load_parsed(bytes: &[u8], path: &Path, origin: Option<DVec3>) -> Result<PointCloud> {
    let fail = |msg: String| ply_error(path, msg);
    // The header is checked before the payload so that its errors are specific.
    let (header, _) = read_header(bytes, path)?;
    let (vertex, layout) = vertex_element(&header, path)?;
    let parser = Parser::<DefaultElement>::new();
    let ply = guarded(|| parser.read_ply(&mut &bytes[..])).map_err(|e| {
        if e.contains("end of file")
            || e.contains("UnexpectedEof")
            || e.contains("fill whole buffer")
        {
            fail(format!(
                "truncated data: the header declares {} vertices ({e})",
                vertex.count
            ))
        } else {
            fail(format!("malformed data: {e}"))
        }
    })?;
    let rows = ply.payload.get("vertex").map(Vec::as_slice).unwrap_or(&[]);
    if rows.len() < vertex.count {
        return Err(fail(format!(
            "truncated data: the header declares {} vertices, the file holds {}",
            vertex.count,
            rows.len()
        )));
    }

    let value = |row: &DefaultElement, name: &str| {
        row.get(name)
            .and_then(Scalar::of)
            .map_or(0.0, Scalar::value)
    };
    let at = |row: &DefaultElement| DVec3::new(value(row, "x"), value(row, "y"), value(row, "z"));
    let wide = ["x", "y", "z"].iter().any(|n| {
        matches!(
            vertex.properties.get(*n).map(|p| &p.data_type),
            Some(PropertyType::Scalar(ty)) if is_wide(ty)
        )
    });
    let shift = origin_to_read_at(origin, wide, || rows.first().map_or(DVec3::ZERO, at));
    let mut cloud = PointCloud {
        origin: shift,
        positions: Vec::with_capacity(rows.len()),
        colors: Vec::with_capacity(rows.len()),
        normals: layout.normals.then(|| Vec::with_capacity(rows.len())),
        has_colors: layout.colors.is_some(),
        has_rgb: layout.colors.is_some(),
        attributes: vertex.properties.keys().cloned().collect(),
        z_up: declares_z_up(&header),
        ..PointCloud::default()
    };
    for (i, row) in rows.iter().enumerate() {
        let get = |name: &str| {
            row.get(name)
                .and_then(Scalar::of)
                .map_or(0.0, Scalar::coordinate)
        };
        let file = at(row);
        let p = (file - shift).as_vec3();
        if !p.is_finite() {
            let raw = file.as_vec3();
            return Err(fail(match raw.is_finite() {
                true => {
                    format!("a point at {file} does not fit in f32 after re-centring on {shift}")
                }
                false => format!("vertex {i} has a non-finite coordinate ({raw})"),
            }));
        }
        cloud.positions.push(p);
        let color = match &layout.colors {
            Some(names) => Vec3::from_array(names.each_ref().map(|n| {
                // A list reads as 0, as a missing channel does.
                row.get(*n)
                    .and_then(Scalar::of)
                    .map_or(srgb_to_linear(0.0), Scalar::linear_color)
            })),
            None => DEFAULT_COLOR,
        };
        cloud.colors.push(color);
        if let Some(normals) = cloud.normals.as_mut() {
            normals.push(unit_normal(Vec3::new(get("nx"), get("ny"), get("nz"))));
        }
    }
    if let Some(PropertyType::Scalar(ty)) = vertex.properties.get(INTENSITY).map(|p| &p.data_type) {
        let raw: Vec<f64> = rows
            .iter()
            .map(|row| f64::from(value(row, INTENSITY) as f32))
            .collect();
        let scale = IntensityScale::of(ty, finite_range(raw.iter().copied()));
        cloud.intensities = Some(raw.iter().map(|&v| scale.code(v)).collect());
    }
    settle_origin(cloud, origin, path)
}

/// Which optional vertex properties a file has.
struct Layout {
    colors: Option<[&'static str; 3]>,
    normals: bool,
}

impl Layout {
    fn of(vertex: &ElementDef) -> std::result::Result<Layout, String> {
        let numeric = |name: &str| -> std::result::Result<bool, String> {
            match vertex.properties.get(name).map(|p| &p.data_type) {
                None => Ok(false),
                Some(PropertyType::Scalar(_)) => Ok(true),
                Some(PropertyType::List(..)) => {
                    Err(format!("vertex property '{name}' is a list, not a number"))
                }
            }
        };
        for axis in ["x", "y", "z"] {
            if !numeric(axis)? {
                return Err(format!("vertex element lacks the '{axis}' coordinate"));
            }
        }
        let mut colors = None;
        for names in COLOR_NAMES {
            let present = names
                .iter()
                .map(|n| numeric(n))
                .collect::<std::result::Result<Vec<_>, _>>()?;
            if present.iter().all(|&p| p) {
                colors = Some(names);
                break;
            }
        }
        let normals = numeric("nx")? && numeric("ny")? && numeric("nz")?;
        Ok(Layout { colors, normals })
    }
}

/// Runs a ply-rs call, turning its errors and any panic into a message.
fn guarded<T, E: std::fmt::Display>(
    f: impl FnOnce() -> std::result::Result<T, E>,
) -> std::result::Result<T, String> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(v)) => Ok(v),
        // One line: ply-rs's messages may span several.
        Ok(Err(e)) => Err(e
            .to_string()
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")),
        Err(_) => Err("the PLY parser could not read it".to_string()),
    }
}

/// One scalar value of a property, as stored: what both readers convert.
#[derive(Debug, Clone, Copy)]
pub(super) enum Scalar {
    Char(i8),
    UChar(u8),
    Short(i16),
    UShort(u16),
    Int(i32),
    UInt(u32),
    Float(f32),
    Double(f64),
}

impl Scalar {
    /// A scalar property of the general reader (None for a list).
    fn of(p: &Property) -> Option<Scalar> {
        Some(match *p {
            Property::Char(v) => Scalar::Char(v),
            Property::UChar(v) => Scalar::UChar(v),
            Property::Short(v) => Scalar::Short(v),
            Property::UShort(v) => Scalar::UShort(v),
            Property::Int(v) => Scalar::Int(v),
            Property::UInt(v) => Scalar::UInt(v),
            Property::Float(v) => Scalar::Float(v),
            Property::Double(v) => Scalar::Double(v),
            _ => return None,
        })
    }

    /// The value as f64.
    pub(super) fn value(self) -> f64 {
        match self {
            Scalar::Char(v) => v as f64,
            Scalar::UChar(v) => v as f64,
            Scalar::Short(v) => v as f64,
            Scalar::UShort(v) => v as f64,
            Scalar::Int(v) => v as f64,
            Scalar::UInt(v) => v as f64,
            Scalar::Float(v) => v as f64,
            Scalar::Double(v) => v,
        }
    }

    /// The value as a coordinate (or normal component) in f32.
    fn coordinate(self) -> f32 {
        self.value() as f32
    }

    /// The code of full intensity: an integer type's maximum, 1 for floats.
    fn color_max(self) -> f64 {
        match self {
            Scalar::Char(_) => i8::MAX as f64,
            Scalar::UChar(_) => u8::MAX as f64,
            Scalar::Short(_) => i16::MAX as f64,
            Scalar::UShort(_) => u16::MAX as f64,
            Scalar::Int(_) => i32::MAX as f64,
            Scalar::UInt(_) => u32::MAX as f64,
            Scalar::Float(_) | Scalar::Double(_) => 1.0,
        }
    }

    /// The linear-light color of the channel, sRGB-encoded: an integer
    /// type's code over its maximum, clamped to [0, 1]; a float as it is,
    /// clamped below at 0 (not a number: 0) and not above: a float color
    /// above 1 is brighter than white (the sRGB curve extended, as
    /// extended-range sRGB does: 2 is 4.95 times white), kept as a
    /// highlight through the blur (EXR keeps it; PNG clips after the blur).
    fn linear_color(self) -> f32 {
        match self {
            Scalar::Float(_) | Scalar::Double(_) => {
                crate::image_io::srgb_to_linear((self.value() as f32).max(0.0))
            }
            _ => linear_from_code(self.value(), self.color_max()),
        }
    }
}

/// A normal as loaded: normalised, or zero when it has no direction.
fn unit_normal(n: Vec3) -> Vec3 {
    n.try_normalize().unwrap_or(Vec3::ZERO)
}

/// The name of the vertex property read as a LiDAR intensity.
const INTENSITY: &str = "intensity";

/// How a PLY `intensity` becomes a 16-bit LAS intensity (which the LAS
/// specification normalises to 0–65535): an 8-bit value times 257 (255 →
/// 65535), a 16-bit one as it is; any other type by the range of the
/// file's finite values: within [0, 1] (a float normalised) times 65535,
/// within [0, 65535] rounded as it is (raw counts), else the range mapped
/// linearly onto 0–65535. Rounded to the nearest code; a value outside
/// the range or not finite is clamped (NaN to 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum IntensityScale {
    Bits8,
    Bits16,
    Unit,
    AsIs,
    Range(f64, f64),
}

impl IntensityScale {
    /// The scale of values of type `ty` whose finite ones lie in
    /// `lo..=hi` (an empty range where there are none).
    fn of(ty: &ScalarType, (lo, hi): (f64, f64)) -> IntensityScale {
        let float = matches!(ty, ScalarType::Float | ScalarType::Double);
        match ty {
            ScalarType::UChar => IntensityScale::Bits8,
            ScalarType::UShort => IntensityScale::Bits16,
            _ if lo > hi => IntensityScale::AsIs,
            _ if float && lo >= 0.0 && hi <= 1.0 => IntensityScale::Unit,
            _ if lo >= 0.0 && hi <= 65535.0 => IntensityScale::AsIs,
            _ => IntensityScale::Range(lo, hi),
        }
    }

    /// The 16-bit intensity of value `v`.
    pub fn code(self, v: f64) -> u16 {
        let scaled = match self {
            IntensityScale::Bits8 => v * 257.0,
            IntensityScale::Bits16 | IntensityScale::AsIs => v,
            IntensityScale::Unit => v * 65535.0,
            IntensityScale::Range(lo, hi) => (v - lo) / (hi - lo).max(f64::MIN_POSITIVE) * 65535.0,
        };
        // `as` saturates, and makes NaN 0.
        scaled.round().clamp(0.0, 65535.0) as u16
    }
}

/// The range of the finite values of `values`: (lo, hi), lo > hi where
/// there are none.
pub fn finite_range(values: impl IntoIterator<Item = f64>) -> (f64, f64) {
    values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        })
}

/// The 16-bit intensities of `raw` values of the `intensity` property of
/// `fields` ([`IntensityScale`]); None without one.
fn intensity_codes(fields: &Fields, raw: &[f32]) -> Option<Vec<u16>> {
    let f = fields.intensity.as_ref()?;
    let scale = IntensityScale::of(&f.ty, finite_range(raw.iter().map(|&v| f64::from(v))));
    Some(raw.iter().map(|&v| scale.code(f64::from(v))).collect())
}

/// Where one scalar vertex property lies in a binary record, or which token
/// of an ASCII line it is, and its type.
#[derive(Debug, Clone)]
struct Field {
    /// Byte offset in the binary record, or token index in the ASCII line.
    at: usize,
    ty: ScalarType,
}

/// The vertex properties the cloud is made of.
struct Fields {
    position: [Field; 3],
    color: Option<[Field; 3]>,
    normal: Option<[Field; 3]>,
    /// The `intensity` property, as stored.
    intensity: Option<Field>,
    /// Bytes per binary record (0 for ASCII).
    stride: usize,
}

pub(super) fn scalar_bytes(ty: &ScalarType) -> usize {
    match ty {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

impl Fields {
    /// The fields of `vertex`; None when a property is a list (records are
    /// then not of one size, and ASCII lines not of one token count).
    fn of(vertex: &ElementDef, layout: &Layout, binary: bool) -> Option<Fields> {
        let mut at = 0;
        let mut found = Vec::new();
        for (name, property) in &vertex.properties {
            let PropertyType::Scalar(ty) = &property.data_type else {
                return None;
            };
            found.push((name.as_str(), Field { at, ty: ty.clone() }));
            at += if binary { scalar_bytes(ty) } else { 1 };
        }
        let get = |name: &str| found.iter().find(|(n, _)| *n == name).map(|f| f.1.clone());
        let three = |names: [&str; 3]| Some([get(names[0])?, get(names[1])?, get(names[2])?]);
        Some(Fields {
            position: three(["x", "y", "z"])?,
            color: match layout.colors {
                Some(names) => Some(three(names)?),
                None => None,
            },
            normal: match layout.normals {
                true => Some(three(["nx", "ny", "nz"])?),
                false => None,
            },
            intensity: get(INTENSITY),
            stride: if binary { at } else { 0 },
        })
    }
}

impl Fields {
    /// The intensities of the binary records of `block`, as stored
    /// (empty without an `intensity` property).
    fn binary_intensities(&self, block: &[u8], big_endian: bool) -> Vec<f32> {
        let Some(f) = &self.intensity else {
            return Vec::new();
        };
        block
            .chunks_exact(self.stride)
            .map(|r| binary_scalar(&r[f.at..], &f.ty, big_endian).value() as f32)
            .collect()
    }

    /// Whether a coordinate may hold more precision than f32 ([`is_wide`]).
    fn wide(&self) -> bool {
        self.position.iter().any(|f| is_wide(&f.ty))
    }

    /// The file position of the first binary record of `block`.
    fn binary_position(&self, block: &[u8], big_endian: bool) -> DVec3 {
        let [x, y, z] = self
            .position
            .each_ref()
            .map(|f| binary_scalar(&block[f.at..], &f.ty, big_endian).value());
        DVec3::new(x, y, z)
    }
}

/// Reads a binary scalar of type `ty` at the start of `b`.
pub(super) fn binary_scalar(b: &[u8], ty: &ScalarType, big_endian: bool) -> Scalar {
    macro_rules! read {
        ($t:ty, $n:expr) => {{
            let a: [u8; $n] = b[..$n].try_into().expect("record holds the field");
            if big_endian {
                <$t>::from_be_bytes(a)
            } else {
                <$t>::from_le_bytes(a)
            }
        }};
    }
    match ty {
        ScalarType::Char => Scalar::Char(read!(i8, 1)),
        ScalarType::UChar => Scalar::UChar(read!(u8, 1)),
        ScalarType::Short => Scalar::Short(read!(i16, 2)),
        ScalarType::UShort => Scalar::UShort(read!(u16, 2)),
        ScalarType::Int => Scalar::Int(read!(i32, 4)),
        ScalarType::UInt => Scalar::UInt(read!(u32, 4)),
        ScalarType::Float => Scalar::Float(read!(f32, 4)),
        ScalarType::Double => Scalar::Double(read!(f64, 8)),
    }
}

/// Parses an ASCII token as the general reader does: only tokens of its
/// grammar (`[-+]?digits(.digits)?([eE][-+]?digits)?`), then Rust's parser
/// for the property's own type. None for anything else.
pub(super) fn ascii_scalar(token: &[u8], ty: &ScalarType) -> Option<Scalar> {
    if !is_ply_number(token) {
        return None;
    }
    // The grammar admits only ASCII.
    let s = std::str::from_utf8(token).ok()?;
    Some(match ty {
        ScalarType::Char => Scalar::Char(s.parse().ok()?),
        ScalarType::UChar => Scalar::UChar(s.parse().ok()?),
        ScalarType::Short => Scalar::Short(s.parse().ok()?),
        ScalarType::UShort => Scalar::UShort(s.parse().ok()?),
        ScalarType::Int => Scalar::Int(s.parse().ok()?),
        ScalarType::UInt => Scalar::UInt(s.parse().ok()?),
        ScalarType::Float => Scalar::Float(s.parse().ok()?),
        ScalarType::Double => Scalar::Double(s.parse().ok()?),
    })
}

/// Whether `t` is a number of the PLY data-line grammar.
fn is_ply_number(t: &[u8]) -> bool {
    let mut i = 0;
    let digits = |i: &mut usize| {
        let start = *i;
        while *i < t.len() && t[*i].is_ascii_digit() {
            *i += 1;
        }
        *i > start
    };
    if i < t.len() && (t[i] == b'-' || t[i] == b'+') {
        i += 1;
    }
    if !digits(&mut i) {
        return false;
    }
    if i < t.len() && t[i] == b'.' {
        i += 1;
        if !digits(&mut i) {
            return false;
        }
    }
    if i < t.len() && (t[i] == b'e' || t[i] == b'E') {
        i += 1;
        if i < t.len() && (t[i] == b'-' || t[i] == b'+') {
            i += 1;
        }
        if !digits(&mut i) {
            return false;
        }
    }
    i == t.len()
}

/// The linear color of an 8- or 16-bit channel value, tabulated with the
/// general reader's own conversion (so the tables are its results).
fn color_table(ty: &ScalarType) -> Option<&'static [f32]> {
    static U8: OnceLock<Vec<f32>> = OnceLock::new();
    static U16: OnceLock<Vec<f32>> = OnceLock::new();
    match ty {
        ScalarType::UChar => Some(U8.get_or_init(|| {
            (0..=u8::MAX)
                .map(|v| Scalar::UChar(v).linear_color())
                .collect()
        })),
        ScalarType::UShort => Some(U16.get_or_init(|| {
            (0..=u16::MAX)
                .map(|v| Scalar::UShort(v).linear_color())
                .collect()
        })),
        _ => None,
    }
}

/// The conversions of the direct reader: positions against the origin
/// `shift` in f64; colors, 8- and 16-bit channels through the tables,
/// other types through [`Scalar::linear_color`].
struct Converter {
    tables: [Option<&'static [f32]>; 3],
    shift: DVec3,
}

impl Converter {
    fn new(fields: &Fields, shift: DVec3) -> Converter {
        Converter {
            tables: fields
                .color
                .as_ref()
                .map_or([None; 3], |c| c.each_ref().map(|f| color_table(&f.ty))),
            shift,
        }
    }

    /// Scene coordinate `axis` (0 x, 1 y, 2 z) of file value `v`.
    #[inline]
    fn coordinate(&self, axis: usize, v: Scalar) -> f32 {
        (v.value() - self.shift[axis]) as f32
    }

    /// Linear color of channel `c` (0 red, 1 green, 2 blue) of value `v`.
    fn channel(&self, c: usize, v: Scalar) -> f32 {
        match (self.tables[c], v) {
            (Some(t), Scalar::UChar(x)) => t[x as usize],
            (Some(t), Scalar::UShort(x)) => t[x as usize],
            _ => v.linear_color(),
        }
    }
}

/// A range of converted vertices: positions, colors, normals (empty when
/// the file has none).
type Part = (Vec<Vec3>, Vec<Vec3>, Vec<Vec3>);

/// The threads that convert `count` vertices: every core, at least 16,384
/// vertices each.
fn threads_for(count: usize) -> usize {
    crate::available_threads()
        .min(count.div_ceil(16_384))
        .max(1)
}

/// Converts `count` vertices on every core, in order: `convert` makes the
/// vertices of one range, None when one is not well-formed.
fn convert_all(
    count: usize,
    convert: impl Fn(std::ops::Range<usize>) -> Option<Part> + Sync,
) -> Option<Part> {
    let threads = threads_for(count);
    let chunk = count.div_ceil(threads);
    let convert = &convert;
    let parts: Vec<_> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let range = t * chunk..((t + 1) * chunk).min(count);
                scope.spawn(move || convert(range))
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().ok().flatten())
            .collect()
    });
    // The first part's vectors grow to hold the rest (a large realloc moves
    // pages, not bytes).
    let mut parts = parts.into_iter();
    let mut all = parts.next()??;
    for part in parts {
        let (p, c, n) = part?;
        all.0.extend(p);
        all.1.extend(c);
        all.2.extend(n);
    }
    Some(all)
}

/// One field of the binary records of `block` into component `axis` of
/// `out` (a slot per record), each value mapped by `map`: the type is
/// matched once, outside the loop.
fn binary_column(
    block: &[u8],
    stride: usize,
    field: &Field,
    big_endian: bool,
    out: &mut [Vec3],
    axis: usize,
    map: impl Fn(Scalar) -> f32,
) {
    macro_rules! column {
        ($variant:ident, $t:ty) => {{
            const N: usize = std::mem::size_of::<$t>();
            for (i, o) in out.iter_mut().enumerate() {
                let at = i * stride + field.at;
                let bytes: [u8; N] = block[at..at + N].try_into().expect("N bytes");
                o[axis] = map(Scalar::$variant(if big_endian {
                    <$t>::from_be_bytes(bytes)
                } else {
                    <$t>::from_le_bytes(bytes)
                }));
            }
        }};
    }
    match field.ty {
        ScalarType::Char => column!(Char, i8),
        ScalarType::UChar => column!(UChar, u8),
        ScalarType::Short => column!(Short, i16),
        ScalarType::UShort => column!(UShort, u16),
        ScalarType::Int => column!(Int, i32),
        ScalarType::UInt => column!(UInt, u32),
        ScalarType::Float => column!(Float, f32),
        ScalarType::Double => column!(Double, f64),
    }
}

/// Where one range of binary records goes: a slot per record in
/// positions and colors, and in normals when the file has them (else
/// empty).
struct Slots<'a> {
    positions: &'a mut [Vec3],
    colors: &'a mut [Vec3],
    normals: &'a mut [Vec3],
}

/// The binary records of `block`, converted column by column into `out`;
/// false when a coordinate is not finite.
fn binary_part(
    block: &[u8],
    fields: &Fields,
    converter: &Converter,
    big_endian: bool,
    out: Slots,
) -> bool {
    let stride = fields.stride;
    let columns = |out: &mut [Vec3], f: &[Field; 3], map: &dyn Fn(usize, Scalar) -> f32| {
        for (c, field) in f.iter().enumerate() {
            binary_column(block, stride, field, big_endian, out, c, |v| map(c, v));
        }
    };
    columns(out.positions, &fields.position, &|c, v| {
        converter.coordinate(c, v)
    });
    if !out.positions.iter().all(|p| p.is_finite()) {
        return false;
    }
    match &fields.color {
        Some(f) => columns(out.colors, f, &|c, v| converter.channel(c, v)),
        None => out.colors.fill(DEFAULT_COLOR),
    }
    if let Some(f) = &fields.normal {
        columns(out.normals, f, &|_, v| v.coordinate());
        for n in out.normals.iter_mut() {
            *n = unit_normal(*n);
        }
    }
    true
}

/// Converts the binary records of `block` and appends them to `cloud`
/// (whose vectors have the room), split over every core; false when a
/// coordinate is not finite.
fn append_binary(
    block: &[u8],
    fields: &Fields,
    converter: &Converter,
    big_endian: bool,
    cloud: &mut Part,
) -> bool {
    let stride = fields.stride;
    let n = block.len() / stride;
    let per_thread = n.div_ceil(threads_for(n));
    let slots = |v: &mut Vec<Vec3>, wanted: bool| -> std::ops::Range<usize> {
        let base = v.len();
        if wanted {
            v.resize(base + n, Vec3::ZERO);
        }
        base..v.len()
    };
    let (at_p, at_c) = (slots(&mut cloud.0, true), slots(&mut cloud.1, true));
    let at_n = slots(&mut cloud.2, fields.normal.is_some());
    let mut positions = &mut cloud.0[at_p];
    let mut colors = &mut cloud.1[at_c];
    let mut normals = &mut cloud.2[at_n];
    let mut block = block;
    std::thread::scope(|scope| {
        let mut handles = Vec::new();
        while !positions.is_empty() {
            let len = per_thread.min(positions.len());
            let p;
            (p, positions) = std::mem::take(&mut positions).split_at_mut(len);
            let c;
            (c, colors) = std::mem::take(&mut colors).split_at_mut(len);
            let nr;
            let len_n = len.min(normals.len());
            (nr, normals) = std::mem::take(&mut normals).split_at_mut(len_n);
            let b;
            (b, block) = block.split_at(len * stride);
            let out = Slots {
                positions: p,
                colors: c,
                normals: nr,
            };
            handles.push(scope.spawn(move || binary_part(b, fields, converter, big_endian, out)));
        }
        // Every thread joined (a panic is a decline, as a bad value is).
        let done: Vec<bool> = handles
            .into_iter()
            .map(|h| h.join().unwrap_or(false))
            .collect();
        done.into_iter().all(|ok| ok)
    })
}

/// The ASCII vertex lines `range`: each line's tokens parsed once, as the
/// general reader parses them (every token a number of its grammar, each
/// property's token of its type; the vertex element has no list, see
/// [`Fields::of`]); None when it would refuse a line.
fn ascii_part(
    lines: &[&[u8]],
    types: &[ScalarType],
    fields: &Fields,
    converter: &Converter,
    range: std::ops::Range<usize>,
) -> Option<Part> {
    let n = range.len();
    let (mut positions, mut colors) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut normals = Vec::with_capacity(if fields.normal.is_some() { n } else { 0 });
    let mut row: Vec<Scalar> = Vec::with_capacity(types.len());
    for line in &lines[range] {
        let tokens = ascii_tokens(line);
        if tokens.len() < types.len() || !tokens[types.len()..].iter().all(|t| is_ply_number(t)) {
            return None;
        }
        row.clear();
        for (token, ty) in tokens.iter().zip(types) {
            row.push(ascii_scalar(token, ty)?);
        }
        let three = |f: &[Field; 3]| f.each_ref().map(|f| row[f.at]);
        let [x, y, z] = three(&fields.position);
        let p = Vec3::new(
            converter.coordinate(0, x),
            converter.coordinate(1, y),
            converter.coordinate(2, z),
        );
        if !p.is_finite() {
            return None;
        }
        positions.push(p);
        colors.push(match &fields.color {
            Some(f) => {
                let [r, g, b] = three(f);
                Vec3::new(
                    converter.channel(0, r),
                    converter.channel(1, g),
                    converter.channel(2, b),
                )
            }
            None => DEFAULT_COLOR,
        });
        if let Some(f) = &fields.normal {
            normals.push(unit_normal(Vec3::from_array(
                three(f).map(Scalar::coordinate),
            )));
        }
    }
    Some((positions, colors, normals))
}

/// Fills `buf` from `input`: false when the file ends first.
fn read_or_end(input: &mut impl Read, buf: &mut [u8]) -> io::Result<bool> {
    match input.read_exact(buf) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => Ok(false),
        Err(e) => Err(e),
    }
}

/// Skips `n` bytes of `input`: false when the file ends first.
fn skip_or_end(input: &mut impl BufRead, mut n: u64) -> io::Result<bool> {
    while n > 0 {
        let available = match input.fill_buf() {
            Ok([]) => return Ok(false),
            Ok(b) => b.len(),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        let k = n.min(available as u64);
        input.consume(k as usize);
        n -= k;
    }
    Ok(true)
}

/// Skips one binary instance of `element`, its list counts read as the
/// general reader reads them: false when the file ends first or a count is
/// negative (or not an integer).
pub(super) fn skip_binary_element(
    input: &mut impl BufRead,
    element: &ElementDef,
    big_endian: bool,
) -> io::Result<bool> {
    for p in element.properties.values() {
        let bytes = match &p.data_type {
            PropertyType::Scalar(ty) => scalar_bytes(ty),
            PropertyType::List(count_ty, item_ty) => {
                let mut buf = [0u8; 8];
                let buf = &mut buf[..scalar_bytes(count_ty)];
                if !read_or_end(input, buf)? {
                    return Ok(false);
                }
                let count = match binary_scalar(buf, count_ty, big_endian) {
                    Scalar::Float(_) | Scalar::Double(_) => return Ok(false),
                    n => usize::try_from(n.value() as i64).ok(),
                };
                match count.and_then(|c| c.checked_mul(scalar_bytes(item_ty))) {
                    Some(bytes) => bytes,
                    None => return Ok(false),
                }
            }
        };
        if !skip_or_end(input, bytes as u64)? {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Whether an ASCII line is an instance of `element` for the general
/// reader: numbers of the grammar, each property's token(s) parsing as its
/// type, list lengths included.
fn ascii_element_ok(tokens: &[&[u8]], element: &ElementDef) -> bool {
    if !tokens.iter().all(|t| is_ply_number(t)) {
        return false;
    }
    let mut it = tokens.iter();
    for p in element.properties.values() {
        let ok = match &p.data_type {
            PropertyType::Scalar(ty) => it.next().is_some_and(|t| ascii_scalar(t, ty).is_some()),
            PropertyType::List(_, item_ty) => {
                let count = it
                    .next()
                    .and_then(|t| std::str::from_utf8(t).ok()?.parse::<usize>().ok());
                match count {
                    Some(n) => (0..n).all(|_| {
                        it.next()
                            .is_some_and(|t| ascii_scalar(t, item_ty).is_some())
                    }),
                    None => false,
                }
            }
        };
        if !ok {
            return false;
        }
    }
    true
}

/// Tokens of an ASCII line, split on spaces and tabs.
pub(super) fn ascii_tokens(line: &[u8]) -> Vec<&[u8]> {
    line.split(|&b| b == b' ' || b == b'\t')
        .filter(|t| !t.is_empty())
        .collect()
}

/// A reader that counts the bytes taken from it.
struct Counted<R> {
    inner: R,
    taken: u64,
}

impl<R: Read> Read for Counted<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.taken += n as u64;
        Ok(n)
    }
}

impl<R: BufRead> BufRead for Counted<R> {
    fn fill_buf(&mut self) -> io::Result<&[u8]> {
        self.inner.fill_buf()
    }

    fn consume(&mut self, n: usize) {
        self.taken += n as u64;
        self.inner.consume(n);
    }
}

/// Reads a binary vertex element straight from the payload, `input` (of
/// `payload_len` bytes), streamed `chunk_bytes` at a time (whole records,
/// at least one) into the cloud's vectors, against the origin of
/// [`origin_to_read_at`] for `origin`. None when the file is anything
/// but well-formed (the general reader then reads it, or says what is
/// wrong). Every element is checked as the general reader would read it,
/// those before and after the vertices too.
fn read_binary(
    input: &mut impl BufRead,
    payload_len: u64,
    header: &Header,
    vertex: &ElementDef,
    layout: &Layout,
    read_as: (usize, Option<DVec3>),
) -> io::Result<Option<PointCloud>> {
    let big_endian = matches!(header.encoding, Encoding::BinaryBigEndian);
    let Some(fields) = Fields::of(vertex, layout, true) else {
        return Ok(None);
    };
    let count = vertex.count;
    let input = &mut Counted {
        inner: input,
        taken: 0,
    };
    let mut vertices = None;
    for element in header.elements.values() {
        if element.name == vertex.name {
            // The block must lie in the file before room is made for it.
            let left = payload_len.saturating_sub(input.taken);
            match (count as u64).checked_mul(fields.stride as u64) {
                Some(bytes) if bytes <= left => {}
                _ => return Ok(None),
            }
            vertices = read_vertex_block(input, &fields, count, big_endian, read_as)?;
            if vertices.is_none() {
                return Ok(None);
            }
            continue;
        }
        if element.properties.is_empty() {
            // Instances of no bytes: nothing to walk, whatever the count.
            continue;
        }
        for _ in 0..element.count {
            if !skip_binary_element(input, element, big_endian)? {
                return Ok(None);
            }
        }
    }
    let Some(((positions, colors, normals), origin, intensities)) = vertices else {
        return Ok(None);
    };
    Ok(Some(PointCloud {
        origin,
        intensities: intensity_codes(&fields, &intensities),
        positions,
        colors,
        normals: layout.normals.then_some(normals),
        has_colors: layout.colors.is_some(),
        has_rgb: layout.colors.is_some(),
        attributes: vertex.properties.keys().cloned().collect(),
        ..PointCloud::default()
    }))
}

/// The `count` binary vertex records at the start of `input`, read
/// `chunk_bytes` at a time (whole records, at least one) and converted
/// into vectors of room for all of them, positions against the origin of
/// [`origin_to_read_at`] (returned with them, and the intensities as
/// stored); None when the file ends first or a coordinate is not finite.
fn read_vertex_block(
    input: &mut impl Read,
    fields: &Fields,
    count: usize,
    big_endian: bool,
    (chunk_bytes, origin): (usize, Option<DVec3>),
) -> io::Result<Option<(Part, DVec3, Vec<f32>)>> {
    let stride = fields.stride;
    let per_chunk = (chunk_bytes / stride).clamp(1, count.max(1));
    let mut cloud: Part = (
        Vec::with_capacity(count),
        Vec::with_capacity(count),
        Vec::with_capacity(if fields.normal.is_some() { count } else { 0 }),
    );
    let mut converter = None;
    let mut intensities = Vec::new();
    let mut buf = vec![0u8; per_chunk * stride];
    let mut done = 0;
    while done < count {
        let n = per_chunk.min(count - done);
        let block = &mut buf[..n * stride];
        if !read_or_end(input, block)? {
            return Ok(None);
        }
        // The origin once the first vertex is known.
        let converter = converter.get_or_insert_with(|| {
            let shift = origin_to_read_at(origin, fields.wide(), || {
                fields.binary_position(block, big_endian)
            });
            Converter::new(fields, shift)
        });
        if !append_binary(block, fields, converter, big_endian, &mut cloud) {
            return Ok(None);
        }
        intensities.extend(fields.binary_intensities(block, big_endian));
        done += n;
    }
    let shift = converter.map_or(DVec3::ZERO, |c| c.shift);
    Ok(Some((cloud, shift, intensities)))
}

/// Reads an ASCII vertex element straight from the payload, or None when
/// the file is anything but well-formed (the general reader then reads it,
/// or says what is wrong). Every element is checked as the general reader
/// would read it, those before and after the vertices too.
fn read_ascii(
    payload: &[u8],
    header: &Header,
    vertex: &ElementDef,
    layout: &Layout,
    origin: Option<DVec3>,
) -> Option<PointCloud> {
    let fields = Fields::of(vertex, layout, false)?;
    let count = vertex.count;
    // Lines as the general reader reads them: up to each '\n', one per
    // element instance.
    let mut rest = payload;
    let mut next_line = || -> Option<&[u8]> {
        let (line, next) = match rest.iter().position(|&b| b == b'\n') {
            Some(n) => (&rest[..n], &rest[n + 1..]),
            None if !rest.is_empty() => (rest, &rest[rest.len()..]),
            None => return None,
        };
        rest = next;
        Some(line.strip_suffix(b"\r").unwrap_or(line))
    };
    let mut vertex_lines = Vec::new();
    for element in header.elements.values() {
        if element.name == vertex.name {
            vertex_lines = (0..count)
                .map(|_| next_line())
                .collect::<Option<Vec<_>>>()?;
            continue;
        }
        for _ in 0..element.count {
            if !ascii_element_ok(&ascii_tokens(next_line()?), element) {
                return None;
            }
        }
    }
    // Every vertex property is a scalar (Fields::of checked).
    let types: Vec<ScalarType> = vertex
        .properties
        .values()
        .filter_map(|p| match &p.data_type {
            PropertyType::Scalar(ty) => Some(ty.clone()),
            PropertyType::List(..) => None,
        })
        .collect();
    let first = ascii_tokens(vertex_lines.first()?);
    let value = |f: &Field| ascii_scalar(first.get(f.at)?, &f.ty).map(Scalar::value);
    let [x, y, z] = fields.position.each_ref().map(value);
    let first = DVec3::new(x?, y?, z?);
    let shift = origin_to_read_at(origin, fields.wide(), || first);
    let converter = Converter::new(&fields, shift);
    let (positions, colors, normals) = convert_all(count, |range| {
        ascii_part(&vertex_lines, &types, &fields, &converter, range)
    })?;
    let intensities = match &fields.intensity {
        Some(f) => vertex_lines
            .iter()
            .map(|l| Some(ascii_scalar(ascii_tokens(l).get(f.at)?, &f.ty)?.value() as f32))
            .collect::<Option<Vec<f32>>>()?,
        None => Vec::new(),
    };
    Some(PointCloud {
        origin: shift,
        intensities: intensity_codes(&fields, &intensities),
        positions,
        colors,
        normals: layout.normals.then_some(normals),
        has_colors: layout.colors.is_some(),
        has_rgb: layout.colors.is_some(),
        attributes: vertex.properties.keys().cloned().collect(),
        ..PointCloud::default()
    })
}
