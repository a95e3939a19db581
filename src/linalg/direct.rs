//! Sparse Cholesky (LLᵀ) of symmetric positive definite `sprs` matrices, through `faer`.
//!
//! Why a direct solver next to the preconditioned CG of [`super::krylov`]: the systems of the
//! surface solvers are 2D-mesh Laplacians and Hessians (planar graphs), whose Cholesky factor
//! stays sparse under a fill-reducing ordering (AMD here; O(n log n) entries under nested
//! dissection), and the systems come in families that share one sparsity pattern: one
//! Laplacian for every least-squares recovery of an ADMM run, one pattern for every proxy and
//! Newton system of the global solver, two UV columns per Tutte map. The ordering and the symbolic factorisation ([`CholeskySymbolic`])
//! are computed once per pattern; each matrix then costs one numeric factorisation
//! ([`CholeskySymbolic::factor`]) and each right-hand side two triangular solves
//! ([`Cholesky::solve`]), with an exact answer instead of an iteration count that grows with
//! the mesh and its conditioning. BENCHMARKS.md (issue 26)
//! has the measurements that decided which solver each caller uses.
//!
//! A matrix that is not positive definite (an indefinite exact Hessian, a singular system)
//! fails the numeric factorisation with [`DirectError::NotPositiveDefinite`]; the callers
//! treat it as CG treats negative curvature (fall back or report).
//!
//! faer is built without its `rayon` feature: the factorisation runs on one thread, so its
//! result, like the rest of the CPU path, does not depend on the thread count.
#![forbid(unsafe_code)]

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::linalg::LltError;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{MatMut, Side};
use std::borrow::Cow;

use sprs::CsMat;

use super::SolveError;

/// Why a direct solve failed.
#[derive(Debug, thiserror::Error)]
pub enum DirectError {
    /// A pivot of the factorisation was ≤ 0 or not finite: the matrix is not (numerically)
    /// positive definite.
    #[error("sparse Cholesky: the matrix is not positive definite (pivot {pivot} of the permuted matrix)")]
    NotPositiveDefinite { pivot: usize },
    /// The matrix is not square, not in compressed-row form, or its sparsity pattern differs
    /// from the one the symbolic factorisation was computed for.
    #[error("sparse Cholesky: {what}")]
    Pattern { what: String },
    /// A right-hand side has the wrong length or non-finite entries.
    #[error("sparse Cholesky: {what}")]
    InvalidInput { what: String },
    /// faer could not allocate the factor or its workspace.
    #[error("sparse Cholesky: {what}")]
    Faer { what: String },
}

impl From<DirectError> for SolveError {
    fn from(e: DirectError) -> SolveError {
        match e {
            // Like CG's negative curvature: a numerical failure the caller may recover from.
            DirectError::NotPositiveDefinite { .. } | DirectError::Faer { .. } => {
                SolveError::Failed {
                    what: e.to_string(),
                }
            }
            DirectError::Pattern { .. } | DirectError::InvalidInput { .. } => {
                SolveError::InvalidInput {
                    what: e.to_string(),
                }
            }
        }
    }
}

/// The AMD ordering and symbolic factorisation of one sparsity pattern, reusable for every
/// matrix with that pattern (cheap to clone: the symbolic part is reference-counted).
#[derive(Clone, Debug)]
pub struct CholeskySymbolic {
    n: usize,
    indptr: Vec<usize>,
    indices: Vec<usize>,
    symbolic: SymbolicLlt<usize>,
}

/// The square CSR structure of `a`, checked (the row pointer rebased to start at 0).
type CsrParts<'a> = (Cow<'a, [usize]>, &'a [usize], &'a [f64]);

fn csr_parts(a: &CsMat<f64>) -> Result<CsrParts<'_>, DirectError> {
    if !a.is_csr() {
        return Err(DirectError::Pattern {
            what: "the matrix must be in compressed-row form".into(),
        });
    }
    if a.rows() != a.cols() {
        return Err(DirectError::Pattern {
            what: format!("the matrix is {}x{}, not square", a.rows(), a.cols()),
        });
    }
    Ok((a.proper_indptr(), a.indices(), a.data()))
}

impl CholeskySymbolic {
    /// Orders and symbolically factors the pattern of the symmetric matrix `a` (CSR, both
    /// triangles stored; only the upper triangle of each row is read, so a matrix symmetric in
    /// pattern but not quite in value is factored as its upper triangle says).
    pub fn new(a: &CsMat<f64>) -> Result<CholeskySymbolic, DirectError> {
        let (indptr, indices, _) = csr_parts(a)?;
        let n = a.rows();
        // The CSR arrays of A are the CSC arrays of Aᵀ = A; the rows' upper triangle is the
        // columns' lower one.
        let pattern = SymbolicSparseColMatRef::new_checked(n, n, &indptr, None, indices);
        let symbolic =
            SymbolicLlt::try_new(pattern, Side::Lower).map_err(|e| DirectError::Faer {
                what: format!("symbolic factorisation: {e:?}"),
            })?;
        Ok(CholeskySymbolic {
            n,
            indptr: indptr.to_vec(),
            indices: indices.to_vec(),
            symbolic,
        })
    }

    /// Rows (= columns) of the matrices this pattern factors.
    pub fn rows(&self) -> usize {
        self.n
    }

    /// Numerically factors `a`, which must have exactly the pattern this was built from.
    pub fn factor(&self, a: &CsMat<f64>) -> Result<Cholesky, DirectError> {
        let (indptr, indices, data) = csr_parts(a)?;
        if a.rows() != self.n || *indptr != *self.indptr || indices != self.indices {
            return Err(DirectError::Pattern {
                what: "the matrix's sparsity pattern differs from the symbolic factorisation's"
                    .into(),
            });
        }
        let pattern = SymbolicSparseColMatRef::new_checked(self.n, self.n, &indptr, None, indices);
        let mat = SparseColMatRef::new(pattern, data);
        let llt = Llt::try_new_with_symbolic(self.symbolic.clone(), mat, Side::Lower).map_err(
            |e| match e {
                LltError::Numeric(
                    faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index },
                ) => DirectError::NotPositiveDefinite { pivot: index },
                LltError::Generic(g) => DirectError::Faer {
                    what: format!("numeric factorisation: {g:?}"),
                },
            },
        )?;
        Ok(Cholesky { n: self.n, llt })
    }
}

/// The numeric factor of one matrix.
#[derive(Clone, Debug)]
pub struct Cholesky {
    n: usize,
    llt: Llt<usize, f64>,
}

impl Cholesky {
    /// Orders, symbolically and numerically factors `a` (a pattern used once).
    pub fn new(a: &CsMat<f64>) -> Result<Cholesky, DirectError> {
        CholeskySymbolic::new(a)?.factor(a)
    }

    /// Rows (= columns) of the factored matrix.
    pub fn rows(&self) -> usize {
        self.n
    }

    /// Solves `A x = b` in place (`x` holds `b` on entry).
    pub fn solve_in_place(&self, x: &mut [f64]) -> Result<(), DirectError> {
        self.solve_many_in_place(x, 1)
    }

    /// Solves `A x = b` for `x`.
    pub fn solve(&self, b: &[f64], x: &mut [f64]) -> Result<(), DirectError> {
        if x.len() != b.len() {
            return Err(DirectError::InvalidInput {
                what: format!(
                    "{} unknowns for {} right-hand-side entries",
                    x.len(),
                    b.len()
                ),
            });
        }
        x.copy_from_slice(b);
        self.solve_in_place(x)
    }

    /// Solves for `k` right-hand sides at once: `x` holds them column by column (column j at
    /// `x[j·n..(j+1)·n]`) and is overwritten with the solutions.
    pub fn solve_many_in_place(&self, x: &mut [f64], k: usize) -> Result<(), DirectError> {
        if x.len() != k * self.n {
            return Err(DirectError::InvalidInput {
                what: format!(
                    "{} entries for {k} right-hand sides of length {}",
                    x.len(),
                    self.n
                ),
            });
        }
        if x.iter().any(|v| !v.is_finite()) {
            return Err(DirectError::InvalidInput {
                what: "non-finite right-hand side".into(),
            });
        }
        if self.n == 0 || k == 0 {
            return Ok(());
        }
        self.llt
            .solve_in_place(MatMut::from_column_major_slice_mut(x, self.n, k));
        if x.iter().any(|v| !v.is_finite()) {
            return Err(DirectError::NotPositiveDefinite { pivot: 0 });
        }
        Ok(())
    }
}

/// Which linear solver a caller uses for its SPD systems. The sparse Cholesky is the default
/// wherever it was measured faster end to end (BENCHMARKS.md, issue 26); preconditioned CG
/// stays selectable for comparisons.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LinearSolver {
    /// Krylov ([`super::krylov`]) with the caller's preconditioner and tolerance.
    Pcg,
    /// [`Cholesky`]: exact up to rounding, symbolic analysis reused per pattern.
    #[default]
    Cholesky,
}

#[cfg(test)]
mod tests {
    use super::*;
    use sprs::TriMat;

    fn csr(n: usize, entries: &[(usize, usize, f64)]) -> CsMat<f64> {
        let mut t = TriMat::new((n, n));
        for &(i, j, v) in entries {
            t.add_triplet(i, j, v);
        }
        t.to_csr()
    }

    fn residual(a: &CsMat<f64>, x: &[f64], b: &[f64]) -> f64 {
        let mut r: f64 = 0.0;
        for (i, row) in a.outer_iterator().enumerate() {
            let ax: f64 = row.iter().map(|(j, &v)| v * x[j]).sum();
            r = r.max((ax - b[i]).abs());
        }
        r
    }

    #[test]
    fn known_answer_spd() {
        // A = [[4, 1, 0], [1, 3, 1], [0, 1, 2]], x = [1, −2, 3] ⇒ b = A x = [2, −2, 4].
        let a = csr(
            3,
            &[
                (0, 0, 4.0),
                (0, 1, 1.0),
                (1, 0, 1.0),
                (1, 1, 3.0),
                (1, 2, 1.0),
                (2, 1, 1.0),
                (2, 2, 2.0),
            ],
        );
        let chol = Cholesky::new(&a).unwrap();
        let mut x = [0.0; 3];
        chol.solve(&[2.0, -2.0, 4.0], &mut x).unwrap();
        for (got, want) in x.iter().zip([1.0, -2.0, 3.0]) {
            assert!((got - want).abs() < 1e-14, "{x:?}");
        }
    }

    /// Path-graph Laplacian on n + 2 vertices with both ends pinned (at 0 and 1): the
    /// interior is the linear interpolation. Two right-hand sides, and a refactorisation of a
    /// scaled matrix through the same symbolic analysis.
    #[test]
    fn pinned_laplacian_two_columns_and_refactor() {
        let n = 50;
        let mut e = Vec::new();
        for i in 0..n {
            e.push((i, i, 2.0));
            if i + 1 < n {
                e.push((i, i + 1, -1.0));
                e.push((i + 1, i, -1.0));
            }
        }
        let a = csr(n, &e);
        let sym = CholeskySymbolic::new(&a).unwrap();
        assert_eq!(sym.rows(), n);
        // Column 0: ends pinned at u = 0 and u = 1 ⇒ b has 1 in the last row.
        // Column 1: ends pinned at v = 2 and v = 2 ⇒ constant 2.
        let mut b = vec![0.0; 2 * n];
        b[n - 1] = 1.0;
        b[n] = 2.0;
        b[2 * n - 1] = 2.0;
        let chol = sym.factor(&a).unwrap();
        let mut x = b.clone();
        chol.solve_many_in_place(&mut x, 2).unwrap();
        for i in 0..n {
            assert!((x[i] - (i + 1) as f64 / (n + 1) as f64).abs() < 1e-12);
            assert!((x[n + i] - 2.0).abs() < 1e-12);
        }
        assert!(residual(&a, &x[..n], &b[..n]) < 1e-12);
        // Same pattern, values doubled: the solution halves.
        let a2 = a.map(|v| 2.0 * v);
        let chol2 = sym.factor(&a2).unwrap();
        let mut x2 = vec![0.0; n];
        chol2.solve(&b[..n], &mut x2).unwrap();
        for i in 0..n {
            assert!((x2[i] - 0.5 * x[i]).abs() < 1e-12);
        }
    }

    #[test]
    fn indefinite_and_singular_are_typed_errors() {
        // Eigenvalues 3 and −1.
        let a = csr(2, &[(0, 0, 1.0), (0, 1, 2.0), (1, 0, 2.0), (1, 1, 1.0)]);
        assert!(matches!(
            Cholesky::new(&a),
            Err(DirectError::NotPositiveDefinite { .. })
        ));
        // Unpinned path Laplacian: singular (constants).
        let l = csr(
            3,
            &[
                (0, 0, 1.0),
                (0, 1, -1.0),
                (1, 0, -1.0),
                (1, 1, 2.0),
                (1, 2, -1.0),
                (2, 1, -1.0),
                (2, 2, 1.0),
            ],
        );
        let err = Cholesky::new(&l).unwrap_err();
        assert!(
            matches!(err, DirectError::NotPositiveDefinite { .. }),
            "{err}"
        );
        assert!(matches!(SolveError::from(err), SolveError::Failed { .. }));
    }

    #[test]
    fn pattern_and_length_mismatches_are_rejected() {
        let a = csr(2, &[(0, 0, 2.0), (1, 1, 2.0)]);
        let b = csr(2, &[(0, 0, 2.0), (0, 1, 1.0), (1, 0, 1.0), (1, 1, 2.0)]);
        let sym = CholeskySymbolic::new(&a).unwrap();
        assert!(matches!(sym.factor(&b), Err(DirectError::Pattern { .. })));
        let chol = sym.factor(&a).unwrap();
        let mut x = [0.0; 3];
        assert!(matches!(
            chol.solve(&[1.0, 1.0, 1.0], &mut x),
            Err(DirectError::InvalidInput { .. })
        ));
        let rect: CsMat<f64> = TriMat::<f64>::new((2, 3)).to_csr();
        assert!(matches!(
            CholeskySymbolic::new(&rect),
            Err(DirectError::Pattern { .. })
        ));
    }
}
