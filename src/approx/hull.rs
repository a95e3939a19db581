//! The polygon mesh no partition is needed for: the convex polytope of K support planes of a
//! closed, connected input.
//!
//! Why: a closed surface may have no partition into K regions that planes realise — a block
//! pierced by a hundred tunnels has more handles than K planes can keep — yet every set of
//! planes bounds one polygon mesh, the intersection of their half-spaces. With each plane a
//! support plane of the input (touching it, every vertex on its inner side) that polytope is
//! convex: each facet a convex polygon, the facets watertight, nothing crossing, and it is
//! bounded because the area-weighted normals of a closed surface sum to zero, so no half-space
//! holds them all. It closes the input's handles and fills its concavities; what that costs is
//! its distance to the input, measured as every output's, and the caller keeps it only where
//! no realised partition is nearer.
//!
//! The planes come from Lloyd rounds on the distance itself: each face to the support plane
//! nearest its centroid, each plane turned towards its faces' mean normal as far as brings it
//! nearer their centroid; they start from normals spread by farthest-point sampling and one
//! spherical k-means step.

use rayon::prelude::*;
use std::collections::HashMap;

use super::cluster::region_normal_sums;
use super::geom::{add, cross, dot, normalize, scale, sub, Plane, V3};
use super::outline::{Moments, Realised, Surface};
use super::polygons::{basis, PolygonMesh};

/// No plane bounds this edge yet (an edge of the starting square).
const OPEN: usize = usize::MAX;

/// The convex polytope of at most `k` support planes of `s`, fitted in at most `rounds` Lloyd
/// rounds, as a realisation: each input face in the region of the plane nearest its centroid.
/// `None` where the input is not one closed surface, or the polytope's facets do not close up
/// at the precision of the output.
pub fn polytope(s: &Surface<'_>, k: usize, rounds: usize) -> Option<Realised> {
    let topo = s.topo;
    if topo.components != 1 || !topo.boundary_loops.is_empty() || k < 4 {
        return None;
    }
    // Outward normals: a closed surface whose faces face out has a positive signed volume.
    let volume: f64 = s
        .faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| s.pos[i as usize]);
            dot(a, cross(b, c))
        })
        .sum();
    let out = if volume < 0.0 { -1.0 } else { 1.0 };
    let normals: Vec<V3> = s.normals.iter().map(|&n| scale(n, out)).collect();
    let mut used: Vec<u32> = s.faces.iter().flatten().copied().collect();
    used.sort_unstable();
    used.dedup();
    let support = |n: V3| Plane {
        n,
        d: -used
            .iter()
            .map(|&v| dot(n, s.pos[v as usize]))
            .fold(f64::MIN, f64::max),
    };
    let nearest = |planes: &[Plane], f: usize| {
        let c = s.moments(f).centroid();
        (0..planes.len())
            .map(|j| (j as u32, -planes[j].signed_distance(c)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap_or((0, 0.0))
    };
    let assign = |planes: &[Plane]| -> (Vec<u32>, f64) {
        let near: Vec<(u32, f64)> = (0..s.faces.len())
            .into_par_iter()
            .map(|f| nearest(planes, f))
            .collect();
        let cost = near.iter().zip(&s.areas).map(|(n, a)| n.1 * a).sum();
        (near.into_iter().map(|n| n.0).collect(), cost)
    };
    // The normals spread by farthest-point sampling may all lie in one half-space; after one
    // spherical k-means step they do not (each face to the spread normal it faces most, each
    // normal its faces' mean: the area-weighted normal sums of faces covering a closed surface
    // sum to zero), so the distance rounds start from a bounded polytope. More k-means steps
    // change where those rounds end by ±2 % (BENCHMARKS, planar approximation round 34).
    let spread = spread(&normals, &s.areas, k);
    let facing: Vec<u32> = (0..s.faces.len())
        .into_par_iter()
        .map(|f| {
            let by = |j: usize| dot(spread[j], normals[f]);
            (0..spread.len())
                .max_by(|&a, &b| by(a).total_cmp(&by(b)))
                .unwrap_or(0) as u32
        })
        .collect();
    let sums = region_normal_sums(&facing, &normals, &s.areas);
    let mean = |j: usize| sums.get(j).and_then(|&m| normalize(m)).unwrap_or(spread[j]);
    let mut planes: Vec<Plane> = (0..spread.len()).map(|j| support(mean(j))).collect();
    let (mut labels, mut cost) = assign(&planes);
    for _ in 0..rounds {
        let sums = region_normal_sums(&labels, &normals, &s.areas);
        let mut region = vec![Moments::default(); planes.len()];
        for (f, &j) in labels.iter().enumerate() {
            region[j as usize] = region[j as usize].add(s.moments(f));
        }
        // A plane's faces are nearest it on the whole when their area-weighted centroid is:
        // the support plane is moved towards its faces' mean normal (the L2,1 step) as far as
        // brings it nearer that centroid — so no round ends farther than the one before.
        let moved: Vec<Plane> = planes
            .par_iter()
            .enumerate()
            .map(|(j, &p)| {
                let Some(m) = sums.get(j).and_then(|&m| normalize(m)) else {
                    return p;
                };
                let c = region[j].centroid();
                [0.25, 0.5, 1.0]
                    .iter()
                    .filter_map(|&t| normalize(add(scale(p.n, 1.0 - t), scale(m, t))))
                    .map(support)
                    .fold(p, |best, q| {
                        if q.signed_distance(c) > best.signed_distance(c) {
                            q
                        } else {
                            best
                        }
                    })
            })
            .collect();
        let (l, c) = assign(&moved);
        if c >= cost {
            break;
        }
        (planes, labels, cost) = (moved, l, c);
    }
    // A plane no face is nearest would bound a region of no faces: dropped (the polytope
    // only grows by it).
    let mut chosen = vec![false; planes.len()];
    labels.iter().for_each(|&j| chosen[j as usize] = true);
    let mut planes: Vec<Plane> = planes
        .into_iter()
        .zip(chosen)
        .filter_map(|(p, c)| c.then_some(p))
        .collect();
    let [lo, hi] = super::geom::bounds(used.iter().map(|&v| s.pos[v as usize]));
    let centre = scale(add(lo, hi), 0.5);
    // A plane touching the input at a point or along an edge bounds a facet of no area, one
    // barely cutting a corner a sliver: a triangle the output check counts as degenerate.
    // Such planes go (the polytope grows by a sliver at most) until no facet has one.
    let mut mesh = loop {
        let (mesh, flat) = triangulated(&facets(&planes, centre, s.diag)?, s.diag);
        if flat.is_empty() {
            break mesh;
        }
        let mut j = 0;
        planes.retain(|_| {
            j += 1;
            flat.binary_search(&(j - 1)).is_err()
        });
    };
    if !watertight(&mesh.polygons) {
        return None;
    }
    let labels: Vec<u32> = (0..s.faces.len())
        .into_par_iter()
        .map(|f| nearest(&planes, f).0)
        .collect();
    if out < 0.0 {
        // The input faces in: so do the output's, on planes facing the same way.
        for p in planes.iter_mut() {
            *p = Plane {
                n: scale(p.n, -1.0),
                d: -p.d,
            };
        }
        mesh.polygons.iter_mut().for_each(|p| p.reverse());
        mesh.triangles.iter_mut().for_each(|t| t.swap(1, 2));
    }
    let (polygons, closes_handles) = (mesh, true);
    Some(Realised {
        polygons,
        labels,
        planes,
        closes_handles,
        ..Default::default()
    })
}

/// `k` of the unit `normals` spread over the sphere (farthest-point sampling from the normal
/// of the largest face): where the Lloyd rounds start.
fn spread(normals: &[V3], areas: &[f64], k: usize) -> Vec<V3> {
    let Some(first) = (0..normals.len()).max_by(|&a, &b| areas[a].total_cmp(&areas[b])) else {
        return Vec::new();
    };
    let mut picked = vec![normals[first]];
    let mut closest: Vec<f64> = normals.iter().map(|&n| dot(n, picked[0])).collect();
    while picked.len() < k {
        let (f, &c) = closest
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .expect("normals is not empty");
        if c >= 1.0 - 1e-12 {
            break; // every normal is one already picked
        }
        picked.push(normals[f]);
        for (cl, &n) in closest.iter_mut().zip(normals) {
            *cl = cl.max(dot(n, normals[f]));
        }
    }
    picked
}

/// Each plane's facet of the intersection of the planes' inner half-spaces (n·x + d ≤ 0):
/// a square of side 8·`diag` in the plane about the point nearest the input's `centre`,
/// clipped by every other plane; counter-clockwise seen along the normal. `None` if an edge
/// of a square is left: the polytope is unbounded, or reaches that far from the input.
fn facets(planes: &[Plane], centre: V3, diag: f64) -> Option<Vec<Vec<V3>>> {
    let r = 4.0 * diag;
    planes
        .iter()
        .enumerate()
        .map(|(j, p)| {
            let (u, w) = basis(p.n);
            let c = sub(centre, scale(p.n, p.signed_distance(centre)));
            let at = |a: f64, b: f64| add(c, add(scale(u, a * r), scale(w, b * r)));
            // (corner, plane bounding the edge from it to the next)
            let mut poly: Vec<(V3, usize)> = [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)]
                .iter()
                .map(|&(a, b)| (at(a, b), OPEN))
                .collect();
            for (i, q) in planes.iter().enumerate().filter(|&(i, _)| i != j) {
                poly = clip(&poly, q, i);
                if poly.is_empty() {
                    break;
                }
            }
            if poly.iter().any(|c| c.1 == OPEN) {
                return None;
            }
            Some(poly.into_iter().map(|c| c.0).collect())
        })
        .collect()
}

/// The convex polygon `poly` (corners, each with the plane of the edge leaving it) cut by
/// the inner side of plane `q` (index `i`).
fn clip(poly: &[(V3, usize)], q: &Plane, i: usize) -> Vec<(V3, usize)> {
    let mut out = Vec::with_capacity(poly.len() + 1);
    for (a, &(pa, ea)) in poly.iter().enumerate() {
        let pb = poly[(a + 1) % poly.len()].0;
        let (sa, sb) = (q.signed_distance(pa), q.signed_distance(pb));
        let cut = || add(pa, scale(sub(pb, pa), sa / (sa - sb)));
        match (sa <= 0.0, sb <= 0.0) {
            (true, true) => out.push((pa, ea)),
            (true, false) => out.extend([(pa, ea), (cut(), i)]),
            (false, true) => out.push((cut(), ea)),
            (false, false) => {}
        }
    }
    out
}

/// The facets' corners made one where closer than 1e-9·`diag` (a corner is met once per
/// facet it bounds, computed by each) and each facet fanned into triangles from its
/// straightest corner (a fan from elsewhere would make that corner a sliver); with the facets
/// (ascending) left with fewer than three corners or a degenerate triangle (area ≤ 1e-12 ×
/// `diag`², the output check's bound).
fn triangulated(facets: &[Vec<V3>], diag: f64) -> (PolygonMesh, Vec<usize>) {
    let mut mesh = PolygonMesh::default();
    let mut weld = Weld::new(1e-9 * diag);
    let mut flat = Vec::new();
    for (j, poly) in facets.iter().enumerate() {
        let mut corners: Vec<u32> = poly.iter().map(|&p| weld.id(p)).collect();
        corners.dedup();
        while corners.len() > 1 && corners.first() == corners.last() {
            corners.pop();
        }
        let n = corners.len();
        if n < 3 {
            flat.push(j);
            continue;
        }
        let at = |i: usize| weld.points[corners[i % n] as usize];
        let turn = |i: usize| {
            let (a, b) = (sub(at(i), at(i + n - 1)), sub(at(i + 1), at(i)));
            normalize(a)
                .zip(normalize(b))
                .map_or(f64::MAX, |(a, b)| dot(a, b))
        };
        let apex = (0..n)
            .max_by(|&a, &b| turn(a).total_cmp(&turn(b)))
            .unwrap_or(0);
        let r = mesh.polygons.len() as u32;
        for i in 1..n - 1 {
            let t = [apex, apex + i, apex + i + 1].map(|c| corners[c % n]);
            let [a, b, c] = t.map(|c| weld.points[c as usize]);
            if 0.5 * super::geom::norm(cross(sub(b, a), sub(c, a))) <= 1e-12 * diag * diag {
                flat.push(j);
            }
            mesh.triangles.push(t);
            mesh.triangle_region.push(r);
        }
        mesh.polygons.push(corners);
        mesh.region.push(r);
    }
    flat.dedup();
    mesh.positions = weld.points;
    (mesh, flat)
}

/// Whether every polygon edge is met once each way (the facets close up).
pub(super) fn watertight(polygons: &[Vec<u32>]) -> bool {
    let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
    for p in polygons {
        for (i, &a) in p.iter().enumerate() {
            *edges.entry((a, p[(i + 1) % p.len()])).or_default() += 1;
        }
    }
    edges
        .iter()
        .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
}

/// Points closer than `tol` made one (the first met), through a grid of `tol` cells.
struct Weld {
    tol: f64,
    points: Vec<V3>,
    cells: HashMap<[i64; 3], Vec<u32>>,
}

impl Weld {
    fn new(tol: f64) -> Weld {
        Weld {
            tol,
            points: Vec::new(),
            cells: HashMap::new(),
        }
    }

    fn id(&mut self, p: V3) -> u32 {
        let cell = p.map(|x| (x / self.tol).floor() as i64);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let near = [cell[0] + dx, cell[1] + dy, cell[2] + dz];
                    for &q in self.cells.get(&near).into_iter().flatten() {
                        if super::geom::norm(sub(self.points[q as usize], p)) <= self.tol {
                            return q;
                        }
                    }
                }
            }
        }
        let id = self.points.len() as u32;
        self.points.push(p);
        self.cells.entry(cell).or_default().push(id);
        id
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approx::testing::cube;

    /// The cube's six sides are support planes meeting at its corners: asked for six planes
    /// or more, the polytope is the cube itself, each face on its side's facet, no distance.
    #[test]
    fn the_polytope_of_a_cube_is_the_cube() {
        let (mesh, topo, sides) = cube(3);
        let s = Surface::new(&topo, &mesh);
        for k in [6, 10] {
            let p = polytope(&s, k, 30).expect("a cube is closed and convex");
            assert_eq!(p.planes.len(), 6, "K = {k}");
            assert_eq!(p.polygons.polygons.len(), 6);
            assert_eq!(p.polygons.positions.len(), 8);
            assert!(p.polygons.polygons.iter().all(|c| c.len() == 4));
            assert_eq!(p.polygons.euler_characteristic(), 2);
            for (f, &l) in p.labels.iter().enumerate() {
                let mut same = p.labels.iter().zip(&sides).filter(|(_, &t)| t == sides[f]);
                assert!(same.all(|(&m, _)| m == l), "face {f} with its side");
            }
            for (t, &r) in p.polygons.triangles.iter().zip(&p.polygons.triangle_region) {
                let [a, b, c] = t.map(|i| p.polygons.positions[i as usize]);
                let n = cross(sub(b, a), sub(c, a));
                assert!(dot(n, p.planes[r as usize].n) > 0.0, "triangle faces out");
            }
            for (f, face) in mesh.faces.iter().enumerate() {
                let plane = p.planes[p.labels[f] as usize];
                for &v in face {
                    assert!(plane.signed_distance(mesh.positions[v as usize]).abs() < 1e-12);
                }
            }
        }
    }

    /// A sphere (the cube's grid pushed out onto one, far from the origin) and eight planes:
    /// a closed convex polytope holding every vertex (each plane a support plane), its facets
    /// meeting edge to edge, every face on a plane that faces its way.
    #[test]
    fn a_sphere_gets_a_closed_polytope_of_support_planes() {
        let (mut mesh, topo, _) = cube(4);
        for p in mesh.positions.iter_mut() {
            let v = normalize(sub(*p, [0.5; 3])).expect("no vertex at the centre");
            *p = add(v, [100.0, -50.0, 7.0]);
        }
        let s = Surface::new(&topo, &mesh);
        let p = polytope(&s, 8, 30).expect("eight planes bound a sphere");
        assert_eq!(p.planes.len(), 8);
        assert_eq!(p.polygons.polygons.len(), 8);
        assert!(watertight(&p.polygons.polygons));
        assert_eq!(p.polygons.euler_characteristic(), 2);
        for (f, &l) in p.labels.iter().enumerate() {
            assert!(dot(s.normals[f], p.planes[l as usize].n) > 0.0, "face {f}");
        }
        for plane in &p.planes {
            let worst = mesh
                .positions
                .iter()
                .map(|&v| plane.signed_distance(v))
                .fold(f64::MIN, f64::max);
            assert!(worst.abs() < 1e-12, "a support plane touches the input");
        }
    }

    /// An open surface has no inside: no polytope.
    #[test]
    fn an_open_surface_has_no_polytope() {
        let (mesh, topo) = crate::approx::testing::grid(4);
        assert!(polytope(&Surface::new(&topo, &mesh), 8, 30).is_none());
    }
}
