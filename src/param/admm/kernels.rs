//! The CPU f64 twins of the ADMM shaders, one function per kernel, written per element so the
//! GLSL in `glsl/admm/` can be read side by side with them. The CPU backend ([`super::cpu`])
//! maps them over all faces / edges / slots; the tests compare each shader against its twin.

use crate::param::energy::{self, Energy};

/// Fixed number of cyclic Jacobi sweeps for the 4x4 eigenproblem (the GLSL twin uses the same
/// count; 6 sweeps take a symmetric 4x4 to machine precision in practice).
pub const JACOBI_SWEEPS: usize = 6;

/// Maximum step halvings in the face line search.
pub const MAX_HALVINGS: usize = 24;

/// Armijo sufficient-decrease constant.
pub const ARMIJO: f64 = 1e-4;

/// Fraction of the largest flip-free step taken at most (the determinant root itself is not a
/// valid step: it makes the face degenerate).
pub const FLIP_FREE_FRACTION: f64 = 0.9;

/// Eigen-decomposition of a symmetric 4x4 matrix by cyclic Jacobi rotations.
/// Returns eigenvalues and eigenvectors as the columns of `v` (`v[row][col]`).
pub fn jacobi_eigen4(h: &[[f64; 4]; 4]) -> ([f64; 4], [[f64; 4]; 4]) {
    let mut a = *h;
    let mut v = [[0.0; 4]; 4];
    for i in 0..4 {
        v[i][i] = 1.0;
    }
    for _ in 0..JACOBI_SWEEPS {
        for p in 0..3 {
            for q in (p + 1)..4 {
                let apq = a[p][q];
                if apq == 0.0 {
                    continue;
                }
                // Rotation angle that zeroes a[p][q]: tan 2θ = 2 a_pq / (a_qq − a_pp).
                let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..4 {
                    let akp = a[k][p];
                    let akq = a[k][q];
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..4 {
                    let apk = a[p][k];
                    let aqk = a[q][k];
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for k in 0..4 {
                    let vkp = v[k][p];
                    let vkq = v[k][q];
                    v[k][p] = c * vkp - s * vkq;
                    v[k][q] = s * vkp + c * vkq;
                }
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2], a[3][3]], v)
}

/// Face objective `w E(A) + (n μ / 2) ‖A − B̄‖²` (the slot penalties summed into one term around
/// their mean `B̄`); +∞ when `det A ≤ 0`.
pub fn face_objective(energy: Energy, a: &[f64; 4], bbar: &[f64; 4], nmu: f64, w: f64) -> f64 {
    let e = energy::value(energy, a);
    if !e.is_finite() {
        return f64::INFINITY;
    }
    let d2: f64 = a.iter().zip(bbar).map(|(x, y)| (x - y) * (x - y)).sum();
    w * e + 0.5 * nmu * d2
}

/// Face step twin of `glsl/admm/face_newton.comp`: `iters` projected-Newton steps on the face
/// objective from `a`, each with the flip-free maximal step and Armijo backtracking.
/// `bbar` is the mean of `Y_t + Λ_t/μ` over the face's `n` slots (ignored when `n = 0`).
pub fn face_newton(
    energy: Energy,
    a: [f64; 4],
    bbar: [f64; 4],
    n: u32,
    mu: f64,
    w: f64,
    iters: u32,
) -> [f64; 4] {
    let mut a = a;
    let nmu = n as f64 * mu;
    // A face with no interior edge only has its own energy: a tiny proximal term keeps the
    // system definite along MIPS's scale direction without moving the minimiser.
    let (nmu, bbar) = if n == 0 { (1e-9 * w, a) } else { (nmu, bbar) };
    for _ in 0..iters {
        let (e, g, h) = energy::eval(energy, &a);
        if !e.is_finite() {
            break;
        }
        let mut grad = [0.0; 4];
        for i in 0..4 {
            grad[i] = w * g[i] + nmu * (a[i] - bbar[i]);
        }
        let (lam, v) = jacobi_eigen4(&h);
        // p = −(w H⁺ + nμ I)⁻¹ ∇F through the eigenbasis; H⁺ clamps negative eigenvalues to 0.
        let mut p = [0.0; 4];
        for k in 0..4 {
            let mut proj = 0.0;
            for i in 0..4 {
                proj += v[i][k] * grad[i];
            }
            let denom = w * lam[k].max(0.0) + nmu;
            let coef = -proj / denom;
            for i in 0..4 {
                p[i] += coef * v[i][k];
            }
        }
        let slope: f64 = grad.iter().zip(&p).map(|(x, y)| x * y).sum();
        if !(slope < 0.0) {
            break;
        }
        let f0 = w * e
            + 0.5
                * nmu
                * a.iter()
                    .zip(&bbar)
                    .map(|(x, y)| (x - y) * (x - y))
                    .sum::<f64>();
        let mut t = (FLIP_FREE_FRACTION * energy::max_flip_free_step(&a, &p)).min(1.0);
        let mut accepted = false;
        for _ in 0..MAX_HALVINGS {
            let cand = [
                a[0] + t * p[0],
                a[1] + t * p[1],
                a[2] + t * p[2],
                a[3] + t * p[3],
            ];
            let f1 = face_objective(energy, &cand, &bbar, nmu, w);
            if f1 <= f0 + ARMIJO * t * slope {
                a = cand;
                accepted = true;
                break;
            }
            t *= 0.5;
        }
        if !accepted {
            break;
        }
    }
    a
}

/// Edge step twin of `glsl/admm/edge_project.comp`: projection of `Q_k = A_k − Λ_k/μ` onto the
/// consensus constraint `Y1 ê1 = Y2 ê2` (ê unit): `r = Q1ê1 − Q2ê2`, `Y1 = Q1 − ½ r ê1ᵀ`,
/// `Y2 = Q2 + ½ r ê2ᵀ`.
pub fn edge_project(
    a1: &[f64; 4],
    a2: &[f64; 4],
    l1: &[f64; 4],
    l2: &[f64; 4],
    e1: &[f64; 2],
    e2: &[f64; 2],
    mu: f64,
) -> ([f64; 4], [f64; 4]) {
    let q1: [f64; 4] = std::array::from_fn(|i| a1[i] - l1[i] / mu);
    let q2: [f64; 4] = std::array::from_fn(|i| a2[i] - l2[i] / mu);
    let r = [
        q1[0] * e1[0] + q1[1] * e1[1] - q2[0] * e2[0] - q2[1] * e2[1],
        q1[2] * e1[0] + q1[3] * e1[1] - q2[2] * e2[0] - q2[3] * e2[1],
    ];
    let y1 = [
        q1[0] - 0.5 * r[0] * e1[0],
        q1[1] - 0.5 * r[0] * e1[1],
        q1[2] - 0.5 * r[1] * e1[0],
        q1[3] - 0.5 * r[1] * e1[1],
    ];
    let y2 = [
        q2[0] + 0.5 * r[0] * e2[0],
        q2[1] + 0.5 * r[0] * e2[1],
        q2[2] + 0.5 * r[1] * e2[0],
        q2[3] + 0.5 * r[1] * e2[1],
    ];
    (y1, y2)
}

/// Dual step twin of `glsl/admm/dual_update.comp`: `Λ += μ (Y − A)`.
pub fn dual_update(lambda: &[f64; 4], y: &[f64; 4], a: &[f64; 4], mu: f64) -> [f64; 4] {
    std::array::from_fn(|i| lambda[i] + mu * (y[i] - a[i]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_diagonalises() {
        let h = [
            [4.0, 1.0, -2.0, 0.5],
            [1.0, 3.0, 0.0, 1.0],
            [-2.0, 0.0, -1.0, 0.3],
            [0.5, 1.0, 0.3, 2.0],
        ];
        let (lam, v) = jacobi_eigen4(&h);
        for k in 0..4 {
            for i in 0..4 {
                let hv: f64 = (0..4).map(|j| h[i][j] * v[j][k]).sum();
                assert!((hv - lam[k] * v[i][k]).abs() < 1e-10, "H v = λ v fails");
            }
        }
    }

    #[test]
    fn edge_projection_satisfies_constraint() {
        let e1 = [0.6, 0.8];
        let e2 = [-0.8, 0.6];
        let (y1, y2) = edge_project(
            &[1.0, 0.2, 0.3, 0.9],
            &[0.5, -0.1, 0.4, 1.2],
            &[0.1; 4],
            &[-0.2; 4],
            &e1,
            &e2,
            10.0,
        );
        let m1 = [y1[0] * e1[0] + y1[1] * e1[1], y1[2] * e1[0] + y1[3] * e1[1]];
        let m2 = [y2[0] * e2[0] + y2[1] * e2[1], y2[2] * e2[0] + y2[3] * e2[1]];
        assert!((m1[0] - m2[0]).abs() < 1e-14 && (m1[1] - m2[1]).abs() < 1e-14);
    }

    #[test]
    fn face_newton_never_flips_and_descends() {
        // Target is a reflection: the optimum shrinks towards it but det stays positive.
        for energy in [Energy::Mips, Energy::SymmetricDirichlet] {
            let a0 = [1.0, 0.0, 0.0, 1.0];
            let bbar = [1.0, 0.0, 0.0, -1.0];
            let a = face_newton(energy, a0, bbar, 3, 10.0, 0.01, 8);
            assert!(energy::det(&a) > 0.0);
            let f0 = face_objective(energy, &a0, &bbar, 30.0, 0.01);
            let f1 = face_objective(energy, &a, &bbar, 30.0, 0.01);
            assert!(f1 <= f0);
        }
    }

    #[test]
    fn face_newton_converges_to_rotation_without_penalty_pull() {
        let a = face_newton(
            Energy::SymmetricDirichlet,
            [1.5, 0.3, -0.2, 0.8],
            [0.0; 4],
            0,
            1.0,
            1.0,
            30,
        );
        assert!((energy::value(Energy::SymmetricDirichlet, &a) - 4.0).abs() < 1e-9);
    }
}
