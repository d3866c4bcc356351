//! The heap corruption of long validated runs on Debian 12
//! (docs/bench/history/heap-at-exit.md), held by a reproducer. The
//! Khronos validation layer 1.3.239 retires submissions on threads of its
//! own and lets go of a submission's command buffers only after it has
//! woken the threads waiting for it. When the application destroys the
//! command pool in between, the last reference to a command buffer's
//! state falls to the layer's thread, whose destructor erases the buffer's
//! debug labels from a map that the application's thread is writing as it
//! records labels into the next frame, without the lock those writes take
//! (fixed upstream in 1.3.243, "layers: Fix debug label race conditions").
//! A pause after every futex wake (`tests/data/slow_wake.c`, preloaded)
//! holds the layer's thread in that window: 1,000 frames of 64 labelled
//! passes, each frame with its own pool, then aborted in 11 processes of
//! 16 (a C++ exception out of the layer, or glibc's "malloc_consolidate():
//! unaligned fastbin chunk detected", the message of the aborts seen in
//! CI), and in none of 16 since each frame waits for a flush submission
//! under validation (`Frame`, `Context::queue_lock`).

mod common;

use std::process::Command;

use pointlens::vk::{Access, Buffer, Frame};

/// Set in the child process, which renders the frames.
const CHILD: &str = "POINTLENS_LABEL_RACE_CHILD";

/// The frames: each a new command pool with `passes` labelled passes (a
/// fill each), submitted, waited for and destroyed, as pointlens's are;
/// under validation, with the canary after them (`common::with_gpu`).
fn frames(count: u32, passes: u32) {
    common::with_gpu(|ctx| {
        let buffer = Buffer::new(
            ctx,
            "label race",
            256,
            ash::vk::BufferUsageFlags::STORAGE_BUFFER | ash::vk::BufferUsageFlags::TRANSFER_DST,
            gpu_allocator::MemoryLocation::GpuOnly,
        )
        .unwrap();
        for f in 0..count {
            let mut frame = Frame::begin(ctx, "label race").unwrap();
            for p in 0..passes {
                frame.pass("label race.fill", |rec| {
                    // After the previous pass's fill.
                    rec.memory_barrier(Access::FILL, Access::FILL);
                    rec.fill_u32(&buffer, f + p);
                });
            }
            frame.submit_and_wait().unwrap();
        }
    });
}

/// Parent: builds the shim and runs the frames in three child processes
/// under it, each of which must exit cleanly. Child: the frames, on the
/// main thread (where the race shows most: before the flush, 11 of 16
/// such processes aborted; on a test harness's thread, rarely).
fn main() {
    if std::env::var_os(CHILD).is_some() {
        frames(1_000, 64);
        return;
    }
    // The shim, built here (a C compiler is part of the build's needs:
    // shaderc is compiled from source).
    let dir = common::scratch("label-race");
    let shim = dir.join("slow_wake.so");
    let source = common::root().join("tests/data/slow_wake.c");
    let cc = Command::new("cc")
        .args(["-O2", "-shared", "-fPIC", "-o"])
        .arg(&shim)
        .arg(&source)
        .arg("-ldl")
        .output()
        .expect("run cc (a C compiler builds the test's shim)");
    assert!(
        cc.status.success(),
        "cc: {}",
        String::from_utf8_lossy(&cc.stderr)
    );
    // Three processes of 1,000 frames: before the flush, the test failed
    // in 4 of its 6 runs here (a child's abort ends it).
    for run in 1..=3 {
        let child = Command::new(std::env::current_exe().unwrap())
            .env(CHILD, "1")
            .env("LD_PRELOAD", &shim)
            .output()
            .unwrap();
        assert!(
            child.status.success(),
            "run {run}: the frames under the shim failed ({}):\n{}",
            child.status,
            String::from_utf8_lossy(&child.stderr)
        );
    }
    println!("label_race: 3 processes of 1,000 validated frames under the shim, no abort");
}
