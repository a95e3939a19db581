//! Least-squares conformal map.
//!
//! B. Lévy, S. Petitjean, N. Ray, J. Maillot, "Least squares conformal maps for automatic
//! texture atlas generation", SIGGRAPH 2002 (equivalently the discrete conformal energy of
//! Desbrun, Meyer & Alliez 2002). The conformal energy of a piecewise-linear map (u, v) is
//! E_C = E_D − A: the Dirichlet energy ½∫|∇u|² + |∇v|² minus the signed UV area. It is ≥ 0,
//! zero exactly on similarities of a planar mesh, and quadratic: E_C = ½ xᵀQx with Q the
//! 2V×2V symmetric matrix [[L, −B], [B, L]] (L the cotangent Laplacian, B the antisymmetric
//! boundary-area form). Two pinned vertices remove the similarity null space; the rest is the
//! SPD system Q_ff x_f = −Q_fp x_p over u and v of each vertex interleaved (2i, 2i+1).
//! [`lscm`] solves it by sparse Cholesky ([`crate::linalg::direct`]); [`lscm_report`] and
//! [`lscm_pinned`] by CG with the given options (multigrid aggregating the pair as one node,
//! block size 2), whose iteration count grows with the boundary (the near-null space of the
//! conformal energy is every holomorphic map, not just constants), while the factor of a
//! planar-graph system under a fill-reducing ordering stays near-linear in size and its cost
//! does not depend on conditioning. Measured over all 61 disks of the sweep corpus (MIPS,
//! BENCHMARKS.md issue 26): the same maps, and the start-map time lower on all 61 (median 4.2×,
//! least 1.3×; sweeps of two sessions, not side by side).
//!
//! The area term is assembled per face (Σ over each triangle's directed edges); interior
//! edges cancel exactly, so holes need no special care. This is the start point of the ADMM
//! solver, so it is solved to a tight tolerance; it may still fold a few triangles on hard
//! meshes, which are returned as they are (counted in [`InitReport::flips`]).
#![forbid(unsafe_code)]

use sprs::{CsMat, TriMat};

use super::vec3::{cross, dot, norm, sub};
use super::{
    check_faces, check_input, count_flips, default_solve_options, orient_ccw, unique_edges,
    unreached, InitReport,
};
use crate::linalg::direct::{Cholesky, LinearSolver};
use crate::linalg::sparse::relative_residual;
use crate::linalg::SolveError;
use crate::linalg::{
    krylov::{pcg, CgOptions},
    precond::Preconditioner,
};

/// LSCM of a disk-topology mesh, solved by sparse Cholesky.
///
/// `positions`: #V×3; `faces`: #F×3, counter-clockwise; `boundary`: the boundary loop (used to
/// choose the two pins: the boundary vertex farthest from `boundary[0]`, then the one farthest
/// from that). The pins are placed at (0, 0) and (d, 0), d their 3D distance, so the map has
/// roughly the scale of the surface. Returns #V×2 UVs with positive total signed area;
/// unused vertices get (0, 0).
pub fn lscm(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    boundary: &[u32],
) -> Result<Vec<[f64; 2]>, SolveError> {
    check_input(positions, faces, boundary)?;
    lscm_solve(
        positions,
        faces,
        lscm_pins(positions, boundary),
        LinearSolver::Cholesky,
        &default_solve_options(),
    )
    .map(|r| r.uv)
}

/// The two pinned vertices: the boundary vertex farthest (in 3D) from `boundary[0]`, then the
/// boundary vertex farthest from that one — an approximate diameter of the boundary.
pub fn lscm_pins(positions: &[[f64; 3]], boundary: &[u32]) -> [u32; 2] {
    let farthest = |from: u32| -> u32 {
        let p = positions[from as usize];
        let mut best = (from, -1.0);
        for &b in boundary {
            let d = norm(sub(positions[b as usize], p));
            if d > best.1 {
                best = (b, d);
            }
        }
        best.0
    };
    let a = farthest(boundary[0]);
    [a, farthest(a)]
}

/// [`lscm`] solved by preconditioned CG with explicit options, also returning the flip count
/// and solve statistics.
pub fn lscm_report(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    boundary: &[u32],
    opts: &CgOptions,
) -> Result<InitReport, SolveError> {
    check_input(positions, faces, boundary)?;
    lscm_pinned(positions, faces, lscm_pins(positions, boundary), opts)
}

/// LSCM with the two pinned vertices given (`pins[0]` goes to (0, 0), `pins[1]` to (d, 0)).
/// Pins need not lie on the boundary, but boundary pins give the least distorted maps.
/// Solved by preconditioned CG with `opts`.
pub fn lscm_pinned(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    pins: [u32; 2],
    opts: &CgOptions,
) -> Result<InitReport, SolveError> {
    lscm_solve(positions, faces, pins, LinearSolver::Pcg, opts)
}

/// [`lscm_pinned`] with the linear solver chosen (`opts` only matter for PCG).
fn lscm_solve(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    pins: [u32; 2],
    solver: LinearSolver,
    opts: &CgOptions,
) -> Result<InitReport, SolveError> {
    let n = positions.len();
    let [pa, pb] = pins;
    let used = check_faces(positions, faces)?;
    if pins.iter().any(|&p| p as usize >= n || !used[p as usize]) {
        return Err(SolveError::InvalidInput {
            what: format!("pinned vertices {pins:?} must be vertices of some face"),
        });
    }
    let d = norm(sub(positions[pb as usize], positions[pa as usize]));
    if pa == pb || d.is_nan() || d <= 0.0 {
        return Err(SolveError::InvalidInput {
            what: "LSCM needs two distinct pinned vertices at positive distance".into(),
        });
    }
    let lost = unreached(n, &unique_edges(faces), &used, &[pa, pb]);
    if lost > 0 {
        return Err(SolveError::InvalidInput { what: format!("{lost} vertices lie in components without a pinned vertex (the mesh is not connected)") });
    }
    // Unknowns: u of free vertex r at 2r, v at 2r + 1.
    let mut index = vec![u32::MAX; n];
    let mut free = Vec::new();
    for v in 0..n {
        if used[v] && v as u32 != pa && v as u32 != pb {
            index[v] = free.len() as u32;
            free.push(v as u32);
        }
    }
    let mut pinned_uv = vec![[0.0; 2]; n];
    pinned_uv[pb as usize] = [d, 0.0];
    let m = 2 * free.len();
    let mut tri = TriMat::with_capacity((m, m), 30 * faces.len());
    let mut rhs = vec![0.0; m];
    // Adds q to Q[(vertex i, coordinate ci)][(vertex j, coordinate cj)] (ci, cj: 0 = u, 1 = v).
    let mut add = |tri: &mut TriMat<f64>, i: usize, ci: usize, j: usize, cj: usize, q: f64| {
        if index[i] == u32::MAX {
            return;
        }
        let row = 2 * index[i] as usize + ci;
        if index[j] != u32::MAX {
            tri.add_triplet(row, 2 * index[j] as usize + cj, q);
        } else {
            // Pinned column moves to the right-hand side: b_f −= Q_fp x_p.
            rhs[row] -= q * pinned_uv[j][cj];
        }
    };
    for face in faces {
        let v = [face[0] as usize, face[1] as usize, face[2] as usize];
        let p = [positions[v[0]], positions[v[1]], positions[v[2]]];
        let area2 = norm(cross(sub(p[1], p[0]), sub(p[2], p[0])));
        let longest2 = (0..3)
            .map(|c| dot(sub(p[(c + 1) % 3], p[c]), sub(p[(c + 1) % 3], p[c])))
            .fold(0.0, f64::max);
        // Dirichlet part, skipped on (numerically) zero-area faces whose cotangents blow up:
        // ½∫_T|∇u|² = ¼ Σ_k cot θ_k (u_i − u_j)², θ_k the angle opposite edge ij.
        if area2 > 1e-14 * longest2 {
            for k in 0..3 {
                let (i, j) = (v[(k + 1) % 3], v[(k + 2) % 3]);
                let (a, b) = (sub(p[(k + 1) % 3], p[k]), sub(p[(k + 2) % 3], p[k]));
                // w = ½ cot θ_k = ½ (a·b)/|a×b|
                let w = 0.5 * dot(a, b) / area2;
                for c in 0..2 {
                    add(&mut tri, i, c, i, c, w);
                    add(&mut tri, j, c, j, c, w);
                    add(&mut tri, i, c, j, c, -w);
                    add(&mut tri, j, c, i, c, -w);
                }
            }
        }
        // Area part: −A_T = −½ Σ_{directed edges a→b} (u_a v_b − u_b v_a).
        for k in 0..3 {
            let (a, b) = (v[k], v[(k + 1) % 3]);
            add(&mut tri, a, 0, b, 1, -0.5);
            add(&mut tri, b, 1, a, 0, -0.5);
            add(&mut tri, b, 0, a, 1, 0.5);
            add(&mut tri, a, 1, b, 0, 0.5);
        }
    }
    let mut uv = vec![[0.0; 2]; n];
    uv[pb as usize] = [d, 0.0];
    let mut report = InitReport {
        uv: Vec::new(),
        flips: 0,
        iterations: 0,
        relative_residual: 0.0,
        preconditioner: opts.preconditioner,
    };
    if m > 0 {
        // Interior edges' area terms cancel to exact zeros: drop them (half the entries).
        let q = drop_zeros(&tri.to_csr());
        let mut x = vec![0.0; m];
        // u and v of a vertex are interleaved: multigrid aggregates them as one node.
        let opts = match opts.preconditioner {
            Preconditioner::Amg { .. } => CgOptions {
                preconditioner: Preconditioner::Amg { block_size: 2 },
                ..*opts
            },
            _ => *opts,
        };
        match solver {
            LinearSolver::Pcg => {
                let stats = pcg(&q, &rhs, &mut x, &opts)?;
                report.iterations = stats.iterations;
                report.relative_residual = stats.relative_residual;
                report.preconditioner = stats.preconditioner;
            }
            LinearSolver::Cholesky => {
                Cholesky::new(&q)?.solve(&rhs, &mut x)?;
                report.relative_residual = relative_residual(&q, &rhs, &x);
            }
        }
        for (r, &v) in free.iter().enumerate() {
            uv[v as usize] = [x[2 * r], x[2 * r + 1]];
        }
    }
    orient_ccw(faces, &mut uv);
    report.flips = count_flips(faces, &uv);
    report.uv = uv;
    Ok(report)
}

/// The same CSR matrix without its explicitly stored zeros.
fn drop_zeros(a: &CsMat<f64>) -> CsMat<f64> {
    let mut indptr = Vec::with_capacity(a.rows() + 1);
    let mut indices = Vec::with_capacity(a.nnz());
    let mut data = Vec::with_capacity(a.nnz());
    indptr.push(0);
    for row in a.outer_iterator() {
        for (j, &v) in row.iter() {
            if v != 0.0 {
                indices.push(j);
                data.push(v);
            }
        }
        indptr.push(indices.len());
    }
    // Rows of a CSR matrix keep their sorted, in-range columns when entries are removed, so
    // the structure stays valid and `new` cannot fail.
    CsMat::new(a.shape(), indptr, indices, data)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::init::test_grid::{bumpy, id, max_diff};

    /// A bumpy 12x12 grid: Cholesky and multigrid CG give the same map.
    #[test]
    fn cholesky_and_pcg_agree() {
        let k = 12;
        let (p, f) = bumpy(k, |x, y| 0.3 * (3.0 * x).sin() * (2.0 * y).cos());
        let id = |i, j| id(k, i, j);
        let pins = [id(0, 0), id(k, k)];
        let opts = default_solve_options();
        let a = lscm_solve(&p, &f, pins, LinearSolver::Cholesky, &opts).unwrap();
        let b = lscm_solve(&p, &f, pins, LinearSolver::Pcg, &opts).unwrap();
        assert_eq!(a.flips, 0);
        assert!(a.relative_residual < 1e-12, "{}", a.relative_residual);
        let diff = max_diff(&a.uv, &b.uv);
        assert!(diff < 1e-9, "{diff}");
    }
}
