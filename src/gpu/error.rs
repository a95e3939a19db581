//! The typed errors of the Vulkan layer and the one place where a `vk::Result` becomes one.
//!
//! Each way Vulkan can be missing on a machine gets its own variant, with a message that says how
//! to fix it: the CLI prints these to users who may never have heard of lavapipe.

use ash::vk;

/// How to get a working Vulkan on Debian/Ubuntu without a GPU (Mesa lavapipe).
pub const INSTALL_HINT: &str = "install a Vulkan driver, e.g. the CPU driver lavapipe: \
     apt-get install libvulkan1 mesa-vulkan-drivers";

/// Every way the Vulkan layer can fail.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GpuError {
    /// `libvulkan.so.1` (the Vulkan loader) could not be opened.
    #[error("Vulkan loader not found ({0}); {INSTALL_HINT}")]
    NoLoader(String),
    /// The loader found no usable driver manifest (`ERROR_INCOMPATIBLE_DRIVER`).
    #[error("no Vulkan driver ({0}); {INSTALL_HINT}")]
    NoDriver(String),
    /// No physical device fits (none at all, none with what we need, or none matching the
    /// requested name); the message lists what is available.
    #[error("no suitable Vulkan device: {0}")]
    NoDevice(String),
    /// The device named by `--device` / `FOLDFREE_DEVICE` does not exist: a wrong request
    /// (exit 2), never a reason to run elsewhere.
    #[error("no such Vulkan device: {0}")]
    NoSuchDevice(String),
    /// A requested instance layer is not installed.
    #[error("Vulkan layer {layer} is missing; install it with: apt-get install {package}")]
    MissingLayer {
        layer: String,
        package: &'static str,
    },
    /// The device was lost (driver crash, GPU hang or reset); the context is unusable.
    #[error("Vulkan device lost during {what}")]
    DeviceLost { what: &'static str },
    /// Host or device memory ran out (from Vulkan or from the allocator).
    #[error("out of {memory} memory during {what}")]
    OutOfMemory { what: String, memory: &'static str },
    /// A fence wait gave up; the GPU work may still be running.
    #[error("GPU work {what} did not finish within {timeout:?}")]
    Timeout {
        what: String,
        timeout: std::time::Duration,
    },
    /// A storage buffer above the device's `maxStorageBufferRange` (checked before allocating).
    #[error(
        "buffer {name}: {bytes} bytes exceeds the device's maxStorageBufferRange of {limit} bytes"
    )]
    BufferTooLarge {
        name: String,
        bytes: u64,
        limit: u64,
    },
    /// The allocator failed for a reason other than running out of memory.
    #[error("allocating {name}: {source}")]
    Allocation {
        name: String,
        #[source]
        source: gpu_allocator::AllocationError,
    },
    /// Work handed to the queue's owner was dropped unsubmitted (a cancelled job).
    #[error("GPU work {what} was cancelled before it was submitted")]
    Cancelled { what: String },
    /// The device lacks something a feature of this layer needs (e.g. timestamps).
    #[error("{0}")]
    Unsupported(String),
    /// The GPU layer was used against its contract (wrong sizes, wrong binding counts, ...).
    #[error("invalid use of the GPU layer: {0}")]
    Invalid(String),
    /// Any other Vulkan failure.
    #[error("Vulkan call {what} failed: {result}")]
    Vk {
        what: &'static str,
        result: vk::Result,
    },
}

impl GpuError {
    /// True for the errors that mean "this machine has no usable Vulkan": callers (tests, the
    /// CLI's automatic backend choice) may fall back to the CPU path on these.
    pub fn is_unavailable(&self) -> bool {
        matches!(
            self,
            GpuError::NoLoader(_)
                | GpuError::NoDriver(_)
                | GpuError::NoDevice(_)
                | GpuError::NoSuchDevice(_)
                | GpuError::MissingLayer { .. }
        )
    }
}

/// Result alias of the GPU layer.
pub type GpuResult<T> = Result<T, GpuError>;

/// Maps a failed Vulkan call to an error: the one place that decides which results get their own
/// variant (device loss and memory exhaustion; the rest keep the raw code and the call's name).
pub fn map_result(what: &'static str, result: vk::Result) -> GpuError {
    match result {
        vk::Result::ERROR_DEVICE_LOST => GpuError::DeviceLost { what },
        vk::Result::ERROR_OUT_OF_HOST_MEMORY => GpuError::OutOfMemory {
            what: what.to_string(),
            memory: "host",
        },
        vk::Result::ERROR_OUT_OF_DEVICE_MEMORY => GpuError::OutOfMemory {
            what: what.to_string(),
            memory: "device",
        },
        vk::Result::ERROR_INCOMPATIBLE_DRIVER => {
            GpuError::NoDriver(format!("{what}: ERROR_INCOMPATIBLE_DRIVER"))
        }
        vk::Result::ERROR_LAYER_NOT_PRESENT => GpuError::MissingLayer {
            layer: format!("(requested by {what})"),
            package: "vulkan-validationlayers",
        },
        result => GpuError::Vk { what, result },
    }
}

/// Maps a gpu-allocator failure for the resource `name`.
pub fn map_allocation(name: &str, err: gpu_allocator::AllocationError) -> GpuError {
    match err {
        gpu_allocator::AllocationError::OutOfMemory => GpuError::OutOfMemory {
            what: format!("allocating {name}"),
            memory: "device (allocator)",
        },
        source => GpuError::Allocation {
            name: name.to_string(),
            source,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_lost_and_oom_get_their_own_variants() {
        assert!(matches!(
            map_result("x", vk::Result::ERROR_DEVICE_LOST),
            GpuError::DeviceLost { .. }
        ));
        assert!(matches!(
            map_result("x", vk::Result::ERROR_OUT_OF_DEVICE_MEMORY),
            GpuError::OutOfMemory {
                memory: "device",
                ..
            }
        ));
        assert!(matches!(
            map_result("x", vk::Result::ERROR_FORMAT_NOT_SUPPORTED),
            GpuError::Vk { .. }
        ));
    }

    #[test]
    fn unavailable_errors_name_the_debian_packages() {
        let e = GpuError::NoLoader("libvulkan.so.1: cannot open".into());
        assert!(e.is_unavailable());
        assert!(e.to_string().contains("mesa-vulkan-drivers"));
    }
}
