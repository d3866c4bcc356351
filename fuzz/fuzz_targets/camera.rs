//! Camera files and camera paths on arbitrary text: parsing, the value
//! checks and `resolve` (auto-framing and the automatic aperture against a
//! small fixed cloud), and a path's frames — an error or a camera, never a
//! panic. A resolved camera's numbers are finite.
#![no_main]

use glam::Vec3;
use libfuzzer_sys::fuzz_target;
use pointlens::camera::{self, CameraSpec};
use pointlens::sequence::CameraPath;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let points = [
        Vec3::new(-1.0, -0.5, -0.2),
        Vec3::new(1.0, 0.5, 0.3),
        Vec3::ZERO,
    ];
    let (lo, hi) = (Vec3::new(-1.0, -0.5, -0.2), Vec3::new(1.0, 0.5, 0.3));
    let resolve = |spec: &CameraSpec| {
        let Ok(scene) = spec.in_scene(glam::DVec3::new(10.0, 20.0, 30.0)) else {
            return;
        };
        if let Ok(cam) = camera::resolve(&scene, lo, hi, &points) {
            let _ = spec.require_complete();
            assert!(cam.fovy_deg > 0.0 && cam.fovy_deg < 180.0, "{cam:?}");
            let _ = cam.to_json();
        }
    };
    if let Ok(spec) = CameraSpec::from_json_str(text) {
        resolve(&spec);
    }
    if let Ok(path) = serde_json::from_str::<CameraPath>(text) {
        if path.check().is_ok() {
            let (first, last) = path.frames();
            // At most a few hundred frames of a long path.
            let step = ((last - first) / 256).max(1);
            let mut f = first;
            while f <= last {
                resolve(&path.spec_at(f));
                f = match f.checked_add(step) {
                    Some(next) => next,
                    None => break,
                };
            }
        }
    }
});
