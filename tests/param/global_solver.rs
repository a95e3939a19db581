//! The global solver (`--solver global`, `param::global`): exactness on a flat grid, quality
//! and validity on the camel, derivative and step-bound checks, monotone descent, the CLI.

use std::path::Path;
use std::process::Command;

use crate::common::{Rng, TempDir};
use foldfree::init::tutte::TutteWeights;
use foldfree::init::{initial_map, normalize_area, InitMethod};
use foldfree::mesh::{self, FaceFrames, Topology, TriMesh};
use foldfree::metrics;
use foldfree::param::global::{self, line_search, GlobalOptions, Phase, StopReason};
use foldfree::param::Energy;

fn load(name: &str) -> (TriMesh, Topology, FaceFrames, Vec<[f64; 2]>) {
    let (m, topo) = crate::common::load(name);
    let frames = mesh::frames::compute(&m);
    let area: f64 = frames.area.iter().sum();
    let mut uv =
        initial_map(&m, &topo, InitMethod::Tutte(TutteWeights::Uniform)).expect("tutte start");
    normalize_area(&m, &mut uv, area);
    (m, topo, frames, uv)
}

#[test]
fn flat_grid_reaches_the_isometry() {
    let (m, topo, frames, uv) = load("square_grid_10x10.obj");
    // The Tutte start puts the boundary on a circle: far from isometric.
    let start = metrics::evaluate(&m.positions, &m.faces, &uv, &topo.boundary_loops);
    assert!(start.sd_energy > 5.0, "start SD {}", start.sd_energy);
    let r = global::solve(
        &m,
        &frames,
        &uv,
        &GlobalOptions::for_energy(Energy::SymmetricDirichlet),
        &mut |_| {},
    )
    .expect("solve");
    assert_eq!(r.stop, StopReason::GradientTolerance);
    assert!((r.energy - 4.0).abs() < 1e-9, "solver SD {}", r.energy);
    let me = metrics::evaluate(&m.positions, &m.faces, &r.uv, &topo.boundary_loops);
    assert_eq!(me.flips, 0);
    assert!(
        (me.sd_energy - 4.0).abs() < 1e-9,
        "metrics SD {}",
        me.sd_energy
    );
    assert!(
        (me.delta_con_max - 1.0).abs() < 1e-5,
        "max δcon {}",
        me.delta_con_max
    );
}

#[test]
fn camel_sd_reaches_slim_quality_flip_free_with_monotone_descent() {
    let (m, topo, frames, uv) = load("camel_open.obj");
    let mut seen = Vec::new();
    let r = global::solve(
        &m,
        &frames,
        &uv,
        &GlobalOptions::for_energy(Energy::SymmetricDirichlet),
        &mut |h| seen.push(h.clone()),
    )
    .expect("solve");
    let me = metrics::evaluate(&m.positions, &m.faces, &r.uv, &topo.boundary_loops);
    assert_eq!(me.flips, 0);
    // libigl SLIM's converged value on this mesh (../shared/peers.md) is 4.0915.
    assert!(me.sd_energy <= 4.0915 * 1.01, "SD {}", me.sd_energy);
    // Converged by its energy test (or the gradient's, which is sufficient).
    assert!(
        matches!(
            r.stop,
            StopReason::EnergyConverged | StopReason::GradientTolerance
        ),
        "{:?}",
        r.stop
    );
    assert!(r.energy_decrease <= 1e-6 || r.grad_norm <= 1e-6);
    // Both phases ran, the proxy first.
    assert_eq!(seen[0].phase, Phase::Proxy);
    assert!(seen.iter().any(|h| h.phase != Phase::Proxy));
    assert_eq!(seen.len(), r.history.len());
    for h in &r.history {
        assert!(
            h.objective_after <= h.objective_before,
            "iteration {}",
            h.iteration
        );
        assert!(h.step > 0.0 && h.step < h.max_step);
    }
    // On the true reference (no capped faces) the objective is the energy: monotone.
    let true_ref: Vec<_> = r.history.iter().filter(|h| h.capped_faces == 0).collect();
    assert!(true_ref.len() > 3);
    for w in true_ref.windows(2) {
        assert!(w[1].energy <= w[0].energy);
    }
}

/// Without progressive references every step lowers the true energy, with the scaffold on or
/// off (the scaffold starts every step at its rest shape, zero gradient, so a step that lowers
/// the sum cannot raise the chart's part); unconstrained, each iteration's objective starts
/// where the last one ended.
#[test]
fn without_progressive_references_the_true_energy_decreases_monotonically() {
    let (m, _, frames, uv) = load("camel_open.obj");
    for bijective in [false, true] {
        let opts = GlobalOptions {
            progressive_cap: None,
            max_iters: 8,
            bijective,
            ..GlobalOptions::for_energy(Energy::SymmetricDirichlet)
        };
        let (e0, _) =
            global::objective_and_gradient(&m, &frames, Energy::SymmetricDirichlet, &uv).unwrap();
        let r = global::solve(&m, &frames, &uv, &opts, &mut |_| {}).expect("solve");
        let mut prev = e0;
        for h in &r.history {
            assert_eq!(h.capped_faces, 0);
            if !bijective {
                assert!((h.objective_before - prev).abs() <= 1e-12 * prev);
            }
            assert!(
                h.energy < prev,
                "bijective {bijective}, iteration {}: {} ≥ {prev}",
                h.iteration,
                h.energy
            );
            prev = h.energy;
        }
        assert_eq!(r.stop, StopReason::MaxIterations);
    }
}

#[test]
fn camel_mips_is_near_the_best_conformal_map() {
    let (m, topo, frames, uv) = load("camel_open.obj");
    let r = global::solve(
        &m,
        &frames,
        &uv,
        &GlobalOptions::for_energy(Energy::Mips),
        &mut |_| {},
    )
    .expect("solve");
    let me = metrics::evaluate(&m.positions, &m.faces, &r.uv, &topo.boundary_loops);
    assert_eq!(me.flips, 0);
    // Best mean δcon among peers (../shared/peers.md): 1.1363.
    assert!(
        me.delta_con_mean <= 1.1363 * 1.01,
        "δcon {}",
        me.delta_con_mean
    );
    // MIPS is scale-free: the result is returned at the 3D area.
    assert!((me.uv_area / me.area_3d - 1.0).abs() < 1e-9);
}

#[test]
fn mesh_gradient_matches_finite_differences() {
    let (m, _, frames, uv) = load("camel_open.obj");
    for energy in [Energy::SymmetricDirichlet, Energy::Mips] {
        let (e, g) = global::objective_and_gradient(&m, &frames, energy, &uv).unwrap();
        assert!(e.is_finite());
        let mut rng = Rng(7);
        for _ in 0..20 {
            let i = (rng.next() * (2 * uv.len()) as f64) as usize;
            // Relative step on the coordinate: central differences, O(h²) error.
            let h = 1e-7 * uv.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
            let mut up = uv.clone();
            let mut um = uv.clone();
            up[i / 2][i % 2] += h;
            um[i / 2][i % 2] -= h;
            let ep = global::objective_and_gradient(&m, &frames, energy, &up)
                .unwrap()
                .0;
            let em = global::objective_and_gradient(&m, &frames, energy, &um)
                .unwrap()
                .0;
            let fd = (ep - em) / (2.0 * h);
            let scale = g.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            assert!(
                (fd - g[i]).abs() <= 1e-5 * scale,
                "{energy:?} x[{i}]: fd {fd} vs {}",
                g[i]
            );
        }
    }
}

#[test]
fn max_flip_free_step_is_the_first_determinant_root() {
    // Random triangles (positively oriented in UV) and random directions: the step bound is
    // exactly where the first face degenerates.
    let mut rng = Rng(42);
    let g = [[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]];
    let faces = [[0u32, 1, 2]];
    let mut checked = 0;
    for _ in 0..500 {
        let mut x: Vec<f64> = (0..6).map(|_| rng.next() * 2.0 - 1.0).collect();
        let area = |x: &[f64]| (x[2] - x[0]) * (x[5] - x[1]) - (x[4] - x[0]) * (x[3] - x[1]);
        if area(&x) < 0.0 {
            x.swap(2, 4);
            x.swap(3, 5);
        }
        if area(&x) < 1e-3 {
            continue;
        }
        let d: Vec<f64> = (0..6).map(|_| rng.next() * 4.0 - 2.0).collect();
        let t = line_search::max_flip_free(&[g], &faces, &x, &d);
        let at = |s: f64| -> Vec<f64> { x.iter().zip(&d).map(|(a, b)| a + s * b).collect() };
        if t.is_finite() {
            assert!(area(&at(0.999 * t)) > 0.0);
            assert!(
                area(&at(1.001 * t)) < 0.0,
                "no sign change past the root {t}"
            );
            assert!(area(&at(t)).abs() < 1e-9);
            checked += 1;
        } else {
            for s in [0.5, 1.0, 10.0, 1e3] {
                assert!(area(&at(s)) > 0.0);
            }
        }
    }
    assert!(checked > 100, "only {checked} finite roots");
}

#[test]
fn a_folded_start_is_refused() {
    let (m, _, frames, mut uv) = load("square_grid_10x10.obj");
    for p in &mut uv {
        p[0] = -p[0]; // mirror: every face flips
    }
    let err = global::solve(
        &m,
        &frames,
        &uv,
        &GlobalOptions::for_energy(Energy::SymmetricDirichlet),
        &mut |_| {},
    );
    assert!(err.is_err());
}

/// `foldfree param --solver global -q -o OUT --report TMP/report.json EXTRA INPUT`, which must
/// succeed; its report.
fn param_report(tmp: &TempDir, input: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let report = tmp.join("report.json");
    let status = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .args(["param", "--solver", "global", "-q", "-o"])
        .arg(out)
        .arg("--report")
        .arg(&report)
        .args(extra)
        .arg(input)
        .status()
        .expect("run foldfree");
    assert!(status.success());
    serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap()
}

#[test]
fn cli_solver_global_writes_a_flip_free_map_and_its_report() {
    let tmp = TempDir::new("cli_solver_global");
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/square_grid_10x10.obj");
    let out = tmp.join("grid.obj");
    let r = param_report(&tmp, &input, &out, &["--energy", "sd"]);
    assert_eq!(r["solver"], "global");
    assert_eq!(r["init"], "tutte");
    assert_eq!(r["flips"], 0);
    assert_eq!(r["converged"], true);
    assert!((r["sd_energy"].as_f64().unwrap() - 4.0).abs() < 1e-9);
    assert_eq!(r["global"]["stop"], "gradient_tolerance");
    assert!(!r["global"]["history"].as_array().unwrap().is_empty());
    assert!(out.exists());
}

/// A start map the solver cannot start from is replaced by Tutte's, and the report says so and
/// why: LSCM folds camel_open (its ears), Tutte's own map is kept as it is.
#[test]
fn cli_report_counts_starts_replaced_by_tutte() {
    let tmp = TempDir::new("cli_tutte_starts");
    let input = crate::common::data_obj("camel_open");
    let mut seen = Vec::new();
    for init in ["lscm", "tutte"] {
        let r = param_report(&tmp, &input, &tmp.join("out.obj"), &["--init", init]);
        assert_eq!(r["init"], init);
        assert_eq!(r["flips"], 0);
        seen.push((r["init_flips"].clone(), r["tutte_starts"].clone()));
    }
    assert!(
        seen[0].0.as_u64().unwrap() > 0,
        "LSCM no longer folds camel_open: {seen:?}"
    );
    let count = |i: usize, k: &str| seen[i].1[k].as_u64().unwrap();
    assert_eq!(count(0, "folded"), 1, "{seen:?}");
    assert_eq!(
        count(0, "non_finite") + count(0, "boundary_crosses_itself"),
        0
    );
    assert_eq!(seen[1].0, 0);
    for k in ["folded", "non_finite", "boundary_crosses_itself"] {
        assert_eq!(count(1, k), 0, "{seen:?}");
    }
}

#[test]
fn cli_solver_global_refuses_admm_only_flags() {
    let tmp = TempDir::new("cli_solver_global_flags");
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/square_grid_10x10.obj");
    for extra in [&["--max-iters", "5"][..], &["--backend", "vulkan"][..]] {
        let out = Command::new(env!("CARGO_BIN_EXE_foldfree"))
            .args(["param", "--solver", "global", "-q", "-o"])
            .arg(tmp.join("x.obj"))
            .args(extra)
            .arg(&input)
            .output()
            .expect("run foldfree");
        assert_eq!(out.status.code(), Some(2), "{extra:?}");
        assert!(String::from_utf8_lossy(&out.stderr).contains("ADMM only"));
        assert!(!tmp.join("x.obj").exists());
    }
}

/// The stop test on scripted histories: an energy that converges (geometrically, to 4.1) while
/// the gradient norm stays far above its tolerance has converged; an energy still falling by
/// 1e-4 per iteration has not; iterations on progressive references do not count.
#[test]
fn stop_test_judges_the_energy_not_the_gradient() {
    use foldfree::param::global::stop::StopTest;
    let opts = GlobalOptions::for_energy(Energy::SymmetricDirichlet);
    let mut t = StopTest::new(&opts);
    let grad_norm = 1e-3; // 1000 × the gradient tolerance, throughout
    let mut met_at = None;
    for k in 0..100 {
        let e = 4.1 + 0.5 * 0.6f64.powi(k);
        assert!(!t.gradient_met(grad_norm, 0));
        if t.energy_met(e, 0) {
            met_at = Some(k);
            break;
        }
    }
    let k = met_at.expect("a converged energy stops the solver whatever its gradient norm");
    // Stopped once the decrease per iteration fell under 1e-6 of the energy, not earlier.
    let e = |k: i32| 4.1 + 0.5 * 0.6f64.powi(k);
    let w = opts.energy_window as i32;
    assert!((e(k - w) - e(k)) / (w as f64 * e(k)) <= opts.energy_tol);
    assert!((e(k - 1 - w) - e(k - 1)) / (w as f64 * e(k - 1)) > opts.energy_tol);

    // Still falling by 1e-4 of itself per iteration: never converged.
    let mut t = StopTest::new(&opts);
    assert!((0..200).all(|k| !t.energy_met(10.0 * (1.0 - 1e-4f64).powi(k), 0)));

    // A flat surrogate (progressive references) says nothing: the window restarts after it.
    let mut t = StopTest::new(&opts);
    assert!((0..10).all(|_| !t.energy_met(5.0, 3)));
    assert!((0..opts.energy_window).all(|_| !t.energy_met(5.0, 0)));
    assert!(t.energy_met(5.0, 0));
    assert!(t.gradient_met(opts.grad_tol, 0) && !t.gradient_met(opts.grad_tol, 1));
}

/// The hand-off: an ADMM run that stops short (a 50-iteration budget) hands its best flip-free
/// map to the global solver, which converges; the map is flip-free and at least as good as
/// ADMM's best, and the path says what ran.
#[test]
fn admm_that_stops_short_hands_off_to_the_global_solver() {
    use foldfree::param::{admm::AdmmOptions, compute_map, SolverChoice, SolverPath};
    let (m, topo, frames, _) = load("camel_open.obj");
    for energy in [Energy::Mips, Energy::SymmetricDirichlet] {
        let mut opts = AdmmOptions::for_energy(energy);
        opts.max_iters = 50;
        let out = compute_map(
            &m,
            &topo,
            InitMethod::Lscm,
            SolverChoice::Admm,
            // The unconstrained pipeline's promise (never worse than ADMM's best map); the
            // bijective one may restart from Tutte (bijective_* tests below).
            false,
            &opts,
            None,
            &mut |_| {},
        )
        .expect("map");
        assert_eq!(out.path, SolverPath::AdmmGlobal, "{energy:?}");
        assert!(out.converged(), "{energy:?}: {}", out.stop_summary());
        let admm = out.admm.as_ref().expect("admm ran");
        assert_eq!(admm.stop, foldfree::param::admm::AdmmStop::MaxIterations);
        let g = out.global.as_ref().expect("global ran");
        assert!(g.converged());
        assert_eq!(foldfree::init::count_flips(&m.faces, &out.uv), 0);
        // Never worse than what ADMM handed over (both scored on the rest triangles).
        let (e_out, _) = global::objective_and_gradient(&m, &frames, energy, &out.uv).expect("e");
        let (e_admm, _) = global::objective_and_gradient(&m, &frames, energy, &admm.uv).expect("e");
        assert!(
            e_out <= e_admm * (1.0 + 1e-12),
            "{energy:?}: {e_out} > {e_admm}"
        );
        assert!(out.stop_summary().contains("handed to the global solver"));
    }
}

/// `global::solve` from `uv` with the default options of `energy`, bijective or not.
fn solve_from(
    m: &TriMesh,
    frames: &FaceFrames,
    uv: &[[f64; 2]],
    energy: Energy,
    bijective: bool,
) -> Result<global::GlobalResult, foldfree::linalg::SolveError> {
    let opts = GlobalOptions {
        bijective,
        ..GlobalOptions::for_energy(energy)
    };
    global::solve(m, frames, uv, &opts, &mut |_| {})
}

/// Boundary crossings of a map, by brute force (tests/common/objcheck.rs).
fn crossings(m: &TriMesh, uv: &[[f64; 2]]) -> usize {
    let faces: Vec<[usize; 3]> = m.faces.iter().map(|f| f.map(|v| v as usize)).collect();
    crate::common::objcheck::boundary_crossings(&faces, uv)
}

/// Bijective mode (SCAF, `GlobalOptions::bijective`, the default): from Tutte on camel_open
/// the unconstrained MIPS optimum folds the boundary over itself; the bijective solve has no
/// crossing, took steps with the scaffold on, and pays under 1 % of energy for it.
#[test]
fn bijective_solve_keeps_the_boundary_apart() {
    let (m, _, frames, tutte) = load("camel_open.obj");
    let a = solve_from(&m, &frames, &tutte, Energy::Mips, false).expect("unconstrained");
    let b = solve_from(&m, &frames, &tutte, Energy::Mips, true).expect("bijective");
    assert!(
        crossings(&m, &a.uv) > 0,
        "the unconstrained map should overlap"
    );
    assert_eq!(a.scaffold_iterations, 0);
    assert_eq!(crossings(&m, &b.uv), 0);
    assert!(b.scaffold_iterations > 0);
    assert!(b.converged(), "{}", b.stop_summary());
    assert_eq!(foldfree::init::count_flips(&m.faces, &b.uv), 0);
    assert!(
        b.energy <= 1.01 * a.energy,
        "bijective {} vs unconstrained {}",
        b.energy,
        a.energy
    );
}

/// The scaffold is joined lazily: a map that never nears overlap is the unconstrained
/// solver's, bit for bit.
#[test]
fn bijective_solve_without_contact_is_the_unconstrained_one() {
    let (m, _, frames, tutte) = load("square_grid_10x10.obj");
    for energy in [Energy::Mips, Energy::SymmetricDirichlet] {
        let a = solve_from(&m, &frames, &tutte, energy, false).expect("unconstrained");
        let b = solve_from(&m, &frames, &tutte, energy, true).expect("bijective");
        assert_eq!(b.scaffold_iterations, 0);
        assert_eq!(a.uv, b.uv, "{energy:?}");
    }
}

/// A start whose boundary already crosses itself is refused by the bijective solver (there is
/// no scaffold around it), with a message saying so.
#[test]
fn bijective_solve_refuses_an_overlapping_start() {
    let (m, _, frames, tutte) = load("camel_open.obj");
    let a = solve_from(&m, &frames, &tutte, Energy::Mips, false).expect("unconstrained");
    assert!(crossings(&m, &a.uv) > 0);
    let err = solve_from(&m, &frames, &a.uv, Energy::Mips, true).expect_err("overlapping start");
    assert!(err.to_string().contains("crosses itself"), "{err}");
}

/// The CLI's default map of camel_open (ADMM, MIPS) is bijective in the written file; with
/// `--no-bijective` it is ADMM's unconstrained map, whose boundary crosses itself.
#[test]
fn cli_default_map_is_bijective() {
    let dir = TempDir::new("bijective_cli");
    let input = crate::common::data_obj("camel_open");
    let mut counts = Vec::new();
    for extra in [&[][..], &["--no-bijective"][..]] {
        let out = dir.join("out.obj");
        let o = crate::common::foldfree(
            &[
                &["param", input.to_str().expect("utf-8"), "-o"][..],
                &[out.to_str().expect("utf-8"), "-q", "--backend", "cpu"][..],
                extra,
            ]
            .concat(),
        );
        crate::common::run::check_ok(&o, "foldfree param");
        let text = std::fs::read_to_string(&out).expect("read");
        let obj = crate::common::objcheck::parse_obj(&text).expect("parse");
        counts.push(crate::common::objcheck::file_boundary_crossings(&obj));
    }
    assert_eq!(counts[0], 0, "default map overlaps");
    assert!(
        counts[1] > 0,
        "the unconstrained map should overlap: {counts:?}"
    );
}
