//! The CPU backend: the exact ADMM iteration of the shaders, in f64, parallel over faces,
//! edges and slots with rayon. It is the reference the Vulkan backend is tested against and
//! the fast path on machines whose only Vulkan device is a software rasterizer.

use rayon::prelude::*;

/// Elements per partial sum in [`residuals`] (fixed, so the summation order is too).
const SUM_CHUNK: usize = 4096;

use super::driver::{Executor, Residuals};
use super::kernels;
use super::{AdmmProblem, AdmmState, NO_SLOT};
use crate::param::energy::{self, Energy};

/// Runs the iteration on the host.
pub struct CpuExecutor<'p> {
    problem: &'p AdmmProblem,
    energy: Energy,
    newton_iters: u32,
    state: AdmmState,
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
        }
    }
}

/// Mean of `Y_t + Λ_t/μ` over the slots of face `f`, and the slot count.
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

/// One full iteration (face, edge, dual steps) on `state`, in place. Returns the previous `A`
/// when `keep_previous` is set, for the dual residual.
pub fn iteration(
    problem: &AdmmProblem,
    state: &mut AdmmState,
    energy: Energy,
    newton_iters: u32,
    mu: f64,
) {
    let new_a: Vec<[f64; 4]> = (0..problem.n_faces())
        .into_par_iter()
        .map(|f| {
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
            mu,
        );
        y[0] = y1;
        y[1] = y2;
    });
    let y = &state.y;
    state.lambda.par_iter_mut().enumerate().for_each(|(s, l)| {
        *l = kernels::dual_update(l, &y[s], &a[problem.slot_face[s] as usize], mu);
    });
}

/// Residual sums of the current state against the `A` of the iteration before (twin of
/// `glsl/admm/residual.comp`).
pub fn residuals(
    problem: &AdmmProblem,
    state: &AdmmState,
    a_prev: &[[f64; 4]],
    energy: Energy,
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
                for i in 0..4 {
                    r[0] += (y[i] - a[i]).powi(2);
                    r[1] += (a[i] - ap[i]).powi(2);
                    r[2] += a[i] * a[i];
                }
            }
            r
        })
        .collect::<Vec<_>>()
        .iter()
        .fold([0.0; 3], |x, y| [x[0] + y[0], x[1] + y[1], x[2] + y[2]]);
    let energy_sum: f64 = state
        .a
        .par_chunks(SUM_CHUNK)
        .zip(problem.weight.par_chunks(SUM_CHUNK))
        .map(|(a, w)| {
            a.iter()
                .zip(w)
                .map(|(a, w)| w * energy::value(energy, a))
                .sum::<f64>()
        })
        .collect::<Vec<_>>()
        .iter()
        .sum();
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

    fn upload(&mut self, state: &AdmmState) -> crate::Result<()> {
        self.state = state.clone();
        Ok(())
    }

    fn download(&mut self) -> crate::Result<AdmmState> {
        Ok(self.state.clone())
    }

    fn iterate(&mut self, n: usize, mu: f64) -> crate::Result<Residuals> {
        // The `A` before the last iteration, for the dual residual (n ≥ 1 so it is always set).
        let n = n.max(1);
        let mut a_prev = Vec::new();
        for k in 0..n {
            if k + 1 == n {
                a_prev.clone_from(&self.state.a);
            }
            iteration(
                self.problem,
                &mut self.state,
                self.energy,
                self.newton_iters,
                mu,
            );
        }
        Ok(residuals(self.problem, &self.state, &a_prev, self.energy))
    }
}
