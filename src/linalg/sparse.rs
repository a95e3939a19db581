//! Compressed sparse row matrices of the iterative solvers and their preconditioners
//! (storage as in Saad, *Iterative Methods for Sparse Linear Systems*, 2nd ed. 2003, §3.4;
//! products by rows with a dense accumulator, Gustavson 1978).
//!
//! The matrix type is `sprs::CsMat<f64>`, the one CSR type of the crate: callers assemble
//! into it, and the solvers copy it once (checked square and finite, with a proper index
//! pointer). This module adds what the factorisations, the multigrid hierarchy and the Krylov
//! loops need on top of it: plain row slices, a row-parallel SpMV whose result does not
//! depend on the thread count, and a row-by-row builder.
#![forbid(unsafe_code)]

use rayon::prelude::*;
use sprs::CsMat;

use super::{norm, SolveError};

/// Matrices with at least this many rows get a rayon-parallel sparse matrix–vector product.
pub const PARALLEL_ROWS: usize = 20_000;

/// The solvers' CSR matrix: `sprs`'s, owned, with a proper index pointer (starting at 0) and
/// sorted column indices in each row.
pub(crate) type Csr = CsMat<f64>;

/// Copies a square `sprs` CSR matrix, checking its entries are finite.
pub(crate) fn from_sprs(a: &CsMat<f64>) -> Result<Csr, SolveError> {
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
    if let Some(i) = a.data().iter().position(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite {
            what: format!("matrix entry {i}"),
        });
    }
    let indptr = a.indptr().to_proper().into_owned();
    Ok(CsMat::new(
        (a.rows(), a.cols()),
        indptr,
        a.indices().to_vec(),
        a.data().to_vec(),
    ))
}

/// Row access and the products of the solvers on a [`Csr`] (as built by [`from_sprs`] or
/// [`RowBuilder`]).
pub(crate) trait CsrOps {
    /// The index pointer as a plain slice.
    fn ptr(&self) -> &[usize];
    /// Column indices and values of row i.
    fn row_of(&self, i: usize) -> (&[usize], &[f64]);
    fn row_dot(&self, i: usize, x: &[f64]) -> f64;
    /// y = A·x, parallel over rows when the matrix is large.
    fn spmv(&self, x: &[f64], y: &mut [f64]);
    /// Position of the diagonal entry of each row, `None` if one is missing.
    fn diagonal_positions(&self) -> Option<Vec<usize>>;
    /// The diagonal (0 where an entry is missing).
    fn diagonal_values(&self) -> Vec<f64>;
    /// A·B by rows with a dense accumulator (Gustavson 1978); rows come out sorted.
    fn product(&self, b: &Csr) -> Csr;
}

/// Position of row i's diagonal entry in the value array, `None` if it is missing.
fn diagonal_position(a: &Csr, i: usize) -> Option<usize> {
    let p = a.row_of(i).0.binary_search(&i).ok()?;
    Some(p + a.ptr()[i])
}

impl CsrOps for Csr {
    #[inline]
    fn ptr(&self) -> &[usize] {
        self.indptr().into_raw_storage()
    }

    #[inline]
    fn row_of(&self, i: usize) -> (&[usize], &[f64]) {
        let (s, e) = (self.ptr()[i], self.ptr()[i + 1]);
        (&self.indices()[s..e], &self.data()[s..e])
    }

    #[inline]
    fn row_dot(&self, i: usize, x: &[f64]) -> f64 {
        let (cols, vals) = self.row_of(i);
        cols.iter().zip(vals).map(|(&j, &v)| v * x[j]).sum()
    }

    fn spmv(&self, x: &[f64], y: &mut [f64]) {
        if self.rows() >= PARALLEL_ROWS {
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

    fn diagonal_positions(&self) -> Option<Vec<usize>> {
        (0..self.rows())
            .map(|i| diagonal_position(self, i))
            .collect()
    }

    fn diagonal_values(&self) -> Vec<f64> {
        (0..self.rows())
            .map(|i| diagonal_position(self, i).map_or(0.0, |p| self.data()[p]))
            .collect()
    }

    fn product(&self, b: &Csr) -> Csr {
        let mut out = RowBuilder::new(self.rows(), b.cols());
        for i in 0..self.rows() {
            let (ac, av) = self.row_of(i);
            for (&k, &a_ik) in ac.iter().zip(av) {
                let (bc, bv) = b.row_of(k);
                for (&j, &b_kj) in bc.iter().zip(bv) {
                    out.add(j, a_ik * b_kj);
                }
            }
            out.finish_row();
        }
        out.build()
    }
}

/// Assembles a CSR matrix row by row, summing duplicate columns with a dense accumulator.
pub(crate) struct RowBuilder {
    rows: usize,
    cols: usize,
    indptr: Vec<usize>,
    indices: Vec<usize>,
    data: Vec<f64>,
    acc: Vec<f64>,
    mark: Vec<bool>,
    here: Vec<usize>,
}

impl RowBuilder {
    pub(crate) fn new(rows: usize, cols: usize) -> RowBuilder {
        RowBuilder {
            rows,
            cols,
            indptr: vec![0],
            indices: Vec::new(),
            data: Vec::new(),
            acc: vec![0.0; cols],
            mark: vec![false; cols],
            here: Vec::new(),
        }
    }

    #[inline]
    pub(crate) fn add(&mut self, j: usize, v: f64) {
        if !self.mark[j] {
            self.mark[j] = true;
            self.acc[j] = 0.0;
            self.here.push(j);
        }
        self.acc[j] += v;
    }

    pub(crate) fn finish_row(&mut self) {
        self.here.sort_unstable();
        for &j in &self.here {
            self.indices.push(j);
            self.data.push(self.acc[j]);
            self.mark[j] = false;
        }
        self.here.clear();
        self.indptr.push(self.indices.len());
    }

    pub(crate) fn build(self) -> Csr {
        debug_assert_eq!(self.indptr.len(), self.rows + 1);
        CsMat::new((self.rows, self.cols), self.indptr, self.indices, self.data)
    }
}

#[inline]
/// r = b − A·x, returns ‖r‖.
pub(crate) fn residual(a: &Csr, b: &[f64], x: &[f64], r: &mut [f64]) -> f64 {
    a.spmv(x, r);
    for (ri, bi) in r.iter_mut().zip(b) {
        *ri = bi - *ri;
    }
    norm(r)
}

/// ‖b − A·x‖ / ‖b‖ (0 when b = 0): the accuracy report of a direct solve.
pub fn relative_residual(a: &Csr, b: &[f64], x: &[f64]) -> f64 {
    let mut r = vec![0.0; b.len()];
    let rn = residual(a, b, x, &mut r);
    let bn = norm(b);
    if bn > 0.0 {
        rn / bn
    } else {
        0.0
    }
}

pub(crate) fn check_vectors(a: &Csr, b: &[f64], x: &[f64]) -> Result<(), SolveError> {
    if b.len() != a.rows() || x.len() != a.rows() {
        return Err(SolveError::InvalidInput {
            what: format!(
                "matrix has {} rows but b has {} and x has {} entries",
                a.rows(),
                b.len(),
                x.len()
            ),
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
