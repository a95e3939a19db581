//! Recording and submitting compute work: one command pool, one command buffer and one fence per
//! [`Recorder`], reused across submissions.
//!
//! Recording calls do not return errors one by one: the first misuse (e.g. a dispatch with no
//! pipeline bound) is remembered, the Vulkan call is skipped, and [`Recorder::submit_and_wait`]
//! returns it. Every resource a command references is kept alive by the recorder until the GPU
//! has finished with it.

use std::any::Any;
use std::time::Duration;

use ash::vk;
use bytemuck::Pod;

use super::buffer::Buffer;
use super::context::Context;
use super::conv;
use super::error::{map_result, GpuError, GpuResult};
use super::pipeline::{ComputePipeline, DescriptorSet};
use super::query::TimestampPool;
use super::timeline::{hand_off, Handoff, Outcome, Ticket, Timeline};

/// One side of a barrier: what a command did to memory before it, or will do after it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    /// A compute shader reads storage buffers.
    ComputeRead,
    /// A compute shader writes storage buffers.
    ComputeWrite,
    /// A compute shader reads and writes storage buffers.
    ComputeReadWrite,
    /// A copy reads a buffer.
    TransferRead,
    /// A copy or fill writes a buffer.
    TransferWrite,
    /// The CPU reads mapped memory.
    HostRead,
    /// The CPU writes mapped memory.
    HostWrite,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    /// Nothing recorded or the last submission is complete.
    Idle,
    /// Between `begin` and `submit_and_wait`.
    Recording,
    /// Submitted; the fence has not been seen signalled yet (after a timeout).
    Pending,
    /// Ended and handed off ([`Recorder::hand_off`]); `ticket` says what became of it.
    Handed,
}

/// Records compute work and submits it, blocking until it is done.
pub struct Recorder {
    ctx: Context,
    name: String,
    pool: vk::CommandPool,
    raw: vk::CommandBuffer,
    fence: vk::Fence,
    state: State,
    bound: Option<ComputePipeline>,
    /// Clones of everything the recorded commands reference, released once the GPU is done.
    keep_alive: Vec<Box<dyn Any + Send + Sync>>,
    /// The first recording error, returned by `submit_and_wait`.
    error: Option<GpuError>,
    dispatches: u32,
    /// In state `Handed`: the recorder's side of the hand-off.
    ticket: Option<Ticket>,
    /// Wall time from submission to observed completion of the last handed-off work.
    last_latency: Option<Duration>,
}

impl Drop for Recorder {
    fn drop(&mut self) {
        if let Some(ticket) = self.ticket.take() {
            if !ticket.revoke() {
                // On the queue: the command buffer must not be freed before it completes.
                ticket.wait_forever();
            }
        }
        if self.state == State::Pending {
            // SAFETY: the fence is ours; waiting forever is the only way to know the command
            // buffer is no longer in use (on device loss the wait returns at once).
            let _ = unsafe {
                self.ctx
                    .device()
                    .wait_for_fences(&[self.fence], true, u64::MAX)
            };
        }
        // SAFETY: the command buffer is not pending (waited above) and the fence is unused.
        unsafe { self.ctx.device().destroy_fence(self.fence, None) };
        // SAFETY: as above; destroying the pool frees its command buffer.
        unsafe { self.ctx.device().destroy_command_pool(self.pool, None) };
    }
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("name", &self.name)
            .field("state", &self.state)
            .field("dispatches", &self.dispatches)
            .finish()
    }
}

impl Recorder {
    /// A recorder for the context's compute queue.
    pub fn new(ctx: &Context, name: &str) -> GpuResult<Recorder> {
        let device = ctx.device();
        let mut rec = Recorder {
            ctx: ctx.clone(),
            name: name.to_string(),
            pool: vk::CommandPool::null(),
            raw: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            state: State::Idle,
            bound: None,
            keep_alive: Vec::new(),
            error: None,
            dispatches: 0,
            ticket: None,
            last_latency: None,
        };
        let pool_info = vk::CommandPoolCreateInfo::default()
            .flags(vk::CommandPoolCreateFlags::TRANSIENT)
            .queue_family_index(ctx.queue_family_index());
        // SAFETY: valid create info; on a later error `rec`'s Drop destroys the pool.
        rec.pool = unsafe { device.create_command_pool(&pool_info, None) }
            .map_err(|r| map_result("vkCreateCommandPool", r))?;
        ctx.set_name(rec.pool, &format!("{name}.pool"));
        let alloc_info = vk::CommandBufferAllocateInfo::default()
            .command_pool(rec.pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool is live; the buffer is freed with it.
        let buffers = unsafe { device.allocate_command_buffers(&alloc_info) }
            .map_err(|r| map_result("vkAllocateCommandBuffers", r))?;
        rec.raw = buffers.first().copied().ok_or_else(|| {
            GpuError::Invalid("vkAllocateCommandBuffers returned no buffer".into())
        })?;
        ctx.set_name(rec.raw, &format!("{name}.commands"));
        // SAFETY: valid create info; destroyed in Drop.
        rec.fence = unsafe { device.create_fence(&vk::FenceCreateInfo::default(), None) }
            .map_err(|r| map_result("vkCreateFence", r))?;
        ctx.set_name(rec.fence, &format!("{name}.fence"));
        Ok(rec)
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// Dispatches recorded since the last `begin`.
    pub fn dispatch_count(&self) -> u32 {
        self.dispatches
    }

    /// Starts a new recording (waiting first for a submission that timed out).
    pub fn begin(&mut self) -> GpuResult<()> {
        if let Some(ticket) = &self.ticket {
            // Work handed off but never submitted is taken back; submitted work is waited for.
            if ticket.revoke() {
                self.ticket = None;
                self.state = State::Idle;
            }
        }
        if matches!(self.state, State::Pending | State::Handed) {
            match self.wait(Duration::MAX) {
                Ok(()) | Err(GpuError::Cancelled { .. }) => {}
                Err(e) => return Err(e),
            }
        }
        let device = self.ctx.device();
        // SAFETY: the command buffer is not pending (state is Idle or Recording), so resetting
        // its pool is allowed; a recording in progress is simply discarded.
        unsafe { device.reset_command_pool(self.pool, vk::CommandPoolResetFlags::empty()) }
            .map_err(|r| map_result("vkResetCommandPool", r))?;
        self.keep_alive.clear();
        self.bound = None;
        self.error = None;
        self.dispatches = 0;
        let info = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: the buffer is in the initial state after the pool reset.
        unsafe { device.begin_command_buffer(self.raw, &info) }
            .map_err(|r| map_result("vkBeginCommandBuffer", r))?;
        self.state = State::Recording;
        Ok(())
    }

    /// The command buffer if recording; otherwise remembers the misuse and returns `None`.
    fn recording(&mut self, what: &str) -> Option<vk::CommandBuffer> {
        if self.state == State::Recording {
            Some(self.raw)
        } else {
            self.fail(format!(
                "{what} outside begin()..submit_and_wait() on {}",
                self.name
            ));
            None
        }
    }

    fn fail(&mut self, message: String) {
        if self.error.is_none() {
            self.error = Some(GpuError::Invalid(message));
        }
    }

    fn keep<T: Any + Send + Sync + Clone>(&mut self, resource: &T) {
        self.keep_alive.push(Box::new(resource.clone()));
    }

    /// Binds a pipeline and its descriptor set for the following dispatches.
    pub fn bind(&mut self, pipeline: &ComputePipeline, set: &DescriptorSet) {
        let Some(cmd) = self.recording("bind") else {
            return;
        };
        if set.bindings() != pipeline.bindings() {
            self.fail(format!(
                "set {} ({} bindings) does not fit pipeline {} ({} bindings)",
                set.name(),
                set.bindings(),
                pipeline.name(),
                pipeline.bindings()
            ));
            return;
        }
        let device = self.ctx.device();
        // SAFETY: recording; the pipeline is live and kept alive below.
        unsafe { device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, pipeline.raw()) };
        // SAFETY: recording; the set's layout is compatible (same binding count) and the set is
        // kept alive below.
        unsafe {
            device.cmd_bind_descriptor_sets(
                cmd,
                vk::PipelineBindPoint::COMPUTE,
                pipeline.layout(),
                0,
                &[set.raw()],
                &[],
            )
        };
        self.keep(pipeline);
        self.keep(set);
        self.bound = Some(pipeline.clone());
    }

    /// Sets the bound pipeline's push constants from raw bytes (a multiple of 4, at most the
    /// pipeline's push-constant size).
    pub fn push_bytes(&mut self, bytes: &[u8]) {
        let Some(cmd) = self.recording("push") else {
            return;
        };
        let Some(pipeline) = &self.bound else {
            self.fail("push constants with no pipeline bound".into());
            return;
        };
        if bytes.len() % 4 != 0 || bytes.len() > pipeline.push_constant_bytes() as usize {
            let message = format!(
                "{} push-constant bytes for pipeline {} (block of {})",
                bytes.len(),
                pipeline.name(),
                pipeline.push_constant_bytes()
            );
            self.fail(message);
            return;
        }
        let layout = pipeline.layout();
        // SAFETY: recording; the range lies inside the layout's push-constant range (checked).
        unsafe {
            self.ctx.device().cmd_push_constants(
                cmd,
                layout,
                vk::ShaderStageFlags::COMPUTE,
                0,
                bytes,
            )
        };
    }

    /// Sets the bound pipeline's push constants from a `#[repr(C)]` Pod struct.
    pub fn push<T: Pod>(&mut self, constants: &T) {
        self.push_bytes(bytemuck::bytes_of(constants));
    }

    /// Dispatches raw workgroup counts.
    pub fn dispatch(&mut self, groups: [u32; 3]) {
        let Some(cmd) = self.recording("dispatch") else {
            return;
        };
        if self.bound.is_none() {
            self.fail("dispatch with no pipeline bound".into());
            return;
        }
        let max = self.ctx.limits().max_compute_work_group_count;
        if groups.iter().zip(max).any(|(&g, m)| g > m) {
            self.fail(format!(
                "dispatch of {groups:?} workgroups exceeds the device's {max:?}"
            ));
            return;
        }
        if groups.contains(&0) {
            return;
        }
        // SAFETY: recording with a compute pipeline bound; counts within the device limits.
        unsafe {
            self.ctx
                .device()
                .cmd_dispatch(cmd, groups[0], groups[1], groups[2])
        };
        self.dispatches += 1;
    }

    /// Dispatches at least `n_threads` invocations of the bound pipeline: workgroups of the
    /// pipeline's size laid out as a 2-D grid whose x stays within the device limit (65535 on
    /// lavapipe), matching `global_index()` in `glsl/common/grid.glsl`. The kernel must ignore
    /// indices `>= n` (the grid is rounded up).
    pub fn dispatch_1d(&mut self, n_threads: u32) {
        let Some(pipeline) = &self.bound else {
            self.fail("dispatch with no pipeline bound".into());
            return;
        };
        let max = self.ctx.limits().max_compute_work_group_count;
        match grid_1d(n_threads, pipeline.workgroup_size(), max) {
            Some(groups) => self.dispatch(groups),
            None => self.fail(format!(
                "{n_threads} threads do not fit a {max:?} workgroup grid"
            )),
        }
    }

    /// A memory barrier: every `from` access recorded before it happens-before (and is visible
    /// to) every `to` access recorded after it.
    pub fn barrier(&mut self, from: Access, to: Access) {
        self.barriers(&[(from, to)]);
    }

    /// Several dependencies in one `vkCmdPipelineBarrier2` (one batched barrier per step).
    pub fn barriers(&mut self, pairs: &[(Access, Access)]) {
        let Some(cmd) = self.recording("barrier") else {
            return;
        };
        if pairs.is_empty() {
            return;
        }
        let barriers: Vec<vk::MemoryBarrier2> = pairs
            .iter()
            .map(|&(from, to)| conv::map_barrier(from, to))
            .collect();
        let info = vk::DependencyInfo::default().memory_barriers(&barriers);
        // SAFETY: recording; synchronization2 is enabled on the device.
        unsafe { self.ctx.sync2().cmd_pipeline_barrier2(cmd, &info) };
    }

    /// Copies the first `bytes` bytes of `src` to `dst`.
    pub fn copy_buffer(&mut self, src: &Buffer, dst: &Buffer, bytes: u64) {
        let Some(cmd) = self.recording("copy_buffer") else {
            return;
        };
        if bytes > src.size() || bytes > dst.size() {
            self.fail(format!(
                "copying {bytes} bytes from {} ({}) to {} ({})",
                src.name(),
                src.size(),
                dst.name(),
                dst.size()
            ));
            return;
        }
        if bytes == 0 {
            return;
        }
        let region = [vk::BufferCopy::default().size(bytes)];
        // SAFETY: recording; both buffers have transfer usage, are live and kept alive below;
        // the region is inside both.
        unsafe {
            self.ctx
                .device()
                .cmd_copy_buffer(cmd, src.raw(), dst.raw(), &region)
        };
        self.keep(src);
        self.keep(dst);
    }

    /// Fills the whole buffer with the 32-bit pattern `value` (`0` for zeros, `f32::to_bits`
    /// for a float). A size that is not a multiple of 4 leaves the last bytes untouched.
    pub fn fill_buffer(&mut self, dst: &Buffer, value: u32) {
        let Some(cmd) = self.recording("fill_buffer") else {
            return;
        };
        let size = dst.size() & !3;
        if size == 0 {
            return;
        }
        // SAFETY: recording; the buffer has TRANSFER_DST usage and the range is a multiple of 4
        // within it.
        unsafe {
            self.ctx
                .device()
                .cmd_fill_buffer(cmd, dst.raw(), 0, size, value)
        };
        self.keep(dst);
    }

    /// Writes timestamp `index` of `pool` once all earlier commands have completed. The query
    /// is reset just before, so a pool can be written again in every recording.
    pub fn write_timestamp(&mut self, pool: &TimestampPool, index: u32) {
        let Some(cmd) = self.recording("write_timestamp") else {
            return;
        };
        if index >= pool.count() {
            self.fail(format!(
                "timestamp {index} of pool {} with {} queries",
                pool.name(),
                pool.count()
            ));
            return;
        }
        // SAFETY: recording; the query exists; a reset is ordered before later query commands
        // on the same query in submission order.
        unsafe {
            self.ctx
                .device()
                .cmd_reset_query_pool(cmd, pool.raw(), index, 1)
        };
        // SAFETY: recording; the query was just reset; ALL_COMMANDS is a single stage bit and
        // the queue supports timestamps (checked when the pool was created).
        unsafe {
            self.ctx.sync2().cmd_write_timestamp2(
                cmd,
                vk::PipelineStageFlags2::ALL_COMMANDS,
                pool.raw(),
                index,
            )
        };
        self.keep(pool);
    }

    /// Ends the recording with a barrier from all device writes to host reads (so mapped
    /// buffers can be read once the work is done), returning the command buffer.
    fn end(&mut self, what: &str) -> GpuResult<vk::CommandBuffer> {
        if self.state != State::Recording {
            return Err(self.error.take().unwrap_or_else(|| {
                GpuError::Invalid(format!("{what} without begin() on {}", self.name))
            }));
        }
        let cmd = self.raw;
        let device = self.ctx.device();
        let to_host = [vk::MemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS)
            .src_access_mask(vk::AccessFlags2::MEMORY_WRITE)
            .dst_stage_mask(vk::PipelineStageFlags2::HOST)
            .dst_access_mask(vk::AccessFlags2::HOST_READ)];
        let info = vk::DependencyInfo::default().memory_barriers(&to_host);
        // SAFETY: recording; synchronization2 is enabled.
        unsafe { self.ctx.sync2().cmd_pipeline_barrier2(cmd, &info) };
        // SAFETY: the buffer is recording.
        let ended = unsafe { device.end_command_buffer(cmd) };
        self.state = State::Idle;
        ended.map_err(|r| map_result("vkEndCommandBuffer", r))?;
        if let Some(e) = self.error.take() {
            self.keep_alive.clear();
            return Err(e);
        }
        Ok(cmd)
    }

    /// Ends the recording, submits it and waits up to `timeout`.
    ///
    /// The recording ends with a barrier from all device writes to host reads, so mapped
    /// buffers can be read right after this returns. On [`GpuError::Timeout`] the work stays
    /// in flight: call [`Recorder::wait`] again, or drop the recorder (which waits).
    pub fn submit_and_wait(&mut self, timeout: Duration) -> GpuResult<()> {
        let cmd = self.end("submit_and_wait")?;
        let buffers = [cmd];
        let submit = vk::SubmitInfo::default().command_buffers(&buffers);
        if let Err(e) = self.ctx.submit(&submit, self.fence) {
            self.keep_alive.clear();
            return Err(e);
        }
        self.state = State::Pending;
        self.wait(timeout)
    }

    /// Ends the recording and hands it to whoever owns the queue: the returned [`Handoff`]
    /// signals `value` on `timeline` once submitted and complete. [`Recorder::wait`] blocks
    /// until then, or returns [`GpuError::Cancelled`] if the hand-off is dropped unsubmitted;
    /// [`Recorder::begin`] and dropping the recorder take unsubmitted work back.
    pub fn hand_off(&mut self, timeline: &Timeline, value: u64) -> GpuResult<Handoff> {
        if timeline.context().device().handle() != self.ctx.device().handle() {
            return Err(GpuError::Invalid(format!(
                "{}: timeline {} belongs to another device",
                self.name,
                timeline.name()
            )));
        }
        let cmd = self.end("hand_off")?;
        let (handoff, ticket) = hand_off(cmd, timeline, value);
        self.keep(timeline);
        self.ticket = Some(ticket);
        self.state = State::Handed;
        Ok(handoff)
    }

    /// Wall time from the submission of the last handed-off work to its observed completion:
    /// an upper bound of its device time.
    pub fn last_latency(&self) -> Option<Duration> {
        self.last_latency
    }

    /// Waits up to `timeout` for the last submission (no-op when none is in flight).
    pub fn wait(&mut self, timeout: Duration) -> GpuResult<()> {
        if self.state == State::Handed {
            let outcome = match &self.ticket {
                Some(ticket) => ticket.wait(timeout, &self.name)?,
                None => Outcome::NeverRan,
            };
            self.ticket = None;
            self.state = State::Idle;
            self.keep_alive.clear();
            self.bound = None;
            return match outcome {
                Outcome::Done { since_submit } => {
                    self.last_latency = Some(since_submit);
                    Ok(())
                }
                Outcome::NeverRan => Err(GpuError::Cancelled {
                    what: self.name.clone(),
                }),
            };
        }
        if self.state != State::Pending {
            return Ok(());
        }
        self.ctx.wait_fence(self.fence, timeout, &self.name)?;
        let device = self.ctx.device();
        // SAFETY: the fence is signalled and no submission uses it now.
        unsafe { device.reset_fences(&[self.fence]) }
            .map_err(|r| map_result("vkResetFences", r))?;
        self.state = State::Idle;
        self.keep_alive.clear();
        self.bound = None;
        Ok(())
    }
}

/// Workgroup counts covering `n` threads in groups of `workgroup` with at most `max[0]` groups
/// along x: `y = ceil(groups / max_x)` rows of `x = ceil(groups / y)` (balanced, so fewer idle
/// threads than filling x to the limit). `None` if even that exceeds `max[1]`.
pub fn grid_1d(n: u32, workgroup: u32, max: [u32; 3]) -> Option<[u32; 3]> {
    let groups = n.div_ceil(workgroup.max(1));
    if groups == 0 {
        return Some([0, 1, 1]);
    }
    let y = groups.div_ceil(max[0].max(1));
    if y > max[1] {
        return None;
    }
    let x = groups.div_ceil(y);
    Some([x, y, 1])
}

#[cfg(test)]
mod tests {
    use super::grid_1d;

    const LAVAPIPE: [u32; 3] = [65535; 3];

    #[test]
    fn small_grids_stay_one_dimensional() {
        assert_eq!(grid_1d(1000, 64, LAVAPIPE), Some([16, 1, 1]));
        assert_eq!(grid_1d(64, 64, LAVAPIPE), Some([1, 1, 1]));
        assert_eq!(grid_1d(0, 64, LAVAPIPE), Some([0, 1, 1]));
    }

    #[test]
    fn large_grids_split_into_rows_that_cover_n() {
        for n in [65535 * 64, 65535 * 64 + 1, 5_000_000, u32::MAX] {
            let [x, y, z] = grid_1d(n, 64, LAVAPIPE).expect("fits");
            assert!(x <= 65535 && y <= 65535 && z == 1);
            assert!(u64::from(x) * u64::from(y) * 64 >= u64::from(n), "n = {n}");
        }
    }

    #[test]
    fn too_many_groups_is_refused() {
        assert_eq!(grid_1d(1 << 20, 1, [16, 16, 1]), None);
    }
}
