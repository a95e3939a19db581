//! Incomplete LU ILU(0) (Saad 2003, §10.3.2, IKJ variant): A ≈ LU with the sparsity of A.
//! The BiCGSTAB preconditioner for the non-symmetric mean-value Tutte systems, where IC(0)
//! does not apply.
#![forbid(unsafe_code)]

use crate::linalg::sparse::{Csr, CsrOps};

/// Incomplete LU ILU(0) with the pattern of A (unit lower L and upper U stored together, in
/// the layout of A).
pub(crate) struct Ilu0 {
    values: Vec<f64>,
    /// Position of the diagonal entry in each row.
    diag: Vec<usize>,
}

impl Ilu0 {
    /// Factorises A + shift·diag(A) (IKJ variant); `None` on a missing, negligible or
    /// non-finite pivot.
    pub(crate) fn factor(a: &Csr, shift: f64) -> Option<Ilu0> {
        let n = a.rows();
        let diag = a.diagonal_positions()?;
        let mut values = a.data().to_vec();
        for &p in &diag {
            values[p] *= 1.0 + shift;
        }
        let mut pos = vec![usize::MAX; n];
        for i in 0..n {
            let (s, e) = (a.ptr()[i], a.ptr()[i + 1]);
            for p in s..e {
                pos[a.indices()[p]] = p;
            }
            for p in s..diag[i] {
                let k = a.indices()[p];
                // l_ik = a_ik / u_kk; then row_i −= l_ik · row_k (U part, on the pattern).
                let lik = values[p] / values[diag[k]];
                values[p] = lik;
                for q in diag[k] + 1..a.ptr()[k + 1] {
                    let pj = pos[a.indices()[q]];
                    if pj != usize::MAX {
                        values[pj] -= lik * values[q];
                    }
                }
            }
            let d = values[diag[i]];
            if !d.is_finite() || d.abs() <= 1e-14 * a.data()[diag[i]].abs() {
                return None;
            }
            for p in s..e {
                pos[a.indices()[p]] = usize::MAX;
            }
        }
        Some(Ilu0 { values, diag })
    }

    /// z = (LU)⁻¹ r.
    pub(crate) fn apply(&self, a: &Csr, r: &[f64], z: &mut [f64]) {
        let n = r.len();
        for i in 0..n {
            let mut acc = r[i];
            for p in a.ptr()[i]..self.diag[i] {
                acc -= self.values[p] * z[a.indices()[p]];
            }
            z[i] = acc;
        }
        for i in (0..n).rev() {
            let mut acc = z[i];
            for p in self.diag[i] + 1..a.ptr()[i + 1] {
                acc -= self.values[p] * z[a.indices()[p]];
            }
            z[i] = acc / self.values[self.diag[i]];
        }
    }
}
