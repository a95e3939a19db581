//! Krylov solvers over `sprs` CSR matrices: preconditioned conjugate gradient (Hestenes &
//! Stiefel 1952) for symmetric positive definite systems, and BiCGSTAB (van der Vorst 1992)
//! for non-symmetric ones (mean-value Tutte embeddings). They exist because every stage of the
//! pipeline (Tutte and LSCM starts, Poisson recovery, the global Newton steps, harmonic and
//! Newton steps of the volumetric map, the approximation stages) solves large sparse
//! Laplacian-like systems, warm-started, where an iterative method with a good preconditioner
//! ([`super::precond`]) beats a factorisation in memory and, warm-started, in time.
//!
//! Convergence is judged on the relative residual ‖b − Ax‖/‖b‖. When the recurrence residual
//! says "converged", the true residual is recomputed: recurrences drift on long solves, and a
//! starting map that is slightly off can flip thin triangles. When it is over the tolerance,
//! CG restarts from it; when a restart no longer halves it, the solve has reached its
//! attainable accuracy — the gap between recurrence and true residual is rounding, of order
//! ε·‖A‖·max‖x_k‖ (Greenbaum 1997), which no further iteration removes — and it is returned as
//! converged with the residual it reached ([`CgStats::relative_residual`]). A tolerance under
//! that floor is met by no solver; only the iteration cap is a failure.
//!
//! [`KrylovSolver`] splits precompute (copy the matrix, build the preconditioner) from solve,
//! for callers that solve with one matrix many times (Poisson recovery in every ADMM step);
//! [`pcg`] and friends are the one-call versions.
#![forbid(unsafe_code)]

use rayon::prelude::*;
use sprs::CsMat;

use super::precond::{build_precond, Precond, Preconditioner};
use super::sparse::{check_vectors, from_sprs, residual, Csr, CsrOps};
use super::{dot, norm, SolveError};

/// Options of a Krylov solve.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CgOptions {
    /// Stop when ‖b − Ax‖ ≤ tolerance·‖b‖.
    pub tolerance: f64,
    /// Give up (with [`SolveError::CgNoConvergence`]) after this many iterations.
    pub max_iterations: usize,
    pub preconditioner: Preconditioner,
}

impl Default for CgOptions {
    fn default() -> Self {
        CgOptions {
            tolerance: 1e-10,
            max_iterations: 10_000,
            preconditioner: Preconditioner::Jacobi,
        }
    }
}

/// What a successful solve did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CgStats {
    /// Krylov iterations (one SpMV each for CG, two for BiCGSTAB).
    pub iterations: usize,
    /// True relative residual ‖b − Ax‖/‖b‖ at exit (0 when b = 0).
    pub relative_residual: f64,
    /// The preconditioner actually applied (differs from the request after a fallback).
    pub preconditioner: Preconditioner,
    /// Diagonal shift α of an incomplete factorisation (0 when none was needed).
    pub shift: f64,
}

/// Which Krylov method a [`KrylovSolver`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KrylovMethod {
    /// Conjugate gradient: A symmetric positive definite.
    Cg,
    /// BiCGSTAB: any non-singular A.
    BiCgStab,
}

/// A matrix with its preconditioner, ready for repeated solves (precompute once, solve many).
pub struct KrylovSolver {
    a: Csr,
    pre: Precond,
    method: KrylovMethod,
    kind: Preconditioner,
    shift: f64,
    opts: CgOptions,
}

impl KrylovSolver {
    /// Prepares CG for the symmetric positive definite CSR matrix `a`.
    pub fn cg(a: &CsMat<f64>, opts: &CgOptions) -> Result<KrylovSolver, SolveError> {
        KrylovSolver::new(a, opts, KrylovMethod::Cg)
    }

    /// Prepares BiCGSTAB for the square CSR matrix `a`.
    pub fn bicgstab(a: &CsMat<f64>, opts: &CgOptions) -> Result<KrylovSolver, SolveError> {
        KrylovSolver::new(a, opts, KrylovMethod::BiCgStab)
    }

    /// Prepares `method` for `a`: copies the matrix and builds the preconditioner.
    pub fn new(
        a: &CsMat<f64>,
        opts: &CgOptions,
        method: KrylovMethod,
    ) -> Result<KrylovSolver, SolveError> {
        let a = from_sprs(a)?;
        let spd = method == KrylovMethod::Cg;
        let (pre, kind, shift) = build_precond(&a, opts.preconditioner, spd)?;
        Ok(KrylovSolver {
            a,
            pre,
            method,
            kind,
            shift,
            opts: *opts,
        })
    }

    /// Number of rows (= unknowns).
    pub fn rows(&self) -> usize {
        self.a.rows()
    }

    /// The preconditioner actually built (after any fallback) and its diagonal shift.
    pub fn preconditioner(&self) -> (Preconditioner, f64) {
        (self.kind, self.shift)
    }

    /// Solves A·x = b, warm-started from and overwriting `x`.
    pub fn solve(&self, b: &[f64], x: &mut [f64]) -> Result<CgStats, SolveError> {
        check_vectors(&self.a, b, x)?;
        let (iterations, relative_residual) = match self.method {
            KrylovMethod::Cg => pcg_iterate(&self.a, &self.pre, b, x, &self.opts)?,
            KrylovMethod::BiCgStab => bicgstab_iterate(&self.a, &self.pre, b, x, &self.opts)?,
        };
        Ok(CgStats {
            iterations,
            relative_residual,
            preconditioner: self.kind,
            shift: self.shift,
        })
    }

    /// Solves A·x_k = b_k for every column k (e.g. u and v of a map), in parallel.
    pub fn solve_multi(
        &self,
        b: &[Vec<f64>],
        x: &mut [Vec<f64>],
    ) -> Result<Vec<CgStats>, SolveError> {
        if b.len() != x.len() {
            return Err(SolveError::InvalidInput {
                what: format!(
                    "{} right-hand sides but {} solution vectors",
                    b.len(),
                    x.len()
                ),
            });
        }
        b.par_iter()
            .zip(x.par_iter_mut())
            .map(|(bi, xi)| self.solve(bi, xi))
            .collect()
    }
}

/// Solves the symmetric positive definite system A·x = b by preconditioned conjugate
/// gradient, warm-started from and overwriting `x`.
///
/// `a` is n×n CSR and must be symmetric positive definite (checked only through the CG
/// recurrence: a non-positive curvature pᵀAp ≤ 0 is reported as [`SolveError::Failed`]).
/// b = 0 returns x = 0 at once.
pub fn pcg(
    a: &CsMat<f64>,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<CgStats, SolveError> {
    KrylovSolver::cg(a, opts)?.solve(b, x)
}

/// [`pcg`] for several right-hand sides sharing one matrix (the u and v columns of a map):
/// the preconditioner is built once and the columns are solved in parallel.
pub fn pcg_multi(
    a: &CsMat<f64>,
    b: &[Vec<f64>],
    x: &mut [Vec<f64>],
    opts: &CgOptions,
) -> Result<Vec<CgStats>, SolveError> {
    KrylovSolver::cg(a, opts)?.solve_multi(b, x)
}

/// Solves a general (non-symmetric) square system A·x = b by right-preconditioned BiCGSTAB,
/// warm-started from `x`.
///
/// Chosen for the mean-value Tutte system: its rows are convex-combination weights, so the
/// matrix is a non-symmetric, diagonally dominant M-matrix on which BiCGSTAB converges in a
/// few dozen iterations, with two SpMVs per iteration and neither a growing Krylov basis
/// (GMRES) nor a squared condition number (normal equations). Breakdowns (ρ = 0 or ω = 0)
/// restart the iteration from the current iterate.
pub fn bicgstab(
    a: &CsMat<f64>,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<CgStats, SolveError> {
    KrylovSolver::bicgstab(a, opts)?.solve(b, x)
}

/// [`bicgstab`] for several right-hand sides sharing one matrix, solved in parallel.
pub fn bicgstab_multi(
    a: &CsMat<f64>,
    b: &[Vec<f64>],
    x: &mut [Vec<f64>],
    opts: &CgOptions,
) -> Result<Vec<CgStats>, SolveError> {
    KrylovSolver::bicgstab(a, opts)?.solve_multi(b, x)
}

/// The CG iteration proper; returns (iterations, true relative residual).
fn pcg_iterate(
    a: &Csr,
    pre: &Precond,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<(usize, f64), SolveError> {
    let n = a.rows();
    let bnorm = norm(b);
    if bnorm == 0.0 {
        x.fill(0.0);
        return Ok((0, 0.0));
    }
    let tol = opts.tolerance * bnorm;
    let mut r = vec![0.0; n];
    let rnorm0 = residual(a, b, x, &mut r);
    if rnorm0 <= tol {
        return Ok((0, rnorm0 / bnorm));
    }
    let mut z = vec![0.0; n];
    let mut q = vec![0.0; n];
    pre.apply(a, &r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    // "Converged by the recurrence but not by the true residual": restarts so far, and the
    // true residual at the last such point.
    let mut restarts = 0;
    let mut floor = f64::INFINITY;
    for it in 1..=opts.max_iterations {
        a.spmv(&p, &mut q);
        let pq = dot(&p, &q);
        if !pq.is_finite() || !rz.is_finite() {
            return Err(SolveError::NonFinite {
                what: format!("conjugate gradient iterate {it}"),
            });
        }
        if pq <= 0.0 {
            return Err(SolveError::Failed { what: format!("conjugate gradient: non-positive curvature pᵀAp = {pq:e} at iteration {it} (matrix not positive definite)") });
        }
        // α = rᵀz / pᵀAp; x += αp; r −= αAp
        let alpha = rz / pq;
        for i in 0..n {
            x[i] += alpha * p[i];
            r[i] -= alpha * q[i];
        }
        let rnorm = norm(&r);
        if !rnorm.is_finite() {
            return Err(SolveError::NonFinite {
                what: format!("conjugate gradient residual at iteration {it}"),
            });
        }
        if rnorm <= tol {
            let true_norm = residual(a, b, x, &mut r);
            if true_norm <= tol {
                return Ok((it, true_norm / bnorm));
            }
            restarts += 1;
            if restarts > 8 || true_norm > 0.5 * floor {
                // Attainable accuracy reached (module docs): restarting no longer helps.
                return Ok((it, true_norm / bnorm));
            }
            floor = true_norm;
            // Restart from the true residual (the recurrence had drifted).
            pre.apply(a, &r, &mut z);
            p.copy_from_slice(&z);
            rz = dot(&r, &z);
            continue;
        }
        pre.apply(a, &r, &mut z);
        let rz_new = dot(&r, &z);
        // β = r₊ᵀz₊ / rᵀz; p = z + βp
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
    }
    let true_norm = residual(a, b, x, &mut r);
    if true_norm <= tol {
        return Ok((opts.max_iterations, true_norm / bnorm));
    }
    Err(SolveError::CgNoConvergence {
        iterations: opts.max_iterations,
        residual: true_norm / bnorm,
        tolerance: opts.tolerance,
    })
}

/// The right-preconditioned BiCGSTAB iteration; returns (iterations, true relative residual).
fn bicgstab_iterate(
    a: &Csr,
    pre: &Precond,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<(usize, f64), SolveError> {
    let n = a.rows();
    let bnorm = norm(b);
    if bnorm == 0.0 {
        x.fill(0.0);
        return Ok((0, 0.0));
    }
    let tol = opts.tolerance * bnorm;
    let mut r = vec![0.0; n];
    let rnorm0 = residual(a, b, x, &mut r);
    if rnorm0 <= tol {
        return Ok((0, rnorm0 / bnorm));
    }
    let mut r_hat = r.clone();
    let (mut rho, mut alpha, mut omega) = (1.0, 1.0, 1.0);
    let mut v = vec![0.0; n];
    let mut p = vec![0.0; n];
    let mut p_hat = vec![0.0; n];
    let mut s = vec![0.0; n];
    let mut s_hat = vec![0.0; n];
    let mut t = vec![0.0; n];
    let mut restarts = 0;
    let mut it = 0;
    while it < opts.max_iterations {
        it += 1;
        let rho_new = dot(&r_hat, &r);
        if !rho_new.is_finite() {
            return Err(SolveError::NonFinite {
                what: format!("BiCGSTAB iterate {it}"),
            });
        }
        if rho_new.abs() < 1e-300 || omega == 0.0 {
            // Breakdown, or a recurrence that drifted from the true residual: restart with
            // the true residual as shadow residual r̂ = r.
            restarts += 1;
            if restarts > 20 {
                break;
            }
            residual(a, b, x, &mut r);
            r_hat.copy_from_slice(&r);
            (rho, alpha, omega) = (1.0, 1.0, 1.0);
            v.fill(0.0);
            p.fill(0.0);
            continue;
        }
        // β = (ρ₊/ρ)(α/ω); p = r + β(p − ωv)
        let beta = (rho_new / rho) * (alpha / omega);
        rho = rho_new;
        for i in 0..n {
            p[i] = r[i] + beta * (p[i] - omega * v[i]);
        }
        pre.apply(a, &p, &mut p_hat);
        a.spmv(&p_hat, &mut v);
        let rv = dot(&r_hat, &v);
        if rv == 0.0 || !rv.is_finite() {
            omega = 0.0;
            continue;
        }
        // α = ρ / r̂ᵀv; s = r − αv
        alpha = rho / rv;
        for i in 0..n {
            s[i] = r[i] - alpha * v[i];
        }
        if norm(&s) <= tol {
            for i in 0..n {
                x[i] += alpha * p_hat[i];
            }
            let true_norm = residual(a, b, x, &mut r);
            if true_norm <= tol {
                return Ok((it, true_norm / bnorm));
            }
            omega = 0.0;
            continue;
        }
        pre.apply(a, &s, &mut s_hat);
        a.spmv(&s_hat, &mut t);
        let tt = dot(&t, &t);
        // ω = tᵀs / tᵀt; x += αp̂ + ωŝ; r = s − ωt
        omega = if tt > 0.0 { dot(&t, &s) / tt } else { 0.0 };
        for i in 0..n {
            x[i] += alpha * p_hat[i] + omega * s_hat[i];
            r[i] = s[i] - omega * t[i];
        }
        let rnorm = norm(&r);
        if !rnorm.is_finite() {
            return Err(SolveError::NonFinite {
                what: format!("BiCGSTAB residual at iteration {it}"),
            });
        }
        if rnorm <= tol {
            let true_norm = residual(a, b, x, &mut r);
            if true_norm <= tol {
                return Ok((it, true_norm / bnorm));
            }
            omega = 0.0;
        }
    }
    let true_norm = residual(a, b, x, &mut r);
    if true_norm <= tol {
        return Ok((it, true_norm / bnorm));
    }
    Err(SolveError::CgNoConvergence {
        iterations: it,
        residual: true_norm / bnorm,
        tolerance: opts.tolerance,
    })
}
