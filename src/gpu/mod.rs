//! The Vulkan layer: the only module with `unsafe` code.
//!
//! Built on ash (raw Vulkan) and gpu-allocator. Every object is RAII and holds the shared device
//! state through an `Arc`, so nothing can outlive the device it came from; handles are named
//! (`VK_EXT_debug_utils`) for validation messages; every `unsafe` block does one thing and says
//! why it is sound. Vulkan 1.2 with `VK_KHR_synchronization2`.
//!
//! - [`Context`]: instance, device, compute queue, allocator, collected validation messages.
//! - [`Buffer`]: storage and staging buffers with host upload/download.
//! - [`ComputePipeline`] + [`DescriptorSet`]: a kernel and the buffers bound to it.
//! - [`Recorder`]: records dispatches, barriers ([`Access`] → [`Access`]), copies, timestamps;
//!   submits and waits.
//! - [`render_checker`]: an offscreen graphics render of a UV-mapped mesh with a checkerboard.
//! - [`TimestampPool`]: GPU timestamps for per-kernel timings.
//! - [`Timeline`] + [`Handoff`]: timeline semaphores, and recordings submitted by the queue's
//!   owner on another thread (asynchronous jobs).
//! - [`shaders`]: the SPIR-V compiled from `glsl/` by `build.rs`.

// The unsafe discipline, checked by clippy: one unsafe operation per block, each with a
// `// SAFETY:` comment.
#![deny(clippy::undocumented_unsafe_blocks)]
#![deny(clippy::multiple_unsafe_ops_per_block)]

mod backend;
mod buffer;
mod command;
mod context;
mod conv;
mod debug;
mod error;
pub mod interop;
mod pipeline;
mod query;
mod render;
pub mod shaders;
mod timeline;

pub use backend::{open_backend, BackendChoice};
pub use buffer::{Buffer, BufferDesc, BufferUsage, MemoryLocation};
pub use command::{grid_1d, Access, Recorder};
pub use context::{
    required_features, Context, ContextDesc, DeviceLimits, HostAllocator, HostDesc,
    RequiredFeatures, API_VERSION, DEVICE_ENV, SYNC2_FEATURE, SYNC_VALIDATION_ENV,
    TIMELINE_FEATURE,
};
pub use debug::MessageLog;
pub use error::{map_result, GpuError, GpuResult, INSTALL_HINT};
pub use pipeline::{ComputePipeline, ComputePipelineDesc, DescriptorSet, DEFAULT_WORKGROUP_SIZE};
pub use query::TimestampPool;
pub use render::{render_checker, RenderDesc, Shade, BACKGROUND};
pub use timeline::{Handoff, Timeline};

/// Raw Vulkan types, for hosts that bring their own device ([`Context::from_host`]).
pub use ash::vk;
/// The allocator crate, re-exported so a host names the same version as [`HostAllocator`].
pub use gpu_allocator;
