//! Sparse and small dense linear algebra: preconditioned conjugate gradient (and BiCGSTAB)
//! over `sprs` matrices, and closed-form 2x2 / small symmetric helpers used by the solvers and
//! their GPU twins.
#![forbid(unsafe_code)]

pub mod cg;
pub mod small;

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
