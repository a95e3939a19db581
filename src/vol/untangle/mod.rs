//! Untangling of a folded map with the boundary held exactly (Garanzha, Kaporin, Kudryavtseva,
//! Protais, Ray, Sokolov 2021, "Foldover-free maps in 50 lines of code"), used as an
//! alternative first stage of `volmap` (`--untangle`).
//!
//! Why: the penalty route of Xu & Liu has to *reach* the constraints from a fold-free start,
//! and on meshes whose init folds right next to pinned vertices the path is blocked by closing
//! slivers. The regularised energy below is finite for every configuration, inverted tets
//! included, so it can start from the init itself with the constrained vertices already on
//! their targets (ρ = 0 by construction) and only the free vertices move. As ε → 0 its
//! minimisers have det J > 0 everywhere when a fold-free map with that boundary exists.
//!
//! Per tet (J = rest → x Jacobian, D = det J, χ(D, ε) = (D + √(ε² + D²))/2 > 0):
//! f_ε(J) = (1 − θ)·‖J‖²_F / χ^{2/3} + θ·(D² + 1) / χ,
//! the first term measuring shape (scale-invariant, ≥ 3 for D > 0 and ε → 0), the second
//! volume change; J is taken against the rest shape scaled to the volume the fixed boundary
//! encloses, so det J = 1 is attainable on average. The minimiser over free vertices is found by L-BFGS with Armijo
//! backtracking (the energy is smooth, so no flip-free step cap is needed); ε follows the
//! paper's schedule, shrinking as the minimum det grows, and becomes negligible once no tet
//! is inverted.

use std::time::Instant;

use rayon::prelude::*;

use crate::linalg::lbfgs::{minimise, next_eps, LbfgsOptions, Objective};

use super::energy::{det3, frob2, Mat3};
use super::newton::{corners_of, jacobian, Corner};
use crate::gpu::Context;
use vulkan::DeviceTets;

pub mod vulkan;
use super::tet::{to_unit_sphere, TetMesh};
use super::VolError;

/// Settings of the untangling stage.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UntangleOptions {
    /// Weight θ of the volume term (the rest is the shape term).
    pub theta: f64,
    /// Cap on ε updates (outer iterations).
    pub max_outer: usize,
    /// Cap on L-BFGS steps per ε.
    pub max_inner: usize,
    /// L-BFGS memory.
    pub history: usize,
    /// Stop once no tet is inverted and an outer iteration changed the energy by less than
    /// this fraction. Default ∞: stop at the first ε whose minimiser is fold-free — polishing
    /// further is left to the post-optimisation, which minimises the measured distortion
    /// itself, where more untangler iterations minimise its ε-regularised stand-in.
    pub rel_tol: f64,
    /// End the L-BFGS steps of one ε once a step lowers the energy by less than this fraction
    /// of it (scale-free: the energy is a volume-weighted mean). Default 1e-6, the stopping
    /// rule of the reference implementation's L-BFGS (stlbfgs `ftol`): each ε only has to be
    /// solved well enough for the next, ≥ 10 % smaller ε (the schedule's σ ≥ 0.1), and steps
    /// that change the energy in its sixth digit do not move the minimum det that sets it.
    pub inner_rel_tol: f64,
    /// Give up (with the tets still inverted) once ε has fallen this many decades since the
    /// number of inverted tets last dropped. An inverted tet's term grows like
    /// (|D|/ε²)^{2/3} as ε shrinks, so over one decade its pull on its corners grows
    /// 10^{4/3} ≈ 20-fold: a fold that yields to none of that is held by its neighbours'
    /// barriers (its det then only follows ε towards 0⁻), and smaller ε only make each step
    /// costlier (the ball target refines there instead). ∞: never.
    pub stall_decades: f64,
}

impl Default for UntangleOptions {
    fn default() -> Self {
        UntangleOptions {
            theta: 0.5,
            max_outer: 200,
            max_inner: 200,
            history: 10,
            rel_tol: f64::INFINITY,
            inner_rel_tol: 1e-6,
            stall_decades: 1.0,
        }
    }
}

/// What the untangling did.
#[derive(Clone, Copy, Debug, Default)]
pub struct UntangleStats {
    pub outer: usize,
    pub iterations: usize,
    /// Smallest det J over the tets at the end (> 0: untangled).
    pub min_det: f64,
    pub inverted: usize,
    /// Inverted tets whose four vertices are all fixed: no free move can repair them, so
    /// the untangler returns at once when there are any.
    pub inverted_pinned: usize,
    pub eps: f64,
    pub energy: f64,
    pub seconds: f64,
}

/// χ(D, ε) and dχ/dD.
#[inline]
fn chi(d: f64, eps: f64) -> (f64, f64) {
    let r = (eps * eps + d * d).sqrt();
    // D + r loses all digits for D ≪ −ε; ε²/(r − D) is the same number without cancellation.
    let c = if d >= 0.0 {
        0.5 * (d + r)
    } else {
        0.5 * eps * eps / (r - d)
    };
    (c, c / r)
}

/// Cofactor matrix of J (∂det J/∂J), rows = cross products of the other two rows.
fn cofactor(j: &Mat3) -> Mat3 {
    let c = |a: [f64; 3], b: [f64; 3]| super::tet::cross(a, b);
    [c(j[1], j[2]), c(j[2], j[0]), c(j[0], j[1])]
}

/// f_ε(J) and ∂f/∂J (see the module doc).
pub fn untangle_energy(j: &Mat3, eps: f64, theta: f64) -> (f64, Mat3) {
    let d = det3(j);
    let (x, dx) = chi(d, eps);
    let c = frob2(j);
    let x13 = x.cbrt();
    let x23 = x13 * x13;
    let f = (1.0 - theta) * c / x23 + theta * (d * d + 1.0) / x;
    // ∂f/∂D, then ∂f/∂J = 2(1 − θ)J/χ^{2/3} + ∂f/∂D · cof J.
    let df_dd = (1.0 - theta) * (-2.0 / 3.0) * c / (x23 * x) * dx
        + theta * (2.0 * d / x - (d * d + 1.0) * dx / (x * x));
    let cof = cofactor(j);
    let mut g = [[0.0; 3]; 3];
    for r in 0..3 {
        for k in 0..3 {
            g[r][k] = 2.0 * (1.0 - theta) * j[r][k] / x23 + df_dd * cof[r][k];
        }
    }
    (f, g)
}

/// One tet's weighted energy and gradient over its 12 corner coordinates (corner j,
/// coordinate r at 3j + r): the CPU f64 twin of `glsl/vol/untangle_tet.comp`.
pub fn tet_terms(
    x: &[[f64; 3]],
    tet: &[u32; 4],
    d: &Corner,
    w: f64,
    eps: f64,
    theta: f64,
) -> (f64, [f64; 12]) {
    let j = jacobian(x, tet, d);
    let (f, p) = untangle_energy(&j, eps, theta);
    let mut g = [0.0; 12];
    for c in 0..4 {
        for r in 0..3 {
            g[3 * c + r] = w * (p[r][0] * d[c][0] + p[r][1] * d[c][1] + p[r][2] * d[c][2]);
        }
    }
    (w * f, g)
}

/// The untangling energy over a tet mesh with per-tet reference data, evaluated with reused
/// buffers: per-tet terms in parallel (rayon), then the gradient gathered per vertex from its
/// incident (tet, corner) slots in a fixed order and the energy summed in tet order, so the
/// result is the same bit for bit on any number of threads (the Armijo tests compare energies
/// that differ in their last digits near convergence).
struct Problem<'a> {
    tets: &'a [[u32; 4]],
    d: Vec<Corner>,
    w: Vec<f64>,
    fixed: &'a [bool],
    theta: f64,
    /// Tets measured with the ε → 0 limit of the energy (empty: none): a barrier, +∞ at
    /// det J ≤ 0, so an accepted step never inverts them (see [`untangle_protected`]).
    protect: &'a [bool],
    /// Incident slots 4·t + c of each vertex: `inc[start[v]..start[v + 1]]`.
    start: Vec<u32>,
    inc: Vec<u32>,
}

/// Per-tet results of one evaluation, and the device that computes them (None: the CPU).
#[derive(Default)]
struct Scratch {
    f: Vec<f64>,
    g: Vec<[f64; 12]>,
    device: Option<DeviceTets>,
}

impl Problem<'_> {
    fn dets(&self, x: &[[f64; 3]]) -> Vec<f64> {
        (0..self.tets.len())
            .into_par_iter()
            .map(|t| det3(&jacobian(x, &self.tets[t], &self.d[t])))
            .collect()
    }

    fn value(&self, x: &[[f64; 3]], eps: f64, sc: &mut Scratch) -> Result<f64, VolError> {
        let mut g = vec![0.0; 3 * x.len()];
        self.value_grad(x, eps, &mut g, sc)
    }

    /// Value and gradient (zero on fixed vertices), flattened 3n.
    fn value_grad(
        &self,
        x: &[[f64; 3]],
        eps: f64,
        g: &mut [f64],
        sc: &mut Scratch,
    ) -> Result<f64, VolError> {
        let nt = self.tets.len();
        sc.f.resize(nt, 0.0);
        sc.g.resize(nt, [0.0; 12]);
        if let Some(dev) = &mut sc.device {
            let (f, gd) = dev.evaluate(x, eps, self.theta)?;
            for t in 0..nt {
                sc.f[t] = f64::from(f[t]);
                for c in 0..4 {
                    for r in 0..3 {
                        sc.g[t][3 * c + r] = f64::from(gd[4 * t + c][r]);
                    }
                }
            }
        } else {
            sc.f.par_iter_mut()
                .zip(sc.g.par_iter_mut())
                .enumerate()
                .for_each(|(t, (fo, go))| {
                    let e = if self.protect.get(t) == Some(&true) {
                        0.0
                    } else {
                        eps
                    };
                    (*fo, *go) = tet_terms(x, &self.tets[t], &self.d[t], self.w[t], e, self.theta);
                });
        }
        if sc.device.is_some() && !self.protect.is_empty() {
            // The device evaluates one ε for all tets: the protected ones again, on the host.
            for t in (0..nt).filter(|&t| self.protect.get(t) == Some(&true)) {
                (sc.f[t], sc.g[t]) =
                    tet_terms(x, &self.tets[t], &self.d[t], self.w[t], 0.0, self.theta);
            }
        }
        let gl = &sc.g;
        g.par_chunks_mut(3).enumerate().for_each(|(v, gv)| {
            gv.iter_mut().for_each(|q| *q = 0.0);
            if self.fixed[v] {
                return;
            }
            for &slot in &self.inc[self.start[v] as usize..self.start[v + 1] as usize] {
                let (t, c) = (slot as usize / 4, slot as usize % 4);
                for r in 0..3 {
                    gv[r] += gl[t][3 * c + r];
                }
            }
        });
        Ok(sc.f.iter().sum())
    }
}

/// One ε of the untangling as an L-BFGS objective over the flattened positions: the gradient
/// restricted to the sphere's tangent plane at the sliding vertices, trial points retracted
/// onto it.
struct AtEps<'a, 'p> {
    prob: &'a Problem<'p>,
    eps: f64,
    sc: &'a mut Scratch,
    sliding: &'a [usize],
    /// The map's bounding-box diagonal: steepest steps move the largest vertex by 1e-3 of it.
    diag: f64,
}

impl Objective for AtEps<'_, '_> {
    type Error = VolError;
    fn value_grad(&mut self, x: &[f64], g: &mut [f64]) -> Result<f64, VolError> {
        let x: &[[f64; 3]] = bytemuck::cast_slice(x);
        let e = self.prob.value_grad(x, self.eps, g, self.sc)?;
        // Tangent part of the gradient at the sliding vertices (x on the unit sphere).
        for &v in self.sliding {
            let gv = [g[3 * v], g[3 * v + 1], g[3 * v + 2]];
            let k = super::tet::dot(gv, x[v]);
            for r in 0..3 {
                g[3 * v + r] -= k * x[v][r];
            }
        }
        Ok(e)
    }
    fn steepest_scale(&self, g: &[f64]) -> Option<f64> {
        let gmax = g.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        (gmax > 0.0).then(|| 1e-3 * self.diag / gmax)
    }
    fn retract(&self, x: &mut [f64]) {
        let p: &mut [[f64; 3]] = bytemuck::cast_slice_mut(x);
        for &v in self.sliding {
            if let Some(u) = to_unit_sphere(p[v]) {
                p[v] = u;
            }
        }
    }
}

/// Untangles `x` in place: vertices with `fixed[v]` never move. Returns the statistics; the
/// caller checks `inverted` (a map with that boundary may not exist, or the iteration cap may
/// be too small).
pub fn untangle(
    rest: &TetMesh,
    x: &mut [[f64; 3]],
    fixed: &[bool],
    opts: &UntangleOptions,
) -> Result<UntangleStats, VolError> {
    untangle_sliding(rest, x, fixed, &[], opts, None)
}

/// [`untangle`] where the vertices with `on_sphere[v]` (an empty slice: none) slide on the
/// unit sphere instead of being fixed: they start on it and every step keeps them there
/// (tangent gradient, then a step followed by normalisation — a retraction, so the Armijo test
/// still sees a descent direction to first order).
///
/// Why: with the boundary pinned to one spherical embedding, tets whose four corners are all
/// on the boundary keep whatever sign that embedding gave them (a tet spanning a thin part
/// with only boundary corners is placed by the embedding alone), and where the embedding
/// inverted one no interior placement can repair it. Letting the boundary slide on the
/// sphere makes the sphere, not one embedding of it, the constraint.
///
/// `device`: evaluate the per-tet terms there ([`vulkan`]) instead of on the CPU.
pub fn untangle_sliding(
    rest: &TetMesh,
    x: &mut [[f64; 3]],
    fixed: &[bool],
    on_sphere: &[bool],
    opts: &UntangleOptions,
    device: Option<&Context>,
) -> Result<UntangleStats, VolError> {
    untangle_sliding_protected(rest, x, fixed, on_sphere, &[], opts, device)
}

/// [`untangle_sliding`] with the tets flagged in `protect` (per tet of `rest`, empty: none)
/// kept positive when they start so (see [`untangle_protected`]).
pub fn untangle_sliding_protected(
    rest: &TetMesh,
    x: &mut [[f64; 3]],
    fixed: &[bool],
    on_sphere: &[bool],
    protect: &[bool],
    opts: &UntangleOptions,
    device: Option<&Context>,
) -> Result<UntangleStats, VolError> {
    // The flags are checked against `x` by `untangle_cells`.
    if x.len() != rest.positions.len() {
        return Err(VolError::Input(format!(
            "untangle: {} positions for a mesh of {} vertices",
            x.len(),
            rest.positions.len()
        )));
    }
    let mut d = Vec::with_capacity(rest.tets.len());
    let mut vol = Vec::with_capacity(rest.tets.len());
    for (i, t) in rest.tets.iter().enumerate() {
        let (c, det) = corners_of(t.map(|v| rest.positions[v as usize])).ok_or_else(|| {
            VolError::Input(format!("rest tet {i} is degenerate (singular edge matrix)"))
        })?;
        d.push(c);
        vol.push(det.abs());
    }
    untangle_protected(
        &rest.tets, d, vol, x, fixed, on_sphere, protect, opts, device,
    )
}

/// [`untangle_sliding`] on cells given by their corner weights `d` (J = Xᵀ·D) and reference
/// volumes instead of a rest mesh: the ball target's spherical embedding untangles its cone
/// tets (centre + boundary face), whose reference shapes share no rest vertex positions.
#[allow(clippy::too_many_arguments)]
pub fn untangle_cells(
    tets: &[[u32; 4]],
    d: Vec<Corner>,
    vol: Vec<f64>,
    x: &mut [[f64; 3]],
    fixed: &[bool],
    on_sphere: &[bool],
    opts: &UntangleOptions,
    device: Option<&Context>,
) -> Result<UntangleStats, VolError> {
    untangle_protected(tets, d, vol, x, fixed, on_sphere, &[], opts, device)
}

/// [`untangle_cells`] where the tets flagged in `protect` (empty: none) that are positive at
/// the start are measured with the ε → 0 limit of the energy, (1 − θ)‖J‖²/D^{2/3} +
/// θ(D² + 1)/D, instead of the ε-regularised one.
///
/// Why: the regularisation is what lets the untangler pass through inverted configurations,
/// and it does so for every tet alike: at a large ε a positive tet may be inverted to relieve
/// its inverted neighbours, and once ε is small it sits behind the barrier the energy has
/// become and cannot come back. For a tet that is already positive the limit energy is
/// finite, and it is a barrier (+∞ at D ≤ 0): every accepted step (finite energy, Armijo)
/// keeps such a tet positive, whatever ε the others use. The minimisers as ε → 0 are those
/// of the unprotected problem (both energies tend to the same limit), so protection only
/// removes the paths that go through inverting the protected tets.
///
/// The ball target protects every tet with three or four corners on the sphere
/// ([`crate::vol::ball::slide_on_sphere`]): protecting only those with four left the untangler
/// stalled on those with three (three corners on a cap, the fourth in the thin lens under it),
/// BENCHMARKS.md.
#[allow(clippy::too_many_arguments)]
pub fn untangle_protected(
    tets: &[[u32; 4]],
    mut d: Vec<Corner>,
    vol: Vec<f64>,
    x: &mut [[f64; 3]],
    fixed: &[bool],
    on_sphere: &[bool],
    protect: &[bool],
    opts: &UntangleOptions,
    device: Option<&Context>,
) -> Result<UntangleStats, VolError> {
    let start = Instant::now();
    let nv = x.len();
    if tets.len() != d.len()
        || tets.len() != vol.len()
        || fixed.len() != nv
        || !(on_sphere.is_empty() || on_sphere.len() == nv)
        || !(protect.is_empty() || protect.len() == tets.len())
        || tets.iter().flatten().any(|&v| v as usize >= nv)
    {
        return Err(VolError::Input(format!(
            "untangle: {} cells, {} corner weights, {} volumes, {} positions, {} fixed and {} \
             sphere flags disagree (or a cell names a vertex past the positions)",
            tets.len(),
            d.len(),
            vol.len(),
            nv,
            fixed.len(),
            on_sphere.len()
        )));
    }
    let sliding: Vec<usize> = (0..on_sphere.len())
        .filter(|&v| on_sphere[v] && !fixed[v])
        .collect();
    for &v in &sliding {
        x[v] = to_unit_sphere(x[v]).ok_or_else(|| {
            VolError::Input(format!(
                "untangle: sliding vertex {v} is at the centre of the sphere"
            ))
        })?;
    }
    let total: f64 = vol.iter().sum();
    // The volume term wants det J = 1, but with the boundary fixed the sum of signed volumes
    // of x is fixed too (it is the volume the boundary encloses): measure J against the rest
    // shape scaled to that volume, so that det J = 1 is attainable on average (a rest mesh of
    // any size mapped onto the unit ball).
    let enclosed: f64 = tets.iter().map(|t| super::tet::det6(x, t)).sum();
    let scale = if enclosed > 0.0 && enclosed.is_finite() {
        (enclosed / total).cbrt()
    } else {
        1.0
    };
    for c in d.iter_mut() {
        for row in c.iter_mut() {
            for v in row.iter_mut() {
                *v /= scale;
            }
        }
    }
    // Only tets positive at the start can be protected (their limit energy is finite there).
    let protect: Vec<bool> = if protect.is_empty() {
        Vec::new()
    } else {
        tets.iter()
            .zip(protect)
            .map(|(t, &p)| p && super::tet::is_positive(super::tet::det6(x, t)))
            .collect()
    };
    let (first, inc) = crate::mesh::topology::corner_incidence(nv, tets);
    let prob = Problem {
        tets,
        d,
        w: vol.iter().map(|v| v / total).collect(),
        fixed,
        theta: opts.theta,
        protect: &protect,
        start: first,
        inc,
    };
    let mut sc = Scratch {
        device: match device {
            Some(ctx) => Some(DeviceTets::new(ctx, prob.tets, &prob.d, &prob.w, nv)?),
            None => None,
        },
        ..Scratch::default()
    };
    let mut evals = 0usize;
    let inverted_pinned = tets
        .iter()
        .filter(|t| {
            t.iter().all(|&v| fixed[v as usize]) && !super::tet::is_positive(super::tet::det6(x, t))
        })
        .count();
    if inverted_pinned > 0 {
        if std::env::var_os("FOLDFREE_VOL_TRACE").is_some() {
            eprintln!("untangle: {inverted_pinned} inverted tet(s) with all corners fixed");
        }
        return Ok(UntangleStats {
            inverted: tets
                .iter()
                .filter(|t| !super::tet::is_positive(super::tet::det6(x, t)))
                .count(),
            inverted_pinned,
            seconds: start.elapsed().as_secs_f64(),
            ..Default::default()
        });
    }
    // Step scale of the first L-BFGS step: the map's size, not the rest shape's.
    let diag = super::tet::bbox_diagonal(x);
    let trace = std::env::var_os("FOLDFREE_VOL_TRACE").is_some();
    let min_det = |x: &[[f64; 3]]| prob.dets(x).into_iter().fold(f64::INFINITY, f64::min);
    let mut detmin = min_det(x);
    if detmin > 0.0 {
        // Nothing to untangle; minimising f_ε anyway would only trade the start's distortion
        // for this energy's (the post-optimisation minimises the measured one).
        return Ok(UntangleStats {
            min_det: detmin,
            energy: prob.value(x, 1e-10, &mut sc)?,
            eps: 1e-10,
            seconds: start.elapsed().as_secs_f64(),
            ..Default::default()
        });
    }
    // The paper's first ε: small when nothing is inverted, else of the order of the worst det.
    let mut eps = (1e-12 + 0.04 * detmin.min(0.0).powi(2)).sqrt();
    let mut stats = UntangleStats::default();
    let lbfgs = LbfgsOptions {
        memory: opts.history,
        max_iterations: opts.max_inner,
        gradient_tolerance: None,
        rel_decrease: opts.inner_rel_tol,
        curvature_rel: 1e-16,
        curvature_abs: 1e-16 * f64::MIN_POSITIVE,
    };
    // (inverted tets, ε) when the count last dropped: the stall test.
    let mut best = (usize::MAX, eps);
    for outer in 0..opts.max_outer {
        stats.outer = outer + 1;
        let mut f = AtEps {
            prob: &prob,
            eps,
            sc: &mut sc,
            sliding: &sliding,
            diag,
        };
        let r = minimise(&mut f, bytemuck::cast_slice_mut(x), &lbfgs)?;
        let (e, e_prev) = (r.energy, r.initial_energy);
        stats.iterations += r.iterations;
        evals += r.evaluations;
        let dets = prob.dets(x);
        detmin = dets.iter().copied().fold(f64::INFINITY, f64::min);
        let inverted = dets
            .iter()
            .filter(|d| !super::tet::is_positive(**d))
            .count();
        if inverted < best.0 {
            best = (inverted, eps);
        } else if inverted > 0 && eps < best.1 * 10f64.powf(-opts.stall_decades) {
            if trace {
                eprintln!(
                    "untangle: stalled, {inverted} inverted since ε {:.3e} (now {eps:.3e})",
                    best.1
                );
            }
            break;
        }
        // The paper's ε update: aim for χ(detmin) to shrink by the achieved relative decrease.
        eps = next_eps(e, e_prev, detmin, chi(detmin, eps).0);
        stats.energy = e;
        if trace {
            eprintln!(
                "untangle outer {outer}: E {e:.6e} min det {detmin:.3e} ε {eps:.3e} steps {} evaluations {evals}",
                stats.iterations
            );
        }
        if detmin > 0.0 && (e_prev - e).abs() <= opts.rel_tol * e.abs() {
            break;
        }
    }
    let dets = prob.dets(x);
    stats.min_det = detmin;
    stats.inverted = dets
        .iter()
        .filter(|d| !super::tet::is_positive(**d))
        .count();
    stats.eps = eps;
    stats.seconds = start.elapsed().as_secs_f64();
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_matches_finite_differences_including_inverted() {
        let js = [
            [[1.2, 0.1, -0.3], [0.2, 0.9, 0.1], [0.0, 0.4, 1.1]],
            [[-1.0, 0.2, 0.1], [0.3, 1.0, 0.0], [0.1, 0.0, 0.8]],
            [[0.5, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, -1e-3]],
        ];
        for eps in [1e-1, 1e-3] {
            for j in &js {
                let (_, g) = untangle_energy(j, eps, 0.5);
                for a in 0..9 {
                    let h = 1e-7;
                    let mut p = *j;
                    let mut m = *j;
                    p[a / 3][a % 3] += h;
                    m[a / 3][a % 3] -= h;
                    let fd = (untangle_energy(&p, eps, 0.5).0 - untangle_energy(&m, eps, 0.5).0)
                        / (2.0 * h);
                    let scale = 1.0 + g[a / 3][a % 3].abs();
                    assert!(
                        (fd - g[a / 3][a % 3]).abs() < 1e-4 * scale,
                        "ε {eps} entry {a}: fd {fd} analytic {}",
                        g[a / 3][a % 3]
                    );
                }
            }
        }
    }

    #[test]
    fn chi_is_positive_and_stable_for_negative_det() {
        let (c, dc) = chi(-1e8, 1e-3);
        assert!(c > 0.0 && c.is_finite() && dc > 0.0);
        let (c, _) = chi(2.0, 1e-12);
        assert!((c - 2.0).abs() < 1e-12);
    }
}
