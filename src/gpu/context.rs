//! The Vulkan context: instance, device, one compute queue and the memory allocator, shared by
//! every GPU object through an `Arc`.
//!
//! A context either owns its instance and device ([`Context::new`]) or borrows a host's
//! ([`Context::from_host`]); teardown destroys only what it owns, in the order written down in
//! `Drop for Shared`.

use std::ffi::{c_char, CStr, CString};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use super::conv;
use super::debug::{self, MessageLog};
use super::error::{map_allocation, map_result, GpuError, GpuResult, INSTALL_HINT};

/// The Khronos validation layer.
const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";
/// Debian package that ships [`VALIDATION_LAYER`].
const VALIDATION_PACKAGE: &str = "vulkan-validationlayers";
/// Instance extension that carries `VkValidationFeaturesEXT` (provided by the layer).
const VALIDATION_FEATURES_EXT: &CStr = c"VK_EXT_validation_features";
/// Device extension a portability driver (MoltenVK) requires us to enable when it offers it.
const PORTABILITY_SUBSET_EXT: &CStr = c"VK_KHR_portability_subset";

/// The Vulkan version we program against: 1.2 core (with its timeline semaphores) plus
/// `VK_KHR_synchronization2`.
pub const API_VERSION: u32 = vk::API_VERSION_1_2;

/// Environment variable selecting the device (a substring of its name, or its index); it
/// overrides [`ContextDesc::device`].
pub const DEVICE_ENV: &str = "FOLDFREE_DEVICE";
/// Environment variable that, when `1`, turns on validation with synchronization validation.
pub const SYNC_VALIDATION_ENV: &str = "FOLDFREE_SYNC_VALIDATION";

/// How to create a [`Context`].
#[derive(Clone, Debug)]
pub struct ContextDesc {
    /// Application name reported to the driver.
    pub app_name: String,
    /// Enable `VK_LAYER_KHRONOS_validation` and collect its messages (see
    /// [`Context::validation_messages`]). Slow; for tests and debugging.
    pub validation: bool,
    /// Also enable synchronization validation (implies `validation`). The environment variable
    /// `FOLDFREE_SYNC_VALIDATION=1` turns this on too.
    pub sync_validation: bool,
    /// Which device to use: a case-insensitive substring of its name, or its index in the
    /// driver's list. `None` picks the best (discrete, integrated, virtual, then CPU). The
    /// environment variable `FOLDFREE_DEVICE` overrides this.
    pub device: Option<String>,
}

impl Default for ContextDesc {
    fn default() -> Self {
        Self {
            app_name: "foldfree".to_string(),
            validation: false,
            sync_validation: false,
            device: None,
        }
    }
}

/// What a host that brings its own device must have enabled for [`Context::from_host`].
#[derive(Clone, Debug)]
pub struct RequiredFeatures {
    /// Minimum `VkApplicationInfo::apiVersion` of the instance and API version of the device.
    pub api_version: u32,
    /// Device extensions to enable.
    pub device_extensions: Vec<&'static CStr>,
    /// Device features to enable, named as in the Vulkan spec (struct.member).
    pub device_features: Vec<&'static str>,
}

/// What the shaders and the recorder need from a device. Kept as data so a host that creates
/// its own device can enable the same things.
pub fn required_features() -> RequiredFeatures {
    RequiredFeatures {
        api_version: API_VERSION,
        device_extensions: vec![ash::khr::synchronization2::NAME],
        device_features: vec![SYNC2_FEATURE, TIMELINE_FEATURE],
    }
}

/// The `VK_KHR_synchronization2` feature, as [`RequiredFeatures::device_features`] names it.
pub const SYNC2_FEATURE: &str = "VkPhysicalDeviceSynchronization2Features.synchronization2";
/// Vulkan 1.2's timeline semaphores (every 1.2 device supports them; they must be enabled):
/// what an asynchronous job signals (`embed::Job`).
pub const TIMELINE_FEATURE: &str = "VkPhysicalDeviceVulkan12Features.timelineSemaphore";

/// The device limits this crate plans with.
#[derive(Clone, Copy, Debug)]
pub struct DeviceLimits {
    /// Workgroups per dispatch, per dimension (65535 on lavapipe and the spec minimum).
    pub max_compute_work_group_count: [u32; 3],
    /// Threads per workgroup.
    pub max_compute_work_group_invocations: u32,
    /// Largest storage-buffer binding in bytes (128 MiB on lavapipe).
    pub max_storage_buffer_range: u64,
    /// Largest push-constant block in bytes (at least 128).
    pub max_push_constants_size: u32,
    /// Nanoseconds per timestamp tick.
    pub timestamp_period_ns: f32,
    /// Whether the compute queue can write timestamps.
    pub timestamps: bool,
    /// Valid bits of a timestamp on the compute queue (0 when unsupported).
    pub timestamp_valid_bits: u32,
}

/// A host's Vulkan objects, lent to [`Context::from_host`].
#[derive(Clone)]
pub struct HostDesc {
    /// The loader the host's instance came from.
    pub entry: ash::Entry,
    pub instance: ash::Instance,
    pub physical_device: vk::PhysicalDevice,
    pub device: ash::Device,
    /// A queue family with compute support, and one queue of it.
    pub queue_family_index: u32,
    pub queue: vk::Queue,
    /// Whether the host enabled `VK_EXT_debug_utils` on its instance (for object names).
    pub debug_utils: bool,
    /// The host's own gpu-allocator (made for this device), to allocate the engine's buffers
    /// from the host's heaps and budget; `None` makes a private one. The engine locks it for
    /// each allocation and free, and frees everything it allocated before its last `Context`
    /// clone is gone; it never drops the host's allocator.
    pub allocator: Option<HostAllocator>,
}

/// A gpu-allocator shared with the host ([`HostDesc::allocator`]).
pub type HostAllocator = Arc<Mutex<Allocator>>;

/// Where the context's allocator lives. One per context, so the size difference between the
/// variants costs nothing worth a box.
#[allow(clippy::large_enum_variant)]
enum AllocatorSlot {
    /// Ours: dropped (and checked for leaks) before the device is destroyed. `None` only
    /// during teardown.
    Own(Mutex<Option<Allocator>>),
    /// The host's: only locked.
    Host(HostAllocator),
}

/// Shared state behind every [`Context`] clone and every GPU object.
pub(crate) struct Shared {
    pub(crate) device: ash::Device,
    pub(crate) sync2: ash::khr::synchronization2::Device,
    debug_utils: Option<ash::ext::debug_utils::Device>,
    allocator: AllocatorSlot,
    /// Queue submission needs external synchronization.
    queue: Mutex<vk::Queue>,
    /// Set once a call returned `VK_ERROR_DEVICE_LOST` (or a test simulated it): every later
    /// submission fails fast with [`GpuError::DeviceLost`], as the spec requires of a lost
    /// device, instead of queueing work that can never run.
    lost: std::sync::atomic::AtomicBool,
    queue_family_index: u32,
    physical_device: vk::PhysicalDevice,
    device_name: String,
    device_type: vk::PhysicalDeviceType,
    api_version: u32,
    limits: DeviceLimits,
    validation: bool,
    sync_validation: bool,
    creation_time: Duration,
    messenger: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    instance: ash::Instance,
    owns_device: bool,
    owns_instance: bool,
    /// Must outlive the messenger and the instance: its pointer is the callback's user data.
    messages: MessageLog,
    /// Keeps libvulkan loaded; dropped last.
    _entry: ash::Entry,
}

/// The one teardown order: wait for the GPU, drop the allocator (frees all memory blocks),
/// destroy the device, the messenger, the instance; then the message log and the loader go.
impl Drop for Shared {
    fn drop(&mut self) {
        if self.owns_device {
            // SAFETY: we own the device and every object created from it holds this `Shared`, so
            // nothing else uses the device or its queue now.
            if let Err(e) = unsafe { self.device.device_wait_idle() } {
                self.messages
                    .note(format!("[foldfree] vkDeviceWaitIdle at teardown: {e}"));
            }
        }
        let allocator = match &mut self.allocator {
            AllocatorSlot::Own(a) => a.get_mut().unwrap_or_else(PoisonError::into_inner).take(),
            AllocatorSlot::Host(_) => None,
        };
        if let Some(allocator) = allocator {
            let report = allocator.generate_report();
            if !report.allocations.is_empty() {
                let names: Vec<_> = report.allocations.iter().map(|a| a.name.as_str()).collect();
                self.messages.note(format!(
                    "[foldfree] {} GPU allocation(s) leaked at teardown: {}",
                    names.len(),
                    names.join(", ")
                ));
            }
            drop(allocator);
        }
        if self.owns_device {
            // SAFETY: the device is idle, owned by us, and all its children were destroyed by
            // their RAII owners (which hold this `Shared` and so are gone).
            unsafe { self.device.destroy_device(None) };
        }
        if let Some((loader, messenger)) = self.messenger.take() {
            // SAFETY: the messenger was created by us from this instance and is used by no one.
            unsafe { loader.destroy_debug_utils_messenger(messenger, None) };
        }
        if self.owns_instance {
            // SAFETY: we own the instance; its device and messenger are destroyed above.
            unsafe { self.instance.destroy_instance(None) };
        }
    }
}

/// A Vulkan device with one compute queue and an allocator. Cheap to clone (an `Arc`).
#[derive(Clone)]
pub struct Context {
    pub(crate) shared: Arc<Shared>,
}

impl std::fmt::Debug for Context {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Context")
            .field("device", &self.shared.device_name)
            .field("type", &conv::device_type_name(self.shared.device_type))
            .field("validation", &self.shared.validation)
            .finish()
    }
}

/// One physical device as seen during selection.
struct Candidate {
    raw: vk::PhysicalDevice,
    index: usize,
    name: String,
    device_type: vk::PhysicalDeviceType,
    api_version: u32,
    queue_family_index: Option<u32>,
    portability_subset: bool,
    /// Why the device cannot be used, if it cannot.
    unusable: Option<String>,
}

impl Candidate {
    fn describe(&self) -> String {
        let mut s = format!(
            "#{} {} ({}, Vulkan {}.{})",
            self.index,
            self.name,
            conv::device_type_name(self.device_type),
            vk::api_version_major(self.api_version),
            vk::api_version_minor(self.api_version)
        );
        if let Some(why) = &self.unusable {
            s.push_str(&format!(" [unusable: {why}]"));
        }
        s
    }
}

fn env_flag(name: &str) -> bool {
    std::env::var(name).is_ok_and(|v| v == "1" || v.eq_ignore_ascii_case("true"))
}

/// A NUL-free C string for names handed to Vulkan.
pub(crate) fn c_name(name: &str) -> CString {
    CString::new(name.replace('\0', " ")).unwrap_or_default()
}

fn has_extension(list: &[vk::ExtensionProperties], name: &CStr) -> bool {
    list.iter()
        .any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == name))
}

impl Context {
    /// Loads libvulkan, creates an instance (with validation if asked), picks a device and
    /// creates it with one compute queue. Takes about 40–70 ms on lavapipe.
    pub fn new(desc: &ContextDesc) -> GpuResult<Context> {
        let start = Instant::now();
        // SAFETY: loading the system's Vulkan loader runs its initialisers; that is the
        // documented way to use a run-time-loaded libvulkan.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| GpuError::NoLoader(e.to_string()))?;

        let sync_validation = desc.sync_validation || env_flag(SYNC_VALIDATION_ENV);
        let validation = desc.validation || sync_validation;

        // SAFETY: plain query on a loaded entry.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }
            .map_err(|r| map_result("vkEnumerateInstanceLayerProperties", r))?;
        if validation
            && !layers
                .iter()
                .any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER))
        {
            return Err(GpuError::MissingLayer {
                layer: VALIDATION_LAYER.to_string_lossy().into_owned(),
                package: VALIDATION_PACKAGE,
            });
        }
        // SAFETY: plain query on a loaded entry.
        let mut extensions = unsafe { entry.enumerate_instance_extension_properties(None) }
            .map_err(|r| map_result("vkEnumerateInstanceExtensionProperties", r))?;
        if validation {
            // SAFETY: plain query; the layer exists (checked above).
            let from_layer =
                unsafe { entry.enumerate_instance_extension_properties(Some(VALIDATION_LAYER)) }
                    .map_err(|r| map_result("vkEnumerateInstanceExtensionProperties", r))?;
            extensions.extend(from_layer);
        }

        let debug_utils = has_extension(&extensions, ash::ext::debug_utils::NAME);
        if validation && !debug_utils {
            return Err(GpuError::Unsupported(
                "validation needs VK_EXT_debug_utils, which this Vulkan loader lacks".into(),
            ));
        }
        if sync_validation && !has_extension(&extensions, VALIDATION_FEATURES_EXT) {
            return Err(GpuError::Unsupported(
                "synchronization validation needs VK_EXT_validation_features (validation layer too old?)"
                    .into(),
            ));
        }
        let portability = has_extension(&extensions, ash::khr::portability_enumeration::NAME);

        let mut ext_names: Vec<*const c_char> = Vec::new();
        if debug_utils {
            ext_names.push(ash::ext::debug_utils::NAME.as_ptr());
        }
        if sync_validation {
            ext_names.push(VALIDATION_FEATURES_EXT.as_ptr());
        }
        if portability {
            ext_names.push(ash::khr::portability_enumeration::NAME.as_ptr());
        }
        let layer_names: Vec<*const c_char> = if validation {
            vec![VALIDATION_LAYER.as_ptr()]
        } else {
            Vec::new()
        };

        let messages = MessageLog::default();
        let app_name = c_name(&desc.app_name);
        let app_info = vk::ApplicationInfo::default()
            .application_name(&app_name)
            .application_version(1)
            .engine_name(c"foldfree")
            .engine_version(1)
            .api_version(API_VERSION);
        let enabled_features = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut validation_features =
            vk::ValidationFeaturesEXT::default().enabled_validation_features(&enabled_features);
        let mut instance_messenger = debug::messenger_info(&messages);
        let mut instance_info = vk::InstanceCreateInfo::default()
            .application_info(&app_info)
            .enabled_layer_names(&layer_names)
            .enabled_extension_names(&ext_names);
        if portability {
            instance_info = instance_info.flags(vk::InstanceCreateFlags::ENUMERATE_PORTABILITY_KHR);
        }
        if validation {
            instance_info = instance_info.push_next(&mut instance_messenger);
        }
        if sync_validation {
            instance_info = instance_info.push_next(&mut validation_features);
        }

        // SAFETY: every pointer in `instance_info` (names, app info, chained structs) lives until
        // the call returns.
        let instance = unsafe { entry.create_instance(&instance_info, None) }.map_err(|r| {
            match r {
                vk::Result::ERROR_INCOMPATIBLE_DRIVER => GpuError::NoDriver(
                    "vkCreateInstance returned ERROR_INCOMPATIBLE_DRIVER: the loader found no usable \
                     driver manifest (see /usr/share/vulkan/icd.d and VK_DRIVER_FILES)"
                        .into(),
                ),
                vk::Result::ERROR_LAYER_NOT_PRESENT => GpuError::MissingLayer {
                    layer: VALIDATION_LAYER.to_string_lossy().into_owned(),
                    package: VALIDATION_PACKAGE,
                },
                r => map_result("vkCreateInstance", r),
            }
        })?;

        let messenger = if validation {
            let loader = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let info = debug::messenger_info(&messages);
            // SAFETY: the instance has VK_EXT_debug_utils enabled; the user data (the log) is kept
            // alive by `Shared` until after the messenger is destroyed.
            match unsafe { loader.create_debug_utils_messenger(&info, None) } {
                Ok(m) => Some((loader, m)),
                Err(r) => {
                    // SAFETY: the instance was created above and has no children.
                    unsafe { instance.destroy_instance(None) };
                    return Err(map_result("vkCreateDebugUtilsMessengerEXT", r));
                }
            }
        } else {
            None
        };

        let requested = std::env::var(DEVICE_ENV)
            .ok()
            .filter(|s| !s.trim().is_empty())
            .or_else(|| desc.device.clone());
        let created = create_device(&instance, requested.as_deref());
        let (candidate, device) = match created {
            Ok(ok) => ok,
            Err(e) => {
                if let Some((loader, m)) = &messenger {
                    // SAFETY: created above from this instance; nothing else uses it.
                    unsafe { loader.destroy_debug_utils_messenger(*m, None) };
                }
                // SAFETY: the instance's only child (the messenger) is destroyed.
                unsafe { instance.destroy_instance(None) };
                return Err(e);
            }
        };

        let parts = Parts {
            entry,
            instance,
            physical_device: candidate.raw,
            device,
            queue_family_index: candidate.queue_family_index.unwrap_or(0),
            queue: None,
            debug_utils,
            messenger,
            messages,
            owns: true,
            validation,
            sync_validation,
            start,
            host_allocator: None,
        };
        assemble(parts)
    }

    /// Wraps a host application's instance and device. The context destroys none of them.
    ///
    /// # Safety
    /// All handles must be valid and come from each other; the device must have been created
    /// with everything in [`required_features`]; the host must keep them alive until the last
    /// clone of this context and every object made from it is dropped; and the host must not
    /// use `queue` concurrently with this context (Vulkan requires external synchronization).
    pub unsafe fn from_host(desc: HostDesc) -> GpuResult<Context> {
        let start = Instant::now();
        let parts = Parts {
            entry: desc.entry,
            instance: desc.instance,
            physical_device: desc.physical_device,
            device: desc.device,
            queue_family_index: desc.queue_family_index,
            queue: Some(desc.queue),
            debug_utils: desc.debug_utils,
            messenger: None,
            messages: MessageLog::default(),
            owns: false,
            validation: false,
            sync_validation: false,
            start,
            host_allocator: desc.allocator,
        };
        assemble(parts)
    }

    /// The device's name as the driver reports it, e.g. `llvmpipe (LLVM 15.0.6, 256 bits)`.
    pub fn device_name(&self) -> &str {
        &self.shared.device_name
    }

    /// Discrete, integrated, virtual GPU or CPU.
    pub fn device_type(&self) -> vk::PhysicalDeviceType {
        self.shared.device_type
    }

    /// [`Self::device_type`] as words.
    pub fn device_type_name(&self) -> &'static str {
        conv::device_type_name(self.shared.device_type)
    }

    /// The device's Vulkan version (`vk::api_version_*` decode it).
    pub fn api_version(&self) -> u32 {
        self.shared.api_version
    }

    /// The limits this crate plans with.
    pub fn limits(&self) -> &DeviceLimits {
        &self.shared.limits
    }

    /// Whether the validation layer is on (and so whether messages are collected).
    pub fn validation_enabled(&self) -> bool {
        self.shared.validation
    }

    /// Whether synchronization validation is on.
    pub fn sync_validation_enabled(&self) -> bool {
        self.shared.sync_validation
    }

    /// Wall time [`Context::new`] took.
    pub fn creation_time(&self) -> Duration {
        self.shared.creation_time
    }

    /// Every validation WARNING/ERROR so far (and leaks this layer noticed).
    pub fn validation_messages(&self) -> Vec<String> {
        self.shared.messages.messages()
    }

    /// Like [`Self::validation_messages`], and clears the list.
    pub fn take_validation_messages(&self) -> Vec<String> {
        self.shared.messages.take()
    }

    /// Takes the messages and fails when there were any: a run with the validation layer on
    /// is a run that must stay silent.
    pub fn check_validation_messages(&self) -> GpuResult<()> {
        let messages = self.take_validation_messages();
        match messages.first() {
            None => Ok(()),
            Some(first) => Err(GpuError::Invalid(format!(
                "{} Vulkan validation messages, first: {first}",
                messages.len()
            ))),
        }
    }

    /// A handle on the message list that outlives the context: check it after dropping the
    /// context to see what the layer said during teardown (leaked objects).
    pub fn message_log(&self) -> MessageLog {
        self.shared.messages.clone()
    }

    /// Waits until the device is idle.
    pub fn wait_idle(&self) -> GpuResult<()> {
        // vkDeviceWaitIdle needs every queue externally synchronized: hold ours.
        let _queue = self.queue();
        // SAFETY: the device is alive (we hold `shared`) and its only queue we use is locked.
        unsafe { self.shared.device.device_wait_idle() }
            .map_err(|r| map_result("vkDeviceWaitIdle", r))
    }

    /// The raw device, for hosts and for code that extends this layer.
    pub fn raw_device(&self) -> &ash::Device {
        &self.shared.device
    }

    /// The raw instance.
    pub fn raw_instance(&self) -> &ash::Instance {
        &self.shared.instance
    }

    /// The physical device in use.
    pub fn physical_device(&self) -> vk::PhysicalDevice {
        self.shared.physical_device
    }

    /// The family of the compute queue.
    pub fn queue_family_index(&self) -> u32 {
        self.shared.queue_family_index
    }

    pub(crate) fn device(&self) -> &ash::Device {
        &self.shared.device
    }

    pub(crate) fn sync2(&self) -> &ash::khr::synchronization2::Device {
        &self.shared.sync2
    }

    /// The compute queue, locked for submission.
    /// Whether the device was lost (a call returned `VK_ERROR_DEVICE_LOST`, or
    /// [`Context::simulate_device_lost`]). A lost context only fails; drop it and make a new one.
    pub fn is_lost(&self) -> bool {
        self.shared.lost.load(std::sync::atomic::Ordering::Acquire)
    }

    /// Makes the context behave as after `VK_ERROR_DEVICE_LOST`: every later submission returns
    /// [`GpuError::DeviceLost`]. A real loss cannot be provoked on demand, so this is how hosts
    /// and tests exercise their recovery path; nothing is destroyed, dropping stays safe.
    pub fn simulate_device_lost(&self) {
        self.shared
            .lost
            .store(true, std::sync::atomic::Ordering::Release);
    }

    /// Marks the context lost when `e` is a device loss; returns `e`.
    pub(crate) fn note_error(&self, e: GpuError) -> GpuError {
        if matches!(e, GpuError::DeviceLost { .. }) {
            self.simulate_device_lost();
        }
        e
    }

    /// Submits one batch on the (locked) queue, failing fast on a lost device.
    pub(crate) fn submit(&self, submit: &vk::SubmitInfo<'_>, fence: vk::Fence) -> GpuResult<()> {
        if self.is_lost() {
            return Err(GpuError::DeviceLost {
                what: "vkQueueSubmit",
            });
        }
        let queue = self.queue();
        // SAFETY: the queue is locked (external synchronization); the caller passes an
        // executable command buffer and an unsignalled fence that no pending submission uses.
        unsafe {
            self.device()
                .queue_submit(*queue, std::slice::from_ref(submit), fence)
        }
        .map_err(|r| self.note_error(super::error::map_result("vkQueueSubmit", r)))
    }

    /// Waits up to `timeout` for `fence`; a timeout is [`GpuError::Timeout`] naming `what`.
    pub(crate) fn wait_fence(
        &self,
        fence: vk::Fence,
        timeout: std::time::Duration,
        what: &str,
    ) -> GpuResult<()> {
        let nanos = u64::try_from(timeout.as_nanos()).unwrap_or(u64::MAX);
        // SAFETY: the fence belongs to this device; waiting has no other requirement.
        match unsafe { self.device().wait_for_fences(&[fence], true, nanos) } {
            Ok(()) => Ok(()),
            Err(vk::Result::TIMEOUT) => Err(GpuError::Timeout {
                what: what.to_string(),
                timeout,
            }),
            Err(r) => Err(self.note_error(super::error::map_result("vkWaitForFences", r))),
        }
    }

    pub(crate) fn queue(&self) -> MutexGuard<'_, vk::Queue> {
        self.shared
            .queue
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }

    /// The allocator, locked. `Invalid` only if called during teardown, which the `Arc`s prevent.
    pub(crate) fn with_allocator<T>(
        &self,
        f: impl FnOnce(&mut Allocator) -> GpuResult<T>,
    ) -> GpuResult<T> {
        match &self.shared.allocator {
            AllocatorSlot::Own(a) => {
                let mut guard = a.lock().unwrap_or_else(PoisonError::into_inner);
                match guard.as_mut() {
                    Some(allocator) => f(allocator),
                    None => Err(GpuError::Invalid("allocator used during teardown".into())),
                }
            }
            AllocatorSlot::Host(a) => f(&mut a.lock().unwrap_or_else(PoisonError::into_inner)),
        }
    }

    /// Gives `handle` a debug name (shown in validation messages and capture tools) when
    /// `VK_EXT_debug_utils` is on; otherwise does nothing. Naming failures are ignored: names
    /// are a debugging aid, never a reason to fail.
    pub(crate) fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        let Some(debug_utils) = &self.shared.debug_utils else {
            return;
        };
        let name = c_name(name);
        let info = vk::DebugUtilsObjectNameInfoEXT::default()
            .object_handle(handle)
            .object_name(&name);
        // SAFETY: `handle` is a live object of this device and `info` outlives the call.
        let _ = unsafe { debug_utils.set_debug_utils_object_name(&info) };
    }
}

/// Everything `assemble` needs, from either constructor.
struct Parts {
    entry: ash::Entry,
    instance: ash::Instance,
    physical_device: vk::PhysicalDevice,
    device: ash::Device,
    queue_family_index: u32,
    /// `None`: fetch queue 0 of the family (we created the device).
    queue: Option<vk::Queue>,
    debug_utils: bool,
    messenger: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    messages: MessageLog,
    owns: bool,
    validation: bool,
    sync_validation: bool,
    start: Instant,
    host_allocator: Option<HostAllocator>,
}

/// Builds the shared state. From the first line on, `Shared`'s `Drop` owns the cleanup, so no
/// error path can leak the device or the instance.
fn assemble(p: Parts) -> GpuResult<Context> {
    // SAFETY: plain queries on a live instance and one of its physical devices.
    let props = unsafe { p.instance.get_physical_device_properties(p.physical_device) };
    // SAFETY: as above.
    let families = unsafe {
        p.instance
            .get_physical_device_queue_family_properties(p.physical_device)
    };
    let queue = match p.queue {
        Some(q) => q,
        // SAFETY: the device was created with one queue of this family.
        None => unsafe { p.device.get_device_queue(p.queue_family_index, 0) },
    };
    let timestamp_valid_bits = families
        .get(p.queue_family_index as usize)
        .map_or(0, |f| f.timestamp_valid_bits);
    let l = &props.limits;
    let limits = DeviceLimits {
        max_compute_work_group_count: l.max_compute_work_group_count,
        max_compute_work_group_invocations: l.max_compute_work_group_invocations,
        max_storage_buffer_range: u64::from(l.max_storage_buffer_range),
        max_push_constants_size: l.max_push_constants_size,
        timestamp_period_ns: l.timestamp_period,
        timestamps: timestamp_valid_bits > 0 && l.timestamp_period > 0.0,
        timestamp_valid_bits,
    };
    let device_name = props
        .device_name_as_c_str()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|_| "(unnamed device)".to_string());
    let sync2 = ash::khr::synchronization2::Device::new(&p.instance, &p.device);
    let debug_utils = p
        .debug_utils
        .then(|| ash::ext::debug_utils::Device::new(&p.instance, &p.device));
    let (allocator, allocator_error) = match p.host_allocator {
        Some(a) => (AllocatorSlot::Host(a), None),
        None => {
            let mut debug_settings = gpu_allocator::AllocatorDebugSettings::default();
            // We report leaks ourselves, into the message log where tests see them.
            debug_settings.log_leaks_on_shutdown = false;
            let allocator_result = Allocator::new(&AllocatorCreateDesc {
                instance: p.instance.clone(),
                device: p.device.clone(),
                physical_device: p.physical_device,
                debug_settings,
                buffer_device_address: false,
                allocation_sizes: gpu_allocator::AllocationSizes::default(),
            });
            match allocator_result {
                Ok(a) => (AllocatorSlot::Own(Mutex::new(Some(a))), None),
                Err(e) => (
                    AllocatorSlot::Own(Mutex::new(None)),
                    Some(map_allocation("allocator", e)),
                ),
            }
        }
    };
    let shared = Shared {
        device: p.device,
        sync2,
        debug_utils,
        allocator,
        queue: Mutex::new(queue),
        lost: std::sync::atomic::AtomicBool::new(false),
        queue_family_index: p.queue_family_index,
        physical_device: p.physical_device,
        device_name,
        device_type: props.device_type,
        api_version: props.api_version,
        limits,
        validation: p.validation,
        sync_validation: p.sync_validation,
        creation_time: p.start.elapsed(),
        messenger: p.messenger,
        instance: p.instance,
        owns_device: p.owns,
        owns_instance: p.owns,
        messages: p.messages,
        _entry: p.entry,
    };
    // Dropping `shared` here tears everything down in the documented order.
    if let Some(e) = allocator_error {
        return Err(e);
    }
    let ctx = Context {
        shared: Arc::new(shared),
    };
    ctx.set_name(queue, "foldfree.compute_queue");
    ctx.set_name(ctx.shared.device.handle(), "foldfree.device");
    Ok(ctx)
}

/// Lists the physical devices with what makes each usable or not.
fn candidates(instance: &ash::Instance) -> GpuResult<Vec<Candidate>> {
    // SAFETY: plain query on a live instance.
    let raws = match unsafe { instance.enumerate_physical_devices() } {
        Ok(list) => list,
        Err(vk::Result::ERROR_INITIALIZATION_FAILED) => {
            return Err(GpuError::NoDevice(format!(
                "vkEnumeratePhysicalDevices returned ERROR_INITIALIZATION_FAILED: the installed \
                 drivers match no hardware; {INSTALL_HINT}"
            )))
        }
        Err(r) => return Err(map_result("vkEnumeratePhysicalDevices", r)),
    };
    if raws.is_empty() {
        return Err(GpuError::NoDevice(format!(
            "the Vulkan loader lists no device; {INSTALL_HINT}"
        )));
    }
    let mut out = Vec::with_capacity(raws.len());
    for (index, raw) in raws.into_iter().enumerate() {
        // SAFETY: plain query on a device of this instance.
        let props = unsafe { instance.get_physical_device_properties(raw) };
        // SAFETY: as above.
        let families = unsafe { instance.get_physical_device_queue_family_properties(raw) };
        // SAFETY: as above.
        let extensions = unsafe { instance.enumerate_device_extension_properties(raw) }
            .map_err(|r| map_result("vkEnumerateDeviceExtensionProperties", r))?;
        let mut sync2_features = vk::PhysicalDeviceSynchronization2Features::default();
        let mut features12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut features2 = vk::PhysicalDeviceFeatures2::default()
            .push_next(&mut sync2_features)
            .push_next(&mut features12);
        // SAFETY: `features2` and its chained struct live across the call. The instance is
        // Vulkan 1.2, so the core entry point exists.
        unsafe { instance.get_physical_device_features2(raw, &mut features2) };

        let compute: Vec<(u32, &vk::QueueFamilyProperties)> = families
            .iter()
            .enumerate()
            .filter(|(_, f)| f.queue_flags.contains(vk::QueueFlags::COMPUTE) && f.queue_count > 0)
            .map(|(i, f)| (i as u32, f))
            .collect();
        // Prefer a family that can write timestamps (for per-kernel profiling).
        let family = compute
            .iter()
            .find(|(_, f)| f.timestamp_valid_bits > 0)
            .or_else(|| compute.first())
            .copied();

        let unusable = if props.api_version < API_VERSION {
            Some("needs Vulkan 1.2".to_string())
        } else if family.is_none() {
            Some("no compute queue".to_string())
        } else if !has_extension(&extensions, ash::khr::synchronization2::NAME)
            || sync2_features.synchronization2 == vk::FALSE
        {
            Some("no VK_KHR_synchronization2".to_string())
        } else if features12.timeline_semaphore == vk::FALSE {
            Some("no timeline semaphores".to_string())
        } else {
            None
        };
        out.push(Candidate {
            raw,
            index,
            name: props
                .device_name_as_c_str()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            device_type: props.device_type,
            api_version: props.api_version,
            queue_family_index: family.map(|(i, _)| i),
            portability_subset: has_extension(&extensions, PORTABILITY_SUBSET_EXT),
            unusable,
        });
    }
    Ok(out)
}

/// Picks a device (the requested one, else the best usable) and creates it.
fn create_device(
    instance: &ash::Instance,
    requested: Option<&str>,
) -> GpuResult<(Candidate, ash::Device)> {
    let mut list = candidates(instance)?;
    let available = || {
        list.iter()
            .map(Candidate::describe)
            .collect::<Vec<_>>()
            .join("; ")
    };
    let chosen = match requested {
        Some(req) => {
            let req = req.trim();
            let found = match req.parse::<usize>() {
                Ok(i) => list.iter().position(|c| c.index == i),
                Err(_) => {
                    let needle = req.to_lowercase();
                    let matching = |c: &Candidate| c.name.to_lowercase().contains(&needle);
                    list.iter()
                        .position(|c| matching(c) && c.unusable.is_none())
                        .or_else(|| list.iter().position(matching))
                }
            };
            match found {
                Some(i) if list[i].unusable.is_none() => i,
                Some(i) => {
                    return Err(GpuError::NoDevice(format!(
                        "requested device {req:?} is {}; available: {}",
                        list[i].describe(),
                        available()
                    )))
                }
                None => {
                    return Err(GpuError::NoSuchDevice(format!(
                    "no device matches {req:?} (set by --device or {DEVICE_ENV}); available: {}",
                    available()
                )))
                }
            }
        }
        None => match list
            .iter()
            .filter(|c| c.unusable.is_none())
            .min_by_key(|c| (conv::device_type_rank(c.device_type), c.index))
        {
            Some(c) => c.index,
            None => {
                return Err(GpuError::NoDevice(format!(
                    "no device is usable; available: {}",
                    available()
                )))
            }
        },
    };
    let candidate = list.swap_remove(chosen);
    let family = candidate
        .queue_family_index
        .ok_or_else(|| GpuError::NoDevice("chosen device has no compute queue".into()))?;

    let priorities = [1.0f32];
    let queue_infos = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(family)
        .queue_priorities(&priorities)];
    let mut ext_names = vec![ash::khr::synchronization2::NAME.as_ptr()];
    if candidate.portability_subset {
        ext_names.push(PORTABILITY_SUBSET_EXT.as_ptr());
    }
    let mut sync2 = vk::PhysicalDeviceSynchronization2Features::default().synchronization2(true);
    let mut features12 = vk::PhysicalDeviceVulkan12Features::default().timeline_semaphore(true);
    let info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queue_infos)
        .enabled_extension_names(&ext_names)
        .push_next(&mut sync2)
        .push_next(&mut features12);
    // SAFETY: the physical device belongs to `instance`; every pointer in `info` lives until
    // the call returns; the extension and feature were checked as supported.
    let device = unsafe { instance.create_device(candidate.raw, &info, None) }
        .map_err(|r| map_result("vkCreateDevice", r))?;
    Ok((candidate, device))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn required_features_name_synchronization2() {
        let f = required_features();
        assert_eq!(f.api_version, vk::API_VERSION_1_2);
        assert!(f
            .device_extensions
            .contains(&ash::khr::synchronization2::NAME));
    }

    /// A context borrowing another's device works, and dropping it destroys nothing it does
    /// not own (the owner stays usable and validation stays silent).
    #[test]
    fn from_host_borrows_and_destroys_nothing() {
        let desc = ContextDesc {
            validation: true,
            ..ContextDesc::default()
        };
        let owner = match Context::new(&desc) {
            Ok(ctx) => ctx,
            Err(e) if std::env::var("REQUIRE_VULKAN").is_ok_and(|v| v == "1") => {
                panic!("REQUIRE_VULKAN=1 but Vulkan is unavailable: {e}")
            }
            Err(e) => {
                eprintln!("skipped: no Vulkan ({e})");
                return;
            }
        };
        let host = HostDesc {
            entry: owner.shared._entry.clone(),
            instance: owner.shared.instance.clone(),
            physical_device: owner.physical_device(),
            device: owner.shared.device.clone(),
            queue_family_index: owner.queue_family_index(),
            queue: *owner.queue(),
            debug_utils: true,
            allocator: None,
        };
        // SAFETY: the handles come from `owner`, which outlives `borrowed`, was created with
        // `required_features()`, and this single-threaded test never submits from both at once.
        let borrowed = unsafe { Context::from_host(host.clone()) }.expect("from_host");
        assert_eq!(borrowed.device_name(), owner.device_name());
        let data: Vec<u32> = (0..1000).collect();
        let b = super::super::Buffer::from_slice(&borrowed, "host.data", &data).expect("buffer");
        assert_eq!(b.download_staged::<u32>().expect("read"), data);
        drop(b);
        drop(borrowed);

        // With the host's own allocator: our buffers show up in its report while alive, are
        // gone from it when dropped, and the allocator outlives the context.
        let host_allocator: HostAllocator = Arc::new(Mutex::new(
            Allocator::new(&AllocatorCreateDesc {
                instance: host.instance.clone(),
                device: host.device.clone(),
                physical_device: host.physical_device,
                debug_settings: Default::default(),
                buffer_device_address: false,
                allocation_sizes: Default::default(),
            })
            .expect("host allocator"),
        ));
        let names = |a: &HostAllocator| -> Vec<String> {
            a.lock()
                .expect("lock")
                .generate_report()
                .allocations
                .iter()
                .map(|x| x.name.clone())
                .collect()
        };
        let with_alloc = HostDesc {
            allocator: Some(host_allocator.clone()),
            ..host
        };
        // SAFETY: as above; the allocator was made for this device.
        let shared_alloc = unsafe { Context::from_host(with_alloc) }.expect("from_host");
        let b = super::super::Buffer::from_slice(&shared_alloc, "host.alloc", &data)
            .expect("buffer in the host's allocator");
        assert!(names(&host_allocator).contains(&"host.alloc".to_string()));
        assert_eq!(b.download_staged::<u32>().expect("read"), data);
        drop(b);
        assert!(!names(&host_allocator).contains(&"host.alloc".to_string()));
        drop(shared_alloc);
        assert_eq!(Arc::strong_count(&host_allocator), 1);
        drop(host_allocator);
        let c = super::super::Buffer::from_slice(&owner, "owner.data", &data).expect("buffer");
        assert_eq!(c.download_staged::<u32>().expect("read"), data);
        drop(c);
        assert_eq!(owner.validation_messages(), Vec::<String>::new());
        let log = owner.message_log();
        drop(owner);
        assert_eq!(log.messages(), Vec::<String>::new());
    }

    #[test]
    fn c_name_drops_interior_nul() {
        assert_eq!(c_name("a\0b").to_str().ok(), Some("a b"));
    }
}
