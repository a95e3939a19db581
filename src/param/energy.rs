//! Per-face distortion energies of a 2x2 Jacobian `A = [a b; c d]`, stored row-major as
//! `[a, b, c, d]`: value, gradient and Hessian in closed form, f64.
//!
//! Both energies are rotation-invariant and +∞ for `det A <= 0`, which is what makes every
//! line search that only accepts finite values flip-proof. The GLSL twin is
//! `glsl/common/admm.glsl`; keep the formulas in step.

/// Which distortion the solver minimises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum Energy {
    /// MIPS `tr(AᵀA)/det A = σ1/σ2 + σ2/σ1`: conformal (angle-preserving), scale-free.
    Mips,
    /// Symmetric Dirichlet `‖A‖² + ‖A⁻¹‖² = σ1² + σ1⁻² + σ2² + σ2⁻²`: isometric.
    #[cfg_attr(feature = "cli", value(name = "sd"))]
    SymmetricDirichlet,
}

impl Energy {
    /// The name the CLI and the report use: `mips` or `sd`.
    pub fn name(self) -> &'static str {
        match self {
            Energy::Mips => "mips",
            Energy::SymmetricDirichlet => "sd",
        }
    }

    /// Value of the energy at its global minimum (a rotation): MIPS 2, SD 4.
    pub fn minimum(self) -> f64 {
        match self {
            Energy::Mips => 2.0,
            Energy::SymmetricDirichlet => 4.0,
        }
    }

    /// Shader-side code (push constant).
    pub fn code(self) -> u32 {
        match self {
            Energy::Mips => 0,
            Energy::SymmetricDirichlet => 1,
        }
    }
}

/// `det A`.
#[inline]
pub fn det(a: &[f64; 4]) -> f64 {
    a[0] * a[3] - a[1] * a[2]
}

/// `∂ det A / ∂A` = (d, −c, −b, a).
#[inline]
fn grad_det(a: &[f64; 4]) -> [f64; 4] {
    [a[3], -a[2], -a[1], a[0]]
}

/// Energy value; +∞ when `det A <= 0`.
pub fn value(energy: Energy, a: &[f64; 4]) -> f64 {
    let d = det(a);
    if d <= 0.0 || !d.is_finite() {
        return f64::INFINITY;
    }
    let s = a.iter().map(|x| x * x).sum::<f64>();
    match energy {
        Energy::Mips => s / d,
        Energy::SymmetricDirichlet => s + s / (d * d),
    }
}

/// Value, gradient and Hessian (4x4, row-major over `[a, b, c, d]`); only for `det A > 0`.
pub fn eval(energy: Energy, a: &[f64; 4]) -> (f64, [f64; 4], [[f64; 4]; 4]) {
    let d = det(a);
    let s = a.iter().map(|x| x * x).sum::<f64>();
    let gd = grad_det(a);
    // Hessian of det: ∂²D/∂a∂d = 1, ∂²D/∂b∂c = −1.
    let hd = |i: usize, j: usize| -> f64 {
        match (i, j) {
            (0, 3) | (3, 0) => 1.0,
            (1, 2) | (2, 1) => -1.0,
            _ => 0.0,
        }
    };
    let mut g = [0.0; 4];
    let mut h = [[0.0; 4]; 4];
    let e;
    match energy {
        Energy::Mips => {
            // E = s/D; ∇E = 2x/D − s∇D/D²;
            // H = 2I/D − 2(x∇Dᵀ + ∇D xᵀ)/D² − s H_D/D² + 2s ∇D∇Dᵀ/D³.
            e = s / d;
            let (d2, d3) = (d * d, d * d * d);
            for i in 0..4 {
                g[i] = 2.0 * a[i] / d - s * gd[i] / d2;
                for j in 0..4 {
                    let id = if i == j { 2.0 / d } else { 0.0 };
                    h[i][j] = id - 2.0 * (a[i] * gd[j] + gd[i] * a[j]) / d2 - s * hd(i, j) / d2
                        + 2.0 * s * gd[i] * gd[j] / d3;
                }
            }
        }
        Energy::SymmetricDirichlet => {
            // E = s + s/D²; ∇E = 2x + 2x/D² − 2s∇D/D³;
            // H = 2I(1 + 1/D²) − 4(x∇Dᵀ + ∇D xᵀ)/D³ − 2s H_D/D³ + 6s ∇D∇Dᵀ/D⁴.
            let (d2, d3, d4) = (d * d, d * d * d, d * d * d * d);
            e = s + s / d2;
            for i in 0..4 {
                g[i] = 2.0 * a[i] + 2.0 * a[i] / d2 - 2.0 * s * gd[i] / d3;
                for j in 0..4 {
                    let id = if i == j { 2.0 + 2.0 / d2 } else { 0.0 };
                    h[i][j] =
                        id - 4.0 * (a[i] * gd[j] + gd[i] * a[j]) / d3 - 2.0 * s * hd(i, j) / d3
                            + 6.0 * s * gd[i] * gd[j] / d4;
                }
            }
        }
    }
    (e, g, h)
}

/// Largest `t` in (0, ∞] with `det(A + τP) > 0` for all τ in [0, t): the first positive root of
/// the quadratic `det A + τ ∇det·P + τ² det P` (∞ when there is none).
pub fn max_flip_free_step(a: &[f64; 4], p: &[f64; 4]) -> f64 {
    let c0 = det(a);
    let c1 = grad_det(a).iter().zip(p).map(|(x, y)| x * y).sum::<f64>();
    let c2 = det(p);
    smallest_positive_root(c2, c1, c0)
}

/// Smallest positive root of `c2 t² + c1 t + c0` (∞ if none), computed without cancellation.
pub fn smallest_positive_root(c2: f64, c1: f64, c0: f64) -> f64 {
    let scale = c2.abs().max(c1.abs()).max(c0.abs());
    if scale == 0.0 {
        return f64::INFINITY;
    }
    if c2.abs() <= 1e-14 * scale {
        // Linear.
        if c1.abs() <= 1e-300 {
            return f64::INFINITY;
        }
        let t = -c0 / c1;
        return if t > 0.0 { t } else { f64::INFINITY };
    }
    let disc = c1 * c1 - 4.0 * c2 * c0;
    if disc < 0.0 {
        return f64::INFINITY;
    }
    let sq = disc.sqrt();
    // q = −(c1 + sign(c1)·√disc)/2; roots q/c2 and c0/q.
    let sign = if c1 >= 0.0 { 1.0 } else { -1.0 };
    let q = -0.5 * (c1 + sign * sq);
    let mut best = f64::INFINITY;
    for t in [q / c2, if q != 0.0 { c0 / q } else { f64::INFINITY }] {
        if t > 0.0 && t < best {
            best = t;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fd_check(energy: Energy, a: [f64; 4]) {
        let (e, g, h) = eval(energy, &a);
        assert!((e - value(energy, &a)).abs() < 1e-12 * e.abs().max(1.0));
        let eps = 1e-6;
        for i in 0..4 {
            let mut ap = a;
            let mut am = a;
            ap[i] += eps;
            am[i] -= eps;
            let gfd = (value(energy, &ap) - value(energy, &am)) / (2.0 * eps);
            assert!(
                (gfd - g[i]).abs() < 1e-5 * g[i].abs().max(1.0),
                "grad {i}: {gfd} vs {}",
                g[i]
            );
            let (_, gp, _) = eval(energy, &ap);
            let (_, gm, _) = eval(energy, &am);
            for j in 0..4 {
                let hfd = (gp[j] - gm[j]) / (2.0 * eps);
                assert!(
                    (hfd - h[i][j]).abs() < 1e-4 * h[i][j].abs().max(1.0),
                    "hess {i}{j}: {hfd} vs {}",
                    h[i][j]
                );
            }
        }
    }

    #[test]
    fn derivatives_match_finite_differences() {
        for a in [
            [1.0, 0.2, -0.3, 0.9],
            [2.0, 0.0, 0.0, 0.5],
            [0.7, -0.4, 0.5, 1.3],
        ] {
            fd_check(Energy::Mips, a);
            fd_check(Energy::SymmetricDirichlet, a);
        }
    }

    #[test]
    fn minima_at_rotations() {
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        let r = [c, -s, s, c];
        assert!((value(Energy::Mips, &r) - 2.0).abs() < 1e-12);
        assert!((value(Energy::SymmetricDirichlet, &r) - 4.0).abs() < 1e-12);
        assert_eq!(value(Energy::Mips, &[1.0, 0.0, 0.0, -1.0]), f64::INFINITY);
    }

    #[test]
    fn flip_free_step_is_the_determinant_root() {
        let a = [1.0, 0.0, 0.0, 1.0];
        let p = [-2.0, 0.0, 0.0, 0.0];
        // det(A + tP) = 1 − 2t → root 0.5.
        assert!((max_flip_free_step(&a, &p) - 0.5).abs() < 1e-12);
        assert_eq!(max_flip_free_step(&a, &[1.0, 0.0, 0.0, 1.0]), f64::INFINITY);
    }
}
