//! The Vulkan layer: the only module with `unsafe` code.

/// Every way Vulkan can be missing or fail.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("Vulkan loader not found ({0}); install it with: apt-get install libvulkan1 mesa-vulkan-drivers")]
    NoLoader(String),
}
