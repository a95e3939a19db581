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

use sprs::CsMat;

use super::vec3::{cross, dot, norm, sub};
use super::{
    check_faces, check_input, count_flips, default_solve_options, orient_ccw, unique_edges,
    unreached, InitReport,
};
use crate::linalg::direct::{CholeskySymbolic, LinearSolver};
use crate::linalg::pattern::BlockPattern;
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
    // Unknowns: u of free vertex r at 2r, v at 2r + 1; the pins come after the free vertices
    // (fixed corners of the block pattern: no rows, their columns go to the right-hand side).
    let mut index = vec![u32::MAX; n];
    let mut free = Vec::new();
    for v in 0..n {
        if used[v] && v as u32 != pa && v as u32 != pb {
            index[v] = free.len() as u32;
            free.push(v as u32);
        }
    }
    let nf = free.len();
    index[pa as usize] = nf as u32;
    index[pb as usize] = nf as u32 + 1;
    // UVs of the pins, by their index − nf.
    let pinned_uv = [[0.0, 0.0], [d, 0.0]];
    let local: Vec<[u32; 3]> = faces.iter().map(|f| f.map(|v| index[v as usize])).collect();
    // Q has a 2×2 block per pair of vertices sharing a face: assembled through the block
    // pattern's precomputed slots, with no sort of triplets.
    let pattern = BlockPattern::<2, 3>::new(nf, &local);
    let m = pattern.n;
    let mut data = vec![0.0; pattern.indices.len()];
    let mut rhs = vec![0.0; m];
    for (fi, (face, lf)) in faces.iter().zip(&local).enumerate() {
        let slot = &pattern.slot[fi];
        // Adds q to Q[(corner i, coordinate ci)][(corner j, coordinate cj)] (0 = u, 1 = v).
        let mut add = |i: usize, ci: usize, j: usize, cj: usize, q: f64| {
            let (a, b) = (lf[i], lf[j]);
            if a as usize >= nf {
                return;
            }
            if b as usize >= nf {
                // Pinned column moves to the right-hand side: b_f −= Q_fp x_p.
                rhs[2 * a as usize + ci] -= q * pinned_uv[b as usize - nf][cj];
            } else {
                data[pattern.pos(a, ci, slot[i][j], cj)] += q;
            }
        };
        let p = face.map(|v| positions[v as usize]);
        let area2 = norm(cross(sub(p[1], p[0]), sub(p[2], p[0])));
        let longest2 = (0..3)
            .map(|c| dot(sub(p[(c + 1) % 3], p[c]), sub(p[(c + 1) % 3], p[c])))
            .fold(0.0, f64::max);
        // Dirichlet part, skipped on (numerically) zero-area faces whose cotangents blow up:
        // ½∫_T|∇u|² = ¼ Σ_k cot θ_k (u_i − u_j)², θ_k the angle opposite edge ij.
        if area2 > 1e-14 * longest2 {
            for k in 0..3 {
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                let (a, b) = (sub(p[i], p[k]), sub(p[j], p[k]));
                // w = ½ cot θ_k = ½ (a·b)/|a×b|
                let w = 0.5 * dot(a, b) / area2;
                for c in 0..2 {
                    add(i, c, i, c, w);
                    add(j, c, j, c, w);
                    add(i, c, j, c, -w);
                    add(j, c, i, c, -w);
                }
            }
        }
        // Area part: −A_T = −½ Σ_{directed edges a→b} (u_a v_b − u_b v_a).
        for k in 0..3 {
            let (a, b) = (k, (k + 1) % 3);
            add(a, 0, b, 1, -0.5);
            add(b, 1, a, 0, -0.5);
            add(b, 0, a, 1, 0.5);
            add(a, 1, b, 0, 0.5);
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
        // Interior edges' area terms cancel to exact zeros (sums of ±½): drop them.
        let q = drop_zeros(&pattern.matrix(data));
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
                // Ordered as 2×2 blocks and factored supernodally, as the global solver's
                // systems ([`CholeskySymbolic::blocked`]).
                CholeskySymbolic::blocked(&q, 2)?
                    .factor(&q)?
                    .solve(&rhs, &mut x)?;
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
