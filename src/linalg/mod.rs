//! The crate's one numerical core: sparse iterative solvers and small dense linear algebra.
//!
//! - [`sparse`]: the one CSR matrix type of the solvers (converted from `sprs`, which callers
//!   assemble into);
//! - [`krylov`]: CG and BiCGSTAB, one-call and precompute-once/solve-many;
//! - [`precond`]: Jacobi, IC(0), ILU(0) and smoothed-aggregation AMG;
//! - [`small`]: closed-form 2×2 / 3×3 helpers (SVD, eigen-decompositions, PSD projection) used
//!   by the solvers and their GPU twins; [`vec3`]: 3-vector arithmetic on `[f64; 3]`;
//! - [`pattern`]: the block-sparse pattern of a per-simplex Hessian; [`lbfgs`]: L-BFGS for the
//!   barrier-energy untanglers; [`rng`]: the crate's seeded pseudo-random numbers;
//! - here: slice [`dot`] / [`norm`] and the thread-count-independent [`ordered_sum`].
//!
//! - [`direct`]: sparse Cholesky (faer), symbolic analysis once per pattern.
#![forbid(unsafe_code)]

pub mod direct;
pub mod krylov;
pub mod lbfgs;
pub mod pattern;
pub mod precond;
pub mod rng;
pub mod small;
pub mod sparse;
pub mod vec3;

use rayon::prelude::*;

/// Σ a_i·b_i over the common length, summed in order (the solvers' and energies' one slice
/// dot product).
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Euclidean norm √(a·a) of a slice.
#[inline]
pub fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// [`dot`] for long vectors: in parallel, summed by [`ordered_sum`] so its bits do not depend
/// on the thread count (equal to [`dot`] up to [`SUM_CHUNK`] entries).
pub fn par_dot(a: &[f64], b: &[f64]) -> f64 {
    ordered_sum(a.len(), |i| a[i] * b[i])
}

/// Items per chunk of [`ordered_sum`].
pub const SUM_CHUNK: usize = 4096;

/// `Σ_{i<n} f(i)` in parallel, with the same bits whatever the thread count: fixed chunks of
/// [`SUM_CHUNK`] items, each summed in order, then the chunk sums in order. (rayon's own `sum`
/// splits the work by how many threads steal it, and floating-point addition is not
/// associative, so its result depends on the machine — and a solver's path with it.)
pub fn ordered_sum(n: usize, f: impl Fn(usize) -> f64 + Sync) -> f64 {
    (0..n.div_ceil(SUM_CHUNK))
        .into_par_iter()
        .map(|c| {
            (c * SUM_CHUNK..((c + 1) * SUM_CHUNK).min(n))
                .map(&f)
                .sum::<f64>()
        })
        .collect::<Vec<_>>()
        .iter()
        .sum()
}

/// A numerical solve that did not produce a usable answer.
#[derive(Debug, thiserror::Error)]
pub enum SolveError {
    #[error("conjugate gradient did not converge: relative residual {residual:.3e} after {iterations} iterations (tolerance {tolerance:.1e})")]
    CgNoConvergence {
        iterations: usize,
        residual: f64,
        tolerance: f64,
    },
    #[error("{what}: non-finite value")]
    NonFinite { what: String },
    #[error("{what}")]
    Failed { what: String },
    /// The arguments of a solve are inconsistent (lengths, indices out of range, too short a
    /// boundary): a caller bug or unvalidated input, not a numerical failure.
    #[error("invalid input: {what}")]
    InvalidInput { what: String },
}
