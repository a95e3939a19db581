//! Closed-form small dense linear algebra in f64: 2x2 determinant, inverse and signed SVD,
//! symmetric 2x2 eigenvalues, and a cyclic Jacobi eigensolver for small symmetric matrices
//! (used for the PSD projection of per-face Hessians).
//!
//! Everything here is branch-light and allocation-free on purpose: the same formulas are
//! mirrored in GLSL (`glsl/common/mat2.glsl`), and the CPU twin must compute the same numbers.
//! Matrices are row-major `[[row0], [row1], ...]`.
#![forbid(unsafe_code)]

/// A 2x2 matrix, row-major: `m[row][col]`.
pub type Mat2 = [[f64; 2]; 2];

/// det [[a, b], [c, d]] = ad − bc.
#[inline]
pub fn det2(m: &Mat2) -> f64 {
    m[0][0] * m[1][1] - m[0][1] * m[1][0]
}

/// Inverse of a 2x2 matrix, `None` when the determinant is zero or the result is not finite.
#[inline]
pub fn inv2(m: &Mat2) -> Option<Mat2> {
    let det = det2(m);
    if det == 0.0 {
        return None;
    }
    let r = 1.0 / det;
    // [[a, b], [c, d]]⁻¹ = [[d, −b], [−c, a]] / det
    let inv = [[m[1][1] * r, -m[0][1] * r], [-m[1][0] * r, m[0][0] * r]];
    inv.iter().flatten().all(|x| x.is_finite()).then_some(inv)
}

/// Product of two 2x2 matrices.
#[inline]
pub fn mul2(a: &Mat2, b: &Mat2) -> Mat2 {
    [
        [
            a[0][0] * b[0][0] + a[0][1] * b[1][0],
            a[0][0] * b[0][1] + a[0][1] * b[1][1],
        ],
        [
            a[1][0] * b[0][0] + a[1][1] * b[1][0],
            a[1][0] * b[0][1] + a[1][1] * b[1][1],
        ],
    ]
}

/// Similarity / anti-similarity split of a 2x2 matrix `[[a, b], [c, d]]`:
/// E = (a+d)/2, F = (a−d)/2, G = (c+b)/2, H = (c−b)/2, so that
/// M = [[E, −H], [H, E]] + [[F, G], [G, −F]] (conformal part + anti-conformal part).
#[inline]
fn efgh(m: &Mat2) -> [f64; 4] {
    [
        0.5 * (m[0][0] + m[1][1]),
        0.5 * (m[0][0] - m[1][1]),
        0.5 * (m[1][0] + m[0][1]),
        0.5 * (m[1][0] - m[0][1]),
    ]
}

/// Signed singular values `[σ1, σ2]` of a 2x2 matrix, with σ1 ≥ |σ2| ≥ 0 and σ2 < 0 exactly
/// when det < 0 (an orientation-reversing map), so σ1·σ2 = det.
///
/// Closed form: σ1 = Q + R, σ2 = Q − R with Q = |conformal part| = √(E²+H²),
/// R = |anti-conformal part| = √(F²+G²) (E, F, G, H as in `efgh`); no iteration, no square root of a
/// difference, so it is accurate near σ1 = σ2.
#[inline]
pub fn svd2_signed_values(m: &Mat2) -> [f64; 2] {
    let [e, f, g, h] = efgh(m);
    let q = e.hypot(h);
    let r = f.hypot(g);
    [q + r, q - r]
}

/// `(cos x, sin x)` of half the angle whose cosine and sine are `(c, s)` (unit vector), taking
/// the half angle in (−π/2, π/2]; each branch divides by the larger of the two results.
pub fn half_angle(c: f64, s: f64) -> [f64; 2] {
    if c >= 0.0 {
        let ch = (0.5 * (1.0 + c)).sqrt();
        [ch, s / (2.0 * ch)]
    } else {
        let sh = (0.5 * (1.0 - c)).sqrt();
        // s/(2 sh) is cos(x/2); its sign follows s, so flip both to keep cos ≥ 0.
        let ch = s / (2.0 * sh);
        if ch >= 0.0 {
            [ch, sh]
        } else {
            [-ch, -sh]
        }
    }
}

/// The crate's signed SVD of a 2x2 `A = U diag(σ1, σ2) Vᵀ` with rotations `U = rot(φ)`, `Vᵀ = rot(θ)`,
/// σ1 ≥ |σ2| (σ2 < 0 iff det A < 0). Returned as `(cos φ, sin φ, σ1, σ2, cos θ, sin θ)`.
///
/// With E, F, G, H the conformal / anti-conformal parts, `a1 = ∠(F, G)`, `a2 = ∠(E, H)`:
/// `φ = (a1 + a2)/2`, `θ = φ − a1`. Computed without trigonometric calls (half-angle of the
/// sum, then a rotation), which were 30% of the face step; the GLSL twin in
/// `glsl/common/admm.glsl` does the same. Input and rotations are row-major `[a00, a01, a10, a11]`.
pub fn svd2(a: &[f64; 4]) -> [f64; 6] {
    let [e, f, g, h] = efgh(&[[a[0], a[1]], [a[2], a[3]]]);
    let q = (e * e + h * h).sqrt();
    let r = (f * f + g * g).sqrt();
    // Unit vectors of a1 and a2; an arbitrary angle (0) where the part vanishes.
    let (c1, s1) = if r > 0.0 { (f / r, g / r) } else { (1.0, 0.0) };
    let (c2, s2) = if q > 0.0 { (e / q, h / q) } else { (1.0, 0.0) };
    let [cp, sp] = half_angle(c1 * c2 - s1 * s2, s1 * c2 + c1 * s2);
    // θ = φ − a1.
    let ct = cp * c1 + sp * s1;
    let st = sp * c1 - cp * s1;
    [cp, sp, q + r, q - r, ct, st]
}

/// A signed SVD of a 2x2 matrix: `M = U · diag(σ1, σ2) · Vᵀ` with `U`, `V` rotations
/// (det = +1) and σ2 carrying the sign of det M.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Svd2 {
    pub u: Mat2,
    pub sigma: [f64; 2],
    pub v: Mat2,
}

/// [`svd2`] with the factors as matrices.
pub fn svd2_signed(m: &Mat2) -> Svd2 {
    let [cu, su, s1, s2, ct, st] = svd2(&[m[0][0], m[0][1], m[1][0], m[1][1]]);
    // Vᵀ = rot(θ), so V = rot(−θ).
    Svd2 {
        u: [[cu, -su], [su, cu]],
        sigma: [s1, s2],
        v: [[ct, st], [-st, ct]],
    }
}

/// Eigenvalues `[λmax, λmin]` of the symmetric 2x2 matrix [[a, b], [b, c]]:
/// λ = (a+c)/2 ± √(((a−c)/2)² + b²).
#[inline]
pub fn sym2_eigenvalues(a: f64, b: f64, c: f64) -> [f64; 2] {
    let mean = 0.5 * (a + c);
    let rad = (0.5 * (a - c)).hypot(b);
    [mean + rad, mean - rad]
}

/// Eigen-decomposition of a small symmetric matrix by cyclic Jacobi rotations.
///
/// Returns `(λ, V)` with `A = V·diag(λ)·Vᵀ`, eigenvectors in the *columns* of `V`, and λ
/// sorted in decreasing order. Only the symmetric part of `m` is used (the upper triangle is
/// trusted). Converges quadratically; 4x4 Hessians take 3–5 sweeps. Jacobi is chosen over
/// QR because it is accurate for small eigenvalues (what a PSD projection clamps) and is a
/// fixed, simple loop that maps one-to-one to a shader.
pub fn sym_eigen<const N: usize>(m: &[[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
    let mut a = *m;
    // Symmetrise from the upper triangle so the iteration sees an exactly symmetric matrix.
    for i in 0..N {
        for j in 0..i {
            a[i][j] = a[j][i];
        }
    }
    let mut v = [[0.0; N]; N];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let frob: f64 = a.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
    if frob == 0.0 || !frob.is_finite() {
        let mut lambda = [0.0; N];
        for i in 0..N {
            lambda[i] = a[i][i];
        }
        return (lambda, v);
    }
    for _sweep in 0..64 {
        let off: f64 = (0..N)
            .flat_map(|i| (0..N).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum::<f64>();
        if off.sqrt() <= 1e-17 * frob {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                let apq = a[p][q];
                if apq == 0.0 {
                    continue;
                }
                // Rotation angle zeroing a_pq: θ = (a_qq − a_pp)/(2 a_pq), t = tan of the angle
                // (the smaller root of t² + 2θt − 1 = 0), c = cos, s = sin.
                let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
                let t = if theta.abs() > 1e150 {
                    0.5 / theta
                } else {
                    theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
                };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                // A ← A·J (columns p, q), then A ← Jᵀ·A (rows p, q); V ← V·J.
                for k in 0..N {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..N {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                a[p][q] = 0.0;
                a[q][p] = 0.0;
                for row in v.iter_mut() {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    // Sort eigenpairs by decreasing eigenvalue (selection sort: N is tiny).
    let mut lambda = [0.0; N];
    for i in 0..N {
        lambda[i] = a[i][i];
    }
    for i in 0..N {
        let mut best = i;
        for j in i + 1..N {
            if lambda[j] > lambda[best] {
                best = j;
            }
        }
        if best != i {
            lambda.swap(i, best);
            for row in v.iter_mut() {
                row.swap(i, best);
            }
        }
    }
    (lambda, v)
}

/// Projection of a symmetric matrix onto the positive semi-definite cone (in the Frobenius
/// norm), with eigenvalues clamped to at least `floor` (use 0 for the plain projection, a
/// small positive value to keep a Newton system strictly positive definite):
/// A⁺ = V·diag(max(λ, floor))·Vᵀ.
pub fn project_psd<const N: usize>(m: &[[f64; N]; N], floor: f64) -> [[f64; N]; N] {
    let (lambda, v) = sym_eigen(m);
    if lambda.iter().all(|&l| l >= floor) {
        // Already PSD: return the (symmetrised) input untouched, without round-off.
        let mut out = *m;
        for i in 0..N {
            for j in 0..i {
                out[i][j] = out[j][i];
            }
        }
        return out;
    }
    let mut out = [[0.0; N]; N];
    for k in 0..N {
        let l = lambda[k].max(floor);
        for i in 0..N {
            let vik = v[i][k] * l;
            for j in 0..N {
                out[i][j] += vik * v[j][k];
            }
        }
    }
    out
}
