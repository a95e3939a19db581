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
//! Last, every region that still has bad faces is repaired as a whole, region by region (its
//! interior vertices touch only its own faces, so regions are independent): a Tutte embedding
//! of its interior against its outline, then, where that still folds (non-convex outlines are
//! the rule here), the barrier untangler of [`super::untangle2d`] in the region's plane. Each
//! is kept only when the region has fewer bad faces afterwards. What remains are faces whose
//! outline itself overlaps: three fixed corners, or an outline that crosses itself in the
//! plane — no interior placement can fix those.

use sprs::TriMat;

use super::cluster::vertex_clusters;
use super::geom::{
    add, cross, dot, face_area_normal, face_normals_areas, norm, scale, sub, Frame, Plane, V3,
};
use super::sparse::solve_spd;
use super::untangle2d::{untangle_2d, Reference, Untangle2dOptions};
use crate::linalg::SolveError;
use crate::mesh::{Topology, NO_FACE};

/// What [`untangle`] changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Untangled {
    pub chains_respaced: usize,
    /// Local Tutte repairs run (growing patches around bad faces).
    pub patches_embedded: usize,
    /// Regions whose whole interior was re-embedded (see `embed_folded_regions`).
    pub regions_embedded: usize,
}

/// What the fold repairs read and do not change: the mesh, its regions and their planes, each
/// vertex's sorted regions, the mesh-border flags, the input positions (reference shapes and
/// arc lengths) and the area at or below which a face counts as degenerate.
#[derive(Clone, Copy)]
pub(crate) struct Layout<'a> {
    pub topo: &'a Topology,
    pub faces: &'a [[u32; 3]],
    pub fc: &'a [u32],
    pub planes: &'a [Option<Plane>],
    pub vc: &'a [Vec<u32>],
    pub on_border: &'a [bool],
    pub input: &'a [V3],
    pub min_area: f64,
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
    let vc = vertex_clusters(topo, fc);
    let on_border = border_vertices(topo);
    let mut out = Untangled {
        chains_respaced: respace_chains(topo, fc, &vc, &on_border, input, pos),
        ..Untangled::default()
    };
    let bad = bad_faces(pos, faces, fc, planes, min_area);
    let layout = Layout {
        topo,
        faces,
        fc,
        planes,
        vc: &vc,
        on_border: &on_border,
        input,
        min_area,
    };
    out.patches_embedded = repair_patches(&layout, pos, bad, None, 64)?;
    out.regions_embedded = embed_folded_regions(&layout, pos)?;
    Ok(out)
}

/// Vertices on the mesh border.
pub(crate) fn border_vertices(topo: &Topology) -> Vec<bool> {
    let mut on_border = vec![false; topo.n_vertices];
    for &e in &topo.boundary_edges {
        for v in topo.edges[e as usize] {
            on_border[v as usize] = true;
        }
    }
    on_border
}

/// Re-spaces every two-region chain between its end corners by its input arc-length fractions
/// (see module doc); idempotent while the corners stay. Returns the chains re-spaced.
pub(crate) fn respace_chains(
    topo: &Topology,
    fc: &[u32],
    vc: &[Vec<u32>],
    on_border: &[bool],
    input: &[V3],
    pos: &mut [V3],
) -> usize {
    let n = topo.n_vertices;
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
    let mut respaced = 0;
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
            respaced += 1;
        }
    }
    respaced
}

/// Local Tutte repair in patches of growing radius around the `bad` faces (see module doc).
/// With `scope`, only bad faces among those faces are looked at and counted (the caller knows
/// nothing else moved). Returns the repairs kept.
pub(crate) fn repair_patches(
    layout: &Layout,
    pos: &mut [V3],
    mut bad: Vec<usize>,
    scope: Option<&[usize]>,
    max_radius: usize,
) -> Result<usize, SolveError> {
    let Layout {
        topo,
        faces,
        fc,
        planes,
        vc,
        on_border,
        min_area,
        ..
    } = *layout;
    let n = topo.n_vertices;
    let count = |pos: &[V3]| match scope {
        Some(s) => bad_faces_among(pos, faces, fc, planes, min_area, s),
        None => bad_faces(pos, faces, fc, planes, min_area),
    };
    // Local Tutte repair: patches of growing radius around the bad faces.
    let mut radius = 1;
    let mut embedded = 0;
    while radius <= max_radius && !bad.is_empty() {
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
            embed(topo, &free, vc, planes, pos)?;
            let after = count(pos);
            if after.len() < bad.len() {
                bad = after;
                embedded += 1;
                continue; // same radius again around what is left
            }
            for (&v, &p) in free.iter().zip(&saved) {
                pos[v] = p;
            }
        }
        radius *= 2;
    }
    Ok(embedded)
}

/// Whole-region repair: the interior vertices of each region that still has bad faces are
/// Tutte-embedded against the region's own boundary. Interior vertices touch only their region's
/// faces, so each region is decided on its own: the embedding is kept when that region ends up
/// with fewer bad faces (it is fold-free whenever the region's boundary, seen in its plane, is a
/// convex polygon, and usually when it is a simple one). Returns the regions changed.
fn embed_folded_regions(layout: &Layout, pos: &mut [V3]) -> Result<usize, SolveError> {
    let Layout {
        topo,
        faces,
        fc,
        planes,
        vc,
        on_border,
        input,
        min_area,
    } = *layout;
    let n_regions = planes.len();
    let mut region_faces: Vec<Vec<usize>> = vec![Vec::new(); n_regions];
    for (f, &c) in fc.iter().enumerate() {
        region_faces[c as usize].push(f);
    }
    let mut region_free: Vec<Vec<usize>> = vec![Vec::new(); n_regions];
    for v in 0..pos.len() {
        if vc[v].len() == 1 && !on_border[v] {
            region_free[vc[v][0] as usize].push(v);
        }
    }
    let count_bad = |pos: &[V3], r: usize| {
        if planes[r].is_none() {
            return 0;
        }
        bad_faces_among(pos, faces, fc, planes, min_area, &region_faces[r]).len()
    };
    let mut changed = 0;
    for r in 0..n_regions {
        let before = count_bad(pos, r);
        if before == 0 || region_free[r].is_empty() {
            continue;
        }
        let saved: Vec<V3> = region_free[r].iter().map(|&v| pos[v]).collect();
        embed(topo, &region_free[r], vc, planes, pos)?;
        let after_tutte = count_bad(pos, r);
        if after_tutte >= before {
            for (&v, &p) in region_free[r].iter().zip(&saved) {
                pos[v] = p;
            }
        }
        let best = after_tutte.min(before);
        if best > 0 {
            if let Some(p) = planes[r] {
                let saved2: Vec<V3> = region_free[r].iter().map(|&v| pos[v]).collect();
                let is_free = |g: usize| vc[g].len() == 1 && !on_border[g];
                untangle_region(faces, &region_faces[r], &is_free, &p, input, pos);
                if count_bad(pos, r) >= best {
                    for (&v, &q) in region_free[r].iter().zip(&saved2) {
                        pos[v] = q;
                    }
                }
            }
        }
        changed += usize::from(count_bad(pos, r) < before);
    }
    Ok(changed)
}

/// Untangles one region in its plane with [`untangle_2d`]: its interior vertices move, its
/// boundary (shared with other regions or the mesh border) stays. The reference triangles are
/// the input ones, scaled so that their total area is the region's current signed area in the
/// plane (the area the untangled layout must cover).
fn untangle_region(
    faces: &[[u32; 3]],
    rf: &[usize],
    is_free: &dyn Fn(usize) -> bool,
    p: &Plane,
    input: &[V3],
    pos: &mut [V3],
) {
    let Some(frame) = Frame::of(p) else {
        return;
    };
    let mut local = std::collections::HashMap::new();
    let mut global = Vec::new();
    let lf: Vec<[usize; 3]> = rf
        .iter()
        .map(|&f| {
            faces[f].map(|g| {
                *local.entry(g as usize).or_insert_with(|| {
                    global.push(g as usize);
                    global.len() - 1
                })
            })
        })
        .collect();
    let mut x: Vec<[f64; 2]> = global.iter().map(|&g| frame.coords(pos[g])).collect();
    let signed: f64 = lf
        .iter()
        .map(|f| {
            let (a, b, c) = (x[f[0]], x[f[1]], x[f[2]]);
            0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
        })
        .sum();
    let input_area: f64 = rf
        .iter()
        .map(|&f| {
            let [a, b, c] = faces[f].map(|g| input[g as usize]);
            0.5 * norm(cross(sub(b, a), sub(c, a)))
        })
        .sum();
    if signed <= 0.0 || input_area <= 0.0 {
        return;
    }
    let s = (signed / input_area).sqrt();
    let mut refs = Vec::with_capacity(rf.len());
    for &f in rf {
        let [a, b, c] = faces[f].map(|g| input[g as usize]);
        match Reference::from_triangle(a, b, c, s) {
            Some(r) => refs.push(r),
            None => return,
        }
    }
    let free: Vec<bool> = global.iter().map(|&g| is_free(g)).collect();
    untangle_2d(&lf, &refs, &free, &mut x, &Untangle2dOptions::default());
    for (i, &g) in global.iter().enumerate() {
        if free[i] {
            pos[g] = frame.point(x[i]);
        }
    }
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

/// The faces of `among` that are flipped against their region's plane or have area ≤ `min_area`.
pub fn bad_faces_among(
    pos: &[V3],
    faces: &[[u32; 3]],
    fc: &[u32],
    planes: &[Option<Plane>],
    min_area: f64,
    among: &[usize],
) -> Vec<usize> {
    among
        .iter()
        .copied()
        .filter(|&f| {
            let n = face_area_normal(pos, faces[f]);
            planes[fc[f] as usize].is_some_and(|p| dot(n, p.n) <= 0.0) || norm(n) <= min_area
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
