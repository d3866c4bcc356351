//! COPC by node (issue 30; docs/ARCHITECTURE.md, "COPC by node"): the
//! octree of a COPC file (the info VLR and its hierarchy pages, child pages
//! read only when a walk reaches them) and the decompression of one node's
//! points, each node an independent LAZ chunk.
//!
//! Pages are read by their absolute file offsets, not relative to the root
//! page: PDAL and untwine write the root page last (las-rs#157), which a
//! reader that subtracts the root's offset cannot follow. Everything a page
//! says is checked before it is used: a page inside the file and a whole
//! number of 32-byte entries, keys inside the octree and below the page's
//! own key, node data inside the file, no page read twice (a cycle), point
//! counts that never add up to more than the header declares, and a node
//! whose data holds fewer points than its entry says.

use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::Cursor;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use glam::{DVec3, Vec3};
use las::{PointData, PointDataBuilder};
use laz::record::{LayeredPointRecordDecompressor, RecordDecompressor};

use super::las::{preflight, Gather, Norms, Preflight};
use crate::camera::Camera;
use crate::cloud::PointCloud;
use crate::color::ColorRanges;
use crate::error::{Error, Result};
use crate::options::Lod;

/// `--point-budget`: the most points of a COPC file one frame takes.
pub const DEFAULT_POINT_BUDGET: u64 = 10_000_000;

/// Whether `path` is a COPC file: a LAS file whose first VLR (at byte
/// 375) is the COPC info VLR (user "copc", record 1), as the COPC
/// specification requires.
pub fn is_copc(path: &Path) -> bool {
    let mut head = [0u8; 375 + 54];
    let Ok(file) = File::open(path) else {
        return false;
    };
    if file.read_exact_at(&mut head, 0).is_err() || &head[..4] != b"LASF" {
        return false;
    }
    let vlr = &head[375..];
    let user = &vlr[2..18];
    let record = u16::from_le_bytes([vlr[18], vlr[19]]);
    user.starts_with(b"copc") && user[4..].iter().all(|&b| b == 0) && record == 1
}

/// Bytes of one hierarchy entry: key (4 × i32), offset (u64), byte size
/// (i32), point count (i32).
const ENTRY_BYTES: u64 = 32;

/// The largest hierarchy page read: 2^21 entries (a page of a 10^10-point
/// file holds about 10^5).
const MAX_PAGE_BYTES: u64 = ENTRY_BYTES << 21;

/// The deepest octree level read: a node there is 2^-30 of the root's
/// width, far below any scale a LAS grid holds.
pub const MAX_LEVEL: i32 = 30;

/// The COPC info VLR: where the octree is and where its first page lies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CopcInfo {
    /// Centre of the root cube, file coordinates.
    pub centre: DVec3,
    /// Half the root cube's width.
    pub halfsize: f64,
    /// Spacing of the root node's points; halved per level.
    pub spacing: f64,
    /// The root hierarchy page: absolute file offset and size in bytes.
    pub root_page: (u64, u64),
}

impl CopcInfo {
    /// Parses the 160-byte payload of the info VLR (user "copc", record 1).
    pub fn parse(data: &[u8]) -> std::result::Result<CopcInfo, String> {
        if data.len() < 160 {
            return Err(format!(
                "the COPC info VLR holds {} bytes, not 160",
                data.len()
            ));
        }
        let f = |i: usize| f64::from_le_bytes(data[8 * i..8 * i + 8].try_into().expect("8 bytes"));
        let u = |i: usize| u64::from_le_bytes(data[8 * i..8 * i + 8].try_into().expect("8 bytes"));
        let info = CopcInfo {
            centre: DVec3::new(f(0), f(1), f(2)),
            halfsize: f(3),
            spacing: f(4),
            root_page: (u(5), u(6)),
        };
        if !(info.centre.is_finite()
            && info.halfsize.is_finite()
            && info.halfsize > 0.0
            && info.spacing.is_finite()
            && info.spacing > 0.0)
        {
            return Err(format!(
                "the COPC info VLR's octree is not a cube with a positive size and spacing \
                 (centre {:?}, halfsize {}, spacing {})",
                info.centre.to_array(),
                info.halfsize,
                info.spacing
            ));
        }
        Ok(info)
    }

    /// The cube of node `key`, file coordinates: (min corner, width).
    pub fn cube(&self, key: NodeKey) -> (DVec3, f64) {
        key.cube_in((
            self.centre - DVec3::splat(self.halfsize),
            2.0 * self.halfsize,
        ))
    }

    /// The spacing of node `key`'s points: the root's, halved per level.
    pub fn spacing_at(&self, level: i32) -> f64 {
        self.spacing / f64::from(1u32 << level)
    }
}

/// An octree node's key: its level and its cell at that level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeKey {
    pub level: i32,
    pub x: i32,
    pub y: i32,
    pub z: i32,
}

impl NodeKey {
    /// The node's cube in the octree whose root cube is `root` (min corner,
    /// width): (min corner, width). The one formula of the reader and of
    /// `convert`.
    pub fn cube_in(self, (min, width): (DVec3, f64)) -> (DVec3, f64) {
        let w = width / f64::from(1u32 << self.level);
        (
            min + w * DVec3::new(f64::from(self.x), f64::from(self.y), f64::from(self.z)),
            w,
        )
    }

    /// The root node.
    pub const ROOT: NodeKey = NodeKey {
        level: 0,
        x: 0,
        y: 0,
        z: 0,
    };

    /// Whether the key names a cell of the octree (level 0 to
    /// [`MAX_LEVEL`], each coordinate in [0, 2^level)).
    fn is_valid(&self) -> bool {
        (0..=MAX_LEVEL).contains(&self.level)
            && [self.x, self.y, self.z]
                .iter()
                .all(|&c| c >= 0 && (c as i64) < (1i64 << self.level))
    }

    /// The node one level up (the root is its own parent).
    pub fn parent(&self) -> NodeKey {
        if self.level == 0 {
            return *self;
        }
        NodeKey {
            level: self.level - 1,
            x: self.x >> 1,
            y: self.y >> 1,
            z: self.z >> 1,
        }
    }

    /// The eight cells one level down.
    pub fn children(&self) -> impl Iterator<Item = NodeKey> + '_ {
        (0..8).map(move |i| NodeKey {
            level: self.level + 1,
            x: (self.x << 1) | (i & 1),
            y: (self.y << 1) | ((i >> 1) & 1),
            z: (self.z << 1) | ((i >> 2) & 1),
        })
    }

    /// Whether `self` is `other` or lies below it.
    fn within(&self, other: &NodeKey) -> bool {
        if self.level < other.level {
            return false;
        }
        let d = self.level - other.level;
        (self.x >> d, self.y >> d, self.z >> d) == (other.x, other.y, other.z)
    }
}

/// A node with points: where its LAZ chunk lies and how many it holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NodeEntry {
    pub key: NodeKey,
    /// Absolute file offset of the node's compressed points.
    pub offset: u64,
    /// Bytes of compressed points.
    pub byte_size: u64,
    pub point_count: u64,
}

/// What the hierarchy knows of a key.
#[derive(Debug, Clone, Copy)]
enum Slot {
    /// A node (point count 0: no points, though children may have some).
    Node(NodeEntry),
    /// The key's entries are in a page not read yet: (offset, size).
    Page(u64, u64),
}

/// The part of the hierarchy read so far.
#[derive(Debug, Default)]
struct Hierarchy {
    slots: HashMap<NodeKey, Slot>,
    /// Offsets of the pages read: a page referenced twice is a cycle.
    pages: HashSet<u64>,
    /// Points of the nodes read so far: never more than the header's.
    points: u64,
}

/// A COPC file opened for reading by node.
#[derive(Debug)]
pub struct CopcFile {
    path: PathBuf,
    file: File,
    file_len: u64,
    /// The LAS header (VLRs included).
    pub header: las::Header,
    pub info: CopcInfo,
    items: Vec<laz::LazItem>,
    record_len: usize,
    hierarchy: Mutex<Hierarchy>,
}

impl CopcFile {
    /// Opens a COPC file: its header, info VLR and root hierarchy page.
    /// Errors name the file and the fault.
    pub fn open(path: &Path, header: las::Header) -> Result<CopcFile> {
        let fail = |msg: String| Error::Las {
            path: path.to_path_buf(),
            msg,
        };
        let file = File::open(path).map_err(|e| fail(e.to_string()))?;
        let file_len = file.metadata().map_err(|e| fail(e.to_string()))?.len();
        let info_vlr = header
            .vlrs()
            .iter()
            .find(|v| v.is_copc_info())
            .ok_or_else(|| fail("not a COPC file: no COPC info VLR".to_string()))?;
        let info = CopcInfo::parse(&info_vlr.data).map_err(fail)?;
        let laz = header
            .laz_vlr()
            .map_err(|e| fail(format!("the LAZ VLR of a COPC file: {e}")))?;
        let record_len = usize::from(header.point_format().len());
        let copc = CopcFile {
            path: path.to_path_buf(),
            file,
            file_len,
            items: laz.items().clone(),
            record_len,
            info,
            header,
            hierarchy: Mutex::new(Hierarchy::default()),
        };
        {
            let mut h = copc.lock();
            let (offset, size) = info.root_page;
            h.slots.insert(NodeKey::ROOT, Slot::Page(offset, size));
            copc.read_page(&mut h, NodeKey::ROOT, offset, size)?;
        }
        Ok(copc)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Hierarchy> {
        self.hierarchy.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn fail(&self, msg: String) -> Error {
        Error::Las {
            path: self.path.clone(),
            msg,
        }
    }

    /// Reads the page at `offset` (`size` bytes) that holds `key`'s
    /// entries and those below it, checking every entry.
    fn read_page(&self, h: &mut Hierarchy, key: NodeKey, offset: u64, size: u64) -> Result<()> {
        let end = offset.checked_add(size).filter(|&e| e <= self.file_len);
        if size == 0 || !size.is_multiple_of(ENTRY_BYTES) || end.is_none() {
            return Err(self.fail(format!(
                "the COPC hierarchy page of node {} at byte {offset} ({size} bytes) is not a \
                 whole number of 32-byte entries inside the file's {} bytes",
                key_name(key),
                self.file_len
            )));
        }
        if !h.pages.insert(offset) {
            return Err(self.fail(format!(
                "the COPC hierarchy page at byte {offset} is referenced twice (a cycle)"
            )));
        }
        if size > MAX_PAGE_BYTES {
            return Err(self.fail(format!(
                "the COPC hierarchy page of node {} at byte {offset} declares {size} bytes, \
                 more than the {MAX_PAGE_BYTES} pointlens reads in one page",
                key_name(key)
            )));
        }
        let mut bytes = vec![0u8; size as usize];
        self.file
            .read_exact_at(&mut bytes, offset)
            .map_err(|e| self.fail(format!("reading a COPC hierarchy page: {e}")))?;
        let total = self.header.number_of_points();
        let mut found_key = false;
        for entry in bytes.chunks_exact(ENTRY_BYTES as usize) {
            found_key |= self.read_entry(h, key, entry, total)? == key;
        }
        if !found_key {
            // The page says nothing of its own key: the node has no points.
            h.slots.insert(
                key,
                Slot::Node(NodeEntry {
                    key,
                    offset: 0,
                    byte_size: 0,
                    point_count: 0,
                }),
            );
        }
        Ok(())
    }

    /// Reads one 32-byte `entry` of the page of node `key` into `h`,
    /// checking it: a key in the octree below `key`, a page that is not
    /// `key`'s own, points inside the file and no more in all than the
    /// header's `total`, a key not seen before. The entry's key.
    fn read_entry(
        &self,
        h: &mut Hierarchy,
        key: NodeKey,
        entry: &[u8],
        total: u64,
    ) -> Result<NodeKey> {
        let i = |at: usize| i32::from_le_bytes(entry[at..at + 4].try_into().expect("4 bytes"));
        let k = NodeKey {
            level: i(0),
            x: i(4),
            y: i(8),
            z: i(12),
        };
        let data_offset = u64::from_le_bytes(entry[16..24].try_into().expect("8 bytes"));
        let (byte_size, count) = (i(24), i(28));
        if !k.is_valid() || !k.within(&key) {
            return Err(self.fail(format!(
                "the COPC hierarchy page of node {} holds the key {}, which is not in \
                 the octree below it",
                key_name(key),
                key_name(k)
            )));
        }
        let slot = match count {
            -1 => {
                if k == key {
                    return Err(self.fail(format!(
                        "the COPC hierarchy page of node {} refers to itself (a cycle)",
                        key_name(key)
                    )));
                }
                Slot::Page(data_offset, u64::try_from(byte_size).unwrap_or(0))
            }
            0 => Slot::Node(NodeEntry {
                key: k,
                offset: 0,
                byte_size: 0,
                point_count: 0,
            }),
            n if n > 0 => {
                let n = n as u64;
                let fits = u64::try_from(byte_size)
                    .ok()
                    .filter(|&b| b > 0)
                    .and_then(|b| data_offset.checked_add(b))
                    .is_some_and(|e| e <= self.file_len);
                if !fits {
                    return Err(self.fail(format!(
                        "node {} of the COPC hierarchy puts its {n} points at byte \
                         {data_offset} ({byte_size} bytes), outside the file's {} bytes",
                        key_name(k),
                        self.file_len
                    )));
                }
                h.points += n;
                if h.points > total {
                    return Err(self.fail(format!(
                        "the COPC hierarchy's nodes hold more points than the header's \
                         {total} (at node {}): counts that lie",
                        key_name(k)
                    )));
                }
                Slot::Node(NodeEntry {
                    key: k,
                    offset: data_offset,
                    byte_size: byte_size as u64,
                    point_count: n,
                })
            }
            n => {
                return Err(self.fail(format!(
                    "node {} of the COPC hierarchy has a point count of {n}",
                    key_name(k)
                )))
            }
        };
        if k != key && h.slots.contains_key(&k) {
            return Err(self.fail(format!(
                "node {} appears twice in the COPC hierarchy",
                key_name(k)
            )));
        }
        h.slots.insert(k, slot);
        Ok(k)
    }

    /// The entry of node `key` (None: no such node), reading the pages on
    /// the way to it.
    pub fn entry(&self, key: NodeKey) -> Result<Option<NodeEntry>> {
        let mut h = self.lock();
        loop {
            match h.slots.get(&key).copied() {
                Some(Slot::Node(e)) => return Ok(Some(e)),
                Some(Slot::Page(offset, size)) => self.read_page(&mut h, key, offset, size)?,
                None => {
                    // An unread page above the key may hold it.
                    let mut up = key;
                    let page = loop {
                        if up.level == 0 {
                            break None;
                        }
                        up = up.parent();
                        match h.slots.get(&up) {
                            Some(Slot::Page(o, s)) => break Some((up, *o, *s)),
                            Some(Slot::Node(_)) => continue,
                            None => continue,
                        }
                    };
                    match page {
                        Some((at, offset, size)) => self.read_page(&mut h, at, offset, size)?,
                        None => return Ok(None),
                    }
                }
            }
        }
    }

    /// How many hierarchy pages have been read so far.
    pub fn pages_read(&self) -> usize {
        self.lock().pages.len()
    }

    /// Every node with points, reading every page: in file order.
    pub fn all_nodes(&self) -> Result<Vec<NodeEntry>> {
        let mut out = Vec::new();
        let mut pending = vec![NodeKey::ROOT];
        while let Some(key) = pending.pop() {
            let Some(e) = self.entry(key)? else {
                continue;
            };
            if e.point_count > 0 {
                out.push(e);
            }
            if key.level < MAX_LEVEL {
                let below = self.has_children(key);
                if below {
                    pending.extend(key.children());
                }
            }
        }
        out.sort_by_key(|e| e.offset);
        Ok(out)
    }

    /// Whether any key below `key` is known or may be in an unread page.
    fn has_children(&self, key: NodeKey) -> bool {
        let h = self.lock();
        key.children().any(|c| h.slots.contains_key(&c))
    }

    /// Decompresses the points of `node` (an independent LAZ chunk):
    /// callable from many threads at once.
    pub fn read_node(&self, node: &NodeEntry) -> Result<PointData> {
        let n = usize::try_from(node.point_count).expect("checked against the header");
        let out_len = n.checked_mul(self.record_len);
        let too_big = || {
            self.fail(format!(
                "node {} declares {n} points ({} bytes compressed), more than memory holds",
                key_name(node.key),
                node.byte_size
            ))
        };
        let mut bytes = Vec::new();
        bytes
            .try_reserve_exact(node.byte_size as usize)
            .map_err(|_| too_big())?;
        bytes.resize(node.byte_size as usize, 0);
        self.file
            .read_exact_at(&mut bytes, node.offset)
            .map_err(|e| self.fail(format!("reading node {}: {e}", key_name(node.key))))?;
        let mut out = Vec::new();
        out.try_reserve_exact(out_len.ok_or_else(too_big)?)
            .map_err(|_| too_big())?;
        out.resize(out_len.expect("checked"), 0);
        let mut decompressor = LayeredPointRecordDecompressor::new(Cursor::new(&bytes[..]));
        decompressor
            .set_fields_from(&self.items)
            .map_err(|e| self.fail(format!("the LAZ items of node {}: {e}", key_name(node.key))))?;
        // The decompressor sizes each layer's buffer from the chunk's own
        // count: the layers must fit in the node's bytes.
        let head_len = super::las::layered_head_len(&self.items, self.record_len as u64);
        if bytes.len() < head_len {
            return Err(self.fail(format!(
                "node {}'s LAZ chunk of {} bytes ends before its layers' sizes",
                key_name(node.key),
                bytes.len()
            )));
        }
        super::las::check_layers(
            &self.items,
            self.record_len as u64,
            &bytes,
            bytes.len() as u64,
        )
        .map_err(|e| self.fail(format!("node {}'s LAZ chunk: {e}", key_name(node.key))))?;
        // Without the GPS times, which nothing read by node needs, and
        // whose decoding in the `laz` crate recurses as deep as a corrupt
        // layer says (input::laz_gps).
        decompressor.set_selection(laz::DecompressionSelection::all().skip_gps_time());
        decompressor.decompress_many(&mut out).map_err(|e| {
            self.fail(format!(
                "node {} does not hold the {n} points its hierarchy entry declares ({e})",
                key_name(node.key)
            ))
        })?;
        PointDataBuilder::new()
            .for_header(&self.header)
            .build_from_bytes(out)
            .map_err(|e| self.fail(format!("the points of node {}: {e}", key_name(node.key))))
    }
}

/// A key as COPC tools print it: level-x-y-z.
fn key_name(k: NodeKey) -> String {
    format!("{}-{}-{}-{}", k.level, k.x, k.y, k.z)
}

/// A COPC file rendered by node (issue 30): each frame's cloud is the
/// points of the nodes that frame needs ([`CopcClouds::select`]), read
/// from a cache of decompressed nodes bounded by `--memory-mb`; every
/// frame's points share one origin and one color scale (the header's
/// bounds; the ranges of every node's points, read once when the file is
/// opened), so a point is the same in every frame and as the file read
/// whole has it.
pub struct CopcClouds {
    path: PathBuf,
    copc: CopcFile,
    facts: Preflight,
    origin: DVec3,
    norms: Norms,
    /// The whole file's ranges, from every node read once.
    scan: FileScan,
    bins: HeightBins,
    /// The most points one frame takes (`--point-budget`).
    point_budget: u64,
    /// The most bytes of decompressed nodes kept (`--memory-mb`).
    memory_bytes: u64,
    cache: Mutex<NodeCache>,
}

/// Decompressed nodes, the least recently used dropped first.
#[derive(Default)]
struct NodeCache {
    nodes: HashMap<NodeKey, (Arc<PointData>, u64)>,
    bytes: u64,
    tick: u64,
}

/// The nodes a frame draws.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Selection {
    /// In file order.
    pub nodes: Vec<NodeEntry>,
    pub points: u64,
    /// Whether the point budget stopped the choice before the level of
    /// detail did.
    pub capped: bool,
}

impl CopcClouds {
    /// Opens `path` (a COPC file) for rendering by node, re-centred on
    /// `origin` (default: the centre of the header's bounds on the file's
    /// grid, as the whole read's).
    pub fn open(
        path: &Path,
        origin: Option<DVec3>,
        point_budget: u64,
        memory_mb: u64,
    ) -> Result<CopcClouds> {
        let fail = |msg: String| Error::Las {
            path: path.to_path_buf(),
            msg,
        };
        let mut file = File::open(path).map_err(|e| fail(e.to_string()))?;
        let file_len = file.metadata().map_err(|e| fail(e.to_string()))?.len();
        let facts = preflight(path, &mut file, file_len)?;
        let copc = CopcFile::open(path, facts.header.clone())?;
        let root = copc
            .entry(NodeKey::ROOT)?
            .filter(|e| e.point_count > 0)
            .ok_or_else(|| fail("the COPC root node holds no points".to_string()))?;
        let data = copc.read_node(&root)?;
        let mut sample = Gather::with_capacity(data.len(), path)?;
        sample.add(&data);
        // Positions on the header's bounds (the whole read's range when the
        // header is right), colors scaled by the whole file's ranges.
        let t = facts.header.transforms();
        let b = facts.header.bounds();
        let code = |v: f64, tr: las::Transform| ((v - tr.offset) / tr.scale).round();
        let lo = [code(b.min.x, t.x), code(b.min.y, t.y), code(b.min.z, t.z)];
        let hi = [code(b.max.x, t.x), code(b.max.y, t.y), code(b.max.z, t.z)];
        if !(0..3).all(|k| lo[k] <= hi[k] && lo[k] >= i32::MIN as f64 && hi[k] <= i32::MAX as f64) {
            return Err(fail(format!(
                "the header's bounds ({:?} to {:?}) are not a box on the file's grid",
                [b.min.x, b.min.y, b.min.z],
                [b.max.x, b.max.y, b.max.z]
            )));
        }
        let (code_lo, code_hi) = (lo.map(|v| v as i32), hi.map(|v| v as i32));
        let started = std::time::Instant::now();
        let bins = HeightBins::new(code_lo[2], code_hi[2]);
        let scan = copc.scan(bins)?;
        log::info!(
            "{}: the ranges of its {} points read in {:.2} s",
            path.display(),
            scan.points,
            started.elapsed().as_secs_f64()
        );
        let norms = Norms {
            code_lo,
            code_hi,
            rgb_max: scan.rgb_max,
            int_lo: scan.int_lo,
            int_hi: scan.int_hi,
        };
        let origin = sample.finish_with(path, &facts, origin, norms)?.origin;
        Ok(CopcClouds {
            path: path.to_path_buf(),
            copc,
            facts,
            origin,
            norms,
            scan,
            bins,
            point_budget,
            memory_bytes: memory_mb.saturating_mul(1 << 20),
            cache: Mutex::new(NodeCache::default()),
        })
    }

    /// Points in the file.
    pub fn total_points(&self) -> u64 {
        self.facts.header.number_of_points()
    }

    /// What `--color` stretches over in every frame: the whole file's
    /// intensity range and 0.5–99.5 % height range, as the file read whole
    /// has them (the heights exact where the header's bounds hold every
    /// point, as the origin assumes; a second read of every node where
    /// they span more than 2^20 grid steps).
    pub fn color_ranges(&self) -> Result<ColorRanges> {
        let [lo, hi] = self.copc.height_codes(self.scan.heights, self.bins)?;
        let z = self.facts.header.transforms().z;
        let height = |code| super::las::local_coord(z.scale, z.offset, self.origin.z, code);
        Ok(ColorRanges {
            intensity: (self.scan.int_lo, self.scan.int_hi),
            elevation: (height(lo), height(hi)),
        })
    }

    /// The root node's points as a cloud: a sample of the whole, spread
    /// over it, for the first camera's framing.
    pub fn preview(&self) -> Result<PointCloud> {
        let root = self.copc.entry(NodeKey::ROOT)?.expect("checked by open");
        self.cloud(&[root])
    }

    /// The nodes a frame through `camera` draws: from the root, each node
    /// for which `decide(centre, radius, spacing)` (its cube's sphere in
    /// scene coordinates and its points' spacing, the root's halved per
    /// level) says it reaches the frame (`Some`), and its children while
    /// it is not fine enough (`Some(false)`): the splat hierarchy's own
    /// rule, `tree::sphere_decision`; the nodes whose spacing is widest on
    /// screen first, until `--point-budget`. `--lod-px 0` (`lod`) takes
    /// every node, and fails beyond the budget.
    pub fn select(
        &self,
        camera: &Camera,
        lod: Lod,
        decide: &dyn Fn(Vec3, f32, f32) -> Option<bool>,
    ) -> Result<Selection> {
        if lod.draws_all() {
            let nodes = self.copc.all_nodes()?;
            let points = nodes.iter().map(|n| n.point_count).sum();
            if points != self.total_points() {
                return Err(Error::Las {
                    path: self.path.clone(),
                    msg: format!(
                        "the COPC hierarchy's nodes hold {points} points, the header declares \
                         {}: counts that lie",
                        self.total_points()
                    ),
                });
            }
            if points > self.point_budget {
                return Err(Error::InvalidArgument(format!(
                    "{}: --lod-px 0 draws all {points} points, more than --point-budget {}; \
                     raise it",
                    self.path.display(),
                    self.point_budget
                )));
            }
            return Ok(Selection {
                nodes,
                points,
                capped: false,
            });
        }
        let info = self.copc.info;
        let sphere = |key: NodeKey| {
            let (min, width) = info.cube(key);
            let centre = min + DVec3::splat(width / 2.0) - self.origin;
            // A cube's circumscribed sphere, a little wider for the
            // points on its faces.
            (centre.as_vec3(), (width * 0.87) as f32)
        };
        // Widest spacing on screen first: (size, key), a max-heap.
        let mut queue = std::collections::BinaryHeap::new();
        let f_px = camera.f_px() as f64;
        // The spacing drawn at the sphere's nearest distance from the eye
        // (at least the spacing away: a node around the eye ranks as one
        // a spacing away, not above every other).
        let priority = |key: NodeKey| {
            let (c, r) = sphere(key);
            let spacing = info.spacing_at(key.level);
            let d = (f64::from((c - camera.eye).length() - r)).max(spacing);
            (f_px * spacing / d * 1e6) as u64
        };
        queue.push((priority(NodeKey::ROOT), NodeKey::ROOT));
        let (mut nodes, mut points, mut capped) = (Vec::new(), 0u64, false);
        while let Some((_, key)) = queue.pop() {
            let Some(entry) = self.copc.entry(key)? else {
                continue;
            };
            let (c, r) = sphere(key);
            let spacing = info.spacing_at(key.level) as f32;
            let Some(fine_enough) = decide(c, r, spacing) else {
                continue;
            };
            if points + entry.point_count > self.point_budget {
                if key == NodeKey::ROOT {
                    return Err(Error::InvalidArgument(format!(
                        "{}: the COPC root node holds {} points, more than --point-budget \
                         {}; raise it",
                        self.path.display(),
                        entry.point_count,
                        self.point_budget
                    )));
                }
                capped = true;
                break;
            }
            if entry.point_count > 0 {
                points += entry.point_count;
                nodes.push(entry);
            }
            if !fine_enough && key.level < MAX_LEVEL {
                for child in key.children() {
                    queue.push((priority(child), child));
                }
            }
        }
        nodes.sort_by_key(|n| n.offset);
        Ok(Selection {
            nodes,
            points,
            capped,
        })
    }

    /// The cloud of `nodes` (in the order given), their points
    /// decompressed on every core where the cache does not hold them.
    pub fn cloud(&self, nodes: &[NodeEntry]) -> Result<PointCloud> {
        let datas = self.nodes(nodes)?;
        let n: usize = datas.iter().map(|d| d.len()).sum();
        let mut gather = Gather::with_capacity(n, &self.path)?;
        for data in &datas {
            gather.add(data);
        }
        gather.finish_with(&self.path, &self.facts, Some(self.origin), self.norms)
    }

    /// [`CopcClouds::cloud`] of `nodes`, and each point's node's spacing
    /// (the root's halved per level), scene units.
    pub fn cloud_with_spacing(&self, nodes: &[NodeEntry]) -> Result<(PointCloud, Vec<f32>)> {
        let cloud = self.cloud(nodes)?;
        let mut spacing = Vec::with_capacity(cloud.len());
        for node in nodes {
            let s = self.copc.info.spacing_at(node.key.level) as f32;
            spacing.extend(std::iter::repeat_n(s, node.point_count as usize));
        }
        if spacing.len() != cloud.len() {
            return Err(Error::Las {
                path: self.path.clone(),
                msg: format!(
                    "the COPC nodes' entries declare {} points, their data hold {}",
                    spacing.len(),
                    cloud.len()
                ),
            });
        }
        Ok((cloud, spacing))
    }

    /// The points of `nodes`: from the cache, the rest decompressed by
    /// every thread, then the cache trimmed to `--memory-mb` (the nodes
    /// of this frame stay while the frame needs them: they are returned).
    fn nodes(&self, nodes: &[NodeEntry]) -> Result<Vec<Arc<PointData>>> {
        let mut out: Vec<Option<Arc<PointData>>> = vec![None; nodes.len()];
        {
            let mut cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
            cache.tick += 1;
            let tick = cache.tick;
            for (slot, node) in out.iter_mut().zip(nodes) {
                if let Some((data, used)) = cache.nodes.get_mut(&node.key) {
                    *used = tick;
                    *slot = Some(data.clone());
                }
            }
        }
        let missing: Vec<usize> = (0..nodes.len()).filter(|&i| out[i].is_none()).collect();
        let decoded = crate::parallel_map(&missing, crate::available_threads(), |&i| {
            self.copc.read_node(&nodes[i])
        });
        let mut cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        let tick = cache.tick;
        for (&i, data) in missing.iter().zip(decoded) {
            let data = Arc::new(data?);
            cache.bytes += node_bytes(&data);
            cache.nodes.insert(nodes[i].key, (data.clone(), tick));
            out[i] = Some(data);
        }
        // The least recently used first, never this frame's.
        while cache.bytes > self.memory_bytes {
            let oldest = cache
                .nodes
                .iter()
                .filter(|(_, (_, used))| *used < tick)
                .min_by_key(|(_, (_, used))| *used)
                .map(|(k, _)| *k);
            let Some(key) = oldest else {
                break;
            };
            if let Some((data, _)) = cache.nodes.remove(&key) {
                cache.bytes -= node_bytes(&data);
            }
        }
        Ok(out.into_iter().map(|d| d.expect("filled")).collect())
    }

    /// Keeps at most `bytes` of decompressed nodes (`--memory-mb` in
    /// bytes; the nodes of the frame being made stay).
    pub fn set_memory_bytes(&mut self, bytes: u64) {
        self.memory_bytes = bytes;
    }

    /// Bytes of decompressed nodes in the cache.
    pub fn cached_bytes(&self) -> u64 {
        self.cache.lock().unwrap_or_else(|e| e.into_inner()).bytes
    }
}

/// The bytes a decompressed node holds.
fn node_bytes(data: &PointData) -> u64 {
    data.len() as u64 * data.format().len() as u64
}

/// Bins of the heights' histogram in [`FileScan`]: a height range of up to
/// this many grid steps is ranked in one pass.
const HEIGHT_BINS: u64 = 1 << 20;

/// What the whole file's points say, read once when the file is opened
/// (every node decompressed in batches and dropped): the largest RGB code
/// and the intensities' range, which the file read whole scales its colors
/// by, and where the heights of the elevation's range lie.
#[derive(Debug, Clone, Copy)]
struct FileScan {
    points: u64,
    rgb_max: u16,
    int_lo: u16,
    int_hi: u16,
    /// The elevation's two order statistics ([`crate::color::percentile_ranks`]).
    heights: [HeightRank; 2],
}

/// An order statistic of the heights' grid codes: the `rank`-th smallest
/// (from 0) of the codes in `[start, start + width)`.
#[derive(Debug, Clone, Copy)]
struct HeightRank {
    start: i64,
    width: u64,
    rank: u64,
}

/// The heights' grid codes `[lo, hi]` (the header's bounds) in at most
/// [`HEIGHT_BINS`] bins of equal width; a code outside falls in the bin at
/// its end.
#[derive(Debug, Clone, Copy)]
struct HeightBins {
    lo: i64,
    hi: i64,
    width: u64,
}

impl HeightBins {
    fn new(lo: i32, hi: i32) -> HeightBins {
        let span = (i64::from(hi) - i64::from(lo) + 1) as u64;
        HeightBins {
            lo: i64::from(lo),
            hi: i64::from(hi),
            width: span.div_ceil(HEIGHT_BINS),
        }
    }

    fn count(&self) -> usize {
        ((self.hi - self.lo) as u64 / self.width + 1) as usize
    }

    fn of(&self, code: i32) -> usize {
        ((i64::from(code).clamp(self.lo, self.hi) - self.lo) as u64 / self.width) as usize
    }

    /// The bin of the `rank`-th smallest code (`counts`: per bin), as a
    /// rank within it.
    fn find(&self, counts: &[u64], rank: u64) -> HeightRank {
        let mut below = 0u64;
        for (b, &n) in counts.iter().enumerate() {
            if rank < below + n {
                return HeightRank {
                    start: self.lo + b as i64 * self.width as i64,
                    width: self.width,
                    rank: rank - below,
                };
            }
            below += n;
        }
        HeightRank {
            start: self.hi,
            width: 1,
            rank: 0,
        }
    }
}

impl CopcFile {
    /// Calls `f` with the points of each of `nodes`, in order, decompressed
    /// by every thread in batches of about [`super::las::CHUNK_POINTS`]
    /// points: the memory of one batch at a time.
    fn stream(&self, nodes: &[NodeEntry], f: &mut dyn FnMut(&PointData)) -> Result<()> {
        let threads = crate::available_threads().max(1);
        let mut rest = nodes;
        while !rest.is_empty() {
            let mut points = 0;
            let len = rest
                .iter()
                .take_while(|n| {
                    let take = points < super::las::CHUNK_POINTS;
                    points += n.point_count;
                    take
                })
                .count();
            let (batch, after) = rest.split_at(len);
            rest = after;
            for data in crate::parallel_map(batch, threads, |node| self.read_node(node)) {
                f(&data?);
            }
        }
        Ok(())
    }

    /// Every node with points, refused in one line where their counts do
    /// not add up to the header's.
    fn all_nodes_checked(&self) -> Result<Vec<NodeEntry>> {
        let nodes = self.all_nodes()?;
        let points: u64 = nodes.iter().map(|n| n.point_count).sum();
        let total = self.header.number_of_points();
        if points != total {
            return Err(self.fail(format!(
                "the COPC hierarchy's nodes hold {points} points, the header declares {total}: \
                 counts that lie"
            )));
        }
        Ok(nodes)
    }

    /// Reads every node once ([`FileScan`]); `heights` bins the grid codes
    /// of z.
    fn scan(&self, heights: HeightBins) -> Result<FileScan> {
        let nodes = self.all_nodes_checked()?;
        let mut counts = vec![0u64; heights.count()];
        let (mut rgb_max, mut int_lo, mut int_hi) = (0u16, u16::MAX, 0u16);
        self.stream(&nodes, &mut |data| {
            for z in data.z_raw() {
                counts[heights.of(z)] += 1;
            }
            for i in data.intensity() {
                (int_lo, int_hi) = (int_lo.min(i), int_hi.max(i));
            }
            if let Some(rgb) = data.rgb() {
                for (r, g, b) in rgb {
                    rgb_max = rgb_max.max(r).max(g).max(b);
                }
            }
        })?;
        let points = self.header.number_of_points();
        let n = usize::try_from(points).unwrap_or(usize::MAX);
        let (lo_at, hi_at) = crate::color::percentile_ranks(n, crate::color::ELEVATION_TAIL);
        Ok(FileScan {
            points,
            rgb_max,
            int_lo,
            int_hi,
            heights: [lo_at, hi_at].map(|r| heights.find(&counts, r as u64)),
        })
    }

    /// The grid codes of the order statistics `ranks` of z (each found in
    /// its bin by [`CopcFile::scan`]): one more read of every node where a
    /// bin is wider than one code.
    fn height_codes(&self, ranks: [HeightRank; 2], bins: HeightBins) -> Result<[i32; 2]> {
        let exact = |r: &HeightRank| (r.start.clamp(bins.lo, bins.hi)) as i32;
        if ranks.iter().all(|r| r.width == 1) {
            return Ok(ranks.map(|r| exact(&r)));
        }
        let mut counts: Vec<Vec<u64>> = ranks.iter().map(|r| vec![0; r.width as usize]).collect();
        let nodes = self.all_nodes_checked()?;
        self.stream(&nodes, &mut |data| {
            for z in data.z_raw() {
                let z = i64::from(z).clamp(bins.lo, bins.hi);
                for (r, c) in ranks.iter().zip(counts.iter_mut()) {
                    if (r.start..r.start + r.width as i64).contains(&z) {
                        c[(z - r.start) as usize] += 1;
                    }
                }
            }
        })?;
        let mut codes = [0i32; 2];
        for ((r, c), code) in ranks.iter().zip(&counts).zip(codes.iter_mut()) {
            let fine = HeightBins {
                lo: r.start,
                hi: r.start + r.width as i64 - 1,
                width: 1,
            };
            *code = exact(&fine.find(c, r.rank));
        }
        Ok(codes)
    }
}
