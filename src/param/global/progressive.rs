//! Progressive reference meshes (Liu, Ye, Wang, Bao & Zhou 2018, "Progressive
//! parameterizations").
//!
//! Far from the optimum (a Tutte start) a few faces have enormous distortion; they dominate
//! both the energy and its Hessian and throttle every step. Instead of the rest triangle each
//! such face gets an intermediate reference `P_f` between the current UV triangle and the rest
//! one: with `A = U diag(σ) Vᵀ`, `P = V diag(σ^{1−β}) Vᵀ`, so the map relative to it,
//! `A P⁻¹ = U diag(σ^β) Vᵀ`, has its distortion capped at a bound (β ∈ (0, 1] per face, by
//! bisection). Faces under the bound keep the rest reference (β = 1). The reference is rebuilt
//! every iteration; once no face is over the bound the solver switches to the true reference
//! for good. `det P > 0`, so a map is flip-free w.r.t. `P` exactly when it is w.r.t. the rest.

use super::assembly::FaceGradient;
use crate::linalg::small::svd2;
use crate::param::energy::{self, Energy};

/// Bisection steps for β (β to 2⁻³⁰).
const BISECTIONS: usize = 30;

/// Energy of the singular values `(s1, s2)` (a diagonal Jacobian).
fn energy_of(en: Energy, s1: f64, s2: f64) -> f64 {
    energy::value(en, &[s1, 0.0, 0.0, s2])
}

/// The gradient operator of face `g` relative to its intermediate reference, and whether the
/// face was capped (false: the rest reference, `g` itself). `a` is the face's true Jacobian
/// (det > 0), `cap` the bound on the face energy.
pub fn capped_gradient(
    en: Energy,
    g: &FaceGradient,
    a: &[f64; 4],
    cap: f64,
) -> (FaceGradient, bool) {
    if energy::value(en, a) <= cap {
        return (*g, false);
    }
    let [_, _, s1, s2, cv, sv] = svd2(a);
    if s2.is_nan() || s2 <= 0.0 {
        return (*g, false);
    }
    // Largest β with E(σ^β) ≤ cap; E(σ^0) = E(1, 1) = the minimum < cap.
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for _ in 0..BISECTIONS {
        let mid = 0.5 * (lo + hi);
        if energy_of(en, s1.powf(mid), s2.powf(mid)) <= cap {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let beta = lo;
    // P⁻¹ = V diag(σ^{β−1}) Vᵀ; Vᵀ = [[cv, −sv], [sv, cv]] so V = [[cv, sv], [−sv, cv]].
    let (p1, p2) = (s1.powf(beta - 1.0), s2.powf(beta - 1.0));
    let v = [[cv, sv], [-sv, cv]];
    let mut pinv = [[0.0; 2]; 2];
    for i in 0..2 {
        for j in 0..2 {
            pinv[i][j] = v[i][0] * p1 * v[j][0] + v[i][1] * p2 * v[j][1];
        }
    }
    // A' = [u; v] G P⁻¹: new rows g_k P⁻¹.
    let mut out = [[0.0; 2]; 3];
    for k in 0..3 {
        for c in 0..2 {
            out[k][c] = g[k][0] * pinv[0][c] + g[k][1] * pinv[1][c];
        }
    }
    (out, true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::param::global::assembly::jacobian;

    #[test]
    fn capped_face_sits_on_the_bound() {
        let en = Energy::SymmetricDirichlet;
        let g: FaceGradient = [[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]];
        // corners (0,0), (6,1), (0.5, 0.3): a long, thin, sheared triangle.
        let x = [0.0, 0.0, 6.0, 1.0, 0.5, 0.3];
        let f = [0u32, 1, 2];
        let a = jacobian(&g, &f, &x);
        assert!(energy::value(en, &a) > 20.0);
        let (gc, capped) = capped_gradient(en, &g, &a, 20.0);
        assert!(capped);
        let ac = jacobian(&gc, &f, &x);
        assert!((energy::value(en, &ac) - 20.0).abs() < 1e-6);
        // Under the bound nothing changes.
        let (g2, c2) = capped_gradient(en, &g, &a, 1e9);
        assert!(!c2 && g2 == g);
    }
}
