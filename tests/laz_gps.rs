//! LAZ GPS times without the `laz` crate's recursion
//! (`pointlens::input::laz_gps`): pointlens's decoding of every LAZ chunk
//! gives the records the crate gives (GPS times that use every code of
//! LASzip's coding, in point-by-point and layered formats), and GPS-time
//! data that switches sequences again and again, which overflowed the
//! crate's stack, is refused, or skipped where no GPS time is needed.

mod common;

use std::io::Cursor;

use common::craft::{copc_gps_switches, laz_gps_switches};
use common::{assert_runs, root, scratch};
use laz::{LasZipCompressor, LasZipDecompressor, LazVlr, LazVlrBuilder};
use pointlens::input::las::{decompress_chunk, load_las, ChunkFault};
use pointlens::input::laz_gps::{check_point14_gps, point14_gps_bits, MAX_SWITCHES};

/// SplitMix64.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// GPS times (bits) that use every code of LASzip's GPS-time coding: the
/// same time again (a pulse's other returns), steps of four interleaved
/// flight lines and multiples of them (2×, 10×, 500×, negative), switches
/// between the lines, jumps to new lines, and any difference.
fn gps_times(n: usize, rng: &mut Rng) -> Vec<i64> {
    let mut lines: Vec<(i64, i64)> = (0..4)
        .map(|i| {
            (
                (1.0e5 * f64::from(i + 1)).to_bits() as i64,
                1000 + 37 * i64::from(i),
            )
        })
        .collect();
    let mut current = 0;
    let mut t = lines[0].0;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        match rng.below(100) {
            0..=19 => {}
            20..=54 => t += lines[current].1 + rng.below(4) as i64,
            55..=64 => {
                let m = [
                    2, 3, 9, 10, 11, 49, 499, 500, 501, 600, -1, -3, -9, -10, -20,
                ];
                t += lines[current].1 * m[rng.below(m.len() as u64) as usize];
            }
            65..=79 => {
                lines[current].0 = t;
                current = rng.below(4) as usize;
                t = lines[current].0 + lines[current].1;
            }
            80..=84 => {
                lines[current].0 = t;
                current = rng.below(4) as usize;
                t = (rng.below(1 << 30) as f64 * 0.37).to_bits() as i64;
            }
            _ => t += rng.below(1 << 21) as i64 - (1 << 20),
        }
        out.push(t);
    }
    out
}

/// `n` records of point format `format` (1, 3, 6 or 7): random positions,
/// returns of one to five, scanner channels that change (6 and 7) and the
/// GPS times of [`gps_times`].
fn records(format: u8, n: usize, seed: u64) -> Vec<u8> {
    let mut rng = Rng(seed);
    let times = gps_times(n, &mut rng);
    let len = [20, 28, 26, 34, 0, 0, 30, 36][format as usize];
    let mut out = vec![0u8; n * len];
    let (mut returns, mut channel) = ((1u8, 1u8), 0u8);
    for (i, r) in out.chunks_exact_mut(len).enumerate() {
        for k in 0..3 {
            r[4 * k..4 * k + 4].copy_from_slice(&(rng.below(1 << 20) as i32).to_le_bytes());
        }
        r[12..14].copy_from_slice(&(rng.below(65536) as u16).to_le_bytes());
        if rng.below(3) > 0 {
            let n = 1 + rng.below(5) as u8;
            returns = (1 + rng.below(u64::from(n)) as u8, n);
        }
        if rng.below(10) == 0 {
            channel = rng.below(4) as u8;
        }
        let gps = times[i].to_le_bytes();
        if format < 6 {
            r[14] = returns.0 | (returns.1 << 3) | ((rng.below(4) as u8) << 6);
            r[15] = rng.below(32) as u8;
            r[16] = rng.below(256) as u8;
            r[17] = rng.below(256) as u8;
            r[18..20].copy_from_slice(&(rng.below(4) as u16).to_le_bytes());
            if format % 2 == 1 {
                r[20..28].copy_from_slice(&gps);
            }
        } else {
            r[14] = returns.0 | (returns.1 << 4);
            r[15] = rng.below(16) as u8 | (channel << 4) | ((rng.below(4) as u8) << 6);
            r[16] = rng.below(32) as u8;
            r[17] = rng.below(256) as u8;
            r[18..20].copy_from_slice(&(rng.below(200) as i16 - 100).to_le_bytes());
            r[20..22].copy_from_slice(&(rng.below(4) as u16).to_le_bytes());
            r[22..30].copy_from_slice(&gps);
        }
        let rgb = if format == 3 { 28 } else { 30 };
        if format == 3 || format == 7 {
            for b in &mut r[rgb..rgb + 6] {
                *b = rng.below(256) as u8;
            }
        }
    }
    out
}

/// `records` compressed by the `laz` crate in chunks of `chunk` points:
/// the LAZ VLR and the compressed data (the chunk table's offset, the
/// chunks, the table).
fn compress(format: u8, records: &[u8], chunk: u32) -> (LazVlr, Vec<u8>) {
    let vlr = LazVlrBuilder::default()
        .with_point_format(format, 0)
        .unwrap()
        .with_fixed_chunk_size(chunk)
        .build();
    let mut c = LasZipCompressor::new(Cursor::new(Vec::new()), vlr.clone()).unwrap();
    c.compress_many(records).unwrap();
    c.done().unwrap();
    (vlr, c.into_inner().into_inner())
}

/// The chunks of `data` (as [`compress`] gives it) of `points` points:
/// (its bytes, its first point, its points).
fn chunks<'a>(vlr: &LazVlr, data: &'a [u8], points: u64) -> Vec<(&'a [u8], u64, u64)> {
    let table = laz::laszip::ChunkTable::read_from(Cursor::new(data), vlr).unwrap();
    let (mut at, mut first) = (8usize, 0u64);
    let mut out = Vec::new();
    for entry in &table {
        let n = u64::from(vlr.chunk_size()).min(points - first);
        let len = entry.byte_count as usize;
        out.push((&data[at..at + len], first, n));
        at += len;
        first += n;
    }
    out
}

#[test]
fn every_chunk_decodes_to_the_crates_records_gps_times_included() {
    for format in [1u8, 3, 6, 7] {
        let n = 20_000;
        let recs = records(format, n, u64::from(format) * 7919);
        let len = recs.len() / n;
        let (vlr, data) = compress(format, &recs, 5000);
        // The crate's own reading is the records (LAZ is lossless).
        let mut crate_out = vec![0u8; recs.len()];
        LasZipDecompressor::new(Cursor::new(&data), vlr.clone())
            .unwrap()
            .decompress_many(&mut crate_out)
            .unwrap();
        assert!(crate_out == recs, "format {format}: the crate's reading");
        for (bytes, first, points) in chunks(&vlr, &data, n as u64) {
            let what = format!("format {format}, points {first}+{points}");
            let at = first as usize * len;
            let expected = &recs[at..at + points as usize * len];
            let decode = |gps| {
                let mut out = vec![0u8; expected.len()];
                decompress_chunk(vlr.items(), len, bytes, points, gps, &mut out).map(|()| out)
            };
            let got = decode(true).unwrap();
            assert!(got == expected, "{what}: records");
            if format >= 6 {
                // The GPS-time layer's check decodes the same times.
                let times = point14_gps_bits(vlr.items(), len, bytes, points).unwrap();
                let want: Vec<i64> = expected
                    .chunks_exact(len)
                    .skip(1)
                    .map(|r| i64::from_le_bytes(r[22..30].try_into().unwrap()))
                    .collect();
                assert!(times == want, "{what}: GPS times");
                // Without the GPS times, the rest is the same.
                let rest = decode(false).unwrap();
                for (a, b) in rest.chunks_exact(len).zip(expected.chunks_exact(len)) {
                    assert_eq!((&a[..22], &a[30..]), (&b[..22], &b[30..]), "{what}");
                }
            }
        }
    }
}

/// The root node of PDAL's COPC file with a GPS-time layer of `count`
/// switches.
fn pdal_with_switches(count: usize) -> Vec<u8> {
    let pdal = std::fs::read(root().join("tests/data/pdal-1.2-with-color.copc.laz")).unwrap();
    copc_gps_switches(&pdal, count)
}

#[test]
fn a_layered_chunk_that_switches_too_often_is_refused_where_gps_is_read() {
    let dir = scratch("laz-gps-layered");
    let path = dir.path().join("switches.copc.laz");
    // 100,000 switches, 16 bytes: the crate's recursion overflowed a 2 MiB
    // thread's stack (`info` aborted).
    std::fs::write(&path, pdal_with_switches(100_000)).unwrap();
    let copc = pointlens::input::copc::CopcFile::open(
        &path,
        las::Reader::from_path(&path).unwrap().header().clone(),
    )
    .unwrap();
    let root_node = copc
        .entry(pointlens::input::copc::NodeKey::ROOT)
        .unwrap()
        .unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let chunk =
        &bytes[root_node.offset as usize..(root_node.offset + root_node.byte_size) as usize];
    let items = copc.header.laz_vlr().unwrap().items().clone();
    let points = root_node.point_count;
    assert!(check_point14_gps(&items, 36, chunk, points).is_err());
    let mut out = vec![0u8; points as usize * 36];
    match decompress_chunk(&items, 36, chunk, points, true, &mut out) {
        Err(ChunkFault::Corrupt(msg)) => {
            assert!(msg.contains("switches between time sequences"), "{msg}")
        }
        other => panic!("{other:?}"),
    }
    // Read by node, as render and info read it, the GPS times are not
    // decoded: every point is the original file's.
    let original = load_las(
        &root().join("tests/data/pdal-1.2-with-color.copc.laz"),
        None,
        &mut |_, _| {},
    )
    .unwrap();
    let read = load_las(&path, None, &mut |_, _| {}).unwrap();
    assert_eq!(read.positions, original.positions);
    assert_eq!(read.colors, original.colors);
    // `info` aborted on it (stack overflow in a node's decompression
    // thread), and render read its root node on the main thread.
    let p = path.to_str().unwrap();
    assert_runs(&["info", p]);
    let out = dir.path().join("frame.png");
    let o = out.to_str().unwrap();
    assert_runs(&[
        "render", p, "-o", o, "--width", "16", "--height", "12", "--device", "llvmpipe",
    ]);
    assert!(out.exists());
    // As many switches as a point may make pass the check.
    let within = pdal_with_switches(MAX_SWITCHES as usize);
    let chunk =
        &within[root_node.offset as usize..(root_node.offset + root_node.byte_size) as usize];
    assert!(check_point14_gps(&items, 36, chunk, points).is_ok());
}

#[test]
fn a_point_by_point_chunk_that_switches_too_often_is_one_error() {
    let dir = scratch("laz-gps-pointwise");
    let path = dir.path().join("switches.laz");
    laz_gps_switches(&path, 100_000);
    let err = load_las(&path, None, &mut |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("switches between time sequences"), "{err}");
    assert!(err.contains("switches.laz"), "{err}");
}

/// `convert` reads LAZ through the same decoding, GPS times included:
/// every point of a LAZ file of point format 1, 3, 6 or 7 (two chunks)
/// is in its COPC file with its GPS time.
#[test]
fn a_laz_file_converts_keeping_every_gps_time() {
    use las::{point::Format, Builder, Color, Point, Writer};
    let dir = scratch("laz-gps-convert");
    for format in [1u8, 3, 6, 7] {
        let input = dir.path().join(format!("f{format}.laz"));
        let mut builder = Builder::from((1, 4));
        builder.point_format = Format::new(format).unwrap();
        builder.point_format.is_compressed = true;
        let mut writer = Writer::from_path(&input, builder.into_header().unwrap()).unwrap();
        let mut rng = Rng(u64::from(format));
        let times = gps_times(60_000, &mut rng);
        let mut want = Vec::new();
        for (i, t) in times.iter().enumerate() {
            let (x, y, z) = ((i % 300) as f64, (i / 300) as f64, (i % 7) as f64);
            let n = 1 + (i % 3) as u8;
            writer
                .write_point(Point {
                    x,
                    y,
                    z,
                    return_number: 1 + (i % n as usize) as u8,
                    number_of_returns: n,
                    gps_time: Some(f64::from_bits(*t as u64)),
                    color: (format % 2 == 1 && format != 1).then(|| Color::new(1, 2, 3)),
                    ..Point::default()
                })
                .unwrap();
            want.push((x as i64, y as i64, z as i64, *t));
        }
        writer.close().unwrap();
        let output = dir.path().join(format!("f{format}.copc.laz"));
        assert_runs(&[
            "convert",
            input.to_str().unwrap(),
            "-o",
            output.to_str().unwrap(),
        ]);
        let data = las::Reader::from_path(&output).unwrap().read_all().unwrap();
        let mut got: Vec<(i64, i64, i64, i64)> = data
            .points()
            .map(|p| {
                let p = p.unwrap();
                let t = p.gps_time.unwrap().to_bits() as i64;
                (
                    p.x.round() as i64,
                    p.y.round() as i64,
                    p.z.round() as i64,
                    t,
                )
            })
            .collect();
        got.sort_unstable();
        want.sort_unstable();
        assert!(got == want, "format {format}: points or GPS times differ");
    }
}
