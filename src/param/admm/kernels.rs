//! The CPU f64 twins of the ADMM shaders, one function per kernel, written per element so the
//! GLSL in `glsl/admm/` can be read side by side with them. The CPU backend ([`super::cpu`])
//! maps them over all faces / edges / slots; the tests compare each shader against its twin.
//!
//! The 2×2 signed SVD and the half-angle step the shaders mirror are the crate's single copies
//! in [`crate::linalg::small`] (written trigonometry-free there because `glsl/common/admm.glsl`
//! is); they are re-exported here so a kernel reads beside its shader.

pub use crate::linalg::small::{half_angle, svd2};
use crate::param::energy::{self, Energy};

/// Maximum step halvings in the face line search.
pub const MAX_HALVINGS: usize = 24;

/// Armijo sufficient-decrease constant.
pub const ARMIJO: f64 = 1e-4;

/// Fraction of the largest flip-free step taken at most (the determinant root itself is not a
/// valid step: it makes the face degenerate).
pub const FLIP_FREE_FRACTION: f64 = 0.9;

/// `U X Vᵀ` for `U = rot(φ)`, `Vᵀ = rot(θ)` given as cos/sin pairs; row-major.
fn rotate(u: [f64; 2], x: [f64; 4], vt: [f64; 2]) -> [f64; 4] {
    let um = [u[0], -u[1], u[1], u[0]];
    let vm = [vt[0], -vt[1], vt[1], vt[0]];
    let ux = [
        um[0] * x[0] + um[1] * x[2],
        um[0] * x[1] + um[1] * x[3],
        um[2] * x[0] + um[3] * x[2],
        um[2] * x[1] + um[3] * x[3],
    ];
    [
        ux[0] * vm[0] + ux[1] * vm[2],
        ux[0] * vm[1] + ux[1] * vm[3],
        ux[2] * vm[0] + ux[3] * vm[2],
        ux[2] * vm[1] + ux[3] * vm[3],
    ]
}

/// Eigen-system of the energy's 4x4 Hessian in closed form (Smith, de Goes & Kim 2019,
/// "Analytic eigensystems for isotropic distortion energies", 2D case): with `A = U Σ Vᵀ`,
/// twist `U[0 −1; 1 0]Vᵀ/√2` has λ = (Ψ₁+Ψ₂)/(σ1+σ2), flip `U[0 1; 1 0]Vᵀ/√2` has
/// λ = (Ψ₁−Ψ₂)/(σ1−σ2) (both simplified below so σ1 = σ2 needs no limit), and the two scaling
/// modes `U diag(c) Vᵀ` come from the 2x2 Hessian of Ψ(σ1, σ2). Orthonormal (Frobenius).
/// Only for `det A > 0`.
pub fn hessian_eigensystem(energy: Energy, a: &[f64; 4]) -> ([f64; 4], [[f64; 4]; 4]) {
    let [cu, su, s1, s2, cv, sv] = svd2(a);
    let p12 = s1 * s2;
    let (twist, flip, h11, h22, h12) = match energy {
        Energy::Mips => {
            let d = 1.0 / (p12 * p12);
            (
                -(s1 - s2) * (s1 - s2) * d,
                (s1 + s2) * (s1 + s2) * d,
                2.0 * s2 / (s1 * s1 * s1),
                2.0 * s1 / (s2 * s2 * s2),
                -(s1 * s1 + s2 * s2) * d,
            )
        }
        Energy::SymmetricDirichlet => {
            let p3 = 1.0 / (p12 * p12 * p12);
            (
                2.0 - 2.0 * (s1 * s1 - p12 + s2 * s2) * p3,
                2.0 + 2.0 * (s1 * s1 + p12 + s2 * s2) * p3,
                2.0 + 6.0 / (s1 * s1 * s1 * s1),
                2.0 + 6.0 / (s2 * s2 * s2 * s2),
                0.0,
            )
        }
    };
    // 2x2 symmetric [h11 h12; h12 h22] by one rotation ψ, tan 2ψ = 2 h12 / (h11 − h22).
    let (dx, dy) = (h11 - h22, 2.0 * h12);
    let n = (dx * dx + dy * dy).sqrt();
    let [c, s] = if n > 0.0 {
        half_angle(dx / n, dy / n)
    } else {
        [1.0, 0.0]
    };
    let l1 = h11 * c * c + 2.0 * h12 * s * c + h22 * s * s;
    let l2 = h11 * s * s - 2.0 * h12 * s * c + h22 * c * c;
    let r = std::f64::consts::FRAC_1_SQRT_2;
    let u = [cu, su];
    let vt = [cv, sv];
    (
        [twist, flip, l1, l2],
        [
            rotate(u, [0.0, -r, r, 0.0], vt),
            rotate(u, [0.0, r, r, 0.0], vt),
            rotate(u, [c, 0.0, 0.0, s], vt),
            rotate(u, [-s, 0.0, 0.0, c], vt),
        ],
    )
}

/// Projected Newton direction `−(w H⁺ + nμ I)⁻¹ ∇F`, `H⁺` the energy Hessian with negative
/// eigenvalues clamped to 0 — always defined, since `nμ > 0` (cf. the singular systems a
/// plain solve hit in the prototype).
pub fn projected_newton_direction(
    energy: Energy,
    a: &[f64; 4],
    grad: &[f64; 4],
    w: f64,
    nmu: f64,
) -> [f64; 4] {
    let (lam, modes) = hessian_eigensystem(energy, a);
    let mut p = [0.0; 4];
    for k in 0..4 {
        let m = &modes[k];
        let proj = m[0] * grad[0] + m[1] * grad[1] + m[2] * grad[2] + m[3] * grad[3];
        let coef = -proj / (w * lam[k].max(0.0) + nmu);
        for i in 0..4 {
            p[i] += coef * m[i];
        }
    }
    p
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
    // A face with no interior edge only has its own energy: a proximal term keeps the system
    // definite along directions whose eigenvalue is clamped to 0 (MIPS's scale, a negative
    // twist), large enough that f32 rounding in the gradient there cannot blow up the step.
    let isolated = n == 0;
    let (nmu, mut bbar) = if isolated { (1e-3 * w, a) } else { (nmu, bbar) };
    for _ in 0..iters {
        if isolated {
            // Proximal centre at the current iterate: a damping term only, not a pull back.
            bbar = a;
        }
        let (e, g, _) = energy::eval(energy, &a);
        if !e.is_finite() {
            break;
        }
        let mut grad = [0.0; 4];
        for i in 0..4 {
            grad[i] = w * g[i] + nmu * (a[i] - bbar[i]);
        }
        let p = projected_newton_direction(energy, &a, &grad, w, nmu);
        let slope: f64 = grad.iter().zip(&p).map(|(x, y)| x * y).sum();
        if slope.is_nan() || slope >= 0.0 {
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

/// Edge step twin of `glsl/admm/edge_project.comp`: projection of `Q_k = A_k − Λ_k/μ_k` onto
/// the consensus constraint `Y1 e1 = Y2 e2` in the metric `μ1‖·‖² + μ2‖·‖²` of the two sides'
/// penalties: with `r = Q1e1 − Q2e2` and `D = μ2‖e1‖² + μ1‖e2‖²`, `Y1 = Q1 − (μ2/D) r e1ᵀ`,
/// `Y2 = Q2 + (μ1/D) r e2ᵀ` (Lagrange: `μ_k (Y_k − Q_k)` is `∓λ e_kᵀ`; the side with the stiffer
/// penalty moves less, equal penalties and unit `e` split `r` in halves). Between two faces of
/// one surface `e_k` is the unit edge vector; an edge between a chart face and a scaffold face
/// ([`super::AdmmProblem::with_scaffold`]) has rest lengths that differ, hence the general `e`.
pub fn edge_project(
    a1: &[f64; 4],
    a2: &[f64; 4],
    l1: &[f64; 4],
    l2: &[f64; 4],
    e1: &[f64; 2],
    e2: &[f64; 2],
    mu1: f64,
    mu2: f64,
) -> ([f64; 4], [f64; 4]) {
    let q1: [f64; 4] = std::array::from_fn(|i| a1[i] - l1[i] / mu1);
    let q2: [f64; 4] = std::array::from_fn(|i| a2[i] - l2[i] / mu2);
    let r = [
        q1[0] * e1[0] + q1[1] * e1[1] - q2[0] * e2[0] - q2[1] * e2[1],
        q1[2] * e1[0] + q1[3] * e1[1] - q2[2] * e2[0] - q2[3] * e2[1],
    ];
    let den = mu2 * (e1[0] * e1[0] + e1[1] * e1[1]) + mu1 * (e2[0] * e2[0] + e2[1] * e2[1]);
    let (t1, t2) = (mu2 / den, mu1 / den);
    let y1 = [
        q1[0] - t1 * r[0] * e1[0],
        q1[1] - t1 * r[0] * e1[1],
        q1[2] - t1 * r[1] * e1[0],
        q1[3] - t1 * r[1] * e1[1],
    ];
    let y2 = [
        q2[0] + t2 * r[0] * e2[0],
        q2[1] + t2 * r[0] * e2[1],
        q2[2] + t2 * r[1] * e2[0],
        q2[3] + t2 * r[1] * e2[1],
    ];
    (y1, y2)
}

/// Bounds of a face's penalty factor: with `μ·F` up to ~1e5 and factors in this range, `μ_f`,
/// `Λ/μ_f` and `μ_f·‖A‖²` stay finite and normal in f32 on the device.
pub const PENALTY_RANGE: (f64, f64) = (1e-12, 1e24);

/// MIPS's curvature at `A` relative to a rotation: along the similarities `sR` (`det = s²`) its
/// Hessian scales as `1/s²` (MIPS is scale-free, homogeneous of degree 0), so `1/det A`. Taken
/// from the determinant, not from the Hessian's largest eigenvalue, so that a face's factor
/// follows its size in the map and not its anisotropy (a nearly degenerate face would
/// otherwise get the penalty of its own stiffest mode, and `m_f ‖A_f‖²` would no longer be
/// bounded by the face's energy `‖A‖²/det A`).
pub fn mips_relative_curvature(a: &[f64; 4]) -> f64 {
    1.0 / energy::det(a)
}

/// Penalty factor of a face with start Jacobian `a` and `fw = F w_f` (its area over the mean
/// face area): its penalty is `μ_f = μ · m_f` (see [`super::cpu::penalty_factors`] for why).
///
/// MIPS: `m_f = F w_f / det A_f`, the face's curvature relative to a unit face mapped
/// isometrically. SD: `m_f = 1`, the uniform penalty — the start map is conformal, and SD's
/// solution differs from it by orders of magnitude in scale where area has to move, so the
/// start's curvature would mislead (measured: SD with penalties from the LSCM start's
/// curvature, `(1 + 3/det²)/4`, locked the shrunk faces to the consensus and ran 8 of 8 sampled
/// corpus disks to the iteration cap; with area weights alone, 5 of 8 stalled).
pub fn penalty_factor(energy: Energy, a: &[f64; 4], fw: f64) -> f64 {
    match energy {
        Energy::SymmetricDirichlet => 1.0,
        Energy::Mips => {
            let m = fw * mips_relative_curvature(a);
            if m.is_finite() {
                m.clamp(PENALTY_RANGE.0, PENALTY_RANGE.1)
            } else {
                PENALTY_RANGE.1
            }
        }
    }
}

/// Dual step twin of `glsl/admm/dual_update.comp`: `Λ += μ (Y − A)`.
pub fn dual_update(lambda: &[f64; 4], y: &[f64; 4], a: &[f64; 4], mu: f64) -> [f64; 4] {
    std::array::from_fn(|i| lambda[i] + mu * (y[i] - a[i]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analytic_eigensystem_matches_jacobi_on_the_hessian() {
        for energy in [Energy::Mips, Energy::SymmetricDirichlet] {
            for a in [
                [1.0, 0.2, -0.3, 0.9],
                [2.0, 0.0, 0.0, 0.5],
                [0.7, -0.4, 0.5, 1.3],
                [1.0, 0.0, 0.0, 1.0],
            ] {
                let (_, _, h) = energy::eval(energy, &a);
                let (lam, modes) = hessian_eigensystem(energy, &a);
                // Σ λ_k m_k m_kᵀ reassembles H.
                for i in 0..4 {
                    for j in 0..4 {
                        let r: f64 = (0..4).map(|k| lam[k] * modes[k][i] * modes[k][j]).sum();
                        assert!(
                            (r - h[i][j]).abs() < 1e-9 * h[i][j].abs().max(1.0),
                            "{energy:?} {a:?} H[{i}][{j}]"
                        );
                    }
                }
                let (mut jl, _) = crate::linalg::small::sym_eigen(&h);
                let mut al = lam;
                jl.sort_by(f64::total_cmp);
                al.sort_by(f64::total_cmp);
                for k in 0..4 {
                    assert!((jl[k] - al[k]).abs() < 1e-8 * al[k].abs().max(1.0));
                }
            }
        }
    }

    #[test]
    fn mips_penalty_is_the_curvature_scale_relative_to_a_unit_face() {
        let rot = [0.6, -0.8, 0.8, 0.6];
        assert!((penalty_factor(Energy::Mips, &rot, 1.0) - 1.0).abs() < 1e-12);
        assert_eq!(penalty_factor(Energy::SymmetricDirichlet, &rot, 7.0), 1.0);
        // MIPS's Hessian scales as 1/s² under A → sA, and so does the factor.
        let s = 1e-3;
        let small = rot.map(|x| s * x);
        let (lam, _) = hessian_eigensystem(Energy::Mips, &small);
        let (lam1, _) = hessian_eigensystem(Energy::Mips, &rot);
        assert!((lam[1] * s * s - lam1[1]).abs() < 1e-6 * lam1[1]);
        let k = penalty_factor(Energy::Mips, &small, 2.0);
        assert!((k * s * s - 2.0).abs() < 1e-9, "{k}");
        // Bounded for f32.
        assert_eq!(
            penalty_factor(Energy::Mips, &rot.map(|x| 1e-20 * x), 1.0),
            PENALTY_RANGE.1
        );
    }

    #[test]
    fn svd2_reconstructs() {
        for a in [
            [1.0, 0.2, -0.3, 0.9],
            [0.0, -1.0, 1.0, 0.0],
            [3.0, 1.0, 1.0, -2.0],
        ] {
            let [cu, su, s1, s2, cv, sv] = svd2(&a);
            assert!(
                (cu * cu + su * su - 1.0).abs() < 1e-12 && (cv * cv + sv * sv - 1.0).abs() < 1e-12
            );
            let r = rotate([cu, su], [s1, 0.0, 0.0, s2], [cv, sv]);
            for i in 0..4 {
                assert!((r[i] - a[i]).abs() < 1e-12);
            }
            assert!(s1 >= s2.abs());
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
            30.0,
        );
        let m1 = [y1[0] * e1[0] + y1[1] * e1[1], y1[2] * e1[0] + y1[3] * e1[1]];
        let m2 = [y2[0] * e2[0] + y2[1] * e2[1], y2[2] * e2[0] + y2[3] * e2[1]];
        assert!((m1[0] - m2[0]).abs() < 1e-14 && (m1[1] - m2[1]).abs() < 1e-14);
    }

    #[test]
    fn edge_projection_with_unequal_edge_lengths_is_the_weighted_projection() {
        // A chart face (unit ê) against a scaffold face whose rest edge is 2.5× longer.
        let (e1, e2) = ([0.6, 0.8], [-2.0, 1.5]);
        let (q1, q2) = ([1.0, 0.2, 0.3, 0.9], [0.5, -0.1, 0.4, 1.2]);
        let (mu1, mu2) = (10.0, 0.3);
        let (y1, y2) = edge_project(&q1, &q2, &[0.0; 4], &[0.0; 4], &e1, &e2, mu1, mu2);
        let m1 = [y1[0] * e1[0] + y1[1] * e1[1], y1[2] * e1[0] + y1[3] * e1[1]];
        let m2 = [y2[0] * e2[0] + y2[1] * e2[1], y2[2] * e2[0] + y2[3] * e2[1]];
        assert!((m1[0] - m2[0]).abs() < 1e-14 && (m1[1] - m2[1]).abs() < 1e-14);
        // Optimality: no feasible direction lowers μ1‖Y1 − Q1‖² + μ2‖Y2 − Q2‖². Feasible
        // directions (D1, D2) have D1 e1 = D2 e2; the objective's gradient must be orthogonal
        // to them, i.e. μ1 (Y1 − Q1) = −λ e1ᵀ and μ2 (Y2 − Q2) = λ e2ᵀ for one λ.
        let g1: [f64; 4] = std::array::from_fn(|i| mu1 * (y1[i] - q1[i]));
        let g2: [f64; 4] = std::array::from_fn(|i| mu2 * (y2[i] - q2[i]));
        let lam = [-g1[0] / e1[0], -g1[2] / e1[0]];
        for (g, e, s) in [(g1, e1, -1.0), (g2, e2, 1.0)] {
            let want = [
                s * lam[0] * e[0],
                s * lam[0] * e[1],
                s * lam[1] * e[0],
                s * lam[1] * e[1],
            ];
            for i in 0..4 {
                assert!((g[i] - want[i]).abs() < 1e-12, "{g:?} vs {want:?}");
            }
        }
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
