//! Sparse helpers of the approximation stages: CSR products and one CG entry point with the
//! stages' tolerances.

use sprs::CsMat;

use crate::linalg::SolveError;
use crate::linalg::{
    krylov::{CgOptions, KrylovSolver},
    precond::Preconditioner,
};

/// y = A x for CSR `a`.
pub fn spmv(a: &CsMat<f64>, x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; a.rows()];
    for (r, row) in a.outer_iterator().enumerate() {
        y[r] = row.iter().map(|(c, v)| v * x[c]).sum();
    }
    y
}

/// Solves the SPD system A X = B column by column (warm start from `x`) with IC(0)-CG.
/// The systems are Laplacian-like with a growing penalty; IC(0) keeps the iteration count low
/// as the penalty grows, for a setup cost of one pass over the matrix.
pub fn solve_spd(
    a: &CsMat<f64>,
    b: &[Vec<f64>],
    x: &mut [Vec<f64>],
    tolerance: f64,
) -> Result<(), SolveError> {
    let solver = KrylovSolver::cg(
        a,
        &CgOptions {
            tolerance,
            max_iterations: 20_000,
            preconditioner: Preconditioner::Ic0,
        },
    )?;
    solver.solve_multi(b, x)?;
    Ok(())
}
