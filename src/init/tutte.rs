//! Tutte embedding: boundary pinned to a convex polygon, every interior vertex a convex
//! combination of its neighbours.
//!
//! W. T. Tutte, "How to draw a graph", Proc. London Math. Soc. 13 (1963): with positive
//! weights and a convex boundary the map is a bijection (no flipped triangles) — exactly, and
//! up to round-off for our f64 solve. M. S. Floater, "Mean value coordinates", CAGD 20 (2003):
//! the mean-value weights are positive for any star-shaped 1-ring and reproduce planar meshes,
//! so they distort less than the uniform (barycentric) weights while keeping the guarantee.
//!
//! Boundary: the loop is laid on the unit circle by cumulative 3D arc length, in loop order,
//! so a counter-clockwise mesh gives a counter-clockwise map (checked, and mirrored if not).
//!
//! Solvers: uniform weights give the graph Laplacian restricted to the interior (symmetric
//! positive definite, boundary moved to the right-hand side): CG. Mean-value weights are not
//! symmetric: each row is normalised to a convex combination (u_i − Σ_j λ_ij u_j = 0,
//! Σ_j λ_ij = 1), a diagonally dominant M-matrix: BiCGSTAB. [`tutte`] factors the uniform
//! system by sparse Cholesky ([`crate::linalg::direct`], both UV columns in one solve: one
//! factorisation serves both right-hand sides, where CG iterates twice; BENCHMARKS.md issue
//! 26 has the per-solve measurement); [`tutte_report`] and the
//! mean-value system use the Krylov solvers, preconditioned by algebraic multigrid by default
//! (about 20 iterations at 125k interior vertices), both UV columns solved in parallel.
#![forbid(unsafe_code)]

use sprs::TriMat;

use super::vec3::{cross, dot, norm, sub};
use super::{
    check_input, count_flips, default_solve_options, orient_ccw, unique_edges, unreached,
    InitReport,
};
use crate::linalg::direct::{Cholesky, LinearSolver};
use crate::linalg::krylov::{bicgstab_multi, pcg_multi, CgOptions};
use crate::linalg::sparse::relative_residual;
use crate::linalg::SolveError;

/// Edge weights of the Tutte embedding.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TutteWeights {
    /// w_ij = 1 for every edge (Tutte's barycentric map; symmetric system).
    #[default]
    Uniform,
    /// Floater's mean-value weights w_ij = (tan(α_ij/2) + tan(β_ij/2)) / |p_i − p_j|, the
    /// angles at p_i on either side of edge ij (non-symmetric system).
    MeanValue,
}

/// Tutte embedding of a disk-topology mesh: uniform weights by sparse Cholesky, mean-value
/// weights by BiCGSTAB with the default options.
///
/// `positions`: #V×3; `faces`: #F×3, counter-clockwise; `boundary`: the boundary loop as an
/// ordered vertex cycle in the direction the faces traverse it. Returns #V×2 UVs; the
/// boundary lies on the unit circle, unused vertices get (0, 0).
pub fn tutte(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    boundary: &[u32],
    weights: TutteWeights,
) -> Result<Vec<[f64; 2]>, SolveError> {
    tutte_solve(
        positions,
        faces,
        boundary,
        weights,
        LinearSolver::Cholesky,
        &default_solve_options(),
    )
    .map(|r| r.uv)
}

/// [`tutte`] with explicit solver options, also returning the flip count and solve statistics
/// (flips can only come from round-off, degenerate input or a non-disk mesh). Solved by the
/// Krylov solvers (CG, BiCGSTAB for mean-value weights) with `opts`.
pub fn tutte_report(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    boundary: &[u32],
    weights: TutteWeights,
    opts: &CgOptions,
) -> Result<InitReport, SolveError> {
    tutte_solve(positions, faces, boundary, weights, LinearSolver::Pcg, opts)
}

/// [`tutte_report`] with the solver of the uniform (symmetric) system chosen.
fn tutte_solve(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    boundary: &[u32],
    weights: TutteWeights,
    solver: LinearSolver,
    opts: &CgOptions,
) -> Result<InitReport, SolveError> {
    let n = positions.len();
    let used = check_input(positions, faces, boundary)?;
    let mut uv = vec![[0.0; 2]; n];
    place_boundary_on_circle(positions, boundary, &mut uv);

    // Interior unknowns: vertices used by a face and not on the boundary.
    let mut on_boundary = vec![false; n];
    for &b in boundary {
        on_boundary[b as usize] = true;
    }
    let mut index = vec![u32::MAX; n];
    let mut interior = Vec::new();
    for v in 0..n {
        if used[v] && !on_boundary[v] {
            index[v] = interior.len() as u32;
            interior.push(v as u32);
        }
    }
    let edges = unique_edges(faces);
    let lost = unreached(n, &edges, &used, boundary);
    if lost > 0 {
        return Err(SolveError::InvalidInput { what: format!("{lost} vertices lie in components that do not touch the boundary loop (the mesh is not one disk)") });
    }
    let m = interior.len();
    let mut report = InitReport {
        uv: Vec::new(),
        flips: 0,
        iterations: 0,
        relative_residual: 0.0,
        preconditioner: opts.preconditioner,
    };
    if m > 0 {
        let mut tri = TriMat::new((m, m));
        let mut rhs = vec![vec![0.0; m]; 2];
        // Adds the term w·(x_i − x_j) of interior row i.
        let mut add = |tri: &mut TriMat<f64>, i: usize, j: usize, w: f64| {
            let ri = index[i] as usize;
            tri.add_triplet(ri, ri, w);
            if index[j] != u32::MAX {
                tri.add_triplet(ri, index[j] as usize, -w);
            } else {
                rhs[0][ri] += w * uv[j][0];
                rhs[1][ri] += w * uv[j][1];
            }
        };
        match weights {
            TutteWeights::Uniform => {
                for e in &edges {
                    let (a, b) = (e[0] as usize, e[1] as usize);
                    if index[a] != u32::MAX {
                        add(&mut tri, a, b, 1.0);
                    }
                    if index[b] != u32::MAX {
                        add(&mut tri, b, a, 1.0);
                    }
                }
            }
            TutteWeights::MeanValue => {
                let (row_sum, corner_w) = mean_value_corner_weights(positions, faces, &index);
                for (f, face) in faces.iter().enumerate() {
                    for c in 0..3 {
                        let i = face[c] as usize;
                        if index[i] == u32::MAX {
                            continue;
                        }
                        let ri = index[i] as usize;
                        let [wj, wk] = corner_w[3 * f + c];
                        let (j, k) = (face[(c + 1) % 3] as usize, face[(c + 2) % 3] as usize);
                        // λ_ij = w_ij / Σ_j w_ij: each row a convex combination (diagonal 1).
                        add(&mut tri, i, j, wj / row_sum[ri]);
                        add(&mut tri, i, k, wk / row_sum[ri]);
                    }
                }
            }
        }
        let a = tri.to_csr();
        let mut x = vec![vec![0.0; m]; 2];
        if weights == TutteWeights::Uniform && solver == LinearSolver::Cholesky {
            // Symmetric positive definite: one factorisation, both UV columns in one solve.
            let mut both: Vec<f64> = rhs.concat();
            Cholesky::new(&a)?.solve_many_in_place(&mut both, 2)?;
            for c in 0..2 {
                x[c].copy_from_slice(&both[c * m..(c + 1) * m]);
                report.relative_residual = report
                    .relative_residual
                    .max(relative_residual(&a, &rhs[c], &x[c]));
            }
        } else {
            let stats = match weights {
                TutteWeights::Uniform => pcg_multi(&a, &rhs, &mut x, opts)?,
                TutteWeights::MeanValue => bicgstab_multi(&a, &rhs, &mut x, opts)?,
            };
            report.iterations = stats.iter().map(|s| s.iterations).max().unwrap_or(0);
            report.relative_residual = stats
                .iter()
                .map(|s| s.relative_residual)
                .fold(0.0, f64::max);
            report.preconditioner = stats
                .first()
                .map_or(opts.preconditioner, |s| s.preconditioner);
        }
        for (r, &v) in interior.iter().enumerate() {
            uv[v as usize] = [x[0][r], x[1][r]];
        }
    }
    orient_ccw(faces, &mut uv);
    report.flips = count_flips(faces, &uv);
    report.uv = uv;
    Ok(report)
}

/// Boundary vertex k goes to angle θ_k = 2π·s_k/L on the unit circle, s_k the 3D arc length
/// from boundary[0] along the loop and L the loop length (equal spacing if L = 0).
fn place_boundary_on_circle(positions: &[[f64; 3]], boundary: &[u32], uv: &mut [[f64; 2]]) {
    let nb = boundary.len();
    let mut s = Vec::with_capacity(nb);
    let mut acc = 0.0;
    for k in 0..nb {
        s.push(acc);
        let (a, b) = (boundary[k] as usize, boundary[(k + 1) % nb] as usize);
        acc += norm(sub(positions[b], positions[a]));
    }
    let total = acc;
    for (k, &v) in boundary.iter().enumerate() {
        let t = if total > 0.0 {
            s[k] / total
        } else {
            k as f64 / nb as f64
        };
        let (sin, cos) = (std::f64::consts::TAU * t).sin_cos();
        uv[v as usize] = [cos, sin];
    }
}

/// Floater's mean-value weights, per face corner: for corner i of a face with next vertices
/// j, k, the contributions tan(α/2)/|p_j − p_i| to w_ij and tan(α/2)/|p_k − p_i| to w_ik,
/// α the corner angle. Returns the row sums Σ_j w_ij (indexed by interior index) and the
/// #F×3 corner pairs.
///
/// Rows with a degenerate corner (zero-length edge, non-finite weight, zero row sum) fall
/// back to uniform weights (each corner contributes 1 to both its edges) so that one bad
/// triangle does not make the system singular; the row stays a convex combination.
fn mean_value_corner_weights(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    index: &[u32],
) -> (Vec<f64>, Vec<[f64; 2]>) {
    let m = index.iter().filter(|&&r| r != u32::MAX).count();
    let mut corner_w = vec![[0.0; 2]; 3 * faces.len()];
    let mut bad = vec![false; m];
    for (f, face) in faces.iter().enumerate() {
        for c in 0..3 {
            let i = face[c] as usize;
            if index[i] == u32::MAX {
                continue;
            }
            let (pi, pj, pk) = (
                positions[i],
                positions[face[(c + 1) % 3] as usize],
                positions[face[(c + 2) % 3] as usize],
            );
            let (a, b) = (sub(pj, pi), sub(pk, pi));
            let (la, lb) = (norm(a), norm(b));
            // tan(α/2) = sin α / (1 + cos α) = |a × b| / (|a||b| + a·b)
            let tan_half = norm(cross(a, b)) / (la * lb + dot(a, b));
            let w = [tan_half / la, tan_half / lb];
            if w.iter().all(|x| x.is_finite() && *x >= 0.0) {
                corner_w[3 * f + c] = w;
            } else {
                bad[index[i] as usize] = true;
            }
        }
    }
    let mut row_sum = vec![0.0; m];
    for (f, face) in faces.iter().enumerate() {
        for c in 0..3 {
            let r = index[face[c] as usize];
            if r != u32::MAX {
                row_sum[r as usize] += corner_w[3 * f + c][0] + corner_w[3 * f + c][1];
            }
        }
    }
    for r in 0..m {
        if !(row_sum[r].is_finite() && row_sum[r] > 0.0) {
            bad[r] = true;
        }
    }
    if bad.iter().any(|&b| b) {
        for r in row_sum.iter_mut() {
            *r = 0.0;
        }
        for (f, face) in faces.iter().enumerate() {
            for c in 0..3 {
                let r = index[face[c] as usize];
                if r != u32::MAX && bad[r as usize] {
                    corner_w[3 * f + c] = [1.0, 1.0];
                }
                if r != u32::MAX {
                    row_sum[r as usize] += corner_w[3 * f + c][0] + corner_w[3 * f + c][1];
                }
            }
        }
    }
    (row_sum, corner_w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::init::test_grid::{bumpy, id, max_diff};

    /// A bumpy disk-like grid: Cholesky and multigrid CG give the same uniform Tutte map.
    #[test]
    fn cholesky_and_pcg_agree() {
        let k = 10;
        let (p, f) = bumpy(k, |x, y| 0.2 * (4.0 * x * y).sin());
        let id = |i, j| id(k, i, j);
        // Counter-clockwise boundary loop.
        let mut boundary: Vec<u32> = (0..k).map(|i| id(i, 0)).collect();
        boundary.extend((0..k).map(|j| id(k, j)));
        boundary.extend((0..k).map(|i| id(k - i, k)));
        boundary.extend((0..k).map(|j| id(0, k - j)));
        let opts = default_solve_options();
        let a = tutte_solve(
            &p,
            &f,
            &boundary,
            TutteWeights::Uniform,
            LinearSolver::Cholesky,
            &opts,
        )
        .unwrap();
        let b = tutte_report(&p, &f, &boundary, TutteWeights::Uniform, &opts).unwrap();
        assert_eq!(a.flips, 0);
        assert_eq!(a.iterations, 0);
        assert!(a.relative_residual < 1e-12, "{}", a.relative_residual);
        let diff = max_diff(&a.uv, &b.uv);
        assert!(diff < 1e-9, "{diff}");
    }
}
