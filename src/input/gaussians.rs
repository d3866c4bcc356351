//! Trained 3D Gaussian Splatting scenes (issue 31, item 1): the PLY layout
//! of Kerbl et al. 2023's reference code, detected by its properties —
//! `x y z` (optional `nx ny nz`, unused), `f_dc_0..2`, `f_rest_0..` (SH
//! degree 1–3: 9, 24 or 45 of them, stored channel-major), `opacity`,
//! `scale_0..2`, `rot_0..3` — with the reference code's activations: exp
//! of the scales, sigmoid of the opacity, the quaternion (r, x, y, z)
//! normalised. docs/ARCHITECTURE.md, "3D Gaussian scenes".

use std::path::Path;

use glam::{Quat, Vec3};
use ply_rs_bw::ply::{ElementDef, Encoding, Header, PropertyType};

use super::ply::{
    ascii_scalar, ascii_tokens, binary_scalar, open_ply, ply_error, read_file, read_header,
    scalar_bytes, skip_binary_element, Opened,
};
use crate::error::Result;

/// The most a stored log-scale may be: its square (a covariance's entry)
/// still fits f32 (e^88 is f32's largest power of e).
pub const MAX_LOG_SCALE: f32 = 44.0;

/// A scene of 3D Gaussians, activated.
#[derive(Debug, Clone, Default)]
pub struct GaussianScene {
    /// Centres, in the file's coordinates.
    pub positions: Vec<Vec3>,
    /// Standard deviations along the Gaussian's own axes: exp(scale_k).
    pub scales: Vec<Vec3>,
    /// Unit rotations of those axes: (rot_0 = w, rot_1..3 = x, y, z),
    /// normalised.
    pub rotations: Vec<Quat>,
    /// Peak opacities in (0, 1): sigmoid(opacity).
    pub opacities: Vec<f32>,
    /// Spherical-harmonics degree, 0–3.
    pub sh_degree: u32,
    /// Each Gaussian's (degree + 1)² SH coefficients of red, green, blue:
    /// coefficient k of channel c at `[g * n * 3 + k * 3 + c]` (n =
    /// [`GaussianScene::coefficients`]), the DC term first.
    pub sh: Vec<f32>,
}

impl GaussianScene {
    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the scene has no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// SH coefficients a channel: (degree + 1)².
    pub fn coefficients(&self) -> usize {
        ((self.sh_degree + 1) * (self.sh_degree + 1)) as usize
    }

    /// Gaussian `g`'s coefficients, `[k][channel]`.
    pub fn sh_of(&self, g: usize) -> &[f32] {
        let n = self.coefficients() * 3;
        &self.sh[g * n..(g + 1) * n]
    }
}

/// Whether a PLY header's vertices are 3D Gaussians: they have properties
/// of at least two of the families `f_dc_*`, `opacity`, `scale_*` and
/// `rot_*`. Every property is checked when read, so a file with some but
/// not all of them is a broken Gaussian file, refused naming what it lacks
/// (one family alone, an `opacity` of a point cloud, is not Gaussian).
pub fn is_gaussian_header(header: &Header) -> bool {
    header.elements.get("vertex").is_some_and(|v| {
        let family = |prefix: &str| v.properties.keys().any(|p| p.starts_with(prefix));
        let families = ["f_dc_", "opacity", "scale_", "rot_"];
        families.iter().filter(|f| family(f)).count() >= 2
    })
}

/// Whether the PLY file at `path` holds 3D Gaussians (its header read
/// alone); false for what is not a regular PLY file.
pub fn is_gaussian_file(path: &Path) -> bool {
    matches!(
        open_ply(path, 64 << 10),
        Ok(Opened::Regular { header, .. }) if is_gaussian_header(&header)
    )
}

/// SH degree of a vertex with `rest` `f_rest_*` properties.
fn sh_degree(rest: usize) -> Option<u32> {
    match rest {
        0 => Some(0),
        9 => Some(1),
        24 => Some(2),
        45 => Some(3),
        _ => None,
    }
}

/// The properties a Gaussian of the reference layout has, in its order,
/// with `rest` `f_rest_*` (the optional `nx ny nz` left out).
pub fn property_names(rest: usize) -> Vec<String> {
    let mut names: Vec<String> = ["x", "y", "z"].map(String::from).to_vec();
    names.extend((0..3).map(|c| format!("f_dc_{c}")));
    names.extend((0..rest).map(|k| format!("f_rest_{k}")));
    names.push("opacity".into());
    names.extend((0..3).map(|c| format!("scale_{c}")));
    names.extend((0..4).map(|c| format!("rot_{c}")));
    names
}

/// Host bytes a Gaussian takes while `render` reads and uploads the scene
/// beyond twice its file record (the file is read whole, and the SH it
/// holds are copied): the read scene's centre, scale, rotation and
/// opacity (44 B), the upload's record (48 B) and the centres kept for
/// each frame's depth range (12 B). Measured: 606 MB peak for 10^6
/// Gaussians of degree 3 (248 MB of records), which this gives as 600 MB.
pub const RENDER_BYTES_PER_GAUSSIAN: u64 = 104;

/// Refuses, in one line, a Gaussian scene whose reading and upload would
/// take more than `memory_mb` MiB: twice its payload plus
/// [`RENDER_BYTES_PER_GAUSSIAN`] a Gaussian (a pipe is not checked).
pub fn check_fits(path: &Path, memory_mb: u64) -> Result<()> {
    let Some((count, _, payload_len)) = super::ply::declared_points(path)? else {
        return Ok(());
    };
    let needed = payload_len
        .saturating_mul(2)
        .saturating_add(count.saturating_mul(RENDER_BYTES_PER_GAUSSIAN));
    if needed <= memory_mb.saturating_mul(1 << 20) {
        return Ok(());
    }
    Err(crate::error::Error::InvalidArgument(format!(
        "{}: {count} Gaussians need about {} MiB, more than --memory-mb {memory_mb}",
        path.display(),
        needed.div_ceil(1 << 20)
    )))
}

/// Reads the 3D Gaussians of the PLY file at `path` (binary or ASCII,
/// read whole). Missing properties, a count of `f_rest_*` that is no SH
/// degree, a value that is not finite, a quaternion of zeros, a log-scale
/// over [`MAX_LOG_SCALE`] and a truncated file are each one line.
pub fn load_gaussians(path: &Path) -> Result<GaussianScene> {
    let fail = |msg: String| ply_error(path, msg);
    let bytes = read_file(path)?;
    let (header, payload_at) = read_header(&bytes, path)?;
    let vertex = header
        .elements
        .get("vertex")
        .ok_or_else(|| fail("no 'vertex' element in the header".into()))?;
    let binary = !matches!(header.encoding, Encoding::Ascii);
    let layout = VertexLayout::of(vertex, binary, path)?;

    // The records, after the elements before the vertices.
    let payload = &bytes[payload_at..];
    let mut scene = GaussianScene {
        sh_degree: layout.sh_degree,
        ..GaussianScene::default()
    };
    let mut read_one =
        |g: usize, values: &[f32]| push_gaussian(&mut scene, g, values, &layout, path);
    if binary {
        read_binary(&header, payload, &layout, path, &mut read_one)?;
    } else {
        read_ascii(&header, payload, &layout, path, &mut read_one)?;
    }
    if scene.is_empty() {
        return Err(fail("the scene is empty (0 Gaussians)".into()));
    }
    Ok(scene)
}

/// Where a Gaussian's values lie in a vertex record, checked against the
/// reference layout.
struct VertexLayout {
    /// Gaussians the header declares.
    count: usize,
    /// A record's bytes (binary) or tokens (ASCII).
    stride: usize,
    /// `f_rest_*` properties.
    rest: usize,
    sh_degree: u32,
    /// The properties read, in [`property_names`]' order.
    names: Vec<String>,
    /// Each of `names`' byte offset (binary) or token (ASCII), and type.
    fields: Vec<(usize, ply_rs_bw::ply::ScalarType)>,
}

impl VertexLayout {
    /// The layout of `vertex`'s properties (`binary` or ASCII records):
    /// scalars only, an SH degree's count of `f_rest_*` in a row, and
    /// every property of [`property_names`]; errors name `path`.
    fn of(vertex: &ElementDef, binary: bool, path: &Path) -> Result<VertexLayout> {
        let fail = |msg: String| ply_error(path, msg);
        // Every property's place: byte offset (binary) or token (ASCII).
        let mut places = std::collections::HashMap::new();
        let mut at = 0;
        for (name, p) in &vertex.properties {
            let PropertyType::Scalar(ty) = &p.data_type else {
                return Err(fail(format!(
                    "the vertex property '{name}' is a list: 3D Gaussians have scalars only"
                )));
            };
            places.insert(name.as_str(), (at, ty.clone()));
            at += if binary { scalar_bytes(ty) } else { 1 };
        }
        let stride = at;
        let rest = (0..)
            .take_while(|k| places.contains_key(format!("f_rest_{k}").as_str()))
            .count();
        let extra = vertex
            .properties
            .keys()
            .filter(|n| n.starts_with("f_rest_"))
            .count();
        let sh_degree = match (sh_degree(rest), rest == extra) {
            (Some(d), true) => d,
            _ => {
                return Err(fail(format!(
                    "{extra} f_rest_* properties (f_rest_0 to f_rest_{} in a row): SH degrees \
                     1, 2 and 3 have 9, 24 and 45",
                    rest.max(1) - 1
                )))
            }
        };
        let names = property_names(rest);
        let missing: Vec<&str> = names
            .iter()
            .map(String::as_str)
            .filter(|n| !places.contains_key(n))
            .collect();
        if !missing.is_empty() {
            return Err(fail(format!(
                "3D Gaussians without the properties {}",
                missing.join(", ")
            )));
        }
        let fields = names.iter().map(|n| places[n.as_str()].clone()).collect();
        Ok(VertexLayout {
            count: vertex.count,
            stride,
            rest,
            sh_degree,
            names,
            fields,
        })
    }
}

/// Activates Gaussian `g`'s `values` (in `layout.names`' order) and adds
/// it to `scene`: a value that is not finite, a log-scale over
/// [`MAX_LOG_SCALE`] and a rotation of zeros are errors naming `path`.
fn push_gaussian(
    scene: &mut GaussianScene,
    g: usize,
    values: &[f32],
    layout: &VertexLayout,
    path: &Path,
) -> Result<()> {
    let fail = |msg: String| ply_error(path, msg);
    let (names, rest) = (&layout.names, layout.rest);
    let k_per_channel = rest / 3;
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(fail(format!(
            "Gaussian {g}: {} is {} (not finite)",
            names[i], values[i]
        )));
    }
    let v = |name_at: usize| values[name_at];
    scene.positions.push(Vec3::new(v(0), v(1), v(2)));
    let dc = 6 + rest;
    // Opacity, scales, rotation after the SH.
    let (o, s, r) = (dc, dc + 1, dc + 4);
    if let Some(k) = (0..3).find(|&k| v(s + k) > MAX_LOG_SCALE) {
        return Err(fail(format!(
            "Gaussian {g}: scale_{k} = {} overflows once activated (exp) and squared; \
             at most {MAX_LOG_SCALE}",
            v(s + k)
        )));
    }
    scene
        .scales
        .push(Vec3::new(v(s).exp(), v(s + 1).exp(), v(s + 2).exp()));
    let q = Quat::from_xyzw(v(r + 1), v(r + 2), v(r + 3), v(r));
    if q.length_squared() == 0.0 {
        return Err(fail(format!(
            "Gaussian {g}: its rotation rot_0..3 is all zeros"
        )));
    }
    scene.rotations.push(q.normalize());
    scene.opacities.push(1.0 / (1.0 + (-v(o)).exp()));
    // DC, then the rest, each [k][channel]; f_rest is channel-major.
    scene.sh.extend_from_slice(&values[3..6]);
    for k in 0..k_per_channel {
        for c in 0..3 {
            scene.sh.push(v(6 + c * k_per_channel + k));
        }
    }
    Ok(())
}

/// Reads the binary `payload`'s Gaussians (after the elements before the
/// vertices), handing each one's index and values to `read_one`; a
/// truncated file is an error naming `path`.
fn read_binary(
    header: &Header,
    payload: &[u8],
    layout: &VertexLayout,
    path: &Path,
    read_one: &mut dyn FnMut(usize, &[f32]) -> Result<()>,
) -> Result<()> {
    let fail = |msg: String| ply_error(path, msg);
    let (count, stride) = (layout.count, layout.stride);
    let mut values = vec![0f32; layout.names.len()];
    let big_endian = matches!(header.encoding, Encoding::BinaryBigEndian);
    let mut input = std::io::Cursor::new(payload);
    for element in header.elements.values() {
        if element.name == "vertex" {
            break;
        }
        if element.properties.is_empty() {
            continue;
        }
        for _ in 0..element.count {
            if !skip_binary_element(&mut input, element, big_endian)
                .map_err(|e| fail(e.to_string()))?
            {
                return Err(fail(format!("truncated: the '{}' element", element.name)));
            }
        }
    }
    let start = input.position() as usize;
    let block = &payload[start..];
    match count.checked_mul(stride) {
        Some(n) if n <= block.len() => {}
        _ => {
            return Err(fail(format!(
                "truncated: the header declares {count} Gaussians of {stride} bytes, the \
                 file holds {} bytes of them",
                block.len()
            )))
        }
    }
    for (g, record) in block.chunks_exact(stride).take(count).enumerate() {
        for (v, (at, ty)) in values.iter_mut().zip(&layout.fields) {
            *v = binary_scalar(&record[*at..], ty, big_endian).value() as f32;
        }
        read_one(g, &values)?;
    }
    Ok(())
}

/// Reads the ASCII `payload`'s Gaussians (after the lines of the elements
/// before the vertices), a line each, handing each one's index and values
/// to `read_one`; a missing line, a line of another length and a token
/// that is no number are errors naming `path`.
fn read_ascii(
    header: &Header,
    payload: &[u8],
    layout: &VertexLayout,
    path: &Path,
    read_one: &mut dyn FnMut(usize, &[f32]) -> Result<()>,
) -> Result<()> {
    let fail = |msg: String| ply_error(path, msg);
    let (count, stride) = (layout.count, layout.stride);
    let mut values = vec![0f32; layout.names.len()];
    let mut lines = payload
        .split(|&b| b == b'\n')
        .map(|l| l.strip_suffix(b"\r").unwrap_or(l));
    for element in header.elements.values() {
        if element.name == "vertex" {
            break;
        }
        for _ in 0..element.count {
            lines.next();
        }
    }
    for g in 0..count {
        let line = lines.next().ok_or_else(|| {
            fail(format!(
                "truncated: the header declares {count} Gaussians, the file holds {g}"
            ))
        })?;
        let tokens = ascii_tokens(line);
        if tokens.len() != stride {
            return Err(fail(format!(
                "Gaussian {g}: {} values on its line, {stride} properties declared",
                tokens.len()
            )));
        }
        for ((v, (at, ty)), name) in values.iter_mut().zip(&layout.fields).zip(&layout.names) {
            *v = ascii_scalar(tokens[*at], ty)
                .ok_or_else(|| {
                    fail(format!(
                        "Gaussian {g}: {name} is '{}', not a number of its type",
                        String::from_utf8_lossy(tokens[*at])
                    ))
                })?
                .value() as f32;
        }
        read_one(g, &values)?;
    }
    Ok(())
}
