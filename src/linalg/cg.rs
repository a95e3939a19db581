//! Krylov solvers over `sprs` CSR matrices: preconditioned conjugate gradient (Hestenes &
//! Stiefel 1952) for symmetric positive definite systems, and BiCGSTAB (van der Vorst 1992)
//! for the non-symmetric ones (mean-value Tutte embeddings).
//!
//! Preconditioners: Jacobi (diagonal) by default; incomplete Cholesky IC(0) for CG and its
//! non-symmetric sibling ILU(0) for BiCGSTAB on request. Incomplete factorisations can break
//! down (non-positive pivot) on matrices that are not M-matrices (cotangent weights with
//! obtuse angles, LSCM); we then retry with a diagonal shift A + α·diag(A) (Manteuffel 1980)
//! and, if that fails too, fall back to Jacobi, so asking for `Ic0` never makes a solve fail.
//!
//! Convergence is judged on the relative residual ‖b − Ax‖/‖b‖. When the recurrence residual
//! says "converged", the true residual is recomputed: recurrences drift on long solves, and an
//! initial map that is a little off can flip thin triangles.
#![forbid(unsafe_code)]

use std::borrow::Cow;

use rayon::prelude::*;
use sprs::CsMat;

use super::SolveError;

/// Matrices with at least this many rows get a rayon-parallel sparse matrix–vector product.
pub const PARALLEL_ROWS: usize = 20_000;

/// Which preconditioner a Krylov solve uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Preconditioner {
    /// No preconditioning (useful only for tests and comparisons).
    None,
    /// M = diag(A).
    #[default]
    Jacobi,
    /// Incomplete factorisation with the sparsity of A: IC(0) (M = LLᵀ) in [`pcg`], ILU(0)
    /// (M = LU) in [`bicgstab`]. Falls back to a shifted factorisation, then to Jacobi, on
    /// breakdown; [`CgStats::preconditioner`] reports what was used.
    Ic0,
}

/// Options of a Krylov solve.
#[derive(Clone, Copy, Debug, PartialEq)]
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

/// A square CSR matrix with a proper (zero-based) row pointer.
struct Csr<'a> {
    n: usize,
    indptr: Cow<'a, [usize]>,
    indices: &'a [usize],
    data: &'a [f64],
}

impl<'a> Csr<'a> {
    fn new(a: &'a CsMat<f64>) -> Result<Csr<'a>, SolveError> {
        if !a.is_csr() {
            return Err(SolveError::InvalidInput {
                what: "Krylov solvers take a CSR matrix (got CSC)".into(),
            });
        }
        if a.rows() != a.cols() {
            return Err(SolveError::InvalidInput {
                what: format!("matrix is {}x{}, not square", a.rows(), a.cols()),
            });
        }
        let indptr = Cow::Owned(a.indptr().to_proper().into_owned());
        Ok(Csr {
            n: a.rows(),
            indptr,
            indices: a.indices(),
            data: a.data(),
        })
    }

    #[inline]
    fn row(&self, i: usize) -> (&[usize], &[f64]) {
        let (s, e) = (self.indptr[i], self.indptr[i + 1]);
        (&self.indices[s..e], &self.data[s..e])
    }

    #[inline]
    fn row_dot(&self, i: usize, x: &[f64]) -> f64 {
        let (cols, vals) = self.row(i);
        cols.iter().zip(vals).map(|(&j, &v)| v * x[j]).sum()
    }

    /// y = A·x, parallel over rows when the matrix is large.
    fn spmv(&self, x: &[f64], y: &mut [f64]) {
        if self.n >= PARALLEL_ROWS {
            y.par_iter_mut()
                .enumerate()
                .with_min_len(4096)
                .for_each(|(i, yi)| *yi = self.row_dot(i, x));
        } else {
            for (i, yi) in y.iter_mut().enumerate() {
                *yi = self.row_dot(i, x);
            }
        }
    }

    fn diagonal(&self) -> Vec<f64> {
        (0..self.n)
            .map(|i| {
                let (cols, vals) = self.row(i);
                cols.binary_search(&i).map_or(0.0, |p| vals[p])
            })
            .collect()
    }
}

#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[inline]
fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// r = b − A·x, returns ‖r‖.
fn residual(a: &Csr, b: &[f64], x: &[f64], r: &mut [f64]) -> f64 {
    a.spmv(x, r);
    for (ri, bi) in r.iter_mut().zip(b) {
        *ri = bi - *ri;
    }
    norm(r)
}

/// Incomplete Cholesky IC(0): lower-triangular L with the pattern of tril(A), A ≈ LLᵀ.
struct Ic0 {
    indptr: Vec<usize>,
    indices: Vec<usize>,
    /// Row i holds its off-diagonal entries (ascending columns) followed by the diagonal.
    values: Vec<f64>,
}

impl Ic0 {
    /// Factorises A + shift·diag(A); `None` on a non-positive or non-finite pivot.
    fn factor(a: &Csr, shift: f64) -> Option<Ic0> {
        let n = a.n;
        let mut indptr = Vec::with_capacity(n + 1);
        let mut indices = Vec::new();
        let mut values = Vec::new();
        indptr.push(0);
        for i in 0..n {
            let start = indices.len();
            let (cols, vals) = a.row(i);
            let mut diag = None;
            for (&j, &v) in cols.iter().zip(vals) {
                if j < i {
                    indices.push(j);
                    values.push(v);
                } else if j == i {
                    diag = Some(v * (1.0 + shift));
                }
            }
            let diag = diag?;
            // l_ik = (a_ik − Σ_{m<k} l_im·l_km) / l_kk for the pattern entries k < i, in order.
            for p in start..indices.len() {
                let k = indices[p];
                let (ks, ke) = (indptr[k], indptr[k + 1] - 1); // row k without its diagonal
                let mut s = values[p];
                let (mut pi, mut pk) = (start, ks);
                while pi < p && pk < ke {
                    let (ci, ck) = (indices[pi], indices[pk]);
                    if ci == ck {
                        s -= values[pi] * values[pk];
                        pi += 1;
                        pk += 1;
                    } else if ci < ck {
                        pi += 1;
                    } else {
                        pk += 1;
                    }
                }
                values[p] = s / values[indptr[k + 1] - 1];
            }
            // l_ii = √(a_ii − Σ_k l_ik²)
            let d = diag - values[start..].iter().map(|v| v * v).sum::<f64>();
            let positive = d.is_finite() && d > 1e-14 * diag.abs();
            if !positive {
                return None;
            }
            indices.push(i);
            values.push(d.sqrt());
            indptr.push(indices.len());
        }
        Some(Ic0 {
            indptr,
            indices,
            values,
        })
    }

    /// z = (LLᵀ)⁻¹ r: forward substitution with L, then backward with Lᵀ (column-oriented).
    fn apply(&self, r: &[f64], z: &mut [f64]) {
        let n = r.len();
        for i in 0..n {
            let (s, e) = (self.indptr[i], self.indptr[i + 1] - 1);
            let mut acc = r[i];
            for p in s..e {
                acc -= self.values[p] * z[self.indices[p]];
            }
            z[i] = acc / self.values[e];
        }
        for i in (0..n).rev() {
            let (s, e) = (self.indptr[i], self.indptr[i + 1] - 1);
            let zi = z[i] / self.values[e];
            z[i] = zi;
            for p in s..e {
                z[self.indices[p]] -= self.values[p] * zi;
            }
        }
    }
}

/// Incomplete LU ILU(0) with the pattern of A (unit lower L, upper U stored together).
struct Ilu0<'a> {
    a: &'a Csr<'a>,
    values: Vec<f64>,
    /// Position of the diagonal entry in each row.
    diag: Vec<usize>,
}

impl<'a> Ilu0<'a> {
    /// Factorises A + shift·diag(A) (IKJ variant); `None` on a zero or non-finite pivot.
    fn factor(a: &'a Csr<'a>, shift: f64) -> Option<Ilu0<'a>> {
        let n = a.n;
        let mut values = a.data.to_vec();
        let mut diag = vec![usize::MAX; n];
        for i in 0..n {
            let (s, e) = (a.indptr[i], a.indptr[i + 1]);
            let p = a.indices[s..e].binary_search(&i).ok()? + s;
            diag[i] = p;
            values[p] *= 1.0 + shift;
        }
        let mut pos = vec![usize::MAX; n];
        for i in 0..n {
            let (s, e) = (a.indptr[i], a.indptr[i + 1]);
            for p in s..e {
                pos[a.indices[p]] = p;
            }
            for p in s..diag[i] {
                let k = a.indices[p];
                // l_ik = a_ik / u_kk; then row_i −= l_ik · row_k (U part, pattern-restricted).
                let lik = values[p] / values[diag[k]];
                values[p] = lik;
                for q in diag[k] + 1..a.indptr[k + 1] {
                    let pj = pos[a.indices[q]];
                    if pj != usize::MAX {
                        values[pj] -= lik * values[q];
                    }
                }
            }
            let d = values[diag[i]];
            if !d.is_finite() || d.abs() <= 1e-14 * a.data[diag[i]].abs() {
                return None;
            }
            for p in s..e {
                pos[a.indices[p]] = usize::MAX;
            }
        }
        Some(Ilu0 { a, values, diag })
    }

    /// z = (LU)⁻¹ r.
    fn apply(&self, r: &[f64], z: &mut [f64]) {
        let (ip, ix) = (&self.a.indptr, self.a.indices);
        let n = r.len();
        for i in 0..n {
            let mut acc = r[i];
            for p in ip[i]..self.diag[i] {
                acc -= self.values[p] * z[ix[p]];
            }
            z[i] = acc;
        }
        for i in (0..n).rev() {
            let mut acc = z[i];
            for p in self.diag[i] + 1..ip[i + 1] {
                acc -= self.values[p] * z[ix[p]];
            }
            z[i] = acc / self.values[self.diag[i]];
        }
    }
}

enum Precond<'a> {
    Identity,
    Jacobi(Vec<f64>),
    Ic0(Ic0),
    Ilu0(Ilu0<'a>),
}

impl Precond<'_> {
    fn apply(&self, r: &[f64], z: &mut [f64]) {
        match self {
            Precond::Identity => z.copy_from_slice(r),
            Precond::Jacobi(inv) => {
                for ((zi, ri), di) in z.iter_mut().zip(r).zip(inv) {
                    *zi = ri * di;
                }
            }
            Precond::Ic0(f) => f.apply(r, z),
            Precond::Ilu0(f) => f.apply(r, z),
        }
    }
}

/// Diagonal shifts tried, in order, when an incomplete factorisation breaks down.
const SHIFTS: [f64; 4] = [0.0, 1e-3, 1e-2, 1e-1];

/// Builds the requested preconditioner (`spd`: IC(0), else ILU(0)); returns it with the kind
/// and shift actually used.
fn build_precond<'a>(
    a: &'a Csr<'a>,
    kind: Preconditioner,
    spd: bool,
) -> Result<(Precond<'a>, Preconditioner, f64), SolveError> {
    if kind == Preconditioner::None {
        return Ok((Precond::Identity, Preconditioner::None, 0.0));
    }
    if kind == Preconditioner::Ic0 {
        for shift in SHIFTS {
            let built = if spd {
                Ic0::factor(a, shift).map(Precond::Ic0)
            } else {
                Ilu0::factor(a, shift).map(Precond::Ilu0)
            };
            if let Some(p) = built {
                return Ok((p, Preconditioner::Ic0, shift));
            }
        }
    }
    let diag = a.diagonal();
    let mut inv = Vec::with_capacity(diag.len());
    for (i, &d) in diag.iter().enumerate() {
        if !d.is_finite() {
            return Err(SolveError::NonFinite {
                what: format!("matrix diagonal at row {i}"),
            });
        }
        if spd && d < 0.0 {
            return Err(SolveError::Failed {
                what: format!("matrix is not positive definite: diagonal entry {d:e} at row {i}"),
            });
        }
        // A zero diagonal gets no scaling (an SPD matrix has none; BiCGSTAB copes).
        inv.push(if d == 0.0 { 1.0 } else { 1.0 / d });
    }
    Ok((Precond::Jacobi(inv), Preconditioner::Jacobi, 0.0))
}

fn check_inputs(a: &Csr, b: &[f64], x: &[f64]) -> Result<(), SolveError> {
    if b.len() != a.n || x.len() != a.n {
        return Err(SolveError::InvalidInput {
            what: format!(
                "matrix has {} rows but b has {} and x has {} entries",
                a.n,
                b.len(),
                x.len()
            ),
        });
    }
    if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite {
            what: format!("matrix entry {i}"),
        });
    }
    if let Some(i) = b.iter().position(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite {
            what: format!("right-hand side at row {i}"),
        });
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite {
            what: format!("initial guess at row {i}"),
        });
    }
    Ok(())
}

/// Solves the symmetric positive definite system A·x = b by preconditioned conjugate
/// gradient, starting from (warm start) and overwriting `x`.
///
/// `a` is n×n CSR and must be symmetric positive definite (only checked through the CG
/// recurrences: a non-positive curvature pᵀAp ≤ 0 is reported as [`SolveError::Failed`]).
/// b = 0 returns x = 0 at once.
pub fn pcg(
    a: &CsMat<f64>,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<CgStats, SolveError> {
    let m = Csr::new(a)?;
    check_inputs(&m, b, x)?;
    let (pre, kind, shift) = build_precond(&m, opts.preconditioner, true)?;
    pcg_with(&m, &pre, b, x, opts).map(|(iterations, relative_residual)| CgStats {
        iterations,
        relative_residual,
        preconditioner: kind,
        shift,
    })
}

/// [`pcg`] for several right-hand sides sharing one matrix (e.g. the u and v columns of a
/// map): the preconditioner is built once and the columns are solved in parallel.
pub fn pcg_multi(
    a: &CsMat<f64>,
    b: &[Vec<f64>],
    x: &mut [Vec<f64>],
    opts: &CgOptions,
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
    let m = Csr::new(a)?;
    for (bi, xi) in b.iter().zip(x.iter()) {
        check_inputs(&m, bi, xi)?;
    }
    let (pre, kind, shift) = build_precond(&m, opts.preconditioner, true)?;
    b.par_iter()
        .zip(x.par_iter_mut())
        .map(|(bi, xi)| {
            pcg_with(&m, &pre, bi, xi, opts).map(|(iterations, relative_residual)| CgStats {
                iterations,
                relative_residual,
                preconditioner: kind,
                shift,
            })
        })
        .collect()
}

/// The CG iteration proper; returns (iterations, true relative residual).
fn pcg_with(
    a: &Csr,
    pre: &Precond,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<(usize, f64), SolveError> {
    let n = a.n;
    let bnorm = norm(b);
    if bnorm == 0.0 {
        x.fill(0.0);
        return Ok((0, 0.0));
    }
    let tol = opts.tolerance * bnorm;
    let mut r = vec![0.0; n];
    let mut rnorm = residual(a, b, x, &mut r);
    if rnorm <= tol {
        return Ok((0, rnorm / bnorm));
    }
    let mut z = vec![0.0; n];
    let mut q = vec![0.0; n];
    pre.apply(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    // Consecutive "converged by recurrence, not by true residual" restarts allowed.
    let mut restarts = 0;
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
        rnorm = norm(&r);
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
            if restarts > 8 {
                return Err(SolveError::CgNoConvergence {
                    iterations: it,
                    residual: true_norm / bnorm,
                    tolerance: opts.tolerance,
                });
            }
            // Restart from the true residual (the recurrence had drifted).
            pre.apply(&r, &mut z);
            p.copy_from_slice(&z);
            rz = dot(&r, &z);
            continue;
        }
        pre.apply(&r, &mut z);
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

/// Solves a general (non-symmetric) square system A·x = b by right-preconditioned BiCGSTAB,
/// warm-started from `x`.
///
/// Chosen for the mean-value Tutte system: its rows are convex-combination weights, so the
/// matrix is a non-symmetric, diagonally dominant M-matrix on which BiCGSTAB with ILU(0)
/// converges in a few dozen iterations, at the cost of two SpMVs per iteration and no
/// growing Krylov basis (GMRES) or squared condition number (normal equations).
/// `Preconditioner::Ic0` selects ILU(0) here. Breakdowns (ρ = 0 or ω = 0) restart the
/// iteration from the current iterate.
pub fn bicgstab(
    a: &CsMat<f64>,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<CgStats, SolveError> {
    let m = Csr::new(a)?;
    check_inputs(&m, b, x)?;
    let (pre, kind, shift) = build_precond(&m, opts.preconditioner, false)?;
    bicgstab_with(&m, &pre, b, x, opts).map(|(iterations, relative_residual)| CgStats {
        iterations,
        relative_residual,
        preconditioner: kind,
        shift,
    })
}

/// [`bicgstab`] for several right-hand sides sharing one matrix, solved in parallel.
pub fn bicgstab_multi(
    a: &CsMat<f64>,
    b: &[Vec<f64>],
    x: &mut [Vec<f64>],
    opts: &CgOptions,
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
    let m = Csr::new(a)?;
    for (bi, xi) in b.iter().zip(x.iter()) {
        check_inputs(&m, bi, xi)?;
    }
    let (pre, kind, shift) = build_precond(&m, opts.preconditioner, false)?;
    b.par_iter()
        .zip(x.par_iter_mut())
        .map(|(bi, xi)| {
            bicgstab_with(&m, &pre, bi, xi, opts).map(|(iterations, relative_residual)| CgStats {
                iterations,
                relative_residual,
                preconditioner: kind,
                shift,
            })
        })
        .collect()
}

fn bicgstab_with(
    a: &Csr,
    pre: &Precond,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<(usize, f64), SolveError> {
    let n = a.n;
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
            // Breakdown: restart with the shadow residual r̂ = r.
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
        pre.apply(&p, &mut p_hat);
        a.spmv(&p_hat, &mut v);
        let rv = dot(&r_hat, &v);
        if rv == 0.0 || !rv.is_finite() {
            rho = 0.0;
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
            omega = 0.0; // forces a restart from the true residual
            continue;
        }
        pre.apply(&s, &mut s_hat);
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
