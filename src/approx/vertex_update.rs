//! Stage 2: move the vertices so that the faces take prescribed normals.
//!
//! Each face is turned to its target normal by the minimal rotation R_f about its centroid;
//! the vertices are then the least-squares fit of the rotated edges,
//!   E = E_Poisson/Ā + λ·E_Smooth/l̄,
//!   E_Poisson = Σ_f A_f Σ_{edges ab of f} |v_b − v_a − R_f(x_b − x_a)|²  (face-gradient matching),
//!   E_Smooth  = Σ_{interior edges, wings k∈f, l∈g} |e| · |v_l − v_k − ½(R_f + R_g)(x_l − x_k)|²
//! (the dihedral-rotation term: across each edge the two faces must agree on how the wing
//! vector turns, which stops a face from sliding against its neighbour). Both are sums of
//! |v_b − v_a − t|² terms, so the normal equations are one weighted graph Laplacian shared by
//! x, y and z, plus a tiny anchor to the current positions that removes the translation null
//! space. The rotation is linearised at the current positions, so the solve is repeated.

use sprs::CsMat;

use super::geom::{add, face_normals_areas, mean_edge_length, rotate_min, scale, sub, V3};
use super::sparse::SpdSolver;
use crate::linalg::pattern::BlockPattern;
use crate::linalg::SolveError;
use crate::mesh::Topology;

/// Parameters of [`update_vertices`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct VertexUpdateOptions {
    /// λ, weight of the smoothness term.
    pub lambda: f64,
    /// Anchor weight (relative to the Laplacian's unit weights).
    pub anchor: f64,
    /// Linearise–solve rounds.
    pub rounds: usize,
}

impl Default for VertexUpdateOptions {
    fn default() -> Self {
        VertexUpdateOptions {
            lambda: 0.1,
            anchor: 1e-4,
            rounds: 4,
        }
    }
}

/// Normal equations of Σ w |v_b − v_a − t|² + anchor·Σ|v − x|² over a fixed list of pairs
/// (a, b): the weights and targets change every round, the pairs do not, so the matrix's
/// pattern is the pairs' [`BlockPattern`] (made once, every entry's position precomputed)
/// and the values are summed in place (assembling from triplets sorts them every round: more
/// time than the factorisation on large meshes).
struct EdgeLsq {
    a: CsMat<f64>,
    /// Entries (a,a), (b,b), (a,b), (b,a) of each pair, as indices into the matrix's values.
    slots: Vec<[usize; 4]>,
    diagonal: Vec<usize>,
    pairs: Vec<[u32; 2]>,
    rhs: [Vec<f64>; 3],
}

impl EdgeLsq {
    fn new(n: usize, pairs: &[[u32; 2]]) -> EdgeLsq {
        let pattern = BlockPattern::<1, 2>::new(n, pairs);
        let slots = pairs
            .iter()
            .zip(&pattern.slot)
            .map(|(&[p, q], s)| {
                let at = |v: u32, i: usize, j: usize| pattern.pos(v, 0, s[i][j], 0);
                [at(p, 0, 0), at(q, 1, 1), at(p, 0, 1), at(q, 1, 0)]
            })
            .collect();
        EdgeLsq {
            a: pattern.matrix(vec![0.0; pattern.indices.len()]),
            slots,
            diagonal: (0..n as u32).map(|v| pattern.diag(v, 0)).collect(),
            pairs: pairs.to_vec(),
            rhs: [vec![0.0; n], vec![0.0; n], vec![0.0; n]],
        }
    }

    /// The system for the anchor to `x` and the pairs' weights and targets, in pair order.
    fn assemble(&mut self, anchor: f64, x: &[V3], terms: impl Iterator<Item = (f64, V3)>) {
        let values = self.a.data_mut();
        values.fill(0.0);
        for (i, p) in x.iter().enumerate() {
            values[self.diagonal[i]] += anchor;
            for k in 0..3 {
                self.rhs[k][i] = anchor * p[k];
            }
        }
        for (t, (w, target)) in terms.enumerate() {
            let [aa, bb, ab, ba] = self.slots[t];
            values[aa] += w;
            values[bb] += w;
            values[ab] -= w;
            values[ba] -= w;
            let [a, b] = self.pairs[t].map(|v| v as usize);
            for k in 0..3 {
                self.rhs[k][b] += w * target[k];
                self.rhs[k][a] -= w * target[k];
            }
        }
    }
}

/// Moves the vertices `pos` of `faces` so that face f gets normal `target[f]` (unit); returns
/// the new positions (unreferenced vertices stay where they are).
pub fn update_vertices(
    pos: &[V3],
    faces: &[[u32; 3]],
    topo: &Topology,
    target: &[V3],
    opts: &VertexUpdateOptions,
) -> Result<Vec<V3>, SolveError> {
    let n = pos.len();
    let mut x = pos.to_vec();
    let lbar = mean_edge_length(&x, &topo.edges);
    // The pairs: every face's three edges, then (λ > 0) the wings of every interior edge,
    // with the edge they cross.
    let mut pairs: Vec<[u32; 2]> = Vec::with_capacity(3 * faces.len());
    for face in faces {
        for k in 0..3 {
            pairs.push([face[k], face[(k + 1) % 3]]);
        }
    }
    let mut wings: Vec<([usize; 2], [usize; 2], [usize; 2])> = Vec::new();
    if opts.lambda > 0.0 {
        for &e in &topo.interior_edges {
            let [f, g] = topo.edge_faces[e as usize].map(|v| v as usize);
            let [i, j] = topo.edges[e as usize].map(|v| v as usize);
            let wing = |face: [u32; 3]| {
                face.iter()
                    .map(|&v| v as usize)
                    .find(|&v| v != i && v != j)
                    .unwrap_or(i)
            };
            let kl = [wing(faces[f]), wing(faces[g])];
            pairs.push(kl.map(|v| v as u32));
            wings.push((kl, [f, g], [i, j]));
        }
    }
    let mut sys = EdgeLsq::new(n, &pairs);
    let mut spd = SpdSolver::default();
    for _ in 0..opts.rounds {
        let (normals, areas) = face_normals_areas(&x, faces);
        let abar = areas.iter().sum::<f64>() / areas.len().max(1) as f64;
        let rot = |f: usize, v: V3| rotate_min(normals[f], target[f], v);
        // Anchor in units of the Laplacian weights (which are ~1 after dividing by Ā, l̄).
        let xr = &x;
        let edges = faces.iter().enumerate().flat_map(|(f, face)| {
            let w = areas[f] / abar;
            (0..3).map(move |k| {
                let (a, b) = (face[k] as usize, face[(k + 1) % 3] as usize);
                (w, rot(f, sub(xr[b], xr[a])))
            })
        });
        let wing_terms = wings.iter().map(|&([k, l], [f, g], [i, j])| {
            let d = sub(x[l], x[k]);
            let t = scale(add(rot(f, d), rot(g, d)), 0.5);
            let len = super::geom::norm(sub(x[j], x[i]));
            (opts.lambda * len / lbar, t)
        });
        sys.assemble(opts.anchor, &x, edges.chain(wing_terms));
        let (a, b) = (&sys.a, &sys.rhs);
        let mut cols: Vec<Vec<f64>> = (0..3).map(|k| x.iter().map(|p| p[k]).collect()).collect();
        spd.solve(a, b, &mut cols, 1e-9)?;
        for (i, p) in x.iter_mut().enumerate() {
            *p = [cols[0][i], cols[1][i], cols[2][i]];
        }
        if x.iter().any(|p| p.iter().any(|c| !c.is_finite())) {
            return Err(SolveError::NonFinite {
                what: "vertex update".into(),
            });
        }
    }
    Ok(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approx::testing::grid;
    use sprs::TriMat;

    /// The system assembled into the pattern made once is the one the terms' triplets sum to,
    /// for any weights and targets (two rounds of different ones through one `EdgeLsq`), with
    /// pairs that repeat (each interior edge is two faces' edge) and wing pairs.
    #[test]
    fn assembled_in_place_equals_the_triplets_summed() {
        let (mesh, _) = grid(5);
        let n = mesh.positions.len();
        let mut pairs: Vec<[u32; 2]> = mesh
            .faces
            .iter()
            .flat_map(|f| (0..3).map(move |k| [f[k], f[(k + 1) % 3]]))
            .collect();
        pairs.extend([[0, 12], [24, 3], [7, 17]]);
        let mut sys = EdgeLsq::new(n, &pairs);
        for round in 0..2 {
            let value = |t: usize, k: usize| ((t * 7 + k * 3 + round * 5) % 11) as f64 / 11.0 + 0.1;
            let terms: Vec<(f64, V3)> = (0..pairs.len())
                .map(|t| (value(t, 0), [value(t, 1), -value(t, 2), value(t, 3)]))
                .collect();
            let anchor = 1e-3 * (round + 1) as f64;
            sys.assemble(anchor, &mesh.positions, terms.iter().copied());
            let mut tri = TriMat::new((n, n));
            let mut rhs = vec![[0.0; 3]; n];
            for (i, p) in mesh.positions.iter().enumerate() {
                tri.add_triplet(i, i, anchor);
                rhs[i] = scale(*p, anchor);
            }
            for (&[a, b], &(w, t)) in pairs.iter().zip(&terms) {
                let (a, b) = (a as usize, b as usize);
                for (r, c, v) in [(a, a, w), (b, b, w), (a, b, -w), (b, a, -w)] {
                    tri.add_triplet(r, c, v);
                }
                rhs[b] = add(rhs[b], scale(t, w));
                rhs[a] = sub(rhs[a], scale(t, w));
            }
            let want: CsMat<f64> = tri.to_csr();
            assert_eq!(sys.a.indptr().raw_storage(), want.indptr().raw_storage());
            assert_eq!(sys.a.indices(), want.indices());
            for (x, y) in sys.a.data().iter().zip(want.data()) {
                assert!((x - y).abs() <= 1e-12, "{x} vs {y}");
            }
            for (i, r) in rhs.iter().enumerate() {
                for k in 0..3 {
                    assert!((sys.rhs[k][i] - r[k]).abs() <= 1e-12);
                }
            }
        }
    }
}
