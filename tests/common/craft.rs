//! Crafted LAZ inputs whose GPS-time data switches between LASzip's time
//! sequences again and again (`pointlens::input::laz_gps`): the `laz`
//! crate decodes each switch by calling itself, so `count` switches are
//! `count` frames of its stack.

use std::io::{Cursor, Seek, SeekFrom};
use std::path::Path;

use laz::encoders::ArithmeticEncoder;
use laz::models::ArithmeticModelBuilder;
use laz::record::FieldCompressor;

/// The arithmetic coding of `symbol`, `count` times, then `last`, with a
/// fresh adaptive model of `symbols` symbols: the model a chunk's GPS-time
/// decoder starts with after a zero difference, where `symbol` is a
/// switch and `last` a difference (the end of the switches). About 20,000
/// a byte.
pub fn repeated_symbol(symbols: u32, symbol: u32, count: usize, last: u32) -> Vec<u8> {
    let mut enc = ArithmeticEncoder::new(Cursor::new(Vec::new()));
    let mut model = ArithmeticModelBuilder::new(symbols).build();
    for _ in 0..count {
        enc.encode_symbol(&mut model, symbol).unwrap();
    }
    enc.encode_symbol(&mut model, last).unwrap();
    enc.done().unwrap();
    enc.into_inner().into_inner()
}

fn u32_at(b: &[u8], at: usize) -> usize {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as usize
}

fn u64_at(b: &[u8], at: usize) -> usize {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap()) as usize
}

/// `copc` (a COPC file's bytes, point format 6–8, its root node's first
/// point with a new GPS time after it) with its root node's GPS-time layer
/// replaced, in place, by `count` switches: layered LAZ (point formats
/// 6–10), `LasPoint6DecompressorImpl::read_gps_time`. The other layers,
/// and every other node, are as they were.
pub fn copc_gps_switches(copc: &[u8], count: usize) -> Vec<u8> {
    let mut f = copc.to_vec();
    // The COPC info VLR's payload follows its 54-byte header at 375: the
    // root hierarchy page's offset and size at 40 and 48.
    let info = 375 + 54;
    let (page, size) = (u64_at(&f, info + 40), u64_at(&f, info + 48));
    let root = f[page..page + size]
        .chunks_exact(32)
        .find(|e| e[..16].iter().all(|&b| b == 0))
        .expect("the root node's entry");
    let chunk = u64_at(root, 16);
    let record_len = u16::from_le_bytes(f[105..107].try_into().unwrap()) as usize;
    // After the first point and the point count: Point14's nine layer
    // sizes, then the other items' (format 7: RGB's one).
    let sizes_at = chunk + record_len + 4;
    let sizes: Vec<usize> = (0..9).map(|i| u32_at(&f, sizes_at + 4 * i)).collect();
    let others = match record_len {
        30 => 0,
        36 => 1,
        38 => 2,
        _ => panic!("point format 6, 7 or 8 without extra bytes"),
    };
    let layers_at = sizes_at + 4 * (9 + others);
    let gps_at = layers_at + sizes[..8].iter().sum::<usize>();
    // After a zero difference (every sequence's first), code 2 of 5 is a
    // switch to the next sequence, code 0 a 32-bit difference.
    let stream = repeated_symbol(5, 2, count, 0);
    assert!(stream.len() <= sizes[8], "the switches fit the GPS layer");
    f[gps_at..gps_at + sizes[8]].fill(0);
    f[gps_at..gps_at + stream.len()].copy_from_slice(&stream);
    f
}

/// Writes a LAZ file of point format 1 (`path`, 1,000 points, GPS times
/// that change, one chunk) whose second point's GPS time switches
/// sequences `count` times: point-by-point LAZ (point formats 1, 3, 4, 5),
/// `gps::v2::GpsTimeDecompressor::decompress_with`. The stream ends after
/// the switches (the rest of the chunk zeros).
pub fn laz_gps_switches(path: &Path, count: usize) {
    use las::{point::Format, Builder, Point, Writer};
    let mut builder = Builder::from((1, 2));
    builder.point_format = Format::new(1).unwrap();
    builder.point_format.is_compressed = true;
    let header = builder.into_header().unwrap();
    {
        let mut w = Writer::from_path(path, header).unwrap();
        for i in 0..1000 {
            let t = f64::from(i);
            w.write_point(Point {
                x: (t * 0.37).sin() * 10.0,
                y: (t * 0.11).cos() * 10.0,
                z: (t * 0.05).sin(),
                intensity: (i * 7 % 500) as u16,
                return_number: 1,
                number_of_returns: 1,
                gps_time: Some(1000.0 + t * 0.731),
                ..Default::default()
            })
            .unwrap();
        }
        w.close().unwrap();
    }
    let mut f = std::fs::read(path).unwrap();
    let data = u32_at(&f, 96);
    let table = u64_at(&f, data);
    let chunk = data + 8;
    // The first two records as the crate decodes them.
    let vlr = las::Reader::from_path(path)
        .unwrap()
        .header()
        .laz_vlr()
        .unwrap();
    let mut cursor = Cursor::new(f.clone());
    cursor.seek(SeekFrom::Start(data as u64)).unwrap();
    let mut d = laz::LasZipDecompressor::new(cursor, vlr).unwrap();
    let mut records = vec![0u8; 2 * 28];
    d.decompress_many(&mut records).unwrap();
    // The first point raw (Point10, then the GPS time), then the coded
    // second point's Point10 and its GPS time: after a zero difference,
    // code 3 of 6 is a switch to the next sequence, code 1 a 32-bit
    // difference.
    let mut point10 = laz::las::v2::LasPoint0Compressor::default();
    let mut out = Vec::new();
    point10.compress_first(&mut out, &records[..20]).unwrap();
    out.extend_from_slice(&records[20..28]);
    let mut enc = ArithmeticEncoder::new(Cursor::new(Vec::new()));
    point10.compress_with(&mut enc, &records[28..48]).unwrap();
    let mut model = ArithmeticModelBuilder::new(6).build();
    for _ in 0..count {
        enc.encode_symbol(&mut model, 3).unwrap();
    }
    enc.encode_symbol(&mut model, 1).unwrap();
    enc.done().unwrap();
    out.extend_from_slice(&enc.into_inner().into_inner());
    assert!(out.len() <= table - chunk, "the switches fit the chunk");
    f[chunk..table].fill(0);
    f[chunk..chunk + out.len()].copy_from_slice(&out);
    std::fs::write(path, &f).unwrap();
}
