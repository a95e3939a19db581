//! Incomplete Cholesky IC(0) (Meijerink & van der Vorst 1977; Saad 2003, §10.3.2): A ≈ LLᵀ
//! with the sparsity of tril(A). The CG preconditioner for SPD systems whose diagonal alone
//! (Jacobi) leaves too many iterations; cheap to build (one pass over the matrix).
#![forbid(unsafe_code)]

use crate::linalg::sparse::{Csr, CsrOps};

/// Incomplete Cholesky IC(0) with the pattern of tril(A), A ≈ LLᵀ.
///
/// Right-looking on the lower triangle stored by columns: column k of tril(A) is row k of
/// triu(A), so the CSR rows of a symmetric A give it without a transpose.
pub(crate) struct Ic0 {
    colptr: Vec<usize>,
    /// Row indices per column, ascending; the first entry of each column is the diagonal.
    rows: Vec<usize>,
    values: Vec<f64>,
}

impl Ic0 {
    /// Factorises A + shift·diag(A); `None` on a missing, non-positive or non-finite pivot.
    pub(crate) fn factor(a: &Csr, shift: f64) -> Option<Ic0> {
        let n = a.rows();
        let mut colptr = Vec::with_capacity(n + 1);
        let mut rows = Vec::new();
        let mut values = Vec::new();
        let mut orig_diag = Vec::with_capacity(n);
        colptr.push(0);
        for k in 0..n {
            let (cols, vals) = a.row_of(k);
            let first = cols.partition_point(|&j| j < k);
            if cols.get(first) != Some(&k) {
                return None;
            }
            orig_diag.push(vals[first]);
            rows.push(k);
            values.push(vals[first] * (1.0 + shift));
            rows.extend_from_slice(&cols[first + 1..]);
            values.extend_from_slice(&vals[first + 1..]);
            colptr.push(rows.len());
        }
        for k in 0..n {
            let (s, e) = (colptr[k], colptr[k + 1]);
            let d = values[s];
            let positive = d.is_finite() && d > 1e-12 * orig_diag[k].abs();
            if !positive {
                return None;
            }
            // l_kk = √d_k; l_ik = a_ik / l_kk
            let lkk = d.sqrt();
            values[s] = lkk;
            for p in s + 1..e {
                values[p] /= lkk;
            }
            // Schur update of the trailing matrix on the pattern: a_ij −= l_ik·l_jk.
            for q in s + 1..e {
                let (j, ljk) = (rows[q], values[q]);
                values[colptr[j]] -= ljk * ljk;
                for p in q + 1..e {
                    let (i, lik) = (rows[p], values[p]);
                    let (cs, ce) = (colptr[j] + 1, colptr[j + 1]);
                    if let Ok(pos) = rows[cs..ce].binary_search(&i) {
                        values[cs + pos] -= lik * ljk;
                    }
                }
            }
        }
        Some(Ic0 {
            colptr,
            rows,
            values,
        })
    }

    /// z = (LLᵀ)⁻¹ r: L y = r column by column, then Lᵀ z = y row by row (row k of Lᵀ is
    /// column k of L).
    pub(crate) fn apply(&self, r: &[f64], z: &mut [f64]) {
        let n = r.len();
        z.copy_from_slice(r);
        for k in 0..n {
            let (s, e) = (self.colptr[k], self.colptr[k + 1]);
            let yk = z[k] / self.values[s];
            z[k] = yk;
            for p in s + 1..e {
                z[self.rows[p]] -= self.values[p] * yk;
            }
        }
        for k in (0..n).rev() {
            let (s, e) = (self.colptr[k], self.colptr[k + 1]);
            let mut acc = z[k];
            for p in s + 1..e {
                acc -= self.values[p] * z[self.rows[p]];
            }
            z[k] = acc / self.values[s];
        }
    }
}
