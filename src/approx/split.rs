//! Splits regions that still fold, spending the part of the budget K that is left unused.
//!
//! The repairs before this one keep the number of regions (or lower it). But a region whose
//! outline overlaps itself once flattened — it turns too much, or its neighbours' planes cut
//! its outline in the wrong order — folds wherever its vertices go, and a small plane nudge
//! does not undo that. Two planes can: the region is split in two along the direction in which
//! its input normals spread ([`lloyd::split_region`]), each half gets a plane and the region's
//! vertices go onto their new plane sets, then the folds around are repaired as after a face
//! move (`dissolve::settle`). Three choices of planes are tried, the first kept: the old plane for
//! one half and a fit for the other (both ways round; the kept half's vertices barely move),
//! then a fit for both (its vertices projected from the input, since the flattened layout is
//! the one that folds). The change is kept only where it leaves fewer bad faces in the region's
//! neighbourhood; planes stay exact, and the count of regions never exceeds K because each
//! split spends one unit of the unused budget.

use super::cluster::vertex_clusters;
use super::dissolve::{neighbourhood, settle};
use super::geom::{add, fit_plane, scale, Plane, V3};
use super::lloyd;
use super::reassign::{no_pinches, onto_plane_sets};
use super::untangle::{bad_faces, bad_faces_among, border_vertices, Layout};
use crate::linalg::SolveError;
use crate::mesh::Topology;

/// Options of [`split_folded_regions`].
#[derive(Clone, Debug, PartialEq)]
pub struct SplitOptions {
    /// Largest number of splits kept (the unused part of K).
    pub budget: usize,
    /// Largest distance of a vertex to any of its new planes (absolute).
    pub tol: f64,
    /// Largest number of regions tried.
    pub max_trials: usize,
}

/// Tries to split each region at a bad face (most bad faces first) while budget is left;
/// returns how many splits were kept. `fc`, `planes` (one plane appended per split) and `pos`
/// change in place. `normals` and `areas` are the input's per-face normals and areas.
#[allow(clippy::too_many_arguments)]
pub fn split_folded_regions(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &mut [u32],
    planes: &mut Vec<Option<Plane>>,
    input: &[V3],
    pos: &mut [V3],
    min_area: f64,
    normals: &[V3],
    areas: &[f64],
    opts: &SplitOptions,
) -> Result<usize, SolveError> {
    let on_border = border_vertices(topo);
    let mut tried = vec![false; planes.len()];
    let (mut trials, mut kept) = (0, 0);
    while kept < opts.budget && trials < opts.max_trials {
        let bad = bad_faces(pos, faces, fc, planes, min_area);
        let mut count = vec![0usize; planes.len()];
        for &f in &bad {
            count[fc[f] as usize] += 1;
        }
        let Some(r) = (0..planes.len())
            .filter(|&c| count[c] > 0 && !tried[c] && planes[c].is_some())
            .max_by_key(|&c| (count[c], std::cmp::Reverse(c)))
        else {
            break;
        };
        tried[r] = true;
        trials += 1;
        if try_split(
            topo, faces, fc, planes, input, pos, min_area, normals, areas, opts.tol, &on_border,
            r as u32,
        )? {
            kept += 1;
            // Both halves may be tried again (the new one is past `tried`'s end).
            tried[r] = false;
            tried.push(false);
        }
    }
    Ok(kept)
}

#[allow(clippy::too_many_arguments)]
fn try_split(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &mut [u32],
    planes: &mut Vec<Option<Plane>>,
    input: &[V3],
    pos: &mut [V3],
    min_area: f64,
    normals: &[V3],
    areas: &[f64],
    tol: f64,
    on_border: &[bool],
    r: u32,
) -> Result<bool, SolveError> {
    let Some(old_plane) = planes[r as usize] else {
        return Ok(false);
    };
    let new = planes.len() as u32;
    let mut labels = fc.to_vec();
    if !lloyd::split_region(topo, normals, areas, &mut labels, r, new, 10) {
        return Ok(false);
    }
    let members: Vec<usize> = (0..fc.len()).filter(|&f| fc[f] == r).collect();
    let halves = [r, new].map(|c| {
        members
            .iter()
            .copied()
            .filter(|&f| labels[f] == c)
            .collect::<Vec<usize>>()
    });
    if halves
        .iter()
        .any(|h| h.is_empty() || !connected(topo, &labels, h))
    {
        return Ok(false);
    }
    let mut verts: Vec<u32> = members.iter().flat_map(|&f| faces[f]).collect();
    verts.sort_unstable();
    verts.dedup();
    if !no_pinches(topo, faces, &labels, &verts) {
        return Ok(false);
    }
    let fit = |half: &[usize]| {
        let orient = half
            .iter()
            .fold([0.0; 3], |s, &f| add(s, scale(normals[f], areas[f])));
        fit_plane(
            half.iter()
                .flat_map(|&f| faces[f].map(|v| (input[v as usize], areas[f]))),
            orient,
        )
    };
    let (Some(fit_a), Some(fit_b)) = (fit(&halves[0]), fit(&halves[1])) else {
        return Ok(false);
    };
    let (regions, scope) = neighbourhood(topo, fc, &verts, [new].into_iter());
    let before = bad_faces_among(pos, faces, fc, planes, min_area, &scope).len();
    let saved = pos.to_vec();
    let old_fc = fc.to_vec();
    planes.push(None);
    // With the old plane kept for one half, the vertices start where they are (that half's
    // layout is already fold-free or nearly); with two new planes, from the input (the
    // flattened layout is what folds).
    for (a, b, from_input) in [
        (old_plane, fit_b, false),
        (fit_a, old_plane, false),
        (fit_a, fit_b, true),
    ] {
        fc.copy_from_slice(&labels);
        planes[r as usize] = Some(a);
        planes[new as usize] = Some(b);
        if from_input {
            for &v in &verts {
                pos[v as usize] = input[v as usize];
            }
        }
        if onto_plane_sets(topo, fc, planes, pos, &verts, tol) {
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
            if settle(&layout, pos, &saved, &scope, &regions, before, usize::MAX)? {
                return Ok(true);
            }
        }
        pos.copy_from_slice(&saved);
    }
    fc.copy_from_slice(&old_fc);
    planes[r as usize] = Some(old_plane);
    planes.pop();
    Ok(false)
}

/// Whether the faces `half` (all labelled alike in `labels`) form one edge-connected piece.
fn connected(topo: &Topology, labels: &[u32], half: &[usize]) -> bool {
    let c = labels[half[0]];
    let mut seen = std::collections::HashSet::from([half[0]]);
    let mut stack = vec![half[0]];
    while let Some(f) = stack.pop() {
        for g in lloyd::neighbors(topo, f) {
            if labels[g] == c && seen.insert(g) {
                stack.push(g);
            }
        }
    }
    seen.len() == half.len()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approx::geom::face_normals_areas;
    use crate::mesh::TriMesh;

    /// A strip bent into a "C" (an arc of 270° about the y axis, normals pointing out), `n`
    /// segments around and two rows of cells along y.
    fn c_strip(n: u32) -> TriMesh {
        let mut positions = Vec::new();
        for y in 0..3 {
            for i in 0..=n {
                let phi = (-135.0 + 270.0 * i as f64 / n as f64).to_radians();
                positions.push([phi.cos(), y as f64, phi.sin()]);
            }
        }
        let at = |i: u32, y: u32| y * (n + 1) + i;
        let mut faces = Vec::new();
        for y in 0..2 {
            for i in 0..n {
                let (a, b, c, d) = (at(i, y), at(i + 1, y), at(i + 1, y + 1), at(i, y + 1));
                faces.push([a, d, b]);
                faces.push([b, d, c]);
            }
        }
        TriMesh { positions, faces }
    }

    /// One region for the whole C, flattened onto its best plane: the back of the C folds over
    /// (its faces turn more than 90° from that plane), and no placement in one plane helps.
    /// Splitting it into two halves that each turn 135° does: the change is kept, nothing
    /// folds, and every vertex lies on all its planes.
    #[test]
    fn splitting_a_region_that_turns_too_much_removes_its_folds() {
        let mesh = c_strip(12);
        let topo = Topology::build(&mesh, std::path::Path::new("c")).unwrap();
        let input = mesh.positions.clone();
        let (normals, areas) = face_normals_areas(&input, &mesh.faces);
        let mut fc = vec![0u32; mesh.faces.len()];
        let plane = fit_plane(input.iter().map(|&p| (p, 1.0)), [1.0, 0.0, 0.0]).unwrap();
        let mut planes = vec![Some(plane)];
        let mut pos: Vec<V3> = input
            .iter()
            .map(|&p| super::super::geom::sub(p, scale(plane.n, plane.signed_distance(p))))
            .collect();
        let min_area = 1e-12;
        let before = bad_faces(&pos, &mesh.faces, &fc, &planes, min_area).len();
        assert!(before >= 8, "{before}");
        let opts = SplitOptions {
            budget: 1,
            tol: 1e-9,
            max_trials: 4,
        };
        let kept = split_folded_regions(
            &topo,
            &mesh.faces,
            &mut fc,
            &mut planes,
            &input,
            &mut pos,
            min_area,
            &normals,
            &areas,
            &opts,
        )
        .unwrap();
        assert_eq!(kept, 1);
        assert_eq!(planes.len(), 2);
        assert!(fc.contains(&0) && fc.contains(&1));
        assert!(bad_faces(&pos, &mesh.faces, &fc, &planes, min_area).is_empty());
        let vc = vertex_clusters(&topo, &fc);
        for (v, p) in pos.iter().enumerate() {
            for &c in &vc[v] {
                let d = planes[c as usize].unwrap().signed_distance(*p);
                assert!(d.abs() < 1e-9, "vertex {v} off plane {c}: {d}");
            }
        }
        // The budget is respected: with none, nothing is split.
        let mut fc0 = vec![0u32; mesh.faces.len()];
        let mut planes0 = vec![Some(plane)];
        let opts0 = SplitOptions { budget: 0, ..opts };
        let mut pos0 = pos.clone();
        let kept0 = split_folded_regions(
            &topo,
            &mesh.faces,
            &mut fc0,
            &mut planes0,
            &input,
            &mut pos0,
            min_area,
            &normals,
            &areas,
            &opts0,
        )
        .unwrap();
        assert_eq!((kept0, planes0.len()), (0, 1));
    }
}
