//! `pointlens convert` (issue 30, item 2; docs/ARCHITECTURE.md,
//! "Converting to COPC"): the COPC it writes holds the input's points
//! unchanged, in an octree whose nodes hold their cubes' points, read back
//! by pointlens node by node (an independent reader: scripts/check-copc).

mod common;

use std::path::Path;

use common::{assert_fails, assert_runs, pointlens, root, scratch};
use pointlens::convert::{GRID_CELLS, MAX_NODE_POINTS};
use pointlens::input::copc::CopcFile;
use pointlens::input::las::load_las;
use pointlens::PointCloud;

fn convert(input: &Path, output: &Path) {
    assert_runs(&[
        "convert",
        input.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
    ]);
}

/// `convert` with parts of at most `part_points` points.
fn convert_in_parts(input: &Path, output: &Path, part_points: u64) {
    convert_in_parts_on(input, output, part_points, None)
}

/// As [`convert_in_parts`], on `threads` threads where given.
fn convert_in_parts_on(input: &Path, output: &Path, part_points: u64, threads: Option<usize>) {
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_pointlens"));
    if let Some(t) = threads {
        command.env("POINTLENS_CONVERT_THREADS", t.to_string());
    }
    let o = command
        .args([
            "convert",
            input.to_str().unwrap(),
            "-o",
            output.to_str().unwrap(),
        ])
        .env("POINTLENS_CONVERT_PART_POINTS", part_points.to_string())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Everything a point holds: position and color bits, intensity, class,
/// return.
type PointTuple = ([u32; 3], [u32; 3], u16, u8, u8);

/// A cloud's points as sorted tuples of everything it holds.
fn multiset(c: &PointCloud) -> Vec<PointTuple> {
    let mut v: Vec<_> = (0..c.len())
        .map(|i| {
            (
                c.positions[i].to_array().map(f32::to_bits),
                c.colors[i].to_array().map(f32::to_bits),
                c.intensities.as_ref().unwrap()[i],
                c.classifications.as_ref().unwrap()[i],
                c.returns.as_ref().unwrap()[i],
            )
        })
        .collect();
    v.sort_unstable();
    v
}

/// The LiDAR tile converted in one part and in parts of 5,000 points (the
/// out-of-core path: parts split until small enough, built apart, the
/// levels above them sampled from their nodes' points).
#[test]
fn a_las_file_converts_to_the_same_points_in_an_octree() {
    let dir = scratch("convert-las");
    let input = root().join("data/autzen_trim.las");
    let whole = dir.path().join("autzen.copc.laz");
    convert(&input, &whole);
    check_octree(&input, &whole, true);
    let parts = dir.path().join("autzen-parts.copc.laz");
    convert_in_parts(&input, &parts, 5_000);
    let levels = check_octree(&input, &parts, false);
    assert!(
        levels >= 4,
        "parts of 5,000 points make a deeper tree: {levels} levels"
    );
    // Parts finish in any order on several threads; the file is the same.
    let one_core = dir.path().join("autzen-one-core.copc.laz");
    convert_in_parts_on(&input, &one_core, 5_000, Some(1));
    let three = dir.path().join("autzen-three.copc.laz");
    convert_in_parts_on(&input, &three, 5_000, Some(3));
    assert!(
        std::fs::read(&three).unwrap() == std::fs::read(&one_core).unwrap(),
        "the file written by three threads differs from one thread's"
    );
    std::fs::remove_file(&three).unwrap();
    std::fs::remove_file(&one_core).unwrap();
    assert_eq!(
        common::file_names(dir.path()),
        ["autzen-parts.copc.laz", "autzen.copc.laz"],
        "no part left behind"
    );
}

/// The converted file holds the input's points (positions bit for bit,
/// colors, intensities, classes, returns), in nodes that hold their cubes'
/// points, each above the leaves sampled on a 128³ grid, a point in every
/// cell its subtree occupies (with its ancestors' unless `top_down`);
/// returns its levels.
fn check_octree(input: &Path, output: &Path, top_down: bool) -> i32 {
    let output = output.to_path_buf();
    let original = load_las(input, None, &mut |_, _| {}).unwrap();
    let converted = load_las(&output, None, &mut |_, _| {}).unwrap();
    assert_eq!(original.origin, converted.origin);
    assert!(
        multiset(&original) == multiset(&converted),
        "the points differ"
    );

    let header = las::Reader::from_path(&output).unwrap().header().clone();
    let transforms = *header.transforms();
    let copc = CopcFile::open(&output, header).unwrap();
    let nodes = copc.all_nodes().unwrap();
    assert!(nodes.len() > 1, "an octree: {} nodes", nodes.len());
    assert_eq!(nodes.iter().map(|n| n.point_count).sum::<u64>(), 110_000);
    // Every point with its node, for the samples' completeness below.
    let mut all: Vec<(pointlens::input::copc::NodeKey, glam::DVec3)> = Vec::new();
    for node in &nodes {
        let data = copc.read_node(node).unwrap();
        for ((x, y), z) in data.x().zip(data.y()).zip(data.z()) {
            all.push((node.key, glam::DVec3::new(x, y, z)));
        }
    }
    let cell_of = |p: glam::DVec3, min: glam::DVec3, cell: f64| {
        let c = ((p - min) / cell).floor();
        let last = f64::from(GRID_CELLS - 1);
        [c.x, c.y, c.z].map(|v| v.clamp(0.0, last) as i64)
    };
    for node in &nodes {
        let (min, width) = copc.info.cube(node.key);
        let data = copc.read_node(node).unwrap();
        assert_eq!(data.len() as u64, node.point_count);
        let slack = transforms.x.scale;
        for ((x, y), z) in data.x().zip(data.y()).zip(data.z()) {
            let p = glam::DVec3::new(x, y, z);
            assert!(
                (p - min).min_element() >= -slack && (p - min - width).max_element() <= slack,
                "node {:?} holds {p:?}, outside its cube",
                node.key
            );
        }
        let inner = nodes.iter().any(|c| {
            c.key.level == node.key.level + 1 && {
                let d = c.key.level - node.key.level;
                (c.key.x >> d, c.key.y >> d, c.key.z >> d) == (node.key.x, node.key.y, node.key.z)
            }
        });
        if inner {
            // One point per occupied cell of its 128³ grid.
            let cell = width / f64::from(GRID_CELLS);
            let mut cells: Vec<[i64; 3]> = data
                .x()
                .zip(data.y())
                .zip(data.z())
                .map(|((x, y), z)| {
                    let c = (glam::DVec3::new(x, y, z) - min) / cell;
                    [c.x.floor() as i64, c.y.floor() as i64, c.z.floor() as i64]
                })
                .collect();
            cells.sort_unstable();
            let n = cells.len();
            cells.dedup();
            assert_eq!(
                cells.len(),
                n,
                "node {:?}: two points in one cell",
                node.key
            );
            // And, with its ancestors, a point in every cell its
            // subtree's points occupy: top down (a part, or the whole in
            // memory) the node alone has one; bottom up (above the parts)
            // a cell's point may have gone to an ancestor.
            let within = |k: &pointlens::input::copc::NodeKey,
                          of: &pointlens::input::copc::NodeKey| {
                let d = k.level - of.level;
                d >= 0 && (k.x >> d, k.y >> d, k.z >> d) == (of.x, of.y, of.z)
            };
            let cells_of = |keep: &dyn Fn(&pointlens::input::copc::NodeKey) -> bool| {
                let mut c: Vec<[i64; 3]> = all
                    .iter()
                    .filter(|(k, p)| {
                        keep(k)
                            && (*p - min).min_element() >= -slack
                            && (*p - min - width).max_element() <= slack
                    })
                    .map(|(_, p)| cell_of(*p, min, cell))
                    .collect();
                c.sort_unstable();
                c.dedup();
                c
            };
            let occupied = cells_of(&|k| within(k, &node.key));
            let covered = match top_down {
                true => cells_of(&|k| *k == node.key),
                false => cells_of(&|k| within(&node.key, k)),
            };
            let missing = occupied
                .iter()
                .filter(|c| covered.binary_search(c).is_err())
                .count();
            assert_eq!(
                missing,
                0,
                "node {:?}: {missing} of {} occupied cells without a point in it or above",
                node.key,
                occupied.len()
            );
        } else {
            assert!(node.point_count as usize <= MAX_NODE_POINTS);
        }
    }
    assert!((copc.info.spacing - 2.0 * copc.info.halfsize / f64::from(GRID_CELLS)).abs() < 1e-9);
    nodes.iter().map(|n| n.key.level).max().unwrap() + 1
}

/// A PLY cloud converts on a grid fine enough for its f32 positions, with
/// its colors as 16-bit sRGB; `render` takes the result by node.
#[test]
fn a_ply_cloud_converts_and_renders() {
    let dir = scratch("convert-ply");
    let input = root().join("data/bunny_colored.ply");
    let output = dir.path().join("bunny.copc.laz");
    convert(&input, &output);
    let original = pointlens::input::ply::load_ply(&input).unwrap();
    let converted = load_las(&output, None, &mut |_, _| {}).unwrap();
    assert_eq!(converted.len(), original.len());
    let (lo, hi) = original.bounds();
    let extent = f64::from((hi - lo).max_element());
    // Every converted point within a millionth of the extent of an
    // original point (the grid is 10⁻⁷ of it; f32 rounds at 6·10⁻⁸),
    // with that point's color within the 16-bit sRGB codes' rounding.
    let cell = 1e-6 * extent;
    let key = |p: glam::DVec3| (p / cell).floor().as_i64vec3().to_array();
    let mut grid = std::collections::HashMap::new();
    for (p, c) in original.positions.iter().zip(&original.colors) {
        grid.entry(key(p.as_dvec3() + original.origin))
            .or_insert_with(Vec::new)
            .push((p.as_dvec3() + original.origin, *c));
    }
    let mut worst = (0.0f64, 0.0f32);
    for (p, c) in converted.positions.iter().zip(&converted.colors) {
        let p = p.as_dvec3() + converted.origin;
        let k = key(p);
        let mut best: Option<(f64, f32)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    for (q, qc) in grid
                        .get(&[k[0] + dx, k[1] + dy, k[2] + dz])
                        .into_iter()
                        .flatten()
                    {
                        let d = (p - *q).length();
                        let e = (*c - *qc).abs().max_element();
                        if best.is_none_or(|b| d < b.0) {
                            best = Some((d, e));
                        }
                    }
                }
            }
        }
        let (d, e) = best.unwrap_or_else(|| panic!("no original point near {p:?}"));
        worst = (worst.0.max(d), worst.1.max(e));
    }
    assert!(worst.0 <= cell, "a point moved by {}", worst.0);
    assert!(worst.1 < 1e-3, "a color moved by {}", worst.1);

    // The file streamed in parts (out of core), and read whole from a
    // pipe (the in-memory path): the same points.
    let parts = dir.path().join("bunny-parts.copc.laz");
    convert_in_parts(&input, &parts, 2_000);
    let piped = dir.path().join("bunny-piped.copc.laz");
    // A pipe (not the file as stdin, which /dev/stdin would reopen).
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_pointlens"))
        .args(["convert", "/dev/stdin", "-o", piped.to_str().unwrap()])
        .stdin(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let bytes = std::fs::read(&input).unwrap();
    let feeder = std::thread::spawn(move || {
        use std::io::Write;
        stdin.write_all(&bytes).unwrap();
    });
    let o = child.wait_with_output().unwrap();
    feeder.join().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let read = |p: &Path| load_las(p, None, &mut |_, _| {}).unwrap();
    let in_parts = read(&parts);
    assert_eq!(multiset(&in_parts), multiset(&converted));
    assert_eq!(multiset(&read(&piped)), multiset(&converted));
    let header = las::Reader::from_path(&parts).unwrap().header().clone();
    let parts_levels = CopcFile::open(&parts, header)
        .unwrap()
        .all_nodes()
        .unwrap()
        .iter()
        .map(|n| n.key.level)
        .max();
    assert!(parts_levels >= Some(2), "parts of 2,000: {parts_levels:?}");

    let image = dir.path().join("bunny.png");
    let o = pointlens(&[
        "render",
        output.to_str().unwrap(),
        "-o",
        image.to_str().unwrap(),
        "--width",
        "64",
        "--height",
        "48",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// What `convert` refuses, in one line and without a file.
#[test]
fn convert_refuses_in_one_line() {
    let dir = scratch("convert-bad");
    let input = root().join("data/autzen_trim.las");
    let i = input.to_str().unwrap();
    let laz = dir.path().join("out.laz");
    assert_fails(
        &["convert", i, "-o", laz.to_str().unwrap()],
        ".copc.laz",
        &laz,
    );
    let missing = dir.path().join("none.las");
    let out = dir.path().join("out.copc.laz");
    assert_fails(
        &[
            "convert",
            missing.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ],
        "none.las",
        &out,
    );
    let bad = dir.path().join("bad.las");
    std::fs::write(&bad, b"LASF but not much else").unwrap();
    assert_fails(
        &[
            "convert",
            bad.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ],
        "bad.las",
        &out,
    );
    let nowhere = dir.path().join("no/such/dir/out.copc.laz");
    assert_fails(
        &["convert", i, "-o", nowhere.to_str().unwrap()],
        "-o",
        &nowhere,
    );
}

/// A PLY or LAS file whose points read whole would exceed `--memory-mb`
/// is refused in one line with the `convert` command that makes it COPC
/// (issue 30, item 3); that command works, and its COPC renders within
/// the same `--memory-mb`.
#[test]
fn a_cloud_over_memory_mb_is_refused_with_the_convert_command() {
    let dir = scratch("convert-memory");
    let out = dir.path().join("frame.png");
    let o = out.to_str().unwrap();
    // The bunny (35,947 points of ASCII) needs about 6 MiB read whole: its
    // text, then the cloud.
    let bunny = root().join("data/bun_zipper.ply");
    let b = bunny.to_str().unwrap();
    assert_fails(
        &["render", b, "-o", o, "--memory-mb", "1"],
        "more than --memory-mb 1; convert it to COPC",
        &out,
    );
    // `convert` streams a binary PLY file; an ASCII one it reads whole,
    // within --memory-mb too.
    let bunny_copc = dir.path().join("bunny.copc.laz");
    assert_fails(
        &[
            "convert",
            b,
            "-o",
            bunny_copc.to_str().unwrap(),
            "--memory-mb",
            "1",
        ],
        "more than --memory-mb 1; convert streams only a regular binary PLY",
        &bunny_copc,
    );
    // The tile (110,000 points, about 6 MiB): the command the line gives,
    // run as given.
    let tile = dir.path().join("autzen.las");
    std::fs::copy(root().join("data/autzen_trim.las"), &tile).unwrap();
    let t = tile.to_str().unwrap();
    let refused = pointlens(&["render", t, "-o", o, "--memory-mb", "5", "--width", "64"]);
    assert!(!refused.status.success());
    let line = String::from_utf8_lossy(&refused.stderr)
        .trim_end()
        .to_string();
    assert_eq!(line.lines().count(), 1, "{line}");
    let command = line
        .split("pointlens convert ")
        .nth(1)
        .unwrap_or_else(|| panic!("no command in: {line}"));
    let args: Vec<&str> = std::iter::once("convert")
        .chain(command.split(' '))
        .collect();
    assert_eq!(args.len(), 4, "convert IN -o OUT: {args:?}");
    assert_runs(&args);
    let copc = dir.path().join("autzen.copc.laz");
    assert_eq!(args[3], copc.to_str().unwrap());
    assert_runs(&[
        "render",
        copc.to_str().unwrap(),
        "-o",
        o,
        "--memory-mb",
        "5",
        "--width",
        "64",
        "--height",
        "48",
    ]);
    assert!(out.exists());
    // `info` reads every point, of a COPC file too (and writes nothing).
    let none = dir.path().join("none");
    assert_fails(
        &["info", t, "--memory-mb", "5"],
        "more than --memory-mb 5; convert it to COPC",
        &none,
    );
    assert_fails(
        &["info", copc.to_str().unwrap(), "--memory-mb", "5"],
        "more than --memory-mb 5; render reads a COPC file by node",
        &none,
    );
    assert_runs(&["info", copc.to_str().unwrap(), "--memory-mb", "7"]);
    // Within the limit, the file itself renders.
    std::fs::remove_file(&out).unwrap();
    assert_runs(&[
        "render",
        t,
        "-o",
        o,
        "--memory-mb",
        "7",
        "--width",
        "64",
        "--height",
        "48",
    ]);
}

/// Every point of a LAS/COPC file in file coordinates, sorted.
fn file_positions(path: &Path) -> Vec<[f64; 3]> {
    let cloud = load_las(path, None, &mut |_, _| {}).unwrap();
    let mut v: Vec<[f64; 3]> = cloud
        .positions
        .iter()
        .map(|p| (p.as_dvec3() + cloud.origin).to_array())
        .collect();
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v
}

/// Issue 47, defect 2: a PLY of double coordinates at 10^7 converts to
/// its own distinct positions, streamed (binary) or read whole (ASCII).
#[test]
fn double_ply_coordinates_far_from_zero_convert_exactly() {
    use common::{cube_points, write_double_plys};
    let dir = scratch("convert-double-far");
    let mut points = cube_points(2_000, 1e7);
    let (binary, ascii) = write_double_plys(dir.path(), &points);
    points.sort_by(|a, b| a.partial_cmp(b).unwrap());
    for (input, name) in [(&binary, "streamed"), (&ascii, "whole")] {
        let output = dir.path().join(format!("{name}.copc.laz"));
        convert(input, &output);
        let got = file_positions(&output);
        assert_eq!(got.len(), points.len());
        for (g, want) in got.iter().zip(&points) {
            for k in 0..3 {
                assert!((g[k] - want[k]).abs() < 1e-6, "{name}: {g:?} for {want:?}");
            }
        }
    }
}

/// Issue 47, defect 9: a PLY without colors converts to point format 6
/// (no RGB invented), its `intensity` kept: floats in [0, 1] scaled to
/// 0–65535, streamed (binary) or read whole (ASCII); a PLY with colors
/// stays format 7.
#[test]
fn a_ply_without_colors_converts_to_format_6_with_its_intensity() {
    use common::{cube_points, write_binary_ply};
    let dir = scratch("convert-intensity");
    let points = cube_points(500, 0.0);
    let props = [
        ("float", "x"),
        ("float", "y"),
        ("float", "z"),
        ("float", "intensity"),
    ];
    let rows: Vec<Vec<f64>> = points
        .iter()
        .enumerate()
        .map(|(i, p)| vec![p[0], p[1], p[2], (i % 101) as f64 / 100.0])
        .collect();
    let binary = dir.path().join("grey.ply");
    write_binary_ply(&binary, &props, &rows);
    let ascii = dir.path().join("grey-ascii.ply");
    let mut text = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nproperty float intensity\nend_header\n",
        rows.len()
    );
    for r in &rows {
        text += &format!(
            "{} {} {} {}\n",
            r[0] as f32, r[1] as f32, r[2] as f32, r[3] as f32
        );
    }
    std::fs::write(&ascii, text).unwrap();
    let mut want: Vec<u16> = rows
        .iter()
        .map(|r| ((r[3] as f32) as f64 * 65535.0).round() as u16)
        .collect();
    want.sort_unstable();
    for (input, name) in [(&binary, "streamed"), (&ascii, "whole")] {
        let output = dir.path().join(format!("{name}.copc.laz"));
        convert(input, &output);
        let header = las::Reader::from_path(&output).unwrap().header().clone();
        assert_eq!(header.point_format().to_u8().unwrap(), 6, "{name}");
        let cloud = load_las(&output, None, &mut |_, _| {}).unwrap();
        assert!(!cloud.has_rgb, "{name}");
        let mut got = cloud.intensities.unwrap();
        got.sort_unstable();
        assert_eq!(got, want, "{name}");
    }
    let colored = dir.path().join("colored.copc.laz");
    convert(&root().join("data/bunny_colored.ply"), &colored);
    let header = las::Reader::from_path(&colored).unwrap().header().clone();
    assert_eq!(header.point_format().to_u8().unwrap(), 7);
}

/// Issue 47, defect 5: a LAS of point format 8 (NIR) with 4 extra bytes
/// a point (`OriginId`, as PDAL's COPC has) converts to COPC format 8
/// keeping every point's NIR, colour and extra bytes bit for bit and the
/// Extra Bytes VLR, without a warning: read whole, and in parts (the
/// split path); read back by the `las` crate and by pointlens.
#[test]
fn format_8_with_extra_bytes_converts_keeping_nir_and_extra_bytes() {
    use las::{Builder, Color, Point, Vlr, Writer};
    let dir = scratch("convert-nir");
    let input = dir.path().join("nir.las");
    let mut builder = Builder::from((1, 4));
    builder.point_format = las::point::Format::new(8).unwrap();
    builder.point_format.extra_bytes = 4;
    let mut descriptor = vec![0u8; 192];
    descriptor[2] = 5; // unsigned long
    descriptor[4..12].copy_from_slice(b"OriginId");
    builder.vlrs.push(Vlr {
        user_id: "LASF_Spec".into(),
        record_id: 4,
        description: "extra bytes".into(),
        data: descriptor.clone(),
    });
    let mut writer = Writer::from_path(&input, builder.into_header().unwrap()).unwrap();
    let n = 3_000u32;
    // Each point's (x, y) code → its colour, NIR and extra bytes.
    let mut want = std::collections::BTreeMap::new();
    for i in 0..n {
        let (x, y) = (f64::from(i % 60), f64::from(i / 60));
        let color = Color::new(i as u16, (i * 3) as u16, (i * 7) as u16);
        let nir = (i * 13 + 5) as u16;
        let extra = (i.wrapping_mul(2_654_435_761)).to_le_bytes().to_vec();
        want.insert(
            (x as i64, y as i64),
            ((color.red, color.green, color.blue), nir, extra.clone()),
        );
        writer
            .write_point(Point {
                x,
                y,
                z: f64::from(i % 7),
                return_number: 1,
                number_of_returns: 1,
                gps_time: Some(f64::from(i)),
                color: Some(color),
                nir: Some(nir),
                extra_bytes: extra,
                ..Point::default()
            })
            .unwrap();
    }
    writer.close().unwrap();
    for (name, part_points) in [("whole", None), ("parts", Some(200u64))] {
        let output = dir.path().join(format!("{name}.copc.laz"));
        let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_pointlens"));
        if let Some(p) = part_points {
            command.env("POINTLENS_CONVERT_PART_POINTS", p.to_string());
        }
        let o = command
            .args([
                "convert",
                input.to_str().unwrap(),
                "-o",
                output.to_str().unwrap(),
            ])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{name}: {stderr}");
        assert!(!stderr.contains(": warn:"), "{name}: {stderr}");
        let mut reader = las::Reader::from_path(&output).unwrap();
        let header = reader.header().clone();
        assert_eq!(header.point_format().to_u8().unwrap(), 8, "{name}");
        assert_eq!(header.point_format().extra_bytes, 4, "{name}");
        let vlr = header
            .all_vlrs()
            .find(|v| v.user_id == "LASF_Spec" && v.record_id == 4)
            .expect("the Extra Bytes VLR");
        assert_eq!(vlr.data, descriptor, "{name}");
        let mut got = std::collections::BTreeMap::new();
        let data = reader.read_all().unwrap();
        for p in data.points() {
            let p = p.unwrap();
            let c = p.color.unwrap();
            got.insert(
                (p.x.round() as i64, p.y.round() as i64),
                ((c.red, c.green, c.blue), p.nir.unwrap(), p.extra_bytes),
            );
        }
        assert_eq!(got.len(), n as usize, "{name}");
        assert!(
            got == want,
            "{name}: the points' NIR, colours or extra bytes differ"
        );
        let cloud = load_las(&output, None, &mut |_, _| {}).unwrap();
        assert_eq!(cloud.len(), n as usize, "{name}");
        assert!(cloud.has_rgb, "{name}");
    }
}

/// Issue 47, defect 5: of point format 10 (NIR and waveform packets) with
/// extra bytes, COPC cannot hold the waveform packets only: the file is
/// format 8 with the NIR and extra bytes, and one warning line names the
/// waveform packets, nothing else.
#[test]
fn convert_names_the_waveform_packets_it_does_not_keep() {
    use las::{Builder, Color, Point, Writer};
    let dir = scratch("convert-waveform");
    let input = dir.path().join("waveform.las");
    let mut builder = Builder::from((1, 4));
    builder.point_format = las::point::Format::new(10).unwrap();
    builder.point_format.extra_bytes = 2;
    let mut writer = Writer::from_path(&input, builder.into_header().unwrap()).unwrap();
    let mut want = Vec::new();
    for i in 0..100u16 {
        want.push((
            i % 10,
            i / 10,
            i * 11 + 1,
            (i ^ 0x5A5A).to_le_bytes().to_vec(),
        ));
        writer
            .write_point(Point {
                x: f64::from(i % 10),
                y: f64::from(i / 10),
                return_number: 1,
                number_of_returns: 1,
                gps_time: Some(0.0),
                color: Some(Color::new(1, 2, 3)),
                nir: Some(i * 11 + 1),
                waveform: Some(Default::default()),
                extra_bytes: (i ^ 0x5A5A).to_le_bytes().to_vec(),
                ..Point::default()
            })
            .unwrap();
    }
    writer.close().unwrap();
    let output = dir.path().join("waveform.copc.laz");
    let o = pointlens(&[
        "convert",
        input.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let warnings: Vec<&str> = stderr.lines().filter(|l| l.contains(": warn:")).collect();
    assert_eq!(warnings.len(), 1, "{stderr}");
    assert!(
        warnings[0].contains("waveform packets of point format 10")
            && !warnings[0].contains("NIR")
            && !warnings[0].contains("extra bytes"),
        "{stderr}"
    );
    let mut reader = las::Reader::from_path(&output).unwrap();
    assert_eq!(reader.header().point_format().to_u8().unwrap(), 8);
    let data = reader.read_all().unwrap();
    let mut got: Vec<_> = data
        .points()
        .map(|p| {
            let p = p.unwrap();
            let (x, y) = (p.x.round() as u16, p.y.round() as u16);
            (x, y, p.nir.unwrap(), p.extra_bytes)
        })
        .collect();
    got.sort();
    want.sort();
    assert_eq!(got, want);
}
