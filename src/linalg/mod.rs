//! Sparse and small dense linear algebra: preconditioned conjugate gradient (and BiCGSTAB)
//! over `sprs` matrices, and closed-form 2x2 / small symmetric helpers used by the solvers and
//! their GPU twins.
#![forbid(unsafe_code)]

pub mod cg;
pub mod direct;
pub mod small;

use rayon::prelude::*;

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
