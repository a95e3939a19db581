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
//! The global solver's systems are made of 2×2 blocks (one per pair of vertices sharing a
//! face): [`CholeskySymbolic::blocked`] orders the vertex graph instead of the unknowns' (a
//! quarter of the entries) and factors supernodally, which faer's scalar heuristic does not
//! choose for 2D-mesh systems; BENCHMARKS.md (issue 21, round 3) has the measured effect.
//!
//! faer is built without its `rayon` feature: the factorisation runs on one thread, so its
//! result, like the rest of the CPU path, does not depend on the thread count.
#![forbid(unsafe_code)]

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltError;
use faer::perm::PermRef;
use faer::sparse::linalg::amd;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, simplicial, supernodal, CholeskySymbolicParams, LltRef,
    SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use std::borrow::Cow;
use std::sync::Arc;

use sprs::CsMat;

use super::pattern::sort_dedup_lists;
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
    symbolic: Arc<SymbolicCholesky<usize>>,
    /// The permuted matrix `P A Pᵀ`'s one triangle, the one the numeric factorisation reads.
    permuted: Arc<Permuted>,
    /// Workspace of one numeric factorisation (it depends on the symbolic factor only).
    scratch: StackReq,
}

/// Where each stored entry of `A` goes in the triangle of `P A Pᵀ` that faer's numeric
/// factorisation reads (lower for a supernodal factor, upper for a simplicial one). faer's
/// own `factorize_numeric_llt` builds that matrix again for every factorisation (counting
/// sort of the permuted entries, a fifth or more of a 2D-mesh system's factorisation); the
/// structure depends only on the pattern and the ordering, so it is built once here and each
/// factorisation only scatters the values.
#[derive(Debug)]
struct Permuted {
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// Per stored entry of `A` (CSR order): its position in `row_idx`, or `usize::MAX` for an
    /// entry of the triangle that is not read (below the diagonal of a CSR row).
    scatter: Vec<usize>,
}

impl Permuted {
    /// The structure of `P A Pᵀ`'s `lower` (or upper) triangle for the symmetric CSR pattern
    /// (`indptr`, `indices`), whose upper triangle per row is read, and the inverse
    /// permutation `inv` (old index → new; `None`: identity). Rows within a column are in no
    /// particular order, as faer's own permuted matrix (its numeric factorisation scatters them).
    fn new(indptr: &[usize], indices: &[usize], inv: Option<&[usize]>, lower: bool) -> Permuted {
        let n = indptr.len() - 1;
        let new = |i: usize| inv.map_or(i, |p| p[i]);
        // (column, row) in the permuted matrix of stored entry k, when read.
        let place = |r: usize, c: usize| -> Option<(usize, usize)> {
            if c < r {
                return None;
            }
            let (a, b) = (new(r), new(c));
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            Some(if lower { (lo, hi) } else { (hi, lo) })
        };
        let mut col_ptr = vec![0usize; n + 1];
        for r in 0..n {
            for &c in &indices[indptr[r]..indptr[r + 1]] {
                if let Some((col, _)) = place(r, c) {
                    col_ptr[col + 1] += 1;
                }
            }
        }
        for j in 0..n {
            col_ptr[j + 1] += col_ptr[j];
        }
        let nnz = col_ptr[n];
        let mut next = col_ptr.clone();
        let mut row_idx = vec![0usize; nnz];
        let mut scatter = vec![usize::MAX; indices.len()];
        for r in 0..n {
            for (k, &c) in indices
                .iter()
                .enumerate()
                .take(indptr[r + 1])
                .skip(indptr[r])
            {
                if let Some((col, row)) = place(r, c) {
                    row_idx[next[col]] = row;
                    scatter[k] = next[col];
                    next[col] += 1;
                }
            }
        }
        Permuted {
            col_ptr,
            row_idx,
            scatter,
        }
    }
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

fn faer_error(what: &str, e: impl std::fmt::Debug) -> DirectError {
    DirectError::Faer {
        what: format!("{what}: {e:?}"),
    }
}

/// The AMD ordering of the quotient graph of `b`×`b` blocks of the symmetric pattern
/// (`indptr`, `indices`), expanded to the unknowns: forward and inverse permutations.
fn block_amd(
    indptr: &[usize],
    indices: &[usize],
    n: usize,
    b: usize,
) -> Result<(Vec<usize>, Vec<usize>), DirectError> {
    let nb = n / b;
    // Block row i: the block columns of its b rows (rows b·i .. b·i + b are contiguous).
    let mut idx: Vec<usize> = indices[..indptr[n]].iter().map(|&j| j / b).collect();
    let starts: Vec<usize> = (0..=nb).map(|i| indptr[i * b]).collect();
    let ptr = sort_dedup_lists(&starts, &mut idx);
    let pattern = SymbolicSparseColMatRef::new_checked(nb, nb, &ptr, None, &idx);
    let (mut fwd, mut inv) = (vec![0usize; nb], vec![0usize; nb]);
    let mut mem = MemBuffer::try_new(amd::order_maybe_unsorted_scratch::<usize>(nb, idx.len()))
        .map_err(|e| faer_error("ordering workspace", e))?;
    amd::order_maybe_unsorted(
        &mut fwd,
        &mut inv,
        pattern,
        amd::Control::default(),
        MemStack::new(&mut mem),
    )
    .map_err(|e| faer_error("ordering", e))?;
    let expand = |p: &[usize]| -> Vec<usize> {
        p.iter()
            .flat_map(|&v| (0..b).map(move |r| b * v + r))
            .collect()
    };
    Ok((expand(&fwd), expand(&inv)))
}

impl CholeskySymbolic {
    /// Orders and symbolically factors the pattern of the symmetric matrix `a` (CSR, both
    /// triangles stored; only the upper triangle of each row is read, so a matrix symmetric in
    /// pattern but not quite in value is factored as its upper triangle says).
    pub fn new(a: &CsMat<f64>) -> Result<CholeskySymbolic, DirectError> {
        Self::analyse(a, None, false)
    }

    /// [`CholeskySymbolic::new`] for a matrix made of dense `b`×`b` blocks (the interleaved
    /// UVs of a mesh: one block per pair of vertices that share a face). The ordering is the
    /// AMD ordering of the blocks' graph, which has `b²` times fewer entries to order and keeps
    /// each block's unknowns together; and the factorisation is supernodal: the `b` columns of
    /// a block have the same structure in the factor, so its columns come at least `b` at a
    /// time and dense kernels apply to every panel (faer's own choice, from the flop count
    /// per entry of a scalar matrix, picks the column-by-column factorisation for 2D-mesh
    /// systems; BENCHMARKS.md has the measured difference).
    pub fn blocked(a: &CsMat<f64>, b: usize) -> Result<CholeskySymbolic, DirectError> {
        let (indptr, indices, _) = csr_parts(a)?;
        let n = a.rows();
        let perm = if b > 1 && n % b == 0 && n > 0 {
            Some(block_amd(&indptr, indices, n, b)?)
        } else {
            None
        };
        Self::analyse(a, perm, b > 1)
    }

    /// Symbolic factorisation of `a` under `perm` (forward, inverse; AMD when `None`).
    fn analyse(
        a: &CsMat<f64>,
        perm: Option<(Vec<usize>, Vec<usize>)>,
        supernodal: bool,
    ) -> Result<CholeskySymbolic, DirectError> {
        let (indptr, indices, _) = csr_parts(a)?;
        let n = a.rows();
        // The CSR arrays of A are the CSC arrays of Aᵀ = A; the rows' upper triangle is the
        // columns' lower one.
        let pattern = SymbolicSparseColMatRef::new_checked(n, n, &indptr, None, indices);
        let ordering = match &perm {
            Some((fwd, inv)) => SymmetricOrdering::Custom(PermRef::new_checked(fwd, inv, n)),
            None => SymmetricOrdering::Amd,
        };
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: if supernodal {
                SupernodalThreshold::FORCE_SUPERNODAL
            } else {
                SupernodalThreshold::default()
            },
            ..Default::default()
        };
        let symbolic = factorize_symbolic_cholesky(pattern, Side::Lower, ordering, params)
            .map_err(|e| faer_error("symbolic factorisation", e))?;
        let lower = matches!(symbolic.raw(), SymbolicCholeskyRaw::Supernodal(_));
        let permuted = Permuted::new(
            &indptr,
            indices,
            symbolic.perm().map(|p| p.arrays().1),
            lower,
        );
        let scratch = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => {
                supernodal::factorize_supernodal_numeric_llt_scratch::<usize, f64>(
                    s,
                    Par::Seq,
                    Default::default(),
                )
            }
            SymbolicCholeskyRaw::Simplicial(_) => {
                simplicial::factorize_simplicial_numeric_llt_scratch::<usize, f64>(n)
            }
        };
        Ok(CholeskySymbolic {
            n,
            indptr: indptr.to_vec(),
            indices: indices.to_vec(),
            symbolic: Arc::new(symbolic),
            permuted: Arc::new(permuted),
            scratch,
        })
    }

    /// Rows (= columns) of the matrices this pattern factors.
    pub fn rows(&self) -> usize {
        self.n
    }

    /// Whether `a` has exactly the pattern this was built from (what [`Self::factor`] needs).
    pub fn fits(&self, a: &CsMat<f64>) -> bool {
        csr_parts(a).is_ok_and(|(indptr, indices, _)| {
            a.rows() == self.n && *indptr == *self.indptr && indices == self.indices
        })
    }

    /// Numerically factors `a`, which must have exactly the pattern this was built from.
    pub fn factor(&self, a: &CsMat<f64>) -> Result<Cholesky, DirectError> {
        let (_, _, data) = csr_parts(a)?;
        if !self.fits(a) {
            return Err(DirectError::Pattern {
                what: "the matrix's sparsity pattern differs from the symbolic factorisation's"
                    .into(),
            });
        }
        let p = &*self.permuted;
        let mut permuted_values = vec![0.0; p.row_idx.len()];
        for (&t, &v) in p.scatter.iter().zip(data) {
            if t != usize::MAX {
                permuted_values[t] = v;
            }
        }
        let pattern = SymbolicSparseColMatRef::new_unsorted_checked(
            self.n, self.n, &p.col_ptr, None, &p.row_idx,
        );
        let mat = SparseColMatRef::new(pattern, &permuted_values);
        let mut values = vec![0.0; self.symbolic.len_val()];
        let mut mem = MemBuffer::try_new(self.scratch)
            .map_err(|e| faer_error("factorisation workspace", e))?;
        let stack = MemStack::new(&mut mem);
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => supernodal::factorize_supernodal_numeric_llt(
                &mut values,
                mat,
                Default::default(),
                s,
                Par::Seq,
                stack,
                Default::default(),
            ),
            SymbolicCholeskyRaw::Simplicial(s) => simplicial::factorize_simplicial_numeric_llt(
                &mut values,
                mat,
                Default::default(),
                s,
                stack,
            ),
        }
        .map_err(|e| match e {
            LltError::NonPositivePivot { index } => {
                DirectError::NotPositiveDefinite { pivot: index }
            }
        })?;
        Ok(Cholesky {
            n: self.n,
            symbolic: self.symbolic.clone(),
            values,
        })
    }
}

/// The numeric factor of one matrix.
#[derive(Clone, Debug)]
pub struct Cholesky {
    n: usize,
    symbolic: Arc<SymbolicCholesky<usize>>,
    values: Vec<f64>,
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
        let scratch = self.symbolic.solve_in_place_scratch::<f64>(k, Par::Seq);
        let mut mem = MemBuffer::try_new(scratch).map_err(|e| faer_error("solve workspace", e))?;
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(x, self.n, k),
            Par::Seq,
            MemStack::new(&mut mem),
        );
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

    /// A matrix of 2×2 blocks on a `w`×`h` grid of vertices (the 4-neighbour graph's
    /// Laplacian ⊗ an SPD 2×2, shifted to be positive definite).
    fn block_grid(w: usize, h: usize) -> CsMat<f64> {
        let nv = w * h;
        let k = [[2.0, 0.5], [0.5, 1.0]];
        let mut e = Vec::new();
        let mut block = |a: usize, b: usize, s: f64| {
            for r in 0..2 {
                for c in 0..2 {
                    e.push((2 * a + r, 2 * b + c, s * k[r][c]));
                }
            }
        };
        for y in 0..h {
            for x in 0..w {
                let v = y * w + x;
                let mut deg = 0.1;
                for (dx, dy) in [(1, 0), (0, 1)] {
                    if x + dx < w && y + dy < h {
                        let u = (y + dy) * w + x + dx;
                        block(v, u, -1.0);
                        block(u, v, -1.0);
                    }
                }
                for (dx, dy) in [(-1i32, 0i32), (1, 0), (0, -1), (0, 1)] {
                    let (xx, yy) = (x as i32 + dx, y as i32 + dy);
                    if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
                        deg += 1.0;
                    }
                }
                block(v, v, deg);
            }
        }
        csr(2 * nv, &e)
    }

    /// The permuted triangle built once per pattern ([`Permuted`]) is the matrix faer's own
    /// numeric factorisation permutes each time: the factors agree bit for bit, for the
    /// supernodal (blocked) and the simplicial (scalar AMD, a small matrix) factorisation.
    #[test]
    fn permuted_once_factors_like_faer_permuting_each_time() {
        // The grid with values that differ per entry (still symmetric), and a small matrix
        // for which faer's heuristic picks the simplicial factorisation.
        let grid = block_grid(9, 7);
        let mut t = TriMat::new((grid.rows(), grid.cols()));
        for (v, (i, j)) in grid.iter() {
            let bump = if i == j {
                0.0
            } else {
                1e-3 * ((i + j) % 5) as f64
            };
            t.add_triplet(i, j, *v - bump);
        }
        let grid = t.to_csr();
        let small = csr(
            4,
            &[
                (0, 0, 2.0),
                (0, 3, 1.0),
                (1, 1, 3.0),
                (2, 2, 1.0),
                (3, 0, 1.0),
                (3, 3, 4.0),
            ],
        );
        for (sym, m, supernodal) in [
            (CholeskySymbolic::blocked(&grid, 2).unwrap(), &grid, true),
            (CholeskySymbolic::new(&small).unwrap(), &small, false),
        ] {
            let raw = sym.symbolic.raw();
            assert_eq!(
                matches!(raw, SymbolicCholeskyRaw::Supernodal(_)),
                supernodal
            );
            let ours = sym.factor(m).unwrap();
            let (indptr, indices, data) = csr_parts(m).unwrap();
            let pattern =
                SymbolicSparseColMatRef::new_checked(sym.n, sym.n, &indptr, None, indices);
            let mut values = vec![0.0; sym.symbolic.len_val()];
            let scratch = sym
                .symbolic
                .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default());
            let mut mem = MemBuffer::try_new(scratch).unwrap();
            sym.symbolic
                .factorize_numeric_llt::<f64>(
                    &mut values,
                    SparseColMatRef::new(pattern, data),
                    Side::Lower,
                    Default::default(),
                    Par::Seq,
                    MemStack::new(&mut mem),
                    Default::default(),
                )
                .unwrap();
            assert_eq!(ours.values, values);
        }
    }

    /// A matrix of 2×2 blocks ([`block_grid`]): the block ordering keeps each block's two
    /// unknowns adjacent, and its supernodal factor solves like the scalar AMD one.
    #[test]
    fn blocked_ordering_solves_like_the_scalar_one() {
        let nv = 6 * 5;
        let a = block_grid(6, 5);
        let b: Vec<f64> = (0..2 * nv).map(|i| ((i * 7) % 11) as f64 - 5.0).collect();
        let blocked = CholeskySymbolic::blocked(&a, 2).unwrap();
        let perm = blocked.symbolic.perm().unwrap();
        let (fwd, _) = perm.arrays();
        for pair in fwd.chunks_exact(2) {
            assert!(pair[0] % 2 == 0 && pair[1] == pair[0] + 1, "{pair:?}");
        }
        let (mut x1, mut x2) = (vec![0.0; 2 * nv], vec![0.0; 2 * nv]);
        blocked.factor(&a).unwrap().solve(&b, &mut x1).unwrap();
        Cholesky::new(&a).unwrap().solve(&b, &mut x2).unwrap();
        assert!(residual(&a, &x1, &b) < 1e-10);
        for (p, q) in x1.iter().zip(&x2) {
            assert!((p - q).abs() < 1e-10 * (1.0 + q.abs()));
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
