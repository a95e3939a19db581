//! Plane and polygon helpers shared by the approximation stages, over the crate's 3-vector
//! functions ([`crate::linalg::vec3`], re-exported here so the stages read as formulas).

use crate::linalg::small::sym_eigen;
use crate::mesh::TriMesh;

pub use crate::linalg::rng::SplitMix;
pub use crate::linalg::vec3::{add, cross, dot, norm, normalize, scale, sub, V3};

/// Area-scaled normal (half the cross product) of face `f` at `pos`.
pub fn face_area_normal(pos: &[V3], f: [u32; 3]) -> V3 {
    let [a, b, c] = f.map(|i| pos[i as usize]);
    scale(cross(sub(b, a), sub(c, a)), 0.5)
}

/// Unit normals and areas of all faces; a zero-area face gets normal 0 (callers that need a
/// direction validated the mesh first).
pub fn face_normals_areas(pos: &[V3], faces: &[[u32; 3]]) -> (Vec<V3>, Vec<f64>) {
    faces
        .iter()
        .map(|&f| {
            let an = face_area_normal(pos, f);
            let a = norm(an);
            (normalize(an).unwrap_or([0.0; 3]), a)
        })
        .unzip()
}

/// Applies the minimal rotation taking unit `from` onto unit `to` to `v` (Rodrigues without
/// trigonometry: R v = c·v + w×v + w(w·v)/(1+c), w = from×to, c = from·to). Opposite vectors
/// have no unique minimal rotation; any half-turn about an axis ⟂ `from` is used.
pub fn rotate_min(from: V3, to: V3, v: V3) -> V3 {
    let c = dot(from, to);
    if c > -1.0 + 1e-9 {
        let w = cross(from, to);
        add(
            add(scale(v, c), cross(w, v)),
            scale(w, dot(w, v) / (1.0 + c)),
        )
    } else {
        let helper = if from[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let k = normalize(cross(from, helper)).unwrap_or([0.0, 0.0, 1.0]);
        sub(scale(k, 2.0 * dot(k, v)), v)
    }
}

/// A plane n·x + d = 0 with unit n.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Plane {
    pub n: V3,
    pub d: f64,
}

impl Plane {
    pub fn signed_distance(&self, p: V3) -> f64 {
        dot(self.n, p) + self.d
    }
}

/// Which principal plane of a region's faces (or points) is its plane.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PlaneRule {
    /// The least-squares plane (the smallest principal direction is the normal): the plane
    /// nearest the faces, what the error is measured by.
    #[default]
    LeastSquares,
    /// The principal plane the faces face: the principal direction nearest their mean normal
    /// is the normal.
    ///
    /// Why: every principal direction is a stationary point of the squared distance, and the
    /// smallest one gives the least-squares plane — but a region thinner than it is curved (a
    /// rim or fillet bent along its length: its sagitta exceeds its width) has its
    /// least-squares plane *across* its faces. Its polygon would be its outline seen edge-on
    /// (the polygon's area is the outline's projection onto the plane, `n · Σ aᵢnᵢ`, near
    /// zero), and its neighbours' planes meet it nearly parallel, far away: a flange's rim or
    /// the wall of a bolt hole through it gets the flange's own plane. The plane the faces face
    /// is the one they project onto with the largest area among the principal planes; on a
    /// region flatter than it is wide it is the least-squares plane itself.
    Facing,
}

/// The column of `vecs` (principal directions, eigenvalues decreasing) that `rule` takes as
/// the normal of a region whose faces face `orient`; ties and a zero `orient` give the last
/// (least-squares) one.
pub fn principal_axis(vecs: &[[f64; 3]; 3], orient: V3, rule: PlaneRule) -> usize {
    match rule {
        PlaneRule::LeastSquares => 2,
        PlaneRule::Facing => {
            let col = |j: usize| dot([vecs[0][j], vecs[1][j], vecs[2][j]], orient).abs();
            (0..3)
                .rev()
                .fold(2, |best, j| if col(j) > col(best) { j } else { best })
        }
    }
}

/// Plane through weighted points (PCA: its normal the principal direction of the covariance
/// that `rule` picks), oriented along `orient` so that its normal agrees with the faces it
/// stands for. `None` when there are no points or no weight.
pub fn fit_plane(
    points: impl Iterator<Item = (V3, f64)> + Clone,
    orient: V3,
    rule: PlaneRule,
) -> Option<Plane> {
    let mut wsum = 0.0;
    let mut c = [0.0; 3];
    for (p, w) in points.clone() {
        wsum += w;
        c = add(c, scale(p, w));
    }
    if wsum <= 0.0 {
        return None;
    }
    c = scale(c, 1.0 / wsum);
    let mut m = [[0.0; 3]; 3];
    for (p, w) in points {
        let q = sub(p, c);
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += w * q[i] * q[j];
            }
        }
    }
    let (_, vecs) = sym_eigen::<3>(&m);
    let j = principal_axis(&vecs, orient, rule);
    let mut n = [vecs[0][j], vecs[1][j], vecs[2][j]];
    n = normalize(n)?;
    if dot(n, orient) < 0.0 {
        n = scale(n, -1.0);
    }
    Some(Plane { n, d: -dot(n, c) })
}

/// The plane minimising `Σ w |n·p + d|` over weighted points (least absolute distances),
/// oriented like `start`, by iteratively reweighted least squares from `start`: each round
/// fits the least-squares plane with weights `w / |r|` at the last residuals `r`, which
/// majorises the absolute value (`|x| ≤ x²/2|r| + |r|/2`, equal at `x = r`) and is minimised
/// exactly by [`fit_plane`], so no round increases the sum (Weiszfeld's argument) — up to the
/// floor: residuals are floored at `floor` (a point on the plane would get an infinite
/// weight), so the best plane met is returned, `start` if no round improves on it. Under
/// [`PlaneRule::Facing`] each round fits the weighted plane the points face instead (no
/// longer a minimiser, so no round is promised a gain: the best met is still what returns).
pub fn l1_plane(points: &[(V3, f64)], start: Plane, floor: f64, rule: PlaneRule) -> Plane {
    /// Rounds: each costs one pass over the points and a 3×3 eigenproblem. IRLS converges
    /// linearly; after 20 rounds the whole mesh's error was within 0.1 % of 100 rounds'
    /// (two corpus meshes at K 60, BENCHMARKS.md round 15).
    const ROUNDS: usize = 20;
    let cost = |p: &Plane| -> f64 {
        points
            .iter()
            .map(|&(q, w)| w * p.signed_distance(q).abs())
            .sum()
    };
    let (mut best, mut best_cost) = (start, cost(&start));
    let mut p = start;
    for _ in 0..ROUNDS {
        let reweighted = points
            .iter()
            .map(|&(q, w)| (q, w / p.signed_distance(q).abs().max(floor)));
        let Some(next) = fit_plane(reweighted, start.n, rule) else {
            break;
        };
        p = next;
        let c = cost(&p);
        if c < best_cost {
            (best, best_cost) = (p, c);
        }
    }
    best
}

/// The plane a share `t` of the way from `a` to `b` (their coefficients blended, then
/// scaled to a unit normal); `a` at 0, `b` at 1. `a` and `b` must not be opposite.
pub fn blend_planes(a: &Plane, b: &Plane, t: f64) -> Plane {
    let n = add(scale(a.n, 1.0 - t), scale(b.n, t));
    let l = norm(n);
    Plane {
        n: scale(n, 1.0 / l),
        d: ((1.0 - t) * a.d + t * b.d) / l,
    }
}

/// The axis-aligned bounding box `[lo, hi]` of `points` (`lo > hi` where there are none).
pub fn bounds(points: impl IntoIterator<Item = V3>) -> [V3; 2] {
    let empty = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
    points.into_iter().fold(empty, |[lo, hi], p| {
        [
            [0, 1, 2].map(|k| lo[k].min(p[k])),
            [0, 1, 2].map(|k| hi[k].max(p[k])),
        ]
    })
}

/// Bounding-box diagonal of the vertices used by faces.
pub fn bbox_diagonal(mesh: &TriMesh) -> f64 {
    let used = mesh
        .faces
        .iter()
        .flatten()
        .map(|&v| mesh.positions[v as usize]);
    let [lo, hi] = bounds(used);
    if lo[0] > hi[0] {
        return 0.0;
    }
    norm(sub(hi, lo))
}

/// Mean edge length over the listed edges (the length unit of the stages' parameters).
pub fn mean_edge_length(pos: &[V3], edges: &[[u32; 2]]) -> f64 {
    if edges.is_empty() {
        return 1.0;
    }
    let s: f64 = edges
        .iter()
        .map(|e| norm(sub(pos[e[1] as usize], pos[e[0] as usize])))
        .sum();
    s / edges.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimal_rotation_maps_from_onto_to_and_keeps_lengths() {
        let from = normalize([1.0, 2.0, 3.0]).unwrap_or([0.0; 3]);
        for to in [[0.0, 0.0, 1.0], [-1.0, 0.5, 0.2], scale(from, -1.0)] {
            let to = normalize(to).unwrap_or([0.0; 3]);
            let r = rotate_min(from, to, from);
            assert!(norm(sub(r, to)) < 1e-12, "{r:?} vs {to:?}");
            let v = [0.3, -0.7, 2.0];
            assert!((norm(rotate_min(from, to, v)) - norm(v)).abs() < 1e-12);
        }
        // The axis from × to is left alone (minimal rotation).
        let (a, b) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        assert!(norm(sub(rotate_min(a, b, [0.0, 0.0, 1.0]), [0.0, 0.0, 1.0])) < 1e-12);
    }

    #[test]
    fn plane_fit_recovers_a_tilted_plane_and_orients_it() {
        let n = normalize([1.0, -2.0, 0.5]).unwrap_or([0.0; 3]);
        let u = normalize(cross(n, [0.0, 0.0, 1.0])).unwrap_or([0.0; 3]);
        let w = cross(n, u);
        let pts: Vec<(V3, f64)> = (0..20)
            .map(|i| {
                let (a, b) = ((i % 5) as f64, (i / 5) as f64 * 0.7);
                (add(add(scale(u, a), scale(w, b)), scale(n, -3.0)), 1.0)
            })
            .collect();
        let p = fit_plane(pts.iter().copied(), scale(n, -1.0), PlaneRule::LeastSquares).unwrap();
        assert!((dot(p.n, n) + 1.0).abs() < 1e-10, "oriented along the hint");
        for (q, _) in &pts {
            assert!(p.signed_distance(*q).abs() < 1e-10);
        }
    }

    /// A band a tenth of a unit wide around a third of a unit cylinder (sagitta 0.5 > width
    /// 0.1): its least-squares plane is across it (normal along the axis, z); the plane its
    /// faces face (normal x, the middle of the arc) is the facing rule's. A slightly bent sheet
    /// as wide as it is long has one plane under both rules.
    #[test]
    fn a_thin_bent_band_faces_a_plane_other_than_its_least_squares_one() {
        let band = |half_angle: f64, width: f64| -> Vec<(V3, f64)> {
            (0..200)
                .map(|i| {
                    let t = half_angle * ((i % 20) as f64 / 9.5 - 1.0);
                    ([t.cos(), t.sin(), width * (i / 20) as f64 / 9.0], 1.0)
                })
                .collect()
        };
        let fit = |pts: &[(V3, f64)], rule| fit_plane(pts.iter().copied(), [1.0, 0.0, 0.0], rule);
        let across = band(std::f64::consts::PI / 3.0, 0.1);
        let l2 = fit(&across, PlaneRule::LeastSquares).unwrap();
        assert!(l2.n[2].abs() > 1.0 - 1e-9, "{l2:?}");
        let facing = fit(&across, PlaneRule::Facing).unwrap();
        assert!(facing.n[0] > 1.0 - 1e-9, "{facing:?}");
        let sheet = band(0.3, 1.0);
        for rule in [PlaneRule::LeastSquares, PlaneRule::Facing] {
            let q = fit(&sheet, rule).unwrap();
            assert!(q.n[0] > 1.0 - 1e-9, "{rule:?}: {q:?}");
        }
    }

    /// Least absolute distances ignore what least squares averages in: a flat 5×5 grid with
    /// one point far above it. The least-squares plane is lifted and tilted towards the
    /// outlier; the L1 plane is the grid's own, and its sum is the outlier's distance alone.
    #[test]
    fn l1_plane_is_the_grid_not_the_outlier_and_never_worse_than_its_start() {
        let mut pts: Vec<(V3, f64)> = (0..25)
            .map(|i| ([(i % 5) as f64, (i / 5) as f64, 0.0], 1.0))
            .collect();
        pts.push(([4.0, 4.0, 10.0], 1.0));
        let l2 = fit_plane(
            pts.iter().copied(),
            [0.0, 0.0, 1.0],
            PlaneRule::LeastSquares,
        )
        .unwrap();
        assert!(l2.d.abs() > 0.1, "{l2:?}");
        let l1 = l1_plane(&pts, l2, 1e-12, PlaneRule::LeastSquares);
        assert!(l1.n[2] > 1.0 - 1e-9 && l1.d.abs() < 1e-6, "{l1:?}");
        let sum = |p: &Plane| -> f64 {
            pts.iter()
                .map(|&(q, w)| w * p.signed_distance(q).abs())
                .sum()
        };
        assert!((sum(&l1) - 10.0).abs() < 1e-5 && sum(&l1) < sum(&l2));
        // From the optimum it stays there.
        let again = l1_plane(&pts, l1, 1e-12, PlaneRule::LeastSquares);
        assert!(sum(&again) <= sum(&l1));
    }

    #[test]
    fn blended_planes_run_from_one_to_the_other_with_unit_normals() {
        let a = Plane {
            n: [0.0, 0.0, 1.0],
            d: -1.0,
        };
        let b = Plane {
            n: normalize([0.0, 1.0, 1.0]).unwrap(),
            d: -2.0,
        };
        assert_eq!(blend_planes(&a, &b, 0.0), a);
        let end = blend_planes(&a, &b, 1.0);
        assert!(dot(end.n, b.n) > 1.0 - 1e-15 && (end.d - b.d).abs() < 1e-12);
        let mid = blend_planes(&a, &b, 0.5);
        assert!((norm(mid.n) - 1.0).abs() < 1e-15 && mid.n[1] > 0.0 && mid.n[1] < b.n[1]);
    }
}
