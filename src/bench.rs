//! `foldfree dev bench`: runs `param` over meshes × energies × backends in one process and prints
//! a Markdown table (the source of the numbers in BENCHMARKS.md). Timing lives here, never in
//! unit tests.
#![forbid(unsafe_code)]

use std::fmt::Write as _;
use std::path::PathBuf;

use crate::param::admm::AdmmOptions;
use crate::param::Energy;
use crate::param::{run_param, BackendChoice, ParamJob};
use crate::report::ParamReport;
use crate::Result;

/// One benchmark run's settings.
#[derive(Clone, Debug)]
pub struct BenchJob {
    pub meshes: Vec<PathBuf>,
    pub energies: Vec<Energy>,
    pub backends: Vec<BackendChoice>,
    pub max_iters: Option<usize>,
    /// Where the OBJ outputs go.
    pub out_dir: PathBuf,
}

/// One row of the table.
pub struct BenchRow {
    pub mesh: String,
    pub energy: Energy,
    pub report: ParamReport,
}

/// What [`run_bench`] produced: the rows that ran, the Markdown table, and the first failed
/// run's error (its row has the error text; the CLI exits with its code after the table, so a
/// failed run is never a silent exit 0).
pub struct BenchOutcome {
    pub rows: Vec<BenchRow>,
    pub table: String,
    pub first_error: Option<crate::Error>,
}

/// The output of one (mesh, energy, backend) run.
fn out_path(
    job: &BenchJob,
    mesh: &std::path::Path,
    energy: Energy,
    backend: BackendChoice,
) -> PathBuf {
    let stem = mesh
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    let tag = format!("{stem}-{energy:?}-{backend:?}").to_lowercase();
    job.out_dir.join(format!("{tag}.obj"))
}

/// Runs every combination; a failed run becomes a row with the error text. Before any run,
/// as for every command: each mesh must be a readable regular file, the output folder must
/// be (or become) a folder, and no run's output may be one of the meshes or another run's
/// output (by file identity) — a later mesh of the list was otherwise replaced by an earlier
/// run's map.
pub fn run_bench(job: &BenchJob, mut log: impl FnMut(&str)) -> Result<BenchOutcome> {
    use crate::files::{FileError, Outputs};
    for mesh in &job.meshes {
        let meta = std::fs::metadata(mesh).map_err(|e| FileError::Unreadable {
            path: mesh.clone(),
            reason: e.to_string(),
        })?;
        if !meta.is_file() {
            return Err(FileError::Unreadable {
                path: mesh.clone(),
                reason: "not a regular file (a pipe, socket, device or folder)".into(),
            }
            .into());
        }
    }
    if job.out_dir.exists() && !job.out_dir.is_dir() {
        return Err(FileError::BadOutput {
            path: job.out_dir.clone(),
            what: "output folder".into(),
            reason: "it exists and is not a folder".into(),
        }
        .into());
    }
    std::fs::create_dir_all(&job.out_dir).map_err(|e| FileError::BadOutput {
        path: job.out_dir.clone(),
        what: "output folder".into(),
        reason: e.to_string(),
    })?;
    let mut plan = Outputs::new();
    for mesh in &job.meshes {
        plan.input(mesh);
    }
    for mesh in &job.meshes {
        for &energy in &job.energies {
            for &backend in &job.backends {
                plan.output(&out_path(job, mesh, energy, backend), "map", &["obj"])?;
            }
        }
    }
    let mut first_error = None;
    let mut rows = Vec::new();
    let mut table = String::from(
        "| mesh | faces | energy | backend | iterations | converged | s/iteration | MB/iteration | GB/s achieved | solve s | total s | δcon mean | SD | flips |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for mesh in &job.meshes {
        let stem = mesh
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        for &energy in &job.energies {
            for &backend in &job.backends {
                let mut pj = ParamJob::new(mesh, out_path(job, mesh, energy, backend));
                pj.backend = backend;
                pj.admm = AdmmOptions::for_energy(energy);
                if let Some(n) = job.max_iters {
                    pj.admm.max_iters = n;
                }
                match run_param(&pj, &mut |_| {}) {
                    Ok(out) => {
                        let r = out.report;
                        let per_it = if r.iterations > 0 {
                            r.seconds_solve / r.iterations as f64
                        } else {
                            0.0
                        };
                        let (mb, gbs) = match r.bytes_per_iteration {
                            Some(b) if per_it > 0.0 => (
                                format!("{:.1}", b as f64 / 1e6),
                                format!("{:.2}", b as f64 / per_it / 1e9),
                            ),
                            _ => (String::new(), String::new()),
                        };
                        let line = format!(
                            "| {stem} | {} | {} | {} ({}) | {} | {} | {:.4} | {mb} | {gbs} | {:.2} | {:.2} | {:.4} | {:.4} | {} |",
                            r.faces,
                            r.energy.clone().unwrap_or_default(),
                            r.backend,
                            r.device,
                            r.iterations,
                            r.converged.unwrap_or(false),
                            per_it,
                            r.seconds_solve,
                            r.seconds,
                            r.delta_con_mean,
                            r.sd_energy,
                            r.flips
                        );
                        log(&line);
                        let _ = writeln!(table, "{line}");
                        rows.push(BenchRow {
                            mesh: stem.clone(),
                            energy,
                            report: r,
                        });
                    }
                    Err(e) => {
                        let line = format!(
                            "| {stem} | | {energy:?} | {backend:?} | error: {e} | | | | | | | |"
                        );
                        log(&line);
                        let _ = writeln!(table, "{line}");
                        first_error.get_or_insert(e);
                    }
                }
            }
        }
    }
    Ok(BenchOutcome {
        rows,
        table,
        first_error,
    })
}

/// Measured device memory bandwidth in GB/s: `y = a·x + y` over `n` floats (12 bytes moved per
/// element), timed with GPU timestamps, best of `reps` dispatches. The ceiling the ADMM kernels'
/// bytes per iteration are compared against in BENCHMARKS.md.
pub fn device_bandwidth(ctx: &crate::gpu::Context, n: u32, reps: u32) -> Result<f64> {
    use crate::gpu::{
        shaders, Buffer, ComputePipeline, ComputePipelineDesc, DescriptorSet, Recorder,
        TimestampPool,
    };
    #[repr(C)]
    #[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
    struct Push {
        a: f32,
        n: u32,
    }
    let words = shaders::words(shaders::TEST_SAXPY)?;
    let pipe = ComputePipeline::new(ctx, &ComputePipelineDesc::new("bench.saxpy", &words, 2, 8))?;
    let x = Buffer::from_slice(ctx, "bench.x", &vec![1.0f32; n as usize])?;
    let y = Buffer::from_slice(ctx, "bench.y", &vec![0.5f32; n as usize])?;
    let set = DescriptorSet::new(&pipe, "bench.saxpy.set", &[&x, &y])?;
    let pool = TimestampPool::new(ctx, "bench.ts", 2)?;
    let mut rec = Recorder::new(ctx, "bench.saxpy")?;
    let mut best = f64::INFINITY;
    for _ in 0..reps.max(1) {
        rec.begin()?;
        rec.write_timestamp(&pool, 0);
        rec.bind(&pipe, &set);
        rec.push(&Push { a: 2.0, n });
        rec.dispatch_1d(n);
        rec.write_timestamp(&pool, 1);
        rec.submit_and_wait(std::time::Duration::from_secs(60))?;
        let t = pool.read_ns()?;
        best = best.min(t[1].saturating_sub(t[0]) as f64);
    }
    Ok(12.0 * f64::from(n) / best.max(1.0))
}

/// One mesh's device profile ([`profile_mesh`]).
#[derive(Clone, Debug)]
pub struct DeviceProfile {
    pub mesh: String,
    pub faces: usize,
    pub device: String,
    pub iterations: usize,
    /// Device time per iteration of face_newton, edge_project, dual_update (ns, timestamps).
    pub kernel_ns: [f64; 3],
    /// Bytes each of those kernels reads and writes per iteration.
    pub kernel_bytes: [u64; 3],
    /// The device's streaming rate (saxpy), GB/s.
    pub stream_gbs: f64,
    /// Wall time per iteration of unprofiled batches (as the driver submits them).
    pub wall_ns_per_iteration: f64,
    /// Device time per iteration of those batches (a timestamp pair per batch).
    pub device_ns_per_iteration: f64,
    /// `foldfree param` end to end on the Vulkan and CPU backends (s), default options.
    pub seconds_vulkan: Option<f64>,
    pub seconds_cpu: Option<f64>,
}

impl DeviceProfile {
    /// The Markdown table: per kernel time, share, bytes, achieved rate and its fraction of
    /// the streaming rate; then dispatch overhead and the end-to-end comparison.
    pub fn table(&self) -> String {
        let names = ["face_newton", "edge_project", "dual_update"];
        let device_ns: f64 = self.kernel_ns.iter().sum();
        let mut t = format!(
            "{} ({} faces) on {} — {} profiled iterations; streaming rate (saxpy) {:.2} GB/s\n\n\
             | kernel | µs/iteration | share | KB/iteration | GB/s achieved | % of streaming |\n\
             |---|---|---|---|---|---|\n",
            self.mesh, self.faces, self.device, self.iterations, self.stream_gbs
        );
        for k in 0..3 {
            let gbs = self.kernel_bytes[k] as f64 / self.kernel_ns[k].max(1e-9);
            let _ = writeln!(
                t,
                "| {} | {:.1} | {:.0} % | {:.1} | {:.2} | {:.0} % |",
                names[k],
                self.kernel_ns[k] / 1e3,
                100.0 * self.kernel_ns[k] / device_ns.max(1e-9),
                self.kernel_bytes[k] as f64 / 1e3,
                gbs,
                100.0 * gbs / self.stream_gbs.max(1e-9)
            );
        }
        let bytes: u64 = self.kernel_bytes.iter().sum();
        let rows = [
            ("iteration, device (kernels timed apart)", device_ns),
            (
                "iteration, device (unprofiled batches)",
                self.device_ns_per_iteration,
            ),
        ];
        for (what, ns) in rows {
            let gbs = bytes as f64 / ns.max(1e-9);
            let _ = writeln!(
                t,
                "| {what} | {:.1} | | {:.1} | {:.2} | {:.0} % |",
                ns / 1e3,
                bytes as f64 / 1e3,
                gbs,
                100.0 * gbs / self.stream_gbs.max(1e-9)
            );
        }
        let _ = writeln!(
            t,
            "| iteration, wall (unprofiled batches of the driver) | {:.1} | | | | |",
            self.wall_ns_per_iteration / 1e3
        );
        let _ = writeln!(
            t,
            "| dispatch + submission + host overhead (wall − device) | {:.1} | | | | |",
            (self.wall_ns_per_iteration - self.device_ns_per_iteration) / 1e3
        );
        let secs = |s: Option<f64>| s.map_or("failed".to_string(), |s| format!("{s:.2} s"));
        let ratio = match (self.seconds_vulkan, self.seconds_cpu) {
            (Some(v), Some(c)) if v > 0.0 => format!("; CPU / Vulkan = {:.2}×", c / v),
            _ => String::new(),
        };
        let _ = writeln!(
            t,
            "\nend to end (`foldfree param`, defaults): Vulkan {}, CPU {}{ratio}",
            secs(self.seconds_vulkan),
            secs(self.seconds_cpu)
        );
        t
    }
}

/// Profiles the ADMM iteration of `mesh` on `ctx`: `iterations` iterations with a timestamp
/// around every kernel (one submission per iteration), the same number in the driver's
/// unprofiled batches of `check_every` timed by wall clock (the difference is the dispatch and
/// host overhead), the device's streaming rate, and `foldfree param` end to end on both
/// backends writing into `out_dir`.
pub fn profile_mesh(
    ctx: &crate::gpu::Context,
    mesh_path: &std::path::Path,
    iterations: usize,
    out_dir: &std::path::Path,
) -> Result<DeviceProfile> {
    use crate::param::admm::driver::Executor;
    use crate::param::admm::{vulkan::VulkanExecutor, AdmmProblem, AdmmState};
    let (mesh, topo, _) = crate::mesh::load(mesh_path, &crate::mesh::ValidateOptions::default())?;
    topo.require_disk(mesh_path)?;
    let (_, unit) = crate::mesh::Scale::normalized(&mesh);
    let frames = crate::mesh::frames::compute(&unit);
    let mut uv = crate::init::initial_map(&unit, &topo, crate::init::InitMethod::Lscm)?;
    crate::init::normalize_area(&unit, &mut uv, frames.area.iter().sum());
    let problem = AdmmProblem::new(&unit, &topo, &frames);
    let opts = AdmmOptions::default();
    let mu = opts.initial_mu_rel() / problem.n_faces().max(1) as f64;
    let state = AdmmState::from_uv(&problem, &unit.faces, &uv);
    let factors = crate::param::admm::cpu::penalty_factors(opts.energy, &problem.weight, &state.a);
    let iterations = iterations.max(1);

    let mut profiled =
        VulkanExecutor::new(ctx, &problem, opts.energy, opts.newton_iters, true, None)?;
    profiled.upload(&state, &factors)?;
    profiled.iterate(iterations, mu)?;
    let times = profiled.kernel_times().cloned().unwrap_or_default();
    let kernel_bytes = profiled.kernel_bytes();
    drop(profiled);

    // Unprofiled batches, as the driver submits them, with one timestamp pair per batch.
    let stats = std::sync::Arc::new(crate::param::admm::vulkan::SliceStats::default());
    let slicing = crate::param::admm::vulkan::Slicing {
        timeline: crate::gpu::Timeline::new(ctx, "bench.profile.timeline")?,
        budget: std::time::Duration::MAX,
        handoff: None,
        stats: stats.clone(),
    };
    let mut plain = VulkanExecutor::new(
        ctx,
        &problem,
        opts.energy,
        opts.newton_iters,
        false,
        Some(slicing),
    )?;
    plain.upload(&state, &factors)?;
    let t = std::time::Instant::now();
    let mut done = 0;
    while done < iterations {
        let n = opts.check_every.max(1).min(iterations - done);
        plain.iterate(n, mu)?;
        done += n;
    }
    let wall = t.elapsed().as_nanos() as f64 / iterations as f64;
    drop(plain);
    let batched =
        stats.device_ns.load(std::sync::atomic::Ordering::Relaxed) as f64 / iterations as f64;

    let per = |ns: u64| ns as f64 / times.iterations.max(1) as f64;
    let stem = mesh_path
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    let end_to_end = |backend: BackendChoice| -> Option<f64> {
        let mut job = ParamJob::new(mesh_path, out_dir.join(format!("{stem}-{backend:?}.obj")));
        job.backend = backend;
        run_param(&job, &mut |_| {}).ok().map(|o| o.report.seconds)
    };
    Ok(DeviceProfile {
        mesh: stem.clone(),
        faces: mesh.faces.len(),
        device: ctx.device_name().to_string(),
        iterations,
        kernel_ns: [
            per(times.face_newton_ns),
            per(times.edge_project_ns),
            per(times.dual_update_ns),
        ],
        kernel_bytes,
        stream_gbs: device_bandwidth(ctx, 1 << 24, 5)?,
        wall_ns_per_iteration: wall,
        device_ns_per_iteration: batched,
        seconds_vulkan: end_to_end(BackendChoice::Vulkan),
        seconds_cpu: end_to_end(BackendChoice::Cpu),
    })
}
