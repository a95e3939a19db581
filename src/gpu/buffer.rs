//! Buffers: a `vk::Buffer` bound to a gpu-allocator allocation, freed on drop.
//!
//! Host access ([`Buffer::write`], [`Buffer::read`]) maps the memory directly when it is host
//! visible and coherent (lavapipe: always, its one memory type is both), and otherwise goes
//! through a temporary staging buffer and a copy on the queue, so the same code runs on discrete
//! GPUs whose device-local memory the CPU cannot see.

use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use ash::vk;
use bytemuck::Pod;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};

use super::command::Recorder;
use super::context::Context;
use super::conv;
use super::error::{map_allocation, map_result, GpuError, GpuResult};

/// How long a staging copy may take before it is reported as a timeout.
const STAGING_TIMEOUT: Duration = Duration::from_secs(120);

/// What a buffer is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BufferUsage {
    /// A shader storage buffer (also a transfer source and destination, so it can be filled,
    /// uploaded through staging and read back). Limited to `maxStorageBufferRange`.
    Storage,
    /// Only a transfer source and destination: staging and readback buffers. No size limit
    /// beyond memory.
    Staging,
    /// A vertex buffer for graphics pipelines (also a transfer destination for uploads).
    Vertex,
    /// An index buffer for graphics pipelines (also a transfer destination for uploads).
    Index,
}

/// Where the memory lives (the allocator picks a memory type accordingly).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MemoryLocation {
    /// Fastest for the GPU; the CPU may not see it (then host access goes through staging).
    GpuOnly,
    /// CPU writes, GPU reads (uploads, per-step parameters).
    CpuToGpu,
    /// GPU writes, CPU reads (readback).
    GpuToCpu,
}

/// Parameters of [`Buffer::with_desc`].
#[derive(Clone, Copy, Debug)]
pub struct BufferDesc<'a> {
    /// Shown in validation messages and leak reports, e.g. `"admm.face_jacobians"`.
    pub name: &'a str,
    /// Size in bytes (non-zero).
    pub size: u64,
    pub usage: BufferUsage,
    pub location: MemoryLocation,
}

impl<'a> BufferDesc<'a> {
    /// A device-local storage buffer: the usual solver state.
    pub fn storage(name: &'a str, size: u64) -> Self {
        Self {
            name,
            size,
            usage: BufferUsage::Storage,
            location: MemoryLocation::GpuOnly,
        }
    }
}

/// A GPU buffer. Cloning shares it (an `Arc`); the last clone frees it. Descriptor sets and
/// recorders keep clones of what they reference, so a buffer cannot be freed while the GPU may
/// still use it.
#[derive(Clone)]
pub struct Buffer {
    inner: Arc<BufferInner>,
}

struct BufferInner {
    ctx: Context,
    raw: vk::Buffer,
    /// `None` before binding and after teardown. A mutex so that `write(&self)` can reach the
    /// mapped slice without `unsafe`.
    allocation: Mutex<Option<Allocation>>,
    size: u64,
    name: String,
    usage: BufferUsage,
    location: MemoryLocation,
}

impl Drop for BufferInner {
    fn drop(&mut self) {
        // SAFETY: the buffer belongs to this device; nothing can use it any more (every user
        // holds a clone of the `Arc` this lives in, and recorders wait for their work).
        // Destroying a null handle (failed construction) is a no-op.
        unsafe { self.ctx.device().destroy_buffer(self.raw, None) };
        let allocation = self
            .allocation
            .get_mut()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        if let Some(allocation) = allocation {
            let name = &self.name;
            let result = self
                .ctx
                .with_allocator(|a| a.free(allocation).map_err(|e| map_allocation(name, e)));
            if let Err(e) = result {
                self.ctx
                    .message_log()
                    .note(format!("[foldfree] freeing buffer {name}: {e}"));
            }
        }
    }
}

impl std::fmt::Debug for Buffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Buffer")
            .field("name", &self.inner.name)
            .field("size", &self.inner.size)
            .field("usage", &self.inner.usage)
            .field("location", &self.inner.location)
            .finish()
    }
}

impl Buffer {
    /// Creates a buffer of `bytes` bytes. Storage buffers above the device's
    /// `maxStorageBufferRange` are refused with [`GpuError::BufferTooLarge`] before anything is
    /// allocated (a shader could not see past the limit anyway).
    pub fn new(
        ctx: &Context,
        name: &str,
        bytes: u64,
        usage: BufferUsage,
        location: MemoryLocation,
    ) -> GpuResult<Buffer> {
        Self::with_desc(
            ctx,
            &BufferDesc {
                name,
                size: bytes,
                usage,
                location,
            },
        )
    }

    /// A device-local storage buffer holding `data`.
    pub fn from_slice<T: Pod>(ctx: &Context, name: &str, data: &[T]) -> GpuResult<Buffer> {
        let bytes = std::mem::size_of_val(data) as u64;
        let buffer = Self::with_desc(ctx, &BufferDesc::storage(name, bytes))?;
        buffer.write(data)?;
        Ok(buffer)
    }

    /// [`Buffer::new`] with a parameter struct.
    pub fn with_desc(ctx: &Context, desc: &BufferDesc<'_>) -> GpuResult<Buffer> {
        if desc.size == 0 {
            return Err(GpuError::Invalid(format!(
                "buffer {}: size 0 (Vulkan buffers cannot be empty)",
                desc.name
            )));
        }
        let limit = ctx.limits().max_storage_buffer_range;
        if desc.usage == BufferUsage::Storage && desc.size > limit {
            return Err(GpuError::BufferTooLarge {
                name: desc.name.to_string(),
                bytes: desc.size,
                limit,
            });
        }
        let info = vk::BufferCreateInfo::default()
            .size(desc.size)
            .usage(conv::map_buffer_usage(desc.usage))
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid create info; the handle is owned by `inner` right below.
        let raw = unsafe { ctx.device().create_buffer(&info, None) }
            .map_err(|r| map_result("vkCreateBuffer", r))?;
        // From here on, dropping `inner` cleans up whatever was created.
        let inner = BufferInner {
            ctx: ctx.clone(),
            raw,
            allocation: Mutex::new(None),
            size: desc.size,
            name: desc.name.to_string(),
            usage: desc.usage,
            location: desc.location,
        };
        // SAFETY: `raw` is a live buffer of this device.
        let requirements = unsafe { ctx.device().get_buffer_memory_requirements(raw) };
        let allocation = ctx.with_allocator(|a| {
            a.allocate(&AllocationCreateDesc {
                name: desc.name,
                requirements,
                location: conv::map_memory_location(desc.location),
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            })
            .map_err(|e| map_allocation(desc.name, e))
        })?;
        // SAFETY: the memory handle is only used to bind this buffer, and the allocation is
        // freed only after the buffer is destroyed (`Drop for BufferInner`).
        let memory = unsafe { allocation.memory() };
        let offset = allocation.offset();
        *inner
            .allocation
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some(allocation);
        // SAFETY: the allocation satisfies `requirements` (size, alignment, memory type) and the
        // buffer has no memory bound yet.
        unsafe { ctx.device().bind_buffer_memory(raw, memory, offset) }
            .map_err(|r| map_result("vkBindBufferMemory", r))?;
        ctx.set_name(raw, desc.name);
        Ok(Buffer {
            inner: Arc::new(inner),
        })
    }

    /// Size in bytes.
    pub fn size(&self) -> u64 {
        self.inner.size
    }

    /// The name given at creation.
    pub fn name(&self) -> &str {
        &self.inner.name
    }

    pub fn usage(&self) -> BufferUsage {
        self.inner.usage
    }

    pub fn location(&self) -> MemoryLocation {
        self.inner.location
    }

    /// The raw handle (valid while any clone of this buffer lives).
    pub fn raw(&self) -> vk::Buffer {
        self.inner.raw
    }

    pub(crate) fn context(&self) -> &Context {
        &self.inner.ctx
    }

    /// Whether the CPU can map this buffer coherently (then host access needs no staging).
    pub fn is_host_visible(&self) -> bool {
        self.inner
            .allocation
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .as_ref()
            .is_some_and(coherent)
    }

    /// Copies `data` to the start of the buffer, waiting until it is there.
    ///
    /// No GPU work may use the buffer meanwhile; with this layer's blocking
    /// [`Recorder::submit_and_wait`] that holds unless another thread is submitting.
    pub fn write<T: Pod>(&self, data: &[T]) -> GpuResult<()> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let len = bytes.len() as u64;
        if len > self.inner.size {
            return Err(GpuError::Invalid(format!(
                "writing {len} bytes into buffer {} of {} bytes",
                self.inner.name, self.inner.size
            )));
        }
        if bytes.is_empty() || self.write_mapped(bytes)? {
            return Ok(());
        }
        self.upload_staged(bytes)
    }

    /// Like [`Buffer::write`], but always through a staging buffer and a copy on the queue —
    /// the path device-local memory of a discrete GPU takes. Public so that it can be tested
    /// and timed on devices (lavapipe) where `write` maps the memory directly.
    pub fn upload_staged<T: Pod>(&self, data: &[T]) -> GpuResult<()> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let len = bytes.len() as u64;
        if len > self.inner.size {
            return Err(GpuError::Invalid(format!(
                "writing {len} bytes into buffer {} of {} bytes",
                self.inner.name, self.inner.size
            )));
        }
        if bytes.is_empty() {
            return Ok(());
        }
        let ctx = &self.inner.ctx;
        let staging = Buffer::new(
            ctx,
            &format!("{}.staging_upload", self.name()),
            len,
            BufferUsage::Staging,
            MemoryLocation::CpuToGpu,
        )?;
        if !staging.write_mapped(bytes)? {
            return Err(GpuError::Unsupported(format!(
                "no host-visible coherent memory for {}",
                staging.name()
            )));
        }
        let mut rec = Recorder::new(ctx, &format!("{}.upload", self.name()))?;
        rec.begin()?;
        rec.copy_buffer(&staging, self, len);
        rec.submit_and_wait(STAGING_TIMEOUT)
    }

    /// The whole buffer as `size / size_of::<T>()` values, after all submitted GPU work that
    /// wrote it (every [`Recorder::submit_and_wait`] ends with a barrier that makes device
    /// writes visible to the host).
    pub fn read<T: Pod>(&self) -> GpuResult<Vec<T>> {
        let elem = std::mem::size_of::<T>();
        if elem == 0 {
            return Err(GpuError::Invalid("reading zero-sized values".into()));
        }
        let count = (self.inner.size / elem as u64) as usize;
        let mut out = vec![T::zeroed(); count];
        let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
        if dst.is_empty() || self.read_mapped(dst)? {
            return Ok(out);
        }
        self.download_staged_into(dst)?;
        Ok(out)
    }

    /// Like [`Buffer::read`], but always through a copy into a staging buffer (see
    /// [`Buffer::upload_staged`]).
    pub fn download_staged<T: Pod>(&self) -> GpuResult<Vec<T>> {
        let elem = std::mem::size_of::<T>();
        if elem == 0 {
            return Err(GpuError::Invalid("reading zero-sized values".into()));
        }
        let count = (self.inner.size / elem as u64) as usize;
        let mut out = vec![T::zeroed(); count];
        let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
        if !dst.is_empty() {
            self.download_staged_into(dst)?;
        }
        Ok(out)
    }

    fn download_staged_into(&self, dst: &mut [u8]) -> GpuResult<()> {
        let ctx = &self.inner.ctx;
        let len = dst.len() as u64;
        let staging = Buffer::new(
            ctx,
            &format!("{}.staging_download", self.name()),
            len,
            BufferUsage::Staging,
            MemoryLocation::GpuToCpu,
        )?;
        let mut rec = Recorder::new(ctx, &format!("{}.download", self.name()))?;
        rec.begin()?;
        rec.copy_buffer(self, &staging, len);
        rec.submit_and_wait(STAGING_TIMEOUT)?;
        if !staging.read_mapped(dst)? {
            return Err(GpuError::Unsupported(format!(
                "no host-visible coherent memory for {}",
                staging.name()
            )));
        }
        Ok(())
    }

    /// Copies `bytes` into the mapping; `false` when the memory is not host visible and coherent.
    fn write_mapped(&self, bytes: &[u8]) -> GpuResult<bool> {
        let mut guard = self
            .inner
            .allocation
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        let Some(allocation) = guard.as_mut() else {
            return Ok(false);
        };
        if !coherent(allocation) {
            return Ok(false);
        }
        let mapped = allocation
            .mapped_slice_mut()
            .ok_or_else(|| GpuError::Invalid(format!("buffer {} is not mapped", self.name())))?;
        mapped[..bytes.len()].copy_from_slice(bytes);
        Ok(true)
    }

    /// Fills `dst` from the mapping; `false` when the memory is not host visible and coherent.
    fn read_mapped(&self, dst: &mut [u8]) -> GpuResult<bool> {
        let guard = self
            .inner
            .allocation
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        let Some(allocation) = guard.as_ref() else {
            return Ok(false);
        };
        if !coherent(allocation) {
            return Ok(false);
        }
        let mapped = allocation
            .mapped_slice()
            .ok_or_else(|| GpuError::Invalid(format!("buffer {} is not mapped", self.name())))?;
        dst.copy_from_slice(&mapped[..dst.len()]);
        Ok(true)
    }
}

/// Mapped and coherent: host reads and writes need no flush or invalidate.
fn coherent(allocation: &Allocation) -> bool {
    allocation.mapped_ptr().is_some()
        && allocation
            .memory_properties()
            .contains(vk::MemoryPropertyFlags::HOST_COHERENT)
}
