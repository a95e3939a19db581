//! The sparse solves of the approximation stages: Cholesky with one CG entry point behind it,
//! at the stages' tolerances.

use sprs::CsMat;

use crate::linalg::direct::{Cholesky, CholeskySymbolic};
use crate::linalg::SolveError;
use crate::linalg::{
    krylov::{CgOptions, KrylovSolver},
    precond::Preconditioner,
};

/// Solves SPD systems A X = B of one sparsity pattern in sequence (a penalty that grows, a
/// linearisation redone): by sparse Cholesky, the ordering and symbolic factorisation
/// computed once and one numeric factorisation for every column (the stages' systems are
/// Laplacians of the mesh or of its dual graph, whose factors stay sparse under AMD, while CG
/// on them needs more iterations the larger the penalty or the weaker the anchor), or, if the
/// factorisation fails (not numerically positive definite), by IC(0)-CG warm-started from `x`.
#[derive(Default)]
pub struct SpdSolver {
    symbolic: Option<CholeskySymbolic>,
}

impl SpdSolver {
    pub fn solve(
        &mut self,
        a: &CsMat<f64>,
        b: &[Vec<f64>],
        x: &mut [Vec<f64>],
        tolerance: f64,
    ) -> Result<(), SolveError> {
        let factor = self.factor_each(std::slice::from_ref(a)).pop().flatten();
        solve_factored(factor.as_ref(), a, b, x, tolerance)
    }

    /// The factors of matrices of one pattern known before any is solved (a penalty schedule
    /// fixed in advance), made in parallel, one per thread at a time; `None` where the
    /// factorisation failed. A factor is the same whichever thread makes it.
    pub fn factor_each(&mut self, mats: &[CsMat<f64>]) -> Vec<Option<Cholesky>> {
        let Some(first) = mats.first() else {
            return Vec::new();
        };
        if !self.symbolic.as_ref().is_some_and(|s| s.fits(first)) {
            self.symbolic = CholeskySymbolic::new(first).ok();
        }
        let Some(sym) = self.symbolic.as_ref() else {
            return vec![None; mats.len()];
        };
        use rayon::prelude::*;
        mats.par_iter().map(|a| sym.factor(a).ok()).collect()
    }
}

/// Solves A X = B by `factor` (of `a`), or where there is none or it fails, by IC(0)-CG
/// warm-started from `x`.
pub fn solve_factored(
    factor: Option<&Cholesky>,
    a: &CsMat<f64>,
    b: &[Vec<f64>],
    x: &mut [Vec<f64>],
    tolerance: f64,
) -> Result<(), SolveError> {
    if let Some(chol) = factor {
        let n = a.rows();
        let mut all: Vec<f64> = b.iter().flatten().copied().collect();
        if chol.solve_many_in_place(&mut all, b.len()).is_ok() {
            for (col, sol) in x.iter_mut().zip(all.chunks(n.max(1))) {
                col.copy_from_slice(sol);
            }
            return Ok(());
        }
    }
    solve_cg(a, b, x, tolerance)
}

/// IC(0)-CG for each column, warm-started from `x`.
fn solve_cg(
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
