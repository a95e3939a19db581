//! The bounded-distortion global solver (issue 4), after Cai, Sun & Ge, "A mesh
//! parameterization method with limiting distortion": from a flip-free start (Tutte), minimise
//! the area-weighted mean of a distortion energy (symmetric Dirichlet or MIPS) over the vertex
//! UVs of one disk-topology mesh.
//!
//! Each iteration solves one sparse SPD system over the interleaved UVs for a direction —
//! the SLIM-like proxy ([`proxy`]) while the energy still falls by more than
//! [`GlobalOptions::proxy_switch`] per step, then projected Newton ([`cm`]) — and moves along
//! it by the largest flip-free step ([`line_search`]) with Armijo backtracking, so every
//! iterate is foldover-free and the objective decreases monotonically. While some faces are
//! over the distortion bound, the objective is taken w.r.t. progressive reference triangles
//! ([`progressive`]). Systems share one CSR pattern ([`assembly`]) and are solved by sparse
//! Cholesky, its symbolic analysis computed once ([`crate::linalg::direct`]), or by
//! preconditioned CG ([`crate::linalg::krylov::KrylovSolver`], [`GlobalOptions::linear_solver`]).
//!
//! With [`GlobalOptions::bijective`] (the default) the map stays bijective: from the first step
//! that would make the boundary cross itself, a scaffold of triangles fills the space around
//! the chart and joins the solve ([`scaffold`], SCAF), so no iterate ever overlaps.
//!
//! Converged when the energy has stopped decreasing: its relative decrease per iteration over
//! the last [`GlobalOptions::energy_window`] iterations is under [`GlobalOptions::energy_tol`]
//! (see there why that is scale-free and enough), or no step decreases it any more (rounding
//! level), or — sufficient but not necessary — the scale-free gradient norm `‖∇E‖·√(3D area)`
//! is under the tolerance (the paper's 1e-6 for symmetric Dirichlet, 1e-4 for MIPS). A
//! gradient norm alone is not a stop test one can rely on: on a well-converged map it can sit
//! above any fixed tolerance while the energy no longer moves in its sixth digit. Not
//! converged: the iteration cap, or the caller's flag.
#![forbid(unsafe_code)]

pub mod assembly;
pub mod cm;
pub mod line_search;
pub mod progressive;
pub mod proxy;
pub mod scaffold;
pub mod stop;

use std::borrow::Cow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use crate::linalg::direct::{CholeskySymbolic, DirectError, LinearSolver};
use crate::linalg::{
    krylov::{CgOptions, KrylovSolver},
    precond::Preconditioner,
};
use crate::linalg::{par_dot as dot, SolveError};
use crate::mesh::{FaceFrames, TriMesh};
use crate::param::energy::{self, Energy};
use assembly::{face_gradients, jacobian, pull_back, pull_back_matrix, FaceGradient, Pattern};

/// Options of [`solve`].
#[derive(Clone, Debug)]
pub struct GlobalOptions {
    pub energy: Energy,
    /// Iteration cap: a guard against a run that never settles, not a stop rule — the energy
    /// test ends runs. The paper's 100 was the stop rule there; under the energy test it cut
    /// runs short that were still gaining 2e-6–6e-6 of their energy per iteration (SLIM's own
    /// reference runs on the corpus take up to 759 iterations, BENCHMARKS.md).
    pub max_iters: usize,
    /// Scale-free gradient-norm tolerance `‖∇E‖·√(area)` (a sufficient stop).
    pub grad_tol: f64,
    /// Converged when `(E_{k−W} − E_k) / (W · E_k)` is under this, `W` =
    /// [`GlobalOptions::energy_window`], on the true energy (no progressive references).
    ///
    /// Why this is scale-free and enough: `E` is an area-weighted *mean* of a per-face energy
    /// bounded below by its value at a rotation (MIPS 2, SD 4), so the ratio is a pure number,
    /// the same for any mesh size, unit or face count. With the iteration converging at rate
    /// `ρ`, the energy left to gain is about `ρ/(1−ρ)` times the last decrease, so 1e-6 per
    /// iteration leaves under 1e-3 of the energy unless `ρ > 0.999` — the proxy and Newton
    /// phases converge far faster than that. SLIM's usual test (libigl, the corpus reference)
    /// is the same quantity per single iteration.
    pub energy_tol: f64,
    /// Iterations the decrease is averaged over: one iteration can decrease little by chance
    /// (a short step at a nearly flipping face, a phase switch), a run of them cannot.
    pub energy_window: usize,
    /// Stay in the proxy phase while the relative objective decrease per step exceeds this.
    pub proxy_switch: f64,
    /// Stop where the proxy phase ends ([`StopReason::ProxyDone`]): the map then has the
    /// energy's global scales and is a start for another solver (see
    /// [`crate::param::compute_map`]: SD's ADMM start).
    pub proxy_only: bool,
    /// Per-face energy bound for progressive references (`None`: always the rest triangles).
    pub progressive_cap: Option<f64>,
    /// Iterations after which progressive references are dropped even if some faces are
    /// still over the bound.
    pub progressive_max_iters: usize,
    /// Linear solver of the proxy and Newton systems: sparse Cholesky (the default: the
    /// symbolic analysis once per solve, a numeric factorisation per iteration, exact
    /// directions whatever the Hessian's conditioning, which is what CG's iteration count
    /// grows with near convergence; the atlas sweep of all 77 non-disk corpus meshes ran 77/77
    /// with the same energies, BENCHMARKS.md issue 26) or PCG with the options below.
    pub linear_solver: LinearSolver,
    /// Preconditioner of the CG solves.
    pub preconditioner: Preconditioner,
    /// Relative CG tolerance in the proxy phase (a direction only needs to be rough).
    pub cg_tol_proxy: f64,
    /// Tightest relative CG tolerance in the Newton phase (the solve is looser while the
    /// gradient is large).
    pub cg_tol_newton: f64,
    pub cg_max_iters: usize,
    /// Try the exact Hessian after a full Newton step was accepted.
    pub exact_newton: bool,
    /// Keep the map bijective: no boundary of the chart crosses itself or another part of the
    /// chart ([`scaffold`]). The start map must then have a simple boundary. The scaffold is
    /// joined lazily, at the first step whose end overlaps (that step is not taken): until
    /// then the iterates are those of the unconstrained solve, so a map that never comes
    /// near overlapping costs nothing more and ends where the unconstrained one does.
    pub bijective: bool,
    /// Raised by the caller (Ctrl-C) to stop after the current iteration.
    pub stop: Option<Arc<AtomicBool>>,
}

impl GlobalOptions {
    /// The documented defaults for `energy`.
    pub fn for_energy(energy: Energy) -> GlobalOptions {
        GlobalOptions {
            energy,
            max_iters: 1000,
            grad_tol: match energy {
                Energy::SymmetricDirichlet => 1e-6,
                Energy::Mips => 1e-4,
            },
            energy_tol: 1e-6,
            energy_window: 3,
            proxy_switch: 0.1,
            proxy_only: false,
            progressive_cap: Some(match energy {
                Energy::SymmetricDirichlet => 50.0,
                Energy::Mips => 20.0,
            }),
            progressive_max_iters: 30,
            linear_solver: LinearSolver::default(),
            preconditioner: Preconditioner::Amg { block_size: 2 },
            cg_tol_proxy: 1e-2,
            cg_tol_newton: 1e-8,
            cg_max_iters: 2000,
            exact_newton: true,
            bijective: true,
            stop: None,
        }
    }
}

/// Which direction an iteration took.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// SLIM-like reweighted Laplacian.
    Proxy,
    /// Projected Newton (composite-majorization phase).
    Newton,
    /// Newton with the exact Hessian (tried near the optimum, where the sum over faces is
    /// positive definite although single faces are not; falls back to the projected one).
    ExactNewton,
}

/// Why [`solve`] returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    GradientTolerance,
    /// The relative energy decrease per iteration over the window is under tolerance.
    EnergyConverged,
    MaxIterations,
    /// No step along the direction decreased the energy (converged to rounding).
    Stalled,
    Interrupted,
    /// The proxy phase ended ([`GlobalOptions::proxy_only`]).
    ProxyDone,
}

/// One iteration of [`solve`].
#[derive(Clone, Debug, Serialize)]
pub struct GlobalIteration {
    pub iteration: usize,
    pub phase: Phase,
    /// Objective before and after the step (w.r.t. the references in use; with the scaffold on,
    /// its share included).
    pub objective_before: f64,
    pub objective_after: f64,
    /// True energy (rest references) after the step.
    pub energy: f64,
    /// Scale-free gradient norm of the objective before the step.
    pub grad_norm: f64,
    /// Accepted step and the largest flip-free step along the direction.
    pub step: f64,
    pub max_step: f64,
    pub cg_iterations: usize,
    /// Faces on a progressive reference (0: the true problem).
    pub capped_faces: usize,
    /// Seconds since the solver started.
    pub seconds: f64,
}

/// Iterations and seconds per phase.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PhaseTotals {
    pub proxy_iterations: usize,
    pub proxy_seconds: f64,
    pub newton_iterations: usize,
    pub newton_seconds: f64,
    /// Of the Newton iterations, those that used the exact Hessian.
    pub exact_newton_iterations: usize,
    /// Exact-Hessian attempts that found negative curvature (their CG runs are wasted).
    pub exact_newton_failures: usize,
}

/// What [`solve`] returns.
#[derive(Clone, Debug, Serialize)]
pub struct GlobalResult {
    /// #V flip-free UVs (MIPS: scaled to the 3D area).
    #[serde(skip)]
    pub uv: Vec<[f64; 2]>,
    pub iterations: usize,
    pub stop: StopReason,
    /// Final true energy (area-weighted mean) and scale-free gradient norm.
    pub energy: f64,
    pub grad_norm: f64,
    /// Relative energy decrease per iteration over the last `energy_window` iterations (∞
    /// before there were that many on the true energy).
    pub energy_decrease: f64,
    pub energy_window: usize,
    pub energy_tol: f64,
    /// Iterations taken with the scaffold on ([`GlobalOptions::bijective`]; 0: the map never
    /// came near overlapping and is the unconstrained solver's).
    pub scaffold_iterations: usize,
    pub totals: PhaseTotals,
    pub history: Vec<GlobalIteration>,
}

impl GlobalResult {
    /// Whether the run reached the gradient tolerance, or stalled because no step along the
    /// direction lowered the energy any more (converged to rounding). An iteration cap or an
    /// interruption is not convergence.
    pub fn converged(&self) -> bool {
        matches!(
            self.stop,
            StopReason::GradientTolerance | StopReason::EnergyConverged | StopReason::Stalled
        )
    }

    /// Why the solver stopped; when it did not converge, how far from its stop test it was.
    pub fn stop_summary(&self) -> String {
        let why = match self.stop {
            StopReason::GradientTolerance => "converged (gradient norm)",
            StopReason::EnergyConverged => "converged (energy decrease under tolerance)",
            StopReason::Stalled => "converged (no step decreases the energy)",
            StopReason::MaxIterations => "iteration cap",
            StopReason::Interrupted => "interrupted",
            StopReason::ProxyDone => "proxy phase done (decrease per step under its switch)",
        };
        format!(
            "global {why} after {} iterations (relative energy decrease {:.1e} per iteration over the last {} iterations, tolerance {:.0e}; gradient norm {:.1e})",
            self.iterations, self.energy_decrease, self.energy_window, self.energy_tol, self.grad_norm
        )
    }
}

/// The data of a solve: the chart's faces, then (while the scaffold is on) the scaffold's.
#[derive(Clone)]
struct Problem {
    energy: Energy,
    faces: Vec<[u32; 3]>,
    rest: Vec<FaceGradient>,
    /// Chart faces: `area_f / total area`; scaffold faces: the step's scaffold weight
    /// ([`scaffold::next_weight`]) times the chart's energy, shared equally.
    weight: Vec<f64>,
    /// Faces of the chart (the first ones); the rest are scaffold.
    n_chart: usize,
    /// Unknowns that move: the chart's 2·#V (the scaffold's frame, after them, is fixed).
    free: usize,
    /// √(total 3D area): makes gradient norms scale-free.
    grad_scale: f64,
}

impl Problem {
    /// The energy of face `i`: the chart's, or symmetric Dirichlet on the scaffold (a barrier
    /// against collapse; MIPS is scale-invariant and would let a scaffold triangle shrink to
    /// nothing).
    fn energy_of(&self, i: usize) -> Energy {
        if i < self.n_chart {
            self.energy
        } else {
            Energy::SymmetricDirichlet
        }
    }

    /// `Σ w_f E(A_f)` under `grads`; +∞ if any face is flipped or degenerate.
    fn objective(&self, grads: &[FaceGradient], x: &[f64]) -> f64 {
        crate::linalg::ordered_sum(self.faces.len(), |i| {
            self.weight[i]
                * energy::value(self.energy_of(i), &jacobian(&grads[i], &self.faces[i], x))
        })
    }

    /// Gradient of the objective under `grads` (2·#V).
    fn gradient(&self, grads: &[FaceGradient], x: &[f64]) -> Vec<f64> {
        let local: Vec<[f64; 6]> = self
            .faces
            .par_iter()
            .zip(grads.par_iter())
            .zip(self.weight.par_iter())
            .enumerate()
            .map(|(i, ((f, g), w))| {
                let (_, ge, _) = energy::eval(self.energy_of(i), &jacobian(g, f, x));
                pull_back(g, &ge.map(|v| v * w))
            })
            .collect();
        let mut out = vec![0.0; x.len()];
        for (f, l) in self.faces.iter().zip(&local) {
            for k in 0..3 {
                out[2 * f[k] as usize] += l[2 * k];
                out[2 * f[k] as usize + 1] += l[2 * k + 1];
            }
        }
        out
    }

    /// This chart problem (no scaffold yet) with the scaffold `s` joined at total weight
    /// `weight` ([`scaffold::next_weight`]) of the chart's true energy `e`.
    fn with_scaffold(&self, s: &scaffold::Scaffold, e: f64, weight: f64) -> Problem {
        let mut p = self.clone();
        p.faces.extend_from_slice(&s.faces);
        p.rest.extend_from_slice(&s.rest);
        let w = weight * e / s.faces.len().max(1) as f64;
        p.weight.extend(std::iter::repeat_n(w, s.faces.len()));
        p
    }
}

/// The solver's objective at `uv` (area-weighted mean energy, +∞ when a face is flipped) and
/// its gradient over the interleaved UVs `[u0, v0, u1, …]`: what [`solve`] minimises, for
/// checks and for callers that want to score a map the way the solver does.
pub fn objective_and_gradient(
    mesh: &TriMesh,
    frames: &FaceFrames,
    energy: Energy,
    uv: &[[f64; 2]],
) -> Result<(f64, Vec<f64>), SolveError> {
    let total: f64 = frames.area.iter().sum();
    if uv.len() != mesh.positions.len() || total.is_nan() || total <= 0.0 {
        return Err(SolveError::InvalidInput {
            what: format!(
                "{} UVs for {} vertices (total area {total})",
                uv.len(),
                mesh.positions.len()
            ),
        });
    }
    let problem = Problem {
        energy,
        faces: mesh.faces.clone(),
        n_chart: mesh.faces.len(),
        free: 2 * mesh.positions.len(),
        rest: face_gradients(frames)?,
        weight: frames.area.iter().map(|a| a / total).collect(),
        grad_scale: total.sqrt(),
    };
    let x: Vec<f64> = uv.iter().flat_map(|p| [p[0], p[1]]).collect();
    let e = problem.objective(&problem.rest, &x);
    let g = if e.is_finite() {
        problem.gradient(&problem.rest, &x)
    } else {
        vec![f64::NAN; x.len()]
    };
    Ok((e, g))
}

/// Relative diagonal shift of every system (see [`Pattern::fill`]).
const REL_SHIFT: f64 = 1e-9;

/// CG tolerance of a Newton solve per unit of scale-free gradient norm.
const FORCING: f64 = 0.01;

/// Longest wait (iterations) between exact-Hessian attempts.
const MAX_BACKOFF: usize = 4;

/// Progressive references end once fewer than one face in this many is capped.
const PROGRESSIVE_MIN_SHARE: usize = 1000;

/// Objective decreases below this relative size count as no progress.
const STALL: f64 = 1e-13;

/// Whether a directional derivative is a (finite) descent slope; NaN is not.
fn descends(slope: f64) -> bool {
    slope < 0.0
}

/// Minimises the energy of `opts` over the UVs of `mesh` from the flip-free start `uv0`.
/// `progress` sees every iteration. Errors: a start map that is flipped or non-finite, a
/// degenerate face, a failed linear solve; the result is verified flip-free and finite.
pub fn solve(
    mesh: &TriMesh,
    frames: &FaceFrames,
    uv0: &[[f64; 2]],
    opts: &GlobalOptions,
    progress: &mut dyn FnMut(&GlobalIteration),
) -> Result<GlobalResult, SolveError> {
    let t0 = Instant::now();
    let nv = mesh.positions.len();
    if uv0.len() != nv {
        return Err(SolveError::InvalidInput {
            what: format!("{} UVs for {nv} vertices", uv0.len()),
        });
    }
    let total: f64 = frames.area.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return Err(SolveError::InvalidInput {
            what: "the mesh has no area".into(),
        });
    }
    let chart = Problem {
        energy: opts.energy,
        faces: mesh.faces.clone(),
        n_chart: mesh.faces.len(),
        free: 2 * mesh.positions.len(),
        rest: face_gradients(frames)?,
        weight: frames.area.iter().map(|a| a / total).collect(),
        grad_scale: total.sqrt(),
    };
    // The chart's UVs; an iteration works on a copy, extended by the scaffold's frame.
    let mut xc: Vec<f64> = uv0.iter().flat_map(|p| [p[0], p[1]]).collect();
    if !chart.objective(&chart.rest, &xc).is_finite() {
        return Err(SolveError::InvalidInput {
            what: "the start map of the global solver has flipped, degenerate or non-finite faces"
                .into(),
        });
    }
    let boundary = opts
        .bijective
        .then(|| scaffold::boundary_edges(&mesh.faces));
    if let Some(b) = &boundary {
        if scaffold::Scaffold::build(&xc, nv, b).is_none() {
            return Err(SolveError::InvalidInput {
                what: "the start map of the bijective global solver has a boundary that touches \
                       or crosses itself"
                    .into(),
            });
        }
    }
    // Whether the scaffold is on (from the first step that would have overlapped).
    let mut scaffolded = false;
    // The scaffold while it is on, and whether to re-triangulate it before the next iteration.
    let mut scaffold: Option<scaffold::Scaffold> = None;
    let mut remesh = true;
    // The scaffold's weight (adapted per step, [`scaffold::next_weight`]); SCAF's at contact.
    let mut scaffold_weight = scaffold::WEIGHT;
    let mut scaffold_iterations = 0;
    let mut pattern = Pattern::new(mesh)?;
    // The scaffold's triangles, pattern and symbolic factorisation, while it is on.
    let mut scaffold_system: Option<(Pattern, Option<CholeskySymbolic>)> = None;
    // Sparse Cholesky's ordering and symbolic factorisation of the pattern, on first use.
    let mut symbolic: Option<CholeskySymbolic> = None;
    let mut history = Vec::new();
    let mut totals = PhaseTotals::default();
    let mut phase = Phase::Proxy;
    let mut progressive = opts.progressive_cap.is_some();
    let mut d = Vec::new();
    let mut stop = StopReason::MaxIterations;
    let mut iterations = 0;
    let mut try_exact = false;
    let mut e_prev = f64::INFINITY;
    let mut stop_test = stop::StopTest::new(opts);
    // Iterations to wait before the next exact-Hessian attempt, and the current back-off.
    let (mut wait, mut backoff) = (0usize, 0usize);

    for it in 0..opts.max_iters {
        if opts
            .stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed))
        {
            stop = StopReason::Interrupted;
            break;
        }
        let t_it = Instant::now();
        // The problem of this iteration: the chart, with the scaffold when it is on (its frame
        // vertices appended to the chart's UVs; fixed, so not unknowns of the linear systems).
        // The scaffold is re-triangulated when the last step was limited by it (a scaffold
        // triangle about to flip where the chart's boundary is not near contact is a poor
        // triangulation, and the Delaunay one of the current boundary is the best there is);
        // otherwise its triangles stay and only their rest shapes are reset to the current
        // ones, so the pattern and the symbolic factorisation stay too.
        // Whether the scaffold's triangles are new this iteration (its system then needs
        // their slots, or a new pattern).
        let mut retriangulated = false;
        if let (Some(b), true) = (&boundary, scaffolded) {
            let kept = !remesh && scaffold.as_mut().is_some_and(|s| s.reset_rest(&xc, nv));
            if !kept {
                retriangulated = true;
                let s =
                    scaffold::Scaffold::build(&xc, nv, b).ok_or_else(|| SolveError::Failed {
                        what:
                            "global solver: the chart's boundary touches itself under the scaffold"
                                .into(),
                    })?;
                scaffold = Some(s);
            }
        }
        let (problem, mut x) = match &scaffold {
            Some(s) => (
                Cow::Owned(chart.with_scaffold(
                    s,
                    chart.objective(&chart.rest, &xc),
                    scaffold_weight,
                )),
                xc.iter()
                    .copied()
                    .chain(s.frame.iter().flatten().copied())
                    .collect(),
            ),
            None => (Cow::Borrowed(&chart), xc.clone()),
        };
        // The scaffold's system: its pattern and symbolic factorisation are kept while the
        // scaffold keeps its triangles, and across a re-triangulation whose triangles the
        // pattern already has blocks for: the pattern also holds, for every edge between two
        // scaffold triangles, the other diagonal of their quad (the edge a flip would make).
        // A new pattern costs an ordering and a symbolic analysis, about three numeric
        // factorisations of a 2D-mesh system; the frame's vertices are not unknowns (the
        // frame is fixed), so triangles that only change how the boundary meets the frame
        // change no block either. A new pattern is the chart's with the boundary rows merged
        // ([`Pattern::extended`]); triangles kept from the last iteration need nothing.
        if let (Some(s), true) = (&scaffold, retriangulated) {
            let n = chart.n_chart;
            // Same structure after a rebind: the symbolic factorisation stays valid.
            let kept = scaffold_system
                .as_mut()
                .is_some_and(|c| c.0.rebind(n, &problem.faces[n..]));
            if !kept {
                let p = pattern.extended(&chart.faces, &problem.faces[n..], &s.flip_diagonals());
                scaffold_system = Some((p, None));
            }
        }
        let (pattern, symbolic) = match (&scaffold, &mut scaffold_system) {
            (Some(_), Some((p, s))) => (p, s),
            _ => (&mut pattern, &mut symbolic),
        };
        d.clear();
        d.resize(x.len(), 0.0);
        // References of this iteration.
        let (mut grads, capped) = match (progressive, opts.progressive_cap) {
            (true, Some(cap)) if it < opts.progressive_max_iters => {
                let pairs: Vec<(FaceGradient, bool)> = chart
                    .faces
                    .par_iter()
                    .zip(chart.rest.par_iter())
                    .map(|(f, g)| {
                        progressive::capped_gradient(opts.energy, g, &jacobian(g, f, &xc), cap)
                    })
                    .collect();
                let capped = pairs.iter().filter(|p| p.1).count();
                (pairs.into_iter().map(|p| p.0).collect::<Vec<_>>(), capped)
            }
            _ => (chart.rest.clone(), 0),
        };
        grads.extend_from_slice(&problem.rest[chart.n_chart..]);
        if capped == 0 {
            progressive = false;
        }
        let f0 = problem.objective(&grads, &x);
        let mut g = problem.gradient(&grads, &x);
        // The frame does not move.
        g[2 * nv..].fill(0.0);
        let grad_norm = dot(&g, &g).sqrt() * problem.grad_scale;
        if stop_test.gradient_met(grad_norm, capped) {
            stop = StopReason::GradientTolerance;
            break;
        }
        // Projected Newton converges only linearly where faces are non-convex (their clamped
        // modes); once full steps are accepted the exact Hessian is tried: near a minimum the
        // assembled one is positive definite, and CG reports when it is not.
        // Inexact Newton (Eisenstat & Walker 1996): a loose solve far from the optimum,
        // tightening with the gradient so the final convergence stays superlinear.
        let forcing = FORCING * grad_norm;
        let allow_exact = wait == 0;
        wait = wait.saturating_sub(1);
        let mut used = if phase == Phase::Newton && try_exact && opts.exact_newton && allow_exact {
            Phase::ExactNewton
        } else {
            phase
        };
        let mut cg_iterations = 0;
        let mut slope = f64::NAN;
        if used == Phase::ExactNewton {
            match direction(
                &problem, &grads, &x, &g, used, pattern, symbolic, opts, forcing, &mut d,
            ) {
                Ok((s, c)) => {
                    cg_iterations += c;
                    slope = s;
                }
                // Negative curvature: not near a minimum yet.
                Err(SolveError::Failed { .. }) => {}
                Err(e) => return Err(e),
            }
            if descends(slope) {
                backoff = 0;
            } else {
                // A failed attempt costs a CG run: back off exponentially before the next.
                totals.exact_newton_failures += 1;
                used = Phase::Newton;
                backoff = (2 * backoff).clamp(1, MAX_BACKOFF);
                wait = backoff;
            }
        }
        if used != Phase::ExactNewton {
            let (s, c) = direction(
                &problem, &grads, &x, &g, used, pattern, symbolic, opts, forcing, &mut d,
            )?;
            slope = s;
            cg_iterations += c;
        }
        if used == Phase::Newton && !descends(slope) {
            // An inexact or indefinite Newton solve: the proxy direction always descends.
            let (s, c) = direction(
                &problem,
                &grads,
                &x,
                &g,
                Phase::Proxy,
                pattern,
                symbolic,
                opts,
                forcing,
                &mut d,
            )?;
            slope = s;
            cg_iterations += c;
            used = Phase::Proxy;
        }
        let f = |y: &[f64]| problem.objective(&grads, y);
        let mut max_step = line_search::max_flip_free(&grads, &problem.faces, &x, &d);
        let t_start = (line_search::FLIP_FREE_FRACTION * max_step).min(1.0);
        let mut accepted = line_search::armijo(&f, &x, &d, f0, slope, t_start);
        if accepted.is_none() && used != Phase::Proxy {
            // A Newton direction can be too poor a model to decrease at all (rounding near
            // the optimum, or a bad inexact solve): the proxy direction gets the last word.
            let (s, c) = direction(
                &problem,
                &grads,
                &x,
                &g,
                Phase::Proxy,
                pattern,
                symbolic,
                opts,
                forcing,
                &mut d,
            )?;
            cg_iterations += c;
            used = Phase::Proxy;
            max_step = line_search::max_flip_free(&grads, &problem.faces, &x, &d);
            let t_start = (line_search::FLIP_FREE_FRACTION * max_step).min(1.0);
            accepted = line_search::armijo(&f, &x, &d, f0, s, t_start);
        }
        let Some(acc) = accepted else {
            stop = StopReason::Stalled;
            break;
        };
        if scaffold.is_some() {
            let n = chart.n_chart;
            let chart_max = line_search::max_flip_free(&grads[..n], &problem.faces[..n], &x, &d);
            remesh = line_search::FLIP_FREE_FRACTION * max_step < 1.0 && max_step < chart_max;
            scaffold_weight = scaffold::next_weight(scaffold_weight, remesh);
        }
        x.par_iter_mut()
            .zip(d.par_iter())
            .for_each(|(xi, di)| *xi += acc.step * di);
        if let Some(b) = &boundary {
            let uv: &[[f64; 2]] = bytemuck::cast_slice(&x[..2 * nv]);
            if crate::metrics::segment_intersections(uv, b) > 0 {
                if scaffolded {
                    // Cannot happen (every scaffold triangle stayed positive); should rounding
                    // say otherwise, the last bijective map is the result.
                    stop = StopReason::Stalled;
                    break;
                }
                // The first step that would overlap is not taken: from here on the scaffold
                // is on, and this iteration is done again with it.
                scaffolded = true;
                continue;
            }
        }
        xc.copy_from_slice(&x[..2 * nv]);
        if scaffold.is_some() {
            scaffold_iterations += 1;
        }
        iterations = it + 1;
        let e_true = if capped == 0 && scaffold.is_none() {
            acc.value
        } else {
            chart.objective(&chart.rest, &xc)
        };
        let rel = (f0 - acc.value) / f0.abs().max(f64::MIN_POSITIVE);
        let secs = t_it.elapsed().as_secs_f64();
        match used {
            Phase::Proxy => {
                totals.proxy_iterations += 1;
                totals.proxy_seconds += secs;
            }
            Phase::Newton | Phase::ExactNewton => {
                totals.newton_iterations += 1;
                totals.newton_seconds += secs;
                if used == Phase::ExactNewton {
                    totals.exact_newton_iterations += 1;
                }
            }
        }
        try_exact = phase == Phase::Newton && acc.step == 1.0;
        let rec = GlobalIteration {
            iteration: it + 1,
            phase: used,
            objective_before: f0,
            objective_after: acc.value,
            energy: e_true,
            grad_norm,
            step: acc.step,
            max_step,
            cg_iterations,
            capped_faces: capped,
            seconds: t0.elapsed().as_secs_f64(),
        };
        progress(&rec);
        history.push(rec);
        if phase == Phase::Proxy && rel <= opts.proxy_switch {
            if opts.proxy_only {
                stop = StopReason::ProxyDone;
                break;
            }
            phase = Phase::Newton;
        }
        // A reference that follows a few stubborn faces lets the surrogate fall while the
        // true energy rises: progressive references end once they are that few, or as soon as
        // the true energy went up.
        if capped > 0 && (e_true > e_prev || capped * PROGRESSIVE_MIN_SHARE <= chart.n_chart) {
            progressive = false;
        }
        e_prev = e_true;
        if capped == 0 && rel <= STALL {
            stop = StopReason::Stalled;
            break;
        }
        if stop_test.energy_met(e_true, capped) {
            stop = StopReason::EnergyConverged;
            break;
        }
    }

    let energy = chart.objective(&chart.rest, &xc);
    let g = chart.gradient(&chart.rest, &xc);
    let grad_norm = dot(&g, &g).sqrt() * chart.grad_scale;
    if stop == StopReason::Stalled && grad_norm <= opts.grad_tol {
        // Stalled at rounding level after the last step already met the tolerance.
        stop = StopReason::GradientTolerance;
    }
    let mut uv: Vec<[f64; 2]> = xc.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
    if opts.energy == Energy::Mips {
        // MIPS has no scale: report the map at the 3D area, like the start map.
        crate::init::normalize_area(mesh, &mut uv, total);
    }
    let flips = crate::init::count_flips(&mesh.faces, &uv);
    if flips > 0 || !energy.is_finite() {
        return Err(SolveError::Failed {
            what: format!("global solver: {flips} flipped faces in the result (energy {energy})"),
        });
    }
    if uv.iter().flatten().any(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite {
            what: "global solver UVs".into(),
        });
    }
    Ok(GlobalResult {
        uv,
        iterations,
        stop,
        energy,
        grad_norm,
        energy_decrease: stop_test.decrease(),
        energy_window: stop_test.window(),
        energy_tol: opts.energy_tol,
        scaffold_iterations,
        totals,
        history,
    })
}

/// Writes the search direction of `phase` into `d` (solving `K d = −g`) and returns the slope
/// `gᵀd` and the CG iterations. A CG solve that stops at its iteration cap still gives a usable
/// direction (checked by the slope), so only hard failures are errors.
#[allow(clippy::too_many_arguments)]
fn direction(
    problem: &Problem,
    grads: &[FaceGradient],
    x: &[f64],
    g: &[f64],
    phase: Phase,
    pattern: &mut Pattern,
    symbolic: &mut Option<CholeskySymbolic>,
    opts: &GlobalOptions,
    forcing: f64,
    d: &mut [f64],
) -> Result<(f64, usize), SolveError> {
    let local: Vec<[[f64; 6]; 6]> = problem
        .faces
        .par_iter()
        .zip(grads.par_iter())
        .zip(problem.weight.par_iter())
        .map(|((f, gr), &w)| {
            let a = jacobian(gr, f, x);
            let m = match phase {
                Phase::Proxy => proxy::proxy_matrix(problem.energy, &a, w),
                Phase::Newton => cm::projected_hessian(problem.energy, &a, w),
                Phase::ExactNewton => energy::eval(problem.energy, &a).2.map(|r| r.map(|v| v * w)),
            };
            pull_back_matrix(gr, &m)
        })
        .collect();
    pattern.fill(&problem.faces, &local, REL_SHIFT);
    // The unknowns are the chart's; the scaffold's frame (after them) does not move.
    let free = problem.free;
    d[free..].fill(0.0);
    let d = &mut d[..free];
    let rhs: Vec<f64> = g[..free].iter().map(|v| -v).collect();
    if opts.linear_solver == LinearSolver::Cholesky {
        if symbolic.is_none() {
            *symbolic = Some(CholeskySymbolic::blocked(&pattern.matrix, 2)?);
        }
        let factor = symbolic.as_ref().map(|s| s.factor(&pattern.matrix));
        match factor {
            Some(Ok(chol)) => {
                chol.solve(&rhs, d)?;
                return Ok((dot(&g[..free], d), 0));
            }
            // An exact Hessian away from a minimum: `SolveError::Failed`, which the caller
            // treats like CG's negative curvature.
            Some(Err(e @ DirectError::NotPositiveDefinite { .. }))
                if phase == Phase::ExactNewton =>
            {
                return Err(e.into())
            }
            // The proxy and projected Hessians are positive definite up to the diagonal shift;
            // should rounding still break the factorisation, CG below gets the step.
            Some(Err(DirectError::NotPositiveDefinite { .. })) => {}
            Some(Err(e)) => return Err(e.into()),
            // Set above.
            None => {}
        }
    }
    let cg = CgOptions {
        tolerance: match phase {
            Phase::Proxy => opts.cg_tol_proxy,
            // The caller's forcing term, bounded.
            Phase::Newton | Phase::ExactNewton => {
                forcing.clamp(opts.cg_tol_newton, opts.cg_tol_newton.max(1e-2))
            }
        },
        max_iterations: opts.cg_max_iters,
        preconditioner: opts.preconditioner,
    };
    let solver = KrylovSolver::cg(&pattern.matrix, &cg)?;
    d.fill(0.0);
    let iterations = match solver.solve(&rhs, d) {
        Ok(stats) => stats.iterations,
        Err(SolveError::CgNoConvergence { iterations, .. }) => iterations,
        Err(e) => return Err(e),
    };
    if d.iter().any(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite {
            what: "global solver search direction".into(),
        });
    }
    Ok((dot(&g[..free], d), iterations))
}
