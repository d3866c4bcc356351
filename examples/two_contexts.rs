//! A reproducer for a heap corruption seen at the exit of a test process
//! that ran two tests at once: two Vulkan contexts (lavapipe under the
//! validation layer) created, used for one small frame and destroyed on two
//! threads at the same time, `ROUNDS` times, then the process exits.
//!
//! ```sh
//! for i in $(seq 100); do MALLOC_CHECK_=3 target/release/examples/two_contexts || echo "abort $i"; done
//! ```

use std::sync::Arc;

use pointlens::vk::{Context, ContextOptions};

const ROUNDS: usize = 4;

fn one_context() -> pointlens::Result<()> {
    let ctx: Arc<Context> = Context::new(&ContextOptions {
        validation: true,
        device: Some("llvmpipe".into()),
    })?;
    let renderer = pointlens::render::Renderer::new(&ctx)?;
    drop(renderer);
    ctx.check_validation()
}

fn main() -> pointlens::Result<()> {
    for _ in 0..ROUNDS {
        let threads: Vec<_> = (0..2).map(|_| std::thread::spawn(one_context)).collect();
        for t in threads {
            t.join().expect("no panic")?;
        }
    }
    Ok(())
}
