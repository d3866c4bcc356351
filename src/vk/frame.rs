//! One command buffer recorded, submitted and waited for, with every pass
//! inside it given a debug label and a GPU timestamp scope (`Frame::pass`).

use std::marker::PhantomData;
use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use super::pipeline::{Bind, ComputePipeline, Groups, PointPipeline, PushConstants};
use super::{Access, Buffer, Context, Image};
use crate::error::{Error, Result, VkContext};

/// Time spent by one named pass (summed when the name occurs several times).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
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
    /// The part of `wall_ms` spent copying the output pixels from the
    /// readback buffer into the host's image, milliseconds.
    pub readback_ms: f64,
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
        self.readback_ms += other.readback_ms;
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

/// Frames' objects the context keeps for the next frames: as many as the
/// frames that can be alive at once (a sequence's frames in flight, the
/// frame of a Gaussian scene beside a point frame), more are destroyed.
pub(super) const KEPT_FRAMES: usize = 4;

/// The Vulkan objects a frame records and waits with: a command pool with
/// its one primary command buffer, a fence, and the timestamp pools. A
/// frame that completed hands them back to its context
/// ([`Context::keep_frame_objects`]), reset, and the next frame takes them
/// instead of making its own: a sequence makes them once.
pub(super) struct FrameObjects {
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    /// Unsignalled whenever the objects are not in a frame's hands.
    fence: vk::Fence,
    /// Timestamp pools, each reset by the frame that uses it, in its
    /// command buffer, before its first query.
    queries: Vec<vk::QueryPool>,
}

impl FrameObjects {
    /// Makes a command pool, its command buffer and an unsignalled fence
    /// (no timestamp pool yet).
    fn create(ctx: &Context) -> Result<FrameObjects> {
        let pool_info = vk::CommandPoolCreateInfo::default().queue_family_index(ctx.queue_family);
        // SAFETY: valid device and create info; the pool is owned by
        // `objects` from the next statement on, destroyed by `destroy`
        // below if a later step fails (null handles harmlessly).
        let pool = unsafe { ctx.device.create_command_pool(&pool_info, None) }
            .vk("vkCreateCommandPool")?;
        let mut objects = FrameObjects {
            pool,
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            queries: Vec::new(),
        };
        let made = (|| -> Result<()> {
            let alloc = vk::CommandBufferAllocateInfo::default()
                .command_pool(objects.pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1);
            // SAFETY: the pool was created above on this device.
            objects.cmd = unsafe { ctx.device.allocate_command_buffers(&alloc) }
                .vk("vkAllocateCommandBuffers")?[0];
            // SAFETY: plain object creation.
            objects.fence = unsafe {
                ctx.device
                    .create_fence(&vk::FenceCreateInfo::default(), None)
            }
            .vk("vkCreateFence")?;
            Ok(())
        })();
        match made {
            Ok(()) => Ok(objects),
            Err(e) => {
                // SAFETY: nothing was submitted with these objects.
                unsafe { objects.destroy(&ctx.device) };
                Err(e)
            }
        }
    }

    /// Destroys the objects (the command buffer with its pool).
    ///
    /// # Safety
    /// No submission that used them is pending.
    pub(super) unsafe fn destroy(self, device: &ash::Device) {
        // SAFETY: by the caller's promise nothing pending uses them; null
        // handles are ignored by Vulkan.
        unsafe {
            for pool in &self.queries {
                device.destroy_query_pool(*pool, None);
            }
            device.destroy_fence(self.fence, None);
            device.destroy_command_pool(self.pool, None);
        }
    }
}

/// A command buffer being recorded. Create with [`Frame::begin`], record
/// passes with [`Frame::pass`], finish with [`Frame::submit_and_wait`].
/// Every resource a pass records is borrowed for `'r`: it outlives the
/// frame, so it is alive until the submission has completed.
pub struct Frame<'r> {
    ctx: Arc<Context>,
    /// `None` only while dropping.
    objects: Option<FrameObjects>,
    cmd: vk::CommandBuffer,
    /// Timestamp pools this frame has reset and writes: the first of
    /// `objects.queries`. Scope i owns queries 2(i mod P) and 2(i mod P)+1
    /// of pool i div P (P = POOL_SCOPES).
    queries_used: usize,
    /// Whether the submission was waited for to completion, so that the
    /// objects can go back to the context.
    completed: bool,
    /// The first error met while recording, returned by `submit_and_wait`.
    deferred_error: Option<Error>,
    scopes: Vec<(String, u32)>,
    started: Instant,
    resources: PhantomData<&'r ()>,
}

impl<'r> Frame<'r> {
    /// Takes a command buffer (the context's kept one of an earlier frame,
    /// or a new one) and begins recording.
    pub fn begin(ctx: &Arc<Context>, name: &str) -> Result<Frame<'r>> {
        let started = Instant::now();
        let objects = match ctx.take_frame_objects() {
            Some(objects) => objects,
            None => {
                let objects = FrameObjects::create(ctx)?;
                ctx.set_name(objects.pool, name);
                ctx.set_name(objects.fence, name);
                objects
            }
        };
        ctx.set_name(objects.cmd, name);
        let frame = Frame {
            ctx: ctx.clone(),
            cmd: objects.cmd,
            objects: Some(objects),
            queries_used: 0,
            completed: false,
            deferred_error: None,
            scopes: Vec::new(),
            started,
            resources: PhantomData,
        };
        let begin = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: a new command buffer, or one whose pool was reset after
        // its submission completed (`Drop`): in the initial state.
        unsafe {
            ctx.device
                .begin_command_buffer(frame.cmd, &begin)
                .vk("vkBeginCommandBuffer")?;
        }
        Ok(frame)
    }

    /// This frame's objects (present until it is dropped).
    fn objects(&self) -> &FrameObjects {
        self.objects
            .as_ref()
            .expect("a frame's objects until its drop")
    }

    /// The context this frame records for.
    pub fn ctx(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// Records one pass: a debug label named `name` around it, and a GPU
    /// timestamp scope that `submit_and_wait` reports under that name.
    pub fn pass<R>(&mut self, name: &str, record: impl FnOnce(&mut Recorder<'_, 'r>) -> R) -> R {
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
        let result = record(&mut Recorder {
            ctx: &self.ctx,
            cmd: self.cmd,
            resources: PhantomData,
        });
        if timed {
            self.timestamp(2 * index + 1);
            self.scopes.push((name.to_string(), index));
        }
        self.ctx.end_label(self.cmd);
        result
    }

    /// Makes sure scope `index` has a query pool: the next of the frame's
    /// objects' pools, or a new one, reset in this command buffer.
    fn reserve_scope(&mut self, index: u32) -> Result<()> {
        if (index / POOL_SCOPES) < self.queries_used as u32 {
            return Ok(());
        }
        let objects = self
            .objects
            .as_mut()
            .expect("a frame's objects until its drop");
        if self.queries_used == objects.queries.len() {
            let info = vk::QueryPoolCreateInfo::default()
                .query_type(vk::QueryType::TIMESTAMP)
                .query_count(2 * POOL_SCOPES);
            // SAFETY: plain object creation; the frame's objects own it.
            let pool = unsafe { self.ctx.device.create_query_pool(&info, None) }
                .vk("vkCreateQueryPool")?;
            objects.queries.push(pool);
            self.ctx.set_name(pool, "frame timestamps");
        }
        let pool = objects.queries[self.queries_used];
        self.queries_used += 1;
        // SAFETY: the pool is reset in this command buffer (outside any
        // render pass: passes record whole render passes) before any of
        // its queries is written; no pending submission uses it (an
        // earlier frame's completed before its objects came back).
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
                self.objects().queries[(query / per_pool) as usize],
                query % per_pool,
            )
        };
    }

    /// Ends recording, submits, waits for completion and reads the timestamps.
    pub fn submit_and_wait(mut self) -> Result<FrameTimings> {
        let ctx = &self.ctx;
        let cmds = [self.cmd];
        let fence = self.objects().fence;
        let submit = vk::SubmitInfo::default().command_buffers(&cmds);
        // SAFETY: the buffer was recorded by this frame and is submitted once;
        // the fence is unsignalled and waited on before anything is read;
        // the flush fence is the context's, unsignalled between uses, and
        // used only under the queue's lock.
        unsafe {
            ctx.device
                .end_command_buffer(self.cmd)
                .vk("vkEndCommandBuffer")?;
            // The queue is externally synchronised: one submission at a
            // time, whichever thread shares the context.
            let flush = ctx.queue_lock();
            if let Some(result) = super::context::injected_fault("vkQueueSubmit") {
                return Err(crate::error::Error::Vulkan {
                    call: "vkQueueSubmit",
                    result,
                });
            }
            ctx.device
                .queue_submit(ctx.queue, &[submit], fence)
                .vk("vkQueueSubmit")?;
            ctx.device
                .wait_for_fences(&[fence], true, u64::MAX)
                .vk("vkWaitForFences")?;
            // Under the validation layer, a submission of nothing with the
            // context's flush fence, waited for: the layer retires each
            // submission on a thread of its own and lets go of its command
            // buffers only after it has signalled the waiters, so without
            // this the frame's pool, reset or destroyed next, could leave the last
            // reference to a command buffer's state on that thread, whose
            // destructor (layer 1.3.239, Debian 12's) then erases the
            // buffer's labels from a map this thread writes while it records
            // the next frame, without the lock: a corrupted heap
            // (Context::queue_lock, tests/label_race.rs). The layer
            // retires in order, so the flush retired means the frame's
            // submission is let go of too.
            if *flush != vk::Fence::null() {
                ctx.device
                    .queue_submit(ctx.queue, &[], *flush)
                    .vk("vkQueueSubmit")?;
                ctx.device
                    .wait_for_fences(&[*flush], true, u64::MAX)
                    .vk("vkWaitForFences")?;
                ctx.device.reset_fences(&[*flush]).vk("vkResetFences")?;
            }
            // Injected after the real wait, so the work is done and the
            // frame's resources are free to destroy, as after a device lost
            // while waiting.
            if let Some(result) = super::context::injected_fault("vkWaitForFences") {
                return Err(crate::error::Error::Vulkan {
                    call: "vkWaitForFences",
                    result,
                });
            }
        }
        self.completed = true;
        let wall_ms = self.started.elapsed().as_secs_f64() * 1e3;
        if let Some(e) = self.deferred_error.take() {
            return Err(e);
        }
        let mut passes = Vec::new();
        let n = self.scopes.len() as u32;
        if n > 0 && ctx.info.timestamp_valid_bits > 0 {
            let mut ticks = Vec::with_capacity(2 * n as usize);
            for (p, pool) in self.objects().queries[..self.queries_used]
                .iter()
                .enumerate()
            {
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
        Ok(FrameTimings {
            passes,
            wall_ms,
            readback_ms: 0.0,
        })
    }
}

impl Drop for Frame<'_> {
    fn drop(&mut self) {
        let Some(objects) = self.objects.take() else {
            return;
        };
        if self.completed {
            // SAFETY: the submission completed (submit_and_wait waited on
            // the fence, and under validation on the flush after it), so
            // the pool's command buffer and the fence are in no pending
            // submission: both may be reset.
            let reset = unsafe {
                self.ctx
                    .device
                    .reset_command_pool(objects.pool, vk::CommandPoolResetFlags::empty())
                    .and_then(|()| self.ctx.device.reset_fences(&[objects.fence]))
            };
            if reset.is_ok() {
                self.ctx.keep_frame_objects(objects);
                return;
            }
        }
        // SAFETY: either the submission completed or nothing was submitted
        // (a frame dropped unsubmitted, or whose submission failed).
        unsafe { objects.destroy(&self.ctx.device) };
    }
}

/// The commands a pass may record: barriers, dispatches, clears, copies
/// and point draws, each taking the resources it touches by reference.
/// Every resource a frame's passes name is borrowed for `'r`, the frame's
/// lifetime, so none can be dropped before the frame is submitted and
/// waited for (or dropped unsubmitted).
pub struct Recorder<'f, 'r> {
    ctx: &'f Context,
    cmd: vk::CommandBuffer,
    resources: PhantomData<&'r ()>,
}

impl<'r> Recorder<'_, 'r> {
    /// Panics unless `image` was made on this frame's device: a handle of
    /// another device in this command buffer would be undefined behaviour.
    fn own_image(&self, image: &Image) {
        assert!(image.made_on(self.ctx), "an image of another device");
    }

    /// As [`Recorder::own_image`], for a buffer.
    fn own_buffer(&self, buffer: &Buffer) {
        assert!(buffer.made_on(self.ctx), "a buffer of another device");
    }

    fn own_binds(&self, binds: &[Bind<'_>]) {
        for bind in binds {
            match bind {
                Bind::StorageImage(image) => self.own_image(image),
                Bind::StorageBuffer(buffer) => self.own_buffer(buffer),
            }
        }
    }

    /// Image barriers from each `src` to its `dst` (layout transitions
    /// included), in one call.
    pub fn barriers(&mut self, list: &[(&'r Image, Access, Access)]) {
        for (image, _, _) in list {
            self.own_image(image);
        }
        let barriers: Vec<_> = list
            .iter()
            .map(|(image, src, dst)| {
                vk::ImageMemoryBarrier2::default()
                    .src_stage_mask(src.stage)
                    .src_access_mask(src.access)
                    .dst_stage_mask(dst.stage)
                    .dst_access_mask(dst.access)
                    .old_layout(src.layout)
                    .new_layout(dst.layout)
                    .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .image(image.raw)
                    .subresource_range(image.full_range())
            })
            .collect();
        let dep = vk::DependencyInfo::default().image_memory_barriers(&barriers);
        // SAFETY: `cmd` is recording outside a render pass (passes record
        // whole render passes inside `draw_points`); the images are alive
        // for the frame (`'r`).
        unsafe { self.ctx.device.cmd_pipeline_barrier2(self.cmd, &dep) };
    }

    /// A global memory barrier (for buffers): `src`'s stages and accesses
    /// before `dst`'s (layouts are ignored).
    pub fn memory_barrier(&mut self, src: Access, dst: Access) {
        let barriers = [vk::MemoryBarrier2::default()
            .src_stage_mask(src.stage)
            .src_access_mask(src.access)
            .dst_stage_mask(dst.stage)
            .dst_access_mask(dst.access)];
        let dep = vk::DependencyInfo::default().memory_barriers(&barriers);
        // SAFETY: `cmd` is recording outside a render pass.
        unsafe { self.ctx.device.cmd_pipeline_barrier2(self.cmd, &dep) };
    }

    /// Binds `pipeline`, pushes `binds` as its descriptors and `push` as its
    /// constants, and dispatches `groups` workgroups. Images must be in
    /// `GENERAL` layout.
    pub fn dispatch<P: PushConstants>(
        &mut self,
        pipeline: &'r ComputePipeline<P>,
        binds: &[Bind<'r>],
        push: &P,
        groups: [u32; 3],
    ) {
        assert!(pipeline.made_on(self.ctx), "a pipeline of another device");
        self.own_binds(binds);
        pipeline.record_dispatch(self.cmd, binds, push, Groups::Direct(groups));
    }

    /// Dispatches `pipeline` with the workgroup counts the GPU wrote at
    /// byte `offset` of `args` (a `VkDispatchIndirectCommand`: x, y, z),
    /// read at [`Access::INDIRECT_READ`](super::Access::INDIRECT_READ).
    pub fn dispatch_indirect<P: PushConstants>(
        &mut self,
        pipeline: &'r ComputePipeline<P>,
        binds: &[Bind<'r>],
        push: &P,
        args: &'r Buffer,
        offset: u64,
    ) {
        assert!(pipeline.made_on(self.ctx), "a pipeline of another device");
        self.own_binds(binds);
        self.own_buffer(args);
        assert!(
            offset.is_multiple_of(4) && offset + 12 <= args.size(),
            "dispatch arguments at {offset} of a {}-byte buffer",
            args.size()
        );
        pipeline.record_dispatch(self.cmd, binds, push, Groups::Indirect(args, offset));
    }

    /// Writes `words` at the start of `buffer` ([`Access::FILL`] in memory
    /// barriers: the specification counts an update among the clear
    /// commands, like a fill).
    pub fn update_u32(&mut self, buffer: &'r Buffer, words: &[u32]) {
        self.own_buffer(buffer);
        let bytes: &[u8] = bytemuck::cast_slice(words);
        assert!(
            !bytes.is_empty() && bytes.len() <= 65536 && bytes.len() as u64 <= buffer.size(),
            "an update of {} bytes into a {}-byte buffer",
            bytes.len(),
            buffer.size()
        );
        // SAFETY: recording outside a render pass; the buffer is this
        // device's (asserted) and was made with TRANSFER_DST usage (the
        // validation layer checks); the data is 4-byte aligned, at most
        // 65536 bytes and inside the buffer (asserted).
        unsafe {
            self.ctx
                .device
                .cmd_update_buffer(self.cmd, buffer.raw, 0, bytes)
        };
    }

    /// Fills every layer of an unsigned-integer color image with `value`;
    /// the image must be in `TRANSFER_DST_OPTIMAL` ([`Access::CLEAR`]).
    pub fn clear_u32(&mut self, image: &'r Image, value: u32) {
        self.own_image(image);
        let clear = vk::ClearColorValue { uint32: [value; 4] };
        // SAFETY: recording outside a render pass; the caller's barrier put
        // the image in TRANSFER_DST_OPTIMAL and the range covers it.
        unsafe {
            self.ctx.device.cmd_clear_color_image(
                self.cmd,
                image.raw,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &clear,
                &[image.full_range()],
            )
        };
    }

    /// Fills all of `buffer` with the 32-bit `value` ([`Access::FILL`] in
    /// memory barriers).
    pub fn fill_u32(&mut self, buffer: &'r Buffer, value: u32) {
        self.own_buffer(buffer);
        assert_eq!(buffer.size() % 4, 0, "a fill writes whole words");
        // SAFETY: recording outside a render pass; the buffer is this
        // device's (asserted) and was made with TRANSFER_DST usage (the
        // validation layer checks); the range is the whole buffer.
        unsafe {
            self.ctx
                .device
                .cmd_fill_buffer(self.cmd, buffer.raw, 0, vk::WHOLE_SIZE, value)
        };
    }

    /// Copies the first `min(src.size, dst.size)` bytes of `src` to `dst`.
    pub fn copy_buffer(&mut self, src: &'r Buffer, dst: &'r Buffer) {
        self.own_buffer(src);
        self.own_buffer(dst);
        let region = vk::BufferCopy {
            src_offset: 0,
            dst_offset: 0,
            size: src.size().min(dst.size()),
        };
        // SAFETY: recording outside a render pass; the region lies inside
        // both buffers.
        unsafe {
            self.ctx
                .device
                .cmd_copy_buffer(self.cmd, src.raw, dst.raw, &[region])
        };
    }

    /// Copies the `extent` region at `offset` of layer 0 of a color image in
    /// `TRANSFER_SRC_OPTIMAL` ([`Access::COPY_SRC`]) into `buffer`, tightly
    /// packed. Panics when the region leaves the image or the buffer is too
    /// small for it.
    pub fn copy_image_to_buffer(
        &mut self,
        image: &'r Image,
        offset: [u32; 2],
        extent: [u32; 2],
        buffer: &'r Buffer,
    ) {
        self.own_image(image);
        self.own_buffer(buffer);
        assert_eq!(image.samples(), 1, "copy from a multisampled image");
        let inside = |o: u32, e: u32, size: u32| o as u64 + e as u64 <= size as u64;
        assert!(
            inside(offset[0], extent[0], image.width())
                && inside(offset[1], extent[1], image.height()),
            "copy region outside the image"
        );
        let bytes = extent[0] as u64 * extent[1] as u64 * texel_bytes(image.format());
        assert!(bytes <= buffer.size(), "readback buffer too small");
        let region = vk::BufferImageCopy {
            buffer_offset: 0,
            buffer_row_length: 0,
            buffer_image_height: 0,
            image_subresource: vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: 0,
                layer_count: 1,
            },
            image_offset: vk::Offset3D {
                x: offset[0] as i32,
                y: offset[1] as i32,
                z: 0,
            },
            image_extent: vk::Extent3D {
                width: extent[0],
                height: extent[1],
                depth: 1,
            },
        };
        // SAFETY: recording outside a render pass; the region lies inside
        // the image and the buffer holds it (asserted above).
        unsafe {
            self.ctx.device.cmd_copy_image_to_buffer(
                self.cmd,
                image.raw,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                buffer.raw,
                &[region],
            )
        };
    }

    /// One render pass over the whole of `colors` and `depth` (all the same
    /// size, in attachment layouts: [`Access::COLOR_WRITE`],
    /// [`Access::DEPTH_WRITE`]): clears each color target to its value and
    /// the depth to 1, draws the first `count` vertices of `vertices` as
    /// point sprites with `pipeline` and `push`, stores the colors and
    /// discards the depth. `binds` are the fragment shader's resources
    /// (images in `GENERAL` layout, none of them a target).
    #[allow(clippy::too_many_arguments)]
    pub fn draw_points<P: PushConstants>(
        &mut self,
        pipeline: &'r PointPipeline<P>,
        colors: &[(&'r Image, [f32; 4])],
        depth: &'r Image,
        binds: &[Bind<'r>],
        vertices: &'r Buffer,
        count: DrawCount<'r>,
        push: &P,
    ) {
        assert!(pipeline.made_on(self.ctx), "a pipeline of another device");
        self.own_binds(binds);
        for bind in binds {
            if let Bind::StorageImage(image) = bind {
                assert!(
                    colors.iter().all(|c| !std::ptr::eq(c.0, *image))
                        && !std::ptr::eq(depth, *image),
                    "a render target bound as a fragment resource"
                );
            }
        }
        for (image, _) in colors {
            self.own_image(image);
        }
        self.own_image(depth);
        self.own_buffer(vertices);
        assert_eq!(
            colors.iter().map(|c| c.0.format()).collect::<Vec<_>>(),
            pipeline.color_formats,
            "color targets do not match the pipeline"
        );
        assert_eq!(depth.format(), pipeline.depth_format, "depth target format");
        assert!(
            colors
                .iter()
                .map(|c| c.0)
                .chain([depth])
                .all(|t| t.samples() == pipeline.samples),
            "targets' sample counts do not match the pipeline's"
        );
        let (w, h) = (depth.width(), depth.height());
        assert!(
            colors.iter().all(|c| (c.0.width(), c.0.height()) == (w, h)),
            "targets of different sizes"
        );
        match count {
            DrawCount::Direct(count) => assert!(
                count as u64 * pipeline.stride as u64 <= vertices.size(),
                "{count} vertices do not fit the vertex buffer"
            ),
            DrawCount::Indirect(args) => {
                self.own_buffer(args);
                assert!(args.size() >= 16, "a draw's arguments are 16 bytes");
            }
        }
        let area = vk::Rect2D {
            offset: vk::Offset2D { x: 0, y: 0 },
            extent: vk::Extent2D {
                width: w,
                height: h,
            },
        };
        let color_attachments: Vec<_> = colors
            .iter()
            .map(|(image, clear)| {
                vk::RenderingAttachmentInfo::default()
                    .image_view(image.view)
                    .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .clear_value(vk::ClearValue {
                        color: vk::ClearColorValue { float32: *clear },
                    })
            })
            .collect();
        let depth_attachment = vk::RenderingAttachmentInfo::default()
            .image_view(depth.view)
            .image_layout(vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::DONT_CARE)
            .clear_value(vk::ClearValue {
                depth_stencil: vk::ClearDepthStencilValue {
                    depth: 1.0,
                    stencil: 0,
                },
            });
        let rendering = vk::RenderingInfo::default()
            .render_area(area)
            .layer_count(1)
            .color_attachments(&color_attachments)
            .depth_attachment(&depth_attachment);
        let viewport = vk::Viewport {
            x: 0.0,
            y: 0.0,
            width: w as f32,
            height: h as f32,
            min_depth: 0.0,
            max_depth: 1.0,
        };
        let (raw_pipeline, layout) = pipeline.raw();
        let device = &self.ctx.device;
        // SAFETY: recording outside a render pass, this begins and ends one;
        // every object is this device's (asserted); the targets match the
        // pipeline's formats and size (asserted) and are in the layouts
        // named above (the caller's barriers); `vertices` holds `count`
        // vertices (asserted), made visible to vertex input by the caller
        // (the upload's barrier), or the indirect arguments (a
        // `VkDrawIndirectCommand` at offset 0, 16 bytes, asserted) count no
        // more vertices than the buffer holds (the writer's contract, made
        // visible to indirect reads by the caller's barrier); the fragment
        // descriptors are checked against the pipeline's set by
        // `push_fragment_descriptors` and are no render target (asserted);
        // all live for the frame (`'r`).
        unsafe {
            device.cmd_begin_rendering(self.cmd, &rendering);
            device.cmd_set_viewport(self.cmd, 0, &[viewport]);
            device.cmd_set_scissor(self.cmd, 0, &[area]);
            device.cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::GRAPHICS, raw_pipeline);
            pipeline.push_fragment_descriptors(self.cmd, binds);
            device.cmd_bind_vertex_buffers(self.cmd, 0, &[vertices.raw], &[0]);
            device.cmd_push_constants(
                self.cmd,
                layout,
                vk::ShaderStageFlags::VERTEX,
                0,
                bytemuck::bytes_of(push),
            );
            match count {
                DrawCount::Direct(count) => device.cmd_draw(self.cmd, count, 1, 0, 0),
                DrawCount::Indirect(args) => {
                    device.cmd_draw_indirect(self.cmd, args.raw, 0, 1, 16);
                }
            }
            device.cmd_end_rendering(self.cmd);
        }
    }
}

/// How many vertices [`Recorder::draw_points`] draws: a count, or the
/// `VkDrawIndirectCommand` a compute pass wrote at the start of a buffer
/// (read at [`Access::INDIRECT_READ`](super::Access::INDIRECT_READ); its
/// vertex count must not exceed the vertex buffer's, which the writer
/// guarantees).
#[derive(Clone, Copy)]
pub enum DrawCount<'r> {
    Direct(u32),
    Indirect(&'r Buffer),
}

/// Bytes per texel of the color formats pointlens reads back.
pub fn texel_bytes(format: vk::Format) -> u64 {
    match format {
        vk::Format::R32G32B32A32_SFLOAT => 16,
        vk::Format::R16G16B16A16_SFLOAT | vk::Format::R32G32_SFLOAT => 8,
        vk::Format::R8G8B8A8_UNORM
        | vk::Format::R8G8B8A8_SRGB
        | vk::Format::R32_SFLOAT
        | vk::Format::R32_UINT
        | vk::Format::D32_SFLOAT => 4,
        other => panic!("no texel size known for {other:?}"),
    }
}
