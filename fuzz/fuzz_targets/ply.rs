//! The PLY reader on arbitrary bytes: `load_cloud` must return a cloud or
//! an error, never panic, hang or allocate without bound.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The reader takes a path: a file in memory-backed /dev/shm, one per
    // fuzzing process.
    let path = std::path::PathBuf::from(format!(
        "/dev/shm/pointlens-fuzz-{}.ply",
        std::process::id()
    ));
    std::fs::write(&path, data).expect("write the input");
    if let Ok(cloud) = pointlens::input::load_cloud(&path, None, &mut |_, _| {}) {
        // What a render does next with a loaded cloud, on the CPU.
        let _ = cloud.bounds();
        assert_eq!(cloud.positions.len(), cloud.colors.len());
    }
});
