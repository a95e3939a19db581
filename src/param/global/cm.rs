//! The Newton phase: the per-face Hessian made positive semi-definite in closed form.
//!
//! Shtengel et al. 2017 ("Geometric optimization via composite majorization") build a convex
//! majorizer of each face's Hessian from the energy's composite structure; Smith, de Goes &
//! Kim 2019 give the exact eigensystem of the same 4x4 Hessians, whose clamping to
//! non-negative eigenvalues is the tightest PSD approximation in the Frobenius norm. We use the
//! latter (already in [`crate::param::admm::kernels::hessian_eigensystem`], shared with the
//! ADMM face step): it costs no more than the majorizer, is exact wherever the face energy is
//! locally convex (so the phase converges quadratically near the optimum, as CM does), and
//! only needs the energy's value, never its composite split.

use crate::param::admm::kernels::hessian_eigensystem;
use crate::param::energy::Energy;

/// `w H⁺`: the energy's 4x4 Hessian at `a` with its eigenvalues clamped to ≥ 0, weighted.
/// Only for det A > 0.
pub fn projected_hessian(energy: Energy, a: &[f64; 4], w: f64) -> [[f64; 4]; 4] {
    let (lam, modes) = hessian_eigensystem(energy, a);
    let mut h = [[0.0; 4]; 4];
    for k in 0..4 {
        let l = w * lam[k].max(0.0);
        if l == 0.0 {
            continue;
        }
        let m = &modes[k];
        for i in 0..4 {
            for j in 0..4 {
                h[i][j] += l * m[i] * m[j];
            }
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::small::sym_eigen;
    use crate::param::energy;

    #[test]
    fn projection_is_exact_when_convex_and_psd_otherwise() {
        for en in [Energy::SymmetricDirichlet, Energy::Mips] {
            for a in [
                [1.3, 0.2, -0.4, 0.7],
                [3.0, 0.0, 0.0, 0.2],
                [1.0, 0.1, 0.0, 1.0],
            ] {
                let (_, _, h) = energy::eval(en, &a);
                let p = projected_hessian(en, &a, 1.0);
                let (lh, _) = sym_eigen(&h);
                let (lp, _) = sym_eigen(&p);
                assert!(lp.iter().all(|&l| l > -1e-9 * lh[0].abs()), "{en:?} {a:?}");
                if lh.iter().all(|&l| l >= 0.0) {
                    for i in 0..4 {
                        for j in 0..4 {
                            assert!((h[i][j] - p[i][j]).abs() < 1e-9 * h[i][i].abs().max(1.0));
                        }
                    }
                }
            }
        }
    }
}
