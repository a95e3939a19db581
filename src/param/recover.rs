//! Recovering per-vertex UVs from per-face Jacobians.
//!
//! Least squares (the default): `min_u Σ_f area_f ‖J_f(u) − A_f‖²`, a Poisson problem whose
//! matrix (the cotangent Laplacian) depends only on the mesh, so it is assembled and factored
//! (sparse Cholesky) once and every recovery is two pairs of triangular solves. It spreads the
//! consensus error of the per-face maps over the whole mesh instead of accumulating it along a
//! tree, which is why it stays flip-free long before the breadth-first recovery does (see
//! ../shared/notes/admm-prototype.md).

use sprs::{CsMat, TriMat};

use crate::linalg::direct::{Cholesky, DirectError};
use crate::linalg::SolveError;
use crate::linalg::{
    krylov::{CgOptions, KrylovSolver},
    precond::Preconditioner,
};
use crate::param::admm::AdmmProblem;

/// Precomputed Poisson system for least-squares recovery.
pub struct LeastSquaresRecovery {
    /// Free-vertex index → vertex (referenced vertices except the pinned one).
    free: Vec<u32>,
    /// Vertex → free index, or `u32::MAX` for pinned / unreferenced vertices.
    index: Vec<u32>,
    /// The pinned vertex (fixes the translation).
    pinned: u32,
    /// The cotangent Laplacian, factored (or with its preconditioner) once.
    solver: Solver,
    /// #F×3 gradients of the corner hat functions in the face's frame.
    grads: Vec<[[f64; 2]; 3]>,
    /// #F face areas.
    areas: Vec<f64>,
    faces: Vec<[u32; 3]>,
}

impl LeastSquaresRecovery {
    /// Assembles the cotangent Laplacian over the referenced vertices of `faces`.
    pub fn new(
        problem: &AdmmProblem,
        faces: &[[u32; 3]],
        n_vertices: usize,
    ) -> Result<LeastSquaresRecovery, SolveError> {
        let mut used = vec![false; n_vertices];
        for f in faces {
            for &v in f {
                used[v as usize] = true;
            }
        }
        let pinned = faces.first().map_or(0, |f| f[0]);
        let mut index = vec![u32::MAX; n_vertices];
        let mut free = Vec::new();
        for v in 0..n_vertices {
            if used[v] && v as u32 != pinned {
                index[v] = free.len() as u32;
                free.push(v as u32);
            }
        }
        let mut grads = Vec::with_capacity(faces.len());
        let mut tri = TriMat::new((free.len(), free.len()));
        for (f, face) in faces.iter().enumerate() {
            // Hat-function gradients: g1, g2 are the rows of M⁻¹, g0 = −g1 − g2.
            let inv = problem.frame_inverse(f);
            let g1 = [inv[0], inv[1]];
            let g2 = [inv[2], inv[3]];
            let g0 = [-g1[0] - g2[0], -g1[1] - g2[1]];
            let g = [g0, g1, g2];
            let area = problem.area[f];
            for i in 0..3 {
                let vi = index[face[i] as usize];
                if vi == u32::MAX {
                    continue;
                }
                for j in 0..3 {
                    let vj = index[face[j] as usize];
                    if vj == u32::MAX {
                        continue;
                    }
                    tri.add_triplet(
                        vi as usize,
                        vj as usize,
                        area * (g[i][0] * g[j][0] + g[i][1] * g[j][1]),
                    );
                }
            }
            grads.push(g);
        }
        let laplacian: CsMat<f64> = tri.to_csr();
        // Factored once: every recovery is then two triangular solve pairs, exact, 7–80× faster
        // than the warm-started multigrid CG it replaced (BENCHMARKS.md, issue 26).
        // A Laplacian that is not positive definite (faces in several components, only one
        // of them pinned) falls back to that CG, which still converges on a consistent system.
        let solver = match Cholesky::new(&laplacian) {
            Ok(c) => Solver::Cholesky(c),
            Err(DirectError::NotPositiveDefinite { .. }) => {
                let opts = CgOptions {
                    tolerance: 1e-10,
                    max_iterations: 20 * free.len().max(100),
                    preconditioner: Preconditioner::Amg { block_size: 1 },
                };
                Solver::Pcg(Box::new(KrylovSolver::cg(&laplacian, &opts)?))
            }
            Err(e) => return Err(e.into()),
        };
        Ok(LeastSquaresRecovery {
            free,
            index,
            pinned,
            solver,
            grads,
            areas: problem.area.clone(),
            faces: faces.to_vec(),
        })
    }

    /// Recovers UVs from the Jacobians `a` (#F, row-major 2x2). `uv` (#V) is overwritten for
    /// referenced vertices (its values are the warm start of the CG fallback); the pinned
    /// vertex keeps its value.
    pub fn recover(&self, a: &[[f64; 4]], uv: &mut [[f64; 2]]) -> Result<(), SolveError> {
        let n = self.free.len();
        let pin = uv[self.pinned as usize];
        for r in 0..2 {
            // b_i = Σ_f area_f g_i · (row r of A_f), minus the pinned vertex's column.
            let mut b = vec![0.0; n];
            for (f, face) in self.faces.iter().enumerate() {
                let row = [a[f][2 * r], a[f][2 * r + 1]];
                let g = &self.grads[f];
                let area = self.areas[f];
                for i in 0..3 {
                    let vi = self.index[face[i] as usize];
                    if vi == u32::MAX {
                        continue;
                    }
                    b[vi as usize] += area * (g[i][0] * row[0] + g[i][1] * row[1]);
                    for j in 0..3 {
                        if face[j] == self.pinned {
                            // Move K_{i,pin} · u_pin to the right-hand side.
                            b[vi as usize] -=
                                area * (g[i][0] * g[j][0] + g[i][1] * g[j][1]) * pin[r];
                        }
                    }
                }
            }
            let mut x: Vec<f64> = self.free.iter().map(|&v| uv[v as usize][r]).collect();
            match &self.solver {
                Solver::Pcg(s) => {
                    s.solve(&b, &mut x)?;
                }
                Solver::Cholesky(c) => c.solve(&b, &mut x)?,
            }
            for (k, &v) in self.free.iter().enumerate() {
                uv[v as usize][r] = x[k];
            }
        }
        Ok(())
    }
}

/// The linear solver of [`LeastSquaresRecovery`]: the factor, or CG where the Laplacian is
/// only semi-definite.
enum Solver {
    Pcg(Box<KrylovSolver>),
    Cholesky(Cholesky),
}

/// How per-vertex UVs are recovered from the per-face maps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Recovery {
    /// [`LeastSquaresRecovery`]: the consensus error spread over the whole mesh.
    #[default]
    #[serde(rename = "ls")]
    LeastSquares,
    /// [`breadth_first`], the seed paper's: exact where the maps agree, but the consensus error
    /// accumulates along the traversal, so it flips long after least squares is clean.
    #[serde(rename = "bfs")]
    BreadthFirst,
}

/// Breadth-first recovery (Wu & Zhang 2020): starting at the first face's first corner, which
/// keeps its position in `uv`, each face reached across an interior edge sets its remaining
/// corner `b` from a known corner `a` as `u(b) = u(a) + A_f (x_b − x_a)`, with `x` the corners in
/// the face's own frame. Every face is reached once (the mesh is a disk: the faces are
/// edge-connected); vertices no face reaches keep their value in `uv`.
pub fn breadth_first(
    problem: &AdmmProblem,
    faces: &[[u32; 3]],
    a: &[[f64; 4]],
    uv: &mut [[f64; 2]],
) {
    let nf = faces.len();
    if nf == 0 {
        return;
    }
    let mut known = vec![false; uv.len()];
    let mut seen = vec![false; nf];
    let mut queue = std::collections::VecDeque::new();
    known[faces[0][0] as usize] = true;
    seen[0] = true;
    queue.push_back(0usize);
    while let Some(f) = queue.pop_front() {
        let face = faces[f];
        let x = &problem.local[f];
        let Some(i) = (0..3).find(|&i| known[face[i] as usize]) else {
            continue; // unreachable: a face is queued only across an edge with known ends
        };
        let ua = uv[face[i] as usize];
        for j in 0..3 {
            let vb = face[j] as usize;
            if known[vb] {
                continue;
            }
            let d = [x[j][0] - x[i][0], x[j][1] - x[i][1]];
            let m = &a[f];
            uv[vb] = [
                ua[0] + m[0] * d[0] + m[1] * d[1],
                ua[1] + m[2] * d[0] + m[3] * d[1],
            ];
            known[vb] = true;
        }
        for &s in &problem.face_slots[f] {
            if s == crate::param::admm::NO_SLOT {
                continue;
            }
            let g = problem.slot_face[(s ^ 1) as usize] as usize;
            if !seen[g] {
                seen[g] = true;
                queue.push_back(g);
            }
        }
    }
}
