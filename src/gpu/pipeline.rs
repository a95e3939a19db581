//! Compute pipelines and the descriptor sets that bind buffers to them.
//!
//! Every kernel of this crate has the same interface shape: storage buffers at set 0, bindings
//! `0..N`, plus one push-constant block. So a pipeline is described by its SPIR-V, `N` and the
//! push-constant size, and a descriptor set by the list of buffers in binding order.

use std::sync::Arc;

use ash::vk;

use super::buffer::{Buffer, BufferUsage};
use super::context::Context;
use super::error::{map_result, GpuError, GpuResult};

/// Threads per workgroup along x that our kernels declare (`layout(local_size_x = 64)`).
pub const DEFAULT_WORKGROUP_SIZE: u32 = 64;

/// Parameters of [`ComputePipeline::new`].
#[derive(Clone, Copy, Debug)]
pub struct ComputePipelineDesc<'a> {
    /// e.g. `"admm.face_newton"`.
    pub name: &'a str,
    /// The kernel (see [`super::shaders::words`]); entry point `main`.
    pub spirv: &'a [u32],
    /// Number of storage buffers, bound at set 0, bindings `0..bindings`.
    pub bindings: u32,
    /// Size of the push-constant block in bytes (a multiple of 4; 0 for none).
    pub push_constant_bytes: u32,
    /// `local_size_x` of the kernel; [`super::Recorder::dispatch_1d`] sizes its grid with it.
    pub workgroup_size: u32,
}

impl<'a> ComputePipelineDesc<'a> {
    /// A kernel with `bindings` storage buffers, `push_constant_bytes` of push constants and
    /// the default workgroup size of 64.
    pub fn new(name: &'a str, spirv: &'a [u32], bindings: u32, push_constant_bytes: u32) -> Self {
        Self {
            name,
            spirv,
            bindings,
            push_constant_bytes,
            workgroup_size: DEFAULT_WORKGROUP_SIZE,
        }
    }
}

/// A compute pipeline with its shader module and layouts. Cloning shares it (an `Arc`).
#[derive(Clone)]
pub struct ComputePipeline {
    inner: Arc<PipelineInner>,
}

struct PipelineInner {
    ctx: Context,
    raw: vk::Pipeline,
    layout: vk::PipelineLayout,
    set_layout: vk::DescriptorSetLayout,
    module: vk::ShaderModule,
    bindings: u32,
    push_constant_bytes: u32,
    workgroup_size: u32,
    name: String,
}

impl Drop for PipelineInner {
    fn drop(&mut self) {
        let device = self.ctx.device();
        // SAFETY: no command buffer that uses the pipeline is pending (recorders hold clones
        // until their work is done). Null handles (failed construction) are no-ops.
        unsafe { device.destroy_pipeline(self.raw, None) };
        // SAFETY: as above; the pipeline that used the layout is destroyed.
        unsafe { device.destroy_pipeline_layout(self.layout, None) };
        // SAFETY: descriptor sets made for this layout hold a clone of the pipeline, so none is
        // alive.
        unsafe { device.destroy_descriptor_set_layout(self.set_layout, None) };
        // SAFETY: the module is only referenced by the (destroyed) pipeline.
        unsafe { device.destroy_shader_module(self.module, None) };
    }
}

impl std::fmt::Debug for ComputePipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ComputePipeline")
            .field("name", &self.inner.name)
            .field("bindings", &self.inner.bindings)
            .field("push_constant_bytes", &self.inner.push_constant_bytes)
            .finish()
    }
}

impl ComputePipeline {
    /// The pipeline of one of the crate's shaders (`shaders::NAME` bytes) with `bindings`
    /// storage buffers and a push-constant block of type `P`.
    pub fn from_shader<P>(
        ctx: &Context,
        name: &str,
        spv: &[u8],
        bindings: u32,
    ) -> GpuResult<ComputePipeline> {
        let words = super::shaders::words(spv)?;
        let push = u32::try_from(std::mem::size_of::<P>())
            .map_err(|_| GpuError::Invalid(format!("{name}: push constants too large")))?;
        ComputePipeline::new(ctx, &ComputePipelineDesc::new(name, &words, bindings, push))
    }

    /// Builds the pipeline. Takes under a millisecond on lavapipe for our kernels.
    pub fn new(ctx: &Context, desc: &ComputePipelineDesc<'_>) -> GpuResult<ComputePipeline> {
        let limits = ctx.limits();
        if desc.push_constant_bytes % 4 != 0
            || desc.push_constant_bytes > limits.max_push_constants_size
        {
            return Err(GpuError::Invalid(format!(
                "pipeline {}: {} push-constant bytes (must be a multiple of 4, at most {})",
                desc.name, desc.push_constant_bytes, limits.max_push_constants_size
            )));
        }
        if desc.workgroup_size == 0
            || desc.workgroup_size > limits.max_compute_work_group_invocations
        {
            return Err(GpuError::Invalid(format!(
                "pipeline {}: workgroup size {} (device allows 1..={})",
                desc.name, desc.workgroup_size, limits.max_compute_work_group_invocations
            )));
        }
        if desc.spirv.is_empty() {
            return Err(GpuError::Invalid(format!(
                "pipeline {}: empty SPIR-V",
                desc.name
            )));
        }
        let device = ctx.device();
        // Filled step by step; dropping it on an error destroys what exists so far.
        let mut inner = PipelineInner {
            ctx: ctx.clone(),
            raw: vk::Pipeline::null(),
            layout: vk::PipelineLayout::null(),
            set_layout: vk::DescriptorSetLayout::null(),
            module: vk::ShaderModule::null(),
            bindings: desc.bindings,
            push_constant_bytes: desc.push_constant_bytes,
            workgroup_size: desc.workgroup_size,
            name: desc.name.to_string(),
        };

        let module_info = vk::ShaderModuleCreateInfo::default().code(desc.spirv);
        // SAFETY: `spirv` is a word slice that lives across the call; the driver validates it.
        inner.module = unsafe { device.create_shader_module(&module_info, None) }
            .map_err(|r| map_result("vkCreateShaderModule", r))?;
        ctx.set_name(inner.module, &format!("{}.module", desc.name));

        let bindings: Vec<vk::DescriptorSetLayoutBinding> = (0..desc.bindings)
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let set_layout_info = vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings);
        // SAFETY: valid create info living across the call.
        inner.set_layout = unsafe { device.create_descriptor_set_layout(&set_layout_info, None) }
            .map_err(|r| map_result("vkCreateDescriptorSetLayout", r))?;
        ctx.set_name(inner.set_layout, &format!("{}.set_layout", desc.name));

        let set_layouts = [inner.set_layout];
        let push_ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .offset(0)
            .size(desc.push_constant_bytes)];
        let ranges: &[vk::PushConstantRange] = if desc.push_constant_bytes > 0 {
            &push_ranges
        } else {
            &[]
        };
        let layout_info = vk::PipelineLayoutCreateInfo::default()
            .set_layouts(&set_layouts)
            .push_constant_ranges(ranges);
        // SAFETY: valid create info; the set layout is live.
        inner.layout = unsafe { device.create_pipeline_layout(&layout_info, None) }
            .map_err(|r| map_result("vkCreatePipelineLayout", r))?;
        ctx.set_name(inner.layout, &format!("{}.layout", desc.name));

        let stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(inner.module)
            .name(c"main");
        let pipeline_info = [vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(inner.layout)];
        // SAFETY: module and layout are live; the create info lives across the call.
        let created = unsafe {
            device.create_compute_pipelines(vk::PipelineCache::null(), &pipeline_info, None)
        };
        inner.raw = match created {
            Ok(pipelines) => pipelines.first().copied().unwrap_or_default(),
            Err((pipelines, r)) => {
                for p in pipelines {
                    // SAFETY: a pipeline handed back on failure is null or ours to destroy.
                    unsafe { device.destroy_pipeline(p, None) };
                }
                return Err(map_result("vkCreateComputePipelines", r));
            }
        };
        ctx.set_name(inner.raw, desc.name);
        Ok(ComputePipeline {
            inner: Arc::new(inner),
        })
    }

    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// Number of storage-buffer bindings.
    pub fn bindings(&self) -> u32 {
        self.inner.bindings
    }

    pub fn push_constant_bytes(&self) -> u32 {
        self.inner.push_constant_bytes
    }

    pub fn workgroup_size(&self) -> u32 {
        self.inner.workgroup_size
    }

    pub(crate) fn raw(&self) -> vk::Pipeline {
        self.inner.raw
    }

    pub(crate) fn layout(&self) -> vk::PipelineLayout {
        self.inner.layout
    }

    pub(crate) fn context(&self) -> &Context {
        &self.inner.ctx
    }
}

/// Buffers bound to a pipeline's set 0, with its own one-set descriptor pool. Cloning shares it.
/// It keeps the buffers and the pipeline (its layout) alive.
#[derive(Clone)]
pub struct DescriptorSet {
    inner: Arc<SetInner>,
}

struct SetInner {
    ctx: Context,
    pool: vk::DescriptorPool,
    raw: vk::DescriptorSet,
    bindings: u32,
    name: String,
    _pipeline: ComputePipeline,
    _buffers: Vec<Buffer>,
}

impl Drop for SetInner {
    fn drop(&mut self) {
        // SAFETY: recorders hold clones of sets until their command buffers finish, so the set
        // is unused; destroying the pool frees the set. A null pool is a no-op.
        unsafe { self.ctx.device().destroy_descriptor_pool(self.pool, None) };
    }
}

impl std::fmt::Debug for DescriptorSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DescriptorSet")
            .field("name", &self.inner.name)
            .field("bindings", &self.inner.bindings)
            .finish()
    }
}

impl DescriptorSet {
    /// Binds `buffers[i]` to binding `i` of `pipeline`'s set 0. The set also works with any
    /// other pipeline with the same number of bindings (their layouts are compatible).
    pub fn new(
        pipeline: &ComputePipeline,
        name: &str,
        buffers: &[&Buffer],
    ) -> GpuResult<DescriptorSet> {
        let ctx = pipeline.context();
        if buffers.len() != pipeline.bindings() as usize {
            return Err(GpuError::Invalid(format!(
                "descriptor set {name}: {} buffers for pipeline {} with {} bindings",
                buffers.len(),
                pipeline.name(),
                pipeline.bindings()
            )));
        }
        for b in buffers {
            check_storage_buffer(ctx, name, b)?;
        }
        let infos: Vec<vk::DescriptorBufferInfo> = buffers
            .iter()
            .map(|b| {
                vk::DescriptorBufferInfo::default()
                    .buffer(b.raw())
                    .offset(0)
                    .range(vk::WHOLE_SIZE)
            })
            .collect();
        let (pool, raw) = allocate_storage_set(pipeline, name, &infos)?;
        let inner = SetInner {
            ctx: ctx.clone(),
            pool,
            raw,
            bindings: pipeline.bindings(),
            name: name.to_string(),
            _pipeline: pipeline.clone(),
            _buffers: buffers.iter().map(|b| (*b).clone()).collect(),
        };
        Ok(DescriptorSet {
            inner: Arc::new(inner),
        })
    }

    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// Number of bindings (buffers) in the set.
    pub fn bindings(&self) -> u32 {
        self.inner.bindings
    }

    pub(crate) fn raw(&self) -> vk::DescriptorSet {
        self.inner.raw
    }
}

/// Refuses a buffer that is not a storage buffer of `ctx` (binding it would be invalid usage).
pub(super) fn check_storage_buffer(ctx: &Context, set_name: &str, b: &Buffer) -> GpuResult<()> {
    if b.usage() != BufferUsage::Storage {
        return Err(GpuError::Invalid(format!(
            "descriptor set {set_name}: buffer {} is not a storage buffer",
            b.name()
        )));
    }
    if !Arc::ptr_eq(&b.context().shared, &ctx.shared) {
        return Err(GpuError::Invalid(format!(
            "descriptor set {set_name}: buffer {} belongs to another context",
            b.name()
        )));
    }
    Ok(())
}

/// A one-set descriptor pool and a set of `pipeline`'s set-0 layout whose storage binding `i`
/// is `infos[i]`: the one place descriptor sets are made ([`DescriptorSet`] and the interop set
/// for host buffers). The caller owns the pool; destroying it frees the set. The buffers must be
/// live and the ranges valid (the callers check).
pub(super) fn allocate_storage_set(
    pipeline: &ComputePipeline,
    name: &str,
    infos: &[vk::DescriptorBufferInfo],
) -> GpuResult<(vk::DescriptorPool, vk::DescriptorSet)> {
    let ctx = pipeline.context();
    let device = ctx.device();
    let sizes = [vk::DescriptorPoolSize::default()
        .ty(vk::DescriptorType::STORAGE_BUFFER)
        .descriptor_count(pipeline.bindings().max(1))];
    let pool_info = vk::DescriptorPoolCreateInfo::default()
        .max_sets(1)
        .pool_sizes(&sizes);
    // SAFETY: valid create info living across the call.
    let pool = unsafe { device.create_descriptor_pool(&pool_info, None) }
        .map_err(|r| map_result("vkCreateDescriptorPool", r))?;
    ctx.set_name(pool, &format!("{name}.pool"));

    let layouts = [pipeline.inner.set_layout];
    let alloc_info = vk::DescriptorSetAllocateInfo::default()
        .descriptor_pool(pool)
        .set_layouts(&layouts);
    // SAFETY: pool and layout are live; the pool has room for exactly this set.
    let raw = match unsafe { device.allocate_descriptor_sets(&alloc_info) } {
        Ok(sets) if !sets.is_empty() => sets[0],
        failed => {
            // SAFETY: the pool was just created and nothing from it is in use.
            unsafe { device.destroy_descriptor_pool(pool, None) };
            return Err(match failed {
                Err(r) => map_result("vkAllocateDescriptorSets", r),
                Ok(_) => GpuError::Invalid("vkAllocateDescriptorSets returned no set".into()),
            });
        }
    };
    ctx.set_name(raw, name);

    let writes: Vec<vk::WriteDescriptorSet> = infos
        .iter()
        .enumerate()
        .map(|(i, info)| {
            vk::WriteDescriptorSet::default()
                .dst_set(raw)
                .dst_binding(i as u32)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .buffer_info(std::slice::from_ref(info))
        })
        .collect();
    if !writes.is_empty() {
        // SAFETY: the set is new and unused; the callers checked the buffers are live and the
        // ranges inside them.
        unsafe { device.update_descriptor_sets(&writes, &[]) };
    }
    Ok((pool, raw))
}
