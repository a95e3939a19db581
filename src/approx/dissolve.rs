//! Dissolves small regions that fold into their neighbours.
//!
//! The one-face moves of [`super::reassign`] change an outline by one triangle; what they leave
//! are mostly small, thin regions squeezed between their neighbours' planes (the outline of
//! such a region overlaps itself in its plane, so no placement of its vertices is fold-free).
//! Giving every face of the region to a neighbour removes that plane altogether: the faces are
//! handed out by region growing from the outline, each to the adjacent neighbour whose plane
//! normal is closest to the face's input normal, the region's vertices go onto their new plane
//! sets, and the folds around are repaired as for a face move (chain re-spacing, Tutte patches,
//! the barrier untangler). The change is kept only when the faces of every region around the
//! dissolved one, plus every face around a vertex that moved, have fewer bad faces than before.
//! Planes stay as they are; the dissolved region is left empty (one region fewer, so never more
//! than K).
//!
//! The same relabel-and-repair step (`try_relabel`) also drives two-face moves
//! ([`Moves::pair_moves`]), for the folds a one-face move cannot leave, whole-region moves
//! into one neighbour ([`Moves::absorb_regions`]) and the moves of a vertex's whole ring into
//! one region ([`Moves::ring_moves`]).

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::cluster::{regions_at, vertex_clusters};
use super::geom::{dot, face_area_normal, normalize, Plane, V3};
use super::reassign::{faces_around, no_pinches, onto_plane_sets};
use super::slide::slide_near;
use super::untangle::{
    bad_faces, bad_faces_among, border_vertices, repair_patches, respace_chains, Layout,
};
use super::untangle2d::Untangle2dOptions;
use crate::linalg::SolveError;
use crate::mesh::{Topology, NO_FACE};

/// Options of [`dissolve_folded_regions`].
#[derive(Clone, Debug, PartialEq)]
pub struct DissolveOptions {
    /// Largest region (faces) tried: big regions carry most of the approximation, and losing
    /// one costs far more error than its folds are worth.
    pub max_faces: usize,
    /// Largest distance of a vertex to any of its new planes (absolute).
    pub tol: f64,
    /// Largest number of regions tried.
    pub max_trials: usize,
}

/// Tries to dissolve every region with bad faces of at most `opts.max_faces` faces, fewest
/// faces first; returns how many were dissolved. `fc` and `pos` change in place; dissolved
/// regions are left empty (renumber afterwards).
#[allow(clippy::too_many_arguments)]
pub fn dissolve_folded_regions(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &mut [u32],
    planes: &[Option<Plane>],
    input: &[V3],
    pos: &mut [V3],
    min_area: f64,
    opts: &DissolveOptions,
) -> Result<usize, SolveError> {
    let on_border = border_vertices(topo);
    let mut tried = vec![false; planes.len()];
    let (mut trials, mut dissolved) = (0, 0);
    loop {
        let bad = bad_faces(pos, faces, fc, planes, min_area);
        if bad.is_empty() || trials >= opts.max_trials {
            break;
        }
        let mut size = vec![0usize; planes.len()];
        for &c in fc.iter() {
            size[c as usize] += 1;
        }
        let mut cands: Vec<u32> = bad.iter().map(|&f| fc[f]).collect();
        cands.sort_unstable();
        cands.dedup();
        cands.retain(|&c| !tried[c as usize] && size[c as usize] <= opts.max_faces);
        cands.sort_by_key(|&c| (size[c as usize], c));
        let Some(&r) = cands.first() else { break };
        tried[r as usize] = true;
        trials += 1;
        if try_dissolve(
            topo, faces, fc, planes, input, pos, min_area, opts, &on_border, r,
        )? {
            dissolved += 1;
        }
    }
    Ok(dissolved)
}

/// Region growing of region `r`'s faces (`members`) into its neighbours: each face goes to
/// the region across one of its edges (a neighbour, or a face already handed out) for which
/// `cost(face, region)` is least, cheapest first (`None`: that region takes no faces). New
/// labels of `members`, or `None` when some face cannot be reached.
pub(super) fn hand_out(
    topo: &Topology,
    fc: &[u32],
    r: u32,
    members: &[usize],
    cost: impl Fn(usize, u32) -> Option<f64>,
) -> Option<Vec<(usize, u32)>> {
    let mut label: std::collections::HashMap<usize, u32> = std::collections::HashMap::new();
    let mut heap: BinaryHeap<Reverse<(u64, usize, u32)>> = BinaryHeap::new();
    let push_from =
        |f: usize, label: &std::collections::HashMap<usize, u32>, heap: &mut BinaryHeap<_>| {
            for &e in &topo.face_edges[f] {
                let ef = topo.edge_faces[e as usize];
                let g = if ef[0] as usize == f { ef[1] } else { ef[0] };
                if g == NO_FACE || fc[g as usize] != r || label.contains_key(&(g as usize)) {
                    continue;
                }
                let c = if fc[f] == r { label[&f] } else { fc[f] };
                if let Some(k) = cost(g as usize, c) {
                    // Non-negative floats order as their bits do.
                    heap.push(Reverse((k.max(0.0).to_bits(), g as usize, c)));
                }
            }
        };
    for &f in members {
        for &e in &topo.face_edges[f] {
            let ef = topo.edge_faces[e as usize];
            let g = if ef[0] as usize == f { ef[1] } else { ef[0] };
            if g != NO_FACE && fc[g as usize] != r {
                push_from(g as usize, &label, &mut heap);
            }
        }
    }
    while let Some(Reverse((_, f, c))) = heap.pop() {
        if label.contains_key(&f) {
            continue;
        }
        label.insert(f, c);
        push_from(f, &label, &mut heap);
    }
    members
        .iter()
        .map(|&f| label.get(&f).map(|&c| (f, c)))
        .collect()
}

#[allow(clippy::too_many_arguments)]
fn try_dissolve(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &mut [u32],
    planes: &[Option<Plane>],
    input: &[V3],
    pos: &mut [V3],
    min_area: f64,
    opts: &DissolveOptions,
    on_border: &[bool],
    r: u32,
) -> Result<bool, SolveError> {
    let members: Vec<usize> = (0..fc.len()).filter(|&f| fc[f] == r).collect();
    let normal = |f: usize| normalize(face_area_normal(input, faces[f])).unwrap_or([0.0; 3]);
    // Cost of giving face f to region c: 1 − cos of the angle between their normals.
    let cost = |f: usize, c: u32| planes[c as usize].map(|p| 1.0 - dot(normal(f), p.n));
    let Some(labels) = hand_out(topo, fc, r, &members, cost) else {
        return Ok(false);
    };
    try_relabel(
        topo, faces, fc, planes, input, pos, min_area, opts.tol, on_border, &labels,
    )
}

/// Gives each face of `moves` its new region, puts the vertices of those faces onto their new
/// plane sets (within `tol`) and keeps the change when [`settle`] says so; otherwise restores
/// `fc` and `pos`. Refused outright when a region would be cut in two or pinched at a vertex
/// (more than one fan of it around a vertex) or a vertex has no point on all its planes.
#[allow(clippy::too_many_arguments)]
pub(super) fn try_relabel(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &mut [u32],
    planes: &[Option<Plane>],
    input: &[V3],
    pos: &mut [V3],
    min_area: f64,
    tol: f64,
    on_border: &[bool],
    moves: &[(usize, u32)],
) -> Result<bool, SolveError> {
    let old: Vec<(usize, u32)> = moves.iter().map(|&(f, _)| (f, fc[f])).collect();
    let mut verts: Vec<u32> = moves.iter().flat_map(|&(f, _)| faces[f]).collect();
    verts.sort_unstable();
    verts.dedup();
    // The faces that can change: those of every region at a moved face's vertex (the new
    // regions are among them: a face only moves to a region it touches).
    let (regions, scope) = neighbourhood(topo, fc, &verts, moves.iter().map(|&(_, c)| c));
    let before = bad_faces_among(pos, faces, fc, planes, min_area, &scope).len();
    let saved = pos.to_vec();
    for &(f, c) in moves {
        fc[f] = c;
    }
    let restore = |fc: &mut [u32], pos: &mut [V3]| {
        for &(f, c) in &old {
            fc[f] = c;
        }
        pos.copy_from_slice(&saved);
    };
    if !no_pinches(topo, faces, fc, &verts) {
        restore(fc, pos);
        return Ok(false);
    }
    if !onto_plane_sets(topo, fc, planes, pos, &verts, tol) {
        restore(fc, pos);
        return Ok(false);
    }
    let vc = vertex_clusters(topo, fc);
    let layout = Layout {
        topo,
        faces,
        fc,
        planes,
        vc: &vc,
        on_border,
        input,
        min_area,
    };
    let keep = settle(&layout, pos, &saved, &scope, &regions, before, usize::MAX)?;
    if !keep {
        restore(fc, pos);
    }
    Ok(keep)
}

/// The regions a change at `verts` can affect — every region at those vertices plus `extra`
/// (sorted, deduplicated) — and all their faces (the scope [`settle`] judges).
pub(super) fn neighbourhood(
    topo: &Topology,
    fc: &[u32],
    verts: &[u32],
    extra: impl Iterator<Item = u32>,
) -> (Vec<u32>, Vec<usize>) {
    let mut regions: Vec<u32> = verts
        .iter()
        .flat_map(|&v| regions_at(topo, fc, v))
        .chain(extra)
        .collect();
    regions.sort_unstable();
    regions.dedup();
    let scope: Vec<usize> = (0..fc.len())
        .filter(|&f| regions.binary_search(&fc[f]).is_ok())
        .collect();
    (regions, scope)
}

/// What the face-move repairs ([`Moves::pair_moves`], [`Moves::absorb_regions`],
/// [`Moves::ring_moves`]) read besides the regions and positions they change.
pub struct Moves<'a> {
    pub topo: &'a Topology,
    pub faces: &'a [[u32; 3]],
    pub planes: &'a [Option<Plane>],
    /// Input positions (chain arc lengths of the repairs).
    pub input: &'a [V3],
    /// Faces of at most this area count as degenerate.
    pub min_area: f64,
    /// Largest distance of a moved vertex to any of its new planes (absolute).
    pub tol: f64,
}

impl Moves<'_> {
    /// Two-face moves at the bad faces left: for each bad face, every face around its corners
    /// together with one edge neighbour of the same region, into each region edge-adjacent to the
    /// pair. A one-face move can be stuck between two bad states (face f bad in region a, a
    /// neighbour bad when f is in region b); moving f with that neighbour can leave neither.
    /// At most `max_trials` pairs are tried; returns the moves kept.
    pub fn pair_moves(
        &self,
        fc: &mut [u32],
        pos: &mut [V3],
        max_trials: usize,
    ) -> Result<usize, SolveError> {
        let Moves {
            topo,
            faces,
            planes,
            ..
        } = *self;
        let edge_neighbors = |f: usize| {
            topo.face_edges[f].map(|e| {
                let ef = topo.edge_faces[e as usize];
                let g = if ef[0] as usize == f { ef[1] } else { ef[0] };
                (g != NO_FACE).then_some(g as usize)
            })
        };
        let pairs = |fc: &[u32], f0: usize| {
            let mut out = Vec::new();
            let cands = faces_around(topo, faces, f0);
            for &g in &cands {
                for h in edge_neighbors(g).into_iter().flatten() {
                    if fc[h] != fc[g] || h < g && cands.contains(&h) {
                        continue; // other region, or this pair comes up from h's side
                    }
                    let mut targets: Vec<u32> = [g, h]
                        .iter()
                        .flat_map(|&x| edge_neighbors(x).into_iter().flatten())
                        .map(|x| fc[x])
                        .filter(|&c| c != fc[g] && planes[c as usize].is_some())
                        .collect();
                    targets.sort_unstable();
                    targets.dedup();
                    out.extend(targets.into_iter().map(|to| vec![(g, to), (h, to)]));
                }
            }
            out
        };
        self.moves_at_bad_faces(fc, pos, max_trials, pairs)
    }

    /// Whole-region moves at the bad faces left: each region at a bad face's vertices with at most
    /// `max_faces` faces goes entirely into one neighbour (closest plane normal first), keeping
    /// every plane. Where [`dissolve_folded_regions`] hands each face to its own closest neighbour,
    /// here the region's outline disappears as a whole, so the vertices that were on its outline
    /// go onto planes they already neighboured; that keeps the chains of one boundary together,
    /// which face-by-face moves break when a region's faces have different closest neighbours.
    /// At most `max_trials` moves are tried; returns those
    /// kept (the regions are left empty: the caller renumbers).
    pub fn absorb_regions(
        &self,
        fc: &mut [u32],
        pos: &mut [V3],
        max_faces: usize,
        max_trials: usize,
    ) -> Result<usize, SolveError> {
        let Moves {
            topo,
            faces,
            planes,
            ..
        } = *self;
        let wholes = |fc: &[u32], f0: usize| {
            let mut regs: Vec<u32> = faces[f0]
                .iter()
                .flat_map(|&w| regions_at(topo, fc, w))
                .collect();
            regs.sort_unstable();
            regs.dedup();
            let mut out = Vec::new();
            for r in regs {
                let Some(pr) = planes[r as usize] else {
                    continue;
                };
                let members: Vec<usize> = (0..fc.len()).filter(|&h| fc[h] == r).collect();
                if members.len() > max_faces {
                    continue;
                }
                let mut targets: Vec<(u32, f64)> = members
                    .iter()
                    .flat_map(|&h| faces[h].iter().flat_map(|&w| regions_at(topo, fc, w)))
                    .filter(|&t| t != r)
                    .filter_map(|t| planes[t as usize].map(|p| (t, dot(p.n, pr.n))))
                    .collect();
                targets.sort_unstable_by_key(|&(t, _)| t);
                targets.dedup_by_key(|&mut (t, _)| t);
                targets.sort_by(|a, b| b.1.total_cmp(&a.1));
                out.extend(
                    targets
                        .into_iter()
                        .map(|(t, _)| members.iter().map(|&h| (h, t)).collect()),
                );
            }
            out
        };
        self.moves_at_bad_faces(fc, pos, max_trials, wholes)
    }

    /// Ring moves at the bad faces left: for each vertex of a bad face and each region there, every
    /// face around the vertex goes into that region, which makes the vertex interior to it. Why: a
    /// region whose corner in its plane needs a reflex angle (its two boundary lines leave the
    /// corner on a saddle of planes) cannot cover it with the single face it has there — a
    /// triangle spans less than 180° — and a one- or two-face move at that corner takes the corner
    /// off a plane or puts a neighbour on four; absorbing the ring of the face's vertex on a
    /// boundary line gives the region a second face there with an interior vertex between them.
    /// Rings of more than `max_ring` faces to move are skipped; at most `max_trials` rings are
    /// tried; returns the rings kept.
    pub fn ring_moves(
        &self,
        fc: &mut [u32],
        pos: &mut [V3],
        max_ring: usize,
        max_trials: usize,
    ) -> Result<usize, SolveError> {
        let Moves {
            topo,
            faces,
            planes,
            ..
        } = *self;
        let rings = |fc: &[u32], f0: usize| {
            let mut out = Vec::new();
            for w in faces[f0] {
                for c in regions_at(topo, fc, w) {
                    if planes[c as usize].is_none() {
                        continue;
                    }
                    let moves: Vec<(usize, u32)> = topo
                        .vertex_faces(w)
                        .iter()
                        .map(|&h| h as usize)
                        .filter(|&h| fc[h] != c)
                        .map(|h| (h, c))
                        .collect();
                    if !moves.is_empty() && moves.len() <= max_ring {
                        out.push(moves);
                    }
                }
            }
            out
        };
        self.moves_at_bad_faces(fc, pos, max_trials, rings)
    }

    /// The loop the move repairs share: for each face bad at the start and still bad, the
    /// candidate move sets `candidates(fc, face)` are tried in order ([`try_relabel`]) until one is
    /// kept; at most `max_trials` sets in all. Returns the sets kept.
    fn moves_at_bad_faces(
        &self,
        fc: &mut [u32],
        pos: &mut [V3],
        max_trials: usize,
        candidates: impl Fn(&[u32], usize) -> Vec<Vec<(usize, u32)>>,
    ) -> Result<usize, SolveError> {
        let Moves {
            topo,
            faces,
            planes,
            input,
            min_area,
            tol,
        } = *self;
        let on_border = border_vertices(topo);
        let (mut trials, mut kept) = (0, 0);
        for f0 in bad_faces(pos, faces, fc, planes, min_area) {
            if bad_faces_among(pos, faces, fc, planes, min_area, &[f0]).is_empty() {
                continue;
            }
            for moves in candidates(fc, f0) {
                if trials >= max_trials {
                    return Ok(kept);
                }
                trials += 1;
                if try_relabel(
                    topo, faces, fc, planes, input, pos, min_area, tol, &on_border, &moves,
                )? {
                    kept += 1;
                    break;
                }
            }
        }
        Ok(kept)
    }
}

/// After a change of regions or planes that put the vertices it touched onto their plane sets:
/// re-spaces the chains, repairs what folds in `scope` (Tutte patches, then the barrier
/// untangler across boundaries) and says whether the change is worth keeping — fewer bad faces
/// in `scope` (the faces of `regions`) than `before`, counting also every face outside it
/// around a vertex that moved (against `saved`, the positions before the change). The caller
/// restores when not. `layout` is the state after the change; the barrier untangler runs only
/// while the patches leave at most `slide_excess` more bad faces than `before`.
pub(super) fn settle(
    layout: &Layout,
    pos: &mut [V3],
    saved: &[V3],
    scope: &[usize],
    regions: &[u32],
    before: usize,
    slide_excess: usize,
) -> Result<bool, SolveError> {
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
    respace_chains(topo, fc, vc, on_border, input, pos);
    let mut bad = bad_faces_among(pos, faces, fc, planes, min_area, scope);
    if bad.len() >= before {
        repair_patches(layout, pos, bad, Some(scope), 4)?;
        bad = bad_faces_among(pos, faces, fc, planes, min_area, scope);
    }
    if bad.len() >= before && !bad.is_empty() && bad.len() <= before.saturating_add(slide_excess) {
        let quick = Untangle2dOptions {
            max_rounds: 12,
            iterations: 100,
            stall_rounds: 4,
            ..Untangle2dOptions::default()
        };
        slide_near(layout, pos, &bad, 3, &quick);
        bad = bad_faces_among(pos, faces, fc, planes, min_area, scope);
    }
    let after = bad.len();
    let mut outside: Vec<usize> = (0..pos.len())
        .filter(|&v| pos[v] != saved[v])
        .flat_map(|v| topo.vertex_faces(v as u32).iter().map(|&h| h as usize))
        .filter(|&h| regions.binary_search(&fc[h]).is_err())
        .collect();
    outside.sort_unstable();
    outside.dedup();
    let (extra_before, extra_after) = if outside.is_empty() {
        (0, 0)
    } else {
        (
            bad_faces_among(saved, faces, fc, planes, min_area, &outside).len(),
            bad_faces_among(pos, faces, fc, planes, min_area, &outside).len(),
        )
    };
    Ok(after + extra_after < before + extra_before)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;

    /// A flat n×n grid in z = 0 (two triangles per cell, normal +z).
    fn flat_grid(n: u32) -> TriMesh {
        let positions = (0..(n + 1) * (n + 1))
            .map(|i| [(i % (n + 1)) as f64, (i / (n + 1)) as f64, 0.0])
            .collect();
        let mut faces = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let a = y * (n + 1) + x;
                faces.push([a, a + 1, a + n + 2]);
                faces.push([a, a + n + 2, a + n + 1]);
            }
        }
        TriMesh { positions, faces }
    }

    /// A small region inside a flat one with a tilted plane: its outline lies on the line where
    /// the planes meet, so it collapses. Dissolving it into the surrounding region restores a
    /// flat, fold-free grid; a limit below its size leaves it alone.
    #[test]
    fn a_collapsed_inner_region_goes_back_to_its_neighbour() {
        let m = flat_grid(4);
        let topo = Topology::build(&m, std::path::Path::new("grid")).unwrap();
        let centre = 12u32;
        let fc: Vec<u32> = m
            .faces
            .iter()
            .map(|f| u32::from(f.contains(&centre)))
            .collect();
        let n = normalize([0.3, 0.0, 1.0]).unwrap();
        let planes = vec![
            Some(Plane {
                n: [0.0, 0.0, 1.0],
                d: 0.0,
            }),
            Some(Plane {
                n,
                d: -dot(n, m.positions[centre as usize]),
            }),
        ];
        let mut pos = m.positions.clone();
        let all: Vec<u32> = (0..pos.len() as u32).collect();
        assert!(onto_plane_sets(&topo, &fc, &planes, &mut pos, &all, 1e-9));
        // The collapsed faces keep areas of ~1e-11 from the projection's round-off.
        let min_area = 1e-9;
        let before = bad_faces(&pos, &m.faces, &fc, &planes, min_area);
        assert!(before.len() >= 2, "{before:?} {fc:?} {pos:?}");
        let opts = |max_faces| DissolveOptions {
            max_faces,
            tol: 1e-9,
            max_trials: 4,
        };
        let (mut fc2, mut pos2) = (fc.clone(), pos.clone());
        let none = dissolve_folded_regions(
            &topo,
            &m.faces,
            &mut fc2,
            &planes,
            &m.positions,
            &mut pos2,
            min_area,
            &opts(5),
        )
        .unwrap();
        assert_eq!((none, &fc2, &pos2), (0, &fc, &pos));
        let mut fc = fc;
        let one = dissolve_folded_regions(
            &topo,
            &m.faces,
            &mut fc,
            &planes,
            &m.positions,
            &mut pos,
            min_area,
            &opts(6),
        )
        .unwrap();
        assert_eq!(one, 1);
        assert!(fc.iter().all(|&c| c == 0));
        assert!(bad_faces(&pos, &m.faces, &fc, &planes, min_area).is_empty());
        assert!(pos.iter().all(|p| p[2].abs() < 1e-9));
    }

    /// The same collapsed inner region, moved whole: into its only neighbour, which leaves a
    /// flat fold-free grid with one region; a size limit below the region's leaves it alone.
    #[test]
    fn absorb_moves_a_collapsed_region_whole_into_its_neighbour() {
        let m = flat_grid(4);
        let topo = Topology::build(&m, std::path::Path::new("grid")).unwrap();
        let centre = 12u32;
        let fc0: Vec<u32> = m
            .faces
            .iter()
            .map(|f| u32::from(f.contains(&centre)))
            .collect();
        let n = normalize([0.0, -0.4, 1.0]).unwrap();
        let planes = vec![
            Some(Plane {
                n: [0.0, 0.0, 1.0],
                d: 0.0,
            }),
            Some(Plane {
                n,
                d: -dot(n, m.positions[centre as usize]),
            }),
        ];
        let mut pos0 = m.positions.clone();
        let all: Vec<u32> = (0..pos0.len() as u32).collect();
        assert!(onto_plane_sets(&topo, &fc0, &planes, &mut pos0, &all, 1e-9));
        let min_area = 1e-9;
        assert!(bad_faces(&pos0, &m.faces, &fc0, &planes, min_area).len() >= 2);
        let run = |max_faces| {
            let (mut fc, mut pos) = (fc0.clone(), pos0.clone());
            let moves = Moves {
                topo: &topo,
                faces: &m.faces,
                planes: &planes,
                input: &m.positions,
                min_area,
                tol: 1e-9,
            };
            let k = moves
                .absorb_regions(&mut fc, &mut pos, max_faces, 8)
                .unwrap();
            (k, fc, pos)
        };
        assert_eq!(run(5), (0, fc0.clone(), pos0.clone()));
        let (k, fc, pos) = run(6);
        assert_eq!(k, 1);
        assert!(fc.iter().all(|&c| c == 0));
        assert!(bad_faces(&pos, &m.faces, &fc, &planes, min_area).is_empty());
        assert!(pos.iter().all(|p| p[2].abs() < 1e-9));
    }

    /// A face-move repair on tangled two-page books: never more bad faces, every vertex on its
    /// planes, some moves kept; nothing changes on a clean layout.
    fn moves_on_tangled_books(name: &str, mv: impl Fn(&Moves, &mut [u32], &mut [V3]) -> usize) {
        let (input, faces, fc0, planes) = crate::approx::slide::tests::grid_book(5);
        let mesh = TriMesh {
            positions: input.clone(),
            faces: faces.clone(),
        };
        let topo = Topology::build(&mesh, std::path::Path::new("book")).unwrap();
        let moves = Moves {
            topo: &topo,
            faces: &faces,
            planes: &planes,
            input: &input,
            min_area: 1e-12,
            tol: 1e-9,
        };
        let (mut fc, mut pos) = (fc0.clone(), input.clone());
        let kept = mv(&moves, &mut fc, &mut pos);
        assert_eq!((kept, &fc, &pos), (0, &fc0, &input), "{name}");
        let border = border_vertices(&topo);
        let mut rnd = crate::approx::slide::tests::uniform(99);
        let mut moved = 0;
        for trial in 0..6 {
            let mut fc = fc0.clone();
            let mut pos = input.clone();
            let vc = vertex_clusters(&topo, &fc);
            // Along the spine for its vertices, in the page for the others.
            for v in 0..pos.len() {
                if border[v] {
                    continue;
                }
                pos[v][0] += 1.5 * rnd();
                if vc[v].len() == 1 {
                    pos[v][if vc[v][0] == 0 { 1 } else { 2 }] += 0.8 * rnd();
                }
            }
            let before = bad_faces(&pos, &faces, &fc, &planes, 1e-12).len();
            let k = mv(&moves, &mut fc, &mut pos);
            let after = bad_faces(&pos, &faces, &fc, &planes, 1e-12).len();
            moved += k;
            assert!(after <= before, "{name} trial {trial}: {before} -> {after}");
            for (v, p) in pos.iter().enumerate() {
                for c in regions_at(&topo, &fc, v as u32) {
                    let d = planes[c as usize].unwrap().signed_distance(*p);
                    assert!(
                        d.abs() < 1e-9,
                        "{name} trial {trial}: vertex {v} off plane {c}: {d}"
                    );
                }
            }
        }
        assert!(moved >= 3, "{name}: only {moved} moves kept");
    }

    #[test]
    fn pair_moves_never_add_folds_and_keep_planes() {
        moves_on_tangled_books("pair", |m, fc, pos| m.pair_moves(fc, pos, 200).unwrap());
    }

    #[test]
    fn ring_moves_never_add_folds_and_keep_planes() {
        moves_on_tangled_books("ring", |m, fc, pos| m.ring_moves(fc, pos, 8, 200).unwrap());
    }
}
