//! PLY input: ASCII and binary (either endianness), float or double
//! coordinates, 8/16-bit integer or float colors, optional normals. Faces,
//! other elements and unknown properties are ignored.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use glam::Vec3;
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, ElementDef, Property, PropertyType};

use crate::cloud::{srgb_to_linear, PointCloud, DEFAULT_COLOR};
use crate::error::{Error, Result};

/// The accepted names of the red, green and blue properties, in order of preference.
const COLOR_NAMES: [[&str; 3]; 3] = [
    ["red", "green", "blue"],
    ["r", "g", "b"],
    ["diffuse_red", "diffuse_green", "diffuse_blue"],
];

/// Loads a point cloud from a PLY file. Colors are taken as sRGB-encoded
/// values scaled to [0, 1] (by the integer type's maximum) and converted to
/// linear light; normals are normalised.
pub fn load_ply(path: &Path) -> Result<PointCloud> {
    let fail = |msg: String| Error::Ply {
        path: path.to_path_buf(),
        msg,
    };
    let bytes = std::fs::read(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    if !bytes.starts_with(b"ply\n") && !bytes.starts_with(b"ply\r\n") {
        return Err(fail("not a PLY file (it does not start with 'ply')".into()));
    }

    // Check the header before the payload so that its errors are specific.
    let parser = Parser::<DefaultElement>::new();
    let header = guarded(|| parser.read_ply_header(&mut &bytes[..]))
        .map_err(|e| fail(format!("malformed header: {e}")))?;
    let vertex = header
        .elements
        .get("vertex")
        .ok_or_else(|| fail("no 'vertex' element in the header".into()))?;
    let layout = Layout::of(vertex).map_err(fail)?;
    if vertex.count == 0 {
        return Err(fail("the cloud is empty (0 vertices)".into()));
    }

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

    let mut cloud = PointCloud {
        positions: Vec::with_capacity(rows.len()),
        colors: Vec::with_capacity(rows.len()),
        normals: layout.normals.then(|| Vec::with_capacity(rows.len())),
        has_colors: layout.colors.is_some(),
        attributes: vertex.properties.keys().cloned().collect(),
    };
    for (i, row) in rows.iter().enumerate() {
        let get = |name: &str| row.get(name).and_then(scalar).unwrap_or(0.0);
        let p = Vec3::new(get("x") as f32, get("y") as f32, get("z") as f32);
        if !p.is_finite() {
            return Err(fail(format!(
                "vertex {i} has a non-finite coordinate ({p})"
            )));
        }
        cloud.positions.push(p);
        let color = match &layout.colors {
            Some(names) => Vec3::from_array(names.each_ref().map(|n| {
                let v = row.get(*n).map(normalised_color).unwrap_or(0.0);
                srgb_to_linear(v.clamp(0.0, 1.0))
            })),
            None => DEFAULT_COLOR,
        };
        cloud.colors.push(color);
        if let Some(normals) = cloud.normals.as_mut() {
            let n = Vec3::new(get("nx") as f32, get("ny") as f32, get("nz") as f32);
            normals.push(n.try_normalize().unwrap_or(Vec3::ZERO));
        }
    }
    Ok(cloud)
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

/// A scalar property as f64 (None for a list).
fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v,
        _ => return None,
    })
}

/// A color channel scaled to [0, 1]: integers by their type's maximum,
/// floats as they are.
fn normalised_color(p: &Property) -> f32 {
    let max = match p {
        Property::Char(_) => i8::MAX as f64,
        Property::UChar(_) => u8::MAX as f64,
        Property::Short(_) => i16::MAX as f64,
        Property::UShort(_) => u16::MAX as f64,
        Property::Int(_) => i32::MAX as f64,
        Property::UInt(_) => u32::MAX as f64,
        _ => 1.0,
    };
    (scalar(p).unwrap_or(0.0) / max) as f32
}
