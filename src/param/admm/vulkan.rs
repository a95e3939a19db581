//! The Vulkan backend: the ADMM iteration as four compute kernels (`glsl/admm/`), many
//! iterations recorded per submission, residuals reduced on the device and read back once per
//! batch. f32 on the device; the CPU twin ([`super::cpu`]) is the f64 reference.
//!
//! Per iteration: face_newton → edge_project → dual_update, with a compute→compute barrier
//! between dependent dispatches (each kernel reads what the previous wrote, and overwrites what
//! the next iteration's earlier kernels read, so every boundary is both RAW and WAR).

use std::time::Duration;

use super::driver::{Executor, Residuals};
use super::layout::{FacePush, MuCountPush, ResidualPush};
use super::{AdmmProblem, AdmmState};
use crate::gpu::{
    shaders, Access, Buffer, ComputePipeline, Context, DescriptorSet, GpuError, Recorder,
    TimestampPool,
};
use crate::param::energy::Energy;

/// Longest a batch of iterations may run before it counts as a hung device.
const BATCH_TIMEOUT: Duration = Duration::from_secs(600);

/// Accumulated device time per kernel (ns), from timestamp queries (`--profile`).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct KernelTimes {
    pub face_newton_ns: u64,
    pub edge_project_ns: u64,
    pub dual_update_ns: u64,
    pub residual_ns: u64,
    pub iterations: u64,
}

/// Four pipelines with their bound buffers.
struct Kernels {
    face: (ComputePipeline, DescriptorSet),
    edge: (ComputePipeline, DescriptorSet),
    dual: (ComputePipeline, DescriptorSet),
    residual: (ComputePipeline, DescriptorSet),
}

/// Runs the iteration on a Vulkan device.
pub struct VulkanExecutor {
    ctx: Context,
    energy: Energy,
    newton_iters: u32,
    n_faces: u32,
    n_slots: u32,
    a: Buffer,
    y: Buffer,
    lambda: Buffer,
    partials: Buffer,
    kernels: Kernels,
    recorder: Recorder,
    profile: Option<(TimestampPool, KernelTimes)>,
}

fn to_f32x4(v: &[[f64; 4]]) -> Vec<[f32; 4]> {
    v.iter().map(|m| m.map(|x| x as f32)).collect()
}

fn to_f64x4(v: &[[f32; 4]]) -> Vec<[f64; 4]> {
    v.iter().map(|m| m.map(f64::from)).collect()
}

/// A storage buffer holding `data`, at least 16 bytes (Vulkan buffers cannot be empty; a mesh
/// with no interior edge has no slots).
fn storage<T: bytemuck::Pod>(ctx: &Context, name: &str, data: &[T]) -> Result<Buffer, GpuError> {
    if data.is_empty() {
        return Buffer::from_slice(ctx, name, &[0u32; 4]);
    }
    Buffer::from_slice(ctx, name, data)
}

impl VulkanExecutor {
    /// Uploads the problem's constant arrays and builds the pipelines. `profile` adds
    /// timestamps around every dispatch.
    pub fn new(
        ctx: &Context,
        problem: &AdmmProblem,
        energy: Energy,
        newton_iters: u32,
        profile: bool,
    ) -> Result<VulkanExecutor, GpuError> {
        let nf = problem.n_faces();
        let ns = problem.n_slots();
        let zeros4 = vec![[0f32; 4]; nf];
        let a = storage(ctx, "admm.face_jacobians", &zeros4)?;
        let a_prev = storage(ctx, "admm.face_jacobians_prev", &zeros4)?;
        let y = storage(ctx, "admm.slot_copies", &vec![[0f32; 4]; ns])?;
        let lambda = storage(ctx, "admm.slot_multipliers", &vec![[0f32; 4]; ns])?;
        let slots: Vec<[u32; 4]> = problem
            .face_slots
            .iter()
            .map(|s| [s[0], s[1], s[2], u32::MAX])
            .collect();
        let face_slots = storage(ctx, "admm.face_slots", &slots)?;
        let weights: Vec<f32> = problem.weight.iter().map(|&w| w as f32).collect();
        let weight = storage(ctx, "admm.face_weights", &weights)?;
        let slot_face = storage(ctx, "admm.slot_face", &problem.slot_face)?;
        let dirs: Vec<[f32; 2]> = problem
            .slot_dir
            .iter()
            .map(|d| [d[0] as f32, d[1] as f32])
            .collect();
        let slot_dir = storage(ctx, "admm.slot_dirs", &dirs)?;
        let groups = nf.max(ns).div_ceil(64).max(1);
        let partials = storage(ctx, "admm.residual_partials", &vec![[0f32; 4]; groups])?;

        let face_pipe = ComputePipeline::from_shader::<FacePush>(
            ctx,
            "admm.face_newton",
            shaders::ADMM_FACE_NEWTON,
            6,
        )?;
        let edge_pipe = ComputePipeline::from_shader::<MuCountPush>(
            ctx,
            "admm.edge_project",
            shaders::ADMM_EDGE_PROJECT,
            5,
        )?;
        let dual_pipe = ComputePipeline::from_shader::<MuCountPush>(
            ctx,
            "admm.dual_update",
            shaders::ADMM_DUAL_UPDATE,
            4,
        )?;
        let resid_pipe = ComputePipeline::from_shader::<ResidualPush>(
            ctx,
            "admm.residual",
            shaders::ADMM_RESIDUAL,
            6,
        )?;
        let face_set = DescriptorSet::new(
            &face_pipe,
            "admm.face_newton.set",
            &[&a, &y, &lambda, &face_slots, &weight, &a_prev],
        )?;
        let edge_set = DescriptorSet::new(
            &edge_pipe,
            "admm.edge_project.set",
            &[&a, &y, &lambda, &slot_face, &slot_dir],
        )?;
        let dual_set = DescriptorSet::new(
            &dual_pipe,
            "admm.dual_update.set",
            &[&a, &y, &lambda, &slot_face],
        )?;
        let resid_set = DescriptorSet::new(
            &resid_pipe,
            "admm.residual.set",
            &[&a, &y, &a_prev, &slot_face, &weight, &partials],
        )?;
        let recorder = Recorder::new(ctx, "admm.iterations")?;
        let profile = if profile {
            Some((
                TimestampPool::new(ctx, "admm.timestamps", 5)?,
                KernelTimes::default(),
            ))
        } else {
            None
        };
        Ok(VulkanExecutor {
            ctx: ctx.clone(),
            energy,
            newton_iters,
            n_faces: nf as u32,
            n_slots: ns as u32,
            a,
            y,
            lambda,
            partials,
            kernels: Kernels {
                face: (face_pipe, face_set),
                edge: (edge_pipe, edge_set),
                dual: (dual_pipe, dual_set),
                residual: (resid_pipe, resid_set),
            },
            recorder,
            profile,
        })
    }

    /// Device time per kernel accumulated over the profiled iterations.
    pub fn kernel_times(&self) -> Option<&KernelTimes> {
        self.profile.as_ref().map(|(_, t)| t)
    }

    /// Storage-buffer bytes one iteration reads and writes (face, edge and dual kernels; the
    /// residual pass once per batch is not counted): face = A r/w, slots, weight, and Y, Λ of
    /// each slot; edge = per slot A, Λ, face index, direction read and Y written; dual = per
    /// slot A, Y, face index read and Λ read/written.
    pub fn bytes_per_iteration(&self) -> u64 {
        let (f, s) = (u64::from(self.n_faces), u64::from(self.n_slots));
        let face = f * (16 + 16 + 16 + 4) + s * 32;
        let edge = s * (16 + 16 + 4 + 8 + 16);
        let dual = s * (16 + 16 + 4 + 16 + 16);
        face + edge + dual
    }

    /// The context (for its validation messages).
    pub fn context(&self) -> &Context {
        &self.ctx
    }

    fn record_iteration(&mut self, mu: f32, save_prev: bool, stamps: Option<&TimestampPool>) {
        let rec = &mut self.recorder;
        let ts = |rec: &mut Recorder, i: u32| {
            if let Some(pool) = stamps {
                rec.write_timestamp(pool, i);
            }
        };
        ts(rec, 0);
        let (p, s) = &self.kernels.face;
        rec.bind(p, s);
        rec.push(&FacePush {
            mu,
            n_faces: self.n_faces,
            energy: self.energy.code(),
            newton_iters: self.newton_iters,
            save_prev: save_prev as u32,
        });
        rec.dispatch_1d(self.n_faces);
        rec.barrier(Access::ComputeReadWrite, Access::ComputeReadWrite);
        ts(rec, 1);
        let n_edges = self.n_slots / 2;
        if n_edges > 0 {
            let (p, s) = &self.kernels.edge;
            rec.bind(p, s);
            rec.push(&MuCountPush { mu, n: n_edges });
            rec.dispatch_1d(n_edges);
            rec.barrier(Access::ComputeReadWrite, Access::ComputeReadWrite);
        }
        ts(rec, 2);
        if self.n_slots > 0 {
            let (p, s) = &self.kernels.dual;
            rec.bind(p, s);
            rec.push(&MuCountPush {
                mu,
                n: self.n_slots,
            });
            rec.dispatch_1d(self.n_slots);
            rec.barrier(Access::ComputeReadWrite, Access::ComputeReadWrite);
        }
        ts(rec, 3);
    }

    fn record_residual(&mut self) {
        let rec = &mut self.recorder;
        let (p, s) = &self.kernels.residual;
        rec.bind(p, s);
        rec.push(&ResidualPush {
            n_slots: self.n_slots,
            n_faces: self.n_faces,
            energy: self.energy.code(),
        });
        rec.dispatch_1d(self.n_faces.max(self.n_slots));
    }
}

impl Executor for VulkanExecutor {
    fn backend(&self) -> &'static str {
        "vulkan"
    }

    fn device(&self) -> String {
        self.ctx.device_name().to_string()
    }

    fn upload(&mut self, state: &AdmmState) -> crate::Result<()> {
        self.a.write(&to_f32x4(&state.a))?;
        if !state.y.is_empty() {
            self.y.write(&to_f32x4(&state.y))?;
            self.lambda.write(&to_f32x4(&state.lambda))?;
        }
        Ok(())
    }

    fn download(&mut self) -> crate::Result<AdmmState> {
        let nf = self.n_faces as usize;
        let ns = self.n_slots as usize;
        let a: Vec<[f32; 4]> = self.a.read()?;
        let y: Vec<[f32; 4]> = self.y.read()?;
        let l: Vec<[f32; 4]> = self.lambda.read()?;
        Ok(AdmmState {
            a: to_f64x4(&a[..nf]),
            y: to_f64x4(&y[..ns]),
            lambda: to_f64x4(&l[..ns]),
        })
    }

    fn iterate(&mut self, n: usize, mu: f64) -> crate::Result<Residuals> {
        let mu = mu as f32;
        let n = n.max(1);
        // Profiled batches are submitted one iteration at a time so that the five timestamps
        // bracket each kernel of every iteration.
        let profiled = self.profile.as_ref().map(|(pool, _)| pool.clone());
        let chunks: Vec<usize> = if profiled.is_some() {
            vec![1; n]
        } else {
            vec![n]
        };
        for (c, &len) in chunks.iter().enumerate() {
            let last_chunk = c + 1 == chunks.len();
            self.recorder.begin()?;
            for k in 0..len {
                let save_prev = last_chunk && k + 1 == len;
                self.record_iteration(mu, save_prev, profiled.as_ref());
            }
            if last_chunk {
                self.record_residual();
            }
            if let Some(pool) = &profiled {
                self.recorder.write_timestamp(pool, 4);
            }
            self.recorder.submit_and_wait(BATCH_TIMEOUT)?;
            if let Some((pool, times)) = &mut self.profile {
                let t = pool.read_ns()?;
                times.face_newton_ns += t[1].saturating_sub(t[0]);
                times.edge_project_ns += t[2].saturating_sub(t[1]);
                times.dual_update_ns += t[3].saturating_sub(t[2]);
                if last_chunk {
                    times.residual_ns += t[4].saturating_sub(t[3]);
                }
                times.iterations += 1;
            }
        }
        let partials: Vec<[f32; 4]> = self.partials.read()?;
        let mut r = Residuals::default();
        for p in &partials {
            r.primal2 += f64::from(p[0]);
            r.dual2 += f64::from(p[1]);
            r.anorm2 += f64::from(p[2]);
            r.energy += f64::from(p[3]);
        }
        Ok(r)
    }
}
