//! The CPU backend: the exact ADMM iteration of the shaders, in f64, parallel over faces,
//! edges and slots with rayon. It is the reference the Vulkan backend is tested against and
//! the fast path on machines whose only Vulkan device is a software rasterizer.

use rayon::prelude::*;

// Elements per partial sum in `residuals` (fixed, so the summation order is too): the
// chunking of `crate::linalg::ordered_sum`.
use crate::linalg::SUM_CHUNK;

use super::anderson::Anderson;
use super::driver::{Accel, Executor, Residuals};
use super::kernels;
use super::{AdmmProblem, AdmmState, NO_SLOT};
use crate::param::energy::{self, Energy};

/// Runs the iteration on the host.
pub struct CpuExecutor<'p> {
    problem: &'p AdmmProblem,
    energy: Energy,
    newton_iters: u32,
    state: AdmmState,
    /// #F penalty factors `m_f` ([`penalty_factors`]): face `f`'s penalty is `μ m_f`.
    penalty: Vec<f64>,
    accel: Option<Accelerator>,
}

/// Anderson acceleration with the safeguard of Zhang et al. 2019: an accelerated step is kept
/// only while the combined residual `Σ‖Y⁺ − A⁺‖² + Σ‖Y⁺ − Y‖²` of the iteration it feeds keeps
/// decreasing; otherwise the iterate goes back to the last plain ADMM output and the history is
/// dropped. So the worst case is plain ADMM plus one wasted iteration per rejection.
struct Accelerator {
    aa: Anderson,
    /// `A` of the last accepted plain ADMM output, to fall back to; its edge state is
    /// [`Anderson::last_plain`] (packed), so only `A` is copied. The driver's residuals are
    /// measured on this output (the accelerated `(Y, Λ)` is an extrapolation, not an ADMM
    /// iterate).
    fallback_a: Vec<[f64; 4]>,
    /// `A` before the iteration that produced the fallback (for the dual residual).
    fallback_a_prev: Vec<[f64; 4]>,
    /// Combined residual of the last accepted iteration.
    last_residual: f64,
    /// The next iteration is accepted unconditionally (start, after a reset or a rejection).
    restart: bool,
    /// μ and block length the history was built with.
    mu: f64,
    block: usize,
    /// Iterations per Anderson step.
    every: usize,
    /// `Y` and `A` before the last iteration of a block (buffers reused across iterations).
    y_last: Vec<[f64; 4]>,
    a_in: Vec<[f64; 4]>,
    accepted: usize,
    rejected: usize,
    /// Scratch: the reduced state `w = Y − Λ/μ` ([`pack_state`]), input and output of one
    /// iteration.
    x: Vec<f64>,
    g: Vec<f64>,
    /// `x` already holds the packed current state (the accelerated output of the last block:
    /// `pack(unpack(w)) = w`, so the next block need not pack again).
    x_ready: bool,
    /// Off: plain iterations (the driver switches acceleration on once plain ADMM has not
    /// converged quickly; short runs then pay nothing for it).
    active: bool,
}

impl Accelerator {
    fn reset(&mut self) {
        self.aa.reset();
        self.restart = true;
        self.last_residual = f64::INFINITY;
        self.x_ready = false;
    }
}

/// Writes the reduced edge state `w_t = Y_t − Λ_t/μ` flattened into `out`.
///
/// After one iteration `Y = P w` and `Λ/μ = Y − w = −P⊥ w`, with `P` the (orthogonal, per
/// edge) projection onto the consensus set `{Y1 ê1 = Y2 ê2}` that the edge step applies and
/// `P⊥ = I − P`: the edge step makes `Y` consistent and the dual step leaves `Λ` in the
/// complement. So `w` alone determines the next iteration (the Douglas–Rachford form of this
/// ADMM), and since `(Y, Λ/μ) ↦ w` is an isometry on such states, Anderson on `w` takes the
/// same steps as on `(Y, Λ/μ)` over half the data.
fn pack_state(problem: &AdmmProblem, state: &AdmmState, pen: Penalty, out: &mut Vec<f64>) {
    out.resize(state.y.len() * 4, 0.0);
    out.par_chunks_mut(4)
        .zip(state.y.par_iter().zip(state.lambda.par_iter()))
        .enumerate()
        .for_each(|(s, (w, (y, l)))| {
            let mu = pen.slot(problem, s);
            for i in 0..4 {
                w[i] = y[i] - l[i] / mu;
            }
        });
}

/// Inverse of [`pack_state`] for the edge state (`A` is left alone): `Y = P w`,
/// `Λ = μ (Y − w)`.
fn unpack_state(problem: &AdmmProblem, v: &[f64], pen: Penalty, state: &mut AdmmState) {
    state
        .y
        .par_chunks_mut(2)
        .zip(state.lambda.par_chunks_mut(2))
        .zip(v.par_chunks(8))
        .enumerate()
        .for_each(|(i, ((y, l), w))| {
            let w1: [f64; 4] = std::array::from_fn(|k| w[k]);
            let w2: [f64; 4] = std::array::from_fn(|k| w[4 + k]);
            let (mu1, mu2) = (pen.slot(problem, 2 * i), pen.slot(problem, 2 * i + 1));
            let (y1, y2) = kernels::edge_project(
                &w1,
                &w2,
                &[0.0; 4],
                &[0.0; 4],
                &problem.slot_dir[2 * i],
                &problem.slot_dir[2 * i + 1],
                mu1,
                mu2,
            );
            y[0] = y1;
            y[1] = y2;
            l[0] = std::array::from_fn(|k| mu1 * (y1[k] - w1[k]));
            l[1] = std::array::from_fn(|k| mu2 * (y2[k] - w2[k]));
        });
}

/// `Σ_t ‖Y⁺_t − A⁺_ft‖² + ‖Y⁺_t − Y_t‖²`, with `Y` the last iteration's input.
fn combined_residual(
    problem: &AdmmProblem,
    state: &AdmmState,
    y_in: &[[f64; 4]],
    pen: Penalty,
) -> f64 {
    let ns = problem.n_slots();
    (0..ns.div_ceil(SUM_CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut r = 0.0;
            for s in c * SUM_CHUNK..((c + 1) * SUM_CHUNK).min(ns) {
                let f = problem.slot_face[s] as usize;
                let (a, y) = (&state.a[f], &state.y[s]);
                let m = pen.factor.get(f).copied().unwrap_or(1.0);
                for i in 0..4 {
                    r += m * ((y[i] - a[i]).powi(2) + (y[i] - y_in[s][i]).powi(2));
                }
            }
            r
        })
        .collect::<Vec<_>>()
        .iter()
        .sum()
}

impl<'p> CpuExecutor<'p> {
    pub fn new(problem: &'p AdmmProblem, energy: Energy, newton_iters: u32) -> CpuExecutor<'p> {
        let state = AdmmState {
            a: Vec::new(),
            y: Vec::new(),
            lambda: Vec::new(),
        };
        CpuExecutor {
            problem,
            energy,
            newton_iters,
            state,
            penalty: Vec::new(),
            accel: None,
        }
    }

    /// Selects the acceleration (`depth` = Anderson history length, one Anderson step every
    /// `every` iterations).
    pub fn with_accel(mut self, accel: Accel, depth: usize, every: usize) -> CpuExecutor<'p> {
        self.accel = match accel {
            Accel::None => None,
            Accel::Anderson => Some(Accelerator {
                aa: Anderson::new(depth),
                fallback_a: Vec::new(),
                fallback_a_prev: Vec::new(),
                last_residual: f64::INFINITY,
                restart: true,
                mu: f64::NAN,
                block: 0,
                every: every.max(1),
                y_last: Vec::new(),
                a_in: Vec::new(),
                accepted: 0,
                rejected: 0,
                x: Vec::new(),
                g: Vec::new(),
                x_ready: false,
                active: true,
            }),
        };
        self
    }

    /// `k ≥ 1` ADMM iterations followed by one Anderson step on their composite map `G^k`,
    /// with the safeguard of [`Accelerator`]. Extrapolating every `k` iterations instead of
    /// every one divides the cost of the acceleration (several passes over the whole edge state)
    /// by `k`.
    fn accelerated_block(&mut self, mu: f64, k: usize) {
        let pen = Penalty {
            mu,
            factor: &self.penalty,
        };
        let Some(acc) = self.accel.as_mut() else {
            for _ in 0..k {
                iteration(
                    self.problem,
                    &mut self.state,
                    self.energy,
                    self.newton_iters,
                    pen,
                );
            }
            return;
        };
        if acc.mu != mu || acc.block != k {
            // A new μ (or block length) is a new fixed-point map: the stored differences
            // describe the old one.
            acc.reset();
            acc.mu = mu;
            acc.block = k;
        }
        if !acc.x_ready {
            pack_state(self.problem, &self.state, pen, &mut acc.x);
        }
        for _ in 1..k {
            iteration(
                self.problem,
                &mut self.state,
                self.energy,
                self.newton_iters,
                pen,
            );
        }
        acc.y_last.clone_from(&self.state.y);
        acc.a_in.clone_from(&self.state.a);
        iteration(
            self.problem,
            &mut self.state,
            self.energy,
            self.newton_iters,
            pen,
        );
        let r = combined_residual(self.problem, &self.state, &acc.y_last, pen);
        if acc.restart || r < acc.last_residual {
            acc.accepted += k;
            acc.restart = false;
            acc.last_residual = r;
            acc.fallback_a.clone_from(&self.state.a);
            std::mem::swap(&mut acc.fallback_a_prev, &mut acc.a_in);
            pack_state(self.problem, &self.state, pen, &mut acc.g);
            acc.aa.step(&acc.x, &mut acc.g);
            unpack_state(self.problem, &acc.g, pen, &mut self.state);
            std::mem::swap(&mut acc.x, &mut acc.g);
            acc.x_ready = true;
        } else {
            // The accelerated input made things worse: continue from the plain output of the
            // last accepted block (same μ: a change of μ restarts, and a restart is accepted),
            // with a fresh history.
            acc.rejected += k;
            self.state.a.clone_from(&acc.fallback_a);
            unpack_state(self.problem, acc.aa.last_plain(), pen, &mut self.state);
            acc.x.clear();
            acc.x.extend_from_slice(acc.aa.last_plain());
            acc.aa.reset();
            acc.restart = true;
            acc.x_ready = true;
        }
    }
}

/// Face `f`'s penalty `μ_f = μ m_f`: the driver's `μ` and the executor's per-face factors
/// ([`kernels::penalty_factor`]); an empty `factor` means `m_f = 1` (the uniform penalty).
#[derive(Clone, Copy, Debug)]
pub struct Penalty<'a> {
    pub mu: f64,
    pub factor: &'a [f64],
}

impl Penalty<'_> {
    /// `μ_f`.
    pub fn face(&self, f: usize) -> f64 {
        self.factor.get(f).map_or(self.mu, |m| self.mu * m)
    }

    /// The penalty of slot `s` (its face's).
    pub fn slot(&self, problem: &AdmmProblem, s: usize) -> f64 {
        self.face(problem.slot_face[s] as usize)
    }
}

/// Penalty factors `m_f` of every face for the iterate `a` ([`kernels::penalty_factor`];
/// `weight` the faces' `w_f`), computed on the host whenever an iterate is uploaded (the
/// start, a re-synchronisation) and fixed until the next upload, on both backends.
///
/// Why per face: the face step minimises `w_f E(A) + μ_f/2 Σ‖A − ·‖²`, and ADMM converges at a
/// rate set by the ratio of the penalty to the curvature of the term it splits off (Giselsson &
/// Boyd 2014, diagonal scaling of ADMM). One `μ` for faces whose curvature `w_f ∇²E` spans many
/// orders of magnitude — the exponentially shrunk protrusions of a conformal map have
/// `∇²MIPS ∝ 1/det A` up to 1e12 times the mean — leaves the stiff faces barely coupled to the
/// consensus (their residual, relative to their size, never closes and the recovered map flips
/// them: the μ-at-its-cap stalls of 24 of 61 corpus disks) while the soft ones are
/// over-coupled. With `m_f ∝ w_f κ(A_f)` the ratio is the same on every face, so `μ·F` is a
/// pure number independent of the mesh, its units and its map's scales; `m_f = 1` on a uniform
/// mesh mapped isometrically, where this is the uniform penalty.
///
/// Why fixed: the curvature is the start map's. For MIPS from LSCM (the unconstrained
/// minimiser of the same conformal energy) the start has the solution's local scales except
/// around its folds. Penalties that follow the iterate change the fixed-point map under the
/// iteration: measured, a refresh every 250 iterations (2× hysteresis) made the residual jump
/// at every refresh and the per-face energy rise instead of converge.
pub fn penalty_factors(energy: Energy, weight: &[f64], a: &[[f64; 4]]) -> Vec<f64> {
    let nf = weight.len() as f64;
    a.par_iter()
        .zip(weight)
        .map(|(a, w)| kernels::penalty_factor(energy, a, nf * w))
        .collect()
}

/// Mean of `Y_t + Λ_t/μ_f` over the slots of face `f`, and the slot count.
pub fn face_target(problem: &AdmmProblem, state: &AdmmState, f: usize, mu: f64) -> ([f64; 4], u32) {
    let mut b = [0.0; 4];
    let mut n = 0u32;
    for &s in &problem.face_slots[f] {
        if s == NO_SLOT {
            continue;
        }
        let (y, l) = (&state.y[s as usize], &state.lambda[s as usize]);
        for i in 0..4 {
            b[i] += y[i] + l[i] / mu;
        }
        n += 1;
    }
    if n > 0 {
        for x in &mut b {
            *x /= n as f64;
        }
    }
    (b, n)
}

/// One full iteration (face, edge, dual steps) on `state`, in place.
pub fn iteration(
    problem: &AdmmProblem,
    state: &mut AdmmState,
    energy: Energy,
    newton_iters: u32,
    pen: Penalty,
) {
    let new_a: Vec<[f64; 4]> = (0..problem.n_faces())
        .into_par_iter()
        .map(|f| {
            let mu = pen.face(f);
            let (bbar, n) = face_target(problem, state, f, mu);
            kernels::face_newton(
                energy,
                state.a[f],
                bbar,
                n,
                mu,
                problem.weight[f],
                newton_iters,
            )
        })
        .collect();
    state.a = new_a;
    let a = &state.a;
    let lambda = &state.lambda;
    state.y.par_chunks_mut(2).enumerate().for_each(|(i, y)| {
        let (s1, s2) = (2 * i, 2 * i + 1);
        let (f1, f2) = (
            problem.slot_face[s1] as usize,
            problem.slot_face[s2] as usize,
        );
        let (y1, y2) = kernels::edge_project(
            &a[f1],
            &a[f2],
            &lambda[s1],
            &lambda[s2],
            &problem.slot_dir[s1],
            &problem.slot_dir[s2],
            pen.face(f1),
            pen.face(f2),
        );
        y[0] = y1;
        y[1] = y2;
    });
    let y = &state.y;
    state.lambda.par_iter_mut().enumerate().for_each(|(s, l)| {
        let f = problem.slot_face[s] as usize;
        *l = kernels::dual_update(l, &y[s], &a[f], pen.face(f));
    });
}

/// Residual sums of the current state against the `A` of the iteration before (twin of
/// `glsl/admm/residual.comp`), each slot's terms weighted by its face's penalty factor (empty
/// `factor`: 1), i.e. measured in the metric the iteration uses: with `m_f ∝ w_f κ(A_f)`,
/// `m_f ‖A_f‖²` is about the same on every face, so the relative residuals are area-weighted
/// means of each face's *relative* mismatch — what decides whether the recovered map flips a
/// face, whatever its size in the map.
pub fn residuals(
    problem: &AdmmProblem,
    state: &AdmmState,
    a_prev: &[[f64; 4]],
    energy: Energy,
    factor: &[f64],
) -> Residuals {
    // Fixed chunks summed in order: a rayon `reduce` would combine partial sums in an order that
    // depends on work stealing, and the driver's μ decisions compare these sums, so runs would
    // not be reproducible bit for bit.
    let ns = problem.n_slots();
    let slot_sums = (0..ns.div_ceil(SUM_CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut r = [0.0; 3];
            for s in c * SUM_CHUNK..((c + 1) * SUM_CHUNK).min(ns) {
                let f = problem.slot_face[s] as usize;
                let (a, y, ap) = (&state.a[f], &state.y[s], &a_prev[f]);
                let m = factor.get(f).copied().unwrap_or(1.0);
                for i in 0..4 {
                    r[0] += m * (y[i] - a[i]).powi(2);
                    r[1] += m * (a[i] - ap[i]).powi(2);
                    r[2] += m * a[i] * a[i];
                }
            }
            r
        })
        .collect::<Vec<_>>()
        .iter()
        .fold([0.0; 3], |x, y| [x[0] + y[0], x[1] + y[1], x[2] + y[2]]);
    let energy_sum = crate::linalg::ordered_sum(state.a.len(), |f| {
        problem.weight[f] * energy::value(energy, &state.a[f])
    });
    Residuals {
        primal2: slot_sums[0],
        dual2: slot_sums[1],
        anorm2: slot_sums[2],
        energy: energy_sum,
    }
}

impl Executor for CpuExecutor<'_> {
    fn backend(&self) -> &'static str {
        "cpu"
    }

    fn device(&self) -> String {
        format!("host CPU ({} threads, f64)", rayon::current_num_threads())
    }

    fn upload(&mut self, state: &AdmmState, penalty: &[f64]) -> crate::Result<()> {
        self.state = state.clone();
        self.penalty = penalty.to_vec();
        if let Some(acc) = self.accel.as_mut() {
            acc.reset();
        }
        Ok(())
    }

    fn accel_stats(&self) -> Option<(usize, usize)> {
        self.accel.as_ref().map(|a| (a.accepted, a.rejected))
    }

    fn download(&mut self) -> crate::Result<AdmmState> {
        Ok(self.state.clone())
    }

    fn set_accel_active(&mut self, on: bool) {
        if let Some(acc) = self.accel.as_mut() {
            if acc.active != on {
                acc.reset();
                acc.active = on;
            }
        }
    }

    fn iterate(&mut self, n: usize, mu: f64) -> crate::Result<Residuals> {
        let n = n.max(1);
        if !self.accel.as_ref().is_some_and(|a| a.active) {
            // The `A` before the last iteration, for the dual residual.
            let mut a_prev = Vec::new();
            for i in 0..n {
                if i + 1 == n {
                    a_prev.clone_from(&self.state.a);
                }
                let pen = Penalty {
                    mu,
                    factor: &self.penalty,
                };
                iteration(
                    self.problem,
                    &mut self.state,
                    self.energy,
                    self.newton_iters,
                    pen,
                );
            }
            return Ok(residuals(
                self.problem,
                &self.state,
                &a_prev,
                self.energy,
                &self.penalty,
            ));
        }
        let every = self.accel.as_ref().map_or(1, |a| a.every);
        let mut done = 0;
        while done < n {
            let k = every.min(n - done);
            self.accelerated_block(mu, k);
            done += k;
        }
        // The first block after a reset is always accepted, so the fallback is set: rebuild
        // its edge state from the packed plain output (once per batch).
        let acc = self
            .accel
            .as_ref()
            .expect("checked active above, and blocks never remove the accelerator");
        let mut plain = AdmmState {
            a: acc.fallback_a.clone(),
            y: vec![[0.0; 4]; self.state.y.len()],
            lambda: vec![[0.0; 4]; self.state.lambda.len()],
        };
        let pen = Penalty {
            mu,
            factor: &self.penalty,
        };
        unpack_state(self.problem, acc.aa.last_plain(), pen, &mut plain);
        Ok(residuals(
            self.problem,
            &plain,
            &acc.fallback_a_prev,
            self.energy,
            &self.penalty,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::init::{initial_map, normalize_area, InitMethod};
    use crate::mesh;

    /// After one iteration the edge state is consistent (`Y` in the consensus set, `Λ` in its
    /// complement), so the reduced state `w` determines it exactly: unpacking a packed state
    /// gives it back, which is what lets Anderson work on half the data.
    #[test]
    fn reduced_edge_state_round_trips_after_an_iteration() {
        // A curved disk, so that the start map is distorted and the dual state is not zero.
        let (positions, faces) =
            crate::init::test_grid::bumpy(12, |x, y| 0.4 * (3.0 * x).sin() * (2.0 * y).cos());
        let m = mesh::TriMesh { positions, faces };
        let t = mesh::Topology::build(&m, std::path::Path::new("bumpy")).expect("a disk");
        let frames = mesh::frames::compute(&m);
        let p = AdmmProblem::new(&m, &t, &frames);
        let mut uv = initial_map(&m, &t, InitMethod::Lscm).expect("lscm");
        normalize_area(&m, &mut uv, frames.area.iter().sum());
        let mut s = AdmmState::from_uv(&p, &m.faces, &uv);
        let mu = 300.0 / p.n_faces() as f64;
        let factor = penalty_factors(Energy::SymmetricDirichlet, &p.weight, &s.a);
        let pen = Penalty {
            mu,
            factor: &factor,
        };
        for _ in 0..3 {
            iteration(&p, &mut s, Energy::SymmetricDirichlet, 1, pen);
        }
        let mut w = Vec::new();
        pack_state(&p, &s, pen, &mut w);
        let mut back = s.clone();
        back.y.iter_mut().for_each(|y| *y = [9.0; 4]);
        back.lambda.iter_mut().for_each(|l| *l = [-9.0; 4]);
        unpack_state(&p, &w, pen, &mut back);
        let scale = s
            .lambda
            .iter()
            .flatten()
            .fold(1.0f64, |m, x| m.max(x.abs()));
        assert!(
            s.lambda.iter().flatten().any(|x| x.abs() > 1e-9),
            "the dual state must not be trivial"
        );
        for (a, b) in
            s.y.iter()
                .zip(&back.y)
                .chain(s.lambda.iter().zip(&back.lambda))
        {
            for i in 0..4 {
                assert!((a[i] - b[i]).abs() <= 1e-9 * scale, "{a:?} vs {b:?}");
            }
        }
    }
}
