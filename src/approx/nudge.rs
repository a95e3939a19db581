//! Tilts and shifts single planes where the folds left need different plane geometry.
//!
//! Every repair before this one keeps the planes: it moves vertices or faces. But where two
//! corners of the same chain (points where three planes meet) nearly coincide or come in the
//! wrong order, the faces between them fold wherever the vertices go; the cure is to move the
//! corners, i.e. the planes. A small coordinate search does that: for a region at a bad face,
//! rotate its plane about its centroid by a few angles around its two in-plane axes (and about
//! its vertices on four or more planes, which only stay feasible while every plane through
//! them turns about them), or shift it along its normal; put the region's vertices onto their new plane sets (a vertex of one
//! region orthogonally, of two onto the new line, of three onto the new point); repair as after
//! a face move (`dissolve::settle`); keep the first change that leaves fewer bad faces
//! in the region and its neighbours. Planarity stays exact; the approximation error changes a
//! little (the plane no longer is the region's best fit).

use super::cluster::vertex_clusters;
use super::dissolve::settle;
use super::geom::{add, cross, dot, norm, normalize, scale, sub, Frame, Plane, V3};
use super::reassign::onto_plane_sets;
use super::untangle::{bad_faces, bad_faces_among, border_vertices, Layout};
use crate::linalg::SolveError;
use crate::mesh::Topology;

/// Options of [`nudge_planes`].
#[derive(Clone, Debug, PartialEq)]
pub struct NudgeOptions {
    /// Rotation angles tried (radians), each in both senses about both in-plane axes.
    pub angles: Vec<f64>,
    /// Shifts along the normal tried, relative to the region's extent, in both senses.
    pub shifts: Vec<f64>,
    /// Largest distance of a vertex to any of its planes after projection (absolute).
    pub tol: f64,
    /// Largest number of changes tried overall.
    pub max_trials: usize,
    /// Rounds over the regions at bad faces; a round that keeps nothing ends the search.
    pub rounds: usize,
    /// The barrier untangler (the slow repair) runs only when Tutte patches leave at most this
    /// many more bad faces than before the change.
    pub slide_excess: usize,
}

/// What [`nudge_planes`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Nudged {
    pub kept: usize,
    pub trials: usize,
}

/// Coordinate search over the planes of regions at bad faces (see module doc). `planes`,
/// `pos` change in place; `fc` does not.
#[allow(clippy::too_many_arguments)]
pub fn nudge_planes(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &[u32],
    planes: &mut [Option<Plane>],
    input: &[V3],
    pos: &mut [V3],
    min_area: f64,
    opts: &NudgeOptions,
) -> Result<Nudged, SolveError> {
    let on_border = border_vertices(topo);
    let vc = vertex_clusters(topo, fc);
    let mut region_verts: Vec<Vec<u32>> = vec![Vec::new(); planes.len()];
    for (v, cs) in vc.iter().enumerate() {
        for &c in cs {
            region_verts[c as usize].push(v as u32);
        }
    }
    let mut region_faces: Vec<Vec<usize>> = vec![Vec::new(); planes.len()];
    for (f, &c) in fc.iter().enumerate() {
        region_faces[c as usize].push(f);
    }
    let mut out = Nudged::default();
    for _ in 0..opts.rounds {
        let bad = bad_faces(pos, faces, fc, planes, min_area);
        if bad.is_empty() {
            break;
        }
        let mut cands: Vec<u32> = bad
            .iter()
            .flat_map(|&f| {
                faces[f]
                    .iter()
                    .flat_map(|&v| vc[v as usize].iter().copied())
            })
            .collect();
        cands.sort_unstable();
        cands.dedup();
        let mut kept = 0;
        for c in cands {
            let Some(p) = planes[c as usize] else {
                continue;
            };
            let verts = &region_verts[c as usize];
            // The faces that can change: the region's and its neighbours'.
            let mut regions: Vec<u32> = verts
                .iter()
                .flat_map(|&v| vc[v as usize].iter().copied())
                .collect();
            regions.sort_unstable();
            regions.dedup();
            let scope: Vec<usize> = regions
                .iter()
                .flat_map(|&r| region_faces[r as usize].iter().copied())
                .collect();
            let before = bad_faces_among(pos, faces, fc, planes, min_area, &scope).len();
            if before == 0 {
                continue;
            }
            let Some(frame) = Frame::of(&p) else { continue };
            let pts: Vec<V3> = verts.iter().map(|&v| pos[v as usize]).collect();
            if pts.is_empty() {
                continue;
            }
            let centroid = scale(
                pts.iter().fold([0.0; 3], |a, &x| add(a, x)),
                1.0 / pts.len() as f64,
            );
            // Twice the largest distance from the centroid: the region's size.
            let extent = 2.0
                * pts
                    .iter()
                    .map(|&x| norm(sub(x, centroid)))
                    .fold(0.0, f64::max);
            let mut trials: Vec<Plane> = Vec::new();
            for (pivot, axes) in pivots(&p, &frame, centroid, verts, &vc, pos) {
                for &a in &opts.angles {
                    for &axis in &axes {
                        for s in [a, -a] {
                            // Rodrigues about an in-plane axis (perpendicular to n).
                            let n = add(scale(p.n, s.cos()), scale(cross(axis, p.n), s.sin()));
                            if let Some(n) = normalize(n) {
                                trials.push(Plane {
                                    n,
                                    d: -dot(n, pivot),
                                });
                            }
                        }
                    }
                }
            }
            for &t in &opts.shifts {
                for s in [t, -t] {
                    trials.push(Plane {
                        n: p.n,
                        d: p.d - s * extent,
                    });
                }
            }
            for q in trials {
                if out.trials >= opts.max_trials {
                    return Ok(out);
                }
                out.trials += 1;
                let saved = pos.to_vec();
                planes[c as usize] = Some(q);
                let placed = onto_plane_sets(topo, fc, planes, pos, verts, opts.tol);
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
                let keep = placed
                    && settle(
                        &layout,
                        pos,
                        &saved,
                        &scope,
                        &regions,
                        before,
                        opts.slide_excess,
                    )?;
                if keep {
                    out.kept += 1;
                    kept += 1;
                    break;
                }
                planes[c as usize] = Some(p);
                pos.copy_from_slice(&saved);
            }
        }
        if kept == 0 {
            break;
        }
    }
    Ok(out)
}

/// The points a plane is rotated about, each with its in-plane axes. The region's centroid
/// (both axes) comes first. Then its over-determined vertices — on four or more planes, which
/// can only stay on all of them while every plane through them keeps passing through them: one
/// such vertex is a pivot with both axes, two are an axis through both; with more, rotations
/// would move one of them off its planes, so only shifts and the centroid remain.
fn pivots(
    p: &Plane,
    frame: &Frame,
    centroid: V3,
    verts: &[u32],
    vc: &[Vec<u32>],
    pos: &[V3],
) -> Vec<(V3, Vec<V3>)> {
    let mut out = vec![(centroid, vec![frame.u, frame.v])];
    let over: Vec<V3> = verts
        .iter()
        .filter(|&&v| vc[v as usize].len() >= 4)
        .map(|&v| pos[v as usize])
        .collect();
    match over.as_slice() {
        [a] => out.push((*a, vec![frame.u, frame.v])),
        [a, b] => {
            // The axis through both, kept in the plane (both lie on it up to the tolerance).
            let d = sub(*b, *a);
            if let Some(axis) = normalize(sub(d, scale(p.n, dot(d, p.n)))) {
                out.push((*a, vec![axis]));
            }
        }
        _ => {}
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approx::slide::tests::grid_book;
    use crate::mesh::TriMesh;

    /// Rotations about the pivots keep the over-determined vertices on the plane: one such
    /// vertex is a pivot with both in-plane axes, two give the axis through both.
    #[test]
    fn pivots_keep_over_determined_vertices_on_the_rotated_plane() {
        let p = Plane {
            n: [0.0, 0.0, 1.0],
            d: -0.5,
        };
        let frame = Frame::of(&p).unwrap();
        let pos = vec![
            [0.0, 0.0, 0.5],
            [1.0, 0.2, 0.5],
            [0.3, 1.0, 0.5],
            [2.0, 2.0, 0.5],
        ];
        let many = vec![0, 1, 2, 3];
        let rotate = |pivot: V3, axis: V3, s: f64| {
            let n = normalize(add(scale(p.n, s.cos()), scale(cross(axis, p.n), s.sin()))).unwrap();
            Plane {
                n,
                d: -dot(n, pivot),
            }
        };
        // Vertex 1 on four planes.
        let vc = vec![vec![0], vec![0, 1, 2, 3], vec![0, 1], vec![0]];
        let centroid = [0.8, 0.8, 0.5];
        let ps = pivots(&p, &frame, centroid, &[0, 1, 2, 3], &vc, &pos);
        assert_eq!(ps.len(), 2);
        assert_eq!(ps[0].0, centroid);
        assert_eq!((ps[1].0, ps[1].1.len()), (pos[1], 2));
        for &axis in &ps[1].1 {
            let q = rotate(ps[1].0, axis, 0.2);
            assert!(q.signed_distance(pos[1]).abs() < 1e-12);
            assert!(q.signed_distance(pos[3]).abs() > 1e-3);
        }
        // Vertices 1 and 3 on four planes: one axis, through both.
        let vc2 = vec![vec![0], vec![0, 1, 2, 3], vec![0, 1], vec![0, 4, 5, 6]];
        let ps = pivots(&p, &frame, centroid, &[0, 1, 2, 3], &vc2, &pos);
        assert_eq!((ps.len(), ps[1].1.len()), (2, 1));
        let q = rotate(ps[1].0, ps[1].1[0], -0.3);
        for v in [1, 3] {
            assert!(q.signed_distance(pos[v]).abs() < 1e-12, "vertex {v}");
        }
        // Three: no pivot beyond the centroid.
        let vc3 = vec![
            vec![0, 7, 8, 9],
            vec![0, 1, 2, 3],
            vec![0, 1],
            vec![0, 4, 5, 6],
        ];
        assert_eq!(pivots(&p, &frame, centroid, &many, &vc3, &pos).len(), 1);
    }

    /// A two-page book whose page B plane is shifted so that the spine (where the pages meet)
    /// lands past page A's first row: faces of page A between them flip, and the row's border
    /// vertices are fixed, so no vertex placement fixes them. Moving page B's plane back does;
    /// every vertex ends on its planes.
    #[test]
    fn shifting_a_plane_moves_a_misplaced_chain_back() {
        let n = 4;
        let (input, faces, fc, mut planes) = grid_book(n);
        let mesh = TriMesh {
            positions: input.clone(),
            faces: faces.clone(),
        };
        let topo = Topology::build(&mesh, std::path::Path::new("book")).unwrap();
        // Page B (normal +y) moved to y = 1.15; its vertices follow, the spine onto the line.
        planes[1] = Some(Plane {
            n: [0.0, 1.0, 0.0],
            d: -1.15,
        });
        let vc = vertex_clusters(&topo, &fc);
        let mut pos = input.clone();
        for (v, cs) in vc.iter().enumerate() {
            if cs.contains(&1) {
                pos[v][1] = 1.15;
            }
        }
        let min_area = 1e-12;
        let before = bad_faces(&pos, &faces, &fc, &planes, min_area).len();
        assert!(before >= 2, "{before}");
        let opts = NudgeOptions {
            angles: vec![0.01, 0.1],
            shifts: vec![0.01, 0.08],
            tol: 1e-9,
            max_trials: 200,
            rounds: 8,
            slide_excess: 2,
        };
        let r = nudge_planes(
            &topo,
            &faces,
            &fc,
            &mut planes,
            &input,
            &mut pos,
            min_area,
            &opts,
        )
        .unwrap();
        assert!(r.kept >= 1);
        assert!(bad_faces(&pos, &faces, &fc, &planes, min_area).is_empty());
        for (v, p) in pos.iter().enumerate() {
            for &c in &vc[v] {
                let d = planes[c as usize].unwrap().signed_distance(*p);
                assert!(d.abs() < 1e-9, "vertex {v} off plane {c}: {d}");
            }
        }
    }
}
