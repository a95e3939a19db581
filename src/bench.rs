//! `foldfree bench`: runs `param` over meshes × energies × backends in one process and prints
//! a Markdown table (the source of the numbers in BENCHMARKS.md). Timing lives here, never in
//! unit tests.
#![forbid(unsafe_code)]

use std::fmt::Write as _;
use std::path::PathBuf;

use crate::param::admm::AdmmOptions;
use crate::param::Energy;
use crate::pipeline::{run_param, BackendChoice, ParamJob};
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
        "| mesh | faces | energy | backend | iterations | converged | s/iteration | solve s | total s | δcon mean | SD | flips |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
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
                        let line = format!(
                            "| {stem} | {} | {} | {} ({}) | {} | {} | {:.4} | {:.2} | {:.2} | {:.4} | {:.4} | {} |",
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
