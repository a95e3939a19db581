//! The per-face linear operators of the global solver and its fixed sparse pattern.
//!
//! Unknowns are the interleaved UVs `x[2v + r]` (r = 0 for u, 1 for v). A face's Jacobian is
//! linear in its three corners: `A[r][c] = Σ_k x[2 v_k + r] · g_k[c]`, with `g_k` the rows of
//! the inverse of the face's local frame edges (see [`crate::mesh::FaceFrames`]). Every system
//! the solver builds (the proxy's reweighted Laplacian and the projected Newton Hessian) is
//! `Σ_f Bᵀ_f M_f B_f` for a 4x4 per-face `M_f`, so both share one CSR pattern: a 2x2 block for
//! every pair of vertices that share a face. The pattern and each face's slots in it are
//! computed once; an iteration only overwrites the values.

use sprs::CsMat;

use crate::linalg::pattern::{BlockPattern, FIXED};
use crate::linalg::SolveError;
use crate::mesh::{FaceFrames, TriMesh};

/// `g_k` (k = 0..3) of one face: `A = [u; v]·G`, `G` the 3x2 matrix with rows `g_k`.
pub type FaceGradient = [[f64; 2]; 3];

/// Gradient operators of every face, from the local frames. A degenerate face is an error
/// (validation rejects those before a solver runs; this only avoids NaNs).
pub fn face_gradients(frames: &FaceFrames) -> Result<Vec<FaceGradient>, SolveError> {
    frames
        .local
        .iter()
        .enumerate()
        .map(|(f, l)| {
            let e1 = [l[1][0] - l[0][0], l[1][1] - l[0][1]];
            let e2 = [l[2][0] - l[0][0], l[2][1] - l[0][1]];
            // X = [e1 e2] (columns); A X = [uv1−uv0, uv2−uv0] ⇒ A = [du] X⁻¹.
            let det = e1[0] * e2[1] - e2[0] * e1[1];
            if !(det > 0.0 && det.is_finite()) {
                return Err(SolveError::InvalidInput {
                    what: format!("face {f} is degenerate (zero area in its frame)"),
                });
            }
            let inv = [[e2[1] / det, -e2[0] / det], [-e1[1] / det, e1[0] / det]];
            let g1 = inv[0];
            let g2 = inv[1];
            Ok([[-g1[0] - g2[0], -g1[1] - g2[1]], g1, g2])
        })
        .collect()
}

/// Jacobian `[a, b, c, d]` (row-major) of face `f` under `x`.
#[inline]
pub fn jacobian(g: &FaceGradient, face: &[u32; 3], x: &[f64]) -> [f64; 4] {
    let mut a = [0.0; 4];
    for k in 0..3 {
        let v = face[k] as usize;
        let (u, w) = (x[2 * v], x[2 * v + 1]);
        a[0] += u * g[k][0];
        a[1] += u * g[k][1];
        a[2] += w * g[k][0];
        a[3] += w * g[k][1];
    }
    a
}

/// `Bᵀ m`: the 6 corner components (k, r) of a Jacobian-space covector `m` (row-major 4).
#[inline]
pub fn pull_back(g: &FaceGradient, m: &[f64; 4]) -> [f64; 6] {
    let mut out = [0.0; 6];
    for k in 0..3 {
        for r in 0..2 {
            out[2 * k + r] = m[2 * r] * g[k][0] + m[2 * r + 1] * g[k][1];
        }
    }
    out
}

/// `Bᵀ M B` (6x6 over corners (k, r)) of a symmetric 4x4 `M` in Jacobian space.
pub fn pull_back_matrix(g: &FaceGradient, m: &[[f64; 4]; 4]) -> [[f64; 6]; 6] {
    // B[(r, c)][(k, s)] = δ_rs g_k[c]; first MB (4x6), then Bᵀ(MB).
    let mut mb = [[0.0; 6]; 4];
    for i in 0..4 {
        for k in 0..3 {
            for s in 0..2 {
                mb[i][2 * k + s] = m[i][2 * s] * g[k][0] + m[i][2 * s + 1] * g[k][1];
            }
        }
    }
    let mut out = [[0.0; 6]; 6];
    for k in 0..3 {
        for r in 0..2 {
            for j in 0..6 {
                out[2 * k + r][j] = g[k][0] * mb[2 * r][j] + g[k][1] * mb[2 * r + 1][j];
            }
        }
    }
    out
}

/// The CSR pattern over interleaved UVs ([`BlockPattern`] of the triangles) with its matrix.
pub struct Pattern {
    /// The matrix (2·#V square); its values are overwritten by [`Pattern::fill`].
    pub matrix: CsMat<f64>,
    blocks: BlockPattern<2, 3>,
    /// Index of each diagonal entry.
    diag: Vec<usize>,
}

impl Pattern {
    /// Builds the pattern of `mesh`: vertex blocks for every pair that shares a face.
    pub fn new(mesh: &TriMesh) -> Result<Pattern, SolveError> {
        Ok(Self::from_blocks(BlockPattern::new(
            mesh.positions.len(),
            &mesh.faces,
        )))
    }

    /// The pattern of this one's faces (`base`, those it is set up for) followed by `faces`,
    /// with blocks reserved for `extra` (a chart with its scaffold, and blocks for the
    /// triangles a re-triangulation may bring: [`Pattern::rebind`]), built from this one
    /// ([`BlockPattern::extended`]: only the rows `faces` add blocks to are merged). Corners
    /// from the chart's vertex count on (the scaffold's frame) are fixed: they are not
    /// unknowns, so they have no rows, and a scaffold triangle only couples the chart vertices
    /// among its corners: re-triangulations that only move the long triangles to the frame
    /// leave the pattern unchanged.
    pub fn extended(&self, base: &[[u32; 3]], faces: &[[u32; 3]], extra: &[[u32; 3]]) -> Pattern {
        Self::from_blocks(self.blocks.extended(base, faces, extra))
    }

    /// The matrix of `blocks` (values zero) and its diagonal entries.
    fn from_blocks(blocks: BlockPattern<2, 3>) -> Pattern {
        let diag = (0..blocks.n)
            .map(|i| blocks.diag((i / 2) as u32, i % 2))
            .collect();
        let matrix = blocks.matrix(vec![0.0; blocks.indices.len()]);
        Pattern {
            matrix,
            blocks,
            diag,
        }
    }

    /// Sets the pattern up for faces that replace those from `first` on, keeping the
    /// structure (and so any symbolic factorisation of it), when it has every block they
    /// need; `false` otherwise.
    pub fn rebind(&mut self, first: usize, faces: &[[u32; 3]]) -> bool {
        self.blocks.rebind(first, faces)
    }

    /// Overwrites the values with `Σ_f local[f] + rel_shift · D` (`local[f]` over corners
    /// (k, r)), `D` the diagonal of the sum (the mean diagonal for an empty row), and returns
    /// the mean shift. The shift keeps the system definite along translations and along modes
    /// a projection clamped to zero; the right-hand sides (gradients) have no translation
    /// component, so it does not bias the step there. It is relative *per row*: on a map whose
    /// triangles span many orders of magnitude in size (conformal maps of long protrusions),
    /// the diagonal spans the square of that, and one shift relative to the mean diagonal would
    /// damp the Newton step of every ordinary-sized triangle into a gradient step.
    /// Faces sharing a vertex write the same entries, so the per-face blocks are computed in
    /// parallel by the caller and scattered here serially (36 additions per face).
    pub fn fill(&mut self, faces: &[[u32; 3]], local: &[[[f64; 6]; 6]], rel_shift: f64) -> f64 {
        let data = self.matrix.data_mut();
        data.fill(0.0);
        for (f, h) in local.iter().enumerate() {
            let slot = &self.blocks.slot[f];
            for k in 0..3 {
                for l in 0..3 {
                    if slot[k][l] == FIXED {
                        continue;
                    }
                    for r in 0..2 {
                        let base = self.blocks.pos(faces[f][k], r, slot[k][l], 0);
                        for s in 0..2 {
                            data[base + s] += h[2 * k + r][2 * l + s];
                        }
                    }
                }
            }
        }
        let mean = self.diag.iter().map(|&d| data[d]).sum::<f64>() / self.diag.len().max(1) as f64;
        let mut total = 0.0;
        for &d in &self.diag {
            let shift = rel_shift * if data[d] > 0.0 { data[d] } else { mean };
            data[d] += shift;
            total += shift;
        }
        total / self.diag.len().max(1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::param::energy::{self, Energy};

    /// The 6x6 pulled-back Hessian and gradient match finite differences of the face energy
    /// as a function of the corner UVs.
    #[test]
    fn pulled_back_derivatives_match_finite_differences() {
        let g: FaceGradient = [[-0.7, -0.4], [0.9, -0.3], [-0.2, 0.7]];
        let face = [0u32, 1, 2];
        let x0 = [0.1, 0.2, 1.3, 0.1, 0.4, 0.9];
        for en in [Energy::SymmetricDirichlet, Energy::Mips] {
            let e = |x: &[f64]| energy::value(en, &jacobian(&g, &face, x));
            let grad = |x: &[f64]| {
                let (_, ge, _) = energy::eval(en, &jacobian(&g, &face, x));
                pull_back(&g, &ge)
            };
            let (_, ge, he) = energy::eval(en, &jacobian(&g, &face, &x0));
            let gx = pull_back(&g, &ge);
            let hx = pull_back_matrix(&g, &he);
            let h = 1e-6;
            for i in 0..6 {
                let (mut xp, mut xm) = (x0, x0);
                xp[i] += h;
                xm[i] -= h;
                let fd = (e(&xp) - e(&xm)) / (2.0 * h);
                assert!(
                    (fd - gx[i]).abs() < 1e-5 * gx[i].abs().max(1.0),
                    "{en:?} g{i}"
                );
                let (gp, gm) = (grad(&xp), grad(&xm));
                for j in 0..6 {
                    let fd = (gp[j] - gm[j]) / (2.0 * h);
                    assert!(
                        (fd - hx[i][j]).abs() < 1e-4 * hx[i][j].abs().max(1.0),
                        "{en:?} H{i}{j}: {fd} vs {}",
                        hx[i][j]
                    );
                }
            }
        }
    }
}
