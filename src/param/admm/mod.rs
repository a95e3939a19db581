//! ADMM parameterization (after Wu & Zhang 2020, "Mesh parameterization based on GPU parallel
//! optimization"), with the frame handling made explicit.
//!
//! Variables: per face `f` a Jacobian `A_f` (2x2, row-major `[a, b, c, d]`, acting on the face's
//! own isometric 2D frame, see [`crate::mesh::FaceFrames`]); per interior edge `e` with faces
//! `f1 < f2` two copies `Y_e1, Y_e2` and two multipliers `Λ_e1, Λ_e2`. A *slot* is one
//! (edge, side) pair: slot `2i + k` is side `k` of the `i`-th interior edge.
//!
//! Constraint: the edge maps to the same UV vector from both sides, `Y_e1 ê1 = Y_e2 ê2`, where
//! `ê_k` is the unit edge vector (lower → higher vertex index) expressed in face `f_k`'s frame.
//!
//! One iteration (each step a GLSL kernel in `glsl/admm/` and a function in [`cpu`]), with
//! face `f`'s penalty `μ_f = μ m_f`:
//! 1. face step: `A_f ← argmin w_f E(A) + μ_f/2 Σ_t ‖A − (Y_t + Λ_t/μ_f)‖²` by projected
//!    Newton with a flip-proof line search (`E = +∞` for `det A ≤ 0`, so `det A_f > 0` always);
//! 2. edge step: `Q_k = A_fk − Λ_k/μ_k`, `r = Q1ê1 − Q2ê2`, `Y1 = Q1 − μ2/(μ1+μ2) r ê1ᵀ`,
//!    `Y2 = Q2 + μ1/(μ1+μ2) r ê2ᵀ`;
//! 3. dual step: `Λ_t += μ_f (Y_t − A_ft)`.
//!
//! Weights are `w_f = area_f / total area`, so `μ` is quoted as `μ_rel = μ · #faces` (with
//! normalised weights the iterates depend on μ only through that product). The per-face
//! factors `m_f` scale each face's penalty to its curvature ([`cpu::penalty_factors`]: MIPS's
//! `F w_f / det A_f` at the start map; 1 for SD).

pub mod anderson;
pub mod cpu;
pub mod driver;
pub mod kernels;
pub mod layout;
pub mod vulkan;

pub use driver::{solve, Accel, AdmmOptions, AdmmResult, AdmmStop, Backend, History};

use crate::mesh::{FaceFrames, Topology, TriMesh, NO_FACE};

/// "No slot" in [`AdmmProblem::face_slots`].
pub const NO_SLOT: u32 = u32::MAX;

/// Everything the iteration needs that does not change while it runs, shaped like the GPU
/// buffers (flat arrays, f64 here, converted to f32 on upload).
#[derive(Clone, Debug)]
pub struct AdmmProblem {
    /// #F: `area_f / total area`.
    pub weight: Vec<f64>,
    /// #F×3: the slots of face `f` (one per interior edge of the face), `NO_SLOT` padded.
    pub face_slots: Vec<[u32; 3]>,
    /// #S: the face owning each slot.
    pub slot_face: Vec<u32>,
    /// #S: unit edge direction `ê` in the owning face's frame.
    pub slot_dir: Vec<[f64; 2]>,
    /// #F×3: local 2D coordinates of each face's corners (corner 0 at the origin).
    pub local: Vec<[[f64; 2]; 3]>,
    /// #F: each face's weight in the least-squares recovery: its 3D area (a scaffold face:
    /// its energy weight at the chart's area scale, see [`AdmmProblem::with_scaffold`]).
    pub area: Vec<f64>,
}

impl AdmmProblem {
    /// Precomputes slots and edge directions from the topology and frames.
    pub fn new(mesh: &TriMesh, topo: &Topology, frames: &FaceFrames) -> AdmmProblem {
        let nf = mesh.faces.len();
        let total: f64 = frames.area.iter().sum();
        let weight = frames.area.iter().map(|a| a / total).collect();
        let mut face_slots = vec![[NO_SLOT; 3]; nf];
        let mut fill = vec![0usize; nf];
        let n_slots = 2 * topo.interior_edges.len();
        let mut slot_face = Vec::with_capacity(n_slots);
        let mut slot_dir = Vec::with_capacity(n_slots);
        for &e in &topo.interior_edges {
            let [v0, v1] = topo.edges[e as usize];
            let p0 = mesh.positions[v0 as usize];
            let p1 = mesh.positions[v1 as usize];
            let d = [p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]];
            for &f in &topo.edge_faces[e as usize] {
                debug_assert!(f != NO_FACE, "interior edges have two faces");
                let l = frames.to_local(f as usize, d);
                let n = (l[0] * l[0] + l[1] * l[1]).sqrt();
                let s = slot_face.len() as u32;
                slot_face.push(f);
                slot_dir.push([l[0] / n, l[1] / n]);
                let k = &mut fill[f as usize];
                face_slots[f as usize][*k] = s;
                *k += 1;
            }
        }
        AdmmProblem {
            weight,
            face_slots,
            slot_face,
            slot_dir,
            local: frames.local.clone(),
            area: frames.area.clone(),
        }
    }

    /// This chart problem with SCAF's scaffold joined ([`crate::param::global::scaffold`]):
    /// the triangles `scaffold` (over the chart's boundary vertices and the frame's vertices,
    /// indices from #V on) become faces after the chart's `chart_faces`, at rest in the map `uv`
    /// (chart and frame), so each starts at the identity; each gets the energy `weight` and
    /// the same weight in the recovery (its `area` is `weight` times the chart's area, the
    /// scale of the chart's own weights), so the scaffold neither pulls the chart's energy
    /// nor its recovery while its faces, like every face, never flip. Their edges become
    /// interior edges with two slots each, after the chart's (whose numbers stay): the
    /// chart's boundary edges (a chart face on one side) and the scaffold's own; the frame's
    /// outer edges stay boundary. An edge's direction is divided by its length in its lower
    /// face (the chart face where there is one), a length common to both sides, so that the
    /// consensus `Y1 e1 = Y2 e2` says the edge maps to one UV vector although its rest lengths
    /// (3D on the chart, UV on the scaffold) differ.
    pub fn with_scaffold(
        &self,
        chart_faces: &[[u32; 3]],
        scaffold: &[[u32; 3]],
        uv: &[[f64; 2]],
        weight: f64,
    ) -> AdmmProblem {
        let nc = chart_faces.len();
        let total: f64 = self.area[..nc].iter().sum();
        let mut p = self.clone();
        for f in scaffold {
            let [o, a, b] = f.map(|v| uv[v as usize]);
            p.local.push([
                [0.0; 2],
                [a[0] - o[0], a[1] - o[1]],
                [b[0] - o[0], b[1] - o[1]],
            ]);
            p.weight.push(weight);
            p.area.push(weight * total);
            p.face_slots.push([NO_SLOT; 3]);
        }
        let face = |f: usize| {
            if f < nc {
                chart_faces[f]
            } else {
                scaffold[f - nc]
            }
        };
        let key = |a: u32, b: u32| (a.min(b), a.max(b));
        // The faces on each side of every scaffold edge (chart faces: along the boundary).
        let mut sides: std::collections::BTreeMap<(u32, u32), Vec<usize>> = Default::default();
        for f in nc..nc + scaffold.len() {
            let t = face(f);
            for k in 0..3 {
                sides.entry(key(t[k], t[(k + 1) % 3])).or_default().push(f);
            }
        }
        for (f, t) in chart_faces.iter().enumerate() {
            for k in 0..3 {
                if let Some(fs) = sides.get_mut(&key(t[k], t[(k + 1) % 3])) {
                    fs.insert(0, f);
                }
            }
        }
        for ((lo, hi), fs) in sides {
            if fs.len() != 2 {
                continue;
            }
            let edge = |f: usize| {
                let t = face(f);
                let c = |v: u32| t.iter().position(|&x| x == v).expect("edge of the face");
                let l = &p.local[f];
                let (a, b) = (l[c(lo)], l[c(hi)]);
                [b[0] - a[0], b[1] - a[1]]
            };
            let r = edge(fs[0]);
            let len = (r[0] * r[0] + r[1] * r[1]).sqrt();
            for &f in &fs {
                let d = edge(f);
                let s = p.slot_face.len() as u32;
                p.slot_face.push(f as u32);
                p.slot_dir.push([d[0] / len, d[1] / len]);
                let free = p.face_slots[f]
                    .iter_mut()
                    .find(|x| **x == NO_SLOT)
                    .expect("a face has at most three edges");
                *free = s;
            }
        }
        p
    }

    pub fn n_faces(&self) -> usize {
        self.weight.len()
    }

    pub fn n_slots(&self) -> usize {
        self.slot_face.len()
    }

    /// `M⁻¹` (row-major) for `M = [l1−l0, l2−l0]`, the face's local corner offsets as columns.
    /// Its rows are the gradients of the hat functions of corners 1 and 2 in the face's frame.
    pub fn frame_inverse(&self, f: usize) -> [f64; 4] {
        let l = &self.local[f];
        let (m00, m01, m10, m11) = (
            l[1][0] - l[0][0],
            l[2][0] - l[0][0],
            l[1][1] - l[0][1],
            l[2][1] - l[0][1],
        );
        let det = m00 * m11 - m01 * m10;
        [m11 / det, -m01 / det, -m10 / det, m00 / det]
    }

    /// Jacobian of face `f` under the per-vertex map `uv`: `A = [u1−u0, u2−u0] · M⁻¹`.
    pub fn jacobian(&self, faces: &[[u32; 3]], uv: &[[f64; 2]], f: usize) -> [f64; 4] {
        let [i0, i1, i2] = faces[f].map(|i| i as usize);
        let inv = self.frame_inverse(f);
        let du = [uv[i1][0] - uv[i0][0], uv[i2][0] - uv[i0][0]];
        let dv = [uv[i1][1] - uv[i0][1], uv[i2][1] - uv[i0][1]];
        [
            du[0] * inv[0] + du[1] * inv[2],
            du[0] * inv[1] + du[1] * inv[3],
            dv[0] * inv[0] + dv[1] * inv[2],
            dv[0] * inv[1] + dv[1] * inv[3],
        ]
    }
}

/// The iterate: per-face Jacobians, per-slot copies and multipliers.
#[derive(Clone, Debug, PartialEq)]
pub struct AdmmState {
    /// #F
    pub a: Vec<[f64; 4]>,
    /// #S
    pub y: Vec<[f64; 4]>,
    /// #S
    pub lambda: Vec<[f64; 4]>,
}

impl AdmmState {
    /// A consistent start: `A_f` from the map `uv`, `Y = A`, `Λ = 0`. Faces the map flips,
    /// collapses or leaves non-finite get the nearest orientation-preserving similarity at the
    /// face's own area scale instead (`orientation_preserving_similarity`), so that every `A_f`
    /// starts orientation-preserving; ADMM reconciles them.
    ///
    /// The test is relative to the face's own size (`det A > 1e-6 ‖A‖²/2`, i.e. `σ2/σ1` above
    /// ~1e-6): that is where the device's f32 copy of `det A = ad − bc` could round to a wrong
    /// sign. It is not relative to the map's mean scale: the exponentially shrunk protrusions
    /// of a conformal map have faces 1e-6 of the mean and less, and replacing those by
    /// mean-size similarities threw away the start map exactly where ADMM converges slowest.
    pub fn from_uv(problem: &AdmmProblem, faces: &[[u32; 3]], uv: &[[f64; 2]]) -> AdmmState {
        let mean_scale = {
            let mut s = 0.0;
            let mut w = 0.0;
            for f in 0..faces.len() {
                let a = problem.jacobian(faces, uv, f);
                let d = crate::param::energy::det(&a);
                if d > 0.0 && d.is_finite() {
                    s += problem.weight[f] * d.sqrt();
                    w += problem.weight[f];
                }
            }
            if w > 0.0 {
                s / w
            } else {
                1.0
            }
        };
        let a: Vec<[f64; 4]> = (0..faces.len())
            .map(|f| {
                let a = problem.jacobian(faces, uv, f);
                let d = crate::param::energy::det(&a);
                let n2: f64 = a.iter().map(|x| x * x).sum();
                if d > 0.5e-6 * n2 && a.iter().all(|x| x.is_finite()) {
                    a
                } else {
                    orientation_preserving_similarity(&a, mean_scale)
                }
            })
            .collect();
        let y: Vec<[f64; 4]> = problem.slot_face.iter().map(|&f| a[f as usize]).collect();
        let lambda = vec![[0.0; 4]; y.len()];
        AdmmState { a, y, lambda }
    }
}

/// The nearest similarity to `A` with positive determinant at the face's own area scale:
/// the rotation of `A`'s conformal part `[p −q; q p]` (p = (a+d)/2, q = (c−b)/2; the identity
/// when that part vanishes) scaled to `√|det A|`, the scale at which the face keeps its area
/// (its conformal part's own size when `A` is collapsed, `scale` when both vanish or are not
/// finite): a folded face in a shrunk region stays at that region's size.
fn orientation_preserving_similarity(a: &[f64; 4], scale: f64) -> [f64; 4] {
    let p = 0.5 * (a[0] + a[3]);
    let q = 0.5 * (a[2] - a[1]);
    let n = (p * p + q * q).sqrt();
    let (c, s) = if n > 0.0 && n.is_finite() {
        (p / n, q / n)
    } else {
        (1.0, 0.0)
    };
    let area_scale = crate::param::energy::det(a).abs().sqrt();
    let r = [area_scale, n, scale]
        .into_iter()
        .find(|x| *x > 0.0 && x.is_finite())
        .unwrap_or(1.0);
    [r * c, -r * s, r * s, r * c]
}
