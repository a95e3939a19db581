//! Stage 4: make every region exactly planar while keeping region boundaries straight.
//!
//!   min ‖V − V*‖² + α‖∇V_B‖₀  s.t.  ⟨N_c, v⟩ + d_c = 0 for every vertex v of region c,
//!
//! where ∇V_B is the second difference v − (a+b)/2 along region-boundary curves (a vertex
//! with exactly two region-boundary edges a–v–b): its L0 norm counts the points where a
//! boundary turns, so minimising it straightens boundaries between corners. Planes are PCA
//! fits of their region's vertices, refit every round. ALM with p = ∇V_B and multipliers for
//! both the split and the plane constraints:
//!   p-step: w = ∇V_B + λ₁/β₁;  p = 0 if 2α/β₁ > ‖w‖², else p = w (hard threshold);
//!   V-step: (2I + β₁GᵀG + β₂Σ N_cN_cᵀ) V = 2V* + β₁Gᵀ(p − λ₁/β₁) − Σ N_c(β₂d_c + μ_vc), by CG;
//!   λ₁ += β₁(GV − p), μ_vc += β₂(⟨N_c,v⟩ + d_c), β ← κβ.
//! A vertex shared by several regions carries one constraint per region, so it ends on their
//! common line or corner.
//!
//! The ALM drives the constraint violation down but not to round-off, so the stage ends with
//! alternating projections: each vertex goes to the nearest point satisfying all its planes
//! (least squares when more than three planes meet, which is generally inconsistent), then the
//! planes are refit; the planes then rotate until they share such corners. Iterates until the
//! worst vertex–plane distance is below the tolerance or the round cap, and reports the worst.

use sprs::{CsMat, TriMat};

use super::cluster::vertex_clusters;
use super::geom::{
    add, face_area_normal, fit_plane, mean_edge_length, scale, solve_dense, sub, Plane, V3,
};
use super::sparse::{solve_spd, spmv};
use crate::linalg::SolveError;
use crate::mesh::{Topology, TriMesh, NO_FACE};

/// Parameters of [`planarize`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BoundaryL0Options {
    /// L0 weight (positions in units of the mean edge length).
    pub alpha: f64,
    pub beta1_0: f64,
    pub beta2_0: f64,
    pub kappa: f64,
    /// ALM stops when β₂ exceeds this.
    pub beta2_max: f64,
    /// Target for the worst vertex–plane distance, relative to the bounding-box diagonal.
    pub tolerance_rel: f64,
    /// Cap on projection/refit rounds.
    pub max_projection_rounds: usize,
}

impl Default for BoundaryL0Options {
    fn default() -> Self {
        BoundaryL0Options {
            alpha: 0.005,
            beta1_0: 0.1,
            beta2_0: 1.0,
            kappa: 2.0,
            beta2_max: 1e4,
            tolerance_rel: 1e-7,
            max_projection_rounds: 3000,
        }
    }
}

/// What [`planarize`] produced.
#[derive(Clone, Debug)]
pub struct Planarized {
    pub positions: Vec<V3>,
    /// One plane per region (refit on `positions`); `None` for an empty region.
    pub planes: Vec<Option<Plane>>,
    /// Worst |⟨N_c, v⟩ + d_c| over (vertex, region) pairs, in the mesh's units.
    pub max_violation: f64,
    pub alm_rounds: usize,
    pub projection_rounds: usize,
    /// Boundary-curve vertices whose second difference survived the last threshold (turns).
    pub turning_vertices: usize,
    /// Vertices on more than three regions (their constraints are over-determined).
    pub vertices_on_4plus: usize,
    /// Vertices on ≥4 regions still above the tolerance at the end.
    pub unresolved_4plus: usize,
    /// Vertices on ≤3 regions still above the tolerance at the end.
    pub unresolved_other: usize,
}

/// Planes of all regions fitted to their vertices, oriented like their faces.
pub fn fit_planes(
    pos: &[V3],
    faces: &[[u32; 3]],
    face_cluster: &[u32],
    members: &[Vec<u32>],
) -> Vec<Option<Plane>> {
    let mut orient = vec![[0.0; 3]; members.len()];
    for (f, &face) in faces.iter().enumerate() {
        let c = face_cluster[f] as usize;
        orient[c] = add(orient[c], face_area_normal(pos, face));
    }
    members
        .iter()
        .zip(&orient)
        .map(|(vs, &o)| fit_plane(vs.iter().map(|&v| (pos[v as usize], 1.0)), o))
        .collect()
}

/// Region-boundary second-difference rows (v, a, b): vertices with exactly two region-boundary
/// edges.
fn chain_rows(topo: &Topology, face_cluster: &[u32]) -> Vec<[usize; 3]> {
    let mut inc: Vec<Vec<usize>> = vec![Vec::new(); topo.n_vertices];
    for (e, ef) in topo.edge_faces.iter().enumerate() {
        let is_b = ef[1] == NO_FACE || face_cluster[ef[0] as usize] != face_cluster[ef[1] as usize];
        if is_b {
            let [a, b] = topo.edges[e].map(|v| v as usize);
            inc[a].push(b);
            inc[b].push(a);
        }
    }
    inc.iter()
        .enumerate()
        .filter(|(_, n)| n.len() == 2)
        .map(|(v, n)| [v, n[0], n[1]])
        .collect()
}

/// Nearest point to `x0` on the planes `ps` (least squares when inconsistent): Tikhonov-damped
/// normal equations (NᵀN + εI)x = −Nᵀd + εx0, whose ε→0 limit is the projection.
pub(crate) fn project(x0: V3, ps: &[Plane], eps: f64) -> Option<V3> {
    // Relative to x0 for accuracy: x = x0 + δ, (NᵀN + εI)δ = −Nᵀ(Nx0 + d).
    let mut a = [0.0; 9];
    let mut b = [0.0; 3];
    for i in 0..3 {
        a[i * 3 + i] = eps;
    }
    for p in ps {
        let r = p.signed_distance(x0);
        for i in 0..3 {
            b[i] -= p.n[i] * r;
            for j in 0..3 {
                a[i * 3 + j] += p.n[i] * p.n[j];
            }
        }
    }
    solve_dense(&mut a, &mut b, 3)?;
    Some(add(x0, b))
}

/// Runs the ALM and the final projections on `mesh.positions` (V*) with the given partition.
pub fn planarize(
    mesh: &TriMesh,
    topo: &Topology,
    face_cluster: &[u32],
    n_clusters: usize,
    diag: f64,
    opts: &BoundaryL0Options,
) -> Result<Planarized, SolveError> {
    let n = mesh.positions.len();
    let vc = vertex_clusters(topo, face_cluster);
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); n_clusters];
    for (v, cs) in vc.iter().enumerate() {
        for &c in cs {
            members[c as usize].push(v as u32);
        }
    }
    // Normalised coordinates: centred, in units of the mean edge length, so α and β are
    // scale-free.
    let s = mean_edge_length(&mesh.positions, &topo.edges).max(f64::MIN_POSITIVE);
    let c0 = {
        let mut c = [0.0; 3];
        for p in &mesh.positions {
            c = add(c, *p);
        }
        scale(c, 1.0 / n.max(1) as f64)
    };
    let vstar: Vec<V3> = mesh
        .positions
        .iter()
        .map(|&p| scale(sub(p, c0), 1.0 / s))
        .collect();
    let mut y = vstar.clone();
    let rows = chain_rows(topo, face_cluster);
    // G (rows·3 × 3n).
    let g: CsMat<f64> = {
        let mut t = TriMat::new((rows.len() * 3, 3 * n));
        for (r, &[v, a, b]) in rows.iter().enumerate() {
            for k in 0..3 {
                t.add_triplet(3 * r + k, 3 * v + k, 1.0);
                t.add_triplet(3 * r + k, 3 * a + k, -0.5);
                t.add_triplet(3 * r + k, 3 * b + k, -0.5);
            }
        }
        t.to_csr()
    };
    let gt = g.transpose_view().to_csr();
    let gtg = &gt * &g;
    let pairs: Vec<(usize, usize)> = vc
        .iter()
        .enumerate()
        .flat_map(|(v, cs)| cs.iter().map(move |&c| (v, c as usize)))
        .collect();
    let mut mu = vec![0.0; pairs.len()];
    let mut lam = vec![0.0; rows.len() * 3];
    let mut p = vec![0.0; rows.len() * 3];
    let (mut beta1, mut beta2) = (opts.beta1_0, opts.beta2_0);
    let mut alm_rounds = 0;
    let mut turning = 0;
    let flat = |y: &[V3]| -> Vec<f64> { y.iter().flat_map(|v| v.iter().copied()).collect() };
    while beta2 <= opts.beta2_max {
        alm_rounds += 1;
        let planes = fit_planes(&y, &mesh.faces, face_cluster, &members);
        // p-step.
        let yf = flat(&y);
        let gv = spmv(&g, &yf);
        turning = 0;
        for r in 0..rows.len() {
            let w: [f64; 3] = [0, 1, 2].map(|k| gv[3 * r + k] + lam[3 * r + k] / beta1);
            let w2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
            let keep = 2.0 * opts.alpha / beta1 <= w2;
            for k in 0..3 {
                p[3 * r + k] = if keep { w[k] } else { 0.0 };
            }
            turning += usize::from(keep);
        }
        // V-step.
        let mut t = TriMat::new((3 * n, 3 * n));
        let mut rhs: Vec<f64> = flat(&vstar).iter().map(|v| 2.0 * v).collect();
        for i in 0..3 * n {
            t.add_triplet(i, i, 2.0);
        }
        for (idx, &(v, c)) in pairs.iter().enumerate() {
            let Some(pl) = planes[c] else { continue };
            for i in 0..3 {
                for j in 0..3 {
                    t.add_triplet(3 * v + i, 3 * v + j, beta2 * pl.n[i] * pl.n[j]);
                }
                rhs[3 * v + i] -= pl.n[i] * (beta2 * pl.d + mu[idx]);
            }
        }
        let q: Vec<f64> = (0..p.len()).map(|i| beta1 * p[i] - lam[i]).collect();
        for (r, v) in rhs.iter_mut().zip(spmv(&gt, &q)) {
            *r += v;
        }
        let a: CsMat<f64> = t.to_csr::<usize>();
        let a = &a + &gtg.map(|v| beta1 * v);
        let mut x = vec![yf];
        solve_spd(&a, &[rhs], &mut x, 1e-10)?;
        let x = &x[0];
        for v in 0..n {
            y[v] = [x[3 * v], x[3 * v + 1], x[3 * v + 2]];
        }
        // Multipliers.
        let gv = spmv(&g, x);
        for i in 0..lam.len() {
            lam[i] += beta1 * (gv[i] - p[i]);
        }
        for (idx, &(v, c)) in pairs.iter().enumerate() {
            if let Some(pl) = planes[c] {
                mu[idx] += beta2 * pl.signed_distance(y[v]);
            }
        }
        beta1 *= opts.kappa;
        beta2 *= opts.kappa;
    }
    if y.iter().any(|p| p.iter().any(|c| !c.is_finite())) {
        return Err(SolveError::NonFinite {
            what: "boundary L0 solve".into(),
        });
    }

    // Alternating projection / refit, in the mesh's own units for an honest tolerance.
    let mut x: Vec<V3> = y.iter().map(|&q| add(c0, scale(q, s))).collect();
    let tol = opts.tolerance_rel * diag;
    let eps = 1e-12;
    let mut planes = fit_planes(&x, &mesh.faces, face_cluster, &members);
    let mut rounds = 0;
    let violation = |x: &[V3], planes: &[Option<Plane>], v: usize| -> f64 {
        vc[v]
            .iter()
            .filter_map(|&c| planes[c as usize].map(|p| p.signed_distance(x[v]).abs()))
            .fold(0.0, f64::max)
    };
    let mut worst = (0..n)
        .map(|v| violation(&x, &planes, v))
        .fold(0.0, f64::max);
    let mut ps: Vec<Plane> = Vec::new();
    while worst > tol && rounds < opts.max_projection_rounds {
        rounds += 1;
        for v in 0..n {
            if vc[v].is_empty() {
                continue;
            }
            ps.clear();
            ps.extend(vc[v].iter().filter_map(|&c| planes[c as usize]));
            if let Some(q) = project(x[v], &ps, eps) {
                x[v] = q;
            }
        }
        planes = fit_planes(&x, &mesh.faces, face_cluster, &members);
        worst = (0..n)
            .map(|v| violation(&x, &planes, v))
            .fold(0.0, f64::max);
    }
    let over: Vec<usize> = (0..n)
        .filter(|&v| violation(&x, &planes, v) > tol)
        .collect();
    let unresolved_4plus = over.iter().filter(|&&v| vc[v].len() > 3).count();
    Ok(Planarized {
        max_violation: worst,
        planes,
        alm_rounds,
        projection_rounds: rounds,
        turning_vertices: turning,
        vertices_on_4plus: vc.iter().filter(|c| c.len() > 3).count(),
        unresolved_4plus,
        unresolved_other: over.len() - unresolved_4plus,
        positions: x,
    })
}
