//! Offscreen graphics: the checkerboard texture-mapping view of a UV-mapped mesh.
//!
//! One classic render pass (colour `R8G8B8A8_UNORM` + depth `D32_SFLOAT`), one graphics
//! pipeline (`glsl/render/checker.{vert,frag}`), one draw, a copy of the colour image into a
//! host-visible buffer and a fence wait. Everything is created per call and destroyed on drop;
//! the camera is orthographic and fits the mesh's bounding box.

use std::time::Duration;

use ash::vk;
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};

use super::buffer::{Buffer, BufferUsage, MemoryLocation};
use super::context::Context;
use super::error::{map_allocation, map_result, GpuError, GpuResult};
use super::shaders;

const COLOR_FORMAT: vk::Format = vk::Format::R8G8B8A8_UNORM;
const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;
/// How long the draw may take before it is reported as a timeout.
const RENDER_TIMEOUT: Duration = Duration::from_secs(120);
/// Background colour (RGBA, linear 0..1): light grey.
pub const BACKGROUND: [f32; 4] = [0.82, 0.84, 0.86, 1.0];

/// What [`render_checker`] draws.
#[derive(Clone, Copy, Debug)]
pub struct RenderDesc {
    /// Picture size in pixels (each 1..=8192).
    pub width: u32,
    pub height: u32,
    /// Checker squares per unit of UV along each axis (so `N×N` over the unit square).
    pub checker: u32,
    /// Direction from the mesh towards the camera (world space; need not be unit length).
    pub view_dir: [f32; 3],
    pub shade: Shade,
}

/// What colours the surface.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Shade {
    /// A checkerboard through the UVs: the texture-mapping check.
    #[default]
    Checker,
    /// Each face coloured by its flat normal: planar regions (an `approx` output, a tet map's
    /// boundary) show as uniform patches; UVs are ignored.
    Normals,
}

impl Default for RenderDesc {
    fn default() -> Self {
        Self {
            width: 1024,
            height: 1024,
            checker: 16,
            view_dir: [0.0, 0.0, 1.0],
            shade: Shade::Checker,
        }
    }
}

/// The push-constant block of both stages (std430-compatible: 96 bytes).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Push {
    view_proj: [f32; 16],
    light_dir: [f32; 4],
    checker: f32,
    /// 0: checkerboard through the UVs; 1: flat normal colours (no UVs needed).
    shade: u32,
    _pad: [f32; 2],
}

/// One interleaved vertex: position then UV.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Vertex {
    position: [f32; 3],
    uv: [f32; 2],
}

/// An orthographic view-projection (Vulkan clip space: y down, depth 0..1) that looks along
/// `-view_dir` at the bounding box of `positions` and fits it, with a 5% margin, into a
/// `width × height` picture.
fn camera(positions: &[[f32; 3]], view_dir: [f32; 3], width: u32, height: u32) -> Mat4 {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for p in positions {
        let p = Vec3::from(*p);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let center = (lo + hi) * 0.5;
    let radius = ((hi - lo).length() * 0.5).max(1e-6);
    let dir = Vec3::from(view_dir).try_normalize().unwrap_or(Vec3::Z);
    let up = if dir.cross(Vec3::Y).length() > 1e-3 {
        Vec3::Y
    } else {
        Vec3::Z
    };
    // View basis: right, up, and forward (towards the mesh, away from the camera).
    let forward = -dir;
    let right = forward.cross(up).normalize();
    let up = right.cross(forward);
    let (mut x0, mut x1, mut y0, mut y1) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
    let (mut d0, mut d1) = (f32::MAX, f32::MIN);
    for p in positions {
        let q = Vec3::from(*p) - center;
        let (x, y, d) = (q.dot(right), q.dot(up), q.dot(forward));
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
        d0 = d0.min(d);
        d1 = d1.max(d);
    }
    let (cx, cy) = ((x0 + x1) * 0.5, (y0 + y1) * 0.5);
    let mut half_w = ((x1 - x0) * 0.5 * 1.05).max(1e-6 * radius);
    let mut half_h = ((y1 - y0) * 0.5 * 1.05).max(1e-6 * radius);
    let aspect = width as f32 / height as f32;
    if half_w / half_h < aspect {
        half_w = half_h * aspect;
    } else {
        half_h = half_w / aspect;
    }
    let margin = 0.01 * radius;
    let (near, far) = (d0 - margin, d1 + margin);
    // clip = ((x - cx) / half_w, -(y - cy) / half_h, (d - near) / (far - near)) with
    // x, y, d relative to `center`; Vulkan's framebuffer y points down, so world "up" is -y.
    let row = |axis: Vec3, offset: f32, scale: f32| {
        glam::Vec4::new(
            axis.x * scale,
            axis.y * scale,
            axis.z * scale,
            (-axis.dot(center) - offset) * scale,
        )
    };
    Mat4::from_rows(
        row(right, cx, 1.0 / half_w),
        row(up, cy, -1.0 / half_h),
        row(forward, near, 1.0 / (far - near)),
        glam::Vec4::W,
    )
}

/// An image with its memory and one view, destroyed on drop.
struct Image {
    ctx: Context,
    raw: vk::Image,
    view: vk::ImageView,
    allocation: Option<Allocation>,
    name: String,
}

impl Drop for Image {
    fn drop(&mut self) {
        // SAFETY: the view belongs to this device and no pending work uses it (the owner waits
        // for its fence before dropping images); destroying a null handle is a no-op.
        unsafe { self.ctx.device().destroy_image_view(self.view, None) };
        // SAFETY: as above, for the image.
        unsafe { self.ctx.device().destroy_image(self.raw, None) };
        if let Some(allocation) = self.allocation.take() {
            let name = &self.name;
            let result = self
                .ctx
                .with_allocator(|a| a.free(allocation).map_err(|e| map_allocation(name, e)));
            if let Err(e) = result {
                self.ctx
                    .message_log()
                    .note(format!("[foldfree] freeing image {name}: {e}"));
            }
        }
    }
}

impl Image {
    /// A device-local 2-D attachment image of `format` with a view of `aspect`.
    fn new(
        ctx: &Context,
        name: &str,
        format: vk::Format,
        usage: vk::ImageUsageFlags,
        aspect: vk::ImageAspectFlags,
        extent: vk::Extent2D,
    ) -> GpuResult<Image> {
        let device = ctx.device();
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(format)
            .extent(vk::Extent3D {
                width: extent.width,
                height: extent.height,
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(1)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: valid create info; the handle is owned by `image` right below.
        let raw = unsafe { device.create_image(&info, None) }
            .map_err(|r| map_result("vkCreateImage", r))?;
        let mut image = Image {
            ctx: ctx.clone(),
            raw,
            view: vk::ImageView::null(),
            allocation: None,
            name: name.to_string(),
        };
        // SAFETY: `raw` is a live image of this device.
        let requirements = unsafe { device.get_image_memory_requirements(raw) };
        let allocation = ctx.with_allocator(|a| {
            a.allocate(&AllocationCreateDesc {
                name,
                requirements,
                location: gpu_allocator::MemoryLocation::GpuOnly,
                linear: false,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            })
            .map_err(|e| map_allocation(name, e))
        })?;
        // SAFETY: the memory handle is only used to bind this image, and the allocation is
        // freed only after the image is destroyed (`Drop for Image`).
        let memory = unsafe { allocation.memory() };
        let offset = allocation.offset();
        image.allocation = Some(allocation);
        // SAFETY: the allocation satisfies `requirements` and the image has no memory yet.
        unsafe { device.bind_image_memory(raw, memory, offset) }
            .map_err(|r| map_result("vkBindImageMemory", r))?;
        ctx.set_name(raw, name);
        let view_info = vk::ImageViewCreateInfo::default()
            .image(raw)
            .view_type(vk::ImageViewType::TYPE_2D)
            .format(format)
            .subresource_range(subresource_range(aspect));
        // SAFETY: the image is live and bound; the view is destroyed before it (`Drop`).
        image.view = unsafe { device.create_image_view(&view_info, None) }
            .map_err(|r| map_result("vkCreateImageView", r))?;
        ctx.set_name(image.view, &format!("{name}.view"));
        Ok(image)
    }
}

fn subresource_range(aspect: vk::ImageAspectFlags) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: aspect,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: 0,
        layer_count: 1,
    }
}

/// The non-memory objects of one render, destroyed on drop in reverse creation order (after
/// waiting for the fence if work is still in flight). Null handles are skipped by Vulkan.
struct Objects {
    ctx: Context,
    render_pass: vk::RenderPass,
    framebuffer: vk::Framebuffer,
    vert: vk::ShaderModule,
    frag: vk::ShaderModule,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    /// Submitted and not yet seen complete.
    pending: bool,
}

impl Drop for Objects {
    fn drop(&mut self) {
        let device = self.ctx.device();
        if self.pending {
            // SAFETY: the fence is ours; waiting forever is the only way to know the command
            // buffer is no longer in use (on device loss the wait returns at once).
            let _ = unsafe { device.wait_for_fences(&[self.fence], true, u64::MAX) };
        }
        // SAFETY: no pending work (waited above); the fence is ours.
        unsafe { device.destroy_fence(self.fence, None) };
        // SAFETY: as above; destroying the pool frees its command buffer.
        unsafe { device.destroy_command_pool(self.pool, None) };
        // SAFETY: no command buffer using the pipeline is pending any more.
        unsafe { device.destroy_pipeline(self.pipeline, None) };
        // SAFETY: the pipeline built from the layout is destroyed.
        unsafe { device.destroy_pipeline_layout(self.layout, None) };
        // SAFETY: modules are only needed during pipeline creation.
        unsafe { device.destroy_shader_module(self.frag, None) };
        // SAFETY: as above.
        unsafe { device.destroy_shader_module(self.vert, None) };
        // SAFETY: no pending work uses the framebuffer.
        unsafe { device.destroy_framebuffer(self.framebuffer, None) };
        // SAFETY: the framebuffer and pipeline that reference the render pass are destroyed.
        unsafe { device.destroy_render_pass(self.render_pass, None) };
    }
}

/// Renders the mesh (`indices`: triangles into `positions`/`uvs`, which have one entry per
/// vertex) textured with a `checker × checker` checkerboard per unit UV square, two-sided
/// Lambert-shaded, on a light-grey background. Returns `width × height` RGBA8 pixels, rows top
/// to bottom.
///
/// The context's queue must support graphics (lavapipe's and most GPUs' single universal queue
/// does); otherwise this returns [`GpuError::Unsupported`].
pub fn render_checker(
    ctx: &Context,
    positions: &[[f32; 3]],
    uvs: &[[f32; 2]],
    indices: &[u32],
    desc: &RenderDesc,
) -> GpuResult<Vec<u8>> {
    if desc.width == 0 || desc.height == 0 || desc.width > 8192 || desc.height > 8192 {
        return Err(GpuError::Invalid(format!(
            "render: size {}x{} (each side must be 1..=8192)",
            desc.width, desc.height
        )));
    }
    if positions.len() != uvs.len() {
        return Err(GpuError::Invalid(format!(
            "render: {} positions but {} UVs",
            positions.len(),
            uvs.len()
        )));
    }
    if indices.is_empty() || indices.len() % 3 != 0 {
        return Err(GpuError::Invalid(format!(
            "render: {} indices (need a positive multiple of 3)",
            indices.len()
        )));
    }
    if let Some(&bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
        return Err(GpuError::Invalid(format!(
            "render: index {bad} out of range ({} vertices)",
            positions.len()
        )));
    }
    check_graphics_queue(ctx)?;

    let device = ctx.device();
    let extent = vk::Extent2D {
        width: desc.width,
        height: desc.height,
    };

    let vertices: Vec<Vertex> = positions
        .iter()
        .zip(uvs)
        .map(|(&position, &uv)| Vertex { position, uv })
        .collect();
    let vertex_buffer = Buffer::new(
        ctx,
        "render.vertices",
        std::mem::size_of_val(vertices.as_slice()) as u64,
        BufferUsage::Vertex,
        MemoryLocation::CpuToGpu,
    )?;
    vertex_buffer.write(&vertices)?;
    let index_buffer = Buffer::new(
        ctx,
        "render.indices",
        std::mem::size_of_val(indices) as u64,
        BufferUsage::Index,
        MemoryLocation::CpuToGpu,
    )?;
    index_buffer.write(indices)?;
    let pixel_bytes = u64::from(desc.width) * u64::from(desc.height) * 4;
    let readback = Buffer::new(
        ctx,
        "render.readback",
        pixel_bytes,
        BufferUsage::Staging,
        MemoryLocation::GpuToCpu,
    )?;

    let color = Image::new(
        ctx,
        "render.color",
        COLOR_FORMAT,
        vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
        vk::ImageAspectFlags::COLOR,
        extent,
    )?;
    let depth = Image::new(
        ctx,
        "render.depth",
        DEPTH_FORMAT,
        vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
        vk::ImageAspectFlags::DEPTH,
        extent,
    )?;

    // Declared after the buffers and images, so it is dropped (and waits) before them.
    let mut obj = Objects {
        ctx: ctx.clone(),
        render_pass: vk::RenderPass::null(),
        framebuffer: vk::Framebuffer::null(),
        vert: vk::ShaderModule::null(),
        frag: vk::ShaderModule::null(),
        layout: vk::PipelineLayout::null(),
        pipeline: vk::Pipeline::null(),
        pool: vk::CommandPool::null(),
        cmd: vk::CommandBuffer::null(),
        fence: vk::Fence::null(),
        pending: false,
    };

    // Render pass: clear both attachments; colour ends ready for the copy.
    let attachments = [
        vk::AttachmentDescription::default()
            .format(COLOR_FORMAT)
            .samples(vk::SampleCountFlags::TYPE_1)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
            .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
            .initial_layout(vk::ImageLayout::UNDEFINED)
            .final_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL),
        vk::AttachmentDescription::default()
            .format(DEPTH_FORMAT)
            .samples(vk::SampleCountFlags::TYPE_1)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::DONT_CARE)
            .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
            .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
            .initial_layout(vk::ImageLayout::UNDEFINED)
            .final_layout(vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL),
    ];
    let color_refs = [vk::AttachmentReference {
        attachment: 0,
        layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
    }];
    let depth_ref = vk::AttachmentReference {
        attachment: 1,
        layout: vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
    };
    let subpasses = [vk::SubpassDescription::default()
        .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
        .color_attachments(&color_refs)
        .depth_stencil_attachment(&depth_ref)];
    let attachment_stages = vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT
        | vk::PipelineStageFlags::EARLY_FRAGMENT_TESTS
        | vk::PipelineStageFlags::LATE_FRAGMENT_TESTS;
    let dependencies = [
        // Layout transitions and clears wait for nothing earlier but order the attachments.
        vk::SubpassDependency::default()
            .src_subpass(vk::SUBPASS_EXTERNAL)
            .dst_subpass(0)
            .src_stage_mask(attachment_stages)
            .dst_stage_mask(attachment_stages)
            .src_access_mask(vk::AccessFlags::empty())
            .dst_access_mask(
                vk::AccessFlags::COLOR_ATTACHMENT_WRITE
                    | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE
                    | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_READ,
            ),
        // The colour writes (and the final layout transition) before the copy reads the image.
        vk::SubpassDependency::default()
            .src_subpass(0)
            .dst_subpass(vk::SUBPASS_EXTERNAL)
            .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
            .dst_stage_mask(vk::PipelineStageFlags::TRANSFER)
            .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
            .dst_access_mask(vk::AccessFlags::TRANSFER_READ),
    ];
    let rp_info = vk::RenderPassCreateInfo::default()
        .attachments(&attachments)
        .subpasses(&subpasses)
        .dependencies(&dependencies);
    // SAFETY: valid create info whose arrays live across the call; destroyed by `obj`.
    obj.render_pass = unsafe { device.create_render_pass(&rp_info, None) }
        .map_err(|r| map_result("vkCreateRenderPass", r))?;
    ctx.set_name(obj.render_pass, "render.pass");

    let views = [color.view, depth.view];
    let fb_info = vk::FramebufferCreateInfo::default()
        .render_pass(obj.render_pass)
        .attachments(&views)
        .width(desc.width)
        .height(desc.height)
        .layers(1);
    // SAFETY: the render pass and both views are live and match the pass's attachments.
    obj.framebuffer = unsafe { device.create_framebuffer(&fb_info, None) }
        .map_err(|r| map_result("vkCreateFramebuffer", r))?;
    ctx.set_name(obj.framebuffer, "render.framebuffer");

    let vert_words = shaders::words(shaders::RENDER_CHECKER_VERT)?;
    let frag_words = shaders::words(shaders::RENDER_CHECKER_FRAG)?;
    let vert_info = vk::ShaderModuleCreateInfo::default().code(&vert_words);
    // SAFETY: the SPIR-V words live across the call; the driver validates them.
    obj.vert = unsafe { device.create_shader_module(&vert_info, None) }
        .map_err(|r| map_result("vkCreateShaderModule", r))?;
    let frag_info = vk::ShaderModuleCreateInfo::default().code(&frag_words);
    // SAFETY: as above.
    obj.frag = unsafe { device.create_shader_module(&frag_info, None) }
        .map_err(|r| map_result("vkCreateShaderModule", r))?;

    let push_stages = vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT;
    let push_ranges = [vk::PushConstantRange::default()
        .stage_flags(push_stages)
        .offset(0)
        .size(std::mem::size_of::<Push>() as u32)];
    let layout_info = vk::PipelineLayoutCreateInfo::default().push_constant_ranges(&push_ranges);
    // SAFETY: valid create info living across the call.
    obj.layout = unsafe { device.create_pipeline_layout(&layout_info, None) }
        .map_err(|r| map_result("vkCreatePipelineLayout", r))?;
    ctx.set_name(obj.layout, "render.layout");

    let stages = [
        vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::VERTEX)
            .module(obj.vert)
            .name(c"main"),
        vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::FRAGMENT)
            .module(obj.frag)
            .name(c"main"),
    ];
    let bindings = [vk::VertexInputBindingDescription {
        binding: 0,
        stride: std::mem::size_of::<Vertex>() as u32,
        input_rate: vk::VertexInputRate::VERTEX,
    }];
    let attributes = [
        vk::VertexInputAttributeDescription {
            location: 0,
            binding: 0,
            format: vk::Format::R32G32B32_SFLOAT,
            offset: 0,
        },
        vk::VertexInputAttributeDescription {
            location: 1,
            binding: 0,
            format: vk::Format::R32G32_SFLOAT,
            offset: 12,
        },
    ];
    let vertex_input = vk::PipelineVertexInputStateCreateInfo::default()
        .vertex_binding_descriptions(&bindings)
        .vertex_attribute_descriptions(&attributes);
    let input_assembly = vk::PipelineInputAssemblyStateCreateInfo::default()
        .topology(vk::PrimitiveTopology::TRIANGLE_LIST);
    let viewports = [vk::Viewport {
        x: 0.0,
        y: 0.0,
        width: desc.width as f32,
        height: desc.height as f32,
        min_depth: 0.0,
        max_depth: 1.0,
    }];
    let scissors = [vk::Rect2D {
        offset: vk::Offset2D { x: 0, y: 0 },
        extent,
    }];
    let viewport_state = vk::PipelineViewportStateCreateInfo::default()
        .viewports(&viewports)
        .scissors(&scissors);
    let raster = vk::PipelineRasterizationStateCreateInfo::default()
        .polygon_mode(vk::PolygonMode::FILL)
        .cull_mode(vk::CullModeFlags::NONE)
        .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
        .line_width(1.0);
    let multisample = vk::PipelineMultisampleStateCreateInfo::default()
        .rasterization_samples(vk::SampleCountFlags::TYPE_1);
    let depth_state = vk::PipelineDepthStencilStateCreateInfo::default()
        .depth_test_enable(true)
        .depth_write_enable(true)
        .depth_compare_op(vk::CompareOp::LESS);
    let blend_attachments = [vk::PipelineColorBlendAttachmentState::default()
        .blend_enable(false)
        .color_write_mask(vk::ColorComponentFlags::RGBA)];
    let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
    let pipeline_info = [vk::GraphicsPipelineCreateInfo::default()
        .stages(&stages)
        .vertex_input_state(&vertex_input)
        .input_assembly_state(&input_assembly)
        .viewport_state(&viewport_state)
        .rasterization_state(&raster)
        .multisample_state(&multisample)
        .depth_stencil_state(&depth_state)
        .color_blend_state(&blend)
        .layout(obj.layout)
        .render_pass(obj.render_pass)
        .subpass(0)];
    // SAFETY: modules, layout and render pass are live; every state struct lives across the
    // call.
    let created = unsafe {
        device.create_graphics_pipelines(vk::PipelineCache::null(), &pipeline_info, None)
    };
    obj.pipeline = match created {
        Ok(pipelines) => pipelines.first().copied().unwrap_or_default(),
        Err((pipelines, r)) => {
            for p in pipelines {
                // SAFETY: a pipeline handed back on failure is null or ours to destroy.
                unsafe { device.destroy_pipeline(p, None) };
            }
            return Err(map_result("vkCreateGraphicsPipelines", r));
        }
    };
    ctx.set_name(obj.pipeline, "render.checker");

    let pool_info = vk::CommandPoolCreateInfo::default()
        .flags(vk::CommandPoolCreateFlags::TRANSIENT)
        .queue_family_index(ctx.queue_family_index());
    // SAFETY: valid create info; destroyed by `obj`.
    obj.pool = unsafe { device.create_command_pool(&pool_info, None) }
        .map_err(|r| map_result("vkCreateCommandPool", r))?;
    let alloc_info = vk::CommandBufferAllocateInfo::default()
        .command_pool(obj.pool)
        .level(vk::CommandBufferLevel::PRIMARY)
        .command_buffer_count(1);
    // SAFETY: the pool is live; the buffer is freed with it.
    let buffers = unsafe { device.allocate_command_buffers(&alloc_info) }
        .map_err(|r| map_result("vkAllocateCommandBuffers", r))?;
    obj.cmd = buffers
        .first()
        .copied()
        .ok_or_else(|| GpuError::Invalid("vkAllocateCommandBuffers returned no buffer".into()))?;
    ctx.set_name(obj.cmd, "render.commands");
    // SAFETY: valid create info; destroyed by `obj`.
    obj.fence = unsafe { device.create_fence(&vk::FenceCreateInfo::default(), None) }
        .map_err(|r| map_result("vkCreateFence", r))?;
    ctx.set_name(obj.fence, "render.fence");

    let view_proj = camera(positions, desc.view_dir, desc.width, desc.height);
    let light = Vec3::from(desc.view_dir)
        .try_normalize()
        .unwrap_or(Vec3::Z)
        .lerp(Vec3::new(0.4, 0.6, 0.7).normalize(), 0.35)
        .normalize();
    let push = Push {
        view_proj: view_proj.to_cols_array(),
        light_dir: [light.x, light.y, light.z, 0.0],
        checker: desc.checker.max(1) as f32,
        shade: match desc.shade {
            Shade::Checker => 0,
            Shade::Normals => 1,
        },
        _pad: [0.0; 2],
    };

    let cmd = obj.cmd;
    let begin_info =
        vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
    // SAFETY: the command buffer is freshly allocated and not in use.
    unsafe { device.begin_command_buffer(cmd, &begin_info) }
        .map_err(|r| map_result("vkBeginCommandBuffer", r))?;
    let clear = [
        vk::ClearValue {
            color: vk::ClearColorValue {
                float32: BACKGROUND,
            },
        },
        vk::ClearValue {
            depth_stencil: vk::ClearDepthStencilValue {
                depth: 1.0,
                stencil: 0,
            },
        },
    ];
    let rp_begin = vk::RenderPassBeginInfo::default()
        .render_pass(obj.render_pass)
        .framebuffer(obj.framebuffer)
        .render_area(scissors[0])
        .clear_values(&clear);
    // SAFETY: recording; pass and framebuffer are live and compatible.
    unsafe { device.cmd_begin_render_pass(cmd, &rp_begin, vk::SubpassContents::INLINE) };
    // SAFETY: recording inside a render pass compatible with the pipeline.
    unsafe { device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, obj.pipeline) };
    // SAFETY: the layout declares this range for both stages; `push` is 96 bytes.
    unsafe {
        device.cmd_push_constants(cmd, obj.layout, push_stages, 0, bytemuck::bytes_of(&push))
    };
    // SAFETY: the vertex buffer is live (kept until after the fence wait) with vertex usage.
    unsafe { device.cmd_bind_vertex_buffers(cmd, 0, &[vertex_buffer.raw()], &[0]) };
    // SAFETY: the index buffer is live with index usage; indices are u32.
    unsafe { device.cmd_bind_index_buffer(cmd, index_buffer.raw(), 0, vk::IndexType::UINT32) };
    // SAFETY: every index was checked to be in range of the bound vertex buffer.
    unsafe { device.cmd_draw_indexed(cmd, indices.len() as u32, 1, 0, 0, 0) };
    // SAFETY: recording inside the render pass begun above.
    unsafe { device.cmd_end_render_pass(cmd) };
    let region = [vk::BufferImageCopy {
        buffer_offset: 0,
        buffer_row_length: 0,
        buffer_image_height: 0,
        image_subresource: vk::ImageSubresourceLayers {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            mip_level: 0,
            base_array_layer: 0,
            layer_count: 1,
        },
        image_offset: vk::Offset3D { x: 0, y: 0, z: 0 },
        image_extent: vk::Extent3D {
            width: desc.width,
            height: desc.height,
            depth: 1,
        },
    }];
    // SAFETY: the image is in TRANSFER_SRC_OPTIMAL (the pass's final layout, ordered by its
    // outgoing dependency) and the buffer holds exactly width*height*4 bytes.
    unsafe {
        device.cmd_copy_image_to_buffer(
            cmd,
            color.raw,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            readback.raw(),
            &region,
        )
    };
    let to_host = [vk::MemoryBarrier2::default()
        .src_stage_mask(vk::PipelineStageFlags2::COPY)
        .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
        .dst_stage_mask(vk::PipelineStageFlags2::HOST)
        .dst_access_mask(vk::AccessFlags2::HOST_READ)];
    let dep = vk::DependencyInfo::default().memory_barriers(&to_host);
    // SAFETY: recording; synchronization2 is enabled on every context.
    unsafe { ctx.sync2().cmd_pipeline_barrier2(cmd, &dep) };
    // SAFETY: the command buffer is recording.
    unsafe { device.end_command_buffer(cmd) }.map_err(|r| map_result("vkEndCommandBuffer", r))?;

    let cmds = [cmd];
    let submit = vk::SubmitInfo::default().command_buffers(&cmds);
    ctx.submit(&submit, obj.fence)?;
    obj.pending = true;
    ctx.wait_fence(obj.fence, RENDER_TIMEOUT, "render.checker")?;
    obj.pending = false;
    drop(obj);
    let pixels = readback.read::<u8>()?;
    Ok(pixels)
}

/// Refuses a context whose queue family cannot run graphics.
fn check_graphics_queue(ctx: &Context) -> GpuResult<()> {
    // SAFETY: the physical device belongs to this instance, which lives as long as `ctx`.
    let families = unsafe {
        ctx.raw_instance()
            .get_physical_device_queue_family_properties(ctx.physical_device())
    };
    let graphics = families
        .get(ctx.queue_family_index() as usize)
        .is_some_and(|f| f.queue_flags.contains(vk::QueueFlags::GRAPHICS));
    if graphics {
        Ok(())
    } else {
        Err(GpuError::Unsupported(format!(
            "render: the queue family of {} has no graphics support",
            ctx.device_name()
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_fits_the_bbox_into_clip_space() {
        let pts = [[0.0, 0.0, 0.0], [2.0, 1.0, 0.5], [1.0, 0.5, -0.5]];
        let m = camera(&pts, [0.0, 0.0, 1.0], 200, 100);
        for p in pts {
            let c = m.project_point3(Vec3::from(p));
            assert!(c.x.abs() <= 1.0 && c.y.abs() <= 1.0, "{c}");
            assert!((0.0..=1.0).contains(&c.z), "{c}");
        }
        // +y in the world is up in the picture (negative clip y in Vulkan).
        let top = m.project_point3(Vec3::new(1.0, 1.0, 0.0));
        let bottom = m.project_point3(Vec3::new(1.0, 0.0, 0.0));
        assert!(top.y < bottom.y);
    }

    #[test]
    fn push_block_is_96_bytes() {
        assert_eq!(std::mem::size_of::<Push>(), 96);
        assert_eq!(std::mem::size_of::<Vertex>(), 20);
    }
}
