//! 3D Gaussian PLY files on arbitrary bytes: what `is_gaussian_file` takes
//! goes through the memory check and `load_gaussians` as `render` reads it
//! (header, property layout, SH degree, every encoding, the activations):
//! a scene or an error, never a panic, a hang or an unbounded allocation.
//! A scene's arrays agree and its values are what the activations give.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pointlens::input::gaussians::{check_fits, is_gaussian_file, load_gaussians};

fuzz_target!(|data: &[u8]| {
    let path = std::path::PathBuf::from(format!(
        "/dev/shm/pointlens-fuzz-{}.ply",
        std::process::id()
    ));
    std::fs::write(&path, data).expect("write the input");
    if !is_gaussian_file(&path) || check_fits(&path, 1024).is_err() {
        return;
    }
    let loaded = load_gaussians(&path);
    // Triage: what an input gives (`POINTLENS_FUZZ_DEBUG=1 fuzz/target/.../gaussians FILE`).
    if std::env::var_os("POINTLENS_FUZZ_DEBUG").is_some() {
        match &loaded {
            Ok(scene) => eprintln!("{} Gaussians of SH degree {}", scene.len(), scene.sh_degree),
            Err(e) => eprintln!("error: {e}"),
        }
    }
    if let Ok(scene) = loaded {
        let n = scene.len();
        assert!(scene.sh_degree <= 3, "{}", scene.sh_degree);
        assert_eq!(scene.scales.len(), n);
        assert_eq!(scene.rotations.len(), n);
        assert_eq!(scene.opacities.len(), n);
        assert_eq!(scene.sh.len(), n * scene.coefficients() * 3);
        for g in 0..n {
            assert!(scene.positions[g].is_finite());
            assert!(scene.scales[g].is_finite() && scene.scales[g].min_element() >= 0.0);
            assert!(scene.rotations[g].is_finite());
            assert!((0.0..=1.0).contains(&scene.opacities[g]));
            assert!(scene.sh_of(g).iter().all(|v| v.is_finite()));
        }
    }
});
