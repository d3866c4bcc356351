//! The LAS/LAZ reader on arbitrary bytes (the file starts `LASF` for the
//! reader to take it as LAS whatever the fuzzer writes after): a cloud or
//! an error, never a panic, a hang or an unbounded allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let (ext, body) = match data.split_first() {
        Some((b, rest)) if b & 1 == 1 => ("laz", rest),
        Some((_, rest)) => ("las", rest),
        None => return,
    };
    let path = std::path::PathBuf::from(format!(
        "/dev/shm/pointlens-fuzz-{}.{ext}",
        std::process::id()
    ));
    let mut bytes = b"LASF".to_vec();
    bytes.extend_from_slice(body.get(4..).unwrap_or(&[]));
    std::fs::write(&path, &bytes).expect("write the input");
    if let Ok(cloud) = pointlens::input::load_cloud(&path, None, &mut |_, _| {}) {
        let _ = cloud.bounds();
        assert_eq!(cloud.positions.len(), cloud.colors.len());
    }
});
