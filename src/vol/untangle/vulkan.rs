//! The untangler's per-tet energy and gradient on a Vulkan device
//! (`glsl/vol/untangle_tet.comp`; CPU twin: [`super::tet_terms`]), selected with
//! `foldfree volmap --backend vulkan`.
//!
//! Why the split: the per-tet terms are the whole cost of an untangler evaluation and are
//! independent per tet, so they scale with the device; the per-vertex sums, the L-BFGS
//! two-loop recursion and the line search stay on the host in f64 (the sums in a fixed order,
//! so the device path is as deterministic as the CPU one). On a real GPU this is how the stage
//! reaches millions of tets; on lavapipe it only has to be correct. The device computes in f32:
//! per-tet energies carry ~1e-7 relative error, below the untangler's 1e-6 inner stop, so the
//! line search still sees real decreases until that stop.

use std::time::Duration;

use super::Corner;
use crate::gpu::{shaders, Buffer, ComputePipeline, Context, DescriptorSet, GpuError, Recorder};

/// Longest one evaluation may run before it counts as a hung device.
const TIMEOUT: Duration = Duration::from_secs(120);

/// Push constants of `untangle_tet.comp` (std430 layout: three 4-byte scalars).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct UntanglePush {
    pub eps: f32,
    pub theta: f32,
    pub n_tets: u32,
}

/// The mesh's constant arrays on the device and the kernel bound to them.
pub struct DeviceTets {
    ctx: Context,
    n_verts: usize,
    n_tets: u32,
    pos: Buffer,
    energy: Buffer,
    grad: Buffer,
    pipeline: ComputePipeline,
    set: DescriptorSet,
    recorder: Recorder,
}

/// The layout of binding 2: entry 3t + c holds the four corner weights of Jacobian column c.
pub fn corner_columns(d: &[Corner]) -> Vec<[f32; 4]> {
    d.iter()
        .flat_map(|c| (0..3).map(move |k| [c[0][k], c[1][k], c[2][k], c[3][k]].map(|v| v as f32)))
        .collect()
}

impl DeviceTets {
    /// Uploads tets, corner weights D and weights w (one per tet) for a mesh of `n_verts`
    /// vertices.
    pub fn new(
        ctx: &Context,
        tets: &[[u32; 4]],
        d: &[Corner],
        w: &[f64],
        n_verts: usize,
    ) -> Result<DeviceTets, GpuError> {
        if tets.is_empty() || tets.len() != d.len() || tets.len() != w.len() || n_verts == 0 {
            return Err(GpuError::Invalid(format!(
                "untangler kernel: {} tets, {} corner weights, {} weights, {n_verts} vertices",
                tets.len(),
                d.len(),
                w.len()
            )));
        }
        let n_tets = u32::try_from(tets.len())
            .map_err(|_| GpuError::Invalid("more than 2^32 tets".into()))?;
        let pos = Buffer::from_slice(ctx, "untangle.positions", &vec![[0f32; 4]; n_verts])?;
        let tet_buf = Buffer::from_slice(ctx, "untangle.tets", tets)?;
        let corners = Buffer::from_slice(ctx, "untangle.corners", &corner_columns(d))?;
        let weights: Vec<f32> = w.iter().map(|&v| v as f32).collect();
        let weight = Buffer::from_slice(ctx, "untangle.weights", &weights)?;
        let energy = Buffer::from_slice(ctx, "untangle.energy", &vec![0f32; tets.len()])?;
        let grad = Buffer::from_slice(ctx, "untangle.gradient", &vec![[0f32; 4]; 4 * tets.len()])?;
        let pipeline = ComputePipeline::from_shader::<UntanglePush>(
            ctx,
            "untangle.tet",
            shaders::VOL_UNTANGLE_TET,
            6,
        )?;
        let set = DescriptorSet::new(
            &pipeline,
            "untangle.tet.set",
            &[&pos, &tet_buf, &corners, &weight, &energy, &grad],
        )?;
        let recorder = Recorder::new(ctx, "untangle.evaluate")?;
        Ok(DeviceTets {
            ctx: ctx.clone(),
            n_verts,
            n_tets,
            pos,
            energy,
            grad,
            pipeline,
            set,
            recorder,
        })
    }

    /// Per-tet energies and corner gradients (already weighted) at `x`.
    pub fn evaluate(
        &mut self,
        x: &[[f64; 3]],
        eps: f64,
        theta: f64,
    ) -> Result<(Vec<f32>, Vec<[f32; 4]>), GpuError> {
        if x.len() != self.n_verts {
            return Err(GpuError::Invalid(format!(
                "untangler kernel: {} positions for {} vertices",
                x.len(),
                self.n_verts
            )));
        }
        let p: Vec<[f32; 4]> = x
            .iter()
            .map(|q| [q[0] as f32, q[1] as f32, q[2] as f32, 0.0])
            .collect();
        self.pos.write(&p)?;
        self.recorder.begin()?;
        self.recorder.bind(&self.pipeline, &self.set);
        self.recorder.push(&UntanglePush {
            eps: eps as f32,
            theta: theta as f32,
            n_tets: self.n_tets,
        });
        self.recorder.dispatch_1d(self.n_tets);
        self.recorder.submit_and_wait(TIMEOUT)?;
        Ok((self.energy.read()?, self.grad.read()?))
    }

    /// The context (for its validation messages).
    pub fn context(&self) -> &Context {
        &self.ctx
    }
}
