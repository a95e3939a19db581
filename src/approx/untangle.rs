//! Removes the folds that exact planarity can create, without leaving the planes.
//!
//! Between two corners, a boundary shared by exactly two regions lies on the line where their
//! planes meet; the constrained solve puts each vertex on that line but not necessarily in
//! order, and a vertex that overtakes its neighbour folds the faces next to it. So every such
//! chain is re-spaced along the segment between its end corners by the arc-length fractions it
//! had in the input (still on both planes, now monotone). Then the interior vertices (those of
//! one region only) near each flipped or degenerate face are placed by a uniform Tutte embedding
//! against the rest, in patches of growing radius: an affine combination of points of
//! the plane stays in the plane, and Tutte's theorem makes it fold-free when the patch
//! boundary is convex, which small patches usually are (the result is checked again).

use sprs::TriMat;

use super::cluster::vertex_clusters;
use super::geom::{add, dot, face_normals_areas, norm, scale, sub, Plane, V3};
use super::sparse::solve_spd;
use crate::linalg::SolveError;
use crate::mesh::{Topology, NO_FACE};

/// What [`untangle`] changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Untangled {
    pub chains_respaced: usize,
    /// Local Tutte repairs run (growing patches around bad faces).
    pub patches_embedded: usize,
}

/// Re-spaces two-region chains and repairs folds locally (see module doc).
/// `input` are the input positions (for arc-length fractions).
pub fn untangle(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &[u32],
    planes: &[Option<Plane>],
    input: &[V3],
    pos: &mut [V3],
    min_area: f64,
) -> Result<Untangled, SolveError> {
    let n = topo.n_vertices;
    let vc = vertex_clusters(topo, fc);
    let mut on_border = vec![false; n];
    for &e in &topo.boundary_edges {
        for v in topo.edges[e as usize] {
            on_border[v as usize] = true;
        }
    }
    // Region-boundary adjacency.
    let mut badj: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (e, ef) in topo.edge_faces.iter().enumerate() {
        if ef[1] != NO_FACE && fc[ef[0] as usize] != fc[ef[1] as usize] {
            let [a, b] = topo.edges[e];
            badj[a as usize].push(b);
            badj[b as usize].push(a);
        }
    }
    let is_chain = |v: usize| vc[v].len() == 2 && !on_border[v] && badj[v].len() == 2;
    let mut out = Untangled::default();
    let mut done = vec![false; n];
    for a in 0..n {
        if badj[a].is_empty() || is_chain(a) {
            continue;
        }
        for &first in &badj[a] {
            let first = first as usize;
            if !is_chain(first) || done[first] {
                continue;
            }
            let mut chain = vec![first];
            let (mut prev, mut cur) = (a, first);
            let end = loop {
                let next = badj[cur]
                    .iter()
                    .map(|&x| x as usize)
                    .find(|&x| x != prev)
                    .unwrap_or(prev);
                if !is_chain(next) {
                    break next;
                }
                if next == first {
                    break usize::MAX; // a closed chain with no corner
                }
                chain.push(next);
                prev = cur;
                cur = next;
            };
            for &v in &chain {
                done[v] = true;
            }
            if end == usize::MAX {
                continue;
            }
            let mut lens = vec![0.0];
            let mut last = a;
            for &v in chain.iter().chain(std::iter::once(&end)) {
                let l = lens[lens.len() - 1] + norm(sub(input[v], input[last]));
                lens.push(l);
                last = v;
            }
            let total = lens[lens.len() - 1];
            if total <= 0.0 {
                continue;
            }
            let (pa, pb) = (pos[a], pos[end]);
            for (i, &v) in chain.iter().enumerate() {
                pos[v] = add(pa, scale(sub(pb, pa), lens[i + 1] / total));
            }
            out.chains_respaced += 1;
        }
    }
    // Local Tutte repair: patches of growing radius around the bad faces.
    let mut radius = 1;
    let mut bad = bad_faces(pos, faces, fc, planes, min_area);
    while radius <= 64 && !bad.is_empty() {
        // Vertices within `radius` rings of a bad face (inside the same region).
        let mut ring = vec![usize::MAX; n];
        let mut frontier: Vec<usize> = Vec::new();
        for &f in &bad {
            for &v in &faces[f] {
                if ring[v as usize] == usize::MAX {
                    ring[v as usize] = 0;
                    frontier.push(v as usize);
                }
            }
        }
        for r in 1..=radius {
            let mut next = Vec::new();
            for &v in &frontier {
                for &w in topo.neighbors(v as u32) {
                    if ring[w as usize] == usize::MAX {
                        ring[w as usize] = r;
                        next.push(w as usize);
                    }
                }
            }
            frontier = next;
        }
        let free: Vec<usize> = (0..n)
            .filter(|&v| ring[v] < radius && vc[v].len() == 1 && !on_border[v])
            .collect();
        // Keep a repair only when it leaves fewer bad faces (a non-convex patch can add folds).
        if !free.is_empty() {
            let saved: Vec<V3> = free.iter().map(|&v| pos[v]).collect();
            embed(topo, &free, &vc, planes, pos)?;
            let after = bad_faces(pos, faces, fc, planes, min_area);
            if after.len() < bad.len() {
                bad = after;
                out.patches_embedded += 1;
                continue; // same radius again around what is left
            }
            for (&v, &p) in free.iter().zip(&saved) {
                pos[v] = p;
            }
        }
        radius *= 2;
    }
    Ok(out)
}

/// Faces flipped against their region's plane or with area ≤ `min_area`.
pub fn bad_faces(
    pos: &[V3],
    faces: &[[u32; 3]],
    fc: &[u32],
    planes: &[Option<Plane>],
    min_area: f64,
) -> Vec<usize> {
    let (n, a) = face_normals_areas(pos, faces);
    (0..faces.len())
        .filter(|&f| {
            planes[fc[f] as usize].is_some_and(|p| dot(n[f], p.n) <= 0.0) || a[f] <= min_area
        })
        .collect()
}

/// Uniform Tutte embedding of the `free` vertices against all others (see module doc).
fn embed(
    topo: &Topology,
    free: &[usize],
    vc: &[Vec<u32>],
    planes: &[Option<Plane>],
    pos: &mut [V3],
) -> Result<(), SolveError> {
    let n = pos.len();
    let mut idx = vec![usize::MAX; n];
    for (i, &v) in free.iter().enumerate() {
        idx[v] = i;
    }
    let m = free.len();
    let mut t = TriMat::new((m, m));
    let mut rhs = vec![vec![0.0; m]; 3];
    for (i, &v) in free.iter().enumerate() {
        let nb = topo.neighbors(v as u32);
        t.add_triplet(i, i, nb.len() as f64);
        for &w in nb {
            let w = w as usize;
            if idx[w] != usize::MAX {
                t.add_triplet(i, idx[w], -1.0);
            } else {
                for k in 0..3 {
                    rhs[k][i] += pos[w][k];
                }
            }
        }
    }
    let mut x: Vec<Vec<f64>> = (0..3)
        .map(|k| free.iter().map(|&v| pos[v][k]).collect())
        .collect();
    solve_spd(&t.to_csr(), &rhs, &mut x, 1e-12)?;
    for (i, &v) in free.iter().enumerate() {
        pos[v] = [x[0][i], x[1][i], x[2][i]];
        // An affine combination of in-plane points; snap away round-off.
        if let Some(p) = planes[vc[v][0] as usize] {
            pos[v] = sub(pos[v], scale(p.n, p.signed_distance(pos[v])));
        }
    }
    Ok(())
}
