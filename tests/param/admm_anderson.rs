//! Anderson acceleration of the CPU ADMM iteration (`[admm] accel = "anderson"` in a tuning file): it must reach a tighter
//! consensus than plain ADMM in the same number of iterations, never cost more than plain ADMM
//! plus the rejected steps, keep every returned map flip-free, and be refused on Vulkan.

use std::process::Command;

use foldfree::init::tutte::TutteWeights;
use foldfree::init::InitMethod;
use foldfree::mesh::TriMesh;
use foldfree::param::admm::driver::{map_energy, Executor};
use foldfree::param::admm::{self, cpu::CpuExecutor, Accel, AdmmOptions, AdmmProblem, AdmmState};
use foldfree::param::Energy;

use crate::common::data;
use crate::{load, start};

/// Relative primal and dual residuals after `iters` iterations at a fixed stable μ.
fn residual_after(
    p: &AdmmProblem,
    m: &TriMesh,
    uv: &[[f64; 2]],
    energy: Energy,
    mu_rel: f64,
    iters: usize,
    accel: Accel,
) -> (f64, f64, Option<(usize, usize)>) {
    let mut exec = CpuExecutor::new(p, energy, 1).with_accel(accel, 6, 1);
    let state = AdmmState::from_uv(p, &m.faces, uv);
    let factors = foldfree::param::admm::cpu::penalty_factors(energy, &p.weight, &state.a);
    exec.upload(&state, &factors).expect("upload");
    let r = exec
        .iterate(iters, mu_rel / p.n_faces() as f64)
        .expect("iterate");
    let norm = r.anorm2.sqrt();
    (
        r.primal2.sqrt() / norm,
        r.dual2.sqrt() / norm,
        exec.accel_stats(),
    )
}

/// Camel, symmetric Dirichlet at μ·F = 100 (stable there, but slow): after 300 iterations the
/// accelerated iteration's primal residual is well below plain ADMM's, and every iteration is
/// accounted for as an accepted or a rejected accelerated step.
#[test]
fn anderson_tightens_the_consensus_faster_than_plain_admm() {
    let (m, t, p) = load("camel_open.obj");
    let uv = start(&m, &t, InitMethod::Lscm);
    let e = Energy::SymmetricDirichlet;
    let (plain_primal, _, plain_stats) = residual_after(&p, &m, &uv, e, 100.0, 300, Accel::None);
    let (aa_primal, aa_dual, stats) = residual_after(&p, &m, &uv, e, 100.0, 300, Accel::Anderson);
    assert!(plain_stats.is_none());
    let (accepted, rejected) = stats.expect("accelerating");
    assert_eq!(accepted + rejected, 300);
    assert!(
        accepted > rejected,
        "{accepted} accepted, {rejected} rejected"
    );
    assert!(
        aa_primal < 0.5 * plain_primal,
        "primal: anderson {aa_primal:e} vs plain {plain_primal:e}"
    );
    assert!(aa_dual.is_finite());
}

/// Whatever the penalty (here an unstable μ·F = 0.1, no adaptation), the accelerated solve
/// returns a flip-free map.
#[test]
fn anderson_under_an_unstable_penalty_still_returns_a_flip_free_map() {
    let (m, t, p) = load("camel_open.obj");
    let lscm = start(&m, &t, InitMethod::Lscm);
    let tutte = start(&m, &t, InitMethod::Tutte(TutteWeights::Uniform));
    for energy in [Energy::Mips, Energy::SymmetricDirichlet] {
        let mut o = AdmmOptions::for_energy(energy);
        o.mu_rel = Some(0.1);
        o.adaptive_mu = false;
        o.max_iters = 150;
        o.accel = Accel::Anderson;
        o.aa_start = Some(0);
        let mut exec = CpuExecutor::new(&p, energy, 1).with_accel(o.accel, o.aa_depth, o.aa_every);
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
        assert!(e.is_finite());
        let last = r.history.last().expect("at least one check");
        assert_eq!(
            last.accel_accepted
                .zip(last.accel_rejected)
                .map(|(a, b)| a + b),
            Some(150)
        );
    }
}

/// Acceleration starts after `aa_start` plain iterations (short runs pay nothing for it): the
/// accelerated iterations counted are exactly the ones after it, and a run that converges
/// before it counts none.
#[test]
fn anderson_starts_after_the_plain_iterations_asked_for() {
    let (m, t, p) = load("camel_open.obj");
    let lscm = start(&m, &t, InitMethod::Lscm);
    let energy = Energy::SymmetricDirichlet;
    for (start_at, max_iters, counted) in [(50, 100, 50), (1000, 50, 0)] {
        let mut o = AdmmOptions::for_energy(energy);
        o.max_iters = max_iters;
        o.accel = Accel::Anderson;
        o.aa_start = Some(start_at);
        let mut exec = CpuExecutor::new(&p, energy, 1).with_accel(o.accel, o.aa_depth, o.aa_every);
        let r = admm::solve(&p, &m.faces, &lscm, None, &o, &mut exec, &mut |_| {}).expect("solve");
        let last = r.history.last().expect("at least one check");
        assert_eq!(
            last.accel_accepted
                .zip(last.accel_rejected)
                .map(|(a, b)| a + b),
            Some(counted),
            "aa_start {start_at}"
        );
        assert_eq!(r.flips, 0);
    }
}

/// The Vulkan backend has no Anderson kernels: asking for both is a usage error (exit code 2)
/// that names the fix, before any device is touched.
#[test]
fn anderson_on_vulkan_is_refused_with_a_usage_error() {
    let out = std::env::temp_dir().join(format!("foldfree_aa_{}.obj", std::process::id()));
    let tuning = out.with_extension("toml");
    std::fs::write(&tuning, "[admm]\naccel = \"anderson\"\n").expect("write tuning");
    let run = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .arg("param")
        .arg(data("two_triangles.obj"))
        .arg("-o")
        .arg(&out)
        .arg("--tuning")
        .arg(&tuning)
        .args(["--backend", "vulkan", "-q"])
        .output()
        .expect("run foldfree");
    assert_eq!(run.status.code(), Some(2));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("--backend cpu"), "stderr: {err}");
    assert!(!out.exists());
    let _ = std::fs::remove_file(&tuning);
}
