//! Stage 1: L0 smoothing of face normals, min ‖N − N*‖² + α‖∇N‖₀ with the edge gradient
//! ∇N_e = (|e|/l̄)(n_f − n_g) over interior edges. The L0 term makes normals piecewise
//! constant (flat regions separated by sharp creases), which is what the clustering needs;
//! an L2 or L1 smoother would round the creases.
//!
//! Augmented Lagrangian with the split p = ∇N: the p-step is a per-edge hard threshold, the
//! N-step the SPD system (2I + β DᵀD) N = 2N* + β Dᵀ(p − λ/β), solved by CG for the three
//! columns; then λ ← λ + β(DN − p) and β ← κβ.

use sprs::{CsMat, TriMat};

use super::geom::{dot, mean_edge_length, normalize, V3};
use super::sparse::{solve_factored, SpdSolver};
use crate::linalg::sparse::CsrOps;
use crate::linalg::SolveError;
use crate::mesh::{Topology, NO_FACE};

/// Parameters of [`smooth_normals`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct NormalL0Options {
    /// Weight of the L0 term: an edge keeps a jump |Δn|² only if smoothing it away costs more
    /// than α (edge lengths in units of the mean edge length).
    pub alpha: f64,
    /// Initial penalty β₀ (relative to α: β₀ = `beta0_rel`·α).
    pub beta0_rel: f64,
    /// Penalty growth per round.
    pub kappa: f64,
    /// Stop when β exceeds this.
    pub beta_max: f64,
}

impl Default for NormalL0Options {
    fn default() -> Self {
        NormalL0Options {
            alpha: 0.02,
            beta0_rel: 20.0,
            kappa: 2.0,
            beta_max: 1e4,
        }
    }
}

/// What [`smooth_normals`] produced.
#[derive(Clone, Debug)]
pub struct NormalL0Result {
    /// Unit normals, one per face.
    pub normals: Vec<V3>,
    /// Interior edges whose gradient survived the last threshold (the creases).
    pub crease_edges: usize,
    /// ALM rounds run.
    pub rounds: usize,
}

/// Edge-gradient operator D (#interior edges × #F): row e = w_e (f − g).
fn gradient(topo: &Topology, weights: &[f64], nf: usize) -> (CsMat<f64>, Vec<[usize; 2]>) {
    let mut t = TriMat::new((topo.interior_edges.len(), nf));
    let mut pairs = Vec::with_capacity(topo.interior_edges.len());
    for (r, &e) in topo.interior_edges.iter().enumerate() {
        let [f, g] = topo.edge_faces[e as usize];
        debug_assert!(g != NO_FACE);
        t.add_triplet(r, f as usize, weights[r]);
        t.add_triplet(r, g as usize, -weights[r]);
        pairs.push([f as usize, g as usize]);
    }
    (t.to_csr(), pairs)
}

/// Runs the ALM from the input normals `n0` (unit, one per face). `positions` give edge lengths.
pub fn smooth_normals(
    positions: &[V3],
    topo: &Topology,
    n0: &[V3],
    opts: &NormalL0Options,
) -> Result<NormalL0Result, SolveError> {
    let nf = n0.len();
    let ne = topo.interior_edges.len();
    let lbar = mean_edge_length(positions, &topo.edges);
    let weights: Vec<f64> = topo
        .interior_edges
        .iter()
        .map(|&e| {
            let [a, b] = topo.edges[e as usize];
            let d = super::geom::sub(positions[b as usize], positions[a as usize]);
            super::geom::norm(d) / lbar
        })
        .collect();
    let (d, pairs) = gradient(topo, &weights, nf);
    let dt = d.transpose_view().to_csr();
    let dtd = &dt * &d;
    let mut eye = TriMat::new((nf, nf));
    for i in 0..nf {
        eye.add_triplet(i, i, 2.0);
    }
    let eye: CsMat<f64> = eye.to_csr();

    // Column-major copies: x[k][f] = N_f[k].
    let mut n: Vec<Vec<f64>> = (0..3).map(|k| n0.iter().map(|v| v[k]).collect()).collect();
    let rhs0: Vec<Vec<f64>> = n
        .iter()
        .map(|c| c.iter().map(|v| 2.0 * v).collect())
        .collect();
    let mut p = vec![[0.0; 3]; ne];
    let mut lam = vec![[0.0; 3]; ne];
    let mut rounds = 0;
    let mut crease_edges = 0;
    let grad = |n: &Vec<Vec<f64>>, r: usize| -> V3 {
        let [f, g] = pairs[r];
        let w = weights[r];
        [0, 1, 2].map(|k| w * (n[k][f] - n[k][g]))
    };
    // The N-step's matrices depend on β alone, and the β schedule is fixed: they are factored
    // ahead, as many at a time as there are threads (the rounds themselves are sequential).
    let mut betas = Vec::new();
    let mut beta = opts.beta0_rel * opts.alpha;
    while beta <= opts.beta_max && ne > 0 {
        betas.push(beta);
        beta *= opts.kappa;
    }
    let mut spd = SpdSolver::default();
    for batch in betas.chunks(rayon::current_num_threads().max(1)) {
        let mats: Vec<CsMat<f64>> = batch
            .iter()
            .map(|&beta| &eye + &dtd.map(|v| beta * v))
            .collect();
        let factors = spd.factor_each(&mats);
        for ((&beta, a), factor) in batch.iter().zip(&mats).zip(&factors) {
            rounds += 1;
            // p-step: hard threshold of w = DN + λ/β.
            crease_edges = 0;
            for r in 0..ne {
                let g = grad(&n, r);
                let w = [0, 1, 2].map(|k| g[k] + lam[r][k] / beta);
                if dot(w, w) > 2.0 * opts.alpha / beta {
                    p[r] = w;
                    crease_edges += 1;
                } else {
                    p[r] = [0.0; 3];
                }
            }
            // N-step.
            let b: Vec<Vec<f64>> = (0..3)
                .map(|k| {
                    let q: Vec<f64> = (0..ne).map(|r| beta * p[r][k] - lam[r][k]).collect();
                    let mut dq = vec![0.0; nf];
                    dt.spmv(&q, &mut dq);
                    rhs0[k].iter().zip(dq.iter()).map(|(a, b)| a + b).collect()
                })
                .collect();
            solve_factored(factor.as_ref(), a, &b, &mut n, 1e-8)?;
            // Multipliers.
            for r in 0..ne {
                let g = grad(&n, r);
                for k in 0..3 {
                    lam[r][k] += beta * (g[k] - p[r][k]);
                }
            }
        }
    }
    let normals = (0..nf)
        .map(|f| normalize([n[0][f], n[1][f], n[2][f]]).unwrap_or(n0[f]))
        .collect();
    Ok(NormalL0Result {
        normals,
        crease_edges,
        rounds,
    })
}
