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
use std::sync::Mutex;

use glam::DVec3;
use las::{PointData, PointDataBuilder};
use laz::record::{LayeredPointRecordDecompressor, RecordDecompressor};

use crate::error::{Error, Result};

/// Bytes of one hierarchy entry: key (4 × i32), offset (u64), byte size
/// (i32), point count (i32).
const ENTRY_BYTES: u64 = 32;

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
        let width = 2.0 * self.halfsize / f64::from(1u32 << key.level);
        let min = self.centre - DVec3::splat(self.halfsize)
            + width * DVec3::new(f64::from(key.x), f64::from(key.y), f64::from(key.z));
        (min, width)
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
        let mut bytes = vec![0u8; size as usize];
        self.file
            .read_exact_at(&mut bytes, offset)
            .map_err(|e| self.fail(format!("reading a COPC hierarchy page: {e}")))?;
        let total = self.header.number_of_points();
        let mut found_key = false;
        for entry in bytes.chunks_exact(ENTRY_BYTES as usize) {
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
            found_key |= k == key;
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
        let mut bytes = vec![0u8; node.byte_size as usize];
        self.file
            .read_exact_at(&mut bytes, node.offset)
            .map_err(|e| self.fail(format!("reading node {}: {e}", key_name(node.key))))?;
        let n = usize::try_from(node.point_count).expect("checked against the header");
        let mut out = vec![0u8; n * self.record_len];
        let mut decompressor = LayeredPointRecordDecompressor::new(Cursor::new(&bytes[..]));
        decompressor
            .set_fields_from(&self.items)
            .map_err(|e| self.fail(format!("the LAZ items of node {}: {e}", key_name(node.key))))?;
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
