//! COPC files read by node on arbitrary bytes: the input is made to start
//! as a COPC file (`LASF`, and the first VLR's user `copc`, record 1, where
//! `input::copc::is_copc` looks), so that the fuzzer's bytes reach the
//! header preflight, the COPC info VLR, the hierarchy pages and the
//! nodes. `HostScene::open` (the whole file's colour ranges, the root's
//! preview), then a camera framed on the preview, the nodes it selects at
//! the default level of detail and at `--lod-px 0`, and their points: an
//! error or a result, never a panic, a hang or an unbounded allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pointlens::camera::{self, CameraSpec};
use pointlens::color::ColorMode;
use pointlens::options::Lod;
use pointlens::scene::{HostScene, SceneSpec};
use pointlens::tree::{sphere_decision, Widening};

/// Where `is_copc` reads the first VLR's user id and record id.
const VLR_USER: usize = 375 + 2;
const VLR_RECORD: usize = 375 + 18;

fuzz_target!(|data: &[u8]| {
    let mut bytes = data.to_vec();
    if bytes.len() < VLR_RECORD + 2 {
        bytes.resize(VLR_RECORD + 2, 0);
    }
    bytes[..4].copy_from_slice(b"LASF");
    bytes[VLR_USER..VLR_USER + 16].copy_from_slice(b"copc\0\0\0\0\0\0\0\0\0\0\0\0");
    bytes[VLR_RECORD..VLR_RECORD + 2].copy_from_slice(&1u16.to_le_bytes());
    let path = std::path::PathBuf::from(format!(
        "/dev/shm/pointlens-fuzz-{}.copc.laz",
        std::process::id()
    ));
    std::fs::write(&path, &bytes).expect("write the input");
    // The last byte picks the colour mode (the whole file's ranges are read
    // when one is given), as `--color` would.
    let color = match data.last().map(|b| b % 4) {
        Some(1) => Some(ColorMode::Intensity),
        Some(2) => Some(ColorMode::Elevation),
        Some(3) => Some(ColorMode::Rgb),
        _ => None,
    };
    let spec = SceneSpec {
        memory_mb: 1024,
        point_budget: Some(1_000_000),
        color,
        ..SceneSpec::of(&path)
    };
    let opened = HostScene::open(&spec, &mut |_, _| {});
    // Triage: what an input gives (`POINTLENS_FUZZ_DEBUG=1 fuzz/target/.../copc FILE`).
    let debug = std::env::var_os("POINTLENS_FUZZ_DEBUG").is_some();
    if debug {
        match &opened {
            Ok(scene) => eprintln!("opened as {:?}", scene.kind()),
            Err(e) => eprintln!("error: {e}"),
        }
    }
    let Ok(HostScene::Copc {
        mut clouds,
        preview,
        ..
    }) = opened
    else {
        return;
    };
    assert_eq!(preview.positions.len(), preview.colors.len());
    clouds.set_memory_bytes(64 << 20);
    let (lo, hi) = preview.bounds();
    let Ok(scene) = CameraSpec::default().in_scene(preview.origin) else {
        return;
    };
    let Ok(mut cam) = camera::resolve_for(&scene, lo, hi, &preview.positions, preview.z_up) else {
        return;
    };
    cam.width = 96;
    cam.height = 72;
    let widening = Widening {
        background_coc_px: cam.coc_px(f32::INFINITY),
        splat_px: 0.0,
    };
    for lod in [Lod::default(), Lod::ALL] {
        let decide = |c, r, s| sphere_decision(&cam, lod, widening, c, r, s);
        let selection = clouds.select(&cam, lod, &decide);
        if debug {
            eprintln!("{lod:?}: {:?}", selection.as_ref().map(|s| (s.nodes.len(), s.points)));
        }
        if let Ok(selection) = selection {
            let read = clouds.cloud_with_spacing(&selection.nodes);
            if debug {
                eprintln!("read: {:?}", read.as_ref().map(|(c, _)| c.len()).map_err(|e| e.to_string()));
            }
            if let Ok((cloud, spacing)) = read {
                assert_eq!(cloud.positions.len(), cloud.colors.len());
                assert_eq!(cloud.positions.len(), spacing.len());
            }
        }
    }
});
