//! Plays a host renderer that embeds foldfree on its own Vulkan device.
//!
//! The host creates its instance, device and queue with ash (enabling what
//! `foldfree::embed::required_features()` lists; plus the Khronos validation layer when
//! `FOLDFREE_EXAMPLE_VALIDATION=1`, and synchronization validation when also
//! `FOLDFREE_SYNC_VALIDATION=1`), its own interleaved vertex buffer (3 floats position + 2
//! floats UV, stride 20 bytes) and index buffer in host-visible memory it allocates itself,
//! then lends its handles to a `foldfree::embed::Engine`, parameterizes
//! `tests/data/camel_open.obj`, has the engine write the UVs into the vertex buffer (once by
//! the engine's own submission, once recorded into the host's command buffer), reads the buffer
//! back, prints summary statistics, and destroys its own objects after the engine is dropped —
//! proving the engine destroyed none of them. Then a frame loop: frames (each clears a 1024²
//! RGBA8 offscreen image and reads one texel back, on the host's queue with the host's fence)
//! while an `embed::Job` parameterizes the same mesh between them (`poll()` once per frame,
//! slices of `FOLDFREE_SLICE_MS` device time, default 4), then as many frames without it, and
//! the frame-time distribution of both, checking the job's UVs against the blocking call's bit
//! for bit. Frames run back to back unless `FOLDFREE_FRAME_HZ` paces them.
//!
//! Run: `cargo run --release --example host_renderer [mesh.obj]`.
//!
//! `tests/gpu/embed.rs` includes this file as a module and runs the same flow under validation.

use std::error::Error;
use std::ffi::{c_char, c_void, CStr};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use ash::vk;
use foldfree::embed::{
    self, EmbedOptions, Engine, ForeignBuffer, ForeignCommandBuffer, HostAccess, UvFormat, UvTarget,
};
use foldfree::gpu::{Context, HostDesc, SYNC2_FEATURE, TIMELINE_FEATURE};
use foldfree::mesh::TriMesh;

pub type BoxResult<T> = Result<T, Box<dyn Error>>;

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";
const VALIDATION_FEATURES_EXT: &CStr = c"VK_EXT_validation_features";

/// Bytes per vertex of the host's interleaved vertex buffer: position (3 × f32), UV (2 × f32).
pub const VERTEX_STRIDE: u64 = 20;
/// Byte offset of the UV inside a vertex.
pub const UV_OFFSET: u64 = 12;
/// What the host puts in the UV slots before the engine writes them.
const SENTINEL: f32 = -12345.0;

/// The host's messages from its debug messenger (the Box keeps the address stable for the
/// callback's user-data pointer).
type MessageSink = Box<Mutex<Vec<String>>>;

/// The debug messenger callback: collects WARNING and ERROR messages.
unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    use vk::DebugUtilsMessageSeverityFlagsEXT as S;
    if !severity.intersects(S::WARNING | S::ERROR) || user.is_null() || data.is_null() {
        return vk::FALSE;
    }
    // SAFETY: the layer passes valid callback data for the duration of the call.
    let message = unsafe { (*data).p_message };
    let text = if message.is_null() {
        String::from("(no message)")
    } else {
        // SAFETY: `p_message` is a NUL-terminated string owned by the layer during the call.
        unsafe { CStr::from_ptr(message) }
            .to_string_lossy()
            .into_owned()
    };
    // SAFETY: `user` is the address of the host's `Mutex<Vec<String>>`, boxed and alive until
    // after the messenger is destroyed (`Drop for Host`).
    let sink = unsafe { &*(user as *const Mutex<Vec<String>>) };
    if let Ok(mut list) = sink.lock() {
        list.push(format!("{severity:?}: {text}"));
    }
    vk::FALSE
}

/// A buffer the host created, with its own memory, persistently mapped.
pub struct HostBuffer {
    pub raw: vk::Buffer,
    pub memory: vk::DeviceMemory,
    pub size: u64,
    ptr: *mut u8,
}

/// The host application's Vulkan objects.
pub struct Host {
    pub entry: ash::Entry,
    pub instance: ash::Instance,
    messenger: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    messages: MessageSink,
    pub physical_device: vk::PhysicalDevice,
    pub device: ash::Device,
    pub queue_family_index: u32,
    pub queue: vk::Queue,
    memory_properties: vk::PhysicalDeviceMemoryProperties,
    pub validation: bool,
}

/// Why the host could not start: Vulkan (or the layer) is missing, as opposed to a bug.
#[derive(Debug)]
pub struct Unavailable(pub String);

impl std::fmt::Display for Unavailable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Vulkan unavailable: {}", self.0)
    }
}
impl Error for Unavailable {}

impl Host {
    /// Creates the host's instance (with validation if asked), device and queue.
    pub fn new(validation: bool, sync_validation: bool) -> BoxResult<Host> {
        let validation = validation || sync_validation;
        let required = embed::required_features();
        // SAFETY: loading the system's Vulkan loader (libvulkan.so.1) runs its initialisers.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| Unavailable(e.to_string()))?;
        if validation {
            // SAFETY: plain query on a loaded entry.
            let layers = unsafe { entry.enumerate_instance_layer_properties() }?;
            if !layers
                .iter()
                .any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER))
            {
                return Err(Unavailable("no VK_LAYER_KHRONOS_validation".into()).into());
            }
        }
        let mut ext_names: Vec<*const c_char> = Vec::new();
        if validation {
            ext_names.push(ash::ext::debug_utils::NAME.as_ptr());
        }
        if sync_validation {
            ext_names.push(VALIDATION_FEATURES_EXT.as_ptr());
        }
        let layer_names: Vec<*const c_char> = if validation {
            vec![VALIDATION_LAYER.as_ptr()]
        } else {
            Vec::new()
        };
        let messages: MessageSink = Box::new(Mutex::new(Vec::new()));
        let user_data = &*messages as *const Mutex<Vec<String>> as *mut c_void;
        let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(
                vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                    | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
            )
            .message_type(
                vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                    | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                    | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
            )
            .pfn_user_callback(Some(on_message))
            .user_data(user_data);
        let enabled_features = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut features =
            vk::ValidationFeaturesEXT::default().enabled_validation_features(&enabled_features);
        let app_info = vk::ApplicationInfo::default()
            .application_name(c"foldfree-host-renderer")
            .api_version(required.api_version);
        let mut info = vk::InstanceCreateInfo::default()
            .application_info(&app_info)
            .enabled_layer_names(&layer_names)
            .enabled_extension_names(&ext_names);
        if validation {
            info = info.push_next(&mut messenger_info);
        }
        if sync_validation {
            info = info.push_next(&mut features);
        }
        // SAFETY: every pointer in `info` outlives the call; the layer and extensions exist.
        let instance = unsafe { entry.create_instance(&info, None) }
            .map_err(|r| Unavailable(format!("vkCreateInstance: {r}")))?;
        let mut messenger = None;
        if validation {
            let loader = ash::ext::debug_utils::Instance::new(&entry, &instance);
            // SAFETY: valid create info; the user data (the boxed sink) outlives the messenger.
            match unsafe { loader.create_debug_utils_messenger(&messenger_info, None) } {
                Ok(m) => messenger = Some((loader, m)),
                Err(r) => {
                    // SAFETY: the instance has no children yet.
                    unsafe { instance.destroy_instance(None) };
                    return Err(r.into());
                }
            }
        }
        let device = match create_device(&instance, &required) {
            Ok(d) => d,
            Err(e) => {
                if let Some((loader, m)) = &messenger {
                    // SAFETY: the host's messenger, of this instance.
                    unsafe { loader.destroy_debug_utils_messenger(*m, None) };
                }
                // SAFETY: its only child (the messenger) is destroyed.
                unsafe { instance.destroy_instance(None) };
                return Err(e);
            }
        };
        Ok(Host {
            entry,
            instance,
            messenger,
            messages,
            physical_device: device.physical_device,
            device: device.device,
            queue_family_index: device.family,
            queue: device.queue,
            memory_properties: device.memory_properties,
            validation,
        })
    }

    /// The handles lent to foldfree.
    pub fn host_desc(&self) -> HostDesc {
        HostDesc {
            entry: self.entry.clone(),
            instance: self.instance.clone(),
            physical_device: self.physical_device,
            device: self.device.clone(),
            queue_family_index: self.queue_family_index,
            queue: self.queue,
            debug_utils: self.validation,
            // The engine makes its own allocator; a host with one passes it here.
            allocator: None,
        }
    }

    /// The validation messages so far, leaving the list empty.
    pub fn take_messages(&self) -> Vec<String> {
        self.messages
            .lock()
            .map(|mut l| std::mem::take(&mut *l))
            .unwrap_or_default()
    }

    /// A buffer with its own host-visible, coherent memory, mapped.
    pub fn create_buffer(&self, size: u64, usage: vk::BufferUsageFlags) -> BoxResult<HostBuffer> {
        let info = vk::BufferCreateInfo::default()
            .size(size)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid create info on a live device.
        let raw = unsafe { self.device.create_buffer(&info, None) }?;
        // SAFETY: `raw` is a live buffer of this device.
        let req = unsafe { self.device.get_buffer_memory_requirements(raw) };
        let wanted = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        let mp = &self.memory_properties;
        let type_index = (0..mp.memory_type_count)
            .find(|&i| {
                req.memory_type_bits & (1 << i) != 0
                    && mp.memory_types[i as usize].property_flags.contains(wanted)
            })
            .ok_or("no host-visible coherent memory type")?;
        let alloc = vk::MemoryAllocateInfo::default()
            .allocation_size(req.size)
            .memory_type_index(type_index);
        // SAFETY: valid allocate info.
        let memory = unsafe { self.device.allocate_memory(&alloc, None) }?;
        // SAFETY: fresh memory of a type the buffer allows, large enough, offset 0.
        unsafe { self.device.bind_buffer_memory(raw, memory, 0) }?;
        // SAFETY: host-visible memory, not mapped yet; the whole allocation.
        let ptr = unsafe {
            self.device
                .map_memory(memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
        }?;
        Ok(HostBuffer {
            raw,
            memory,
            size,
            ptr: ptr.cast(),
        })
    }

    /// Copies `data` to the start of the buffer (no GPU work may use it meanwhile).
    pub fn write_buffer<T: bytemuck::Pod>(&self, b: &HostBuffer, data: &[T]) {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        assert!(bytes.len() as u64 <= b.size);
        // SAFETY: the mapping covers `b.size` bytes; coherent memory needs no flush; no GPU
        // work touches the buffer during the copy (the caller's promise).
        unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), b.ptr, bytes.len()) };
    }

    /// The buffer's bytes as `T`s (after the GPU work that wrote them is waited for).
    pub fn read_buffer<T: bytemuck::Pod>(&self, b: &HostBuffer) -> Vec<T> {
        let mut out = vec![T::zeroed(); b.size as usize / std::mem::size_of::<T>()];
        let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
        // SAFETY: the mapping covers `b.size` bytes ≥ dst.len(); coherent memory.
        unsafe { std::ptr::copy_nonoverlapping(b.ptr, dst.as_mut_ptr(), dst.len()) };
        out
    }

    pub fn destroy_buffer(&self, b: HostBuffer) {
        // SAFETY: no pending GPU work uses the buffer (every submission was waited for).
        unsafe { self.device.destroy_buffer(b.raw, None) };
        // SAFETY: the buffer bound to it is destroyed; freeing unmaps it.
        unsafe { self.device.free_memory(b.memory, None) };
    }

    /// Records `record` into a fresh command buffer of the host's, submits it on the host's
    /// queue, waits, and frees what it created.
    pub fn submit_once(
        &self,
        record: impl FnOnce(vk::CommandBuffer) -> BoxResult<()>,
    ) -> BoxResult<()> {
        self.submit_after(None, record)
    }

    /// [`Host::submit_once`], the submission waiting (all commands) until the timeline
    /// semaphore `wait.0` reaches `wait.1` — how a host orders its work after a job's slices
    /// without a CPU wait.
    pub fn submit_after(
        &self,
        wait: Option<(vk::Semaphore, u64)>,
        record: impl FnOnce(vk::CommandBuffer) -> BoxResult<()>,
    ) -> BoxResult<()> {
        let pool_info = vk::CommandPoolCreateInfo::default()
            .flags(vk::CommandPoolCreateFlags::TRANSIENT)
            .queue_family_index(self.queue_family_index);
        // SAFETY: valid create info.
        let pool = unsafe { self.device.create_command_pool(&pool_info, None) }?;
        let result = (|| -> BoxResult<()> {
            let alloc = vk::CommandBufferAllocateInfo::default()
                .command_pool(pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1);
            // SAFETY: the pool is live.
            let cmd = unsafe { self.device.allocate_command_buffers(&alloc) }?[0];
            let begin = vk::CommandBufferBeginInfo::default()
                .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
            // SAFETY: a fresh command buffer in the initial state.
            unsafe { self.device.begin_command_buffer(cmd, &begin) }?;
            record(cmd)?;
            // SAFETY: recording.
            unsafe { self.device.end_command_buffer(cmd) }?;
            // SAFETY: valid create info.
            let fence = unsafe {
                self.device
                    .create_fence(&vk::FenceCreateInfo::default(), None)
            }?;
            let cmds = [cmd];
            let wait_semaphores: Vec<vk::Semaphore> = wait.iter().map(|w| w.0).collect();
            let wait_values: Vec<u64> = wait.iter().map(|w| w.1).collect();
            let wait_stages = vec![vk::PipelineStageFlags::ALL_COMMANDS; wait_values.len()];
            let mut timeline =
                vk::TimelineSemaphoreSubmitInfo::default().wait_semaphore_values(&wait_values);
            let submit = vk::SubmitInfo::default()
                .command_buffers(&cmds)
                .wait_semaphores(&wait_semaphores)
                .wait_dst_stage_mask(&wait_stages)
                .push_next(&mut timeline);
            // SAFETY: the host is the only user of its queue right now; the fence is fresh; the
            // wait names a timeline semaphore with its value (arrays outlive the call).
            let submitted = unsafe { self.device.queue_submit(self.queue, &[submit], fence) };
            let waited = submitted.and_then(|()| {
                // SAFETY: our fence, just submitted.
                unsafe { self.device.wait_for_fences(&[fence], true, u64::MAX) }
            });
            // SAFETY: the fence is signalled (or was never submitted).
            unsafe { self.device.destroy_fence(fence, None) };
            Ok(waited?)
        })();
        // SAFETY: the command buffer is no longer pending (waited above); freeing the pool
        // frees it.
        unsafe { self.device.destroy_command_pool(pool, None) };
        result
    }
}

/// The device the host made.
struct HostDevice {
    physical_device: vk::PhysicalDevice,
    family: u32,
    memory_properties: vk::PhysicalDeviceMemoryProperties,
    device: ash::Device,
    queue: vk::Queue,
}

/// Picks a Vulkan 1.2 device with a graphics + compute queue family and creates it with what
/// foldfree requires.
fn create_device(
    instance: &ash::Instance,
    required: &embed::RequiredFeatures,
) -> BoxResult<HostDevice> {
    for f in &required.device_features {
        if *f != SYNC2_FEATURE && *f != TIMELINE_FEATURE {
            return Err(format!("this host does not know how to enable {f}").into());
        }
    }
    // SAFETY: plain query on a live instance.
    let devices = unsafe { instance.enumerate_physical_devices() }
        .map_err(|r| Unavailable(format!("vkEnumeratePhysicalDevices: {r}")))?;
    let mut chosen = None;
    for pd in devices {
        // SAFETY: plain query on a device of this instance.
        let props = unsafe { instance.get_physical_device_properties(pd) };
        // SAFETY: as above.
        let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
        // A renderer wants graphics and compute on one queue.
        let family = families.iter().position(|f| {
            f.queue_flags
                .contains(vk::QueueFlags::GRAPHICS | vk::QueueFlags::COMPUTE)
        });
        if let (Some(family), true) = (family, props.api_version >= required.api_version) {
            chosen = Some((pd, family as u32));
            break;
        }
    }
    let (pd, family) =
        chosen.ok_or_else(|| Unavailable("no Vulkan 1.2 device with graphics".into()))?;
    // SAFETY: plain query.
    let memory_properties = unsafe { instance.get_physical_device_memory_properties(pd) };
    let priorities = [1.0f32];
    let queue_infos = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(family)
        .queue_priorities(&priorities)];
    let ext_names: Vec<*const c_char> = required
        .device_extensions
        .iter()
        .map(|e| e.as_ptr())
        .collect();
    let mut sync2 = vk::PhysicalDeviceSynchronization2Features::default().synchronization2(true);
    let mut features12 = vk::PhysicalDeviceVulkan12Features::default().timeline_semaphore(true);
    let info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queue_infos)
        .enabled_extension_names(&ext_names)
        .push_next(&mut sync2)
        .push_next(&mut features12);
    // SAFETY: the physical device belongs to the instance; pointers outlive the call.
    let device = unsafe { instance.create_device(pd, &info, None) }?;
    // SAFETY: the device was created with one queue of this family.
    let queue = unsafe { device.get_device_queue(family, 0) };
    Ok(HostDevice {
        physical_device: pd,
        family,
        memory_properties,
        device,
        queue,
    })
}

impl Drop for Host {
    fn drop(&mut self) {
        // SAFETY: the host owns its device; nothing else uses it any more.
        let _ = unsafe { self.device.device_wait_idle() };
        // SAFETY: idle, and every child object was destroyed by the host.
        unsafe { self.device.destroy_device(None) };
        if let Some((loader, m)) = self.messenger.take() {
            // SAFETY: the host's messenger, of this instance.
            unsafe { loader.destroy_debug_utils_messenger(m, None) };
        }
        // SAFETY: its device and messenger are destroyed above.
        unsafe { self.instance.destroy_instance(None) };
    }
}

/// What one run of the host flow produced.
pub struct RunOutput {
    /// `Engine::parameterize`'s answer.
    pub uv: Vec<[f64; 2]>,
    /// The UVs read back from the host's vertex buffer after `Engine::write_uvs`.
    pub uv_submitted: Vec<[f32; 2]>,
    /// The same, after `Engine::record_write_uvs` into the host's command buffer.
    pub uv_recorded: Vec<[f32; 2]>,
    /// Whether the positions in the vertex buffers came back bit-identical.
    pub positions_intact: bool,
    /// Seconds spent in `Engine::parameterize`.
    pub seconds: f64,
}

fn vertices_of(mesh: &TriMesh) -> Vec<f32> {
    mesh.positions
        .iter()
        .flat_map(|p| [p[0] as f32, p[1] as f32, p[2] as f32, SENTINEL, SENTINEL])
        .collect()
}

fn split_vertices(words: &[f32], n: usize) -> (Vec<[f32; 3]>, Vec<[f32; 2]>) {
    let v = &words[..n * 5];
    let pos = v.chunks_exact(5).map(|c| [c[0], c[1], c[2]]).collect();
    let uv = v.chunks_exact(5).map(|c| [c[3], c[4]]).collect();
    (pos, uv)
}

/// The host flow: buffers, engine, parameterize, both ways of writing UVs, read back. The
/// engine is dropped before this returns; the host's buffers are destroyed after it.
pub fn run(host: &Host, mesh: &TriMesh) -> BoxResult<RunOutput> {
    let n = mesh.positions.len();
    let vb_size = n as u64 * VERTEX_STRIDE;
    let usage = vk::BufferUsageFlags::VERTEX_BUFFER | vk::BufferUsageFlags::STORAGE_BUFFER;
    let vb_submit = host.create_buffer(vb_size, usage)?;
    let vb_record = host.create_buffer(vb_size, usage | vk::BufferUsageFlags::TRANSFER_DST)?;
    let ib = host.create_buffer(
        (mesh.faces.len() * 12) as u64,
        vk::BufferUsageFlags::INDEX_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
    )?;
    let vertices = vertices_of(mesh);
    host.write_buffer(&vb_submit, &vertices);
    host.write_buffer(&vb_record, &vertices);
    host.write_buffer(&ib, &mesh.faces);

    let result = (|| -> BoxResult<(Vec<[f64; 2]>, f64)> {
        // SAFETY: the handles come from `host`, which outlives the engine (dropped at the end
        // of this closure); the device has `required_features()`; this thread does not use the
        // queue while the engine runs.
        let ctx = unsafe { Context::from_host(host.host_desc()) }?;
        let engine = Engine::new(ctx)?;
        let t = Instant::now();
        let uv = engine.parameterize(&mesh.positions, &mesh.faces, &EmbedOptions::default())?;
        let seconds = t.elapsed().as_secs_f64();

        // (b) The engine submits on the host's queue and waits on its own fence.
        let target = UvTarget {
            // SAFETY: a live storage buffer of the lent device, `vb_size` bytes, exclusive to
            // the lent queue's family, destroyed only after the engine is dropped.
            buffer: unsafe { ForeignBuffer::new(vb_submit.raw, vb_submit.size) },
            offset: UV_OFFSET,
            stride: VERTEX_STRIDE,
            format: UvFormat::F32x2,
        };
        engine.write_uvs(&uv, &target)?;

        // (a) The engine records into the host's command buffer; the host submits.
        let target = UvTarget {
            // SAFETY: as above, for the second vertex buffer.
            buffer: unsafe { ForeignBuffer::new(vb_record.raw, vb_record.size) },
            ..target
        };
        let mut keep = None;
        host.submit_once(|cmd| {
            // SAFETY: `cmd` is recording, outside a render pass, from a pool of the lent
            // family, submitted to the lent queue; `keep` outlives the wait in `submit_once`.
            let cmd = unsafe { ForeignCommandBuffer::new(cmd) };
            // The host's own earlier command on the range: it clears vertex 0's UV slot
            // (which the engine then overwrites), so `before` must name a transfer write.
            // SAFETY: recording; the buffer is live with TRANSFER_DST usage; the 4-byte-aligned
            // range lies inside it.
            unsafe {
                host.device
                    .cmd_fill_buffer(cmd.raw(), vb_record.raw, UV_OFFSET, 8, 0)
            };
            keep = engine.record_write_uvs(
                cmd,
                &uv,
                &target,
                HostAccess {
                    stage: vk::PipelineStageFlags2::ALL_TRANSFER,
                    access: vk::AccessFlags2::TRANSFER_WRITE,
                },
                // Next uses: drawing with it, and reading it back on the CPU.
                HostAccess {
                    stage: vk::PipelineStageFlags2::VERTEX_ATTRIBUTE_INPUT
                        | vk::PipelineStageFlags2::HOST,
                    access: vk::AccessFlags2::VERTEX_ATTRIBUTE_READ | vk::AccessFlags2::HOST_READ,
                },
            )?;
            Ok(())
        })?;
        drop(keep);
        drop(engine);
        Ok((uv, seconds))
    })();

    let out = result.map(|(uv, seconds)| {
        let (pos_a, uv_submitted) = split_vertices(&host.read_buffer::<f32>(&vb_submit), n);
        let (pos_b, uv_recorded) = split_vertices(&host.read_buffer::<f32>(&vb_record), n);
        let (pos_in, _) = split_vertices(&vertices, n);
        RunOutput {
            uv,
            uv_submitted,
            uv_recorded,
            positions_intact: pos_a == pos_in && pos_b == pos_in,
            seconds,
        }
    });
    // The engine is gone: the host's device must still work. Use it once more.
    let device_usable = host.submit_once(|cmd| {
        // SAFETY: recording; the index buffer is live; 4-byte aligned range inside it.
        unsafe { host.device.cmd_fill_buffer(cmd, ib.raw, 0, 4, 7) };
        Ok(())
    });
    let fill_ok = host.read_buffer::<u32>(&ib).first() == Some(&7);
    host.destroy_buffer(vb_submit);
    host.destroy_buffer(vb_record);
    host.destroy_buffer(ib);
    device_usable?;
    if !fill_ok {
        return Err(
            "the host's device did not run its own fill after the engine was dropped".into(),
        );
    }
    out
}

/// The host's frame: clear a `size`² RGBA8 offscreen image to a colour that changes every
/// frame and copy it into a host-visible buffer (a renderer's clear-and-read-back, the stand-in
/// for drawing on a device without a window), submitted on the host's queue and waited for
/// with the host's fence. Recorded once, submitted every frame.
pub struct Frame {
    image: vk::Image,
    memory: vk::DeviceMemory,
    readback: HostBuffer,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
}

impl Frame {
    pub fn new(host: &Host, size: u32) -> BoxResult<Frame> {
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(vk::Format::R8G8B8A8_UNORM)
            .extent(vk::Extent3D {
                width: size,
                height: size,
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(1)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(vk::ImageUsageFlags::TRANSFER_DST | vk::ImageUsageFlags::TRANSFER_SRC)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: valid create info on a live device.
        let image = unsafe { host.device.create_image(&info, None) }?;
        // SAFETY: `image` is a live image of this device.
        let req = unsafe { host.device.get_image_memory_requirements(image) };
        let type_index = (0..host.memory_properties.memory_type_count)
            .find(|&i| req.memory_type_bits & (1 << i) != 0)
            .ok_or("no memory type for the offscreen image")?;
        let alloc = vk::MemoryAllocateInfo::default()
            .allocation_size(req.size)
            .memory_type_index(type_index);
        // SAFETY: valid allocate info.
        let memory = unsafe { host.device.allocate_memory(&alloc, None) }?;
        // SAFETY: fresh memory of a type the image allows, large enough, offset 0.
        unsafe { host.device.bind_image_memory(image, memory, 0) }?;
        let bytes = u64::from(size) * u64::from(size) * 4;
        let readback = host.create_buffer(bytes, vk::BufferUsageFlags::TRANSFER_DST)?;
        let pool_info =
            vk::CommandPoolCreateInfo::default().queue_family_index(host.queue_family_index);
        // SAFETY: valid create info.
        let pool = unsafe { host.device.create_command_pool(&pool_info, None) }?;
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool is live.
        let cmd = unsafe { host.device.allocate_command_buffers(&alloc) }?[0];
        // SAFETY: valid create info.
        let fence = unsafe {
            host.device
                .create_fence(&vk::FenceCreateInfo::default(), None)
        }?;
        let frame = Frame {
            image,
            memory,
            readback,
            pool,
            cmd,
            fence,
        };
        frame.record(host, size)?;
        Ok(frame)
    }

    /// The whole read-back buffer, from `src` to `dst` accesses.
    fn readback_barrier(
        &self,
        src: vk::AccessFlags,
        dst: vk::AccessFlags,
    ) -> vk::BufferMemoryBarrier<'static> {
        vk::BufferMemoryBarrier::default()
            .src_access_mask(src)
            .dst_access_mask(dst)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .buffer(self.readback.raw)
            .size(vk::WHOLE_SIZE)
    }

    /// The whole image, from `(access, layout)` to `(access, layout)`.
    fn image_barrier(
        &self,
        from: (vk::AccessFlags, vk::ImageLayout),
        to: (vk::AccessFlags, vk::ImageLayout),
    ) -> vk::ImageMemoryBarrier<'static> {
        vk::ImageMemoryBarrier::default()
            .src_access_mask(from.0)
            .dst_access_mask(to.0)
            .old_layout(from.1)
            .new_layout(to.1)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(self.image)
            .subresource_range(COLOR_RANGE)
    }

    fn record(&self, host: &Host, size: u32) -> BoxResult<()> {
        let d = &host.device;
        let range = COLOR_RANGE;
        // SAFETY: a fresh command buffer in the initial state.
        unsafe { d.begin_command_buffer(self.cmd, &vk::CommandBufferBeginInfo::default()) }?;
        // Last frame's copy (and host read) → this frame's clear; contents discarded.
        let to_clear = self.image_barrier(
            (vk::AccessFlags::TRANSFER_READ, vk::ImageLayout::UNDEFINED),
            (
                vk::AccessFlags::TRANSFER_WRITE,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            ),
        );
        // SAFETY: recording; the image is live.
        unsafe {
            d.cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_clear],
            )
        };
        let colour = vk::ClearColorValue {
            float32: [0.2, 0.4, 0.8, 1.0],
        };
        // SAFETY: recording; the image is in TRANSFER_DST_OPTIMAL with TRANSFER_DST usage.
        unsafe {
            d.cmd_clear_color_image(
                self.cmd,
                self.image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &colour,
                &[range],
            )
        };
        let to_copy = self.image_barrier(
            (
                vk::AccessFlags::TRANSFER_WRITE,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            ),
            (
                vk::AccessFlags::TRANSFER_READ,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            ),
        );
        // Last frame's host read of the read-back buffer → this frame's copy into it.
        let buffer_reuse =
            self.readback_barrier(vk::AccessFlags::HOST_READ, vk::AccessFlags::TRANSFER_WRITE);
        // SAFETY: recording; image and buffer are live.
        unsafe {
            d.cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::TRANSFER | vk::PipelineStageFlags::HOST,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[buffer_reuse],
                &[to_copy],
            )
        };
        let region = vk::BufferImageCopy::default()
            .image_subresource(
                vk::ImageSubresourceLayers::default()
                    .aspect_mask(vk::ImageAspectFlags::COLOR)
                    .layer_count(1),
            )
            .image_extent(vk::Extent3D {
                width: size,
                height: size,
                depth: 1,
            });
        // SAFETY: recording; the image is TRANSFER_SRC_OPTIMAL; the buffer holds size² texels.
        unsafe {
            d.cmd_copy_image_to_buffer(
                self.cmd,
                self.image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                self.readback.raw,
                &[region],
            )
        };
        let to_host =
            self.readback_barrier(vk::AccessFlags::TRANSFER_WRITE, vk::AccessFlags::HOST_READ);
        // SAFETY: recording; the buffer is live.
        unsafe {
            d.cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &[],
                &[to_host],
                &[],
            )
        };
        // SAFETY: recording.
        unsafe { d.end_command_buffer(self.cmd) }?;
        Ok(())
    }

    /// Submits the frame and waits for it; returns the first texel as a check.
    pub fn draw(&self, host: &Host) -> BoxResult<u32> {
        let cmds = [self.cmd];
        let submit = vk::SubmitInfo::default().command_buffers(&cmds);
        // SAFETY: the host owns its queue on this thread (the engine's job submits only inside
        // `Job::poll`, called on this thread); the fence is unsignalled and unused; the command
        // buffer is executable and not pending (the last frame was waited for).
        unsafe { host.device.queue_submit(host.queue, &[submit], self.fence) }?;
        // SAFETY: our fence, just submitted.
        unsafe { host.device.wait_for_fences(&[self.fence], true, u64::MAX) }?;
        // SAFETY: signalled, no pending submission uses it.
        unsafe { host.device.reset_fences(&[self.fence]) }?;
        // One texel, not the whole image: the host's CPU should not compete with the device.
        let mut first = [0u8; 4];
        // SAFETY: the mapping covers the buffer (≥ 4 bytes); coherent memory; the frame that
        // wrote it was waited for.
        unsafe { std::ptr::copy_nonoverlapping(self.readback.ptr, first.as_mut_ptr(), 4) };
        Ok(u32::from_ne_bytes(first))
    }

    pub fn destroy(self, host: &Host) {
        // SAFETY: every submission of the command buffer was waited for.
        unsafe { host.device.destroy_command_pool(self.pool, None) };
        // SAFETY: unused (waited for and reset).
        unsafe { host.device.destroy_fence(self.fence, None) };
        // SAFETY: no pending work uses the image.
        unsafe { host.device.destroy_image(self.image, None) };
        // SAFETY: the image bound to it is destroyed.
        unsafe { host.device.free_memory(self.memory, None) };
        host.destroy_buffer(self.readback);
    }
}

/// The offscreen image's one mip level and layer.
const COLOR_RANGE: vk::ImageSubresourceRange = vk::ImageSubresourceRange {
    aspect_mask: vk::ImageAspectFlags::COLOR,
    base_mip_level: 0,
    level_count: 1,
    base_array_layer: 0,
    layer_count: 1,
};

/// Frame times of the host's loop, without and with a parameterization job on its queue.
pub struct FrameLoop {
    pub idle: Vec<Duration>,
    pub busy: Vec<Duration>,
    pub job_seconds: f64,
    pub progress: embed::JobProgress,
    pub uv: Vec<[f64; 2]>,
}

/// The frame loop: frames while a job (slices of `budget` device time, on the host's queue
/// between frames) parameterizes `mesh` — each frame polls the job once, then draws — then
/// as many frames alone (at least `idle_frames`), paced at `period` when given. The job's UVs
/// come back with the times.
pub fn frame_loop(
    host: &Host,
    mesh: &TriMesh,
    idle_frames: usize,
    budget: Duration,
    period: Option<Duration>,
) -> BoxResult<FrameLoop> {
    const FRAME_TEXELS: u32 = 1024;
    let frame = Frame::new(host, FRAME_TEXELS)?;
    let result = (|| -> BoxResult<FrameLoop> {
        let expected = frame.draw(host)?;
        // A renderer's cadence (vsync): sleep until the next frame is due.
        let mut next = Instant::now();
        let mut pace = || {
            if let Some(p) = period {
                next += p;
                let now = Instant::now();
                if next > now {
                    std::thread::sleep(next - now);
                } else {
                    next = now;
                }
            }
        };

        // SAFETY: the handles come from `host`, which outlives the engine (dropped at the end
        // of this closure); the device has `required_features()`; this thread submits to the
        // queue only between the job's `poll` calls, which are on this thread too.
        let ctx = unsafe { Context::from_host(host.host_desc()) }?;
        let engine = Engine::new(ctx)?;
        let opts = embed::JobOptions {
            queue: embed::JobQueue::BetweenFrames,
            slice_budget: budget,
        };
        let t0 = Instant::now();
        let mut job = engine.start_parameterize(
            &mesh.positions,
            &mesh.faces,
            &EmbedOptions::default(),
            &opts,
        )?;
        let mut busy = Vec::new();
        loop {
            pace();
            let t = Instant::now();
            let done = job.poll();
            if frame.draw(host)? != expected {
                return Err("the frame's read-back changed while the job ran".into());
            }
            busy.push(t.elapsed());
            if done {
                break;
            }
        }
        let job_seconds = t0.elapsed().as_secs_f64();
        let progress = job.progress();
        let uv = job.finish()?;
        drop(engine);
        // As many frames alone as ran with the job (at least `idle_frames`): the maximum of
        // n samples grows with n, so the two maxima are compared over equal counts.
        let n_idle = idle_frames.max(busy.len());
        let mut idle = Vec::with_capacity(n_idle);
        for _ in 0..n_idle {
            pace();
            let t = Instant::now();
            frame.draw(host)?;
            idle.push(t.elapsed());
        }
        Ok(FrameLoop {
            idle,
            busy,
            job_seconds,
            progress,
            uv,
        })
    })();
    frame.destroy(host);
    result
}

/// `(median, 99th percentile, max)` of frame times.
pub fn distribution(times: &[Duration]) -> (Duration, Duration, Duration) {
    let mut t = times.to_vec();
    t.sort();
    if t.is_empty() {
        return (Duration::ZERO, Duration::ZERO, Duration::ZERO);
    }
    let at = |q: f64| t[((t.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.99), t[t.len() - 1])
}

fn env_on(name: &str) -> bool {
    std::env::var(name).is_ok_and(|v| v == "1")
}

/// The repository's test mesh.
pub fn default_mesh() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/camel_open.obj")
}

#[allow(dead_code)]
fn main() -> BoxResult<()> {
    let path = std::env::args_os()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(default_mesh);
    let validation = env_on("FOLDFREE_EXAMPLE_VALIDATION");
    let sync = validation && env_on(foldfree::gpu::SYNC_VALIDATION_ENV);
    let mesh = foldfree::mesh::read_obj(&path)?;
    let host = Host::new(validation, sync)?;
    let out = run(&host, &mesh)?;
    let n = out.uv.len();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &out.uv {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let max_diff = |got: &[[f32; 2]]| {
        out.uv
            .iter()
            .zip(got)
            .map(|(a, b)| {
                (a[0] - f64::from(b[0]))
                    .abs()
                    .max((a[1] - f64::from(b[1])).abs())
            })
            .fold(0.0f64, f64::max)
    };
    println!(
        "host: {} faces, {n} vertices, {}",
        mesh.faces.len(),
        path.display()
    );
    println!("parameterize: {:.2} s", out.seconds);
    println!(
        "uv bbox: [{:.4}, {:.4}] x [{:.4}, {:.4}]",
        lo[0], hi[0], lo[1], hi[1]
    );
    println!(
        "host buffer vs engine, max |diff|: submitted {:.3e}, recorded {:.3e}",
        max_diff(&out.uv_submitted),
        max_diff(&out.uv_recorded)
    );
    println!("positions intact: {}", out.positions_intact);
    let messages = host.take_messages();
    println!(
        "validation (parameterize + UV writes): {}",
        if !validation {
            "off".to_string()
        } else {
            format!("{} message(s)", messages.len())
        }
    );
    for m in &messages {
        println!("  {m}");
    }
    let budget_ms: f64 = std::env::var("FOLDFREE_SLICE_MS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(4.0);
    let budget = Duration::from_secs_f64(budget_ms / 1000.0);
    // Frames per second of the host's loop (FOLDFREE_FRAME_HZ; 0: back to back, no pacing).
    let hz: f64 = std::env::var("FOLDFREE_FRAME_HZ")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.0);
    let period = (hz > 0.0).then(|| Duration::from_secs_f64(1.0 / hz));
    let frames = frame_loop(&host, &mesh, 200, budget, period)?;
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let (m0, p0, x0) = distribution(&frames.idle);
    let (m1, p1, x1) = distribution(&frames.busy);
    println!(
        "frame loop (clear + read back 1024² RGBA8 per frame, {hz} Hz), slice budget {budget_ms} ms:"
    );
    println!(
        "  without a job: {} frames, median {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        frames.idle.len(),
        ms(m0),
        ms(p0),
        ms(x0)
    );
    println!(
        "  with the job:  {} frames, median {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        frames.busy.len(),
        ms(m1),
        ms(p1),
        ms(x1)
    );
    let p = &frames.progress;
    println!(
        "  job: {:.2} s wall, {} iterations in {} slices, device {:.0} ms, longest slice {:.2} ms",
        frames.job_seconds,
        p.iterations,
        p.slices,
        ms(p.device_time),
        ms(p.longest_slice)
    );
    let same = frames.uv.len() == out.uv.len()
        && frames
            .uv
            .iter()
            .zip(&out.uv)
            .all(|(a, b)| a[0].to_bits() == b[0].to_bits() && a[1].to_bits() == b[1].to_bits());
    println!("  job UVs identical to the blocking call's: {same}");
    let bound = x0 * 2 + budget;
    println!(
        "  longest frame with the job {:.2} ms vs bound 2 × {:.2} + {budget_ms} = {:.2} ms: {}",
        ms(x1),
        ms(x0),
        ms(bound),
        if x1 <= bound { "within" } else { "OVER" }
    );
    let messages = [messages, host.take_messages()].concat();
    drop(host);
    println!("host objects destroyed by the host");
    if !messages.is_empty() || !out.positions_intact || !same {
        return Err("validation messages, clobbered positions or a job result that differs".into());
    }
    Ok(())
}
