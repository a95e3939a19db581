//! Properties of the ADMM driver on the CPU backend: whatever the settings, the returned map is
//! flip-free; a stop request is honoured; on a flat mesh the answer is exact.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use foldfree::init::tutte::TutteWeights;
use foldfree::init::InitMethod;
use foldfree::mesh::{self, Topology, TriMesh};
use foldfree::param::admm::{self, cpu::CpuExecutor, driver::map_energy, AdmmOptions, AdmmProblem};
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

/// A disk whose conformal map spans many orders of magnitude in scale: a flat annulus (radii
/// 3..1) with a tube of radius 1 and length `len` standing on its inner circle, closed by a
/// hemisphere, `n` vertices per ring. The conformal map shrinks the tube by about `e^−len`
/// (log-polar: one unit of tube length is one unit of log radius), so its faces' MIPS
/// curvature is ~`e^{2 len}` times the annulus's.
fn finger(n: usize, len: f64) -> TriMesh {
    use std::f64::consts::{FRAC_PI_2, TAU};
    let step = TAU / n as f64;
    let mut rings: Vec<(f64, f64)> = Vec::new();
    let na = ((2.0 / step) as usize).max(2);
    rings.extend((0..=na).map(|i| (3.0 - 2.0 * i as f64 / na as f64, 0.0)));
    let nt = (len / step) as usize;
    rings.extend((1..=nt).map(|i| (1.0, len * i as f64 / nt as f64)));
    let nc = ((FRAC_PI_2 / step) as usize).max(2);
    rings.extend((1..nc).map(|i| {
        let phi = FRAC_PI_2 * i as f64 / nc as f64;
        (phi.cos(), len + phi.sin())
    }));
    let mut positions = Vec::new();
    for &(r, z) in &rings {
        for k in 0..n {
            let a = step * k as f64;
            positions.push([r * a.cos(), r * a.sin(), z]);
        }
    }
    let apex = positions.len() as u32;
    positions.push([0.0, 0.0, len + 1.0]);
    let mut faces = Vec::new();
    let n32 = n as u32;
    for j in 0..rings.len() as u32 - 1 {
        for k in 0..n32 {
            let (a, b) = (j * n32 + k, j * n32 + (k + 1) % n32);
            let (c, d) = (a + n32, b + n32);
            faces.push([a, b, d]);
            faces.push([a, d, c]);
        }
    }
    let last = (rings.len() as u32 - 1) * n32;
    for k in 0..n32 {
        faces.push([last + k, last + (k + 1) % n32, apex]);
    }
    TriMesh { positions, faces }
}

/// The default pipeline (LSCM start, ADMM with the hand-off) on `finger(16, 8)`.
fn finger_map(energy: Energy) -> (TriMesh, Topology, foldfree::param::MapOutput) {
    let m = finger(16, 8.0);
    let (_, t) = mesh::validate::validate_with_topology(
        &m,
        Path::new("finger"),
        &mesh::ValidateOptions::default(),
    )
    .expect("the finger is a valid disk");
    let out = foldfree::param::compute_map(
        &m,
        &t,
        InitMethod::Lscm,
        foldfree::param::SolverChoice::Admm,
        &AdmmOptions::for_energy(energy),
        None,
        &mut |_| {},
    )
    .expect("map");
    (m, t, out)
}

/// Per-face penalties ([`admm::cpu::penalty_factors`]): on a finger whose conformal map shrinks
/// the tube by ~e^−8 (faces 1e-7 of the annulus's area), MIPS ADMM from LSCM meets its own stop
/// test — no hand-off to the global solver — with a flip-free map. With one penalty for all
/// faces, the tube's faces (curvature ~1e7 × the annulus's) stayed uncoupled and the run
/// stalled at its μ cap (measured: 2 757 iterations, then the hand-off).
#[test]
fn admm_alone_converges_where_the_conformal_scale_spans_seven_decades() {
    use foldfree::param::SolverPath;
    let (m, t, out) = finger_map(Energy::Mips);
    let admm = out.admm.as_ref().expect("ADMM ran");
    let tube_scale = {
        let frames = mesh::frames::compute(&m);
        let p = AdmmProblem::new(&m, &t, &frames);
        let start = start(&m, &t, InitMethod::Lscm);
        let dets: Vec<f64> = (0..m.faces.len())
            .map(|f| foldfree::param::energy::det(&p.jacobian(&m.faces, &start, f)))
            .collect();
        dets.iter().copied().fold(f64::INFINITY, f64::min)
            / dets.iter().copied().fold(0.0, f64::max)
    };
    assert!(
        tube_scale < 1e-6,
        "the start map spans {tube_scale:e} in area scale"
    );
    assert_eq!(out.path, SolverPath::Admm, "{}", admm.stop_summary());
    assert!(admm.converged());
    assert_eq!(foldfree::init::count_flips(&m.faces, &out.uv), 0);
}

/// SD's ADMM start ([`foldfree::param::compute_map`]): from the finger's conformal start, whose
/// tube SD wants ~e^8 times larger, a few proxy steps of the global solver move the area back
/// (each lowering the energy by more than 10 %), and ADMM converges from there without the
/// hand-off (measured: 7 proxy steps, then 1 125 ADMM iterations instead of 3 650 from the
/// conformal start).
#[test]
fn sd_admm_starts_from_proxy_steps_and_converges_alone() {
    use foldfree::param::SolverPath;
    let (m, _, out) = finger_map(Energy::SymmetricDirichlet);
    assert!(
        (1..=50).contains(&out.start_proxy_iterations),
        "{} proxy steps",
        out.start_proxy_iterations
    );
    assert_eq!(out.path, SolverPath::Admm, "{}", out.stop_summary());
    assert!(out.stop_summary().starts_with("start: "));
    assert_eq!(foldfree::init::count_flips(&m.faces, &out.uv), 0);
    let admm = out.admm.as_ref().expect("ADMM ran");
    assert!(
        admm.iterations < 3000,
        "{} ADMM iterations",
        admm.iterations
    );
}
