//! Writes a cloud's splats as pointlens renders them — position, world
//! diameter and linear RGB — for another renderer to draw the same splats
//! (`scripts/bench-vs-mitsuba` builds Mitsuba 3 squares from it).
//!
//! `cargo run --release --example export_splats -- INPUT OUT.bin [--splat-size W]`
//!
//! INPUT is any cloud `render` reads (PLY, LAS, LAZ), in the coordinates
//! `render` draws it in (a LAS file re-centred as by default).
//!
//! The splats are the leaves of the splat hierarchy that `Renderer::upload`
//! builds (`render::splat_tree`), in its Morton order: by default each
//! point's diameter is the tree's local spacing times
//! `render::SPACING_TO_DIAMETER` (DESIGN §3); `--splat-size W` gives every
//! point W, as `render --splat-size` does. Colors are the UNORM16 values
//! the raster reads. They are what `render --lod-px 0` draws.
//!
//! Output, little endian: the 8 bytes `PLSPLAT1`, the point count as u64,
//! then per point 7 f32: x y z diameter r g b (colors linear, in [0, 1]).

use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Context as _};
use pointlens::input::load_cloud;
use pointlens::render::{splat_tree, SplatSize};
use pointlens::tree::median;

const MAGIC: &[u8; 8] = b"PLSPLAT1";

fn main() {
    // One line on stderr and a non-zero exit status, as `pointlens` does.
    if let Err(e) = run() {
        eprintln!("export_splats: {e}");
        std::process::exit(1);
    }
}

fn run() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let mut positional = Vec::new();
    let mut splat_size = None;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--splat-size" => {
                let v = args.next().context("--splat-size needs a value")?;
                let Ok(w) = v.parse::<f32>() else {
                    bail!("--splat-size: not a number: {v}");
                };
                if !(w.is_finite() && w > 0.0) {
                    bail!("--splat-size must be a positive number, not {w}");
                }
                splat_size = Some(w);
            }
            _ if a.starts_with("--") => bail!("unknown option {a}"),
            _ => positional.push(PathBuf::from(a)),
        }
    }
    let [input, output] = positional.as_slice() else {
        bail!("usage: export_splats INPUT OUT.bin [--splat-size W]");
    };
    let cloud = load_cloud(input, None, &mut |_, _| {})?;
    let splat = splat_size.map_or(SplatSize::Spacing, SplatSize::World);
    let tree = splat_tree(&cloud, splat, pointlens::available_threads());
    let d: Vec<f32> = tree.leaves().iter().map(|v| v.position_size[3]).collect();

    let mut bytes = Vec::with_capacity(16 + cloud.len() * 28);
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&(cloud.len() as u64).to_le_bytes());
    for leaf in tree.leaves() {
        let [x, y, z, d] = leaf.position_size;
        // Codes of the tree's colour scale (1 for a cloud within white).
        let c = leaf.color.map(|u| u as f32 / 65535.0 * tree.color_scale());
        for v in [x, y, z, d, c[0], c[1], c[2]] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    // Written beside the target and renamed: no half-written file.
    let tmp = output.with_extension("bin.partial");
    let written = std::fs::File::create(&tmp)
        .and_then(|mut file| file.write_all(&bytes).and_then(|_| file.sync_all()))
        .and_then(|_| std::fs::rename(&tmp, output));
    if let Err(e) = written {
        // Best effort: the error below is the one to report.
        let _ = std::fs::remove_file(&tmp);
        bail!("writing {}: {e}", output.display());
    }
    eprintln!(
        "{}: {} splats, diameter median {}",
        output.display(),
        cloud.len(),
        median(d)
    );
    Ok(())
}
