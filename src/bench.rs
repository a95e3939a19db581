//! `foldfree bench`: runs `param` over meshes × energies × backends in one process and prints
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

/// Runs every combination; a failed run becomes a row with the error text.
pub fn run_bench(job: &BenchJob, mut log: impl FnMut(&str)) -> Result<(Vec<BenchRow>, String)> {
    std::fs::create_dir_all(&job.out_dir).map_err(|source| crate::Error::Io {
        path: job.out_dir.clone(),
        source,
    })?;
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
                let tag = format!("{stem}-{energy:?}-{backend:?}").to_lowercase();
                let mut pj = ParamJob::new(mesh, job.out_dir.join(format!("{tag}.obj")));
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
                    }
                }
            }
        }
    }
    Ok((rows, table))
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
