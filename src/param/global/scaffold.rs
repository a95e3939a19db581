//! The scaffold that keeps a chart's boundary from crossing itself: SCAF (Jiang, Schaefer &
//! Panozzo, "Simplicial Complex Augmentation Framework for Bijective Maps", SIGGRAPH Asia 2017).
//!
//! The region between the chart's UV boundary and a fixed square frame around it is
//! triangulated (a constrained Delaunay triangulation of the boundary vertices and the frame,
//! no Steiner points), and those triangles join the chart in the solve with the symmetric
//! Dirichlet energy relative to their own shape at the time they were built. Chart and scaffold
//! together triangulate the frame's square, whose boundary does not move; a step that keeps
//! every triangle of the union positive therefore keeps the union a bijection onto the square
//! (a locally injective map of a disk that is injective on its boundary is injective), so the
//! chart's boundary cannot touch itself. The flip-free line search of the solver already finds
//! the largest such step: for a scaffold triangle spanned by a boundary vertex and a boundary
//! edge, the root of its determinant *is* the time of impact of that vertex on that edge's line,
//! and every first contact is between vertices and edges of one scaffold triangle (the
//! triangulation fills the gap between them). The scaffold is rebuilt from the current map
//! before every iteration, so it never limits the chart more than its local geometry demands.
//!
//! At its rest shape a scaffold triangle has zero gradient; its only effects are the barrier
//! (its energy grows without bound as it collapses) and its stiffness in the step's Hessian,
//! set by a weight the solver adapts per step ([`next_weight`]).
//!
//! ADMM uses the same scaffold as more faces of its per-face iteration
//! ([`crate::param::admm::AdmmProblem::with_scaffold`]), built once around its start map.

use spade::{ConstrainedDelaunayTriangulation, HasPosition, Point2, Triangulation};

use super::assembly::FaceGradient;

/// Largest total weight of the scaffold relative to the chart's energy (SCAF's published
/// choice: each of the `n` scaffold triangles weighs `W E / n`, `W = 1/100`, for a chart of mean
/// energy `E` and unit total weight; scale-free, as `E` is a mean of a dimensionless energy).
/// With equal weights a triangle's stiffness grows as its area shrinks, so it is greatest
/// exactly where boundary parts are close (the scaffold triangles between them are small).
///
/// The scaffold's gradient is zero at its rest shape (reset before every step), so at a
/// fixed point of the iteration the weight has no effect on the map: it only sets how stiffly
/// the scaffold resists the boundary's motion within one step, a proximal term that slows
/// every mode of the chart it couples to, contact or not, while its barrier (infinite at
/// collapse whatever the weight) and the flip-free step bound keep the boundary apart. So the
/// solver adapts `W` as an interior-point method adapts its barrier parameter
/// ([`next_weight`]): stiffer while contact bounds the steps (the Newton model then sees the
/// contact and slides along it instead of being cut short at it), softer while it does not.
/// Either fixed extreme fails for a reason that holds on any chart: a stiff weight drags every
/// step (full Newton steps that barely lower the energy), a soft one leaves the Newton model
/// blind to the contact, so steps are cut short at it. Measured on the whole atlas corpus, 77
/// meshes (BENCHMARKS.md, "Bijective maps, round 2"): scaffold iterations in total 6403 at a
/// fixed `1/100`, 1764 at a fixed `1e-4`, 1865 adapted, at the same energies.
pub const WEIGHT: f64 = 0.01;

/// Smallest scaffold weight: the scaffold's share of the objective (`4 W E` at rest) stays
/// ~1e-8 of it, far above rounding, so its barrier is still there, while its stiffness is too
/// small to hold the chart back.
pub const WEIGHT_MIN: f64 = 1e-8;

/// Factor by which the scaffold weight changes per step (one decade: from the softest to
/// the stiffest weight in six steps of contact).
pub const WEIGHT_STEP: f64 = 10.0;

/// The scaffold weight for the next step after a step at `w`: ×[`WEIGHT_STEP`] when a
/// scaffold triangle bounded the step (`limited`), ÷[`WEIGHT_STEP`] when it did not, within
/// [`WEIGHT_MIN`]..=[`WEIGHT`].
pub fn next_weight(w: f64, limited: bool) -> f64 {
    if limited {
        (w * WEIGHT_STEP).min(WEIGHT)
    } else {
        (w / WEIGHT_STEP).max(WEIGHT_MIN)
    }
}

/// Half-size of the frame square over the largest half-extent of the chart's boundary, as
/// in SCAF: far enough that the chart never reaches it within a step (the triangles between
/// them would have to flip first), near enough to keep those triangles well shaped.
const FRAME_SCALE: f64 = 3.0;

/// Frame vertices per side of the square.
const FRAME_POINTS_PER_SIDE: usize = 5;

/// Directed boundary edges `[a, b]` of a triangle mesh, in the direction their one face
/// traverses them (counter-clockwise around the chart in a flip-free map), sorted.
pub fn boundary_edges(faces: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut half: Vec<[u32; 2]> = faces
        .iter()
        .flat_map(|f| (0..3).map(move |k| [f[k], f[(k + 1) % 3]]))
        .collect();
    half.sort_unstable();
    half.iter()
        .filter(|e| half.binary_search(&[e[1], e[0]]).is_err())
        .copied()
        .collect()
}

/// Whether the map `uv` of the triangles `faces` has a boundary that is a set of simple,
/// disjoint curves (no two boundary edges cross, no two boundary vertices coincide): the
/// start the bijective global solver needs.
pub fn simple_boundary(uv: &[[f64; 2]], faces: &[[u32; 3]]) -> bool {
    let x: &[f64] = bytemuck::cast_slice(uv);
    Scaffold::build(x, uv.len(), &boundary_edges(faces)).is_some()
}

/// The scaffold triangles around one map of a chart.
#[derive(Clone, Debug)]
pub struct Scaffold {
    /// Counter-clockwise triangles over chart vertices (indices < `nv`, boundary vertices only)
    /// and frame vertices (index `nv + i` for `frame[i]`).
    pub faces: Vec<[u32; 3]>,
    /// Each triangle's gradient operator at its rest shape.
    pub rest: Vec<FaceGradient>,
    /// Positions of the frame vertices (fixed).
    pub frame: Vec<[f64; 2]>,
}

/// A CDT vertex: its position and the solver's index for it.
#[derive(Clone, Copy, Debug)]
struct Vertex {
    p: Point2<f64>,
}

impl HasPosition for Vertex {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.p
    }
}

impl Scaffold {
    /// The scaffold of the chart map `x` (interleaved UVs of `nv` vertices) with boundary
    /// edges `boundary` ([`boundary_edges`]). `None` when the boundary is not a set of simple,
    /// disjoint curves (two boundary edges cross or two boundary vertices coincide): there is
    /// no scaffold for a map that already overlaps.
    pub fn build(x: &[f64], nv: usize, boundary: &[[u32; 2]]) -> Option<Scaffold> {
        // Boundary vertices, in ascending index, and their local numbers.
        let mut verts: Vec<u32> = boundary.iter().flatten().copied().collect();
        verts.sort_unstable();
        verts.dedup();
        if verts.len() < 3 {
            return None;
        }
        let local = |v: u32| verts.binary_search(&v).ok();
        let at = |v: u32| [x[2 * v as usize], x[2 * v as usize + 1]];
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for &v in &verts {
            let p = at(v);
            for r in 0..2 {
                lo[r] = lo[r].min(p[r]);
                hi[r] = hi[r].max(p[r]);
            }
        }
        let half = 0.5 * (hi[0] - lo[0]).max(hi[1] - lo[1]);
        if !(half > 0.0 && half.is_finite()) {
            return None;
        }
        let mid = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        let s = FRAME_SCALE * half;
        let corners = [[-s, -s], [s, -s], [s, s], [-s, s]];
        let n = FRAME_POINTS_PER_SIDE;
        let frame: Vec<[f64; 2]> = (0..4)
            .flat_map(|side| {
                let (a, b) = (corners[side], corners[(side + 1) % 4]);
                (0..n).map(move |i| {
                    let t = i as f64 / n as f64;
                    [
                        mid[0] + a[0] + t * (b[0] - a[0]),
                        mid[1] + a[1] + t * (b[1] - a[1]),
                    ]
                })
            })
            .collect();
        let nb = verts.len();
        let points: Vec<Vertex> = verts
            .iter()
            .map(|&v| at(v))
            .chain(frame.iter().copied())
            .map(|p| Vertex {
                p: Point2::new(p[0], p[1]),
            })
            .collect();
        let mut edges: Vec<[usize; 2]> = boundary
            .iter()
            .map(|e| Some([local(e[0])?, local(e[1])?]))
            .collect::<Option<_>>()?;
        let nf = frame.len();
        edges.extend((0..nf).map(|i| [nb + i, nb + (i + 1) % nf]));
        let mut conflict = false;
        let cdt =
            ConstrainedDelaunayTriangulation::<Vertex>::try_bulk_load_cdt(points, edges, |_| {
                conflict = true
            })
            .ok()?;
        // Coinciding vertices were merged: the boundary touches itself.
        if conflict || cdt.num_vertices() != nb + nf {
            return None;
        }
        // Chart faces are the triangles reached from the frame across an odd number of chart
        // boundary edges; the rest (the outside, and holes) is scaffold.
        let faces: Vec<_> = cdt.inner_faces().collect();
        let mut side = vec![u8::MAX; cdt.num_all_faces()];
        let mut stack = Vec::new();
        for f in &faces {
            if f.adjacent_edges().iter().any(|e| e.rev().face().is_outer()) {
                side[f.fix().index()] = 0;
                stack.push(f.fix());
            }
        }
        while let Some(fh) = stack.pop() {
            let f = cdt.face(fh);
            let s = side[fh.index()];
            for e in f.adjacent_edges() {
                let g = e.rev().face();
                let Some(g) = g.as_inner() else { continue };
                let crosses = e.is_constraint_edge()
                    && e.from().fix().index() < nb
                    && e.to().fix().index() < nb;
                let t = s ^ u8::from(crosses);
                let gi = g.fix().index();
                if side[gi] == u8::MAX {
                    side[gi] = t;
                    stack.push(g.fix());
                } else if side[gi] != t {
                    return None;
                }
            }
        }
        let id = |i: usize| {
            if i < nb {
                verts[i]
            } else {
                (nv + i - nb) as u32
            }
        };
        let mut out_faces = Vec::new();
        let mut rest = Vec::new();
        for f in &faces {
            if side[f.fix().index()] != 0 {
                continue;
            }
            let vs = f.vertices().map(|v| v.fix().index());
            let p = f.positions().map(|q| [q.x, q.y]);
            out_faces.push(vs.map(id));
            rest.push(rest_gradient(p)?);
        }
        Some(Scaffold {
            faces: out_faces,
            rest,
            frame,
        })
    }
}

impl Scaffold {
    /// One triangle `[c, e, a]` per edge `(a, b)` shared by two scaffold triangles `(a, b, c)`
    /// and `(b, a, e)`: it holds the edge `c–e` that flipping `(a, b)` would create. A
    /// re-triangulation that differs from this one by such flips only is served by a pattern
    /// that has these edges too, unchanged ([`super::assembly::Pattern::rebind`]). It serves
    /// when the boundary moves little between re-triangulations: the Delaunay triangulations
    /// of nearby point sets differ by few flips, and by more the farther the points move (how
    /// often it serves on the corpus: BENCHMARKS.md, round 3).
    pub fn flip_diagonals(&self) -> Vec<[u32; 3]> {
        // Directed edge (a, b) → opposite corner, for every triangle.
        let mut half: Vec<([u32; 2], u32)> = self
            .faces
            .iter()
            .flat_map(|f| (0..3).map(move |k| ([f[k], f[(k + 1) % 3]], f[(k + 2) % 3])))
            .collect();
        half.sort_unstable();
        half.iter()
            .filter(|(e, _)| e[0] < e[1])
            .filter_map(|&([a, b], c)| {
                let k = half.binary_search_by(|h| h.0.cmp(&[b, a])).ok()?;
                Some([c, half[k].1, a])
            })
            .collect()
    }

    /// Makes the current shape of every triangle its rest shape (chart map `x` of `nv`
    /// vertices), keeping the triangles, so the scaffold starts the next step at zero gradient
    /// again. `false` (nothing changed) if a triangle has no area left: build a new scaffold.
    pub fn reset_rest(&mut self, x: &[f64], nv: usize) -> bool {
        let at = |v: u32| {
            let v = v as usize;
            if v < nv {
                [x[2 * v], x[2 * v + 1]]
            } else {
                self.frame[v - nv]
            }
        };
        match self
            .faces
            .iter()
            .map(|f| rest_gradient(f.map(at)))
            .collect()
        {
            Some(rest) => {
                self.rest = rest;
                true
            }
            None => false,
        }
    }
}

/// The gradient operator of a scaffold triangle at rest: its own shape, so it starts at the
/// energy's minimum with zero gradient, and the chart's energy cannot rise in a step that
/// lowers the sum (SCAF's implementation gives slivers an equilateral rest shape instead, to
/// bound the system's conditioning; that gives them a gradient, and steps then traded chart
/// energy for scaffold energy). `None` for a triangle with no positive area.
fn rest_gradient(p: [[f64; 2]; 3]) -> Option<FaceGradient> {
    let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1]];
    let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1]];
    let det = e1[0] * e2[1] - e2[0] * e1[1];
    let g1 = [e2[1] / det, -e2[0] / det];
    let g2 = [-e1[1] / det, e1[0] / det];
    let g = [[-g1[0] - g2[0], -g1[1] - g2[1]], g1, g2];
    (det > 0.0 && g.iter().flatten().all(|v| v.is_finite())).then_some(g)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::param::global::assembly::jacobian;

    /// A square of two triangles, and a C-shaped chart.
    fn square() -> (Vec<[u32; 3]>, Vec<f64>) {
        (
            vec![[0, 1, 2], [0, 2, 3]],
            vec![0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0],
        )
    }

    #[test]
    fn boundary_edges_of_a_square() {
        let (f, _) = square();
        assert_eq!(boundary_edges(&f), vec![[0, 1], [1, 2], [2, 3], [3, 0]]);
    }

    /// Scaffold and chart tile the frame square: areas add up, every scaffold triangle is
    /// positive, at rest (Jacobian = identity) and touches only boundary or frame vertices.
    #[test]
    fn scaffold_fills_the_frame_around_the_chart() {
        let (f, x) = square();
        let s = Scaffold::build(&x, 4, &boundary_edges(&f)).expect("simple boundary");
        let pos = |v: u32| {
            if (v as usize) < 4 {
                [x[2 * v as usize], x[2 * v as usize + 1]]
            } else {
                s.frame[v as usize - 4]
            }
        };
        let mut area = 0.0;
        let xe: Vec<f64> = (0..4 + s.frame.len() as u32).flat_map(pos).collect();
        for (t, g) in s.faces.iter().zip(&s.rest) {
            let [a, b, c] = t.map(pos);
            let det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
            assert!(det > 0.0);
            area += 0.5 * det;
            let j = jacobian(g, t, &xe);
            for (v, w) in j.iter().zip([1.0, 0.0, 0.0, 1.0]) {
                assert!((v - w).abs() < 1e-9, "{j:?}");
            }
        }
        // Frame square of side 2·3·0.5 = 3, minus the unit chart.
        assert!((area - 8.0).abs() < 1e-9, "{area}");
    }

    /// Every edge shared by two scaffold triangles gives the triangle holding the other
    /// diagonal of their quad, and nothing else does.
    #[test]
    fn flip_diagonals_hold_the_other_diagonal_of_each_quad() {
        let (f, x) = square();
        let s = Scaffold::build(&x, 4, &boundary_edges(&f)).expect("simple boundary");
        let mut shared: Vec<[u32; 2]> = s
            .faces
            .iter()
            .flat_map(|t| (0..3).map(move |k| [t[k], t[(k + 1) % 3]]))
            .filter(|e| {
                e[0] < e[1]
                    && s.faces
                        .iter()
                        .any(|t| (0..3).any(|k| [t[k], t[(k + 1) % 3]] == [e[1], e[0]]))
            })
            .collect();
        shared.sort_unstable();
        let diagonals = s.flip_diagonals();
        assert_eq!(diagonals.len(), shared.len());
        for ([a, b], [c, e, a2]) in shared.iter().zip(&diagonals) {
            assert_eq!(*a, *a2);
            // c and e are the corners opposite (a, b) in its two triangles.
            for v in [c, e] {
                assert!(v != a && v != b);
                assert!(s
                    .faces
                    .iter()
                    .any(|t| t.contains(a) && t.contains(b) && t.contains(v)));
            }
            assert_ne!(c, e);
        }
    }

    /// A map whose boundary crosses itself has no scaffold.
    #[test]
    fn no_scaffold_for_an_overlapping_boundary() {
        let (f, mut x) = square();
        // Vertex 2 pulled across edge 0–1: the boundary 1–2 crosses 3–0.
        x[4] = -1.0;
        x[5] = 0.5;
        assert!(Scaffold::build(&x, 4, &boundary_edges(&f)).is_none());
    }
}
