//! Pure translations from this layer's small enums to `vk::` flags, in one place so a reviewer
//! can check every barrier and usage bit against the spec without reading the recorder.

use ash::vk;

use super::buffer::{BufferUsage, MemoryLocation};
use super::command::Access;

/// The pipeline stage and the memory access an [`Access`] stands for (synchronization2 flags).
pub fn map_access(access: Access) -> (vk::PipelineStageFlags2, vk::AccessFlags2) {
    use vk::AccessFlags2 as A;
    use vk::PipelineStageFlags2 as S;
    match access {
        Access::ComputeRead => (S::COMPUTE_SHADER, A::SHADER_STORAGE_READ),
        Access::ComputeWrite => (S::COMPUTE_SHADER, A::SHADER_STORAGE_WRITE),
        Access::ComputeReadWrite => (
            S::COMPUTE_SHADER,
            A::SHADER_STORAGE_READ | A::SHADER_STORAGE_WRITE,
        ),
        Access::TransferRead => (S::ALL_TRANSFER, A::TRANSFER_READ),
        Access::TransferWrite => (S::ALL_TRANSFER, A::TRANSFER_WRITE),
        Access::HostRead => (S::HOST, A::HOST_READ),
        Access::HostWrite => (S::HOST, A::HOST_WRITE),
    }
}

/// Only writes need to be made available: a read before the barrier needs an execution
/// dependency (the stage), not a memory one, so its access bits are dropped from the source.
fn write_bits(access: vk::AccessFlags2) -> vk::AccessFlags2 {
    access
        & (vk::AccessFlags2::SHADER_STORAGE_WRITE
            | vk::AccessFlags2::TRANSFER_WRITE
            | vk::AccessFlags2::HOST_WRITE)
}

/// A global memory barrier ordering every `from` access before every later `to` access.
pub fn map_barrier(from: Access, to: Access) -> vk::MemoryBarrier2<'static> {
    let (src_stage, src_access) = map_access(from);
    let (dst_stage, dst_access) = map_access(to);
    vk::MemoryBarrier2::default()
        .src_stage_mask(src_stage)
        .src_access_mask(write_bits(src_access))
        .dst_stage_mask(dst_stage)
        .dst_access_mask(dst_access)
}

/// Vulkan usage bits of a buffer.
pub fn map_buffer_usage(usage: BufferUsage) -> vk::BufferUsageFlags {
    // Storage buffers are also transfer sources and destinations: `fill_buffer`, the staging
    // upload/download of device-only memory and readback copies all need it, and the bits cost
    // nothing on the drivers we know.
    let transfer = vk::BufferUsageFlags::TRANSFER_SRC | vk::BufferUsageFlags::TRANSFER_DST;
    match usage {
        BufferUsage::Storage => vk::BufferUsageFlags::STORAGE_BUFFER | transfer,
        BufferUsage::Staging => transfer,
        BufferUsage::Vertex => vk::BufferUsageFlags::VERTEX_BUFFER | transfer,
        BufferUsage::Index => vk::BufferUsageFlags::INDEX_BUFFER | transfer,
    }
}

/// gpu-allocator's location for ours (kept separate so its version does not leak into our API).
pub fn map_memory_location(location: MemoryLocation) -> gpu_allocator::MemoryLocation {
    match location {
        MemoryLocation::GpuOnly => gpu_allocator::MemoryLocation::GpuOnly,
        MemoryLocation::CpuToGpu => gpu_allocator::MemoryLocation::CpuToGpu,
        MemoryLocation::GpuToCpu => gpu_allocator::MemoryLocation::GpuToCpu,
    }
}

/// Preference of a device type when none is requested: lower is better.
pub fn device_type_rank(ty: vk::PhysicalDeviceType) -> u32 {
    match ty {
        vk::PhysicalDeviceType::DISCRETE_GPU => 0,
        vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
        vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
        vk::PhysicalDeviceType::CPU => 3,
        _ => 4,
    }
}

/// Human-readable device type for reports.
pub fn device_type_name(ty: vk::PhysicalDeviceType) -> &'static str {
    match ty {
        vk::PhysicalDeviceType::DISCRETE_GPU => "discrete GPU",
        vk::PhysicalDeviceType::INTEGRATED_GPU => "integrated GPU",
        vk::PhysicalDeviceType::VIRTUAL_GPU => "virtual GPU",
        vk::PhysicalDeviceType::CPU => "CPU",
        _ => "other",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_to_write_barrier_carries_no_source_access() {
        let b = map_barrier(Access::ComputeRead, Access::ComputeWrite);
        assert_eq!(b.src_access_mask, vk::AccessFlags2::empty());
        assert_eq!(b.src_stage_mask, vk::PipelineStageFlags2::COMPUTE_SHADER);
    }

    #[test]
    fn write_to_read_barrier_makes_the_write_visible() {
        let b = map_barrier(Access::ComputeReadWrite, Access::HostRead);
        assert_eq!(b.src_access_mask, vk::AccessFlags2::SHADER_STORAGE_WRITE);
        assert_eq!(b.dst_access_mask, vk::AccessFlags2::HOST_READ);
        assert_eq!(b.dst_stage_mask, vk::PipelineStageFlags2::HOST);
    }

    #[test]
    fn discrete_gpus_rank_before_cpus() {
        assert!(
            device_type_rank(vk::PhysicalDeviceType::DISCRETE_GPU)
                < device_type_rank(vk::PhysicalDeviceType::CPU)
        );
    }
}
