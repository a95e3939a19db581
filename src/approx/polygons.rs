//! Stage 5: one planar polygon per region — the simplified mesh.
//!
//! A region's boundary is the set of its faces' half-edges whose other side is another region
//! or nothing; chained head to tail they form loops, counter-clockwise (seen along the plane
//! normal) for the outer loop and clockwise for holes, because the faces are. A loop vertex is
//! a corner where three or more regions meet (the mesh's outside counting as one) or where the
//! loop turns: between two regions the boundary lies on their planes' intersection line and is
//! straight, so these are exactly the polygon's corners. OBJ faces cannot have holes, so a hole
//! is joined to the outer loop by a bridge (a keyhole polygon); `--triangulate` ear-clips it.

use std::collections::HashMap;

use super::cluster::vertex_clusters;
use super::geom::{cross, dot, normalize, sub, V3};
use crate::mesh::{Topology, NO_FACE};

/// Polygons over a shared list of corner vertices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PolygonMesh {
    /// Mesh vertex of each corner (positions are the output mesh's).
    pub corners: Vec<u32>,
    pub positions: Vec<V3>,
    /// One polygon per region (indices into `corners`), holes bridged in.
    pub polygons: Vec<Vec<u32>>,
    /// Region of each polygon.
    pub region: Vec<u32>,
    /// Holes bridged.
    pub holes: usize,
}

/// A corner turns by more than this (radians) on a one-plane boundary (mesh border).
const TURN: f64 = 2.0_f64 * std::f64::consts::PI / 180.0;

/// An orthonormal frame of the plane with unit normal `n`.
pub(super) fn basis(n: V3) -> (V3, V3) {
    let h = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let u = normalize(cross(n, h)).unwrap_or([1.0, 0.0, 0.0]);
    (u, cross(n, u))
}

/// Signed area of a 2D polygon (positive counter-clockwise).
pub(super) fn area2(p: &[[f64; 2]]) -> f64 {
    let n = p.len();
    (0..n)
        .map(|i| {
            let (a, b) = (p[i], p[(i + 1) % n]);
            a[0] * b[1] - a[1] * b[0]
        })
        .sum::<f64>()
        * 0.5
}

/// Twice the signed area of triangle `a b c`.
pub(super) fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Whether segments `ab` and `cd` cross at a point interior to both.
pub(super) fn segments_cross(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (o1, o2) = (orient(a, b, c), orient(a, b, d));
    let (o3, o4) = (orient(c, d, a), orient(c, d, b));
    o1 * o2 < 0.0 && o3 * o4 < 0.0
}

/// Region loops as vertex cycles (each in face direction: counter-clockwise seen along the
/// normal for the outer loop, clockwise for holes).
pub(super) fn region_loops(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &[u32],
    n: usize,
) -> Vec<Vec<Vec<u32>>> {
    let mut out: Vec<HashMap<u32, Vec<u32>>> = vec![HashMap::new(); n];
    for (f, face) in faces.iter().enumerate() {
        for k in 0..3 {
            let e = topo.face_edges[f][k] as usize;
            let [g0, g1] = topo.edge_faces[e];
            let g = if g0 as usize == f { g1 } else { g0 };
            if g == NO_FACE || fc[g as usize] != fc[f] {
                let (a, b) = (face[k], face[(k + 1) % 3]);
                out[fc[f] as usize].entry(a).or_default().push(b);
            }
        }
    }
    out.into_iter()
        .map(|mut next| {
            let mut starts: Vec<u32> = next.keys().copied().collect();
            starts.sort_unstable();
            let mut loops = Vec::new();
            for s in starts {
                while next.get(&s).is_some_and(|v| !v.is_empty()) {
                    let mut lp = vec![s];
                    let mut cur = s;
                    while let Some(b) = next.get_mut(&cur).and_then(|v| v.pop()) {
                        if b == s {
                            break;
                        }
                        lp.push(b);
                        cur = b;
                    }
                    loops.push(lp);
                }
            }
            loops
        })
        .collect()
}

/// Ear clipping of a simple (possibly keyhole) polygon given by 2D points; returns index
/// triples into `p`. A vertex with no ear available (round-off) is clipped anyway so that the
/// loop terminates.
pub fn ear_clip(p: &[[f64; 2]]) -> Vec<[usize; 3]> {
    let mut idx: Vec<usize> = (0..p.len()).collect();
    let mut tris = Vec::new();
    while idx.len() > 3 {
        let m = idx.len();
        let mut best: Option<(usize, f64)> = None;
        let mut ear = None;
        for i in 0..m {
            let (a, b, c) = (idx[(i + m - 1) % m], idx[i], idx[(i + 1) % m]);
            let o = orient(p[a], p[b], p[c]);
            if best.is_none_or(|(_, bo)| o > bo) {
                best = Some((i, o));
            }
            if o <= 0.0 {
                continue;
            }
            let inside = idx.iter().any(|&q| {
                let pq = p[q];
                if pq == p[a] || pq == p[b] || pq == p[c] {
                    return false;
                }
                orient(p[a], p[b], pq) > 0.0
                    && orient(p[b], p[c], pq) > 0.0
                    && orient(p[c], p[a], pq) > 0.0
            });
            if !inside {
                ear = Some(i);
                break;
            }
        }
        // `best` is set on the first pass of the loop above since m > 3.
        let i = ear.or(best.map(|b| b.0)).unwrap_or(0);
        tris.push([idx[(i + m - 1) % m], idx[i], idx[(i + 1) % m]]);
        idx.remove(i);
    }
    if idx.len() == 3 {
        tris.push([idx[0], idx[1], idx[2]]);
    }
    tris
}

/// The outer loop `outer` with the `holes` joined in by bridges (a keyhole polygon, what an
/// OBJ face can hold), each from the hole's rightmost point to the nearest corner it sees;
/// corners are indices whose 2D positions `to2` gives.
pub fn bridge_holes(
    outer: &[u32],
    mut holes: Vec<Vec<u32>>,
    to2: &dyn Fn(u32) -> [f64; 2],
) -> Vec<u32> {
    let mut poly = outer.to_vec();
    // Bridge holes in order of their rightmost point (classic keyhole construction).
    let rightmost = |h: &[u32]| h.iter().map(|&v| to2(v)[0]).fold(f64::MIN, f64::max);
    holes.sort_by(|a, b| rightmost(b).total_cmp(&rightmost(a)));
    let all: Vec<Vec<u32>> = holes.clone();
    for h in &holes {
        let hi = (0..h.len())
            .max_by(|&a, &b| to2(h[a])[0].total_cmp(&to2(h[b])[0]))
            .unwrap_or(0);
        let hp = to2(h[hi]);
        let all_edges: Vec<([f64; 2], [f64; 2])> = all
            .iter()
            .chain(std::iter::once(&poly))
            .flat_map(|l| (0..l.len()).map(move |i| (l[i], l[(i + 1) % l.len()])))
            .map(|(a, b)| (to2(a), to2(b)))
            .collect();
        let mut cand: Vec<usize> = (0..poly.len()).collect();
        let d2 = |i: usize| {
            let q = to2(poly[i]);
            (q[0] - hp[0]).powi(2) + (q[1] - hp[1]).powi(2)
        };
        cand.sort_by(|&a, &b| d2(a).total_cmp(&d2(b)));
        let pick = cand
            .iter()
            .copied()
            .find(|&i| {
                let q = to2(poly[i]);
                !all_edges.iter().any(|&(a, b)| segments_cross(hp, q, a, b))
            })
            .or(cand.first().copied());
        let Some(pi) = pick else { continue };
        let mut merged: Vec<u32> = poly[..=pi].to_vec();
        merged.extend((0..=h.len()).map(|k| h[(hi + k) % h.len()]));
        merged.extend_from_slice(&poly[pi..]);
        poly = merged;
    }
    poly
}

/// Builds the polygons of all regions on the output positions `pos`.
pub fn extract(
    topo: &Topology,
    faces: &[[u32; 3]],
    pos: &[V3],
    face_cluster: &[u32],
    n_regions: usize,
) -> PolygonMesh {
    let vc = vertex_clusters(topo, face_cluster);
    let mut on_border = vec![false; topo.n_vertices];
    for &e in &topo.boundary_edges {
        for v in topo.edges[e as usize] {
            on_border[v as usize] = true;
        }
    }
    let mut normals = vec![[0.0; 3]; n_regions];
    for (f, &face) in faces.iter().enumerate() {
        let c = face_cluster[f] as usize;
        normals[c] = super::geom::add(normals[c], super::geom::face_area_normal(pos, face));
    }
    let mut out = PolygonMesh::default();
    let mut corner_of: HashMap<u32, u32> = HashMap::new();
    for (c, loops) in region_loops(topo, faces, face_cluster, n_regions)
        .into_iter()
        .enumerate()
    {
        let Some(nrm) = normalize(normals[c]) else {
            continue;
        };
        let (u, w) = basis(nrm);
        let to2 = |v: u32| {
            let q = pos[v as usize];
            [dot(q, u), dot(q, w)]
        };
        // Corners of each loop.
        let mut cloops: Vec<Vec<u32>> = Vec::new();
        for lp in &loops {
            let m = lp.len();
            let mut cs: Vec<u32> = (0..m)
                .filter(|&i| {
                    let v = lp[i];
                    let regions = vc[v as usize].len() + usize::from(on_border[v as usize]);
                    if regions >= 3 {
                        return true;
                    }
                    let a = sub(pos[v as usize], pos[lp[(i + m - 1) % m] as usize]);
                    let b = sub(pos[lp[(i + 1) % m] as usize], pos[v as usize]);
                    let (la, lb) = (dot(a, a).sqrt(), dot(b, b).sqrt());
                    la > 0.0 && lb > 0.0 && (dot(a, b) / (la * lb)).clamp(-1.0, 1.0).acos() > TURN
                })
                .map(|i| lp[i])
                .collect();
            if cs.len() < 3 {
                // Too few natural corners (a smooth hole): keep every loop vertex.
                cs = lp.clone();
            }
            if cs.len() >= 3 {
                cloops.push(cs);
            }
        }
        if cloops.is_empty() {
            continue;
        }
        // Outer loop = largest positive area; the rest are holes.
        let areas: Vec<f64> = cloops
            .iter()
            .map(|l| area2(&l.iter().map(|&v| to2(v)).collect::<Vec<_>>()))
            .collect();
        let outer = (0..cloops.len())
            .max_by(|&a, &b| areas[a].total_cmp(&areas[b]))
            .unwrap_or(0);
        let holes: Vec<Vec<u32>> = (0..cloops.len())
            .filter(|&i| i != outer)
            .map(|i| cloops[i].clone())
            .collect();
        out.holes += holes.len();
        let poly = bridge_holes(&cloops[outer], holes, &to2);
        let ids: Vec<u32> = poly
            .iter()
            .map(|&v| {
                let next = out.corners.len() as u32;
                *corner_of.entry(v).or_insert_with(|| {
                    out.corners.push(v);
                    out.positions.push(pos[v as usize]);
                    next
                })
            })
            .collect();
        out.polygons.push(ids);
        out.region.push(c as u32);
    }
    out
}

impl PolygonMesh {
    /// Triangles of all polygons (ear clipping in each region's plane), indices into `positions`.
    pub fn triangulate(&self) -> Vec<[u32; 3]> {
        self.triangulate_with_regions().0
    }

    /// Whether two polygons cross each other (their triangles, [`super::intersect`]).
    pub fn crossing(&self) -> Option<[u32; 2]> {
        let (tris, region) = self.triangulate_with_regions();
        super::intersect::first_crossing(&self.positions, &tris, &region)
    }

    /// [`PolygonMesh::triangulate`] and the region of each triangle.
    pub fn triangulate_with_regions(&self) -> (Vec<[u32; 3]>, Vec<u32>) {
        let mut tris = Vec::new();
        let mut regions = Vec::new();
        for (poly, &reg) in self.polygons.iter().zip(&self.region) {
            let pts: Vec<V3> = poly.iter().map(|&i| self.positions[i as usize]).collect();
            let m = pts.len();
            let mut nrm = [0.0; 3];
            for i in 0..m {
                nrm = super::geom::add(nrm, cross(pts[i], pts[(i + 1) % m]));
            }
            let Some(nrm) = normalize(nrm) else { continue };
            let (u, w) = basis(nrm);
            let p2: Vec<[f64; 2]> = pts.iter().map(|&q| [dot(q, u), dot(q, w)]).collect();
            for t in ear_clip(&p2) {
                tris.push(t.map(|k| poly[k]));
                regions.push(reg);
            }
        }
        (tris, regions)
    }

    /// OBJ text: `v` per corner, `f` per polygon (or per triangle).
    pub fn to_obj(&self, triangulate: bool) -> String {
        use std::fmt::Write;
        let mut s = String::from("# foldfree approx: planar polygons\n");
        for p in &self.positions {
            let _ = writeln!(s, "v {:.17e} {:.17e} {:.17e}", p[0], p[1], p[2]);
        }
        let faces: Vec<Vec<u32>> = if triangulate {
            self.triangulate().into_iter().map(|t| t.to_vec()).collect()
        } else {
            self.polygons.clone()
        };
        for f in faces {
            s.push('f');
            for i in f {
                let _ = write!(s, " {}", i + 1);
            }
            s.push('\n');
        }
        s
    }
}
