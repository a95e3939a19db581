//! The 3D symmetric Dirichlet energy D(M) = ‖M‖²_F + ‖M⁻¹‖²_F of a 3x3 Jacobian, its gradient,
//! and its Hessian projected onto the PSD cone in closed form.
//!
//! Projection: the Hessian of an isotropic energy Ψ(σ₁, σ₂, σ₃) has a known eigensystem
//! (Smith, de Goes & Kim, "Analytic eigensystems for isotropic distortion energies", TOG 2019):
//! three scaling modes U·diag(e)·Vᵀ with the eigenvalues of ∂²Ψ/∂σ² (diagonal for this
//! separable Ψ: 2 + 6/σᵢ⁴), and for every pair i < j a twist mode U(eᵢeⱼᵀ − eⱼeᵢᵀ)Vᵀ/√2 with
//! eigenvalue (Ψᵢ + Ψⱼ)/(σᵢ + σⱼ) and a flip mode U(eᵢeⱼᵀ + eⱼeᵢᵀ)Vᵀ/√2 with eigenvalue
//! (Ψᵢ − Ψⱼ)/(σᵢ − σⱼ), Ψᵢ = ∂Ψ/∂σᵢ = 2σᵢ − 2σᵢ⁻³. Both pair eigenvalues simplify to forms
//! without the division by σᵢ − σⱼ (so repeated singular values are harmless); only the twist
//! one can be negative, and clamping it at 0 is the exact projection — no 9x9 eigen-solve per
//! tet.

use crate::linalg::small::sym_eigen;

/// Row-major 3x3 matrix: `m[row][col]`.
pub type Mat3 = [[f64; 3]; 3];

pub fn det3(m: &Mat3) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// Inverse, or `None` when the determinant is zero or not finite.
pub fn inv3(m: &Mat3) -> Option<Mat3> {
    let d = det3(m);
    if d == 0.0 || !d.is_finite() {
        return None;
    }
    let c =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adj = [
        [c(1, 2, 1, 2), -c(0, 2, 1, 2), c(0, 1, 1, 2)],
        [-c(1, 2, 0, 2), c(0, 2, 0, 2), -c(0, 1, 0, 2)],
        [c(1, 2, 0, 1), -c(0, 2, 0, 1), c(0, 1, 0, 1)],
    ];
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = adj[i][j] / d;
        }
    }
    Some(out)
}

pub fn mul3(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut o = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            o[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    o
}

pub fn transpose3(a: &Mat3) -> Mat3 {
    let mut o = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            o[i][j] = a[j][i];
        }
    }
    o
}

pub fn frob2(a: &Mat3) -> f64 {
    a.iter().flatten().map(|x| x * x).sum()
}

pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// D(M), +∞ when det M ≤ 0 (the barrier that keeps every tet positive).
pub fn sym_dirichlet(m: &Mat3) -> f64 {
    if !super::tet::is_positive(det3(m)) {
        return f64::INFINITY;
    }
    match inv3(m) {
        Some(n) => frob2(m) + frob2(&n),
        None => f64::INFINITY,
    }
}

/// D(M) and ∂D/∂M = 2M − 2M⁻ᵀM⁻¹M⁻ᵀ; `None` when det M ≤ 0.
pub fn sym_dirichlet_grad(m: &Mat3) -> Option<(f64, Mat3)> {
    if !super::tet::is_positive(det3(m)) {
        return None;
    }
    let n = inv3(m)?;
    let nt = transpose3(&n);
    let t = mul3(&mul3(&nt, &n), &nt);
    let mut g = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            g[i][j] = 2.0 * m[i][j] - 2.0 * t[i][j];
        }
    }
    Some((frob2(m) + frob2(&n), g))
}

/// The nine eigenpairs (λ, Q) of ∂²D/∂M², Q a unit 3x3 matrix; eigenvalues unclamped.
/// Requires det M > 0.
pub fn sym_dirichlet_eigensystem(m: &Mat3) -> [(f64, Mat3); 9] {
    // V and σ² from MᵀM (Jacobi is accurate for the small eigenvalues), σᵢ = ‖M vᵢ‖ and
    // uᵢ = M vᵢ/σᵢ re-orthogonalised (Gram–Schmidt from the largest σ), σ₃ from det M so that
    // its relative accuracy does not depend on the conditioning.
    let mtm = mul3(&transpose3(m), m);
    let (_, v) = sym_eigen::<3>(&mtm);
    let col = |k: usize| [v[0][k], v[1][k], v[2][k]];
    let mut u = [[0.0f64; 3]; 3]; // u[k] = k-th left singular vector
    let mut s = [0.0f64; 3];
    for k in 0..3 {
        let vk = col(k);
        let mut w = [0.0; 3];
        for r in 0..3 {
            w[r] = m[r][0] * vk[0] + m[r][1] * vk[1] + m[r][2] * vk[2];
        }
        s[k] = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        for prev in 0..k {
            let d = w[0] * u[prev][0] + w[1] * u[prev][1] + w[2] * u[prev][2];
            for r in 0..3 {
                w[r] -= d * u[prev][r];
            }
        }
        let n = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        if n > 0.0 {
            for r in 0..3 {
                u[k][r] = w[r] / n;
            }
        }
    }
    // A zero-length Gram–Schmidt residue (σ₃ underflow) would leave u₃ = 0: complete the frame.
    if u[2].iter().all(|&x| x == 0.0) {
        u[2] = super::tet::cross(u[0], u[1]);
    }
    // Sign of u₃ relative to M v₃: det M = σ₁σ₂σ₃·det U·det V.
    let det_u = super::tet::dot(u[0], super::tet::cross(u[1], u[2]));
    let det_v = det3(&v);
    s[2] = det3(m) / (s[0] * s[1] * det_u * det_v);
    let outer = |a: [f64; 3], b: [f64; 3]| -> Mat3 {
        let mut o = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                o[i][j] = a[i] * b[j];
            }
        }
        o
    };
    let mut out = [(0.0, [[0.0; 3]; 3]); 9];
    for k in 0..3 {
        out[k] = (2.0 + 6.0 / s[k].powi(4), outer(u[k], col(k)));
    }
    let r = std::f64::consts::FRAC_1_SQRT_2;
    let mut idx = 3;
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        let (a, b) = (s[i], s[j]);
        let p = (a * b).powi(3);
        let twist = 2.0 - 2.0 * (a * a - a * b + b * b) / p;
        let flip = 2.0 + 2.0 * (a * a + a * b + b * b) / p;
        let uivj = outer(u[i], col(j));
        let ujvi = outer(u[j], col(i));
        let mut qt = [[0.0; 3]; 3];
        let mut qf = [[0.0; 3]; 3];
        for x in 0..3 {
            for y in 0..3 {
                qt[x][y] = r * (uivj[x][y] - ujvi[x][y]);
                qf[x][y] = r * (uivj[x][y] + ujvi[x][y]);
            }
        }
        out[idx] = (twist, qt);
        out[idx + 1] = (flip, qf);
        idx += 2;
    }
    out
}

/// The rotation closest to `c` in the Frobenius norm (U·diag(1, 1, det UVᵀ)·Vᵀ from the SVD
/// c = UΣVᵀ), or `None` for a rank-deficient or non-finite `c`.
pub fn closest_rotation(c: &Mat3) -> Option<Mat3> {
    let ctc = mul3(&transpose3(c), c);
    let (l, v) = sym_eigen::<3>(&ctc);
    if !super::tet::is_positive(l[1] - 1e-24 * l[0].max(f64::MIN_POSITIVE)) || !l[0].is_finite() {
        return None;
    }
    let col = |k: usize| [v[0][k], v[1][k], v[2][k]];
    let mut u = [[0.0f64; 3]; 3];
    for k in 0..2 {
        let vk = col(k);
        let mut w = [0.0; 3];
        for r in 0..3 {
            w[r] = c[r][0] * vk[0] + c[r][1] * vk[1] + c[r][2] * vk[2];
        }
        for prev in 0..k {
            let d = super::tet::dot(w, u[prev]);
            for r in 0..3 {
                w[r] -= d * u[prev][r];
            }
        }
        let n = super::tet::dot(w, w).sqrt();
        for r in 0..3 {
            u[k][r] = w[r] / n;
        }
    }
    // u₃ = ±u₁×u₂, v₃ = ±v₁×v₂: choosing both as cross products makes U, V rotations and
    // U·Vᵀ the closest rotation (the reflection-free Kabsch solution).
    u[2] = super::tet::cross(u[0], u[1]);
    let v3 = super::tet::cross(col(0), col(1));
    let vv = [col(0), col(1), v3];
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = (0..3).map(|k| u[k][i] * vv[k][j]).sum();
        }
    }
    Some(r)
}

/// ∂²D/∂M² projected onto the PSD cone, as a 9x9 matrix over vec(M) (index 3·row + col).
pub fn sym_dirichlet_hessian_psd(m: &Mat3) -> [[f64; 9]; 9] {
    let mut h = [[0.0; 9]; 9];
    for (l, q) in sym_dirichlet_eigensystem(m) {
        let l = l.max(0.0);
        if l == 0.0 {
            continue;
        }
        let q: Vec<f64> = q.iter().flatten().copied().collect();
        for a in 0..9 {
            for b in 0..9 {
                h[a][b] += l * q[a] * q[b];
            }
        }
    }
    h
}

/// The exact (unprojected) ∂²D/∂M², derived directly from d(M⁻¹) = −M⁻¹ dM M⁻¹ — an
/// independent route used to check the eigensystem.
pub fn sym_dirichlet_hessian_exact(m: &Mat3) -> Option<[[f64; 9]; 9]> {
    let n = inv3(m)?;
    let nt = transpose3(&n);
    let mut h = [[0.0; 9]; 9];
    for k in 0..9 {
        let mut dm = [[0.0; 3]; 3];
        dm[k / 3][k % 3] = 1.0;
        // dN = −N dM N; dG = 2 dM − 2 (dNᵀ N Nᵀ + Nᵀ dN Nᵀ + Nᵀ N dNᵀ).
        let dn = mul3(&mul3(&n, &dm), &n);
        let dn = dn.map(|r| r.map(|x| -x));
        let dnt = transpose3(&dn);
        let t1 = mul3(&mul3(&dnt, &n), &nt);
        let t2 = mul3(&mul3(&nt, &dn), &nt);
        let t3 = mul3(&mul3(&nt, &n), &dnt);
        for a in 0..9 {
            let (i, j) = (a / 3, a % 3);
            h[a][k] = 2.0 * dm[i][j] - 2.0 * (t1[i][j] + t2[i][j] + t3[i][j]);
        }
    }
    Some(h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::rng::SplitMix;
    use crate::linalg::small::project_psd;

    fn random_positive(seed: &mut SplitMix) -> Mat3 {
        loop {
            let mut m = [[0.0; 3]; 3];
            for r in 0..3 {
                for c in 0..3 {
                    m[r][c] = seed.symmetric() * 1.5 + if r == c { 0.3 } else { 0.0 };
                }
            }
            if det3(&m) > 0.05 {
                return m;
            }
        }
    }

    #[test]
    fn gradient_and_hessian_match_finite_differences() {
        let mut seed = SplitMix(7);
        for _ in 0..20 {
            let m = random_positive(&mut seed);
            let (e, g) = sym_dirichlet_grad(&m).unwrap();
            assert!((e - sym_dirichlet(&m)).abs() < 1e-12 * e);
            let h = sym_dirichlet_hessian_exact(&m).unwrap();
            let eps = 1e-6;
            for k in 0..9 {
                let mut mp = m;
                let mut mm = m;
                mp[k / 3][k % 3] += eps;
                mm[k / 3][k % 3] -= eps;
                let fd = (sym_dirichlet(&mp) - sym_dirichlet(&mm)) / (2.0 * eps);
                assert!((fd - g[k / 3][k % 3]).abs() < 1e-5 * (1.0 + e), "grad {k}");
                let gp = sym_dirichlet_grad(&mp).unwrap().1;
                let gm = sym_dirichlet_grad(&mm).unwrap().1;
                for a in 0..9 {
                    let fdh = (gp[a / 3][a % 3] - gm[a / 3][a % 3]) / (2.0 * eps);
                    assert!(
                        (fdh - h[a][k]).abs() < 1e-4 * (1.0 + h[a][k].abs()),
                        "hess {a} {k}"
                    );
                }
            }
        }
    }

    #[test]
    fn analytic_projection_matches_numeric_projection() {
        let mut seed = SplitMix(11);
        for _ in 0..200 {
            let m = random_positive(&mut seed);
            let exact = sym_dirichlet_hessian_exact(&m).unwrap();
            // Unclamped eigensystem reproduces the exact Hessian.
            let mut full = [[0.0; 9]; 9];
            for (l, q) in sym_dirichlet_eigensystem(&m) {
                let q: Vec<f64> = q.iter().flatten().copied().collect();
                for a in 0..9 {
                    for b in 0..9 {
                        full[a][b] += l * q[a] * q[b];
                    }
                }
            }
            let scale = exact.iter().flatten().map(|x| x.abs()).fold(0.0, f64::max);
            let numeric = project_psd::<9>(&exact, 0.0);
            let analytic = sym_dirichlet_hessian_psd(&m);
            for a in 0..9 {
                for b in 0..9 {
                    assert!(
                        (full[a][b] - exact[a][b]).abs() < 1e-8 * scale,
                        "full {a} {b}"
                    );
                    assert!(
                        (numeric[a][b] - analytic[a][b]).abs() < 1e-8 * scale,
                        "psd {a} {b}"
                    );
                }
            }
        }
    }
}
