//! The Vulkan backend: the ADMM iteration as four compute kernels (`glsl/admm/`), many
//! iterations recorded per submission, residuals reduced on the device and read back once per
//! batch. f32 on the device; the CPU twin ([`super::cpu`]) is the f64 reference.
//!
//! Per iteration: face_newton → edge_project → dual_update, with a compute→compute barrier
//! between dependent dispatches (each kernel reads what the previous wrote, and overwrites what
//! the next iteration's earlier kernels read, so every boundary is both RAW and WAR).
//!
//! **Slices.** By default a batch is one submission waited for with a fence. Run as an
//! asynchronous job ([`Slicing`]), a batch is cut into slices of about `budget` device time
//! (iterations per slice from the last slice's timestamps), each signalling the next value of
//! the job's timeline semaphore and either submitted here or handed to the thread that owns
//! the queue; uploads and downloads that need a staging copy travel in slices too, so the
//! executor never touches the queue itself when it does not own it. Cutting a batch changes no
//! arithmetic: the same kernels run in the same order, so the iterates are bit-identical.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Duration;

use super::driver::{Executor, Residuals};
use super::layout::{FacePush, MuCountPush, ResidualPush};
use super::{AdmmProblem, AdmmState};
use crate::gpu::{
    shaders, Access, Buffer, BufferDesc, BufferUsage, ComputePipeline, Context, DescriptorSet,
    GpuError, Handoff, MemoryLocation, Recorder, Timeline, TimestampPool,
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

/// How the executor's work reaches the queue when it runs as an asynchronous job.
#[derive(Clone, Debug)]
pub struct Slicing {
    /// Slice `k` of the job signals value `k` (counting from the value the timeline had).
    pub timeline: Timeline,
    /// Device time one slice should take: iterations per slice are sized from the measured
    /// time of the previous slice (the first has one iteration).
    pub budget: Duration,
    /// `None`: the executor submits each slice itself (the queue is the job's alone). `Some`:
    /// each slice goes to the queue's owner, who submits it (e.g. between two frames); a
    /// dropped hand-off cancels the run ([`GpuError::Cancelled`]).
    pub handoff: Option<mpsc::Sender<Handoff>>,
    /// Counters the job's owner reads without locking.
    pub stats: Arc<SliceStats>,
}

/// What the slices of a job did so far.
#[derive(Debug, Default)]
pub struct SliceStats {
    pub slices: AtomicU64,
    pub iterations: AtomicU64,
    /// Measured device time of all slices (timestamps; the submission-to-completion wall time
    /// where the queue has none).
    pub device_ns: AtomicU64,
    /// The longest slice.
    pub longest_ns: AtomicU64,
    /// The timeline value of the last slice submitted to the queue.
    pub last_value: AtomicU64,
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
    /// #F penalty factors `m_f`, written at every upload.
    penalty: Buffer,
    kernels: Kernels,
    recorder: Recorder,
    profile: Option<(TimestampPool, KernelTimes)>,
    slices: Option<Slices>,
    /// Upload and download the iterate through staging copies even where it is mapped.
    staged: bool,
}

fn not_sliced() -> GpuError {
    GpuError::Invalid("admm: a split iteration needs a job's slicing".into())
}

/// The three kernels of an iteration, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kernel {
    Face = 0,
    Edge = 1,
    Dual = 2,
}

/// The executor's side of a [`Slicing`].
struct Slices {
    plan: Slicing,
    /// Start and end of the current slice (`None` when the queue has no timestamps).
    stamps: Option<TimestampPool>,
    next_value: u64,
    /// Device time per iteration, once a slice has run.
    ns_per_iteration: Rate,
    /// Device time per element of each [`Kernel`] (from split iterations).
    ns_per_element: [Rate; 3],
    /// Measured / planned time of recent slices: how far the device's spread exceeds what the
    /// rates foresaw. Slices are planned at `budget / max(1, overshoot)`, so that a slice as
    /// unlucky as the worst recent one still fits the budget.
    overshoot: Rate,
}

impl Slices {
    /// The device time to plan a slice for (ns).
    fn plan_ns(&self) -> f64 {
        let spread = self.overshoot.estimate().unwrap_or(1.0).max(1.0);
        self.plan.budget.as_nanos() as f64 / spread
    }

    /// Records a slice planned to take `planned` ns that took `ns`.
    fn measured(&mut self, planned: Option<f64>, ns: u64) {
        if let Some(p) = planned.filter(|&p| p > 0.0) {
            self.overshoot.push(ns as f64 / p);
        }
    }
}

/// A cost rate from the last few measurements, estimated by their maximum: the same work can
/// take a few times longer when the device is shared (on a CPU device, with the host's own
/// threads), and a slice sized for the worst recent case stays inside its budget where one
/// sized for the mean overshoots every other time. On a dedicated GPU the spread is small and
/// the maximum is close to the mean.
#[derive(Clone, Debug)]
struct Rate {
    recent: std::collections::VecDeque<f64>,
    window: usize,
}

impl Default for Rate {
    fn default() -> Self {
        Rate::new(16)
    }
}

impl Rate {
    fn new(window: usize) -> Rate {
        Rate {
            recent: std::collections::VecDeque::with_capacity(window),
            window,
        }
    }

    fn push(&mut self, x: f64) {
        if self.recent.len() == self.window {
            self.recent.pop_front();
        }
        self.recent.push_back(x);
    }

    fn estimate(&self) -> Option<f64> {
        self.recent.iter().copied().reduce(f64::max)
    }
}

fn to_f32x4(v: &[[f64; 4]]) -> Vec<[f32; 4]> {
    v.iter().map(|m| m.map(|x| x as f32)).collect()
}

fn to_f64x4(v: &[[f32; 4]]) -> Vec<[f64; 4]> {
    v.iter().map(|m| m.map(f64::from)).collect()
}

/// A device-local storage buffer for `n` values of `T`, at least 16 bytes (Vulkan buffers
/// cannot be empty; a mesh with no interior edge has no slots). Filled by
/// [`VulkanExecutor::put`].
fn storage<T>(ctx: &Context, name: &str, n: usize) -> Result<Buffer, GpuError> {
    let bytes = (n * std::mem::size_of::<T>()).max(16) as u64;
    Buffer::with_desc(ctx, &BufferDesc::storage(name, bytes))
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
        slicing: Option<Slicing>,
    ) -> Result<VulkanExecutor, GpuError> {
        let nf = problem.n_faces();
        let ns = problem.n_slots();
        let a = storage::<[f32; 4]>(ctx, "admm.face_jacobians", nf)?;
        let a_prev = storage::<[f32; 4]>(ctx, "admm.face_jacobians_prev", nf)?;
        let y = storage::<[f32; 4]>(ctx, "admm.slot_copies", ns)?;
        let lambda = storage::<[f32; 4]>(ctx, "admm.slot_multipliers", ns)?;
        let slots: Vec<[u32; 4]> = problem
            .face_slots
            .iter()
            .map(|s| [s[0], s[1], s[2], u32::MAX])
            .collect();
        let face_slots = storage::<[u32; 4]>(ctx, "admm.face_slots", nf)?;
        let weights: Vec<f32> = problem.weight.iter().map(|&w| w as f32).collect();
        let weight = storage::<f32>(ctx, "admm.face_weights", nf)?;
        let slot_face = storage::<u32>(ctx, "admm.slot_face", ns)?;
        let dirs: Vec<[f32; 2]> = problem
            .slot_dir
            .iter()
            .map(|d| [d[0] as f32, d[1] as f32])
            .collect();
        let slot_dir = storage::<[f32; 2]>(ctx, "admm.slot_dirs", ns)?;
        let penalty = storage::<f32>(ctx, "admm.face_penalties", nf)?;
        let groups = nf.max(ns).div_ceil(64).max(1);
        // Read back at every check: host-visible, so the read is never a queue operation.
        let partials = Buffer::with_desc(
            ctx,
            &BufferDesc {
                name: "admm.residual_partials",
                size: (groups * 16) as u64,
                usage: BufferUsage::Storage,
                location: MemoryLocation::GpuToCpu,
            },
        )?;

        let face_pipe = ComputePipeline::from_shader::<FacePush>(
            ctx,
            "admm.face_newton",
            shaders::ADMM_FACE_NEWTON,
            7,
        )?;
        let edge_pipe = ComputePipeline::from_shader::<MuCountPush>(
            ctx,
            "admm.edge_project",
            shaders::ADMM_EDGE_PROJECT,
            6,
        )?;
        let dual_pipe = ComputePipeline::from_shader::<MuCountPush>(
            ctx,
            "admm.dual_update",
            shaders::ADMM_DUAL_UPDATE,
            5,
        )?;
        let resid_pipe = ComputePipeline::from_shader::<ResidualPush>(
            ctx,
            "admm.residual",
            shaders::ADMM_RESIDUAL,
            7,
        )?;
        let face_set = DescriptorSet::new(
            &face_pipe,
            "admm.face_newton.set",
            &[&a, &y, &lambda, &face_slots, &weight, &a_prev, &penalty],
        )?;
        let edge_set = DescriptorSet::new(
            &edge_pipe,
            "admm.edge_project.set",
            &[&a, &y, &lambda, &slot_face, &slot_dir, &penalty],
        )?;
        let dual_set = DescriptorSet::new(
            &dual_pipe,
            "admm.dual_update.set",
            &[&a, &y, &lambda, &slot_face, &penalty],
        )?;
        let resid_set = DescriptorSet::new(
            &resid_pipe,
            "admm.residual.set",
            &[&a, &y, &a_prev, &slot_face, &weight, &partials, &penalty],
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
        let slices = match slicing {
            None => None,
            Some(plan) => Some(Slices {
                stamps: if ctx.limits().timestamps {
                    Some(TimestampPool::new(ctx, "admm.slice_timestamps", 2)?)
                } else {
                    None
                },
                next_value: plan.timeline.value()? + 1,
                ns_per_iteration: Rate::default(),
                ns_per_element: Default::default(),
                // Spikes are rarer than rate changes: remember them longer.
                overshoot: Rate::new(64),
                plan,
            }),
        };
        let mut exec = VulkanExecutor {
            ctx: ctx.clone(),
            energy,
            newton_iters,
            n_faces: nf as u32,
            n_slots: ns as u32,
            a: a.clone(),
            y,
            lambda,
            partials,
            penalty,
            kernels: Kernels {
                face: (face_pipe, face_set),
                edge: (edge_pipe, edge_set),
                dual: (dual_pipe, dual_set),
                residual: (resid_pipe, resid_set),
            },
            recorder,
            profile,
            slices,
            staged: false,
        };
        let zeros = vec![[0f32; 4]; nf];
        exec.put(&a_prev, &zeros)?;
        exec.put(&face_slots, &slots)?;
        exec.put(&weight, &weights)?;
        exec.put(&slot_face, &problem.slot_face)?;
        exec.put(&slot_dir, &dirs)?;
        Ok(exec)
    }

    /// Starts a submission (a slice when sliced: timestamp 0 first).
    fn open(&mut self) -> Result<(), GpuError> {
        self.recorder.begin()?;
        if let Some(pool) = self.slices.as_ref().and_then(|s| s.stamps.as_ref()) {
            self.recorder.write_timestamp(pool, 0);
        }
        Ok(())
    }

    /// Ends the submission, sends it on its way and waits for it; returns the slice's measured
    /// device time when sliced.
    fn close(&mut self) -> Result<Option<u64>, GpuError> {
        let Some(sl) = &mut self.slices else {
            self.recorder.submit_and_wait(BATCH_TIMEOUT)?;
            return Ok(None);
        };
        if let Some(pool) = &sl.stamps {
            self.recorder.write_timestamp(pool, 1);
        }
        let value = sl.next_value;
        sl.next_value += 1;
        let handoff = self.recorder.hand_off(&sl.plan.timeline, value)?;
        match &sl.plan.handoff {
            None => {
                handoff.submit()?;
                sl.plan.stats.last_value.store(value, Ordering::Release);
            }
            // The owner records the value when it submits.
            Some(tx) => {
                if let Err(mpsc::SendError(h)) = tx.send(handoff) {
                    // The owner is gone: the hand-off is abandoned and the wait says so.
                    drop(h);
                }
            }
        }
        self.recorder.wait(BATCH_TIMEOUT)?;
        let ns = match &sl.stamps {
            Some(pool) => {
                let t = pool.read_ns()?;
                t[1].saturating_sub(t[0])
            }
            None => self
                .recorder
                .last_latency()
                .map_or(0, |d| d.as_nanos() as u64),
        };
        let stats = &sl.plan.stats;
        stats.slices.fetch_add(1, Ordering::Relaxed);
        stats.device_ns.fetch_add(ns, Ordering::Relaxed);
        stats.longest_ns.fetch_max(ns, Ordering::Relaxed);
        Ok(Some(ns))
    }

    /// Writes `data` at the start of `buf`: through the mapping when it is host visible (no
    /// queue work), else through a staging buffer and a copy in a submission of our own.
    fn put<T: bytemuck::Pod>(&mut self, buf: &Buffer, data: &[T]) -> Result<(), GpuError> {
        if data.is_empty() {
            return Ok(());
        }
        if buf.is_host_visible() && !self.staged {
            return buf.write(data);
        }
        let bytes = std::mem::size_of_val(data) as u64;
        let staging = Buffer::new(
            &self.ctx,
            &format!("{}.staging_upload", buf.name()),
            bytes,
            BufferUsage::Staging,
            MemoryLocation::CpuToGpu,
        )?;
        staging.write(data)?;
        self.open()?;
        self.recorder
            .barrier(Access::ComputeReadWrite, Access::TransferWrite);
        self.recorder.copy_buffer(&staging, buf, bytes);
        self.recorder
            .barrier(Access::TransferWrite, Access::ComputeReadWrite);
        self.close()?;
        Ok(())
    }

    /// The first `n` values of `buf` (see [`VulkanExecutor::put`]).
    fn get<T: bytemuck::Pod>(&mut self, buf: &Buffer, n: usize) -> Result<Vec<T>, GpuError> {
        if n == 0 {
            return Ok(Vec::new());
        }
        if buf.is_host_visible() && !self.staged {
            let mut all: Vec<T> = buf.read()?;
            all.truncate(n);
            return Ok(all);
        }
        let bytes = (n * std::mem::size_of::<T>()) as u64;
        let staging = Buffer::new(
            &self.ctx,
            &format!("{}.staging_download", buf.name()),
            bytes,
            BufferUsage::Staging,
            MemoryLocation::GpuToCpu,
        )?;
        self.open()?;
        self.recorder
            .barrier(Access::ComputeReadWrite, Access::TransferRead);
        self.recorder.copy_buffer(buf, &staging, bytes);
        self.close()?;
        let mut all: Vec<T> = staging.read()?;
        all.truncate(n);
        Ok(all)
    }

    /// Whether one iteration is measured to take longer than a slice may.
    fn iteration_exceeds_budget(&self) -> bool {
        self.slices.as_ref().is_some_and(|sl| {
            sl.plan.budget != Duration::MAX
                && sl
                    .ns_per_iteration
                    .estimate()
                    .is_some_and(|t| t > sl.plan_ns())
        })
    }

    /// Iterations of the next slice out of `remaining`: all of them unless sliced; when
    /// sliced, as many as fit the budget at the measured rate (one until measured).
    fn slice_len(&self, remaining: usize) -> usize {
        match &self.slices {
            None => remaining,
            Some(sl) if sl.plan.budget == Duration::MAX => remaining,
            Some(sl) => match sl.ns_per_iteration.estimate() {
                None => 1,
                Some(t) => {
                    let fit = sl.plan_ns() / t.max(1.0);
                    (fit.floor() as usize).clamp(1, remaining)
                }
            },
        }
        .min(remaining)
    }

    /// Makes [`Executor::upload`] and [`Executor::download`] go through staging buffers and
    /// copies in submissions of the executor's own (slices, when sliced) even where the
    /// buffers are host visible: the path of a discrete GPU's device-local memory, exercised
    /// and checked on devices (lavapipe) whose memory is all mapped.
    pub fn with_staged_transfers(mut self) -> VulkanExecutor {
        self.staged = true;
        self
    }

    /// Device time per kernel accumulated over the profiled iterations.
    pub fn kernel_times(&self) -> Option<&KernelTimes> {
        self.profile.as_ref().map(|(_, t)| t)
    }

    /// Storage-buffer bytes one iteration reads and writes (face, edge and dual kernels; the
    /// residual pass once per batch is not counted): face = A r/w, slots, weight, penalty, and
    /// Y, Λ of each slot; edge = per slot A, Λ, face index, direction, penalty read and Y
    /// written; dual = per slot A, Y, face index, penalty read and Λ read/written.
    pub fn bytes_per_iteration(&self) -> u64 {
        self.kernel_bytes().iter().sum()
    }

    /// [`VulkanExecutor::bytes_per_iteration`] per kernel: face_newton, edge_project,
    /// dual_update.
    pub fn kernel_bytes(&self) -> [u64; 3] {
        let (f, s) = (u64::from(self.n_faces), u64::from(self.n_slots));
        let face = f * (16 + 16 + 16 + 4 + 4) + s * 32;
        let edge = s * (16 + 16 + 4 + 8 + 16 + 4);
        let dual = s * (16 + 16 + 4 + 16 + 16 + 4);
        [face, edge, dual]
    }

    /// The context (for its validation messages).
    pub fn context(&self) -> &Context {
        &self.ctx
    }

    fn record_iteration(&mut self, mu: f32, save_prev: bool, stamps: Option<&TimestampPool>) {
        let ts = |rec: &mut Recorder, i: u32| {
            if let Some(pool) = stamps {
                rec.write_timestamp(pool, i);
            }
        };
        ts(&mut self.recorder, 0);
        self.record_piece(Kernel::Face, 0, self.n_faces, mu, save_prev);
        ts(&mut self.recorder, 1);
        self.record_piece(Kernel::Edge, 0, self.n_slots / 2, mu, save_prev);
        ts(&mut self.recorder, 2);
        self.record_piece(Kernel::Dual, 0, self.n_slots, mu, save_prev);
        ts(&mut self.recorder, 3);
    }

    /// One kernel over elements `first..end` (faces, interior edges or slots), then the
    /// compute→compute barrier the next dispatch needs.
    fn record_piece(&mut self, kernel: Kernel, first: u32, end: u32, mu: f32, save_prev: bool) {
        if end <= first {
            return;
        }
        let rec = &mut self.recorder;
        match kernel {
            Kernel::Face => {
                let (p, s) = &self.kernels.face;
                rec.bind(p, s);
                rec.push(&FacePush {
                    mu,
                    n_faces: end,
                    energy: self.energy.code(),
                    newton_iters: self.newton_iters,
                    save_prev: save_prev as u32,
                    first,
                });
            }
            Kernel::Edge | Kernel::Dual => {
                let (p, s) = if kernel == Kernel::Edge {
                    &self.kernels.edge
                } else {
                    &self.kernels.dual
                };
                rec.bind(p, s);
                rec.push(&MuCountPush { mu, n: end, first });
            }
        }
        rec.dispatch_1d(end - first);
        rec.barrier(Access::ComputeReadWrite, Access::ComputeReadWrite);
    }

    /// Elements of `kernel`'s dispatch in one iteration.
    fn count(&self, kernel: Kernel) -> u32 {
        match kernel {
            Kernel::Face => self.n_faces,
            Kernel::Edge => self.n_slots / 2,
            Kernel::Dual => self.n_slots,
        }
    }

    /// One iteration cut into pieces of about the slice budget, one piece per slice: used when
    /// a whole iteration takes longer than the budget (large meshes, slow devices). Each
    /// kernel's elements are independent, so the pieces compute exactly what one dispatch
    /// would. Piece sizes come from each kernel's measured time per element (until measured,
    /// the iteration's time split evenly).
    fn split_iteration(&mut self, mu: f32, last: bool) -> Result<(), GpuError> {
        for kernel in [Kernel::Face, Kernel::Edge, Kernel::Dual] {
            let n = self.count(kernel);
            let mut first = 0;
            while first < n {
                let Some(sl) = self.slices.as_ref() else {
                    return Err(not_sliced());
                };
                let budget = sl.plan_ns();
                let measured_rate = sl.ns_per_element[kernel as usize].estimate();
                let per = measured_rate.unwrap_or_else(|| {
                    let per_iteration = sl.ns_per_iteration.estimate().unwrap_or(budget);
                    let pieces = (per_iteration / budget).ceil().max(1.0);
                    budget / (f64::from(n) / pieces).max(1.0)
                });
                // At least a workgroup's worth, at most what is left.
                let len = ((budget / per.max(1e-3)).floor() as u32)
                    .max(64)
                    .min(n - first);
                let end = first + len;
                self.open()?;
                self.record_piece(kernel, first, end, mu, last);
                let tail = last && kernel == Kernel::Dual && end == n;
                if tail {
                    self.record_residual();
                }
                let ns = self.close()?.unwrap_or(0);
                if let (false, Some(sl)) = (tail, self.slices.as_mut()) {
                    sl.measured(measured_rate.map(|r| r * f64::from(len)), ns);
                    sl.ns_per_element[kernel as usize].push(ns as f64 / f64::from(len));
                }
                first = end;
            }
        }
        let counts = [Kernel::Face, Kernel::Edge, Kernel::Dual].map(|k| f64::from(self.count(k)));
        let Some(sl) = self.slices.as_mut() else {
            return Err(not_sliced());
        };
        // The iteration's cost from its kernels' rates: decides whether the next one fits.
        let total: Option<f64> = sl
            .ns_per_element
            .iter()
            .zip(counts)
            .map(|(r, n)| r.estimate().map(|r| r * n))
            .sum();
        if let Some(t) = total {
            sl.ns_per_iteration.push(t);
        }
        sl.plan.stats.iterations.fetch_add(1, Ordering::Relaxed);
        Ok(())
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

    fn upload(&mut self, state: &AdmmState, factors: &[f64]) -> crate::Result<()> {
        let (a, y, lambda) = (self.a.clone(), self.y.clone(), self.lambda.clone());
        let penalty = self.penalty.clone();
        self.put(
            &penalty,
            &factors.iter().map(|&m| m as f32).collect::<Vec<_>>(),
        )?;
        self.put(&a, &to_f32x4(&state.a))?;
        self.put(&y, &to_f32x4(&state.y))?;
        self.put(&lambda, &to_f32x4(&state.lambda))?;
        Ok(())
    }

    fn download(&mut self) -> crate::Result<AdmmState> {
        let nf = self.n_faces as usize;
        let ns = self.n_slots as usize;
        let (a, y, lambda) = (self.a.clone(), self.y.clone(), self.lambda.clone());
        let a: Vec<[f32; 4]> = self.get(&a, nf)?;
        let y: Vec<[f32; 4]> = self.get(&y, ns)?;
        let l: Vec<[f32; 4]> = self.get(&lambda, ns)?;
        Ok(AdmmState {
            a: to_f64x4(&a),
            y: to_f64x4(&y),
            lambda: to_f64x4(&l),
        })
    }

    fn iterate(&mut self, n: usize, mu: f64) -> crate::Result<Residuals> {
        let mu = mu as f32;
        let n = n.max(1);
        // Profiled batches are submitted one iteration at a time so that the five timestamps
        // bracket each kernel of every iteration.
        let profiled = self.profile.as_ref().map(|(pool, _)| pool.clone());
        let mut done = 0;
        while done < n {
            if profiled.is_none() && self.iteration_exceeds_budget() {
                self.split_iteration(mu, done + 1 == n)?;
                done += 1;
                continue;
            }
            let len = if profiled.is_some() {
                1
            } else {
                self.slice_len(n - done)
            };
            let last_chunk = done + len == n;
            let planned = self
                .slices
                .as_ref()
                .and_then(|sl| sl.ns_per_iteration.estimate())
                .map(|t| t * len as f64);
            self.open()?;
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
            let slice_ns = self.close()?;
            if let (Some(sl), Some(ns)) = (&mut self.slices, slice_ns) {
                if !last_chunk {
                    // The batch's last slice also runs the residual pass, which the rate
                    // does not foresee.
                    sl.measured(planned, ns);
                }
                sl.ns_per_iteration.push(ns as f64 / len as f64);
                sl.plan
                    .stats
                    .iterations
                    .fetch_add(len as u64, Ordering::Relaxed);
            }
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
            done += len;
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
