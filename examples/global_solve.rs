//! Runs the global solver on one disk mesh with tuning knobs the CLI does not expose, and
//! prints its per-iteration history and the `metrics::evaluate` scores (used for the
//! BENCHMARKS.md section of `--solver global`).
//!
//! `cargo run --release --example global_solve -- MESH.obj [sd|mips] [--pcg] [--pre jacobi|ic0|amg]
//!  [--cap X|none] [--no-exact] [--proxy-switch R] [--cg-proxy T] [--cg-newton T] [--max-iters N] [--lscm] [--mvc] [--no-bijective] [-q]
//!  [--ttq TARGET]`
//!
//! `--ttq TARGET` (time to quality) also reruns the (deterministic) solver with an iteration
//! cap of 1, 2, … until the `metrics::evaluate` score (SD for sd, mean δcon for mips) is at
//! most TARGET, and prints that run's iterations and solve time.

use foldfree::init::tutte::TutteWeights;
use foldfree::init::{initial_map, normalize_area, InitMethod};
use foldfree::linalg::direct::LinearSolver;
use foldfree::linalg::precond::Preconditioner;
use foldfree::mesh;
use foldfree::param::global::{self, GlobalOptions};
use foldfree::param::Energy;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args
        .first()
        .ok_or("usage: global_solve MESH.obj [sd|mips] [options]")?;
    let energy = if args.iter().any(|a| a == "mips") {
        Energy::Mips
    } else {
        Energy::SymmetricDirichlet
    };
    let mut opts = GlobalOptions::for_energy(energy);
    let mut lscm = false;
    let mut mvc = false;
    let mut quiet = false;
    let mut ttq: Option<f64> = None;
    let mut it = args.iter().skip(1);
    while let Some(a) = it.next() {
        let mut val = || it.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            // PCG instead of the sparse Cholesky, with the preconditioner of `--pre`.
            "--pcg" => opts.linear_solver = LinearSolver::Pcg,
            "--pre" => {
                opts.preconditioner = match val()?.as_str() {
                    "jacobi" => Preconditioner::Jacobi,
                    "ic0" => Preconditioner::Ic0,
                    "amg" => Preconditioner::Amg { block_size: 2 },
                    p => return Err(format!("unknown preconditioner {p}").into()),
                }
            }
            "--cap" => {
                let v = val()?;
                opts.progressive_cap = if v == "none" { None } else { Some(v.parse()?) };
            }
            "--no-exact" => opts.exact_newton = false,
            "--proxy-switch" => opts.proxy_switch = val()?.parse()?,
            "--cg-proxy" => opts.cg_tol_proxy = val()?.parse()?,
            "--cg-newton" => opts.cg_tol_newton = val()?.parse()?,
            "--max-iters" => opts.max_iters = val()?.parse()?,
            "--lscm" => lscm = true,
            "--mvc" => mvc = true,
            // The unconstrained solve (the scaffold off): the map's boundary may overlap.
            "--no-bijective" => opts.bijective = false,
            "-q" => quiet = true,
            "--ttq" => ttq = Some(val()?.parse()?),
            "sd" | "mips" => {}
            o => return Err(format!("unknown option {o}").into()),
        }
    }
    let (m, topo, _) = mesh::load(
        std::path::Path::new(path),
        &mesh::ValidateOptions::default(),
    )?;
    let frames = mesh::frames::compute(&m);
    let area: f64 = frames.area.iter().sum();
    let t = std::time::Instant::now();
    let tutte = InitMethod::Tutte(if mvc {
        TutteWeights::MeanValue
    } else {
        TutteWeights::Uniform
    });
    let mut uv = initial_map(&m, &topo, if lscm { InitMethod::Lscm } else { tutte })?;
    if foldfree::init::count_flips(&m.faces, &uv) > 0 {
        // The solver never crosses det = 0: a folded LSCM start is replaced by Tutte.
        uv = initial_map(&m, &topo, tutte)?;
    }
    normalize_area(&m, &mut uv, area);
    let t_init = t.elapsed().as_secs_f64();
    let r = global::solve(&m, &frames, &uv, &opts, &mut |h| {
        if !quiet {
            println!(
                "{:3} {:12} obj {:.6} → {:.6}  E {:.6}  |g| {:.2e}  t {:.3} (max {:.3})  cg {:4}  capped {:5}  {:.2} s",
                h.iteration,
                format!("{:?}", h.phase),
                h.objective_before,
                h.objective_after,
                h.energy,
                h.grad_norm,
                h.step,
                h.max_step,
                h.cg_iterations,
                h.capped_faces,
                h.seconds
            );
        }
    })?;
    let solve = t.elapsed().as_secs_f64() - t_init;
    let me = foldfree::metrics::evaluate(&m.positions, &m.faces, &r.uv, &topo.boundary_loops);
    println!(
        "{path} {energy:?}: stop {:?} after {} its, init {t_init:.2} s, solve {solve:.2} s \
         (proxy {} its {:.2} s, newton {} its ({} exact, {} failed attempts) {:.2} s); E {:.6} |g| {:.2e}; \
         metrics: flips {} SD {:.5} mean δcon {:.5} MIPS {:.5}",
        r.stop,
        r.iterations,
        r.totals.proxy_iterations,
        r.totals.proxy_seconds,
        r.totals.newton_iterations,
        r.totals.exact_newton_iterations,
        r.totals.exact_newton_failures,
        r.totals.newton_seconds,
        r.energy,
        r.grad_norm,
        me.flips,
        me.sd_energy,
        me.delta_con_mean,
        me.mips_energy
    );
    if let Some(target) = ttq {
        let score = |uv: &[[f64; 2]]| {
            let me = foldfree::metrics::evaluate(&m.positions, &m.faces, uv, &topo.boundary_loops);
            match energy {
                Energy::SymmetricDirichlet => me.sd_energy,
                Energy::Mips => me.delta_con_mean,
            }
        };
        for k in 1..=opts.max_iters {
            let o = GlobalOptions {
                max_iters: k,
                ..opts.clone()
            };
            let t = std::time::Instant::now();
            let r = global::solve(&m, &frames, &uv, &o, &mut |_| {})?;
            let secs = t.elapsed().as_secs_f64();
            let s = score(&r.uv);
            if s <= target || r.iterations < k {
                println!(
                    "time to quality {target}: {} its, {secs:.2} s solve, score {s:.5}{}",
                    r.iterations,
                    if s <= target { "" } else { " (NOT reached)" }
                );
                break;
            }
        }
    }
    Ok(())
}
