//! One command buffer recorded, submitted and waited for, with every pass
//! inside it given a debug label and a GPU timestamp scope (`Frame::pass`).

use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use super::Context;
use crate::error::{Error, Result, VkContext};

/// Time spent by one named pass (summed when the name occurs several times).
#[derive(Debug, Clone, PartialEq)]
pub struct PassTiming {
    pub name: String,
    /// GPU time from timestamp queries, milliseconds.
    pub gpu_ms: f64,
    /// How many scopes of this name the frame had (e.g. one per SSAA sample).
    pub count: u32,
}

/// GPU timings of a frame's passes, in recording order, and its wall time.
#[derive(Debug, Clone, Default)]
pub struct FrameTimings {
    pub passes: Vec<PassTiming>,
    /// From the start of command recording to the results being readable
    /// on the host, milliseconds.
    pub wall_ms: f64,
}

impl FrameTimings {
    /// Sum of the passes' GPU times.
    pub fn gpu_total_ms(&self) -> f64 {
        self.passes.iter().map(|p| p.gpu_ms).sum()
    }

    /// Appends another frame's passes (and wall time), merging equal names.
    pub fn merge(&mut self, other: &FrameTimings) {
        for p in &other.passes {
            add_pass(&mut self.passes, &p.name, p.gpu_ms, p.count);
        }
        self.wall_ms += other.wall_ms;
    }
}

fn add_pass(passes: &mut Vec<PassTiming>, name: &str, gpu_ms: f64, count: u32) {
    match passes.iter_mut().find(|p| p.name == name) {
        Some(p) => {
            p.gpu_ms += gpu_ms;
            p.count += count;
        }
        None => passes.push(PassTiming {
            name: name.to_string(),
            gpu_ms,
            count,
        }),
    }
}

/// Scopes per timestamp query pool; a frame adds pools as it needs them.
const POOL_SCOPES: u32 = 256;

/// A command buffer being recorded. Create with [`Frame::begin`], record
/// passes with [`Frame::pass`], finish with [`Frame::submit_and_wait`].
pub struct Frame {
    ctx: Arc<Context>,
    pool: vk::CommandPool,
    pub cmd: vk::CommandBuffer,
    fence: vk::Fence,
    /// Timestamp pools; scope i owns queries 2(i mod P) and 2(i mod P)+1 of
    /// pool i div P (P = POOL_SCOPES).
    pools: Vec<vk::QueryPool>,
    /// The first error met while recording, returned by `submit_and_wait`.
    deferred_error: Option<Error>,
    scopes: Vec<(String, u32)>,
    started: Instant,
}

impl Frame {
    /// Allocates a command buffer and begins recording.
    pub fn begin(ctx: &Arc<Context>, name: &str) -> Result<Frame> {
        let started = Instant::now();
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(ctx.queue_family)
            .flags(vk::CommandPoolCreateFlags::TRANSIENT);
        // SAFETY: valid device; each object is owned by the Frame from here
        // (Drop destroys the null handles harmlessly if a later step fails).
        let mut frame = Frame {
            ctx: ctx.clone(),
            pool: unsafe { ctx.device.create_command_pool(&pool_info, None) }
                .vk("vkCreateCommandPool")?,
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            pools: Vec::new(),
            deferred_error: None,
            scopes: Vec::new(),
            started,
        };
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(frame.pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool was created above on this device.
        frame.cmd = unsafe { ctx.device.allocate_command_buffers(&alloc) }
            .vk("vkAllocateCommandBuffers")?[0];
        // SAFETY: plain object creation.
        frame.fence = unsafe {
            ctx.device
                .create_fence(&vk::FenceCreateInfo::default(), None)
        }
        .vk("vkCreateFence")?;
        ctx.set_name(frame.pool, name);
        ctx.set_name(frame.cmd, name);
        ctx.set_name(frame.fence, name);
        let begin = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: a freshly allocated buffer, recorded once.
        unsafe {
            ctx.device
                .begin_command_buffer(frame.cmd, &begin)
                .vk("vkBeginCommandBuffer")?;
        }
        Ok(frame)
    }

    /// The context this frame records for.
    pub fn ctx(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// Records one pass: a debug label named `name` around it, and a GPU
    /// timestamp scope that `submit_and_wait` reports under that name.
    pub fn pass<R>(
        &mut self,
        name: &str,
        record: impl FnOnce(&Context, vk::CommandBuffer) -> R,
    ) -> R {
        let index = self.scopes.len() as u32;
        self.ctx.begin_label(self.cmd, name);
        // A pool that cannot be created fails the frame at submit.
        let timed = match self.reserve_scope(index) {
            Ok(()) => true,
            Err(e) => {
                self.deferred_error.get_or_insert(e);
                false
            }
        };
        if timed {
            self.timestamp(2 * index);
        }
        let result = record(&self.ctx, self.cmd);
        if timed {
            self.timestamp(2 * index + 1);
            self.scopes.push((name.to_string(), index));
        }
        self.ctx.end_label(self.cmd);
        result
    }

    /// Makes sure scope `index` has a query pool, creating and resetting a
    /// new one when the last is full.
    fn reserve_scope(&mut self, index: u32) -> Result<()> {
        if (index / POOL_SCOPES) < self.pools.len() as u32 {
            return Ok(());
        }
        let info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::TIMESTAMP)
            .query_count(2 * POOL_SCOPES);
        // SAFETY: plain object creation; the pool is reset in this command
        // buffer (outside any render pass: passes record whole render passes)
        // before any of its queries is written.
        let pool =
            unsafe { self.ctx.device.create_query_pool(&info, None) }.vk("vkCreateQueryPool")?;
        self.pools.push(pool);
        self.ctx.set_name(pool, "frame timestamps");
        // SAFETY: see above.
        unsafe {
            self.ctx
                .device
                .cmd_reset_query_pool(self.cmd, pool, 0, 2 * POOL_SCOPES)
        };
        Ok(())
    }

    /// Writes timestamp `query` (a frame-wide index) once every earlier
    /// command has completed.
    fn timestamp(&self, query: u32) {
        let per_pool = 2 * POOL_SCOPES;
        // SAFETY: recording; the query's pool exists (reserve_scope) and was
        // reset, and the query is written once.
        unsafe {
            self.ctx.device.cmd_write_timestamp2(
                self.cmd,
                vk::PipelineStageFlags2::ALL_COMMANDS,
                self.pools[(query / per_pool) as usize],
                query % per_pool,
            )
        };
    }

    /// Ends recording, submits, waits for completion and reads the timestamps.
    pub fn submit_and_wait(mut self) -> Result<FrameTimings> {
        let ctx = &self.ctx;
        let cmds = [self.cmd];
        let submit = vk::SubmitInfo::default().command_buffers(&cmds);
        // SAFETY: the buffer was recorded by this frame and is submitted once;
        // the fence is unsignalled and waited on before anything is read.
        unsafe {
            ctx.device
                .end_command_buffer(self.cmd)
                .vk("vkEndCommandBuffer")?;
            ctx.device
                .queue_submit(ctx.queue, &[submit], self.fence)
                .vk("vkQueueSubmit")?;
            ctx.device
                .wait_for_fences(&[self.fence], true, u64::MAX)
                .vk("vkWaitForFences")?;
        }
        let wall_ms = self.started.elapsed().as_secs_f64() * 1e3;
        if let Some(e) = self.deferred_error.take() {
            return Err(e);
        }
        let mut passes = Vec::new();
        let n = self.scopes.len() as u32;
        if n > 0 && ctx.info.timestamp_valid_bits > 0 {
            let mut ticks = Vec::with_capacity(2 * n as usize);
            for (p, pool) in self.pools.iter().enumerate() {
                let used = (n - p as u32 * POOL_SCOPES).min(POOL_SCOPES);
                let mut part = vec![0u64; 2 * used as usize];
                // SAFETY: queries 0..2*used of this pool were written by this
                // completed submission.
                unsafe {
                    ctx.device
                        .get_query_pool_results(
                            *pool,
                            0,
                            &mut part,
                            vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                        )
                        .vk("vkGetQueryPoolResults")?
                };
                ticks.extend(part);
            }
            let mask = if ctx.info.timestamp_valid_bits >= 64 {
                u64::MAX
            } else {
                (1u64 << ctx.info.timestamp_valid_bits) - 1
            };
            let period = ctx.info.timestamp_period_ns as f64;
            for (name, i) in &self.scopes {
                let (a, b) = (
                    ticks[2 * *i as usize] & mask,
                    ticks[2 * *i as usize + 1] & mask,
                );
                let ms = b.wrapping_sub(a) as f64 * period / 1e6;
                add_pass(&mut passes, name, ms, 1);
            }
        }
        Ok(FrameTimings { passes, wall_ms })
    }
}

impl Drop for Frame {
    fn drop(&mut self) {
        // SAFETY: either the submission completed (submit_and_wait waited on
        // the fence) or nothing was submitted; destroying the pool frees the
        // command buffer. Null handles are ignored by Vulkan.
        unsafe {
            for pool in &self.pools {
                self.ctx.device.destroy_query_pool(*pool, None);
            }
            self.ctx.device.destroy_fence(self.fence, None);
            self.ctx.device.destroy_command_pool(self.pool, None);
        }
    }
}
