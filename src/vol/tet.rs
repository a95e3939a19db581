//! The tetrahedral mesh and the checks every stage relies on: orientation (signed volumes),
//! the boundary surface (tet faces used once) and located validation of a rest shape.

use std::collections::HashMap;
use std::path::Path;

use super::VolError;

/// A tetrahedral mesh: positions and 0-based tets. MEDIT reference numbers are kept so a
/// written file carries the input's labels.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TetMesh {
    pub positions: Vec<[f64; 3]>,
    pub tets: Vec<[u32; 4]>,
    pub vertex_refs: Vec<i64>,
    pub tet_refs: Vec<i64>,
}

pub use crate::linalg::vec3::{cross, dot, sub};

/// `p / ‖p‖`, the nearest point of the unit sphere (`None` at the centre or for non-finite
/// input): the retraction that keeps the ball target's sliding boundary on the sphere.
pub fn to_unit_sphere(p: [f64; 3]) -> Option<[f64; 3]> {
    let r = dot(p, p).sqrt();
    (r > 0.0 && r.is_finite()).then(|| p.map(|c| c / r))
}

/// `x > 0`, false for NaN: the one orientation test (a NaN volume counts as inverted).
#[inline]
pub fn is_positive(x: f64) -> bool {
    x > 0.0
}

/// det[b − a, c − a, d − a] = 6 × signed volume.
#[inline]
pub fn det6(p: &[[f64; 3]], t: &[u32; 4]) -> f64 {
    let a = p[t[0] as usize];
    let e1 = sub(p[t[1] as usize], a);
    let e2 = sub(p[t[2] as usize], a);
    let e3 = sub(p[t[3] as usize], a);
    dot(e1, cross(e2, e3))
}

impl TetMesh {
    /// Builds a mesh without labels (all references 0).
    pub fn new(positions: Vec<[f64; 3]>, tets: Vec<[u32; 4]>) -> TetMesh {
        let nv = positions.len();
        let nt = tets.len();
        TetMesh {
            positions,
            tets,
            vertex_refs: vec![0; nv],
            tet_refs: vec![0; nt],
        }
    }

    /// Signed volume of tet `t` at `positions` (which may be a map of this mesh).
    pub fn volume_at(&self, positions: &[[f64; 3]], t: usize) -> f64 {
        det6(positions, &self.tets[t]) / 6.0
    }

    /// Bounding-box diagonal of the positions (scale for relative tolerances).
    pub fn bbox_diagonal(&self) -> f64 {
        bbox_diagonal(&self.positions)
    }

    /// Tets with det ≤ 0 (inverted or flat) at `positions`.
    pub fn inverted(&self, positions: &[[f64; 3]]) -> Vec<usize> {
        (0..self.tets.len())
            .filter(|&t| !is_positive(det6(positions, &self.tets[t])))
            .collect()
    }

    /// Rejects what no reader should accept as a tet mesh, wherever it came from: no vertex or
    /// no tet, a tet that uses one vertex twice, or two tets on the same four vertices (one
    /// of them is a copy: the mesh double-counts volume and the boundary surface breaks).
    pub fn check_structure(&self, file: &Path) -> Result<(), VolError> {
        if self.positions.is_empty() || self.tets.is_empty() {
            return Err(VolError::Input(format!(
                "{}: no {}: a volumetric map needs at least one tetrahedron",
                file.display(),
                if self.positions.is_empty() {
                    "vertices"
                } else {
                    "tetrahedra"
                }
            )));
        }
        check_indices(&self.tets, self.positions.len(), file)?;
        if let Some((t, v)) = self.tets.iter().enumerate().find_map(|(t, tet)| {
            (0..4).find_map(|a| {
                ((a + 1)..4)
                    .find(|&b| tet[a] == tet[b])
                    .map(|_| (t, tet[a]))
            })
        }) {
            return Err(VolError::Input(format!(
                "{}: tet {t} uses vertex {v} twice",
                file.display()
            )));
        }
        if let Some((a, b)) = crate::mesh::validate::first_duplicate(&self.tets) {
            return Err(VolError::Input(format!(
                "{}: tet {b} is a duplicate of tet {a} (same four vertices)",
                file.display()
            )));
        }
        Ok(())
    }

    /// Rejects a rest shape with a flat or inverted tet: the Jacobians (and the energy) are
    /// defined relative to it, so one bad tet poisons the whole problem. Flat means volume
    /// ≤ 1e-15·diag³ (far below any real mesh's smallest tet, far above round-off).
    pub fn check_rest(&self, file: &Path) -> Result<(), VolError> {
        // At unit scale (a power of two: exact), so a mesh at 1e308 has no volume that
        // overflows and one at 1e-300 none that underflows; the reported volume is at that
        // scale too.
        let scale = crate::mesh::Scale::fit(&self.positions);
        let p: Vec<[f64; 3]> = self.positions.iter().map(|&q| scale.apply(q)).collect();
        let d = bbox_diagonal(&p);
        let eps = 1e-15 * d * d * d;
        for (t, tet) in self.tets.iter().enumerate() {
            let v = det6(&p, tet) / 6.0;
            if !v.is_finite() || v.abs() <= eps {
                return Err(VolError::ZeroVolume {
                    file: file.to_path_buf(),
                    tet: t,
                    volume: v,
                });
            }
            if v < 0.0 {
                return Err(VolError::InvertedRest {
                    file: file.to_path_buf(),
                    tet: t,
                    volume: v,
                });
            }
        }
        Ok(())
    }

    /// Boundary triangles (tet faces used by exactly one tet), oriented outward for a
    /// positively oriented tet.
    pub fn boundary_faces(&self) -> Vec<[u32; 3]> {
        let mut count: HashMap<[u32; 3], (u32, [u32; 3])> = HashMap::new();
        for t in &self.tets {
            let [a, b, c, d] = *t;
            // Outward faces of a positive tet (a, b, c, d).
            for f in [[b, c, d], [a, d, c], [a, b, d], [a, c, b]] {
                let mut k = f;
                k.sort_unstable();
                count.entry(k).or_insert((0, f)).0 += 1;
            }
        }
        let mut out: Vec<[u32; 3]> = count
            .into_values()
            .filter(|(n, _)| *n == 1)
            .map(|(_, f)| f)
            .collect();
        // Deterministic order regardless of the hash map's.
        out.sort_unstable();
        out
    }

    /// Splits each edge `[a, b]` at its midpoint, in order: a vertex is appended (reference 0)
    /// at the midpoint of `a` and `b` in the positions and in each of `maps` (maps of this
    /// mesh), and every tet on the edge is replaced by its two halves, `b → m` in place and
    /// `a → m` appended, both with the parent's reference. Returns the edges split, as
    /// `[m, a, b]`; an edge no tet has is skipped.
    ///
    /// A half has half its parent's signed volume in the positions and in every map (m is on
    /// the segment ab, and the determinant is linear in each corner), so a positive rest
    /// stays positive and a map's inverted tets are still inverted: a split adds freedom (the
    /// new vertex), never a fold. The boundary surface is unchanged when the edges are
    /// interior (no boundary face has an interior edge).
    pub fn split_edges(
        &mut self,
        edges: &[[u32; 2]],
        maps: &mut [&mut Vec<[f64; 3]>],
    ) -> Vec<[u32; 3]> {
        let mut inc: Vec<Vec<u32>> = vec![Vec::new(); self.positions.len()];
        for (i, t) in self.tets.iter().enumerate() {
            for &v in t {
                inc[v as usize].push(i as u32);
            }
        }
        let mid = |p: &[[f64; 3]], a: u32, b: u32| -> [f64; 3] {
            let (pa, pb) = (p[a as usize], p[b as usize]);
            [0, 1, 2].map(|k| 0.5 * (pa[k] + pb[k]))
        };
        let mut done = Vec::new();
        for &[a, b] in edges {
            let on: Vec<u32> = inc[a as usize]
                .iter()
                .copied()
                .filter(|&t| self.tets[t as usize].contains(&b))
                .collect();
            if on.is_empty() || a == b {
                continue;
            }
            let m = self.positions.len() as u32;
            self.positions.push(mid(&self.positions, a, b));
            for x in maps.iter_mut() {
                let p = mid(x, a, b);
                x.push(p);
            }
            self.vertex_refs.push(0);
            inc.push(Vec::new());
            for t in on {
                let parent = self.tets[t as usize];
                let new = self.tets.len() as u32;
                self.tets[t as usize] = parent.map(|v| if v == b { m } else { v });
                self.tets.push(parent.map(|v| if v == a { m } else { v }));
                let r = self.tet_refs.get(t as usize).copied().unwrap_or(0);
                self.tet_refs.push(r);
                inc[b as usize].retain(|&s| s != t);
                inc[b as usize].push(new);
                inc[m as usize].extend([t, new]);
                for &v in parent.iter().filter(|&&v| v != a && v != b) {
                    inc[v as usize].push(new);
                }
            }
            done.push([m, a, b]);
        }
        done
    }

    /// Vertices on the boundary surface, ascending.
    pub fn boundary_vertices(&self) -> Vec<u32> {
        let mut on = vec![false; self.positions.len()];
        for f in self.boundary_faces() {
            for v in f {
                on[v as usize] = true;
            }
        }
        (0..on.len() as u32).filter(|&v| on[v as usize]).collect()
    }
}

/// Bounding-box diagonal of a point set (0 for an empty set).
pub fn bbox_diagonal(p: &[[f64; 3]]) -> f64 {
    if p.is_empty() {
        return 0.0;
    }
    let (lo, hi) = bbox(p);
    let d = sub(hi, lo);
    dot(d, d).sqrt()
}

/// Lower and upper corners of the bounding box of a point set (±∞ for an empty set).
pub fn bbox(p: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for q in p {
        for k in 0..3 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    (lo, hi)
}

/// Checks that `tets` index inside `nv` vertices (for meshes built in code, not read).
pub fn check_indices(tets: &[[u32; 4]], nv: usize, file: &Path) -> Result<(), VolError> {
    for (t, tet) in tets.iter().enumerate() {
        for &v in tet {
            if v as usize >= nv {
                return Err(VolError::BadIndex {
                    file: file.to_path_buf(),
                    line: 0,
                    tet: t,
                    index: v as i64,
                    count: nv,
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn single_tet_boundary_is_outward() {
        let m = TetMesh::new(
            vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
            vec![[0, 1, 2, 3]],
        );
        let f = m.boundary_faces();
        assert_eq!(f.len(), 4);
        // Every outward face's normal points away from the centroid.
        let c = [0.25; 3];
        for t in f {
            let p = |i: u32| m.positions[i as usize];
            let n = cross(sub(p(t[1]), p(t[0])), sub(p(t[2]), p(t[0])));
            assert!(dot(n, sub(p(t[0]), c)) > 0.0);
        }
        assert_eq!(m.boundary_vertices(), vec![0, 1, 2, 3]);
    }

    /// Three tets around the axis 3–4 of a triangular bipyramid: the axis is an interior edge
    /// whose two ends are on the boundary (a chord, once on the sphere).
    pub(crate) fn bipyramid() -> TetMesh {
        TetMesh::new(
            vec![
                [1., 0., 0.],
                [-0.5, 0.8, 0.],
                [-0.5, -0.8, 0.],
                [0., 0., 1.],
                [0., 0., -1.],
            ],
            vec![[3, 4, 1, 0], [3, 4, 2, 1], [3, 4, 0, 2]],
        )
    }

    #[test]
    fn split_edge_halves_every_tet_on_it_and_keeps_the_boundary() {
        let mut m = bipyramid();
        assert!(m.inverted(&m.positions).is_empty());
        let before = m.boundary_faces();
        let vol: f64 = (0..3).map(|t| m.volume_at(&m.positions, t)).sum();
        // A map with one tet inverted: the halves of that tet stay inverted, no other is.
        let mut x = m.positions.clone();
        x[0] = [-0.2, 0.0, 0.0];
        let inv = m.inverted(&x).len();
        assert!(inv > 0);
        let done = m.split_edges(&[[3, 4], [0, 1], [4, 3]], &mut [&mut x]);
        // 3–4 split (vertex 5 at its midpoint); 0–1 is an edge of one tet now; 4–3 no more.
        assert_eq!(done, vec![[5, 3, 4], [6, 0, 1]]);
        assert_eq!(m.positions[5], [0.0, 0.0, 0.0]);
        assert_eq!(x.len(), 7);
        assert_eq!(m.tets.len(), 3 * 2 + 2);
        assert_eq!(m.tet_refs.len(), m.tets.len());
        assert_eq!(m.vertex_refs.len(), 7);
        let after: f64 = (0..m.tets.len())
            .map(|t| m.volume_at(&m.positions, t))
            .sum();
        assert!((after - vol).abs() < 1e-12 * vol);
        assert!(m.inverted(&m.positions).is_empty());
        // The surface is the same triangles, split where 0–1 was (a boundary edge here).
        assert_eq!(before.len() + 2, m.boundary_faces().len());
        assert!(m.inverted(&x).len() >= inv);
        let mut m2 = bipyramid();
        m2.split_edges(&[[3, 4]], &mut []);
        assert_eq!(before, m2.boundary_faces());
    }
}
