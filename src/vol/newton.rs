//! Projected Newton on an objective over all vertex positions: a sum of per-tet terms
//! w·[D(M) + ω‖F − G‖²] (M and F linear in the tet's corners), a quadratic position penalty
//! λΣ‖xᵥ − x̃ᵥ‖², and optionally fixed vertices.
//!
//! Per iteration: per-tet value/gradient/PSD Hessian in parallel (rayon), scattered into a
//! CSR matrix whose pattern (vertex adjacency × 3x3 blocks) is built once; the system is
//! solved by PCG; the step is capped by the largest flip-free step (every tet's det cubic)
//! and then backtracked until the energy decreases (Armijo). Because every accepted point has
//! finite energy, and the energy is +∞ on any non-positive tet, no iterate ever inverts a tet.
//!
//! Diagnostics: with `FOLDFREE_VOL_TRACE` set, every step prints energy, step, largest
//! flip-free step, gradient norm and cumulative PCG iterations to stderr.

use rayon::prelude::*;

use super::energy::{inv3, sym_dirichlet, sym_dirichlet_grad, sym_dirichlet_hessian_psd, Mat3};
use super::line_search::max_flip_free_step;
use super::VolError;
use crate::linalg::pattern::BlockPattern;
use crate::linalg::SolveError;
use crate::linalg::{
    krylov::{CgOptions, KrylovSolver},
    precond::Preconditioner,
};

/// Corner weights D (4x3) of a linear Jacobian: M = Xᵀ·D for the tet's corner rows X (4x3).
pub type Corner = [[f64; 3]; 4];

/// The corner weights of M = Ds·B, Ds = [x₁ − x₀, x₂ − x₀, x₃ − x₀].
pub fn corner_weights(b: &Mat3) -> Corner {
    let mut d = [[0.0; 3]; 4];
    for c in 0..3 {
        d[0][c] = -(b[0][c] + b[1][c] + b[2][c]);
        for k in 0..3 {
            d[k + 1][c] = b[k][c];
        }
    }
    d
}

/// Dm = [p₁ − p₀, p₂ − p₀, p₃ − p₀] (columns) of the corners `p`.
pub fn edge_matrix_of(p: [[f64; 3]; 4]) -> Mat3 {
    let e = [1, 2, 3].map(|k| [0, 1, 2].map(|r| p[k][r] - p[0][r]));
    [0, 1, 2].map(|r| [e[0][r], e[1][r], e[2][r]])
}

/// The corner weights D of the Jacobian against the reference tet with corners `p`
/// (J = Xᵀ·D = Ds·Dm⁻¹) and det Dm (6 × its signed volume); None when Dm is singular.
pub fn corners_of(p: [[f64; 3]; 4]) -> Option<(Corner, f64)> {
    let dm = edge_matrix_of(p);
    Some((corner_weights(&inv3(&dm)?), super::energy::det3(&dm)))
}

/// M = Xᵀ·D for the corners of `t` in `x`.
#[inline]
pub fn jacobian(x: &[[f64; 3]], t: &[u32; 4], d: &Corner) -> Mat3 {
    let mut m = [[0.0; 3]; 3];
    for j in 0..4 {
        let p = x[t[j] as usize];
        for r in 0..3 {
            for c in 0..3 {
                m[r][c] += p[r] * d[j][c];
            }
        }
    }
    m
}

/// The objective (see the module doc).
#[derive(Clone, Debug)]
pub struct Objective {
    pub tets: Vec<[u32; 4]>,
    /// Per tet: weight w (volume fraction), D of the distortion Jacobian M.
    pub weight: Vec<f64>,
    pub d_dist: Vec<Corner>,
    /// Per tet: D of F and the guide G of the ω‖F − G‖² term (unused when ω = 0).
    pub d_fit: Vec<Corner>,
    pub guide: Vec<Mat3>,
    pub omega: f64,
    /// Position penalty λ·Σ‖xᵥ − x̃ᵥ‖² (λ = 0: none).
    pub targets: Vec<(u32, [f64; 3])>,
    pub lambda: f64,
    /// Vertices that do not move.
    pub fixed: Vec<bool>,
    /// Vertices that stay on the unit sphere (empty: none): their Newton steps are tangent to
    /// it and every trial point is renormalised onto it (the ball target's boundary, which
    /// must lie on the sphere but may slide along it).
    pub on_sphere: Vec<bool>,
}

pub type Local = (f64, [f64; 12], [[f64; 12]; 12]);

impl Objective {
    fn tet_value(&self, t: usize, x: &[[f64; 3]]) -> f64 {
        let tet = &self.tets[t];
        let m = jacobian(x, tet, &self.d_dist[t]);
        let mut e = sym_dirichlet(&m);
        if self.omega != 0.0 && e.is_finite() {
            let f = jacobian(x, tet, &self.d_fit[t]);
            let g = &self.guide[t];
            let mut s = 0.0;
            for r in 0..3 {
                for c in 0..3 {
                    s += (f[r][c] - g[r][c]).powi(2);
                }
            }
            e += self.omega * s;
        }
        self.weight[t] * e
    }

    /// Distortion + fit part only (no penalty), +∞ if any tet is not positive.
    pub fn tet_energy(&self, x: &[[f64; 3]]) -> f64 {
        (0..self.tets.len())
            .into_par_iter()
            .map(|t| self.tet_value(t, x))
            .sum()
    }

    /// λΣ‖xᵥ − x̃ᵥ‖² / λ, i.e. the unweighted position energy ρ.
    pub fn position_energy(&self, x: &[[f64; 3]]) -> f64 {
        position_energy(&self.targets, x)
    }

    /// The full objective (+∞ when a tet is not positive).
    pub fn value(&self, x: &[[f64; 3]]) -> f64 {
        let e = self.tet_energy(x);
        if self.lambda != 0.0 {
            e + self.lambda * self.position_energy(x)
        } else {
            e
        }
    }

    /// Value, gradient and PSD-projected Hessian of tet `t`'s term over its 12 corner
    /// coordinates (`None` when the tet is not positive).
    pub fn tet_local(&self, t: usize, x: &[[f64; 3]]) -> Option<Local> {
        let tet = &self.tets[t];
        let w = self.weight[t];
        let d = &self.d_dist[t];
        let m = jacobian(x, tet, d);
        let (e, p) = sym_dirichlet_grad(&m)?;
        let hm = sym_dirichlet_hessian_psd(&m);
        let mut g = [0.0; 12];
        let mut h = [[0.0; 12]; 12];
        // ∂M[r][c]/∂x_j[s] = δ_rs D[j][c]: g_(j,r) = Σ_c P[r][c] D[j][c], and
        // H_(j,r),(k,s) = Σ_{c,d} D[j][c] H_M[(r,c),(s,d)] D[k][d].
        let mut a = [[0.0; 9]; 12]; // a[(j,r)][(r',c)] = δ_rr' D[j][c]
        for j in 0..4 {
            for r in 0..3 {
                for c in 0..3 {
                    g[3 * j + r] += w * p[r][c] * d[j][c];
                    a[3 * j + r][3 * r + c] = d[j][c];
                }
            }
        }
        let mut ah = [[0.0; 9]; 12];
        for i in 0..12 {
            let r = i % 3;
            for b in 0..9 {
                let mut s = 0.0;
                for c in 0..3 {
                    s += a[i][3 * r + c] * hm[3 * r + c][b];
                }
                ah[i][b] = s;
            }
        }
        for i in 0..12 {
            for k in i..12 {
                let s = k % 3;
                let mut v = 0.0;
                for c in 0..3 {
                    v += ah[i][3 * s + c] * a[k][3 * s + c];
                }
                h[i][k] = w * v;
                h[k][i] = w * v;
            }
        }
        let mut e_tot = e;
        if self.omega != 0.0 {
            let f = jacobian(x, tet, &self.d_fit[t]);
            let gd = &self.guide[t];
            let df = &self.d_fit[t];
            let wo = w * self.omega;
            for r in 0..3 {
                for c in 0..3 {
                    let diff = f[r][c] - gd[r][c];
                    e_tot += self.omega * diff * diff;
                    for j in 0..4 {
                        g[3 * j + r] += 2.0 * wo * diff * df[j][c];
                    }
                }
            }
            for j in 0..4 {
                for k in 0..4 {
                    let dd: f64 = (0..3).map(|c| df[j][c] * df[k][c]).sum();
                    for r in 0..3 {
                        h[3 * j + r][3 * k + r] += 2.0 * wo * dd;
                    }
                }
            }
        }
        Some((w * e_tot, g, h))
    }
}

/// Σ‖xᵥ − x̃ᵥ‖² over the targets.
pub fn position_energy(targets: &[(u32, [f64; 3])], x: &[[f64; 3]]) -> f64 {
    targets
        .iter()
        .map(|(v, t)| {
            let p = x[*v as usize];
            (p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2) + (p[2] - t[2]).powi(2)
        })
        .sum()
}

/// CSR pattern of the 3n×3n Hessian, built once per mesh: row 3a + r holds columns 3b + s for
/// every vertex b sharing a tet with a (and a itself), b ascending.
pub type Pattern = BlockPattern<3, 4>;

/// Stopping rules and solver choices.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NewtonOptions {
    pub max_iters: usize,
    /// Stop when |ΔE| < tol·|E|.
    pub rel_tol: f64,
    /// Fraction of the largest flip-free step tried first.
    pub step_fraction: f64,
    pub cg: CgOptions,
}

impl Default for NewtonOptions {
    fn default() -> Self {
        NewtonOptions {
            max_iters: 250,
            rel_tol: 1e-4,
            step_fraction: 0.9,
            cg: CgOptions {
                tolerance: 1e-4,
                max_iterations: 200,
                preconditioner: Preconditioner::Ic0,
            },
        }
    }
}

/// What a Newton run did.
#[derive(Clone, Copy, Debug, Default)]
pub struct NewtonStats {
    pub iterations: usize,
    pub energy: f64,
    pub converged: bool,
    pub cg_iterations: usize,
}

/// Minimises `obj` from `x` (which must have finite energy), in place.
pub fn newton(
    obj: &Objective,
    pattern: &Pattern,
    x: &mut [[f64; 3]],
    opts: &NewtonOptions,
    progress: &mut dyn FnMut(usize, f64),
) -> Result<NewtonStats, VolError> {
    let nv = x.len();
    let n = 3 * nv;
    let mut energy = obj.value(x);
    if !energy.is_finite() {
        return Err(VolError::BadResult(
            "Newton start has an inverted tet or a non-finite value".into(),
        ));
    }
    let mut stats = NewtonStats {
        energy,
        ..Default::default()
    };
    let fixed = |v: u32| obj.fixed.get(v as usize).copied().unwrap_or(false);
    let sliding = |v: u32| obj.on_sphere.get(v as usize).copied().unwrap_or(false) && !fixed(v);
    let slide: Vec<u32> = (0..nv as u32).filter(|&v| sliding(v)).collect();
    let mut data = vec![0.0; pattern.indices.len()];
    let mut grad = vec![0.0; n];
    let mut step = vec![0.0; n];
    for it in 0..opts.max_iters {
        let locals: Vec<Option<Local>> = (0..obj.tets.len())
            .into_par_iter()
            .map(|t| {
                let mut l = obj.tet_local(t, x)?;
                let tet = &obj.tets[t];
                if tet.iter().any(|&v| sliding(v)) {
                    project_tangent(tet, x, &sliding, &mut l);
                }
                Some(l)
            })
            .collect();
        data.iter_mut().for_each(|v| *v = 0.0);
        grad.iter_mut().for_each(|v| *v = 0.0);
        for (t, l) in locals.iter().enumerate() {
            let Some((_, g, h)) = l else {
                return Err(VolError::BadResult(format!(
                    "tet {t} is not positive during Newton (line search bug)"
                )));
            };
            let tet = &obj.tets[t];
            let sl = &pattern.slot[t];
            for i in 0..4 {
                let a = tet[i];
                if fixed(a) {
                    continue;
                }
                for r in 0..3 {
                    grad[3 * a as usize + r] += g[3 * i + r];
                    for j in 0..4 {
                        if fixed(tet[j]) {
                            continue;
                        }
                        let base = pattern.pos(a, r, sl[i][j], 0);
                        for s in 0..3 {
                            data[base + s] += h[3 * i + r][3 * j + s];
                        }
                    }
                }
            }
        }
        if obj.lambda != 0.0 {
            for (v, t) in &obj.targets {
                if fixed(*v) {
                    continue;
                }
                let p = x[*v as usize];
                for r in 0..3 {
                    grad[3 * *v as usize + r] += 2.0 * obj.lambda * (p[r] - t[r]);
                    data[pattern.diag(*v, r)] += 2.0 * obj.lambda;
                }
            }
        }
        // Fixed rows become identity; a tiny relative diagonal shift makes the system
        // definite when nothing pins the translations (the deformation phase).
        let mean_diag = {
            let mut s = 0.0;
            for v in 0..nv as u32 {
                for r in 0..3 {
                    s += data[pattern.diag(v, r)];
                }
            }
            (s / n as f64).max(f64::MIN_POSITIVE)
        };
        for v in 0..nv as u32 {
            let k = pattern.diag_slot[v as usize];
            for r in 0..3 {
                let p = pattern.pos(v, r, k, r);
                if fixed(v) {
                    data[p] = 1.0;
                } else {
                    data[p] += 1e-10 * mean_diag;
                }
            }
        }
        // A sliding vertex's block is P·H·P (P = I − nnᵀ), singular along n: add mean_diag·nnᵀ,
        // so the normal component of its step solves mean_diag·(n·d) = n·(−Pg) = 0.
        for &v in &slide {
            let k = pattern.diag_slot[v as usize];
            let nrm = x[v as usize];
            for r in 0..3 {
                for c in 0..3 {
                    data[pattern.pos(v, r, k, c)] += mean_diag * nrm[r] * nrm[c];
                }
            }
        }
        let gnorm = grad.iter().map(|g| g * g).sum::<f64>().sqrt();
        if gnorm == 0.0 || !gnorm.is_finite() {
            stats.converged = gnorm == 0.0;
            break;
        }
        let a = pattern.matrix(std::mem::take(&mut data));
        let rhs: Vec<f64> = grad.iter().map(|g| -g).collect();
        step.iter_mut().for_each(|v| *v = 0.0);
        let solver = KrylovSolver::cg(&a, &opts.cg)?;
        match solver.solve(&rhs, &mut step) {
            Ok(s) => stats.cg_iterations += s.iterations,
            Err(SolveError::CgNoConvergence { iterations, .. }) => {
                stats.cg_iterations += iterations;
            }
            Err(e) => return Err(e.into()),
        }
        data = a.into_raw_storage().2;
        let slope: f64 = step.iter().zip(&grad).map(|(p, g)| p * g).sum();
        if !super::tet::is_positive(-slope) {
            // Not a descent direction (CG broke down): fall back to preconditioned gradient.
            for v in 0..nv as u32 {
                let k = pattern.diag_slot[v as usize];
                for r in 0..3 {
                    let i = 3 * v as usize + r;
                    step[i] = -grad[i] / data[pattern.pos(v, r, k, r)];
                }
            }
        }
        let slope: f64 = step.iter().zip(&grad).map(|(p, g)| p * g).sum();
        let p3: Vec<[f64; 3]> = step.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let tmax = max_flip_free_step(&obj.tets, x, &p3);
        let mut t = (opts.step_fraction * tmax).min(1.0);
        let mut trial = x.to_vec();
        let mut accepted = None;
        for _ in 0..60 {
            for (v, q) in trial.iter_mut().enumerate() {
                let o = x[v];
                let d = p3[v];
                *q = [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
            }
            // Back onto the sphere (a retraction: second-order close to the tangent step, and
            // the energy test below sees any tet the renormalisation inverts as +∞).
            for &v in &slide {
                let q = &mut trial[v as usize];
                if let Some(u) = super::tet::to_unit_sphere(*q) {
                    *q = u;
                }
            }
            let e = obj.value(&trial);
            if e.is_finite() && e <= energy + 1e-4 * t * slope {
                accepted = Some(e);
                break;
            }
            t *= 0.5;
        }
        stats.iterations = it + 1;
        let Some(e_new) = accepted else {
            stats.converged = true;
            break;
        };
        x.copy_from_slice(&trial);
        let change = (energy - e_new).abs();
        let prev = energy;
        energy = e_new;
        stats.energy = energy;
        progress(it + 1, energy);
        if std::env::var_os("FOLDFREE_VOL_TRACE").is_some() {
            eprintln!(
                "it {it} E {energy:.6e} t {t:.3e} tmax {tmax:.3e} |g| {gnorm:.3e} cg {}",
                stats.cg_iterations
            );
        }
        if change < opts.rel_tol * prev.abs() {
            stats.converged = true;
            break;
        }
    }
    stats.energy = energy;
    Ok(stats)
}

/// Restricts a tet's gradient and Hessian to the tangent planes of its sliding corners:
/// g_i ← P_i g_i, H_ij ← P_i H_ij P_j with P = I − nnᵀ, n = the corner's (unit) position.
/// The projected Hessian stays positive semi-definite (a congruence of a PSD matrix).
fn project_tangent(tet: &[u32; 4], x: &[[f64; 3]], sliding: &dyn Fn(u32) -> bool, l: &mut Local) {
    let (_, g, h) = l;
    let mut p = [[[0.0; 3]; 3]; 4];
    for (i, &v) in tet.iter().enumerate() {
        let nrm = x[v as usize];
        for r in 0..3 {
            for c in 0..3 {
                let id = if r == c { 1.0 } else { 0.0 };
                p[i][r][c] = if sliding(v) { id - nrm[r] * nrm[c] } else { id };
            }
        }
    }
    for i in 0..4 {
        let gi = [g[3 * i], g[3 * i + 1], g[3 * i + 2]];
        for r in 0..3 {
            g[3 * i + r] = (0..3).map(|c| p[i][r][c] * gi[c]).sum();
        }
    }
    let old = *h;
    for i in 0..4 {
        for j in 0..4 {
            // (P_i H_ij P_j)[r][s] = Σ_a Σ_b P_i[r][a] H_ij[a][b] P_j[b][s].
            for r in 0..3 {
                for s_ in 0..3 {
                    let mut v = 0.0;
                    for a in 0..3 {
                        for b in 0..3 {
                            v += p[i][r][a] * old[3 * i + a][3 * j + b] * p[j][b][s_];
                        }
                    }
                    h[3 * i + r][3 * j + s_] = v;
                }
            }
        }
    }
}
