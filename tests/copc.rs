//! COPC by node (issue 30; docs/ARCHITECTURE.md, "COPC by node"): the
//! hierarchy read page by page from absolute offsets (PDAL's root page
//! written last, las-rs#157), nodes decompressed on every core, the cloud
//! equal to the file read as the LAZ stream it also is, and a bad
//! hierarchy refused in one line.

mod common;

use std::path::{Path, PathBuf};

use common::{assert_fails, root, scratch};
use pointlens::input::copc::{CopcFile, NodeKey};
use pointlens::input::las::{load_las, load_las_stream};
use pointlens::PointCloud;

/// PDAL's COPC test file (1065 points in 65 nodes on 4 levels, one
/// hierarchy page): tests/data/README.md.
fn pdal_file() -> PathBuf {
    root().join("tests/data/pdal-1.2-with-color.copc.laz")
}

fn header_of(path: &Path) -> las::Header {
    las::Reader::from_path(path).unwrap().header().clone()
}

fn assert_same_cloud(a: &PointCloud, b: &PointCloud) {
    assert_eq!(a.len(), b.len());
    assert!(
        a.positions
            .iter()
            .zip(&b.positions)
            .all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits)),
        "positions differ"
    );
    assert_eq!(a.colors, b.colors);
    assert_eq!(a.origin, b.origin);
    assert_eq!(a.classifications, b.classifications);
    assert_eq!(a.intensities, b.intensities);
    assert_eq!(a.returns, b.returns);
    assert_eq!(a.has_rgb, b.has_rgb);
}

/// Both COPC fixtures read by node equal their LAZ stream, bit for bit.
#[test]
fn a_copc_file_read_by_node_is_its_laz_stream() {
    for path in [pdal_file(), root().join("tests/data/autzen.copc.laz")] {
        let by_node = load_las(&path, None, &mut |_, _| {}).unwrap();
        let stream = load_las_stream(&path, None, &mut |_, _| {}).unwrap();
        assert_same_cloud(&by_node, &stream);
    }
    let copc = CopcFile::open(&pdal_file(), header_of(&pdal_file())).unwrap();
    let nodes = copc.all_nodes().unwrap();
    assert_eq!(nodes.len(), 65);
    assert_eq!(nodes.iter().map(|n| n.point_count).sum::<u64>(), 1065);
    assert_eq!(nodes.iter().map(|n| n.key.level).max(), Some(3));
}

/// The bytes of a COPC file and where its octree's pages are.
#[derive(Clone)]
struct Layout {
    bytes: Vec<u8>,
}

/// Offset of the info VLR's payload (the first VLR, after the 375-byte
/// LAS 1.4 header and its 54-byte VLR header).
const INFO: usize = 375 + 54;

impl Layout {
    fn read(path: &Path) -> Layout {
        Layout {
            bytes: std::fs::read(path).unwrap(),
        }
    }

    fn root_page(&self) -> (u64, u64) {
        let u = |at: usize| u64::from_le_bytes(self.bytes[at..at + 8].try_into().unwrap());
        (u(INFO + 40), u(INFO + 48))
    }

    fn set_root_page(&mut self, offset: u64, size: u64) {
        self.bytes[INFO + 40..INFO + 48].copy_from_slice(&offset.to_le_bytes());
        self.bytes[INFO + 48..INFO + 56].copy_from_slice(&size.to_le_bytes());
    }

    /// The root page's 32-byte entries.
    fn entries(&self) -> Vec<[u8; 32]> {
        let (offset, size) = self.root_page();
        self.bytes[offset as usize..(offset + size) as usize]
            .chunks_exact(32)
            .map(|e| e.try_into().unwrap())
            .collect()
    }

    fn write(&self, dir: &Path, name: &str) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, &self.bytes).unwrap();
        path
    }
}

fn key_of(entry: &[u8; 32]) -> NodeKey {
    let i = |at: usize| i32::from_le_bytes(entry[at..at + 4].try_into().unwrap());
    NodeKey {
        level: i(0),
        x: i(4),
        y: i(8),
        z: i(12),
    }
}

fn within(k: NodeKey, of: NodeKey) -> bool {
    let d = k.level - of.level;
    d >= 0 && (k.x >> d, k.y >> d, k.z >> d) == (of.x, of.y, of.z)
}

/// An entry for `key` pointing to a page (point count −1).
fn page_entry(key: NodeKey, offset: u64, size: u64) -> [u8; 32] {
    let mut e = [0u8; 32];
    for (i, v) in [key.level, key.x, key.y, key.z].iter().enumerate() {
        e[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
    }
    e[16..24].copy_from_slice(&offset.to_le_bytes());
    e[24..28].copy_from_slice(&(size as i32).to_le_bytes());
    e[28..32].copy_from_slice(&(-1i32).to_le_bytes());
    e
}

/// PDAL's file with the subtree of node 1-0-0-0 moved to a child page and
/// the root page rewritten after it, at the file's end: the layout PDAL
/// and untwine write for large files (root page last, las-rs#157).
fn with_child_page() -> Layout {
    let mut layout = Layout::read(&pdal_file());
    let sub = NodeKey {
        level: 1,
        x: 0,
        y: 0,
        z: 0,
    };
    let (below, rest): (Vec<_>, Vec<_>) = layout
        .entries()
        .into_iter()
        .partition(|e| within(key_of(e), sub));
    let child_offset = layout.bytes.len() as u64;
    let child_size = 32 * below.len() as u64;
    for e in &below {
        layout.bytes.extend_from_slice(e);
    }
    let root_offset = layout.bytes.len() as u64;
    let mut root_entries = rest;
    root_entries.push(page_entry(sub, child_offset, child_size));
    for e in &root_entries {
        layout.bytes.extend_from_slice(e);
    }
    layout.set_root_page(root_offset, 32 * root_entries.len() as u64);
    layout
}

/// A child page before a root page written last is followed, and only
/// when a walk reaches it.
#[test]
fn a_root_page_written_last_is_followed_lazily() {
    let dir = scratch("copc-pages");
    let path = with_child_page().write(dir.path(), "child-page.copc.laz");
    let cloud = load_las(&path, None, &mut |_, _| {}).unwrap();
    let original = load_las(&pdal_file(), None, &mut |_, _| {}).unwrap();
    assert_same_cloud(&cloud, &original);

    let copc = CopcFile::open(&path, header_of(&path)).unwrap();
    assert_eq!(copc.pages_read(), 1, "the root page only");
    let elsewhere = NodeKey {
        level: 1,
        x: 1,
        y: 0,
        z: 0,
    };
    assert!(copc.entry(elsewhere).unwrap().is_some());
    assert_eq!(copc.pages_read(), 1, "a node outside the child page");
    let inside = NodeKey {
        level: 3,
        x: 1,
        y: 1,
        z: 0,
    };
    let entry = copc.entry(inside).unwrap().expect("node 3-1-1-0");
    assert_eq!(copc.pages_read(), 2, "the child page, once reached");
    assert_eq!(entry.point_count, 18);
    assert_eq!(copc.read_node(&entry).unwrap().len(), 18);
}

/// A bad hierarchy is one line naming the fault, for `info` and `render`.
#[test]
fn a_bad_copc_hierarchy_is_one_line() {
    let dir = scratch("copc-bad");
    let out = dir.path().join("out.png");
    let check = |layout: &Layout, name: &str, phrase: &str| {
        let path = layout.write(dir.path(), name);
        let p = path.to_str().unwrap();
        assert_fails(&["info", p], phrase, &out);
        assert_fails(&["render", p, "-o", out.to_str().unwrap()], phrase, &out);
    };
    let original = Layout::read(&pdal_file());
    let (root_offset, root_size) = original.root_page();

    // A truncated page: the root page written last runs past the file's
    // end (a truncated hierarchy EVLR is the preflight's: "truncated").
    let mut truncated = with_child_page();
    let (last_offset, last_size) = truncated.root_page();
    truncated
        .bytes
        .truncate((last_offset + last_size / 2) as usize);
    check(&truncated, "truncated.copc.laz", "hierarchy page");
    let mut evlr = original.clone();
    evlr.bytes.truncate((root_offset + root_size / 2) as usize);
    check(&evlr, "truncated-evlr.copc.laz", "truncated");

    // A node's points outside the file.
    let mut outside = original.clone();
    let at = (root_offset + 32 * 3 + 16) as usize;
    let far = outside.bytes.len() as u64 + 1000;
    outside.bytes[at..at + 8].copy_from_slice(&far.to_le_bytes());
    check(&outside, "outside.copc.laz", "outside the file");

    // A cycle: the child page refers back to the root page.
    let mut cycle = with_child_page();
    let (child_offset, _) = {
        let e = cycle.entries();
        let last = e.last().unwrap();
        (
            u64::from_le_bytes(last[16..24].try_into().unwrap()),
            u64::from_le_bytes(last[24..32].try_into().unwrap()),
        )
    };
    let (new_root, new_root_size) = cycle.root_page();
    let back = page_entry(
        NodeKey {
            level: 2,
            x: 0,
            y: 0,
            z: 0,
        },
        new_root,
        new_root_size,
    );
    // Node 2-0-0-0's entry in the child page becomes a page: the root's.
    let child_entries = (cycle.bytes.len() as u64 - new_root_size - child_offset) / 32;
    for i in 0..child_entries {
        let at = (child_offset + 32 * i) as usize;
        let e: [u8; 32] = cycle.bytes[at..at + 32].try_into().unwrap();
        if key_of(&e).level == 2 && key_of(&e).x == 0 && key_of(&e).y == 0 {
            cycle.bytes[at..at + 32].copy_from_slice(&back);
        }
    }
    check(&cycle, "cycle.copc.laz", "cycle");

    // Counts that lie: one node claims a point more (more than the
    // header's), one a point fewer (fewer than the header's).
    let count_at = (root_offset + 28) as usize;
    let count = i32::from_le_bytes(original.bytes[count_at..count_at + 4].try_into().unwrap());
    for (delta, name) in [(1, "more.copc.laz"), (-1, "fewer.copc.laz")] {
        let mut lie = original.clone();
        lie.bytes[count_at..count_at + 4].copy_from_slice(&(count + delta).to_le_bytes());
        check(&lie, name, "counts that lie");
    }
}
