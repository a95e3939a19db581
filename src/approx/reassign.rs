//! Moves faces across region boundaries where no vertex placement can remove a fold.
//!
//! Once the planes are fixed, a face whose three corners all sit on region boundaries is fixed
//! too: its corners lie on plane–plane lines or at three-plane points. At a reflex corner of a
//! region's outline, the face spanning the two boundary edges there is flipped wherever the
//! chain vertices slide; where three corners share a face, nothing moves at all. These are most
//! of the bad faces the untangler leaves ([`super::untangle`]). Changing which region such a
//! face (or a face next to it) belongs to changes the outline there, and with it the constraint
//! set of its corners. So this is a local search with the planes frozen: try moving one face
//! near a bad face into an edge-adjacent region, put the corners on their new plane sets,
//! re-space the chains, repair the interior around what is still bad (Tutte patches, then, where
//! those fold — a move often leaves a reflex outline corner next to it — a short run of the
//! barrier untangler across boundaries, [`super::slide`]), and keep the move when the regions it
//! touches, plus every face around a vertex that moved, have fewer bad faces than before (chain
//! re-spacing and the repairs can reach past those regions; counting only them let moves add
//! folds elsewhere).
//!
//! A move is only tried when both regions stay locally disk-like (one fan of each around every
//! corner of the face, so no region is cut in two or pinched at a vertex) and when every corner
//! still has a point on all its planes (within `tol`: exact planarity is kept).

use super::boundary_l0::project;
use super::cluster::{regions_at, vertex_clusters};
use super::geom::{Plane, V3};
use super::slide::slide_near;
use super::untangle::{
    bad_faces, bad_faces_among, border_vertices, repair_patches, respace_chains, Layout,
};
use super::untangle2d::Untangle2dOptions;
use crate::linalg::SolveError;
use crate::mesh::{Topology, NO_FACE};

/// What [`reassign_bad_faces`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Reassigned {
    /// Moves kept.
    pub faces_moved: usize,
    /// Moves tried (each costs a local re-layout).
    pub trials: usize,
    /// Moves repaired with the barrier untangler (see `max_slides`).
    pub slides: usize,
}

/// Options of [`reassign_bad_faces`].
#[derive(Clone, Debug, PartialEq)]
pub struct ReassignOptions {
    /// Rounds over the bad faces; a round that keeps no move ends the search.
    pub rounds: usize,
    /// Largest distance of a moved corner to any of its planes (absolute).
    pub tol: f64,
    /// Largest number of moves tried overall (bounds the time on meshes with many folds).
    pub max_trials: usize,
    /// Largest number of barrier-untangler repairs of a move (each costs far more than a
    /// Tutte repair), and the most bad faces near a move for which one is run.
    pub max_slides: usize,
    pub max_slide_faces: usize,
}

/// Nearest point to `x` on all `planes` (least squares, then checked): `None` when the planes
/// have no common point within `tol` or do not pin enough down to be solved stably.
pub(super) fn onto_planes(x: V3, planes: &[Plane], tol: f64) -> Option<V3> {
    // A tiny ridge keeps the directions the planes leave free at x.
    let y = project(x, planes, 1e-12)?;
    planes
        .iter()
        .all(|p| p.signed_distance(y).abs() <= tol)
        .then_some(y)
}

/// Puts each of `verts` onto the planes of its regions under `fc` ([`onto_planes`]); false at
/// the first vertex with no common point (earlier ones have moved: the caller restores).
pub(super) fn onto_plane_sets(
    topo: &Topology,
    fc: &[u32],
    planes: &[Option<Plane>],
    pos: &mut [V3],
    verts: &[u32],
    tol: f64,
) -> bool {
    verts.iter().all(|&v| {
        let ps: Vec<Plane> = regions_at(topo, fc, v)
            .iter()
            .filter_map(|&c| planes[c as usize])
            .collect();
        match onto_planes(pos[v as usize], &ps, tol) {
            Some(y) => {
                pos[v as usize] = y;
                true
            }
            None => false,
        }
    })
}

/// Face `f0` first, then the other faces around its corners (the candidates of a move that
/// may remove a fold at `f0`).
pub(super) fn faces_around(topo: &Topology, faces: &[[u32; 3]], f0: usize) -> Vec<usize> {
    let mut out: Vec<usize> = vec![f0];
    for &v in &faces[f0] {
        for &h in topo.vertex_faces(v) {
            if !out.contains(&(h as usize)) {
                out.push(h as usize);
            }
        }
    }
    out
}

/// Whether every region of `labels` around each vertex of `verts` forms one fan there (no
/// region pinched at a vertex: its outline would touch itself, which no layout in its plane
/// can realise without a fold).
pub(super) fn no_pinches(
    topo: &Topology,
    faces: &[[u32; 3]],
    labels: &[u32],
    verts: &[u32],
) -> bool {
    verts.iter().all(|&v| {
        regions_at(topo, labels, v).iter().all(|&c| {
            let inside = |h: usize| labels[h] == c;
            fans(topo, faces, v, &inside) <= 1
        })
    })
}

/// Number of contiguous fans of faces satisfying `inside` around vertex `v` (0 when none;
/// 1 when all). Each fan ends where the edge leaving `v` in face order leads to a face outside
/// (or to no face: the mesh border). Needs consistently oriented faces (validated input).
pub(super) fn fans(
    topo: &Topology,
    faces: &[[u32; 3]],
    v: u32,
    inside: &dyn Fn(usize) -> bool,
) -> usize {
    let vf = topo.vertex_faces(v);
    let mut ends = 0;
    let mut all = true;
    for &h in vf {
        let h = h as usize;
        if !inside(h) {
            all = false;
            continue;
        }
        let k = faces[h].iter().position(|&w| w == v).unwrap_or(0);
        let e = topo.face_edges[h][k];
        // Side k of a face runs from f[k] to f[k+1] (see `Topology::face_edges`).
        let ef = topo.edge_faces[e as usize];
        let other = if ef[0] as usize == h { ef[1] } else { ef[0] };
        if other == NO_FACE || !inside(other as usize) {
            ends += 1;
        }
    }
    if all && !vf.is_empty() {
        1
    } else {
        ends
    }
}

/// Local search over face moves (see module doc). `fc` and `pos` are changed in place; planes
/// stay. `input` are the input positions (chain arc lengths).
#[allow(clippy::too_many_arguments)]
pub fn reassign_bad_faces(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &mut [u32],
    planes: &[Option<Plane>],
    input: &[V3],
    pos: &mut [V3],
    min_area: f64,
    opts: &ReassignOptions,
) -> Result<Reassigned, SolveError> {
    let mut out = Reassigned::default();
    let on_border = border_vertices(topo);
    let mut region_faces: Vec<Vec<usize>> = vec![Vec::new(); planes.len()];
    for (f, &c) in fc.iter().enumerate() {
        region_faces[c as usize].push(f);
    }
    let edge_neighbor = |f: usize, e: u32| {
        let ef = topo.edge_faces[e as usize];
        let o = if ef[0] as usize == f { ef[1] } else { ef[0] };
        (o != NO_FACE).then_some(o as usize)
    };
    for _ in 0..opts.rounds {
        let bad = bad_faces(pos, faces, fc, planes, min_area);
        if bad.is_empty() {
            break;
        }
        let mut kept = 0;
        for &f0 in &bad {
            if out.trials >= opts.max_trials {
                return Ok(out);
            }
            // Still bad? (an earlier move nearby may have fixed it)
            if bad_faces_among(pos, faces, fc, planes, min_area, &[f0]).is_empty() {
                continue;
            }
            let cands = faces_around(topo, faces, f0);
            'cand: for &g in &cands {
                let from = fc[g];
                let mut targets: Vec<u32> = topo.face_edges[g]
                    .iter()
                    .filter_map(|&e| edge_neighbor(g, e))
                    .map(|h| fc[h])
                    .filter(|&c| c != from && planes[c as usize].is_some())
                    .collect();
                targets.sort_unstable();
                targets.dedup();
                for to in targets {
                    if out.trials >= opts.max_trials {
                        return Ok(out);
                    }
                    if try_move(
                        topo,
                        faces,
                        fc,
                        planes,
                        input,
                        pos,
                        min_area,
                        opts,
                        &on_border,
                        &mut region_faces,
                        g,
                        to,
                        &mut out,
                    )? {
                        kept += 1;
                        break 'cand;
                    }
                }
            }
        }
        if kept == 0 {
            break;
        }
    }
    Ok(out)
}

/// Tries moving face `g` into region `to`; keeps it (returns true) when the regions around
/// `g` end with fewer bad faces, else restores everything.
#[allow(clippy::too_many_arguments)]
fn try_move(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &mut [u32],
    planes: &[Option<Plane>],
    input: &[V3],
    pos: &mut [V3],
    min_area: f64,
    opts: &ReassignOptions,
    on_border: &[bool],
    region_faces: &mut [Vec<usize>],
    g: usize,
    to: u32,
    out: &mut Reassigned,
) -> Result<bool, SolveError> {
    let from = fc[g];
    if region_faces[from as usize].len() <= 1 {
        return Ok(false);
    }
    // Both regions stay one fan around each corner of g after the move.
    let simple = faces[g].iter().all(|&v| {
        let in_to = |h: usize| h == g || fc[h] == to;
        let in_from = |h: usize| h != g && fc[h] == from;
        fans(topo, faces, v, &in_to) <= 1 && fans(topo, faces, v, &in_from) <= 1
    });
    if !simple {
        return Ok(false);
    }
    out.trials += 1;
    // Regions whose faces can change: every region at a corner of g (chains and corners
    // there move), plus `to`.
    let mut regions: Vec<u32> = faces[g]
        .iter()
        .flat_map(|&v| topo.vertex_faces(v).iter().map(|&h| fc[h as usize]))
        .chain(std::iter::once(to))
        .collect();
    regions.sort_unstable();
    regions.dedup();
    let scope: Vec<usize> = regions
        .iter()
        .flat_map(|&r| region_faces[r as usize].iter().copied())
        .collect();
    let before = bad_faces_among(pos, faces, fc, planes, min_area, &scope).len();
    let saved = pos.to_vec();
    fc[g] = to;
    let restore = |fc: &mut [u32], pos: &mut [V3]| {
        fc[g] = from;
        pos.copy_from_slice(&saved);
    };
    // Corners of g onto their new plane sets.
    if !onto_plane_sets(topo, fc, planes, pos, &faces[g], opts.tol) {
        restore(fc, pos);
        return Ok(false);
    }
    let vc = vertex_clusters(topo, fc);
    respace_chains(topo, fc, &vc, on_border, input, pos);
    let bad = bad_faces_among(pos, faces, fc, planes, min_area, &scope);
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
    let after = if bad.len() < before {
        bad.len()
    } else {
        repair_patches(&layout, pos, bad, Some(&scope), 4)?;
        let bad = bad_faces_among(pos, faces, fc, planes, min_area, &scope);
        if bad.len() < before || bad.is_empty() {
            bad.len()
        } else {
            // Tutte patches fold where the region's outline is not convex near the move (a
            // reflex corner is what many moves create): the barrier untangler across
            // boundaries is the stronger, slower repair.
            let quick = Untangle2dOptions {
                max_rounds: 12,
                iterations: 100,
                stall_rounds: 4,
                ..Untangle2dOptions::default()
            };
            // Only the folds next to the move: far ones are not this move's doing.
            let mut near: Vec<u32> = faces[g].to_vec();
            for _ in 0..2 {
                let ring: Vec<u32> = near
                    .iter()
                    .flat_map(|&v| topo.neighbors(v).to_vec())
                    .collect();
                near.extend(ring);
                near.sort_unstable();
                near.dedup();
            }
            let local: Vec<usize> = bad
                .iter()
                .copied()
                .filter(|&b| faces[b].iter().any(|v| near.binary_search(v).is_ok()))
                .collect();
            if !local.is_empty()
                && local.len() <= opts.max_slide_faces
                && out.slides < opts.max_slides
            {
                out.slides += 1;
                slide_near(&layout, pos, &local, 3, &quick);
            }
            bad_faces_among(pos, faces, fc, planes, min_area, &scope).len()
        }
    };
    // Chains and the barrier repair can move vertices of regions outside `scope`: their faces
    // count too (`fc` differs from before only at g, which is in `scope`).
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
            bad_faces_among(&saved, faces, fc, planes, min_area, &outside).len(),
            bad_faces_among(pos, faces, fc, planes, min_area, &outside).len(),
        )
    };
    if after + extra_after < before + extra_before {
        let r = &mut region_faces[from as usize];
        if let Some(i) = r.iter().position(|&h| h == g) {
            r.swap_remove(i);
        }
        region_faces[to as usize].push(g);
        out.faces_moved += 1;
        return Ok(true);
    }
    restore(fc, pos);
    Ok(false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;

    /// 3×3 vertices, 8 triangles; the centre vertex 4 has six faces around it.
    fn grid() -> (TriMesh, Topology) {
        crate::approx::testing::grid(3)
    }

    #[test]
    fn fans_count_contiguous_runs_around_a_vertex() {
        let (m, t) = grid();
        let around: Vec<usize> = t.vertex_faces(4).iter().map(|&f| f as usize).collect();
        assert_eq!(around.len(), 6);
        assert_eq!(fans(&t, &m.faces, 4, &|_| true), 1);
        assert_eq!(fans(&t, &m.faces, 4, &|_| false), 0);
        // Two faces on opposite sides of the centre: two runs; one face: one run.
        let (a, b) = (around[0], around[0] ^ 7);
        assert!(around.contains(&b));
        assert_eq!(fans(&t, &m.faces, 4, &|h| h == a || h == b), 2);
        assert_eq!(fans(&t, &m.faces, 4, &|h| h == a), 1);
        // On the border: the missing face ends a run.
        assert_eq!(fans(&t, &m.faces, 0, &|_| true), 1);
    }

    #[test]
    fn corners_go_to_the_planes_common_point_or_are_refused() {
        let p = |n: V3, d: f64| Plane { n, d };
        let three = [
            p([1.0, 0.0, 0.0], -1.0),
            p([0.0, 1.0, 0.0], -2.0),
            p([0.0, 0.0, 1.0], -3.0),
        ];
        let y = onto_planes([0.0; 3], &three, 1e-9).unwrap();
        for (a, b) in y.iter().zip([1.0, 2.0, 3.0]) {
            assert!((a - b).abs() < 1e-9);
        }
        // One plane: the orthogonal projection.
        let y = onto_planes([5.0, 6.0, 7.0], &three[..1], 1e-9).unwrap();
        assert!((y[0] - 1.0).abs() < 1e-9 && (y[1] - 6.0).abs() < 1e-9);
        // A fourth plane missing that point: no common point, refused.
        let mut four = three.to_vec();
        four.push(p([0.6, 0.8, 0.0], -1.0));
        assert!(onto_planes([0.0; 3], &four, 1e-6).is_none());
    }
}
