//! The `--backend auto|cpu|vulkan` decision, shared by every command with a device path.

use super::{Context, ContextDesc, GpuError, DEVICE_ENV};

/// Where the device kernels of a job run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum BackendChoice {
    /// Vulkan on a real GPU; the CPU backend when the only device is a CPU rasterizer or none.
    Auto,
    Cpu,
    Vulkan,
}

/// Opens the context `backend` asks for, or None for the CPU. `device` (or `FOLDFREE_DEVICE`)
/// names a device: then it runs there or fails, never silently on the CPU; so does a run
/// that asked for the validation layer.
pub fn open_backend(
    backend: BackendChoice,
    device: Option<&str>,
    validation: bool,
) -> Result<Option<Context>, GpuError> {
    let desc = ContextDesc {
        validation,
        device: device.map(str::to_string),
        ..ContextDesc::default()
    };
    let named = device.is_some() || std::env::var(DEVICE_ENV).is_ok_and(|s| !s.trim().is_empty());
    match backend {
        BackendChoice::Cpu => Ok(None),
        BackendChoice::Vulkan => Ok(Some(Context::new(&desc)?)),
        BackendChoice::Auto => match Context::new(&desc) {
            // A device the user named (`--device` or the environment) is a request: it runs
            // there (even lavapipe) or fails.
            Ok(ctx) if named => Ok(Some(ctx)),
            // A CPU "GPU" (lavapipe) is slower than the native f64 backend on the same cores.
            Ok(ctx) if ctx.device_type() == super::vk::PhysicalDeviceType::CPU => Ok(None),
            Ok(ctx) => Ok(Some(ctx)),
            // Falling back to the CPU silently would ignore a named device or the validation
            // the user asked for.
            Err(e) if e.is_unavailable() && !named && !validation => Ok(None),
            Err(e) => Err(e),
        },
    }
}
