//! The polygon mesh of the approximation and the polygon tools [`super::outline`] builds it
//! with.
//!
//! A region's boundary is the set of its faces' half-edges whose other side is another region
//! or nothing; chained head to tail they form loops (`region_loops`), counter-clockwise (seen
//! along the plane normal) for the outer loop and clockwise for holes, because the faces are.
//! OBJ faces cannot have holes, so a hole is joined to the outer loop by a bridge (a keyhole
//! polygon, [`bridge_holes`]), and each polygon is ear-clipped into triangles in its plane
//! ([`ear_clip`]).

use super::geom::{cross, normalize, V3};
use crate::mesh::{Topology, NO_FACE};

/// Polygons over a shared list of corner vertices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PolygonMesh {
    /// The corners' positions.
    pub positions: Vec<V3>,
    /// One polygon per region (indices into `positions`), holes bridged in.
    pub polygons: Vec<Vec<u32>>,
    /// Region of each polygon.
    pub region: Vec<u32>,
    /// Holes bridged.
    pub holes: usize,
    /// The polygons' triangles (ear clipping in each region's plane; indices into
    /// `positions`) and the region of each: OUT.obj, the triangles every output check counts.
    pub triangles: Vec<[u32; 3]>,
    pub triangle_region: Vec<u32>,
}

impl PolygonMesh {
    /// V − E + F of the polygon mesh's surface (corners on a polygon, edges between them, a
    /// polygon with h holes counting 1 − h): with the holes bridged in, each bridge is one
    /// more edge and each bridged polygon one disk, so the count over the bridged polygons is
    /// the same. Compared with the input's, it says whether a region closed a handle of it
    /// (a region is flattened into a planar polygon, which has no handle).
    pub fn euler_characteristic(&self) -> i64 {
        let mut edges: Vec<(u32, u32)> = Vec::new();
        for p in &self.polygons {
            for (i, &a) in p.iter().enumerate() {
                let b = p[(i + 1) % p.len()];
                if a != b {
                    edges.push((a.min(b), a.max(b)));
                }
            }
        }
        edges.sort_unstable();
        edges.dedup();
        let mut used: Vec<u32> = self.polygons.iter().flatten().copied().collect();
        used.sort_unstable();
        used.dedup();
        used.len() as i64 - edges.len() as i64 + self.polygons.len() as i64
    }

    /// OBJ text: `v` per corner, `f` per polygon, or per triangle (OUT.obj, the triangles
    /// checked: `--triangulate` writes the same ones).
    pub fn to_obj(&self, triangles: bool) -> String {
        use std::fmt::Write;
        let mut s = String::from(if triangles {
            "# foldfree approx: the triangles of the planar polygons\n"
        } else {
            "# foldfree approx: planar polygons\n"
        });
        for p in &self.positions {
            let _ = writeln!(s, "v {:.17e} {:.17e} {:.17e}", p[0], p[1], p[2]);
        }
        let faces: Vec<&[u32]> = if triangles {
            self.triangles.iter().map(|t| &t[..]).collect()
        } else {
            self.polygons.iter().map(|p| &p[..]).collect()
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
/// normal for the outer loop, clockwise for holes), of the regions `want`s (the others'
/// lists are left empty). Each region's loops start at its boundary vertices in increasing
/// order; where a region leaves a vertex by several boundary half-edges, the one of the
/// latest face goes first. A region's loops depend on its set of faces alone. `among` lists
/// every face of the wanted regions (each region's ascending: only the order of one region's
/// faces matters); only those are looked at, so the cost is theirs, not the mesh's.
pub(super) fn region_loops(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &[u32],
    n: usize,
    want: &[bool],
    among: &[u32],
) -> Vec<Vec<Vec<u32>>> {
    // The boundary half-edges (region, from, to), each region's in face order.
    let mut half: Vec<(u32, u32, u32)> = Vec::new();
    for &f in among {
        let f = f as usize;
        if !want[fc[f] as usize] {
            continue;
        }
        let face = &faces[f];
        for (k, &g) in topo.face_faces[f].iter().enumerate() {
            if g == NO_FACE || fc[g as usize] != fc[f] {
                half.push((fc[f], face[k], face[(k + 1) % 3]));
            }
        }
    }
    // Grouped by source vertex, face order kept within a group (a counting sort: stable, and
    // each vertex's group found by index while the loops are walked).
    let mut start = vec![0u32; topo.n_vertices + 1];
    for h in &half {
        start[h.1 as usize + 1] += 1;
    }
    for v in 0..topo.n_vertices {
        start[v + 1] += start[v];
    }
    let mut by_source = vec![0u32; half.len()];
    let mut next = start.clone();
    for (i, h) in half.iter().enumerate() {
        by_source[next[h.1 as usize] as usize] = i as u32;
        next[h.1 as usize] += 1;
    }
    let mut used = vec![false; half.len()];
    // The latest unused half-edge of region r leaving v.
    let mut take = |r: u32, v: u32| -> Option<u32> {
        let (lo, hi) = (start[v as usize] as usize, start[v as usize + 1] as usize);
        let &i = by_source[lo..hi]
            .iter()
            .rev()
            .find(|&&i| !used[i as usize] && half[i as usize].0 == r)?;
        used[i as usize] = true;
        Some(half[i as usize].2)
    };
    let mut sources: Vec<Vec<u32>> = vec![Vec::new(); n];
    for h in &half {
        sources[h.0 as usize].push(h.1);
    }
    let mut out = Vec::with_capacity(n);
    for (r, mut starts) in sources.into_iter().enumerate() {
        let r = r as u32;
        starts.sort_unstable();
        starts.dedup();
        let mut loops = Vec::new();
        for s in starts {
            while let Some(mut b) = take(r, s) {
                let mut lp = vec![s];
                while b != s {
                    lp.push(b);
                    match take(r, b) {
                        Some(next) => b = next,
                        None => break,
                    }
                }
                loops.push(lp);
            }
        }
        out.push(loops);
    }
    out
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
