//! Asynchronous parameterization: [`Engine::start_parameterize`] returns a [`Job`] at once; the
//! host advances it with [`Job::poll`] once per frame and never waits for it.
//!
//! # How it runs
//! A worker thread does the CPU parts (validation, start map, the driver's decisions, recovery,
//! a global-solver hand-off) and records the ADMM iterations in **slices** of about
//! [`JobOptions::slice_budget`] device time: the first slice has one iteration, later ones as
//! many as the previous slice's timestamps say fit the budget. Each slice signals the next value
//! of the job's timeline semaphore ([`Job::timeline`]). What submits it depends on
//! [`JobQueue`]:
//! - [`JobQueue::BetweenFrames`]: the engine's queue is the host's. The worker hands each slice
//!   to the job, and [`Job::poll`] — called by the host on its own thread, between its frames —
//!   submits at most one slice per call. The host's frame therefore waits for at most one slice
//!   of foldfree's device time, and the queue is only touched on the host's thread.
//! - [`JobQueue::Own`]: the engine's queue is foldfree's alone (a dedicated compute queue the
//!   host lent through [`crate::gpu::Context::from_host`]). The worker submits each slice
//!   itself; `poll` only reports.
//!
//! The worker waits for each slice on the timeline semaphore (`vkWaitSemaphores`: no fence, no
//! device-wide stall) and reads the residuals back from host-visible memory, so between slices
//! nothing else stops. A host may also wait for the job's progress on the device: its own
//! submission can wait on [`Job::timeline`] at any value up to [`Job::submitted_value`].
//!
//! The result is the blocking call's: [`Engine::parameterize`] is `start` + [`Job::finish`],
//! and slicing changes no arithmetic (the same kernels in the same order), so the UVs are
//! identical bit for bit.
//!
//! # Cancelling
//! [`Job::cancel`] (and dropping a job) sets the run's stop flag, drops any slice not yet
//! submitted (the worker's wait then fails as cancelled), and joins the worker, which first
//! waits for a slice already on the queue. When it returns, none of the job's work is on the
//! device and every object it made is freed. It can take as long as the CPU step running at
//! that moment (the start map is not interruptible; ADMM checks and the global solver's
//! iterations are).
#![forbid(unsafe_code)]

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, TryRecvError};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use super::{EmbedOptions, Engine, MEMORY_FILE};
use crate::gpu::{Context, GpuError, Handoff, Timeline};
use crate::mesh::{self, TriMesh};
use crate::param::admm::vulkan::{SliceStats, Slicing};
use crate::param::{OnDevice, Progress, SolverChoice};
use crate::{Error, Result};

/// Which queue a job's slices go to; see the module docs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum JobQueue {
    /// The engine's queue is the host's: [`Job::poll`] submits one slice per call.
    #[default]
    BetweenFrames,
    /// The engine's queue is used by nothing else: the job submits as it goes.
    Own,
}

/// How a [`Job`] runs.
#[derive(Clone, Copy, Debug)]
pub struct JobOptions {
    pub queue: JobQueue,
    /// Device time a slice should take. A few milliseconds keeps a 60 Hz host's frames
    /// smooth; `Duration::MAX` makes every residual check one submission (the blocking call).
    pub slice_budget: Duration,
}

impl JobOptions {
    /// What [`Engine::parameterize`] runs: the job submits on its own (the caller does not use
    /// the queue during a blocking call) and one submission per residual check.
    pub fn blocking() -> JobOptions {
        JobOptions {
            queue: JobQueue::Own,
            slice_budget: Duration::MAX,
        }
    }
}

impl Default for JobOptions {
    fn default() -> Self {
        JobOptions {
            queue: JobQueue::BetweenFrames,
            slice_budget: Duration::from_millis(4),
        }
    }
}

/// What the job is doing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum JobPhase {
    /// Validation and the start map (CPU), before the first slice.
    #[default]
    Preparing,
    /// ADMM slices on the device.
    Iterating,
    /// The global solver (CPU) finishing a map ADMM did not converge on.
    Global,
    /// The result is ready for [`Job::finish`].
    Done,
}

/// A snapshot of a job ([`Job::progress`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct JobProgress {
    pub phase: JobPhase,
    /// ADMM iterations the device has completed, of at most `max_iterations`.
    pub iterations: u64,
    pub max_iterations: usize,
    /// The last residual check's relative primal residual and energy.
    pub primal: Option<f64>,
    pub energy: Option<f64>,
    /// Global-solver iterations (after a hand-off).
    pub global_iterations: usize,
    /// Slices completed, their total and longest device time.
    pub slices: u64,
    pub device_time: Duration,
    pub longest_slice: Duration,
    /// The timeline value of the last slice submitted ([`Job::submitted_value`]).
    pub submitted_value: u64,
}

/// What the worker reports besides the counters.
#[derive(Default)]
struct Status {
    /// The global solver has started (the other phases follow from the counters).
    global: bool,
    primal: Option<f64>,
    energy: Option<f64>,
    global_iterations: usize,
}

/// A parameterization in flight; see the module docs. Dropping it cancels it.
pub struct Job {
    timeline: Timeline,
    /// Slices waiting for [`Job::poll`] (`BetweenFrames`); `None` when the job submits itself.
    slices: Option<Receiver<Handoff>>,
    worker: Option<JoinHandle<Result<Vec<[f64; 2]>>>>,
    stop: Arc<AtomicBool>,
    stats: Arc<SliceStats>,
    status: Arc<Mutex<Status>>,
    max_iterations: usize,
    /// A submission of ours that failed (reported by `finish` instead of the worker's error).
    submit_error: Option<GpuError>,
    result: Option<Result<Vec<[f64; 2]>>>,
}

impl std::fmt::Debug for Job {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Job")
            .field("timeline", &self.timeline)
            .field("progress", &self.progress())
            .finish()
    }
}

const _: () = {
    const fn send<T: Send>() {}
    send::<Job>();
};

impl Engine {
    /// Starts parameterizing the disk mesh `positions` / `faces` (as
    /// [`Engine::parameterize`]) and returns at once; see the module docs of [`Job`].
    pub fn start_parameterize(
        &self,
        positions: &[[f64; 3]],
        faces: &[[u32; 3]],
        opts: &EmbedOptions,
        job: &JobOptions,
    ) -> Result<Job> {
        if job.slice_budget.is_zero() {
            return Err(Error::Usage("a job's slice budget must be positive".into()));
        }
        let ctx = self.context().clone();
        let timeline = Timeline::new(&ctx, "embed.job.timeline")?;
        let stats = Arc::new(SliceStats::default());
        let status = Arc::new(Mutex::new(Status::default()));
        let mut opts = opts.clone();
        let stop = opts
            .admm
            .stop
            .get_or_insert_with(|| Arc::new(AtomicBool::new(false)))
            .clone();
        let (handoff, slices) = match job.queue {
            JobQueue::BetweenFrames => {
                let (tx, rx) = mpsc::channel();
                (Some(tx), Some(rx))
            }
            JobQueue::Own => (None, None),
        };
        let slicing = Slicing {
            timeline: timeline.clone(),
            budget: job.slice_budget,
            handoff,
            stats: stats.clone(),
        };
        let mesh = TriMesh {
            positions: positions.to_vec(),
            faces: faces.to_vec(),
        };
        let max_iterations = opts.admm.max_iters;
        let worker_status = status.clone();
        let worker = std::thread::Builder::new()
            .name("foldfree-job".into())
            .spawn(move || run(&ctx, &mesh, &opts, slicing, &worker_status))
            .map_err(|e| GpuError::Invalid(format!("starting the job's worker thread: {e}")))?;
        Ok(Job {
            timeline,
            slices,
            worker: Some(worker),
            stop,
            stats,
            status,
            max_iterations,
            submit_error: None,
            result: None,
        })
    }
}

/// The worker: the blocking pipeline with sliced submissions.
fn run(
    ctx: &Context,
    mesh: &TriMesh,
    opts: &EmbedOptions,
    slicing: Slicing,
    status: &Mutex<Status>,
) -> Result<Vec<[f64; 2]>> {
    let file = Path::new(MEMORY_FILE);
    let (_report, topo) = mesh::validate::validate_with_topology(mesh, file, &opts.validate)?;
    topo.require_disk(file)?;
    // Solved at unit scale and mapped back exactly (see `mesh::Scale`), as `param` does.
    let (scale, unit) = mesh::Scale::normalized(mesh);
    let device = OnDevice {
        slicing: Some(slicing),
        ..OnDevice::new(ctx)
    };
    let set = |f: &mut dyn FnMut(&mut Status)| {
        f(&mut status.lock().unwrap_or_else(PoisonError::into_inner))
    };
    let map = crate::param::compute_map(
        &unit,
        &topo,
        opts.init,
        SolverChoice::Admm,
        opts.bijective,
        &opts.admm,
        Some(&device),
        &mut |p| match p {
            Progress::Admm(h) => set(&mut |s| {
                s.primal = Some(h.primal);
                s.energy = Some(h.energy);
            }),
            Progress::Global(it) => set(&mut |s| {
                s.global = true;
                s.global_iterations = it.iteration;
                s.energy = Some(it.energy);
            }),
        },
    )?;
    Ok(map
        .uv
        .iter()
        .map(|t| [scale.length(t[0]), scale.length(t[1])])
        .collect())
}

impl Job {
    /// Advances the job without blocking: submits the next slice if one is waiting
    /// (`BetweenFrames`; at most one per call) and collects the result when the worker is done.
    /// Returns `true` once the result is ready ([`Job::finish`] then returns at once).
    pub fn poll(&mut self) -> bool {
        if self.result.is_some() {
            return true;
        }
        if let Some(rx) = &self.slices {
            match rx.try_recv() {
                Ok(slice) => self.submit(slice),
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => {}
            }
        }
        if self.worker.as_ref().is_some_and(JoinHandle::is_finished) {
            self.collect();
        }
        self.result.is_some()
    }

    /// Where the job stands (cheap: a lock and a few atomics).
    pub fn progress(&self) -> JobProgress {
        let s = self.status.lock().unwrap_or_else(PoisonError::into_inner);
        let ns = |a: &std::sync::atomic::AtomicU64| Duration::from_nanos(a.load(Ordering::Relaxed));
        JobProgress {
            phase: if self.result.is_some() {
                JobPhase::Done
            } else if s.global {
                JobPhase::Global
            } else if self.stats.slices.load(Ordering::Relaxed) > 0 {
                JobPhase::Iterating
            } else {
                JobPhase::Preparing
            },
            iterations: self.stats.iterations.load(Ordering::Relaxed),
            max_iterations: self.max_iterations,
            primal: s.primal,
            energy: s.energy,
            global_iterations: s.global_iterations,
            slices: self.stats.slices.load(Ordering::Relaxed),
            device_time: ns(&self.stats.device_ns),
            longest_slice: ns(&self.stats.longest_ns),
            submitted_value: self.submitted_value(),
        }
    }

    /// The job's timeline semaphore: slice `k` signals value `k`.
    pub fn timeline(&self) -> &Timeline {
        &self.timeline
    }

    /// The value of the last slice submitted to the queue: a host submission may wait on the
    /// timeline at any value up to this one.
    pub fn submitted_value(&self) -> u64 {
        self.stats.last_value.load(Ordering::Acquire)
    }

    /// Runs the job to its end and returns the UVs (the blocking call's result). With
    /// `BetweenFrames`, this submits the slices itself: the host must not use the queue
    /// meanwhile, as for every blocking engine call.
    pub fn finish(mut self) -> Result<Vec<[f64; 2]>> {
        while self.result.is_none() {
            match &self.slices {
                Some(rx) => match rx.recv_timeout(Duration::from_millis(20)) {
                    Ok(slice) => self.submit(slice),
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => self.collect(),
                },
                None => self.collect(),
            }
            if self.worker.as_ref().is_some_and(JoinHandle::is_finished) {
                self.collect();
            }
        }
        self.result
            .take()
            .unwrap_or_else(|| Err(GpuError::Invalid("the job has no result".into()).into()))
    }

    /// Stops the job: see the module docs. Returns when none of its work is on the device and
    /// everything it made is freed, with the job's last progress.
    pub fn cancel(mut self) -> JobProgress {
        self.stop_now();
        self.progress()
    }

    fn stop_now(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Dropping unsubmitted slices makes the worker's waits fail as cancelled; it drops its
        // end of the channel when it is done.
        let rx = self.slices.take();
        if let Some(rx) = &rx {
            while self.worker.as_ref().is_some_and(|w| !w.is_finished()) {
                match rx.recv_timeout(Duration::from_millis(5)) {
                    Ok(slice) => drop(slice),
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => break,
                }
            }
        }
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
        drop(rx);
    }

    /// Submits one handed-off slice; a failure cancels the rest (the worker's wait reports it
    /// as cancelled, `finish` reports this error).
    fn submit(&mut self, slice: Handoff) {
        let value = slice.value();
        match slice.submit() {
            Ok(()) => self.stats.last_value.store(value, Ordering::Release),
            Err(e) => {
                self.stop.store(true, Ordering::Relaxed);
                self.submit_error.get_or_insert(e);
            }
        }
    }

    /// Joins the worker and keeps its result.
    fn collect(&mut self) {
        let Some(worker) = self.worker.take() else {
            return;
        };
        let result = match worker.join() {
            Ok(r) => r,
            Err(_) => Err(GpuError::Invalid("the job's worker thread panicked".into()).into()),
        };
        self.result = Some(match self.submit_error.take() {
            Some(e) => Err(e.into()),
            None => result,
        });
    }
}

impl Drop for Job {
    fn drop(&mut self) {
        if self.worker.is_some() {
            self.stop_now();
        }
    }
}
