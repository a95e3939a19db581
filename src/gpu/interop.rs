//! Working with a host application's own Vulkan objects: a buffer the host created
//! ([`ForeignBuffer`]), a command buffer the host is recording ([`ForeignCommandBuffer`]), a
//! descriptor set that binds such buffers next to ours ([`ForeignSet`]), and one dispatch that
//! writes a host range with the barriers around it ([`ForeignDispatch`]), either recorded into
//! the host's command buffer or submitted on the context's (the host's) queue.
//!
//! The host vouches for its handles once, in the `unsafe` constructors
//! [`ForeignBuffer::new`] and [`ForeignCommandBuffer::new`]; everything after that is checked
//! and safe. Nothing here creates, frees or destroys a host object.

use std::sync::Arc;

/// How long an engine-submitted dispatch may take before it is reported as hung.
const DISPATCH_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(600);

use ash::vk;

use super::buffer::Buffer;
use super::command::grid_1d;
use super::context::Context;
use super::error::{map_result, GpuError, GpuResult};
use super::pipeline::{allocate_storage_set, check_storage_buffer, ComputePipeline};

/// A `vk::Buffer` owned by the host application.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ForeignBuffer {
    raw: vk::Buffer,
    size: u64,
}

impl ForeignBuffer {
    /// Wraps the host's buffer.
    ///
    /// # Safety
    /// `raw` must be a buffer of the device the [`Context`] it is used with was made from
    /// (`Context::from_host`), created with `VK_BUFFER_USAGE_STORAGE_BUFFER_BIT`, exactly `size`
    /// bytes large (or larger: `size` is the bound this layer checks writes against), bound to
    /// memory, and with `VK_SHARING_MODE_CONCURRENT` or owned by the context's queue family.
    /// It must stay alive (and bound to the same memory) until every descriptor set and every
    /// recorded or submitted command that uses it is finished: for submissions made by this
    /// layer that is when the call returns; for commands recorded into a
    /// [`ForeignCommandBuffer`] see its contract.
    pub unsafe fn new(raw: vk::Buffer, size: u64) -> ForeignBuffer {
        ForeignBuffer { raw, size }
    }

    /// A null handle with a size, for tests of layout arithmetic that never reach Vulkan.
    #[cfg(test)]
    pub(crate) fn for_layout_tests(size: u64) -> ForeignBuffer {
        ForeignBuffer {
            raw: vk::Buffer::null(),
            size,
        }
    }

    pub fn raw(&self) -> vk::Buffer {
        self.raw
    }

    /// Size in bytes, as the host declared it.
    pub fn size(&self) -> u64 {
        self.size
    }
}

/// A primary command buffer the host is recording.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ForeignCommandBuffer {
    raw: vk::CommandBuffer,
}

impl ForeignCommandBuffer {
    /// Wraps the host's command buffer.
    ///
    /// # Safety
    /// `raw` must come from the context's device, be in the recording state, outside a render
    /// pass, from a pool of the context's queue family with compute support, and not be recorded
    /// by another thread during the call. It must be submitted to the context's queue (the one
    /// the host lent in `HostDesc`): the entry barrier relies on submission order with the
    /// layer's own earlier uploads. Every object a recording call returns (e.g. the
    /// [`ForeignSet`] a dispatch used) must be kept alive until the command buffer has finished
    /// executing, or has been reset or freed without being submitted.
    pub unsafe fn new(raw: vk::CommandBuffer) -> ForeignCommandBuffer {
        ForeignCommandBuffer { raw }
    }

    pub fn raw(&self) -> vk::CommandBuffer {
        self.raw
    }
}

/// One side of a barrier, in synchronization2 terms, as the host names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HostAccess {
    pub stage: vk::PipelineStageFlags2,
    pub access: vk::AccessFlags2,
}

impl HostAccess {
    /// "Anything before / after on this queue, and host reads": the conservative choice when
    /// the host does not say (used for submissions this layer makes itself).
    pub fn any() -> HostAccess {
        HostAccess {
            stage: vk::PipelineStageFlags2::ALL_COMMANDS | vk::PipelineStageFlags2::HOST,
            access: vk::AccessFlags2::MEMORY_READ
                | vk::AccessFlags2::MEMORY_WRITE
                | vk::AccessFlags2::HOST_READ
                | vk::AccessFlags2::HOST_WRITE,
        }
    }
}

/// A byte range of a [`ForeignBuffer`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ForeignRange {
    pub buffer: ForeignBuffer,
    pub offset: u64,
    pub range: u64,
}

/// What one binding of a [`ForeignSet`] refers to.
#[derive(Clone, Copy, Debug)]
pub enum SetEntry<'a> {
    /// One of this layer's storage buffers, whole.
    Owned(&'a Buffer),
    /// A range of a host buffer. `offset` must be a multiple of the device's
    /// `minStorageBufferOffsetAlignment` ([`min_storage_buffer_offset_alignment`]) and `range`
    /// at most `maxStorageBufferRange`.
    Foreign(ForeignRange),
}

/// The device's `minStorageBufferOffsetAlignment` (a descriptor's offset must be a multiple).
pub fn min_storage_buffer_offset_alignment(ctx: &Context) -> u64 {
    // SAFETY: plain query on the context's live instance and physical device.
    let props = unsafe {
        ctx.raw_instance()
            .get_physical_device_properties(ctx.physical_device())
    };
    props.limits.min_storage_buffer_offset_alignment.max(1)
}

/// Like [`super::DescriptorSet`], but binding may also refer to host buffers. It is a set of the
/// pipeline's own set-0 layout, made by the same code as `DescriptorSet`, in its own one-set
/// pool. Keeps the pipeline and the owned buffers alive; the host keeps its own.
pub struct ForeignSet {
    inner: Arc<ForeignSetInner>,
}

struct ForeignSetInner {
    ctx: Context,
    pool: vk::DescriptorPool,
    raw: vk::DescriptorSet,
    name: String,
    pipeline: ComputePipeline,
    _buffers: Vec<Buffer>,
}

impl Drop for ForeignSetInner {
    fn drop(&mut self) {
        let device = self.ctx.device();
        // SAFETY: the set is unused (this layer's submissions are waited for; for recordings
        // into a host command buffer the host promised to keep the set alive until it is done);
        // destroying the pool frees the set. A null pool is a no-op.
        unsafe { device.destroy_descriptor_pool(self.pool, None) };
    }
}

impl std::fmt::Debug for ForeignSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ForeignSet")
            .field("name", &self.inner.name)
            .field("pipeline", &self.inner.pipeline.name())
            .finish()
    }
}

impl ForeignSet {
    /// Binds `entries[i]` to binding `i` of `pipeline`'s set 0.
    pub fn new(
        pipeline: &ComputePipeline,
        name: &str,
        entries: &[SetEntry<'_>],
    ) -> GpuResult<ForeignSet> {
        let ctx = pipeline.context();
        if entries.len() != pipeline.bindings() as usize {
            return Err(GpuError::Invalid(format!(
                "descriptor set {name}: {} entries for pipeline {} with {} bindings",
                entries.len(),
                pipeline.name(),
                pipeline.bindings()
            )));
        }
        let align = min_storage_buffer_offset_alignment(ctx);
        let max_range = ctx.limits().max_storage_buffer_range;
        let mut owned = Vec::new();
        let mut infos: Vec<vk::DescriptorBufferInfo> = Vec::with_capacity(entries.len());
        for (i, entry) in entries.iter().enumerate() {
            let info = match entry {
                SetEntry::Owned(b) => {
                    check_storage_buffer(ctx, name, b)?;
                    owned.push((*b).clone());
                    vk::DescriptorBufferInfo::default()
                        .buffer(b.raw())
                        .offset(0)
                        .range(vk::WHOLE_SIZE)
                }
                SetEntry::Foreign(r) => {
                    let end = r.offset.checked_add(r.range);
                    if r.range == 0
                        || r.offset % align != 0
                        || r.range > max_range
                        || !matches!(end, Some(e) if e <= r.buffer.size)
                    {
                        return Err(GpuError::Invalid(format!(
                            "descriptor set {name}, binding {i}: host range at offset {} of {} \
                             bytes in a buffer of {} (offset must be a multiple of {align}, range \
                             1..={max_range} bytes and inside the buffer)",
                            r.offset, r.range, r.buffer.size
                        )));
                    }
                    vk::DescriptorBufferInfo::default()
                        .buffer(r.buffer.raw)
                        .offset(r.offset)
                        .range(r.range)
                }
            };
            infos.push(info);
        }

        // The pipeline's own set layout: the set binds with the pipeline's layout by definition.
        let (pool, raw) = allocate_storage_set(pipeline, name, &infos)?;
        let inner = ForeignSetInner {
            ctx: ctx.clone(),
            pool,
            raw,
            name: name.to_string(),
            pipeline: pipeline.clone(),
            _buffers: owned,
        };
        Ok(ForeignSet {
            inner: Arc::new(inner),
        })
    }

    pub fn name(&self) -> &str {
        &self.inner.name
    }
}

/// One dispatch of `pipeline` with `set` over `threads` invocations (a 1-D grid, see
/// [`grid_1d`]) that writes `target`, a host range, with the barriers around it:
///
/// - entry: a buffer barrier on `target` from `before` (the host's earlier accesses to it) to
///   compute-shader storage writes, and a global barrier from transfer writes to compute-shader
///   storage reads (this layer's staged uploads of the dispatch's inputs);
/// - exit: a buffer barrier on `target` from compute-shader storage writes to `after`.
#[derive(Clone, Copy, Debug)]
pub struct ForeignDispatch<'a> {
    pub pipeline: &'a ComputePipeline,
    pub set: &'a ForeignSet,
    /// Push-constant bytes (a multiple of 4, at most the pipeline's block).
    pub push: &'a [u8],
    pub threads: u32,
    pub target: ForeignRange,
    /// Whether the kernel writes `target` (UV scatter) or only reads it (mesh gather).
    pub target_use: TargetUse,
    pub before: HostAccess,
    pub after: HostAccess,
}

/// What a [`ForeignDispatch`] does to its host range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TargetUse {
    /// The kernel writes the range: entry barrier to storage writes, exit barrier from them.
    Written,
    /// The kernel only reads the range (and writes this layer's own buffers): entry barrier
    /// from the host's writes to storage reads; exit: an execution dependency so the host's
    /// later writes wait for the reads, and this layer's storage writes made visible to host
    /// reads and to later transfers (read-back).
    Read,
}

impl ForeignDispatch<'_> {
    fn check(&self) -> GpuResult<[u32; 3]> {
        let ctx = self.pipeline.context();
        if !Arc::ptr_eq(&self.set.inner.ctx.shared, &ctx.shared)
            || self.set.inner.pipeline.bindings() != self.pipeline.bindings()
        {
            return Err(GpuError::Invalid(format!(
                "set {} does not fit pipeline {}",
                self.set.name(),
                self.pipeline.name()
            )));
        }
        if self.push.len() % 4 != 0
            || self.push.len() > self.pipeline.push_constant_bytes() as usize
        {
            return Err(GpuError::Invalid(format!(
                "{} push-constant bytes for pipeline {} (block of {})",
                self.push.len(),
                self.pipeline.name(),
                self.pipeline.push_constant_bytes()
            )));
        }
        let max = ctx.limits().max_compute_work_group_count;
        grid_1d(self.threads, self.pipeline.workgroup_size(), max).ok_or_else(|| {
            GpuError::Invalid(format!(
                "{} threads do not fit a {max:?} workgroup grid",
                self.threads
            ))
        })
    }

    /// Records barriers and the dispatch into `cmd` (already checked).
    fn record_raw(&self, cmd: vk::CommandBuffer, groups: [u32; 3]) {
        let ctx = self.pipeline.context();
        let device = ctx.device();
        let t = self.target;
        let (use_access, exit_src_access) = match self.target_use {
            TargetUse::Written => (
                vk::AccessFlags2::SHADER_STORAGE_WRITE,
                vk::AccessFlags2::SHADER_STORAGE_WRITE,
            ),
            TargetUse::Read => (
                vk::AccessFlags2::SHADER_STORAGE_READ,
                vk::AccessFlags2::NONE,
            ),
        };
        let entry_buffer = [vk::BufferMemoryBarrier2::default()
            .src_stage_mask(self.before.stage)
            .src_access_mask(self.before.access)
            .dst_stage_mask(vk::PipelineStageFlags2::COMPUTE_SHADER)
            .dst_access_mask(use_access)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .buffer(t.buffer.raw)
            .offset(t.offset)
            .size(t.range)];
        let entry_global = [vk::MemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::ALL_TRANSFER)
            .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
            .dst_stage_mask(vk::PipelineStageFlags2::COMPUTE_SHADER)
            .dst_access_mask(vk::AccessFlags2::SHADER_STORAGE_READ)];
        let entry = vk::DependencyInfo::default()
            .memory_barriers(&entry_global)
            .buffer_memory_barriers(&entry_buffer);
        // SAFETY: `cmd` is recording (the host's promise, or ours); synchronization2 is enabled
        // on the device (a requirement of `Context::from_host`); the range lies in the buffer.
        unsafe { ctx.sync2().cmd_pipeline_barrier2(cmd, &entry) };
        // SAFETY: recording; the pipeline is live (the set holds a clone).
        unsafe {
            device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline.raw())
        };
        // SAFETY: recording; the set was allocated with the pipeline's own set-0 layout.
        unsafe {
            device.cmd_bind_descriptor_sets(
                cmd,
                vk::PipelineBindPoint::COMPUTE,
                self.pipeline.layout(),
                0,
                &[self.set.inner.raw],
                &[],
            )
        };
        if !self.push.is_empty() {
            // SAFETY: recording; the bytes fit the layout's push-constant range (checked).
            unsafe {
                device.cmd_push_constants(
                    cmd,
                    self.pipeline.layout(),
                    vk::ShaderStageFlags::COMPUTE,
                    0,
                    self.push,
                )
            };
        }
        if !groups.contains(&0) {
            // SAFETY: recording with a compute pipeline and its set bound; counts within limits.
            unsafe { device.cmd_dispatch(cmd, groups[0], groups[1], groups[2]) };
        }
        let exit_buffer = [vk::BufferMemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::COMPUTE_SHADER)
            .src_access_mask(exit_src_access)
            .dst_stage_mask(self.after.stage)
            .dst_access_mask(self.after.access)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .buffer(t.buffer.raw)
            .offset(t.offset)
            .size(t.range)];
        // The layer's own outputs of a gather, read back by the host or copied to staging.
        let exit_global = [vk::MemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::COMPUTE_SHADER)
            .src_access_mask(vk::AccessFlags2::SHADER_STORAGE_WRITE)
            .dst_stage_mask(vk::PipelineStageFlags2::ALL_TRANSFER | vk::PipelineStageFlags2::HOST)
            .dst_access_mask(vk::AccessFlags2::TRANSFER_READ | vk::AccessFlags2::HOST_READ)];
        let exit = match self.target_use {
            TargetUse::Written => {
                vk::DependencyInfo::default().buffer_memory_barriers(&exit_buffer)
            }
            TargetUse::Read => vk::DependencyInfo::default()
                .memory_barriers(&exit_global)
                .buffer_memory_barriers(&exit_buffer),
        };
        // SAFETY: as for the entry barrier.
        unsafe { ctx.sync2().cmd_pipeline_barrier2(cmd, &exit) };
    }

    /// Records the barriers and the dispatch into the host's command buffer. The caller must
    /// keep `set` (and so the owned buffers it binds) alive until that command buffer is done.
    pub fn record(&self, cmd: ForeignCommandBuffer) -> GpuResult<()> {
        let groups = self.check()?;
        self.record_raw(cmd.raw, groups);
        Ok(())
    }

    /// Records into a command buffer of this layer's own, submits it on the context's queue
    /// (the host's) and waits for a fence of its own. Everything it created is destroyed
    /// before it returns.
    pub fn submit_and_wait(&self, name: &str) -> GpuResult<()> {
        let groups = self.check()?;
        let ctx = self.pipeline.context();
        let mut one = OneShot::new(ctx, name)?;
        let device = ctx.device();
        let info = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: a freshly allocated command buffer in the initial state.
        unsafe { device.begin_command_buffer(one.cmd, &info) }
            .map_err(|r| map_result("vkBeginCommandBuffer", r))?;
        self.record_raw(one.cmd, groups);
        // SAFETY: the buffer is recording.
        unsafe { device.end_command_buffer(one.cmd) }
            .map_err(|r| map_result("vkEndCommandBuffer", r))?;
        one.submit_and_wait()
    }
}

/// A command pool, one command buffer and a fence, destroyed on drop (after waiting for the
/// fence if the buffer was submitted).
struct OneShot {
    ctx: Context,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    pending: bool,
}

impl Drop for OneShot {
    fn drop(&mut self) {
        let device = self.ctx.device();
        if self.pending {
            // SAFETY: our fence, submitted with our command buffer; waiting forever is the only
            // way to know it is no longer in use (on device loss the wait returns at once).
            let _ = unsafe { device.wait_for_fences(&[self.fence], true, u64::MAX) };
        }
        // SAFETY: the fence is no longer used by a pending submission (waited above).
        unsafe { device.destroy_fence(self.fence, None) };
        // SAFETY: as above; destroying the pool frees its command buffer.
        unsafe { device.destroy_command_pool(self.pool, None) };
    }
}

impl OneShot {
    fn new(ctx: &Context, name: &str) -> GpuResult<OneShot> {
        let device = ctx.device();
        let mut one = OneShot {
            ctx: ctx.clone(),
            pool: vk::CommandPool::null(),
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            pending: false,
        };
        let pool_info = vk::CommandPoolCreateInfo::default()
            .flags(vk::CommandPoolCreateFlags::TRANSIENT)
            .queue_family_index(ctx.queue_family_index());
        // SAFETY: valid create info; destroyed in Drop.
        one.pool = unsafe { device.create_command_pool(&pool_info, None) }
            .map_err(|r| map_result("vkCreateCommandPool", r))?;
        ctx.set_name(one.pool, &format!("{name}.pool"));
        let alloc_info = vk::CommandBufferAllocateInfo::default()
            .command_pool(one.pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool is live; the buffer is freed with it.
        let buffers = unsafe { device.allocate_command_buffers(&alloc_info) }
            .map_err(|r| map_result("vkAllocateCommandBuffers", r))?;
        one.cmd = buffers.first().copied().ok_or_else(|| {
            GpuError::Invalid("vkAllocateCommandBuffers returned no buffer".into())
        })?;
        ctx.set_name(one.cmd, &format!("{name}.commands"));
        // SAFETY: valid create info; destroyed in Drop.
        one.fence = unsafe { device.create_fence(&vk::FenceCreateInfo::default(), None) }
            .map_err(|r| map_result("vkCreateFence", r))?;
        ctx.set_name(one.fence, &format!("{name}.fence"));
        Ok(one)
    }

    fn submit_and_wait(&mut self) -> GpuResult<()> {
        let buffers = [self.cmd];
        let submit = vk::SubmitInfo::default().command_buffers(&buffers);
        // The host promised not to use the queue concurrently; the context locks it anyway.
        self.ctx.submit(&submit, self.fence)?;
        self.pending = true;
        self.ctx
            .wait_fence(self.fence, DISPATCH_TIMEOUT, "interop dispatch")?;
        self.pending = false;
        Ok(())
    }
}
