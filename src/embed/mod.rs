//! Embedding foldfree in a host application's Vulkan renderer: the [`Engine`] runs on the
//! host's device and queue, creates and destroys only its own objects, and writes UVs into the
//! host's buffer.
//!
//! # Setting up
//! 1. Create the device with everything [`required_features`] lists (Vulkan 1.2 with its
//!    `timelineSemaphore` feature, `VK_KHR_synchronization2` and its feature) and a queue
//!    family with compute support.
//! 2. Lend the handles: `unsafe { Context::from_host(HostDesc { .. }) }` — the one place the
//!    host vouches for them (see [`crate::gpu::Context::from_host`]) — and wrap the context with
//!    [`Engine::new`].
//! 3. [`Engine::parameterize`] the host's positions and faces (same pipeline and defaults as
//!    `foldfree param --backend vulkan`) — or, when the mesh already lives in the host's
//!    vertex and index buffers, [`Engine::parameterize_buffers`] with a [`MeshBuffers`]
//!    layout (a gather kernel reads them on the device; entry barrier from
//!    [`MeshBuffers::before`], the host's buffers are only read) — then write the UVs into the
//!    host's buffer with
//!    [`Engine::write_uvs`] (the engine submits and waits) or
//!    [`Engine::record_write_uvs`] (the engine records into the host's command buffer).
//! 4. Drop the engine (and every [`RecordedUvWrite`]) before destroying the device. The engine
//!    destroys its pipelines, buffers, pools and fences, and nothing of the host's: no
//!    instance, device, queue, buffer or memory.
//!
//! # The UV target
//! [`UvTarget`] describes where vertex `i`'s UV goes: two `f32` at byte
//! `offset + i * stride` of the host's buffer. `offset` and `stride` must be multiples of 4
//! (the buffer is bound as an array of 32-bit words), `stride >= 8` (UVs must not overlap),
//! and `offset + (n - 1) * stride + 8` must not exceed the buffer's size. The words between
//! UVs (e.g. positions in an interleaved vertex buffer) are never written. The buffer needs
//! `VK_BUFFER_USAGE_STORAGE_BUFFER_BIT`, and the written span (from `offset` rounded down to
//! `minStorageBufferOffsetAlignment` to the last UV) must fit in `maxStorageBufferRange`.
//!
//! # Synchronisation contract
//! **Queue.** The blocking calls submit to the host's queue (parameterization: one submission
//! per residual check, each signalling a timeline semaphore the engine waits on;
//! [`Engine::write_uvs`]: one, with a fence). A `vk::Queue` needs external synchronization, so
//! while a blocking engine call runs the host must not submit to, wait idle on, or present with
//! that queue, nor call `vkDeviceWaitIdle`, from another thread. Between calls the engine has no
//! work in flight: every call returns only after its work completed. A [`Job`]
//! ([`Engine::start_parameterize`]) instead touches the host's queue only inside
//! [`Job::poll`] / [`Job::finish`] on the host's thread (`JobQueue::BetweenFrames`), or only a
//! queue the host gave it alone (`JobQueue::Own`); see the [`job`] module docs.
//!
//! **[`Engine::write_uvs`] (engine submits).** Entry: the engine's command buffer starts with a
//! barrier from all earlier commands' writes on the queue (`ALL_COMMANDS`/`HOST`,
//! `MEMORY_WRITE`/`HOST_WRITE`) to its compute-shader storage writes on the target span, so
//! host work submitted earlier *to the same queue* is ordered before it; host writes through a
//! mapping are covered by the submission itself. Work on other queues touching the span must be
//! finished (fence or semaphore waited for) by the host before the call. Exit: a barrier from
//! the compute-shader writes to all later commands on the queue and to host reads
//! (`ALL_COMMANDS`/`HOST`, `MEMORY_READ`/`MEMORY_WRITE`/`HOST_READ`); the call returns after
//! the fence signalled, so the host may map and read the span, or use it in its next
//! submission to the same queue, with no further synchronization.
//!
//! **[`Engine::record_write_uvs`] (host's command buffer).** The engine records, into the
//! host's command buffer, (1) a buffer barrier on the target span from the host-specified
//! `before` access (the host's prior accesses to it in submission order) to compute-shader
//! storage writes — that is how the host's prior writes to the range are made visible to (and
//! ordered before) the engine's writes; (2) a global barrier from transfer writes to
//! compute-shader storage reads (the engine's staged upload of the UVs); (3) bind, push,
//! dispatch; (4) a buffer barrier on the span from compute-shader storage writes to the
//! host-specified `after` access (e.g. `VERTEX_ATTRIBUTE_INPUT`/`VERTEX_ATTRIBUTE_READ`). The
//! host must submit that command buffer to the engine's queue and keep the returned
//! [`RecordedUvWrite`] alive until it has finished executing (or was reset unsubmitted). The
//! engine changes the command buffer's bound compute pipeline, descriptor set 0 and push
//! constants: the host must rebind its own compute state afterwards.
//!
//! # Thread safety
//! - [`Engine`] is `Send + Sync`: calls from several threads are allowed; each call builds its
//!   own executor, command pool and fence, and queue submissions are serialized by an internal
//!   lock — which the host cannot see, hence the queue rule above.
//! - [`RecordedUvWrite`] is `Send + Sync`; dropping it frees a descriptor pool of the device.
//! - [`UvTarget`], [`ForeignBuffer`], [`ForeignCommandBuffer`] are plain `Copy` data; the
//!   promises are made in their `unsafe` constructors. Recording into one command buffer from
//!   two threads at once is the host's error (Vulkan requires external synchronization).
#![forbid(unsafe_code)]

pub mod job;

pub use job::{Job, JobOptions, JobPhase, JobProgress, JobQueue};

use crate::gpu::interop::{ForeignDispatch, ForeignRange, ForeignSet, SetEntry, TargetUse};
use crate::gpu::{shaders, vk, Buffer, ComputePipeline, Context};
use crate::init::InitMethod;
use crate::mesh::{self, TriMesh};
use crate::param::admm::AdmmOptions;
use crate::{Error, Result};

pub use crate::gpu::interop::{ForeignBuffer, ForeignCommandBuffer, HostAccess};
pub use crate::gpu::{HostDesc, RequiredFeatures};

/// The file name that validation errors of in-memory meshes carry.
pub const MEMORY_FILE: &str = "<memory>";

/// What the host's instance and device must enable for the engine (API version, device
/// extensions, device features).
pub fn required_features() -> RequiredFeatures {
    crate::gpu::required_features()
}

/// Settings of [`Engine::parameterize`]. `Default` gives the CLI's defaults
/// (`foldfree param`: LSCM start, ADMM on MIPS).
#[derive(Clone, Debug)]
pub struct EmbedOptions {
    pub init: InitMethod,
    pub admm: AdmmOptions,
    /// A bijective map (no boundary overlap; see [`crate::param::global::scaffold`]).
    pub bijective: bool,
    pub validate: mesh::ValidateOptions,
}

impl Default for EmbedOptions {
    fn default() -> Self {
        EmbedOptions {
            init: InitMethod::Lscm,
            admm: AdmmOptions::default(),
            bijective: true,
            validate: mesh::ValidateOptions::default(),
        }
    }
}

/// How one UV is stored in the host's buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UvFormat {
    /// Two IEEE `f32` (u then v), 8 bytes.
    F32x2,
}

impl UvFormat {
    /// Bytes per UV.
    pub fn bytes(self) -> u64 {
        match self {
            UvFormat::F32x2 => 8,
        }
    }
}

/// Where the UVs go: vertex `i` at byte `offset + i * stride` of `buffer` (see the module docs
/// for the alignment rules).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UvTarget {
    pub buffer: ForeignBuffer,
    /// Byte offset of vertex 0's UV; a multiple of 4.
    pub offset: u64,
    /// Bytes between consecutive vertices' UVs; a multiple of 4, at least the UV size.
    pub stride: u64,
    pub format: UvFormat,
}

/// Push constants of `glsl/embed/scatter_uv.comp` (same field order).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
struct ScatterPush {
    n: u32,
    first_word: u32,
    stride_words: u32,
}
const _: () = assert!(std::mem::size_of::<ScatterPush>() == 12);

/// A target resolved against the device: the descriptor range and the kernel's word indices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct ScatterPlan {
    range: ForeignRange,
    push: ScatterPush,
}

/// A run of `n` elements of `elem_bytes` bytes, element `i` at byte `offset + i * stride` of a
/// host buffer, resolved against the device: the bound descriptor range (from `offset` rounded
/// down to `minStorageBufferOffsetAlignment` to the end of the last element) and the kernel's
/// word indices. Shared by the UV scatter and the mesh gather, whose layouts follow one rule.
fn plan_span(
    what: &str,
    buffer: ForeignBuffer,
    offset: u64,
    stride: u64,
    elem_bytes: u64,
    n: usize,
    align: u64,
    max_range: u64,
) -> Result<(ForeignRange, u32, u32)> {
    let bad = |why: String| Error::Usage(format!("{what}: {why}"));
    if n == 0 {
        return Err(bad("no elements".into()));
    }
    if offset % 4 != 0 || stride % 4 != 0 {
        return Err(bad(format!(
            "offset {offset} and stride {stride} must be multiples of 4"
        )));
    }
    if stride < elem_bytes {
        return Err(bad(format!(
            "stride {stride} is less than an element ({elem_bytes} bytes)"
        )));
    }
    let end = (n as u64 - 1)
        .checked_mul(stride)
        .and_then(|x| x.checked_add(offset))
        .and_then(|x| x.checked_add(elem_bytes));
    let Some(end) = end.filter(|&e| e <= buffer.size()) else {
        return Err(bad(format!(
            "{n} elements at offset {offset} with stride {stride} do not fit a buffer of {} bytes",
            buffer.size()
        )));
    };
    let align = align.max(1);
    let base = offset - offset % align;
    let range = end - base;
    if range > max_range {
        return Err(bad(format!(
            "the span is {range} bytes, more than the device's maxStorageBufferRange \
             ({max_range})"
        )));
    }
    let words = |x: u64| u32::try_from(x / 4).map_err(|_| bad("span too large".into()));
    Ok((
        ForeignRange {
            buffer,
            offset: base,
            range,
        },
        words(offset - base)?,
        words(stride)?,
    ))
}

impl UvTarget {
    /// Checks the layout for `n ≥ 1` UVs and derives the bound range: from `offset` rounded down
    /// to `align` (`minStorageBufferOffsetAlignment`) to the end of the last UV.
    fn plan(&self, n: usize, align: u64, max_range: u64) -> Result<ScatterPlan> {
        let (range, first_word, stride_words) = plan_span(
            "UV target",
            self.buffer,
            self.offset,
            self.stride,
            self.format.bytes(),
            n,
            align,
            max_range,
        )?;
        Ok(ScatterPlan {
            range,
            push: ScatterPush {
                n: u32::try_from(n).map_err(|_| Error::Usage(format!("{n} vertices")))?,
                first_word,
                stride_words,
            },
        })
    }
}

/// A mesh that lives in the host's own buffers: vertex `i`'s position is three `f32` (x, y, z)
/// at byte `position_offset + i * position_stride` of `positions` (e.g. an interleaved vertex
/// buffer), face `f` is three `u32` vertex indices (counter-clockwise) at byte
/// `index_offset + 12 f` of `indices`. Offsets and the stride are multiples of 4; both buffers
/// need `VK_BUFFER_USAGE_STORAGE_BUFFER_BIT` (they are read by a compute kernel, never written).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshBuffers {
    pub positions: ForeignBuffer,
    pub position_offset: u64,
    pub position_stride: u64,
    pub vertex_count: u32,
    pub indices: ForeignBuffer,
    pub index_offset: u64,
    pub face_count: u32,
    /// The host's earlier accesses to both ranges on this queue (e.g. the transfer that
    /// uploaded them); [`HostAccess::any`] when unsure.
    pub before: HostAccess,
}

/// Push constants of `glsl/embed/gather_words.comp` (same field order).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
struct GatherPush {
    n: u32,
    first_word: u32,
    stride_words: u32,
    width: u32,
}
const _: () = assert!(std::mem::size_of::<GatherPush>() == 16);

/// CPU twin of `glsl/embed/gather_words.comp`: `n` elements of `width` words, element `i`
/// starting at word `first_word + i * stride_words` of `src`, packed. `None` if `src` is too
/// short (the kernel's caller guarantees it is not).
pub fn gather_words(
    src: &[u32],
    n: usize,
    first_word: usize,
    stride_words: usize,
    width: usize,
) -> Option<Vec<u32>> {
    let mut out = Vec::with_capacity(n * width);
    for i in 0..n {
        let s = first_word + i * stride_words;
        out.extend_from_slice(src.get(s..s + width)?);
    }
    Some(out)
}

/// Keeps what a [`Engine::record_write_uvs`] recording uses alive (the UV source buffer and the
/// descriptor set). Drop it only after the host's command buffer has finished executing.
#[derive(Debug)]
pub struct RecordedUvWrite {
    _set: ForeignSet,
}

/// foldfree on a host's device and queue. See the module docs for the contract.
pub struct Engine {
    ctx: Context,
    scatter: ComputePipeline,
    gather: ComputePipeline,
}

const _: () = {
    const fn send_sync<T: Send + Sync>() {}
    send_sync::<Engine>();
    send_sync::<RecordedUvWrite>();
};

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Engine").field("ctx", &self.ctx).finish()
    }
}

impl Engine {
    /// An engine on `ctx`, normally made by `unsafe { Context::from_host(..) }`. Builds the UV
    /// scatter pipeline (under a millisecond).
    pub fn new(ctx: Context) -> Result<Engine> {
        let scatter = ComputePipeline::from_shader::<ScatterPush>(
            &ctx,
            "embed.scatter_uv",
            shaders::EMBED_SCATTER_UV,
            2,
        )?;
        let gather = ComputePipeline::from_shader::<GatherPush>(
            &ctx,
            "embed.gather_words",
            shaders::EMBED_GATHER_WORDS,
            2,
        )?;
        Ok(Engine {
            ctx,
            scatter,
            gather,
        })
    }

    /// The context the engine runs on.
    pub fn context(&self) -> &Context {
        &self.ctx
    }

    /// Per-vertex UVs (#V) of the disk mesh `positions` (#V) / `faces` (#F, counter-clockwise,
    /// 0-based): validation (errors name the file [`MEMORY_FILE`]), the start map, ADMM on this
    /// device, recovery. Same steps and defaults as `foldfree param --backend vulkan`, so the
    /// same mesh and options give the same UVs (the CLI's output is normalised by area, and so
    /// is this). Fails rather than return a map with flipped faces.
    pub fn parameterize(
        &self,
        positions: &[[f64; 3]],
        faces: &[[u32; 3]],
        opts: &EmbedOptions,
    ) -> Result<Vec<[f64; 2]>> {
        self.start_parameterize(positions, faces, opts, &JobOptions::blocking())?
            .finish()
    }

    /// Reads a mesh out of the host's buffers (see [`MeshBuffers`]): one gather kernel per
    /// buffer copies the words exactly (positions stay the host's `f32` values, widened to
    /// f64), submitted on the host's queue after a barrier from `src.before`, then read back.
    /// The result is not validated; [`Engine::parameterize_buffers`] does that.
    pub fn read_mesh(&self, src: &MeshBuffers) -> Result<TriMesh> {
        let align = crate::gpu::interop::min_storage_buffer_offset_alignment(&self.ctx);
        let max_range = self.ctx.limits().max_storage_buffer_range;
        let positions = self.gather(
            "mesh positions",
            src.positions,
            src.position_offset,
            src.position_stride,
            3,
            src.vertex_count as usize,
            src.before,
            align,
            max_range,
        )?;
        let indices = self.gather(
            "mesh indices",
            src.indices,
            src.index_offset,
            12,
            3,
            src.face_count as usize,
            src.before,
            align,
            max_range,
        )?;
        Ok(TriMesh {
            positions: positions
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]].map(|w| f64::from(f32::from_bits(w))))
                .collect(),
            faces: indices
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
        })
    }

    /// [`Engine::read_mesh`] then [`Engine::parameterize`]: the UVs of a disk mesh that lives
    /// in the host's buffers (bad indices or geometry get the same located errors as a file,
    /// naming [`MEMORY_FILE`]).
    pub fn parameterize_buffers(
        &self,
        src: &MeshBuffers,
        opts: &EmbedOptions,
    ) -> Result<Vec<[f64; 2]>> {
        let mesh = self.read_mesh(src)?;
        self.parameterize(&mesh.positions, &mesh.faces, opts)
    }

    /// One gather dispatch: `n` elements of `width` words from a strided host range.
    #[allow(clippy::too_many_arguments)]
    fn gather(
        &self,
        what: &str,
        buffer: ForeignBuffer,
        offset: u64,
        stride: u64,
        width: u32,
        n: usize,
        before: HostAccess,
        align: u64,
        max_range: u64,
    ) -> Result<Vec<u32>> {
        if n == 0 {
            return Ok(Vec::new());
        }
        let (range, first_word, stride_words) = plan_span(
            what,
            buffer,
            offset,
            stride,
            4 * u64::from(width),
            n,
            align,
            max_range,
        )?;
        let n32 = u32::try_from(n).map_err(|_| Error::Usage(format!("{what}: {n} elements")))?;
        let dst = Buffer::with_desc(
            &self.ctx,
            &crate::gpu::BufferDesc {
                name: "embed.gather_dst",
                size: 4 * u64::from(width) * n as u64,
                usage: crate::gpu::BufferUsage::Storage,
                location: crate::gpu::MemoryLocation::GpuToCpu,
            },
        )?;
        let set = ForeignSet::new(
            &self.gather,
            "embed.gather_words.set",
            &[SetEntry::Foreign(range), SetEntry::Owned(&dst)],
        )?;
        let push = GatherPush {
            n: n32,
            first_word,
            stride_words,
            width,
        };
        ForeignDispatch {
            pipeline: &self.gather,
            set: &set,
            push: bytemuck::bytes_of(&push),
            threads: n32,
            target: range,
            target_use: TargetUse::Read,
            before,
            after: HostAccess::any(),
        }
        .submit_and_wait("embed.gather_words")?;
        Ok(dst.read::<u32>()?)
    }

    /// Uploads `uv` (rounded to f32) and a descriptor set binding the target's span.
    fn prepare(&self, uv: &[[f64; 2]], target: &UvTarget) -> Result<(ScatterPlan, ForeignSet)> {
        let plan = target.plan(
            uv.len(),
            crate::gpu::interop::min_storage_buffer_offset_alignment(&self.ctx),
            self.ctx.limits().max_storage_buffer_range,
        )?;
        let data: Vec<[f32; 2]> = uv.iter().map(|p| [p[0] as f32, p[1] as f32]).collect();
        let src = Buffer::from_slice(&self.ctx, "embed.uv_source", &data)?;
        let set = ForeignSet::new(
            &self.scatter,
            "embed.scatter_uv.set",
            &[SetEntry::Owned(&src), SetEntry::Foreign(plan.range)],
        )?;
        Ok((plan, set))
    }

    /// Writes `uv` into the host's buffer as `target` describes: records the scatter kernel
    /// with its barriers (see the module docs), submits it on the host's queue and waits for a
    /// fence of the engine's own. Afterwards the host may read the span through a mapping or
    /// use it in its next submission to the same queue. An empty `uv` writes nothing.
    pub fn write_uvs(&self, uv: &[[f64; 2]], target: &UvTarget) -> Result<()> {
        if uv.is_empty() {
            return Ok(());
        }
        let (plan, set) = self.prepare(uv, target)?;
        let dispatch = ForeignDispatch {
            pipeline: &self.scatter,
            set: &set,
            push: bytemuck::bytes_of(&plan.push),
            threads: plan.push.n,
            target: plan.range,
            target_use: TargetUse::Written,
            before: HostAccess {
                stage: vk::PipelineStageFlags2::ALL_COMMANDS | vk::PipelineStageFlags2::HOST,
                access: vk::AccessFlags2::MEMORY_WRITE | vk::AccessFlags2::HOST_WRITE,
            },
            after: HostAccess::any(),
        };
        dispatch.submit_and_wait("embed.scatter_uv")?;
        Ok(())
    }

    /// Records the UV write into the host's command buffer `cmd`, between a barrier from
    /// `before` (the host's earlier accesses to the span) and one to `after` (its later ones);
    /// see the module docs. Nothing is submitted. Keep the returned value alive until `cmd` has
    /// finished executing. `None` for an empty `uv` (nothing recorded).
    pub fn record_write_uvs(
        &self,
        cmd: ForeignCommandBuffer,
        uv: &[[f64; 2]],
        target: &UvTarget,
        before: HostAccess,
        after: HostAccess,
    ) -> Result<Option<RecordedUvWrite>> {
        if uv.is_empty() {
            return Ok(None);
        }
        let (plan, set) = self.prepare(uv, target)?;
        ForeignDispatch {
            pipeline: &self.scatter,
            set: &set,
            push: bytemuck::bytes_of(&plan.push),
            threads: plan.push.n,
            target: plan.range,
            target_use: TargetUse::Written,
            before,
            after,
        }
        .record(cmd)?;
        Ok(Some(RecordedUvWrite { _set: set }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn target(size: u64, offset: u64, stride: u64) -> UvTarget {
        UvTarget {
            // No Vulkan call is made with this handle: `plan` is pure arithmetic.
            buffer: fake_buffer(size),
            offset,
            stride,
            format: UvFormat::F32x2,
        }
    }

    fn fake_buffer(size: u64) -> ForeignBuffer {
        crate::gpu::interop::ForeignBuffer::for_layout_tests(size)
    }

    #[test]
    fn interleaved_layout_words_skip_the_position() {
        // 3 floats position + 2 floats UV = 20 bytes per vertex; UV at byte 12.
        let p = target(20 * 10, 12, 20).plan(10, 16, 1 << 27).expect("fits");
        assert_eq!(p.range.offset, 0);
        assert_eq!(p.range.range, 12 + 9 * 20 + 8);
        assert_eq!(
            (p.push.first_word, p.push.stride_words, p.push.n),
            (3, 5, 10)
        );
    }

    #[test]
    fn offset_is_rounded_down_to_the_descriptor_alignment() {
        let p = target(1000, 100, 8).plan(4, 64, 1 << 27).expect("fits");
        assert_eq!(p.range.offset, 64);
        assert_eq!(p.push.first_word, 9);
        assert_eq!(p.range.range, 100 + 3 * 8 + 8 - 64);
    }

    #[test]
    fn unaligned_overlapping_or_overflowing_targets_are_refused() {
        assert!(target(1000, 2, 8).plan(4, 16, 1 << 27).is_err());
        assert!(target(1000, 0, 6).plan(4, 16, 1 << 27).is_err());
        assert!(target(1000, 0, 4).plan(4, 16, 1 << 27).is_err());
        assert!(target(31, 0, 8).plan(4, 16, 1 << 27).is_err());
        assert!(target(32, 0, 8).plan(4, 16, 1 << 27).is_ok());
        assert!(target(u64::MAX, 8, u64::MAX / 2)
            .plan(4, 16, u64::MAX)
            .is_err());
        assert!(target(1 << 40, 0, 8).plan(1 << 26, 16, 1 << 27).is_err());
    }
}
