//! Preconditioners of the Krylov solvers ([`super::krylov`]): Jacobi by default; incomplete
//! Cholesky IC(0) for CG and ILU(0) for BiCGSTAB (Saad, *Iterative Methods for Sparse Linear
//! Systems*, 2003, §10.3); smoothed-aggregation algebraic multigrid (Vaněk, Mandel & Brezina
//! 1996), whose iteration count hardly grows with the mesh where IC(0)'s grows like √n
//! (uniform Tutte on 125k vertices: 22 iterations against 529). They exist because plain CG
//! on mesh Laplacians needs O(√n)–O(n) iterations. Incomplete factorisations can break down
//! (non-positive pivot) on matrices that are not M-matrices (cotangent weights of obtuse
//! triangles, LSCM): we retry with a diagonal shift A + α·diag(A) (Manteuffel 1980), then fall
//! back to Jacobi, so asking for a stronger preconditioner never makes a solve fail;
//! [`super::krylov::CgStats::preconditioner`] says what was used.
#![forbid(unsafe_code)]

mod amg;
mod ic0;
mod ilu0;

use self::amg::Amg;
use self::ic0::Ic0;
use self::ilu0::Ilu0;
use super::sparse::{Csr, CsrOps};
use super::SolveError;

/// Which preconditioner a Krylov solve uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Preconditioner {
    /// No preconditioning (for tests and comparisons).
    None,
    /// M = diag(A).
    #[default]
    Jacobi,
    /// Incomplete factorisation with the sparsity of A: IC(0) (M = LLᵀ) for CG, ILU(0)
    /// (M = LU) for BiCGSTAB. Shifted retry, then Jacobi, on breakdown.
    Ic0,
    /// One smoothed-aggregation AMG V(1,1)-cycle (symmetric Gauss–Seidel smoothing). The
    /// `block_size` unknowns of a mesh vertex (consecutive rows) are aggregated together and
    /// keep separate coarse unknowns: 1 for a scalar Laplacian, 2 for u, v interleaved.
    /// Falls back to IC(0)/ILU(0), then Jacobi, if no hierarchy can be built.
    Amg { block_size: usize },
}

/// A built preconditioner.
pub(crate) enum Precond {
    Identity,
    Jacobi(Vec<f64>),
    Ic0(Ic0),
    Ilu0(Ilu0),
    Amg(Amg),
}

impl Precond {
    /// z = M⁻¹ r (`a` is the matrix the preconditioner was built for).
    pub(crate) fn apply(&self, a: &Csr, r: &[f64], z: &mut [f64]) {
        match self {
            Precond::Identity => z.copy_from_slice(r),
            Precond::Jacobi(inv) => {
                for ((zi, ri), di) in z.iter_mut().zip(r).zip(inv) {
                    *zi = ri * di;
                }
            }
            Precond::Ic0(f) => f.apply(r, z),
            Precond::Ilu0(f) => f.apply(a, r, z),
            Precond::Amg(m) => m.apply(a, r, z),
        }
    }
}

/// Diagonal shifts tried, in order, when an incomplete factorisation breaks down.
pub(crate) const SHIFTS: [f64; 4] = [0.0, 1e-3, 1e-2, 1e-1];

/// Builds the requested preconditioner (`spd`: symmetric variants); returns it with the kind
/// and shift actually used.
pub(crate) fn build_precond(
    a: &Csr,
    kind: Preconditioner,
    spd: bool,
) -> Result<(Precond, Preconditioner, f64), SolveError> {
    if kind == Preconditioner::None {
        return Ok((Precond::Identity, Preconditioner::None, 0.0));
    }
    if let Preconditioner::Amg { block_size } = kind {
        if let Some(amg) = Amg::build(a, block_size) {
            return Ok((Precond::Amg(amg), kind, 0.0));
        }
    }
    if matches!(kind, Preconditioner::Ic0 | Preconditioner::Amg { .. }) {
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
    let diag = a.diagonal_values();
    let mut inv = Vec::with_capacity(diag.len());
    for (i, &d) in diag.iter().enumerate() {
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
