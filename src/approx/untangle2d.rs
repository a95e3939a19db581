//! Untangling of a planar triangle patch with a fixed boundary: the free vertices are moved
//! (in 2D) to remove inverted triangles.
//!
//! A Tutte embedding only untangles when the fixed boundary is convex; the regions of the planar
//! approximation have long non-convex boundaries (their outlines follow plane–plane lines), so
//! the interior vertices are instead found by minimising the regularised barrier energy of
//! Garanzha et al. (2021, "Foldover-free maps in 50 lines of code"): per triangle
//! `((1-θ)|J|²/2 + θ(det J² + 1)/2) / χ(det J, ε)` with `χ(d, ε) = (d + √(ε² + d²))/2`, which is
//! finite for inverted triangles while ε > 0; ε is lowered round by round so the minimiser is
//! pushed to positive determinants. Each round is an L-BFGS minimisation.
#![forbid(unsafe_code)]

use crate::linalg::lbfgs::{minimise, next_eps, LbfgsOptions, Objective};
use crate::param::energy::det;

/// Parameters of [`untangle_2d`].
#[derive(Clone, Debug, PartialEq)]
pub struct Untangle2dOptions {
    /// Weight of the area term against the conformal (shape) term.
    pub theta: f64,
    /// Rounds of "minimise, lower ε".
    pub max_rounds: usize,
    /// L-BFGS iterations per round.
    pub iterations: usize,
    /// Stop after this many rounds without fewer inverted triangles.
    pub stall_rounds: usize,
}

impl Default for Untangle2dOptions {
    fn default() -> Self {
        Untangle2dOptions {
            theta: 1.0 / 128.0,
            max_rounds: 100,
            iterations: 300,
            stall_rounds: 40,
        }
    }
}

/// Outcome of [`untangle_2d`].
#[derive(Clone, Debug, PartialEq)]
pub struct Untangle2dResult {
    /// Triangles with determinant ≤ 0 at the end.
    pub inverted: usize,
    pub rounds: usize,
}

/// A triangle's reference shape: the inverse of its 2×2 edge matrix `[r1 r2]` (row-major) and
/// its area (the energy's weight).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reference {
    pub inv: [f64; 4],
    pub area: f64,
}

impl Reference {
    /// Reference of the 3D triangle `a b c` scaled by `s` (in its own plane). `None` when it
    /// is degenerate.
    pub fn from_triangle(a: [f64; 3], b: [f64; 3], c: [f64; 3], s: f64) -> Option<Reference> {
        use super::geom::{cross, dot, norm, sub};
        let e1 = sub(b, a);
        let e2 = sub(c, a);
        let l1 = norm(e1);
        if l1 <= 0.0 {
            return None;
        }
        let x2 = dot(e2, e1) / l1;
        let y2 = norm(cross(e1, e2)) / l1;
        // [r1 r2] = s [[l1, x2], [0, y2]]
        let det = s * s * l1 * y2;
        if det <= 0.0 || !det.is_finite() {
            return None;
        }
        Some(Reference {
            inv: [s * y2 / det, -s * x2 / det, 0.0, s * l1 / det],
            area: 0.5 * det,
        })
    }
}

fn chi(d: f64, eps: f64) -> f64 {
    0.5 * (d + (eps * eps + d * d).sqrt())
}

fn chi_deriv(d: f64, eps: f64) -> f64 {
    0.5 * (1.0 + d / (eps * eps + d * d).sqrt())
}

/// Jacobian `[e1 e2] · inv` (row-major) of the triangle with corners `q`.
fn jacobian(q: &[[f64; 2]; 3], r: &Reference) -> [f64; 4] {
    let e1 = [q[1][0] - q[0][0], q[1][1] - q[0][1]];
    let e2 = [q[2][0] - q[0][0], q[2][1] - q[0][1]];
    let m = r.inv;
    [
        e1[0] * m[0] + e2[0] * m[2],
        e1[0] * m[1] + e2[0] * m[3],
        e1[1] * m[0] + e2[1] * m[2],
        e1[1] * m[1] + e2[1] * m[3],
    ]
}

/// Jacobian determinant of the triangle `q` against its reference (≤ 0: inverted).
pub(crate) fn triangle_det(q: &[[f64; 2]; 3], r: &Reference) -> f64 {
    det(&jacobian(q, r))
}

/// Regularised energy of one triangle with corners `q` (see module doc) and, with `grad`, its
/// gradient with respect to the three corners (overwritten).
pub(crate) fn triangle_energy(
    q: &[[f64; 2]; 3],
    r: &Reference,
    theta: f64,
    eps: f64,
    grad: Option<&mut [[f64; 2]; 3]>,
) -> f64 {
    let j = jacobian(q, r);
    let d = det(&j);
    let c = chi(d, eps);
    let fro = j.iter().map(|v| v * v).sum::<f64>();
    let a = (1.0 - theta) * 0.5 * fro + theta * 0.5 * (d * d + 1.0);
    if let Some(g) = grad {
        let cof = [j[3], -j[2], -j[1], j[0]];
        let k = -a * chi_deriv(d, eps) / (c * c);
        let mut gj = [0.0; 4];
        for i in 0..4 {
            gj[i] = r.area * (((1.0 - theta) * j[i] + theta * d * cof[i]) / c + k * cof[i]);
        }
        // dE/d[e1 e2] = gj · invᵀ
        let m = r.inv;
        let ge1 = [gj[0] * m[0] + gj[1] * m[1], gj[2] * m[0] + gj[3] * m[1]];
        let ge2 = [gj[0] * m[2] + gj[1] * m[3], gj[2] * m[2] + gj[3] * m[3]];
        for k in 0..2 {
            g[1][k] = ge1[k];
            g[2][k] = ge2[k];
            g[0][k] = -(ge1[k] + ge2[k]);
        }
    }
    r.area * a / c
}

/// A barrier problem over a flat vector of unknowns, minimised by [`minimise_rounds`].
pub(crate) trait Barrier {
    /// Energy at `x` for the regularisation `eps` and (with `grad`) its gradient.
    fn eval(&self, x: &[f64], eps: f64, grad: Option<&mut [f64]>) -> f64;
    /// Smallest Jacobian determinant and the number of inverted triangles at `x`.
    fn min_det(&self, x: &[f64]) -> (f64, usize);
}

/// The patch problem of [`untangle_2d`]: unknowns are the 2D positions, flattened.
struct Problem<'a> {
    faces: &'a [[usize; 3]],
    refs: &'a [Reference],
    free: &'a [bool],
    theta: f64,
}

impl Problem<'_> {
    fn corners(&self, f: &[usize; 3], x: &[[f64; 2]]) -> [[f64; 2]; 3] {
        f.map(|i| x[i])
    }
}

impl Barrier for Problem<'_> {
    /// Energy and (when `grad` is given) its gradient, zero on fixed vertices.
    fn eval(&self, x: &[f64], eps: f64, grad: Option<&mut [f64]>) -> f64 {
        let x: &[[f64; 2]] = bytemuck::cast_slice(x);
        let mut grad: Option<&mut [[f64; 2]]> = grad.map(bytemuck::cast_slice_mut);
        if let Some(g) = grad.as_deref_mut() {
            g.iter_mut().for_each(|v| *v = [0.0; 2]);
        }
        let mut e = 0.0;
        let mut gq = [[0.0; 2]; 3];
        for (f, r) in self.faces.iter().zip(self.refs) {
            let q = self.corners(f, x);
            match grad.as_deref_mut() {
                Some(g) => {
                    e += triangle_energy(&q, r, self.theta, eps, Some(&mut gq));
                    for (c, &i) in f.iter().enumerate() {
                        g[i][0] += gq[c][0];
                        g[i][1] += gq[c][1];
                    }
                }
                None => e += triangle_energy(&q, r, self.theta, eps, None),
            }
        }
        if let Some(g) = grad {
            for (gv, &fr) in g.iter_mut().zip(self.free) {
                if !fr {
                    *gv = [0.0; 2];
                }
            }
        }
        e
    }

    fn min_det(&self, x: &[f64]) -> (f64, usize) {
        let x: &[[f64; 2]] = bytemuck::cast_slice(x);
        let mut m = f64::INFINITY;
        let mut inv = 0;
        for (f, r) in self.faces.iter().zip(self.refs) {
            let d = triangle_det(&self.corners(f, x), r);
            m = m.min(d);
            inv += usize::from(d <= 0.0);
        }
        (m, inv)
    }
}

/// Dot product, summed in pairs: the order of the 2D untangler's sums before it was written
/// over flat vectors, kept so that its results stay bit-identical.
/// (`chunks_exact`: the fixed chunk length lets the compiler drop the per-chunk length checks
/// in this innermost loop, which the generic `chunks` keeps.)
fn dot_pairs(a: &[f64], b: &[f64]) -> f64 {
    let (pa, pb) = (a.chunks_exact(2), b.chunks_exact(2));
    let tail: f64 = pa
        .remainder()
        .iter()
        .zip(pb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    pa.zip(pb)
        .map(|(p, q)| p[0] * q[0] + p[1] * q[1])
        .sum::<f64>()
        + tail
}

/// One round's L-BFGS objective: a [`Barrier`] at a fixed ε.
struct AtEps<'a> {
    p: &'a dyn Barrier,
    eps: f64,
}

impl Objective for AtEps<'_> {
    type Error = std::convert::Infallible;
    fn value_grad(&mut self, x: &[f64], g: &mut [f64]) -> Result<f64, Self::Error> {
        Ok(self.p.eval(x, self.eps, Some(g)))
    }
    fn steepest_scale(&self, g: &[f64]) -> Option<f64> {
        Some(1.0 / dot_pairs(g, g).sqrt().max(1e-300))
    }
    fn dot(&self, a: &[f64], b: &[f64]) -> f64 {
        dot_pairs(a, b)
    }
}

/// L-BFGS settings of a round (memory 8, the iteration cap is the options').
const LBFGS: LbfgsOptions = LbfgsOptions {
    memory: 8,
    max_iterations: 0,
    gradient_tolerance: Some(1e-12),
    rel_decrease: 1e-14,
    curvature_rel: 0.0,
    curvature_abs: 1e-300,
};

/// Moves the `free` vertices of `x` to untangle the triangles `faces` (local vertex indices)
/// against their `refs` (see module doc). Fixed vertices are not touched. Stops as soon as no
/// triangle is inverted after a round.
pub fn untangle_2d(
    faces: &[[usize; 3]],
    refs: &[Reference],
    free: &[bool],
    x: &mut [[f64; 2]],
    opts: &Untangle2dOptions,
) -> Untangle2dResult {
    let p = Problem {
        faces,
        refs,
        free,
        theta: opts.theta,
    };
    minimise_rounds(&p, bytemuck::cast_slice_mut(x), opts)
}

/// The rounds of "L-BFGS, lower ε" of Garanzha et al. on any [`Barrier`] problem. Returns the
/// iterate with the fewest inverted triangles seen (in `x`).
pub(crate) fn minimise_rounds(
    p: &dyn Barrier,
    x: &mut [f64],
    opts: &Untangle2dOptions,
) -> Untangle2dResult {
    let (mut min_det, mut inverted) = p.min_det(x);
    let mut eps = if min_det > 0.0 {
        1e-10
    } else {
        // Large enough to make every triangle's χ well away from 0 at the start.
        (1e-8 + 0.04 * min_det * min_det).sqrt().max(1e-3)
    };
    let mut e_prev = p.eval(x, eps, None);
    let mut rounds = 0;
    // The layout with the fewest inverted triangles is returned; a hopeless patch (its fixed
    // outline overlaps itself) stops after `stall_rounds` rounds without progress.
    let mut best = (inverted, x.to_vec());
    let mut since_best = 0;
    while rounds < opts.max_rounds && since_best < opts.stall_rounds {
        rounds += 1;
        let lbfgs = LbfgsOptions {
            max_iterations: opts.iterations,
            ..LBFGS
        };
        let r = minimise(&mut AtEps { p, eps }, x, &lbfgs).unwrap_or_else(|never| match never {});
        let e = r.energy;
        (min_det, inverted) = p.min_det(x);
        if inverted < best.0 {
            best = (inverted, x.to_vec());
            since_best = 0;
        } else {
            since_best += 1;
        }
        if inverted == 0 {
            break;
        }
        // ε update of Garanzha et al.: shrink by the relative energy decrease, but keep χ of
        // the worst triangle bounded away from zero.
        eps = next_eps(e, e_prev, min_det, chi(min_det, eps));
        e_prev = p.eval(x, eps, None);
    }
    if best.0 < inverted {
        x.copy_from_slice(&best.1);
    }
    Untangle2dResult {
        inverted: best.0,
        rounds,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square fan (4 fixed corners + 1 free centre, 4 triangles) with the centre placed
    /// outside: two triangles are inverted; the untangler must bring the centre back inside.
    #[test]
    fn untangles_fan_with_outside_centre() {
        let mut x = vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.7, 0.4]];
        let faces = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
        let refs: Vec<Reference> = faces
            .iter()
            .map(|f| {
                let p = |i: usize| match i {
                    4 => [0.5, 0.5, 0.0],
                    _ => [x[i][0], x[i][1], 0.0],
                };
                Reference::from_triangle(p(f[0]), p(f[1]), p(f[2]), 1.0).unwrap()
            })
            .collect();
        let free = [false, false, false, false, true];
        let before = Problem {
            faces: &faces,
            refs: &refs,
            free: &free,
            theta: 1.0 / 128.0,
        }
        .min_det(bytemuck::cast_slice(&x))
        .1;
        assert!(before > 0);
        let r = untangle_2d(&faces, &refs, &free, &mut x, &Untangle2dOptions::default());
        assert_eq!(r.inverted, 0);
        assert!(x[4][0] > 0.0 && x[4][0] < 1.0 && x[4][1] > 0.0 && x[4][1] < 1.0);
        assert_eq!(x[1], [1.0, 0.0]);
    }

    /// The analytic gradient matches central differences.
    #[test]
    fn gradient_matches_finite_differences() {
        let x = vec![[0.0, 0.0], [1.0, 0.1], [0.9, 1.2], [0.2, 0.8], [1.3, 0.3]];
        let faces = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
        let refs: Vec<Reference> = (0..4)
            .map(|_| {
                Reference::from_triangle([0.0; 3], [1.0, 0.0, 0.0], [0.3, 0.9, 0.0], 1.0).unwrap()
            })
            .collect();
        let free = [true; 5];
        let p = Problem {
            faces: &faces,
            refs: &refs,
            free: &free,
            theta: 0.2,
        };
        let mut g = vec![[0.0; 2]; 5];
        p.eval(
            bytemuck::cast_slice(&x),
            0.3,
            Some(bytemuck::cast_slice_mut(&mut g)),
        );
        let h = 1e-6;
        for v in 0..5 {
            for k in 0..2 {
                let mut xp = x.clone();
                let mut xm = x.clone();
                xp[v][k] += h;
                xm[v][k] -= h;
                let e = |y: &Vec<[f64; 2]>| p.eval(bytemuck::cast_slice(y), 0.3, None);
                let fd = (e(&xp) - e(&xm)) / (2.0 * h);
                assert!((fd - g[v][k]).abs() < 1e-5 * (1.0 + fd.abs()), "{v} {k}");
            }
        }
    }
}
