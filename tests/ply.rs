//! PLY input: every supported encoding and type, and malformed files.

// The test tables P, C8 and N are indexed in parallel by vertex and axis.
#![allow(clippy::needless_range_loop)]

mod common;

use std::path::{Path, PathBuf};

use common::{root, scratch};
use glam::Vec3;
use pointlens::image_io::srgb_to_linear;
use pointlens::input::ply::{
    load_ply, load_ply_direct, load_ply_direct_with_chunk, load_ply_general, load_ply_with_chunk,
    CHUNK_BYTES,
};
use pointlens::input::DEFAULT_COLOR;
use pointlens::tree::{exact_spacing, median};
use pointlens::PointCloud;

/// The three test points: positions, 8-bit sRGB colors, and normals (not unit
/// length, to check normalisation).
const P: [[f64; 3]; 3] = [[0.5, -1.25, 2.0], [1e-3, 0.0, -7.5], [-3.0, 4.0, 0.125]];
const C8: [[u8; 3]; 3] = [[255, 0, 128], [10, 200, 64], [0, 0, 0]];
const N: [[f32; 3]; 3] = [[0.0, 0.0, 2.0], [3.0, 4.0, 0.0], [0.0, 0.0, 0.0]];

#[derive(Clone, Copy, PartialEq)]
enum Enc {
    Ascii,
    Le,
    Be,
}

#[derive(Clone, Copy)]
enum ColorType {
    UChar,
    UShort,
    Float,
}

struct Spec {
    enc: Enc,
    double: bool,
    colors: Option<(ColorType, [&'static str; 3])>,
    normals: bool,
    extras: bool,
}

impl Spec {
    fn header(&self) -> String {
        let fmt = match self.enc {
            Enc::Ascii => "ascii",
            Enc::Le => "binary_little_endian",
            Enc::Be => "binary_big_endian",
        };
        let coord = if self.double { "double" } else { "float" };
        let mut h = format!("ply\nformat {fmt} 1.0\ncomment test\nelement vertex 3\n");
        for a in ["x", "y", "z"] {
            h += &format!("property {coord} {a}\n");
            if self.extras && a == "x" {
                h += "property float confidence\n";
            }
        }
        if self.normals {
            for a in ["nx", "ny", "nz"] {
                h += &format!("property float {a}\n");
            }
        }
        if let Some((t, names)) = self.colors {
            let t = match t {
                ColorType::UChar => "uchar",
                ColorType::UShort => "ushort",
                ColorType::Float => "float",
            };
            for n in names {
                h += &format!("property {t} {n}\n");
            }
            h += &format!("property {t} alpha\n");
        }
        if self.extras {
            h += "property uchar intensity\nelement face 1\nproperty list uchar int vertex_indices\n";
        }
        h + "end_header\n"
    }

    /// The channel value as stored, and the sRGB value in [0, 1] it means.
    fn color(&self, i: usize, c: usize) -> (f64, f32) {
        let v8 = C8[i][c];
        match self.colors.map(|c| c.0) {
            Some(ColorType::UShort) => {
                let v = v8 as u32 * 257;
                (v as f64, v as f32 / 65535.0)
            }
            Some(ColorType::Float) => (v8 as f64 / 255.0, v8 as f32 / 255.0),
            _ => (v8 as f64, v8 as f32 / 255.0),
        }
    }

    fn bytes(&self) -> Vec<u8> {
        let mut out = self.header().into_bytes();
        let mut ascii = String::new();
        // `put(_, "eol")` ends an ASCII line.
        let mut put = |v: f64, ty: &str| match self.enc {
            Enc::Ascii if ty == "eol" => ascii += "\n",
            Enc::Ascii => ascii += &format!("{v} "),
            _ if ty == "eol" => {}
            _ => {
                let le = self.enc == Enc::Le;
                let b: Vec<u8> = match ty {
                    "float" => {
                        if le {
                            (v as f32).to_le_bytes().to_vec()
                        } else {
                            (v as f32).to_be_bytes().to_vec()
                        }
                    }
                    "double" => {
                        if le {
                            v.to_le_bytes().to_vec()
                        } else {
                            v.to_be_bytes().to_vec()
                        }
                    }
                    "uchar" => vec![v as u8],
                    "ushort" => {
                        if le {
                            (v as u16).to_le_bytes().to_vec()
                        } else {
                            (v as u16).to_be_bytes().to_vec()
                        }
                    }
                    "int" => {
                        if le {
                            (v as i32).to_le_bytes().to_vec()
                        } else {
                            (v as i32).to_be_bytes().to_vec()
                        }
                    }
                    _ => unreachable!(),
                };
                out.extend(b);
            }
        };
        let coord = if self.double { "double" } else { "float" };
        let ctype = match self.colors.map(|c| c.0) {
            Some(ColorType::UShort) => "ushort",
            Some(ColorType::Float) => "float",
            _ => "uchar",
        };
        for i in 0..3 {
            for a in 0..3 {
                put(P[i][a], coord);
                if self.extras && a == 0 {
                    put(0.75, "float");
                }
            }
            if self.normals {
                for a in 0..3 {
                    put(N[i][a] as f64, "float");
                }
            }
            if self.colors.is_some() {
                for c in 0..3 {
                    put(self.color(i, c).0, ctype);
                }
                put(if ctype == "float" { 1.0 } else { 255.0 }, ctype);
            }
            if self.extras {
                put(7.0, "uchar");
            }
            put(0.0, "eol");
        }
        if self.extras {
            // One face: 3 vertex indices.
            put(3.0, "uchar");
            for v in 0..3 {
                put(v as f64, "int");
            }
            put(0.0, "eol");
        }
        if self.enc == Enc::Ascii {
            out.extend(ascii.into_bytes());
        }
        out
    }

    fn check(&self, cloud: &PointCloud) {
        assert_eq!(cloud.len(), 3);
        for i in 0..3 {
            let expected = Vec3::new(P[i][0] as f32, P[i][1] as f32, P[i][2] as f32);
            assert_eq!(cloud.positions[i], expected, "position {i}");
            let color = match self.colors {
                Some(_) => Vec3::from_array([0, 1, 2].map(|c| srgb_to_linear(self.color(i, c).1))),
                None => DEFAULT_COLOR,
            };
            assert!(
                (cloud.colors[i] - color).abs().max_element() < 1e-6,
                "color {i}: {} vs {color}",
                cloud.colors[i]
            );
        }
        assert_eq!(cloud.has_colors, self.colors.is_some());
        match (&cloud.normals, self.normals) {
            (Some(n), true) => {
                assert_eq!(n[0], Vec3::Z);
                assert!((n[1] - Vec3::new(0.6, 0.8, 0.0)).length() < 1e-6);
                assert_eq!(n[2], Vec3::ZERO, "a zero normal stays zero");
            }
            (None, false) => {}
            (n, want) => panic!("normals {:?}, wanted {want}", n.is_some()),
        }
        assert_eq!(
            &cloud.attributes[..3],
            &[
                "x",
                if self.extras { "confidence" } else { "y" },
                if self.extras { "y" } else { "z" }
            ]
        );
    }
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

#[test]
fn every_encoding_type_and_naming_loads_exactly() {
    let dir = scratch("ply-variants");
    let mut n = 0;
    for enc in [Enc::Ascii, Enc::Le, Enc::Be] {
        for double in [false, true] {
            for colors in [
                None,
                Some((ColorType::UChar, ["red", "green", "blue"])),
                Some((ColorType::UShort, ["r", "g", "b"])),
                Some((
                    ColorType::Float,
                    ["diffuse_red", "diffuse_green", "diffuse_blue"],
                )),
                Some((
                    ColorType::UChar,
                    ["diffuse_red", "diffuse_green", "diffuse_blue"],
                )),
            ] {
                for normals in [false, true] {
                    for extras in [false, true] {
                        let spec = Spec {
                            enc,
                            double,
                            colors,
                            normals,
                            extras,
                        };
                        let path = write(&dir, &format!("v{n}.ply"), &spec.bytes());
                        let cloud = load_ply(&path).unwrap_or_else(|e| {
                            panic!("{}: {e}\n{}", path.display(), spec.header())
                        });
                        spec.check(&cloud);
                        // The direct reader read it, and gives the general
                        // reader's cloud bit for bit.
                        let direct = load_ply_direct(&path).unwrap();
                        let general = load_ply_general(&path).unwrap();
                        assert_same(direct.as_ref().expect("read directly"), &general, &path);
                        n += 1;
                    }
                }
            }
        }
    }
    assert_eq!(n, 120);
}

/// Two clouds equal bit for bit.
fn assert_same(a: &PointCloud, b: &PointCloud, what: &Path) {
    let bits = |v: &[Vec3]| -> Vec<[u32; 3]> {
        v.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
    };
    let what = what.display();
    assert_eq!(bits(&a.positions), bits(&b.positions), "{what}: positions");
    assert_eq!(bits(&a.colors), bits(&b.colors), "{what}: colors");
    assert_eq!(
        a.normals.as_deref().map(bits),
        b.normals.as_deref().map(bits),
        "{what}: normals"
    );
    assert_eq!(a.has_colors, b.has_colors, "{what}");
    assert_eq!(a.attributes, b.attributes, "{what}");
}

#[test]
fn the_bundled_clouds_load_directly_as_the_general_reader_loads_them() {
    for name in [
        "bunny_colored.ply",
        "bun_zipper.ply",
        "pcl_table_scene_mug_rgb.ply",
    ] {
        let path = root().join("data").join(name);
        let direct = load_ply_direct(&path).unwrap();
        let general = load_ply_general(&path).unwrap();
        assert_same(direct.as_ref().expect("read directly"), &general, &path);
    }
}

#[test]
fn elements_around_the_vertices_are_walked_and_bad_data_is_left_to_the_general_reader() {
    // A list element before the vertices: walked by its counts.
    let dir = scratch("ply-declined");
    let faces_first = b"ply\nformat binary_little_endian 1.0\nelement face 1\n\
        property list uchar int vertex_indices\nelement vertex 1\n\
        property float x\nproperty float y\nproperty float z\nend_header\n";
    let mut bytes = faces_first.to_vec();
    bytes.extend([3u8]);
    for i in [0i32, 0, 0] {
        bytes.extend(i.to_le_bytes());
    }
    for v in [1.0f32, 2.0, 3.0] {
        bytes.extend(v.to_le_bytes());
    }
    let path = write(&dir, "faces-first.ply", &bytes);
    let direct = load_ply_direct(&path).unwrap().expect("read directly");
    assert_eq!(direct.positions, [Vec3::new(1.0, 2.0, 3.0)]);
    assert_same(&direct, &load_ply_general(&path).unwrap(), &path);
    // Cut inside the face list: both readers refuse it.
    let path = write(&dir, "faces-cut.ply", &bytes[..faces_first.len() + 7]);
    assert!(load_ply_direct(&path).unwrap().is_none());
    assert_error(&path, "truncated");
    // An element of no properties takes no bytes, whatever its count: the
    // direct reader skips it at once (the general one would try to hold
    // 2^64 empty rows).
    let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\n\
        property float x\nproperty float y\nproperty float z\n\
        element pad 18446744073709551615\nend_header\n"
        .to_vec();
    for v in [4.0f32, 5.0, 6.0] {
        bytes.extend(v.to_le_bytes());
    }
    let path = write(&dir, "empty-elements.ply", &bytes);
    let direct = load_ply_direct(&path).unwrap().expect("read directly");
    assert_eq!(direct.positions, [Vec3::new(4.0, 5.0, 6.0)]);
    // ".5" is not a number of the PLY grammar: both readers refuse it.
    let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n\
        property float y\nproperty float z\nend_header\n.5 1 2\n";
    let path = write(&dir, "dot-five.ply", text.as_bytes());
    assert!(load_ply_direct(&path).unwrap().is_none());
    assert_error(&path, "malformed data");
}

/// A binary PLY of `count` vertices between a face element and an edge
/// element (lists and scalars): positions double or float, normals, 16-bit
/// or 8-bit colors, an extra property; values from a fixed stream. Also
/// the vertex record's size and where the vertex block starts.
fn streamed_file(count: usize, big_endian: bool, wide: bool) -> (Vec<u8>, usize, usize) {
    let fmt = if big_endian { "big" } else { "little" };
    let (coord, color) = if wide {
        ("double", "ushort")
    } else {
        ("float", "uchar")
    };
    let mut header = format!(
        "ply\nformat binary_{fmt}_endian 1.0\nelement face 2\n\
         property list uchar int vertex_indices\nproperty uchar flags\n\
         element vertex {count}\nproperty {coord} x\nproperty float y\n\
         property {coord} z\nproperty uchar intensity\n"
    );
    if wide {
        header += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    header += &format!(
        "property {color} red\nproperty {color} green\nproperty {color} blue\n\
         element edge 3\nproperty int vertex1\nproperty list ushort float weights\n\
         end_header\n"
    );
    let mut out = header.into_bytes();
    // A value given in little-endian bytes, in the file's order.
    let put = |out: &mut Vec<u8>, le: &[u8]| {
        let start = out.len();
        out.extend(le);
        if big_endian {
            out[start..].reverse();
        }
    };
    // Faces: 3 and 4 indices, then a flag.
    for n in [3u8, 4] {
        put(&mut out, &[n]);
        for i in 0..n as i32 {
            put(&mut out, &i.to_le_bytes());
        }
        put(&mut out, &[1]);
    }
    let mut x = 0x1234_5678_9abc_def0u64;
    let mut rnd = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let value = |r: u64| (r % 2_000_001) as f64 / 1000.0 - 1000.0 + 1e-7;
    let block_at = out.len();
    for _ in 0..count {
        for axis in 0..3 {
            let v = value(rnd());
            if wide && axis != 1 {
                put(&mut out, &v.to_le_bytes());
            } else {
                put(&mut out, &(v as f32).to_le_bytes());
            }
            if axis == 2 {
                put(&mut out, &[rnd() as u8]);
            }
        }
        if wide {
            for _ in 0..3 {
                put(&mut out, &(value(rnd()) as f32 / 500.0).to_le_bytes());
            }
        }
        for _ in 0..3 {
            if wide {
                put(&mut out, &(rnd() as u16).to_le_bytes());
            } else {
                put(&mut out, &[rnd() as u8]);
            }
        }
    }
    let stride = (out.len() - block_at) / count;
    assert_eq!(stride, if wide { 8 + 4 + 8 + 1 + 12 + 6 } else { 16 });
    // Edges: an index and a list of 0, 1 or 2 weights.
    for e in 0..3u16 {
        put(&mut out, &(e as i32).to_le_bytes());
        put(&mut out, &e.to_le_bytes());
        for w in 0..e {
            put(&mut out, &(w as f32 * 0.5).to_le_bytes());
        }
    }
    (out, stride, block_at)
}

#[test]
fn binary_blocks_are_streamed_in_chunks_as_the_general_reader_reads_them() {
    let dir = scratch("ply-chunks");
    for big_endian in [false, true] {
        for wide in [false, true] {
            for count in [1, 6, 7, 8, 100, 1001] {
                let (bytes, stride, block_at) = streamed_file(count, big_endian, wide);
                let name = format!("c{count}-{big_endian}-{wide}.ply");
                let path = write(&dir, &name, &bytes);
                let general = load_ply_general(&path).unwrap();
                assert_eq!(general.len(), count);
                assert_eq!(general.normals.is_some(), wide);
                // Chunks of one record, of 7 (a boundary mid-file for odd
                // counts), of 7 and a bit (rounded down to whole records),
                // of the whole block, and the default.
                for chunk in [1, 7 * stride, 7 * stride + 5, count * stride, CHUNK_BYTES] {
                    let what = dir.join(format!("{name} in chunks of {chunk} bytes"));
                    let direct = load_ply_direct_with_chunk(&path, chunk)
                        .unwrap()
                        .expect("read directly");
                    assert_same(&direct, &general, &what);
                    assert_same(&load_ply_with_chunk(&path, chunk).unwrap(), &general, &what);
                }
                if count < 100 {
                    continue;
                }
                // Cut in the vertex block, after a few chunks: declined, and
                // the general reader says it is truncated.
                let cut = write(&dir, "cut.ply", &bytes[..block_at + 50 * stride + 3]);
                assert!(load_ply_direct_with_chunk(&cut, 7 * stride)
                    .unwrap()
                    .is_none());
                let err = load_ply_with_chunk(&cut, 7 * stride)
                    .unwrap_err()
                    .to_string();
                assert!(err.contains("truncated"), "{err}");
                // Cut in the edges after the vertices: declined too.
                let cut = write(&dir, "cut-edges.ply", &bytes[..bytes.len() - 3]);
                assert!(load_ply_direct_with_chunk(&cut, 7 * stride)
                    .unwrap()
                    .is_none());
                assert!(load_ply_with_chunk(&cut, 7 * stride).is_err());
                // A NaN in a later chunk: declined, and the general reader
                // names the vertex.
                let mut nan = bytes.clone();
                let at = block_at + 57 * stride + if wide { 8 } else { 4 };
                nan[at..at + 4].copy_from_slice(&if big_endian {
                    f32::NAN.to_be_bytes()
                } else {
                    f32::NAN.to_le_bytes()
                });
                let nan = write(&dir, "nan.ply", &nan);
                assert!(load_ply_direct_with_chunk(&nan, 7 * stride)
                    .unwrap()
                    .is_none());
                assert_error(&nan, "vertex 57 has a non-finite coordinate");
            }
        }
    }
}

#[test]
fn a_vertex_count_beyond_the_file_is_truncated_without_a_huge_allocation() {
    let dir = scratch("ply-huge-count");
    for count in ["1000000000000", "18446744073709551615"] {
        let mut bytes = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {count}\n\
             property float x\nproperty float y\nproperty float z\nend_header\n"
        )
        .into_bytes();
        for v in [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0] {
            bytes.extend(v.to_le_bytes());
        }
        let path = write(&dir, &format!("huge-{count}.ply"), &bytes);
        assert!(load_ply_direct(&path).unwrap().is_none());
        assert_error(&path, "truncated data: the header declares");
    }
}

fn assert_error(path: &Path, phrase: &str) {
    let err = load_ply(path)
        .expect_err("malformed file loaded")
        .to_string();
    let name = path.file_name().unwrap().to_string_lossy();
    assert!(err.contains(&*name), "error does not name the file: {err}");
    assert!(err.contains(phrase), "'{phrase}' not in: {err}");
    assert_eq!(err.lines().count(), 1, "not one line: {err}");
}

#[test]
fn malformed_files_are_errors_that_say_what_is_wrong() {
    let dir = scratch("ply-malformed");
    let good = Spec {
        enc: Enc::Le,
        double: false,
        colors: Some((ColorType::UChar, ["red", "green", "blue"])),
        normals: false,
        extras: false,
    };
    let ascii = Spec {
        enc: Enc::Ascii,
        ..good
    };

    assert_error(&dir.join("missing.ply"), "No such file");
    assert_error(
        &write(&dir, "magic.ply", b"PLY\nformat ascii 1.0\n"),
        "not a PLY file",
    );
    let bytes = good.bytes();
    assert_error(
        &write(&dir, "truncated.ply", &bytes[..bytes.len() - 5]),
        "truncated",
    );
    let text = String::from_utf8(ascii.bytes()).unwrap();
    let short: String = text
        .lines()
        .take(text.lines().count() - 1)
        .map(|l| format!("{l}\n"))
        .collect();
    assert_error(&write(&dir, "short.ply", short.as_bytes()), "vertices");
    assert_error(
        &write(
            &dir,
            "noz.ply",
            text.replace("property float z\n", "").as_bytes(),
        ),
        "lacks the 'z' coordinate",
    );
    assert_error(
        &write(
            &dir,
            "novertex.ply",
            text.replace("element vertex", "element point").as_bytes(),
        ),
        "no 'vertex' element",
    );
    // A NaN in binary data (ASCII "nan" is already a parse error).
    let mut nan = good.bytes();
    let at = good.header().len() + 4; // vertex 0, y
    nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    assert_error(
        &write(&dir, "nan.ply", &nan),
        "vertex 0 has a non-finite coordinate",
    );
    let ascii_nan = text.replacen("-1.25", "nan", 1);
    assert_error(
        &write(&dir, "ascii-nan.ply", ascii_nan.as_bytes()),
        "malformed data",
    );
    let empty = "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    assert_error(&write(&dir, "empty.ply", empty.as_bytes()), "empty");
    let list = "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\nproperty float y\nproperty float z\nend_header\n1 0.5 1 2\n";
    assert_error(&write(&dir, "list.ply", list.as_bytes()), "'x' is a list");
    assert_error(
        &write(
            &dir,
            "header.ply",
            b"ply\nformat ascii 1.0\nelement vertex three\n",
        ),
        "header",
    );
}

#[test]
fn garbage_and_every_truncation_never_panic() {
    let dir = scratch("ply-garbage");
    let bytes = Spec {
        enc: Enc::Be,
        double: true,
        colors: Some((ColorType::UShort, ["r", "g", "b"])),
        normals: true,
        extras: true,
    }
    .bytes();
    let path = dir.join("t.ply");
    for len in 0..bytes.len() {
        std::fs::write(&path, &bytes[..len]).unwrap();
        assert!(load_ply(&path).is_err(), "a {len}-byte prefix loaded");
    }
    // Deterministic pseudo-random bytes after a valid magic.
    let mut x = 0x2545_f491_4f6c_dd1du64;
    for _ in 0..200 {
        let mut junk = b"ply\n".to_vec();
        for _ in 0..64 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            junk.push(x as u8);
        }
        std::fs::write(&path, &junk).unwrap();
        assert!(load_ply(&path).is_err());
    }
}

#[test]
fn bundled_clouds_load() {
    let bunny = load_ply(&root().join("data/bunny_colored.ply")).unwrap();
    assert_eq!(bunny.len(), 35947);
    assert!(bunny.has_colors && bunny.normals.is_some());
    let zipper = load_ply(&root().join("data/bun_zipper.ply")).unwrap();
    assert_eq!(zipper.len(), 35947);
    assert!(!zipper.has_colors && zipper.normals.is_none());
    assert_eq!(
        zipper.attributes,
        ["x", "y", "z", "confidence", "intensity"]
    );
    // The same points in both files.
    assert_eq!(bunny.bounds(), zipper.bounds());
    let pcl = load_ply(&root().join("data/pcl_table_scene_mug_rgb.ply")).unwrap();
    assert_eq!(pcl.len(), 209_280);
}

#[test]
fn local_spacing_of_a_grid_is_the_analytic_mean() {
    // A 2D square grid of spacing h: an interior point's 8 nearest are 4 at
    // h and 4 at h·√2, so the mean is h·(1 + √2)/2.
    let h = 0.01f32;
    let positions: Vec<Vec3> = (0..40 * 40)
        .map(|i| Vec3::new((i % 40) as f32 * h, (i / 40) as f32 * h, 0.5))
        .collect();
    let cloud = PointCloud {
        colors: vec![Vec3::ONE; positions.len()],
        positions,
        ..Default::default()
    };
    let s = exact_spacing(&cloud.positions, 2);
    let expected = h * (1.0 + 2f32.sqrt()) / 2.0;
    let interior = 20 * 40 + 20;
    assert!(
        (s[interior] - expected).abs() < 1e-6,
        "{} vs {expected}",
        s[interior]
    );
    assert!((median(exact_spacing(&cloud.positions, 3)) - expected).abs() < 1e-6);
}

#[test]
fn local_spacing_equals_brute_force() {
    let mut x = 12345u64;
    let mut rnd = || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (x >> 40) as f32 / (1u64 << 24) as f32
    };
    // A thin slab (surface-like) plus a few duplicates and outliers.
    let mut positions: Vec<Vec3> = (0..2000)
        .map(|_| Vec3::new(rnd(), rnd(), rnd() * 0.01))
        .collect();
    positions.push(positions[7]);
    positions.push(positions[7]);
    positions.push(Vec3::splat(5.0));
    let cloud = PointCloud {
        colors: vec![Vec3::ONE; positions.len()],
        positions: positions.clone(),
        ..Default::default()
    };
    let fast = exact_spacing(&cloud.positions, 2);
    for (i, p) in positions.iter().enumerate() {
        let mut d: Vec<f32> = positions
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(_, q)| p.distance(*q))
            .collect();
        d.sort_by(f32::total_cmp);
        let brute = d[..8].iter().sum::<f32>() / 8.0;
        assert!(
            (fast[i] - brute).abs() <= 1e-5 * brute.max(1e-6),
            "point {i}: {} vs {brute}",
            fast[i]
        );
    }
}

/// A PLY header may say its cloud is z-up (`comment up z`, documented in
/// README): LiDAR exported to PLY then opens in the same oblique view.
#[test]
fn a_comment_says_the_cloud_is_z_up() {
    use pointlens::input::ply::says_z_up;
    for yes in ["up z", "up: z", "Up = +Z", " up   z "] {
        assert!(says_z_up(yes), "{yes}");
    }
    for no in ["up y", "z up", "upz axis", "", "made by something"] {
        assert!(!says_z_up(no), "{no}");
    }
    let dir = scratch("ply-z-up");
    let header = |comment: &str| {
        format!(
            "ply\nformat ascii 1.0\n{comment}element vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n"
        )
    };
    for (name, comment, z_up) in [
        ("plain.ply", "", false),
        ("comment.ply", "comment up z\n", true),
        ("obj-info.ply", "obj_info up: z\n", true),
        ("other.ply", "comment up y\n", false),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, header(comment)).unwrap();
        assert_eq!(load_ply(&path).unwrap().z_up, z_up, "{name}");
    }
    // Binary files too.
    let path = dir.join("binary.ply");
    let mut bytes = b"ply\nformat binary_little_endian 1.0\ncomment up z\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    bytes.extend([1.0f32, 2.0, 3.0].iter().flat_map(|v| v.to_le_bytes()));
    std::fs::write(&path, bytes).unwrap();
    assert!(load_ply(&path).unwrap().z_up);
}

/// Issue 47, defect 2: double coordinates far from zero are re-centred
/// in f64 before they become f32, by every reader (binary, ASCII, the
/// general one), on `--origin` where given and by default on the centre of
/// the bounds; `info` sees the points' true spacing. A float PLY keeps
/// the file's coordinates.
#[test]
fn double_coordinates_far_from_zero_keep_their_precision() {
    use common::{cube_points, write_binary_ply, write_double_plys};
    use glam::DVec3;
    use pointlens::input::load_cloud;
    let dir = scratch("ply-double-far");
    let points = cube_points(2_000, 1e7);
    let (binary, ascii) = write_double_plys(&dir, &points);
    let check = |cloud: &PointCloud, what: &str| {
        assert_eq!(cloud.len(), points.len(), "{what}");
        for (p, want) in cloud.positions.iter().zip(&points) {
            let got = p.as_dvec3() + cloud.origin;
            let d = (got - DVec3::from_array(*want)).abs().max_element();
            assert!(d < 1e-6, "{what}: {got} for {want:?}");
        }
        let mut xs: Vec<u32> = cloud.positions.iter().map(|p| p.x.to_bits()).collect();
        xs.sort_unstable();
        xs.dedup();
        assert!(xs.len() > 1_990, "{what}: {} distinct x", xs.len());
    };
    let given = DVec3::splat(1e7);
    for path in [&binary, &ascii] {
        let at = load_cloud(path, Some(given), &mut |_, _| {}).unwrap();
        assert_eq!(at.origin, given);
        check(&at, "--origin");
        let default = load_cloud(path, None, &mut |_, _| {}).unwrap();
        assert!(
            (default.origin - DVec3::splat(1e7 + 0.5))
                .abs()
                .max_element()
                < 0.01
        );
        check(&default, "the default origin");
    }
    check(&load_ply_general(&binary).unwrap(), "the general reader");

    let o = common::assert_runs(&[
        "info",
        binary.to_str().unwrap(),
        "--origin",
        "10000000,10000000,10000000",
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    let spacing: f64 = text
        .lines()
        .find_map(|l| l.strip_prefix("median_spacing: "))
        .unwrap()
        .parse()
        .unwrap();
    // 2,000 points in a unit cube: some 0.05 apart.
    assert!(spacing > 0.01 && spacing < 0.2, "{text}");

    // A float PLY keeps the file's coordinates (its images unchanged).
    let float = dir.join("far-float.ply");
    let float_props = [("float", "x"), ("float", "y"), ("float", "z")];
    let rows: Vec<Vec<f64>> = points.iter().map(|p| p.to_vec()).collect();
    write_binary_ply(&float, &float_props, &rows);
    let cloud = load_cloud(&float, None, &mut |_, _| {}).unwrap();
    assert_eq!(cloud.origin, DVec3::ZERO);
    assert_eq!(
        cloud.positions[0],
        Vec3::from_array(points[0].map(|v| v as f32))
    );
}

/// Issue 47, defect 9: a PLY `intensity` is read as a 16-bit intensity
/// (`IntensityScale`): 8-bit times 257, floats in [0, 1] times 65535,
/// within [0, 65535] as they are, else their range onto 0–65535.
#[test]
fn a_ply_intensity_is_read_as_16_bits() {
    use common::write_binary_ply;
    let dir = scratch("ply-intensity");
    for (ty, values, want) in [
        ("uchar", vec![0.0, 128.0, 255.0], vec![0u16, 32896, 65535]),
        ("float", vec![0.0, 0.5, 1.0], vec![0, 32768, 65535]),
        ("float", vec![0.0, 12.4, 4000.0], vec![0, 12, 4000]),
        ("float", vec![-2.0, 0.0, 2.0], vec![0, 32768, 65535]),
        ("int", vec![-10.0, 0.0, 10.0], vec![0, 32768, 65535]),
    ] {
        let props = [
            ("float", "x"),
            ("float", "y"),
            ("float", "z"),
            (ty, "intensity"),
        ];
        let rows: Vec<Vec<f64>> = values
            .iter()
            .enumerate()
            .map(|(i, &v)| vec![i as f64, 0.0, 0.0, v])
            .collect();
        let path = dir.join(format!("{ty}-{}.ply", values[2]));
        write_binary_ply(&path, &props, &rows);
        for cloud in [load_ply(&path).unwrap(), load_ply_general(&path).unwrap()] {
            assert_eq!(
                cloud.intensities.as_deref(),
                Some(&want[..]),
                "{ty} {values:?}"
            );
        }
    }
}

/// Float colours are sRGB-encoded as 8- and 16-bit codes are, and a float
/// above 1 is brighter than white: the sRGB curve extended (2 is 4.95 times
/// white), not clamped; below 0 and not a number are 0. Both readers.
#[test]
fn float_colours_above_one_are_brighter_than_white() {
    use common::write_binary_ply;
    let dir = scratch("ply-bright");
    let values = [0.5, 1.0, 2.0, 30.0, -1.0, f64::NAN];
    let props = common::XYZ_RGB_FLOATS;
    let rows: Vec<Vec<f64>> = values
        .iter()
        .enumerate()
        .map(|(i, &v)| vec![i as f64, 0.0, 0.0, v, v, 0.5])
        .collect();
    let path = dir.join("bright.ply");
    write_binary_ply(&path, &props, &rows);
    let want = [
        srgb_to_linear(0.5),
        1.0,
        ((2.0f32 + 0.055) / 1.055).powf(2.4),
        ((30.0f32 + 0.055) / 1.055).powf(2.4),
        0.0,
        0.0,
    ];
    assert!((want[2] - 4.95).abs() < 0.01, "{}", want[2]);
    for cloud in [load_ply(&path).unwrap(), load_ply_general(&path).unwrap()] {
        let got: Vec<f32> = cloud.colors.iter().map(|c| c.x).collect();
        assert_eq!(got, want);
        assert_eq!(got, cloud.colors.iter().map(|c| c.y).collect::<Vec<_>>());
        assert!(cloud.colors.iter().all(|c| c.z == srgb_to_linear(0.5)));
    }
}
