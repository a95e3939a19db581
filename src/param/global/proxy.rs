//! The proxy phase: SLIM's reweighted local/global step (Rabinovich, Poranne, Panozzo &
//! Sorkine-Hornung 2017) as a search direction.
//!
//! Per face, with `A = U diag(σ) Vᵀ`, the proxy is `w_f ‖W (A − T)‖²`, `W = U diag(ω) Uᵀ`.
//! The weights are chosen so that the proxy's gradient at the current map *equals* the true
//! energy gradient (`2 ω_i² (σ_i − t_i) = ∂E/∂σ_i`); the step then needs no target `T` at all:
//! it is `d = −K⁻¹ ∇E` with `K = Σ_f Bᵀ (2 w_f S ⊗ I) B`, `S = U diag(ω²) Uᵀ`, a
//! reweighted-Laplacian-preconditioned gradient step. `K` is positive definite on every
//! direction but translations, whatever the distortion, which is why this phase is robust far
//! from the optimum where the Newton model is poor.
//!
//! - symmetric Dirichlet, target σ = 1: `ω² = (σ − σ⁻³)/(σ − 1) = (1 + σ)(1 + σ²)/σ³`
//!   (the removable singularity at σ = 1 cancelled in closed form);
//! - MIPS, target the closest similarity `m = (σ1 + σ2)/2` (MIPS has no preferred scale):
//!   `ω1² = (σ1 + σ2)/(σ1² σ2)`, `ω2² = (σ1 + σ2)/(σ1 σ2²)`.

use crate::linalg::small::svd2;
use crate::param::energy::Energy;

/// Squared proxy weights `[ω1², ω2²]` for singular values σ1 ≥ σ2 > 0.
pub fn proxy_weights(energy: Energy, s1: f64, s2: f64) -> [f64; 2] {
    match energy {
        Energy::SymmetricDirichlet => {
            let w = |s: f64| (1.0 + s) * (1.0 + s * s) / (s * s * s);
            [w(s1), w(s2)]
        }
        Energy::Mips => {
            let sum = s1 + s2;
            [sum / (s1 * s1 * s2), sum / (s1 * s2 * s2)]
        }
    }
}

/// The proxy's 4x4 Hessian in Jacobian space (row-major `[a, b, c, d]`), weighted by `w`:
/// `2 w (S ⊗ I)`, i.e. entry `((r, c), (s, c'))` is `2 w S[r][s] δ_cc'`. Only for det A > 0.
pub fn proxy_matrix(energy: Energy, a: &[f64; 4], w: f64) -> [[f64; 4]; 4] {
    let [cu, su, s1, s2, _, _] = svd2(a);
    let [o1, o2] = proxy_weights(energy, s1, s2);
    // S = U diag(o1, o2) Uᵀ with U = [[cu, −su], [su, cu]].
    let s00 = o1 * cu * cu + o2 * su * su;
    let s11 = o1 * su * su + o2 * cu * cu;
    let s01 = (o1 - o2) * cu * su;
    let s = [[s00, s01], [s01, s11]];
    let mut m = [[0.0; 4]; 4];
    for r in 0..2 {
        for t in 0..2 {
            for c in 0..2 {
                m[2 * r + c][2 * t + c] = 2.0 * w * s[r][t];
            }
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::param::energy;

    /// The proxy's gradient `2 S (A − T)` equals the energy gradient, T the target of the
    /// module docs.
    #[test]
    fn proxy_gradient_matches_energy_gradient() {
        for en in [Energy::SymmetricDirichlet, Energy::Mips] {
            for a in [
                [1.3, 0.2, -0.4, 0.7],
                [0.5, 0.0, 0.0, 2.0],
                [1.0, 0.0, 0.0, 1.0],
            ] {
                let [cu, su, s1, s2, cv, sv] = svd2(&a);
                let t_sigma = match en {
                    Energy::SymmetricDirichlet => [1.0, 1.0],
                    Energy::Mips => [0.5 * (s1 + s2); 2],
                };
                // A − T = U diag(σ − t) Vᵀ.
                let u = [[cu, -su], [su, cu]];
                let vt = [[cv, -sv], [sv, cv]];
                let dsig = [s1 - t_sigma[0], s2 - t_sigma[1]];
                let mut diff = [0.0; 4];
                for r in 0..2 {
                    for c in 0..2 {
                        diff[2 * r + c] = (0..2).map(|k| u[r][k] * dsig[k] * vt[k][c]).sum();
                    }
                }
                let m = proxy_matrix(en, &a, 1.0);
                let (_, g, _) = energy::eval(en, &a);
                for i in 0..4 {
                    let pg: f64 = (0..4).map(|j| m[i][j] * diff[j]).sum();
                    assert!(
                        (pg - g[i]).abs() < 1e-10 * g[i].abs().max(1.0),
                        "{en:?} {a:?} {i}"
                    );
                }
            }
        }
    }
}
