//! The ADMM outer loop, written once for both backends: batches of iterations on an
//! [`Executor`], residual checks every `check_every` iterations (read back from the device, not
//! every iteration), penalty adaptation, least-squares re-synchronisation and recovery.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use super::{AdmmProblem, AdmmState};
use crate::param::energy::{self, Energy};
use crate::param::recover::{self, LeastSquaresRecovery, Recovery};

/// Which executor runs the iteration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Backend {
    Cpu,
    Vulkan,
}

/// Acceleration of the ADMM fixed-point iteration.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Accel {
    /// Plain ADMM.
    #[default]
    None,
    /// Anderson acceleration of the edge state with a residual safeguard (CPU backend only).
    Anderson,
}

/// Residual sums measured after the last iteration of a batch (twin of `residual.comp`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Residuals {
    /// Σ_t ‖Y_t − A_ft‖²
    pub primal2: f64,
    /// Σ_t ‖A_ft − A_ft(previous iteration)‖²
    pub dual2: f64,
    /// Σ_t ‖A_ft‖²
    pub anorm2: f64,
    /// Σ_f w_f E(A_f)
    pub energy: f64,
}

/// Runs batches of ADMM iterations somewhere (host threads or a Vulkan device).
pub trait Executor {
    /// `"cpu"` or `"vulkan"`.
    fn backend(&self) -> &'static str;
    /// Human-readable device name.
    fn device(&self) -> String;
    /// Replaces the iterate and the #F per-face penalty factors `m_f` (face `f`'s penalty is
    /// `μ m_f`, [`super::cpu::penalty_factors`]). The driver owns the factors: they belong to
    /// the map they were derived from, and a restored iterate must keep the ones it ran with.
    fn upload(&mut self, state: &AdmmState, penalty: &[f64]) -> crate::Result<()>;
    /// Reads the iterate back.
    fn download(&mut self) -> crate::Result<AdmmState>;
    /// Runs `n ≥ 1` iterations with penalty `mu`; residuals of the last one.
    fn iterate(&mut self, n: usize, mu: f64) -> crate::Result<Residuals>;
    /// Iterations in accepted and rejected accelerated blocks so far (from the start of the
    /// acceleration), when accelerating.
    fn accel_stats(&self) -> Option<(usize, usize)> {
        None
    }
    /// Switches the acceleration on or off (no-op without one).
    fn set_accel_active(&mut self, _on: bool) {}
}

/// Solver settings. `Default` gives the documented defaults for MIPS; use
/// [`AdmmOptions::for_energy`]. The `[admm]` table of a tuning file ([`crate::tuning`]): every
/// field but `energy` (the job's) and `stop` (the host's), `mu_rel` spelt `mu`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdmmOptions {
    #[serde(skip)]
    pub energy: Energy,
    /// Penalty as `μ · #faces`; `None` picks the energy's default.
    #[serde(rename = "mu", skip_serializing_if = "Option::is_none")]
    pub mu_rel: Option<f64>,
    pub max_iters: usize,
    /// Iterations per batch between residual read-backs.
    pub check_every: usize,
    /// Newton steps per face per iteration.
    pub newton_iters: u32,
    /// Relative primal residual `‖Y − AS‖ / ‖AS‖` tolerance.
    pub tol_primal: f64,
    /// Relative dual residual `‖ΔA S‖ / ‖AS‖` tolerance.
    pub tol_dual: f64,
    /// Relative energy change between checks.
    pub tol_energy: f64,
    /// Consecutive checks the energy change must stay under `tol_energy`. One is not enough:
    /// the per-face energy sum of an ADMM iterate oscillates while the consensus settles, and a
    /// single sample of an oscillation is small near each turning point by chance; two
    /// consecutive small samples are the fewest that exclude a lone turning point. With this
    /// stop test every disk of the corpus converged or handed off with a map within 1 % of
    /// SLIM's (55/55 MIPS, 54/55 SD; BENCHMARKS.md, "Corpus sweeps").
    pub energy_checks: usize,
    /// Least-squares re-synchronisation period in iterations (0: off).
    pub resync_every: usize,
    /// Raise μ (×2) when the primal residual stalls above tolerance (oscillation that
    /// precedes divergence).
    pub adaptive_mu: bool,
    /// Checks without a new low (< 0.95× the best) of the primal residual before μ is raised
    /// (and, with μ at its cap, before the run counts as stalled); `None`: the energy's
    /// default ([`AdmmOptions::stall_checks`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stall_checks: Option<usize>,
    /// Bound of the μ raises: μ stays at or below initial μ × this factor.
    pub mu_growth_max: f64,
    /// Bound of residual balancing: μ stays at or above initial μ ÷ this factor; `None`: the
    /// energy's default ([`AdmmOptions::mu_shrink_max`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mu_shrink_max: Option<f64>,
    /// Halve μ when the consensus is tight (primal residual under `balance_primal ×
    /// tol_primal`) but the maps still move (dual residual or energy change over tolerance), at
    /// most once per `stall_checks` checks and never below a μ that had to be raised on a stall.
    pub balance: bool,
    /// Balancing needs the primal residual under this fraction of `tol_primal` (a tight
    /// consensus, well above the f32 rounding floor of the residual on devices).
    pub balance_primal: f64,
    /// Set to stop early (Ctrl-C); the best flip-free map so far is returned.
    #[serde(skip)]
    pub stop: Option<Arc<AtomicBool>>,
    /// Acceleration (every iteration counts, rejected accelerated ones included).
    pub accel: Accel,
    /// Anderson history length `m`.
    pub aa_depth: usize,
    /// ADMM iterations per Anderson step (the acceleration extrapolates the composite map).
    pub aa_every: usize,
    /// Plain iterations before acceleration starts: runs that converge within them (MIPS from
    /// LSCM: 75–275 iterations) pay nothing for it, and the history then starts near the
    /// slowly converging regime it is meant for. `None`: the energy's default
    /// ([`AdmmOptions::aa_start`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub aa_start: Option<usize>,
    /// While accelerating, residual balancing (lowering μ) also waits for the relative energy
    /// change between checks to fall under this (∞: no extra condition).
    pub aa_balance_energy: f64,
    /// Per-vertex UVs from the per-face maps at each check that recovers (least squares by
    /// default; the seed's breadth-first traversal as an option).
    pub recovery: Recovery,
}

impl AdmmOptions {
    /// Documented defaults per energy (see the module docs of [`super`] and BENCHMARKS.md).
    pub fn for_energy(energy: Energy) -> AdmmOptions {
        AdmmOptions {
            energy,
            mu_rel: None,
            max_iters: 10_000,
            check_every: 25,
            newton_iters: 1,
            tol_primal: 1e-4,
            tol_dual: 1e-4,
            // Per 25-iteration check, relative (the energy is a mean bounded below by 2 or 4, so
            // the ratio is a pure number); with 2 consecutive checks. The per-face energy sum
            // moves with the iterates at the size of the residuals (1e-4), so a tolerance far
            // under that is met only at a turning point of an oscillation.
            tol_energy: 1e-5,
            energy_checks: 2,
            resync_every: 0,
            adaptive_mu: true,
            stall_checks: None,
            mu_growth_max: 64.0,
            mu_shrink_max: None,
            balance: true,
            balance_primal: 0.25,
            stop: None,
            accel: Accel::None,
            aa_depth: 6,
            aa_every: 1,
            aa_start: None,
            // Off: Anderson acceleration is opt-in, and this gate, measured on the shared
            // disks only, helped one run and slowed three (BENCHMARKS.md, Anderson round 2).
            aa_balance_energy: f64::INFINITY,
            recovery: Recovery::LeastSquares,
        }
    }

    /// Checks every setting against its meaningful range, so a host gets the same usage error
    /// (exit 2 in the CLI) as the command line: tolerances are relative, so they lie in (0, 1);
    /// counts are at least 1 and bounded where a larger value can only run for ever (one face's
    /// Newton solve converges quadratically: more than 100 steps per iteration cannot help).
    pub fn validate(&self) -> Result<(), crate::OptionError> {
        let rel = |x: f64| x.is_finite() && x > 0.0 && x < 1.0;
        if let Some(mu) = self.mu_rel {
            if !(mu.is_finite() && mu > 0.0) {
                return crate::OptionError::reject("ADMM", "mu", mu, "(0, ∞), finite");
            }
        }
        if !(1..=100_000_000).contains(&self.max_iters) {
            return crate::OptionError::reject("ADMM", "max_iters", self.max_iters, "[1, 1e8]");
        }
        if !(1..=100_000).contains(&self.check_every) {
            return crate::OptionError::reject(
                "ADMM",
                "check_every",
                self.check_every,
                "[1, 100000]",
            );
        }
        if !(1..=100).contains(&self.newton_iters) {
            return crate::OptionError::reject(
                "ADMM",
                "newton_iters",
                self.newton_iters,
                "[1, 100]",
            );
        }
        for (what, x) in [
            ("tol_primal", self.tol_primal),
            ("tol_dual", self.tol_dual),
            ("tol_energy", self.tol_energy),
        ] {
            if !rel(x) {
                return crate::OptionError::reject("ADMM", what, x, "(0, 1)");
            }
        }
        if !(1..=10_000).contains(&self.energy_checks) {
            return crate::OptionError::reject(
                "ADMM",
                "energy_checks",
                self.energy_checks,
                "[1, 10000]",
            );
        }
        if self.resync_every > 100_000_000 {
            return crate::OptionError::reject(
                "ADMM",
                "resync_every",
                self.resync_every,
                "[0, 1e8]",
            );
        }
        if let Some(n) = self.stall_checks {
            if !(1..=10_000).contains(&n) {
                return crate::OptionError::reject("ADMM", "stall_checks", n, "[1, 10000]");
            }
        }
        for (what, x) in [
            ("mu_growth_max", Some(self.mu_growth_max)),
            ("mu_shrink_max", self.mu_shrink_max),
        ] {
            if let Some(x) = x {
                if !(x.is_finite() && x >= 1.0) {
                    return crate::OptionError::reject("ADMM", what, x, "[1, ∞), finite");
                }
            }
        }
        if !rel(self.balance_primal) {
            return crate::OptionError::reject(
                "ADMM",
                "balance_primal",
                self.balance_primal,
                "(0, 1)",
            );
        }
        if !(1..=64).contains(&self.aa_depth) {
            return crate::OptionError::reject("ADMM", "aa_depth", self.aa_depth, "[1, 64]");
        }
        if !(1..=10_000).contains(&self.aa_every) {
            return crate::OptionError::reject("ADMM", "aa_every", self.aa_every, "[1, 10000]");
        }
        if self.aa_balance_energy.is_nan() || self.aa_balance_energy <= 0.0 {
            return crate::OptionError::reject(
                "ADMM",
                "aa_balance_energy",
                self.aa_balance_energy,
                "(0, ∞]",
            );
        }
        Ok(())
    }

    /// Checks without a new primal low before μ is raised (the option, or the energy's default).
    ///
    /// Why SD waits twice as long: MIPS is scale-free, so its per-face optimum is local and
    /// the consensus settles with local corrections; SD prescribes area, so from a conformal
    /// (LSCM) start area has to move across the whole mesh, a transient in which the primal
    /// residual makes no new low for a while without being unstable — raising μ there locks
    /// the iteration into a slow limit cycle at a needlessly stiff penalty. The window is in
    /// checks (iteration counts), independent of mesh size and units. Measured over the whole
    /// disk corpus with these values (BENCHMARKS.md, "Corpus sweeps"): 61/61 runs per energy
    /// end with a flip-free map; not varied over the corpus.
    pub fn stall_checks(&self) -> usize {
        self.stall_checks.unwrap_or(match self.energy {
            Energy::Mips => 8,
            Energy::SymmetricDirichlet => 16,
        })
    }

    /// Bound of residual balancing (the option, or the energy's default).
    ///
    /// Why a bound at all: on an f32 device the primal residual has a rounding floor that
    /// grows as μ shrinks (the multipliers grow as 1/μ and `A − Λ/μ` cancels), and balancing
    /// needs the residual under a quarter of its tolerance; without a bound the two backends
    /// take different paths once the device's floor reaches that threshold. The bounds stop
    /// balancing at μ·F 6.25 (MIPS, start 100) and 15.6 (SD, start 1000), where the measured f32
    /// floor is at most that threshold (BENCHMARKS.md, "Stopping test and μ adaptation"); the
    /// CPU/Vulkan agreement test (tests/param/admm_gpu.rs) checks that the backends still follow one
    /// path.
    pub fn mu_shrink_max(&self) -> f64 {
        self.mu_shrink_max.unwrap_or(match self.energy {
            Energy::Mips => 16.0,
            Energy::SymmetricDirichlet => 64.0,
        })
    }

    /// Plain iterations before Anderson acceleration starts (the option, or the energy's
    /// default). MIPS from LSCM starts next to its optimum (LSCM minimises the conformal
    /// energy without the flip constraint), so most runs converge within a few hundred plain
    /// iterations and pay nothing for acceleration; SD starts far from it (area has to move),
    /// so acceleration pays from the first iteration.
    pub fn aa_start(&self) -> usize {
        self.aa_start.unwrap_or(match self.energy {
            Energy::Mips => 100,
            Energy::SymmetricDirichlet => 0,
        })
    }

    /// The penalty actually used at the start, as `μ · #faces`.
    pub fn initial_mu_rel(&self) -> f64 {
        self.mu_rel.unwrap_or(match self.energy {
            Energy::Mips => 100.0,
            Energy::SymmetricDirichlet => 1000.0,
        })
    }
}

impl Default for AdmmOptions {
    fn default() -> Self {
        AdmmOptions::for_energy(Energy::Mips)
    }
}

/// One residual check.
#[derive(Clone, Debug, serde::Serialize)]
pub struct History {
    pub iteration: usize,
    pub mu_rel: f64,
    pub primal: f64,
    pub dual: f64,
    /// Σ w E(A) of the per-face maps (not of a recovered map).
    pub energy: f64,
    pub energy_change: f64,
    /// Set when a recovery happened at this check: flips of the recovered map and its energy.
    pub recovered_flips: Option<usize>,
    pub recovered_energy: Option<f64>,
    /// Iterations in accepted and in rejected accelerated blocks so far (`None` without
    /// acceleration).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub accel_accepted: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub accel_rejected: Option<usize>,
    /// At this check the last residual-balancing decrease of μ was undone (its iterate and μ
    /// restored): it had lost the consensus.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub rolled_back: bool,
}

/// Why [`solve`] returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AdmmStop {
    /// Residuals and energy change under tolerance, and the recovered map flip-free.
    Converged,
    /// μ at its cap (or fixed) and no progress: the primal residual made no new low for
    /// `stall_checks` checks, or the residuals are small but the recovered map still flips.
    /// Raising μ is the only remedy the iteration has for either; without it, more iterations
    /// repeat the same cycle.
    Stalled,
    /// The iteration cap.
    MaxIterations,
    /// Stopped by the caller's flag.
    Interrupted,
}

/// What [`solve`] returns.
#[derive(Clone, Debug)]
pub struct AdmmResult {
    /// #V per-vertex UVs (the best flip-free map seen; the start map if none was better).
    pub uv: Vec<[f64; 2]>,
    pub iterations: usize,
    /// Why the run ended ([`AdmmResult::converged`], [`AdmmResult::interrupted`]).
    pub stop: AdmmStop,
    pub mu_rel_final: f64,
    pub history: Vec<History>,
    /// Flips of the map in `uv` (0 unless even the start map was flipped).
    pub flips: usize,
    pub backend: &'static str,
    pub device: String,
    /// The tolerances the stop test used (for [`AdmmResult::stop_summary`]).
    pub tol_primal: f64,
    pub tol_dual: f64,
    /// Residual-balancing decreases of μ undone because they lost the consensus.
    pub balance_rollbacks: usize,
}

impl AdmmResult {
    /// Residuals and energy change under tolerance, and the recovered map flip-free.
    pub fn converged(&self) -> bool {
        self.stop == AdmmStop::Converged
    }

    /// Stopped by the caller's flag.
    pub fn interrupted(&self) -> bool {
        self.stop == AdmmStop::Interrupted
    }

    /// Why ADMM stopped, with its last residuals against their tolerances.
    pub fn stop_summary(&self) -> String {
        let last = self.history.last();
        let (p, d) = last.map_or((f64::NAN, f64::NAN), |h| (h.primal, h.dual));
        let why = match self.stop {
            AdmmStop::Converged => "converged",
            AdmmStop::Stalled => "stalled (μ at its cap, no progress)",
            AdmmStop::MaxIterations => "iteration cap",
            AdmmStop::Interrupted => "interrupted",
        };
        format!(
            "admm {why} after {} iterations (primal {p:.2e} / tol {:.0e}, dual {d:.2e} / tol {:.0e}, μ·F {})",
            self.iterations, self.tol_primal, self.tol_dual, self.mu_rel_final
        )
    }
}

/// Σ_f w_f E(J_f(uv)) and the number of faces with `det J ≤ 0`.
pub fn map_energy(
    problem: &AdmmProblem,
    faces: &[[u32; 3]],
    uv: &[[f64; 2]],
    e: Energy,
) -> (f64, usize) {
    let mut sum = 0.0;
    let mut flips = 0;
    for f in 0..faces.len() {
        let a = problem.jacobian(faces, uv, f);
        if energy::det(&a) <= 0.0 {
            flips += 1;
            sum = f64::INFINITY;
        } else {
            sum += problem.weight[f] * energy::value(e, &a);
        }
    }
    (sum, flips)
}

/// Whether the penalty factors in use (`old`) no longer describe the map (`now`): more than 1 %
/// of the faces have a factor off by more than 2×. The 2× band is the smallest change that
/// matters to the stop test (a weight within 2× misstates its face's share of the residual norm
/// by at most √2, which the tolerance's own order of magnitude absorbs). The 1 % is a
/// judgement, not derived: a handful of faces whose scale moved cannot shift an area-weighted
/// sum, and each refresh costs at least the stop test's window. Measured on the corpus MIPS
/// disks: refreshes on 15 of 61, and every one of them ended at a lower energy.
fn stale_penalties(old: &[f64], now: &[f64]) -> bool {
    let off = old
        .iter()
        .zip(now)
        .filter(|(o, n)| !(**n <= 2.0 * **o && **n >= 0.5 * **o))
        .count();
    off * 100 > old.len()
}

/// The best flip-free per-vertex map seen so far.
struct Best {
    uv: Vec<[f64; 2]>,
    energy: f64,
    flips: usize,
}

impl Best {
    /// Keeps `uv` when it is flip-free and no worse. When it flips, the part of the way from
    /// the best map towards it that flips nothing is taken instead if it lowers the energy:
    /// along `best + t (uv − best)` every face's Jacobian is affine in `t`, so the largest
    /// flip-free `t` is exact ([`energy::max_flip_free_step`]); a fraction of it keeps every
    /// face strictly positive, and halving looks for a decrease. A recovered map that flips a
    /// few faces is still mostly closer to the optimum than the start map.
    fn offer(&mut self, problem: &AdmmProblem, faces: &[[u32; 3]], uv: &[[f64; 2]], e: Energy) {
        let (energy, flips) = map_energy(problem, faces, uv, e);
        if flips == 0 && energy <= self.energy {
            self.uv = uv.to_vec();
            self.energy = energy;
            self.flips = 0;
            return;
        }
        if self.flips > 0 || flips == 0 {
            return;
        }
        let d: Vec<[f64; 2]> = uv
            .iter()
            .zip(&self.uv)
            .map(|(a, b)| [a[0] - b[0], a[1] - b[1]])
            .collect();
        let t_max = (0..faces.len())
            .map(|f| {
                energy::max_flip_free_step(
                    &problem.jacobian(faces, &self.uv, f),
                    &problem.jacobian(faces, &d, f),
                )
            })
            .fold(f64::INFINITY, f64::min);
        let mut t = (0.85 * t_max).min(1.0);
        for _ in 0..12 {
            if t.is_nan() || t <= 0.0 {
                break;
            }
            let trial: Vec<[f64; 2]> = self
                .uv
                .iter()
                .zip(&d)
                .map(|(b, d)| [b[0] + t * d[0], b[1] + t * d[1]])
                .collect();
            let (te, tf) = map_energy(problem, faces, &trial, e);
            if tf == 0 && te < self.energy {
                self.uv = trial;
                self.energy = te;
                return;
            }
            t *= 0.5;
        }
    }
}

/// Runs ADMM from the per-vertex start map `init_uv` (#V) until convergence, a stall, or
/// `max_iters`.
///
/// `fallback` is a flip-free map (e.g. Tutte) returned if neither the start map nor any
/// recovered map is flip-free. `progress` is called at every check. Never returns a flipped map
/// silently: the result's `flips` counts them (non-zero only when the start map was already
/// flipped and no recovered map ever was flip-free).
pub fn solve(
    problem: &AdmmProblem,
    faces: &[[u32; 3]],
    init_uv: &[[f64; 2]],
    fallback: Option<&[[f64; 2]]>,
    opts: &AdmmOptions,
    exec: &mut dyn Executor,
    progress: &mut dyn FnMut(&History),
) -> crate::Result<AdmmResult> {
    let nf = problem.n_faces().max(1) as f64;
    let mut mu_rel = opts.initial_mu_rel();
    let ls = match opts.recovery {
        Recovery::LeastSquares => Some(LeastSquaresRecovery::new(problem, faces, init_uv.len())?),
        Recovery::BreadthFirst => None,
    };
    let recover = |a: &[[f64; 4]], uv: &mut [[f64; 2]]| -> crate::Result<()> {
        match &ls {
            Some(ls) => ls.recover(a, uv)?,
            None => recover::breadth_first(problem, faces, a, uv),
        }
        Ok(())
    };

    let state = AdmmState::from_uv(problem, faces, init_uv);
    // The penalty factors of the uploaded map: the stop test checks that they still describe it.
    let mut factors = super::cpu::penalty_factors(opts.energy, &problem.weight, &state.a);
    exec.upload(&state, &factors)?;
    let accelerating = opts.accel != Accel::None;
    exec.set_accel_active(accelerating && opts.aa_start() == 0);

    let (e0, flips0) = map_energy(problem, faces, init_uv, opts.energy);
    let mut best = Best {
        uv: init_uv.to_vec(),
        energy: if flips0 == 0 { e0 } else { f64::INFINITY },
        flips: flips0,
    };
    if let Some(fb) = fallback {
        let (e, flips) = map_energy(problem, faces, fb, opts.energy);
        if flips == 0 && e < best.energy {
            best = Best {
                uv: fb.to_vec(),
                energy: e,
                flips: 0,
            };
            // The folded start map is still the better guess almost everywhere: the flip-free
            // part of the way towards it.
            best.offer(problem, faces, init_uv, opts.energy);
        }
    }
    let mut uv = init_uv.to_vec();
    let mu_cap = opts.initial_mu_rel() * opts.mu_growth_max;

    let mut history: Vec<History> = Vec::new();
    let mut it = 0usize;
    let mut stop = AdmmStop::MaxIterations;
    let mut prev_energy = f64::NAN;
    // Stall detection: the best primal residual since the last change of μ, and how many
    // checks ago it was set.
    let mut best_primal = f64::INFINITY;
    let mut checks_since_best = 0usize;
    let mut checks_since_change = 0usize;
    let mut since_resync = 0usize;
    // Consecutive checks with the energy change under tolerance.
    let mut calm_checks = 0usize;
    // Lowest μ·F residual balancing may go to (raised when μ had to be raised on a stall, or a
    // decrease was rolled back).
    let mut mu_floor = 0.0f64;
    // The last balancing decrease, until it has held for a stall window.
    let mut trial: Option<BalanceTrial> = None;
    let mut rollbacks = 0usize;
    while it < opts.max_iters {
        if opts
            .stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed))
        {
            stop = AdmmStop::Interrupted;
            break;
        }
        let batch = opts.check_every.max(1).min(opts.max_iters - it);
        let mu = mu_rel / nf;
        if accelerating && it >= opts.aa_start() {
            exec.set_accel_active(true);
        }
        let r = exec.iterate(batch, mu)?;
        it += batch;
        since_resync += batch;
        let norm = r.anorm2.max(1e-300).sqrt();
        let primal = r.primal2.sqrt() / norm;
        let dual = r.dual2.sqrt() / norm;
        let energy_change = ((r.energy - prev_energy) / r.energy).abs();
        prev_energy = r.energy;
        if !(primal.is_finite() && dual.is_finite() && r.energy.is_finite()) {
            return Err(crate::linalg::SolveError::NonFinite {
                what: format!("ADMM iterate at iteration {it}"),
            }
            .into());
        }
        let mut h = History {
            iteration: it,
            mu_rel,
            primal,
            dual,
            energy: r.energy,
            energy_change,
            recovered_flips: None,
            recovered_energy: None,
            accel_accepted: exec.accel_stats().map(|s| s.0),
            accel_rejected: exec.accel_stats().map(|s| s.1),
            rolled_back: false,
        };

        if let Some(t) = trial.take() {
            if primal > opts.tol_primal {
                // The decrease lost the consensus it was made on (the primal residual was under
                // a quarter of its tolerance and is now over it): μ went below the stability
                // threshold, where the iteration oscillates away from the fixed point instead
                // of moving along it. Go back to the iterate and μ it left, and never below
                // that μ again.
                exec.upload(&t.state, &factors)?;
                mu_rel = t.mu_rel;
                mu_floor = mu_floor.max(t.mu_rel);
                rollbacks += 1;
                prev_energy = f64::NAN;
                calm_checks = 0;
                best_primal = f64::INFINITY;
                checks_since_best = 0;
                checks_since_change = 0;
                h.rolled_back = true;
                progress(&h);
                history.push(h);
                continue;
            }
            if checks_since_change < opts.stall_checks() {
                trial = Some(t);
            }
        }
        if energy_change < opts.tol_energy {
            calm_checks += 1;
        } else {
            calm_checks = 0;
        }
        // μ can still be raised: the only remedy of the iteration for a stalled consensus.
        let can_raise = opts.adaptive_mu && mu_rel * 2.0 <= mu_cap;
        if primal < 0.95 * best_primal {
            best_primal = primal;
            checks_since_best = 0;
        } else {
            checks_since_best += 1;
        }
        let small = primal < opts.tol_primal
            && dual < opts.tol_dual
            && calm_checks >= opts.energy_checks.max(1);
        // No new primal low for a window, above tolerance, and nothing left to adapt.
        let mut stalled =
            primal > opts.tol_primal && checks_since_best >= opts.stall_checks() && !can_raise;
        let resync_due = opts.resync_every > 0 && since_resync >= opts.resync_every;
        let last = it >= opts.max_iters;
        let mut converged = false;
        if small || resync_due || last || stalled {
            let st = exec.download()?;
            recover(&st.a, &mut uv)?;
            let (e, flips) = map_energy(problem, faces, &uv, opts.energy);
            h.recovered_flips = Some(flips);
            h.recovered_energy = Some(e);
            best.offer(problem, faces, &uv, opts.energy);
            let mut refreshed = false;
            if small && flips == 0 {
                let synced = AdmmState::from_uv(problem, faces, &uv);
                let now = super::cpu::penalty_factors(opts.energy, &problem.weight, &synced.a);
                if stale_penalties(&factors, &now) {
                    // The residuals met their tolerance in a metric the map has outgrown: a
                    // face whose scale changed since the upload is weighted by its old
                    // curvature, so its relative mismatch is under- (or over-) counted. Go on
                    // from this consistent, flip-free map with penalties of its own scales (the
                    // multipliers are kept: they do not depend on the penalty).
                    let mut synced = synced;
                    synced.lambda = st.lambda.clone();
                    exec.upload(&synced, &now)?;
                    factors = now;
                    refreshed = true;
                } else {
                    converged = true;
                }
            } else if small && flips > 0 && can_raise {
                // Residuals are small but the consensus is not yet tight enough for a flip-free
                // recovery: tighten it.
                mu_rel *= 2.0;
            } else if small && flips > 0 {
                stalled = true;
            }
            if resync_due && flips == 0 && !refreshed {
                let mut synced = AdmmState::from_uv(problem, faces, &uv);
                synced.lambda = st.lambda;
                factors = super::cpu::penalty_factors(opts.energy, &problem.weight, &synced.a);
                exec.upload(&synced, &factors)?;
            }
            if refreshed {
                // A new metric: the stop test starts over.
                calm_checks = 0;
                best_primal = f64::INFINITY;
                checks_since_best = 0;
            }
            if resync_due {
                since_resync = 0;
            }
        }
        if converged || stalled {
            stop = if converged {
                AdmmStop::Converged
            } else {
                AdmmStop::Stalled
            };
            progress(&h);
            history.push(h);
            break;
        }
        // Below the stability threshold of μ the iteration oscillates (primal ≈ dual, no
        // progress) and then diverges; above it, it converges monotonically. So: raise μ when
        // the primal residual is above tolerance and has made no new low for a while.
        if can_raise && primal > opts.tol_primal && checks_since_best >= opts.stall_checks() {
            // Hysteresis: μ at which the iteration stalled is below the stability threshold;
            // residual balancing never goes back under it (otherwise the two rules alternate,
            // halving on a tight consensus and raising on the stall, until μ reaches its bound;
            // tests/param/admm_driver.rs scripts that history).
            mu_floor = mu_floor.max(2.0 * mu_rel);
            mu_rel *= 2.0;
            best_primal = primal;
            checks_since_best = 0;
            checks_since_change = 0;
        } else if opts.balance
            && primal < opts.balance_primal * opts.tol_primal
            && (dual > opts.tol_dual || energy_change > opts.tol_energy)
            && checks_since_change >= opts.stall_checks()
            && (!accelerating || energy_change < opts.aa_balance_energy)
            && mu_rel / 2.0 >= (opts.initial_mu_rel() / opts.mu_shrink_max()).max(mu_floor)
        {
            // Residual balancing (Boyd et al. 2011, §3.4.1) in its safe half: the consensus is
            // already tight (a quarter of its tolerance) while the maps still move (dual residual
            // or energy change over tolerance), so a smaller μ lets the energy move. An earlier
            // rule, "dual > 10 × primal", hinged on how small the primal residual gets, and on f32
            // devices that has a rounding floor, so the two backends balanced to different μ and
            // followed different paths; a threshold relative to the tolerance does not depend on
            // it. While accelerating, the extrapolated consensus can tighten long before the
            // energy has settled (each μ change drops the Anderson history);
            // `aa_balance_energy` can make balancing wait for the energy change too.
            //
            // Where the stability threshold lies is not known in advance (it depends on the
            // curvature of the faces the consensus binds), so the decrease is a trial: the
            // iterate before it is kept until the consensus has held for a stall window, and
            // restored if the primal residual rises over its tolerance meanwhile.
            trial = Some(BalanceTrial {
                state: exec.download()?,
                mu_rel,
            });
            mu_rel /= 2.0;
            best_primal = primal;
            checks_since_best = 0;
            checks_since_change = 0;
        } else {
            checks_since_change += 1;
        }
        progress(&h);
        history.push(h);
    }
    if stop == AdmmStop::Interrupted {
        let st = exec.download()?;
        recover(&st.a, &mut uv)?;
        best.offer(problem, faces, &uv, opts.energy);
    }
    Ok(AdmmResult {
        uv: best.uv,
        iterations: it,
        stop,
        mu_rel_final: mu_rel,
        history,
        flips: best.flips,
        backend: exec.backend(),
        device: exec.device(),
        tol_primal: opts.tol_primal,
        tol_dual: opts.tol_dual,
        balance_rollbacks: rollbacks,
    })
}

/// A residual-balancing decrease of μ on trial: the iterate and μ·F before it.
struct BalanceTrial {
    state: AdmmState,
    mu_rel: f64,
}
