//! LAZ GPS times without the `laz` crate's recursion.
//!
//! LASzip codes a point's GPS time against one of four sequences of
//! earlier times; a code may first switch to another sequence, and the
//! `laz` crate (0.13) decodes a switch by calling itself
//! (`gps::v2::GpsTimeDecompressor::decompress_with` for point formats 1, 3,
//! 4 and 5, `point6::LasPoint6DecompressorImpl::read_gps_time` for 6–10).
//! A writer switches at most once a point: after a switch the time is in
//! reach of the new sequence. A corrupt stream can say "switch" for as
//! long as it lasts, and each switch is a frame of the recursion, 64 bytes
//! in a release build: 32,500 switches (12 bytes of GPS-time data)
//! overflowed `pointlens info`'s 2 MiB decoding threads, 131,072 (17
//! bytes) fill a main thread's 8 MiB. The adaptive arithmetic coder makes
//! a symbol it keeps seeing nearly free: about 20,000 switches a byte, and
//! at most 45,000 before the decoder reads its next byte (its interval
//! shrinks by at least 4/32,768 a symbol and gains 8 bits a byte). No
//! stack is large enough: a chunk's GPS-time bytes are bounded only by the
//! file.
//!
//! Here the same decoding is a loop that refuses a point whose time
//! switches more than [`MAX_SWITCHES`] times (`GpsSequences`): it replaces
//! the crate's decompressor of the point-by-point formats ([`GpsTimeV2`]),
//! and, for the layered formats, whose GPS times are one part of the
//! crate's point decompressor, checks a chunk's GPS-time layer before the
//! crate decodes it ([`check_point14_gps`]: the channel, return and XY
//! layer say which points carry a new time, so it is decoded too, values
//! aside), so that the crate recurses at most `MAX_SWITCHES` + 1 frames
//! deep. Where no GPS time is needed (`render` and `info`: the LAZ stream
//! of `input::las`, a COPC file's nodes) the layered formats' GPS-time
//! layer is skipped, not decoded; `convert` decodes and checks it.

use std::io::{self, Cursor, Read};

use laz::decoders::ArithmeticDecoder;
use laz::decompressors::{IntegerDecompressor, IntegerDecompressorBuilder};
use laz::models::{ArithmeticModel, ArithmeticModelBuilder};
use laz::record::FieldDecompressor;

/// The most sequence switches one point's GPS time may make (a writer
/// makes at most one).
pub const MAX_SWITCHES: u32 = 4;

/// LASzip's multiplier codes of a GPS-time difference.
const MULTI: i32 = 500;
const MULTI_MINUS: i32 = -10;
/// The first code past the multipliers (the point-by-point formats' "time
/// unchanged"; the layered formats' "a full time follows").
const MULTI_END: i32 = MULTI - MULTI_MINUS + 1;

/// The error of a point whose GPS time switches sequences more than
/// [`MAX_SWITCHES`] times: the payload of the `io::Error` the decoders
/// return, so that a reader can tell it from a truncated stream.
#[derive(Debug)]
pub struct TooManySwitches;

impl std::fmt::Display for TooManySwitches {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "a point's GPS time switches between time sequences more than {MAX_SWITCHES} times \
             (a LAZ writer switches at most once): corrupt GPS-time data"
        )
    }
}

impl std::error::Error for TooManySwitches {}

/// Whether `e` is [`TooManySwitches`].
pub fn is_too_many_switches(e: &io::Error) -> bool {
    e.get_ref()
        .is_some_and(|inner| inner.is::<TooManySwitches>())
}

/// The two codings of LASzip's GPS times, which differ only in how they
/// number the codes after a zero difference.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Coding {
    /// Point formats 1, 3, 4, 5 (item GpsTime, version 2): code 0 after a
    /// zero difference is "unchanged", and every code is one higher.
    PointByPoint,
    /// Point formats 6–10 (item Point14): the point's own flag says that
    /// its time changed.
    Layered,
}

/// One stream's four sequences of GPS times and their models: the state
/// of the `laz` crate's GPS-time decoding, decoded by a loop.
struct GpsSequences {
    coding: Coding,
    no_diff: ArithmeticModel,
    multi: ArithmeticModel,
    ic: IntegerDecompressor,
    last: usize,
    next: usize,
    /// The times' bits (an f64 as the i64 LASzip adds differences to).
    times: [i64; 4],
    diffs: [i32; 4],
    counters: [i32; 4],
}

impl GpsSequences {
    fn new(coding: Coding, first: i64) -> GpsSequences {
        let offset = match coding {
            Coding::PointByPoint => 1,
            Coding::Layered => 0,
        };
        GpsSequences {
            coding,
            no_diff: ArithmeticModelBuilder::new(5 + offset).build(),
            multi: ArithmeticModelBuilder::new((MULTI_END + 4 + offset as i32) as u32).build(),
            ic: IntegerDecompressorBuilder::new()
                .bits(32)
                .contexts(9)
                .build_initialized(),
            last: 0,
            next: 0,
            times: [first, 0, 0, 0],
            diffs: [0; 4],
            counters: [0; 4],
        }
    }

    /// The current time's bits.
    fn time(&self) -> i64 {
        self.times[self.last]
    }

    /// Decodes the next time (`gps::v2::GpsTimeDecompressor::decompress_with`
    /// or `LasPoint6DecompressorImpl::read_gps_time` of `laz` 0.13, a
    /// switch of sequence a turn of the loop rather than a call).
    fn decode<R: Read>(&mut self, dec: &mut ArithmeticDecoder<R>) -> io::Result<()> {
        // Codes after a zero difference, less this: 0 a 32-bit difference,
        // 1 a full time, 2 and up a switch (-1: unchanged).
        let offset = match self.coding {
            Coding::PointByPoint => 1,
            Coding::Layered => 0,
        };
        let mut switches = 0;
        loop {
            let last = self.last;
            let by = if self.diffs[last] == 0 {
                match dec.decode_symbol(&mut self.no_diff)? as i32 - offset {
                    -1 => return Ok(()),
                    0 => {
                        self.diffs[last] = self.ic.decompress(dec, 0, 0)?;
                        self.times[last] = self.times[last].wrapping_add(self.diffs[last].into());
                        self.counters[last] = 0;
                        return Ok(());
                    }
                    1 => return self.full_time(dec),
                    code => code as usize - 1,
                }
            } else {
                let multi = dec.decode_symbol(&mut self.multi)? as i32;
                if multi < MULTI_END {
                    self.difference(dec, multi)?;
                    return Ok(());
                }
                match multi - MULTI_END - offset {
                    -1 => return Ok(()),
                    0 => return self.full_time(dec),
                    by => by as usize,
                }
            };
            switches += 1;
            if switches > MAX_SWITCHES {
                return Err(io::Error::new(io::ErrorKind::InvalidData, TooManySwitches));
            }
            self.last = (last + by) & 3;
        }
    }

    /// A time coded whole: a new sequence.
    fn full_time<R: Read>(&mut self, dec: &mut ArithmeticDecoder<R>) -> io::Result<()> {
        self.next = (self.next + 1) & 3;
        let high = self
            .ic
            .decompress(dec, (self.times[self.last] >> 32) as i32, 8)?;
        let low = dec.read_int()?;
        self.times[self.next] = (i64::from(high) << 32) | i64::from(low);
        self.last = self.next;
        self.diffs[self.last] = 0;
        self.counters[self.last] = 0;
        Ok(())
    }

    /// A difference coded as a multiple `multi` (below [`MULTI_END`]) of
    /// the sequence's last one.
    fn difference<R: Read>(
        &mut self,
        dec: &mut ArithmeticDecoder<R>,
        multi: i32,
    ) -> io::Result<()> {
        let last = self.last;
        let prev = self.diffs[last];
        if multi == 1 {
            let d = self.ic.decompress(dec, prev, 1)?;
            self.times[last] = self.times[last].wrapping_add(d.into());
            self.counters[last] = 0;
            return Ok(());
        }
        // The multipliers that count towards taking the difference as the
        // sequence's new one.
        let (d, extreme) = if multi == 0 {
            (self.ic.decompress(dec, 0, 7)?, true)
        } else if multi < MULTI {
            let context = if multi < 10 { 2 } else { 3 };
            (
                self.ic.decompress(dec, multi.wrapping_mul(prev), context)?,
                false,
            )
        } else if multi == MULTI {
            (self.ic.decompress(dec, MULTI.wrapping_mul(prev), 4)?, true)
        } else {
            let m = MULTI - multi;
            if m > MULTI_MINUS {
                (self.ic.decompress(dec, m.wrapping_mul(prev), 5)?, false)
            } else {
                let pred = MULTI_MINUS.wrapping_mul(prev);
                (self.ic.decompress(dec, pred, 6)?, true)
            }
        };
        if extreme {
            self.counters[last] += 1;
            if self.counters[last] > 3 {
                self.diffs[last] = d;
                self.counters[last] = 0;
            }
        }
        self.times[last] = self.times[last].wrapping_add(d.into());
        Ok(())
    }
}

/// The GPS time of point formats 1, 3, 4 and 5 (LAZ item GpsTime, version
/// 2): the `laz` crate's `GpsTimeDecompressor` as a loop.
pub struct GpsTimeV2 {
    sequences: GpsSequences,
}

impl Default for GpsTimeV2 {
    fn default() -> Self {
        GpsTimeV2 {
            sequences: GpsSequences::new(Coding::PointByPoint, 0),
        }
    }
}

impl<R: Read> FieldDecompressor<R> for GpsTimeV2 {
    fn size_of_field(&self) -> usize {
        8
    }

    fn decompress_first(&mut self, src: &mut R, first_point: &mut [u8]) -> io::Result<()> {
        src.read_exact(&mut first_point[..8])?;
        self.sequences.times[0] = i64::from_le_bytes(first_point[..8].try_into().expect("8 bytes"));
        Ok(())
    }

    fn decompress_with(
        &mut self,
        decoder: &mut ArithmeticDecoder<R>,
        buf: &mut [u8],
    ) -> io::Result<()> {
        self.sequences.decode(decoder)?;
        buf[..8].copy_from_slice(&self.sequences.time().to_le_bytes());
        Ok(())
    }
}

/// One scanner channel's state of a layered chunk's channel, return and
/// XY layer, and its GPS times (`laz`'s `Point6DecompressionContext`, the
/// parts that decide what the two layers decode: the XY predictions, which
/// change the values and never what is decoded, are left out).
struct Channel {
    changed_values: Vec<ArithmeticModel>,
    scanner_channel: ArithmeticModel,
    number_of_returns: Vec<Option<ArithmeticModel>>,
    return_number: Vec<Option<ArithmeticModel>>,
    return_number_gps_same: ArithmeticModel,
    dx: IntegerDecompressor,
    dy: IntegerDecompressor,
    /// The last point's return number and number of returns, and whether
    /// its GPS time changed.
    returns: (u8, u8),
    gps_changed: bool,
    gps: GpsSequences,
}

impl Channel {
    /// A channel's state after a point with `returns` (return number,
    /// number of returns) and GPS time `time` (bits).
    fn from_point(returns: (u8, u8), time: i64) -> Channel {
        let integers = |contexts| {
            IntegerDecompressorBuilder::new()
                .bits(32)
                .contexts(contexts)
                .build_initialized()
        };
        Channel {
            changed_values: (0..8)
                .map(|_| ArithmeticModelBuilder::new(128).build())
                .collect(),
            scanner_channel: ArithmeticModelBuilder::new(3).build(),
            number_of_returns: (0..16).map(|_| None).collect(),
            return_number: (0..16).map(|_| None).collect(),
            return_number_gps_same: ArithmeticModelBuilder::new(13).build(),
            dx: integers(2),
            dy: integers(22),
            returns,
            gps_changed: false,
            gps: GpsSequences::new(Coding::Layered, time),
        }
    }
}

/// A decoder of one layer of a chunk (none where the layer is empty: the
/// crate then decodes nothing of it).
fn layer_decoder(bytes: &[u8]) -> io::Result<ArithmeticDecoder<Cursor<&[u8]>>> {
    let mut dec = ArithmeticDecoder::new(Cursor::new(bytes));
    if !bytes.is_empty() {
        dec.read_init_bytes()?;
    }
    Ok(dec)
}

/// Decodes the GPS times of a layered LAZ chunk (point formats 6–10:
/// `chunk`, its first item Point14, of `points` points), as the `laz`
/// crate's `LasPoint6Decompressor` does, calling `visit` with each point's
/// time (bits) after the first; the layers' sizes at `sizes_at` (nine u32,
/// Point14's) and its layers from `layers_at`. An error where the data
/// ends or a point switches sequences more than [`MAX_SWITCHES`] times.
fn point14_gps_times(
    chunk: &[u8],
    points: u64,
    (sizes_at, layers_at): (usize, usize),
    visit: &mut dyn FnMut(i64),
) -> io::Result<()> {
    let short = || io::Error::new(io::ErrorKind::UnexpectedEof, "the chunk ends early");
    let word = |at: usize| -> io::Result<usize> {
        let b = chunk.get(at..at + 4).ok_or_else(short)?;
        Ok(u32::from_le_bytes(b.try_into().expect("4 bytes")) as usize)
    };
    let sizes: Vec<usize> = (0..9)
        .map(|i| word(sizes_at + 4 * i))
        .collect::<io::Result<_>>()?;
    let gps_at = layers_at + sizes[..8].iter().sum::<usize>();
    if sizes[8] == 0 {
        // No GPS-time layer: the crate decodes no time.
        return Ok(());
    }
    let layer = |at: usize, len: usize| chunk.get(at..at + len).ok_or_else(short);
    let mut xy = layer_decoder(layer(layers_at, sizes[0])?)?;
    let mut gps = layer_decoder(layer(gps_at, sizes[8])?)?;
    let first = chunk.get(..30).ok_or_else(short)?;
    let returns = (first[14] & 0x0F, first[14] >> 4);
    let time = i64::from_le_bytes(first[22..30].try_into().expect("8 bytes"));
    let mut current = usize::from((first[15] >> 4) & 3);
    let mut channels: [Option<Channel>; 4] = Default::default();
    channels[current] = Some(Channel::from_point(returns, time));
    for _ in 1..points {
        let c = channels[current].as_mut().expect("the current channel");
        let (last_r, last_n) = c.returns;
        let lpr = usize::from(last_r == 1)
            + 2 * usize::from(last_r >= last_n)
            + 4 * usize::from(c.gps_changed);
        let changed = xy.decode_symbol(&mut c.changed_values[lpr])?;
        if changed & (1 << 6) != 0 {
            let diff = xy.decode_symbol(&mut c.scanner_channel)? as usize;
            let next = (current + diff + 1) % 4;
            if channels[next].is_none() {
                let c = channels[current].as_ref().expect("the current channel");
                channels[next] = Some(Channel::from_point(c.returns, c.gps.time()));
            }
            current = next;
        }
        let c = channels[current].as_mut().expect("the current channel");
        let gps_changed = changed & (1 << 4) != 0;
        let (last_r, last_n) = c.returns;
        let n = if changed & (1 << 2) != 0 {
            let model = c.number_of_returns[usize::from(last_n)]
                .get_or_insert_with(|| ArithmeticModelBuilder::new(16).build());
            xy.decode_symbol(model)? as u8
        } else {
            last_n
        };
        let r = match changed & 3 {
            0 => last_r,
            1 => (last_r + 1) % 16,
            2 => (last_r + 15) % 16,
            _ if gps_changed => {
                let model = c.return_number[usize::from(last_r)]
                    .get_or_insert_with(|| ArithmeticModelBuilder::new(16).build());
                xy.decode_symbol(model)? as u8
            }
            _ => {
                let sym = xy.decode_symbol(&mut c.return_number_gps_same)?;
                ((u32::from(last_r) + sym + 2) % 16) as u8
            }
        };
        c.returns = (r, n);
        let single = u32::from(n == 1);
        c.dx.decompress(&mut xy, 0, single)?;
        let k = c.dx.k();
        let context = single + if k < 20 { k & !1 } else { 20 };
        c.dy.decompress(&mut xy, 0, context)?;
        c.gps_changed = gps_changed;
        if gps_changed {
            c.gps.decode(&mut gps)?;
        }
        visit(c.gps.time());
    }
    Ok(())
}

/// Where a layered chunk of items `items` and records of `record_len`
/// bytes keeps Point14's nine layer sizes and its first layer: None where
/// its first item is not Point14.
fn point14_layout(items: &[laz::LazItem], record_len: usize) -> Option<(usize, usize)> {
    let first = items.first()?;
    if !matches!(first.item_type(), laz::LazItemType::Point14) {
        return None;
    }
    let head_len = super::las::layered_head_len(items, record_len as u64);
    Some((record_len + 4, head_len))
}

/// Checks a layered LAZ chunk's GPS times before the `laz` crate decodes
/// them (`chunk`: its bytes, `points` points of items `items`, records of
/// `record_len` bytes): an error only where a point's time switches
/// sequences more than [`MAX_SWITCHES`] times, where the crate would
/// recurse that deep. A chunk whose data ends early, or whose first item
/// is not Point14, passes: the crate reports what is wrong with it.
pub fn check_point14_gps(
    items: &[laz::LazItem],
    record_len: usize,
    chunk: &[u8],
    points: u64,
) -> Result<(), TooManySwitches> {
    let Some(layout) = point14_layout(items, record_len) else {
        return Ok(());
    };
    match point14_gps_times(chunk, points, layout, &mut |_| {}) {
        Err(e) if is_too_many_switches(&e) => Err(TooManySwitches),
        _ => Ok(()),
    }
}

/// The GPS times (bits) of a layered chunk's points after the first, as
/// [`check_point14_gps`] decodes them (none where the first item is not
/// Point14 or the chunk has no GPS-time layer): what the tests hold
/// against the `laz` crate's.
pub fn point14_gps_bits(
    items: &[laz::LazItem],
    record_len: usize,
    chunk: &[u8],
    points: u64,
) -> io::Result<Vec<i64>> {
    let mut out = Vec::new();
    if let Some(layout) = point14_layout(items, record_len) {
        point14_gps_times(chunk, points, layout, &mut |t| out.push(t))?;
    }
    Ok(out)
}
