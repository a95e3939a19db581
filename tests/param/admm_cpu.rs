//! Properties of the ADMM driver on the CPU backend: whatever the settings, the returned map is
//! flip-free; a stop request is honoured; on a flat mesh the answer is exact.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use foldfree::init::tutte::TutteWeights;
use foldfree::init::InitMethod;
use foldfree::param::admm::{self, cpu::CpuExecutor, driver::map_energy, AdmmOptions};
use foldfree::param::Energy;

use crate::{load, start};

/// An unstable penalty (μ·F = 0.1, no adaptation) on the hard camel still returns a flip-free
/// map: the best flip-free recovered map, or the Tutte fallback.
#[test]
fn unstable_penalty_still_returns_a_flip_free_map() {
    let (m, t, p) = load("camel_open.obj");
    let lscm = start(&m, &t, InitMethod::Lscm);
    let tutte = start(&m, &t, InitMethod::Tutte(TutteWeights::Uniform));
    for energy in [Energy::Mips, Energy::SymmetricDirichlet] {
        let mut o = AdmmOptions::for_energy(energy);
        o.mu_rel = Some(0.1);
        o.adaptive_mu = false;
        o.max_iters = 200;
        let mut exec = CpuExecutor::new(&p, energy, 1);
        let r = admm::solve(
            &p,
            &m.faces,
            &lscm,
            Some(&tutte),
            &o,
            &mut exec,
            &mut |_| {},
        )
        .expect("solve");
        let (e, flips) = map_energy(&p, &m.faces, &r.uv, energy);
        assert_eq!(flips, 0, "{energy:?}: returned map flips");
        assert_eq!(r.flips, 0);
        assert!(e.is_finite());
        assert!(r.uv.iter().all(|q| q[0].is_finite() && q[1].is_finite()));
    }
}

/// A stop flag set before the first batch ends the solve after one batch with `interrupted`,
/// returning a flip-free map.
#[test]
fn stop_flag_interrupts_and_keeps_a_flip_free_map() {
    let (m, t, p) = load("camel_open.obj");
    let lscm = start(&m, &t, InitMethod::Lscm);
    let tutte = start(&m, &t, InitMethod::Tutte(TutteWeights::Uniform));
    let mut o = AdmmOptions::for_energy(Energy::Mips);
    o.stop = Some(Arc::new(AtomicBool::new(true)));
    let mut exec = CpuExecutor::new(&p, Energy::Mips, 1);
    let r = admm::solve(
        &p,
        &m.faces,
        &lscm,
        Some(&tutte),
        &o,
        &mut exec,
        &mut |_| {},
    )
    .expect("solve");
    assert!(r.interrupted() && !r.converged());
    assert_eq!(r.iterations, 0);
    assert_eq!(map_energy(&p, &m.faces, &r.uv, Energy::Mips).1, 0);
}

/// The job keeps an interrupted run's map: `run_param` writes the best flip-free map, says
/// it did not converge (the CLI's exit 3) and does not hand off (the user asked to stop).
#[test]
fn an_interrupted_job_writes_its_best_map_and_reports_not_converged() {
    let dir = std::env::temp_dir().join(format!("foldfree-interrupt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let out = dir.join("camel.obj");
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/camel_open.obj");
    let mut job = foldfree::param::ParamJob::new(&input, &out);
    job.backend = foldfree::param::BackendChoice::Cpu;
    job.admm.stop = Some(Arc::new(AtomicBool::new(true)));
    let r = foldfree::param::run_param(&job, &mut |_| {})
        .expect("job")
        .report;
    assert_eq!(r.converged, Some(false));
    assert!(r.written && out.exists());
    assert_eq!(r.solver_path, "admm");
    assert_eq!(r.iterations_global, 0);
    assert_eq!(r.flips, 0);
    assert!(r.stop.contains("interrupted"), "{}", r.stop);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A flat square from its (distorted) Tutte map: with tight tolerances ADMM finds the isometry
/// up to similarity for both energies and says it converged.
#[test]
fn flat_grid_converges_to_the_exact_answer_from_tutte() {
    let (m, t, p) = load("square_grid_10x10.obj");
    let tutte = start(&m, &t, InitMethod::Tutte(TutteWeights::Uniform));
    for energy in [Energy::Mips, Energy::SymmetricDirichlet] {
        let mut o = AdmmOptions::for_energy(energy);
        o.tol_energy = 1e-9;
        o.max_iters = 6000;
        let mut exec = CpuExecutor::new(&p, energy, 1);
        let r = admm::solve(&p, &m.faces, &tutte, None, &o, &mut exec, &mut |_| {}).expect("solve");
        let metrics = foldfree::metrics::evaluate(&m.positions, &m.faces, &r.uv, &t.boundary_loops);
        assert!(
            r.converged(),
            "{energy:?} did not converge in {} iterations",
            r.iterations
        );
        assert_eq!(metrics.flips, 0);
        assert!(
            metrics.delta_con_max < 1.001,
            "{energy:?}: δ max {}",
            metrics.delta_con_max
        );
        assert!(
            metrics.sd_energy < 4.0 + 1e-4,
            "{energy:?}: SD {}",
            metrics.sd_energy
        );
    }
}

/// The first residual check of the iteration is the same whether the iteration is run by the
/// CPU executor in one batch or step by step through `cpu::iteration` (the executor adds no
/// hidden state).
#[test]
fn executor_batches_equal_single_iterations() {
    use foldfree::param::admm::driver::Executor;
    let (m, t, p) = load("camel_open.obj");
    let lscm = start(&m, &t, InitMethod::Lscm);
    let s0 = admm::AdmmState::from_uv(&p, &m.faces, &lscm);
    let mu = 100.0 / p.n_faces() as f64;
    let factor = admm::cpu::penalty_factors(Energy::SymmetricDirichlet, &p.weight, &s0.a);
    let mut exec = CpuExecutor::new(&p, Energy::SymmetricDirichlet, 1);
    exec.upload(&s0, &factor).expect("upload");
    exec.iterate(5, mu).expect("iterate");
    let batched = exec.download().expect("download");
    let pen = admm::cpu::Penalty {
        mu,
        factor: &factor,
    };
    let mut s = s0.clone();
    for _ in 0..5 {
        admm::cpu::iteration(&p, &mut s, Energy::SymmetricDirichlet, 1, pen);
    }
    assert_eq!(batched, s);
}

/// Breadth-first recovery of the Jacobians of a map gives back that map (up to the pinned first
/// corner, which keeps its position), exactly where the per-face maps agree; least squares gives
/// the same map. With the per-face maps perturbed, breadth-first accumulates the error along the
/// traversal, least squares spreads it: its error stays smaller.
#[test]
fn breadth_first_recovery_reproduces_a_consistent_map() {
    use foldfree::param::recover::{breadth_first, LeastSquaresRecovery};
    let (m, t, p) = load("camel_open.obj");
    let uv0 = start(&m, &t, InitMethod::Tutte(TutteWeights::Uniform));
    let a: Vec<[f64; 4]> = (0..m.faces.len())
        .map(|f| p.jacobian(&m.faces, &uv0, f))
        .collect();
    let max_err = |uv: &[[f64; 2]]| {
        uv.iter()
            .zip(&uv0)
            .map(|(x, y)| (x[0] - y[0]).hypot(x[1] - y[1]))
            .fold(0.0f64, f64::max)
    };
    // Start from a scrambled map: only the pinned corner's value may be used.
    let scrambled: Vec<[f64; 2]> = uv0
        .iter()
        .enumerate()
        .map(|(i, x)| {
            if i == m.faces[0][0] as usize {
                *x
            } else {
                [7.0, -3.0]
            }
        })
        .collect();
    let mut bfs = scrambled.clone();
    breadth_first(&p, &m.faces, &a, &mut bfs);
    assert!(
        max_err(&bfs) < 1e-9,
        "breadth-first error {}",
        max_err(&bfs)
    );
    let ls = LeastSquaresRecovery::new(&p, &m.faces, uv0.len()).expect("recovery");
    let mut lsq = scrambled.clone();
    ls.recover(&a, &mut lsq).expect("recover");
    assert!(
        max_err(&lsq) < 1e-6,
        "least-squares error {}",
        max_err(&lsq)
    );

    // Deterministic perturbation of every per-face map by up to 1e-3.
    let noisy: Vec<[f64; 4]> = a
        .iter()
        .enumerate()
        .map(|(f, x)| std::array::from_fn(|i| x[i] + 1e-3 * ((f * 4 + i) as f64 * 0.7).sin()))
        .collect();
    let mut bfs = scrambled.clone();
    breadth_first(&p, &m.faces, &noisy, &mut bfs);
    let mut lsq = scrambled;
    ls.recover(&noisy, &mut lsq).expect("recover");
    assert!(
        max_err(&lsq) < max_err(&bfs),
        "least squares {} vs breadth-first {}",
        max_err(&lsq),
        max_err(&bfs)
    );
}
