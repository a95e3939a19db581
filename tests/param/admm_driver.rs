//! The ADMM driver's decisions (stop test, μ adaptation) on scripted residuals: an executor that
//! runs no iteration but reports residual sums from a script, so each rule is exercised exactly
//! and on both sides of its threshold.

use std::path::Path;

use foldfree::init::{initial_map, normalize_area, InitMethod};
use foldfree::mesh;
use foldfree::param::admm::driver::{Executor, Residuals};
use foldfree::param::admm::{self, AdmmOptions, AdmmProblem, AdmmState};
use foldfree::param::Energy;

/// Reports `script(check index, μ·F)` = (relative primal, relative dual, energy) at every check
/// and keeps the uploaded state (the flip-free start map) for the driver's recoveries.
struct Scripted<F: FnMut(usize, f64) -> (f64, f64, f64)> {
    script: F,
    state: Option<AdmmState>,
    nf: f64,
    checks: usize,
    /// μ·F passed to each batch.
    mu_seen: Vec<f64>,
    /// The first download returns the iterate with every Jacobian scaled by this (a map whose
    /// scales moved away from the uploaded one's).
    scale_once: Option<f64>,
    uploads: usize,
}

impl<F: FnMut(usize, f64) -> (f64, f64, f64)> Executor for Scripted<F> {
    fn backend(&self) -> &'static str {
        "scripted"
    }
    fn device(&self) -> String {
        "script".into()
    }
    fn upload(&mut self, state: &AdmmState, _penalty: &[f64]) -> foldfree::Result<()> {
        self.state = Some(state.clone());
        self.uploads += 1;
        Ok(())
    }
    fn download(&mut self) -> foldfree::Result<AdmmState> {
        let mut st = self
            .state
            .clone()
            .expect("the driver uploads before it downloads");
        if let Some(s) = self.scale_once.take() {
            st.a.iter_mut()
                .chain(st.y.iter_mut())
                .for_each(|a| *a = a.map(|x| s * x));
        }
        Ok(st)
    }
    fn iterate(&mut self, _n: usize, mu: f64) -> foldfree::Result<Residuals> {
        let mu_rel = mu * self.nf;
        self.mu_seen.push(mu_rel);
        let (p, d, e) = (self.script)(self.checks, mu_rel);
        self.checks += 1;
        Ok(Residuals {
            primal2: p * p,
            dual2: d * d,
            anorm2: 1.0,
            energy: e,
        })
    }
}

fn grid() -> (mesh::TriMesh, AdmmProblem, Vec<[f64; 2]>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/square_grid_10x10.obj");
    let (m, t, _) = mesh::load(&path, &mesh::ValidateOptions::default()).expect("test mesh loads");
    let frames = mesh::frames::compute(&m);
    let p = AdmmProblem::new(&m, &t, &frames);
    let mut uv = initial_map(&m, &t, InitMethod::Lscm).expect("start map");
    let area: f64 = frames.area.iter().sum();
    normalize_area(&m, &mut uv, area);
    (m, p, uv)
}

fn run<F: FnMut(usize, f64) -> (f64, f64, f64)>(
    opts: &AdmmOptions,
    script: F,
) -> (admm::AdmmResult, Vec<f64>) {
    let (r, exec) = run_scaled(opts, script, None);
    (r, exec.mu_seen)
}

/// [`run`] whose executor's first download scales the map by `scale_once`.
fn run_scaled<F: FnMut(usize, f64) -> (f64, f64, f64)>(
    opts: &AdmmOptions,
    script: F,
    scale_once: Option<f64>,
) -> (admm::AdmmResult, Scripted<F>) {
    let (m, p, uv) = grid();
    let mut exec = Scripted {
        script,
        state: None,
        nf: p.n_faces() as f64,
        checks: 0,
        mu_seen: Vec::new(),
        scale_once,
        uploads: 0,
    };
    let r =
        admm::solve(&p, &m.faces, &uv, None, opts, &mut exec, &mut |_| {}).expect("scripted run");
    (r, exec)
}

/// MIPS penalties are the start map's curvature (`∝ 1/det A`). When the stop test is met by a
/// map whose scales moved away from the ones the penalties were computed for (here every face
/// shrunk 4×, so every factor is 16× stale), the residuals were measured in the wrong metric:
/// the run re-uploads that map (fresh penalties, the stop test starts over) and converges at
/// the next stop test met with penalties that fit. SD's penalties are uniform: never stale.
#[test]
fn stale_penalties_are_refreshed_before_the_run_counts_as_converged() {
    let mut opts = AdmmOptions::for_energy(Energy::Mips);
    opts.max_iters = 40 * opts.check_every;
    let calm = |_: usize, _: f64| (1e-7, 1e-7, 2.0);
    let (r, exec) = run_scaled(&opts, calm, None);
    assert!(r.converged());
    assert_eq!(exec.uploads, 1);
    let plain = r.iterations;

    let (r, exec) = run_scaled(&opts, calm, Some(0.25));
    assert!(r.converged(), "{}", r.stop_summary());
    assert_eq!(exec.uploads, 2, "one refresh");
    assert_eq!(
        r.iterations,
        plain + opts.energy_checks * opts.check_every,
        "the stop test started over"
    );

    let opts = AdmmOptions::for_energy(Energy::SymmetricDirichlet);
    let (r, exec) = run_scaled(&opts, calm, Some(0.25));
    assert!(r.converged());
    assert_eq!(exec.uploads, 1);
}

/// Residuals far under tolerance and an energy that oscillates: one calm check now and then (a
/// turning point) must not stop the run, three in a row must.
#[test]
fn one_calm_check_in_an_oscillation_does_not_stop() {
    let mut opts = AdmmOptions::for_energy(Energy::SymmetricDirichlet);
    opts.max_iters = 40 * opts.check_every;
    opts.balance = false;
    // Every third check repeats the previous energy (a turning point), the others swing by 1e-3.
    let swing = |k: usize| {
        if k % 3 == 2 {
            (k - 1) as f64
        } else {
            k as f64
        }
    };
    let (r, _) = run(&opts, |k, _| {
        (1e-7, 1e-7, 1.0 + 1e-3 * (swing(k) * 2.1).sin())
    });
    assert!(!r.converged(), "a lone calm check stopped the run");
    assert_eq!(r.iterations, opts.max_iters);

    // The same swing until check 20 (itself a turning point), then a settled energy: calm from
    // check 20 (0-based) on, so the run stops after check 20 + energy_checks − 1.
    assert!(opts.energy_checks >= 2, "one calm check must not be enough");
    let (r, _) = run(&opts, |k, _| {
        let k = k.min(20);
        (1e-7, 1e-7, 1.0 + 1e-3 * (swing(k) * 2.1).sin())
    });
    assert!(r.converged());
    assert_eq!(r.iterations, (20 + opts.energy_checks) * opts.check_every);
}

/// A μ at which the primal residual stalled above tolerance is a floor for residual balancing:
/// without it the two rules alternate (halve on a tight consensus, raise on the stall below the
/// stability threshold) until μ hits its bound.
#[test]
fn balancing_never_returns_below_a_mu_that_stalled() {
    let mut opts = AdmmOptions::for_energy(Energy::Mips);
    opts.mu_rel = Some(100.0);
    opts.max_iters = 120 * opts.check_every;
    let threshold = 200.0;
    // Below the threshold: a stalled primal residual over tolerance. At or above it: a tight
    // consensus with moving maps (dual over tolerance), which asks for a smaller μ.
    let (r, mu_seen) = run(&opts, |k, mu_rel| {
        let e = 1.0 + 1e-2 * (k as f64).sin();
        if mu_rel < threshold {
            (1e-3, 1e-3, e)
        } else {
            (1e-6, 1e-3, e)
        }
    });
    assert!(!r.converged());
    let first = mu_seen
        .iter()
        .position(|&m| m >= threshold)
        .expect("the stall raised μ");
    assert!(
        mu_seen[first..].iter().all(|&m| m >= threshold),
        "μ went back under the stalled value: {mu_seen:?}"
    );
    assert!(mu_seen.iter().all(|&m| m <= 2.0 * threshold));
}

/// Residual balancing's decrease is a trial. Here μ·F 50 is below the stability threshold: the
/// consensus that was tight at 100 is lost at once (the primal residual over its tolerance). The
/// driver restores the iterate and μ it left, never goes under that μ again, and the run then
/// converges at 100 instead of stalling at its cap.
#[test]
fn a_balancing_decrease_that_loses_the_consensus_is_rolled_back() {
    let mut opts = AdmmOptions::for_energy(Energy::SymmetricDirichlet);
    opts.mu_rel = Some(100.0);
    opts.max_iters = 200 * opts.check_every;
    let (r, exec) = run_scaled(
        &opts,
        |k, mu_rel| {
            if mu_rel < 100.0 {
                (1e-3, 1e-3, 2.0)
            } else if k < 60 {
                // Tight consensus, maps still moving: balancing wants a smaller μ.
                (1e-6, 1e-3, 2.0 + 1e-2 * (k as f64).sin())
            } else {
                (1e-6, 1e-6, 2.0)
            }
        },
        None,
    );
    assert!(r.converged(), "{}", r.stop_summary());
    assert_eq!(r.balance_rollbacks, 1);
    assert_eq!(exec.uploads, 2, "the start and the restored iterate");
    let low = exec
        .mu_seen
        .iter()
        .position(|&m| m < 100.0)
        .expect("balancing tried a smaller μ");
    assert_eq!(
        exec.mu_seen.iter().filter(|&&m| m < 100.0).count(),
        1,
        "one check at the lost μ, then never again: {:?}",
        exec.mu_seen
    );
    assert!(r.history[low].rolled_back);
    assert!(r.iterations < opts.max_iters / 2);
}

/// Without any stall, balancing halves μ down to its bound (initial ÷ `mu_shrink_max`) while the
/// consensus is tight and the maps move; the rule waits `stall_checks` checks between halvings.
#[test]
fn balancing_halves_mu_to_its_bound_when_the_consensus_is_tight() {
    let mut opts = AdmmOptions::for_energy(Energy::Mips);
    opts.mu_rel = Some(100.0);
    opts.max_iters = 100 * opts.check_every;
    let (_, mu_seen) = run(&opts, |k, _| (1e-6, 1e-3, 1.0 + 1e-2 * (k as f64).sin()));
    let last = *mu_seen.last().expect("ran");
    assert!(
        (last - 100.0 / opts.mu_shrink_max()).abs() < 1e-9,
        "ended at {last}"
    );
    // Halvings are at least stall_checks checks apart.
    let changes: Vec<usize> = (1..mu_seen.len())
        .filter(|&i| mu_seen[i] != mu_seen[i - 1])
        .collect();
    assert_eq!(changes.len() as f64, opts.mu_shrink_max().log2().round());
    assert!(changes
        .windows(2)
        .all(|w| w[1] - w[0] > opts.stall_checks()));

    // A consensus at 0.3 × tolerance is not tight enough (the f32 floor of the residual on a
    // device is close to that): μ stays.
    let (_, mu_seen) = run(&opts, |k, _| (3e-5, 1e-3, 1.0 + 1e-2 * (k as f64).sin()));
    assert!(mu_seen.iter().all(|&m| m == 100.0));
}

/// A consensus that stalls just above tolerance (the primal residual never makes a new low):
/// μ is raised to its cap, and once it is there and the window passes without progress the run
/// stops as stalled — long before the iteration cap — instead of repeating the cycle.
#[test]
fn a_stall_at_the_mu_cap_stops_the_run_as_stalled() {
    let mut opts = AdmmOptions::for_energy(Energy::Mips);
    opts.mu_rel = Some(100.0);
    opts.max_iters = 400 * opts.check_every;
    let (r, mu_seen) = run(&opts, |k, _| {
        (1.3e-4, 1.3e-4, 2.0 + 1e-4 * (k as f64).sin())
    });
    assert_eq!(r.stop, admm::AdmmStop::Stalled);
    assert!(!r.converged() && !r.interrupted());
    let cap = 100.0 * opts.mu_growth_max;
    assert_eq!(*mu_seen.last().expect("ran"), cap);
    // One window per doubling up to the cap, then one more at the cap: nothing else.
    let doublings = opts.mu_growth_max.log2().round() as usize;
    let checks = (doublings + 1) * opts.stall_checks() + 1;
    assert!(
        r.iterations <= checks * opts.check_every,
        "{} iterations, expected at most {}",
        r.iterations,
        checks * opts.check_every
    );
    // The best map is flip-free (the start map at worst) and the stall says how far it was.
    assert_eq!(r.flips, 0);
    assert!(r.stop_summary().contains("stalled"), "{}", r.stop_summary());

    // With μ fixed there is nothing to adapt: the first window without progress is a stall.
    opts.adaptive_mu = false;
    let (r, mu_seen) = run(&opts, |_, _| (1.3e-4, 1.3e-4, 2.0));
    assert_eq!(r.stop, admm::AdmmStop::Stalled);
    assert!(mu_seen.iter().all(|&m| m == 100.0));
    assert!(r.iterations <= (opts.stall_checks() + 1) * opts.check_every);

    // A primal residual that keeps making new lows is progress, not a stall, even at the cap.
    opts.adaptive_mu = true;
    opts.max_iters = 60 * opts.check_every;
    let (r, _) = run(&opts, |k, _| {
        (1e-2 * 0.9f64.powi(k as i32) + 1e-4, 1e-3, 2.0)
    });
    assert_eq!(r.stop, admm::AdmmStop::MaxIterations);
}
