//! Stage 6: the realised regions' borders moved to where the error is measured.
//!
//! The partition is drawn on the smoothed normals and realised by splits and merges; its
//! borders were never chosen by the error the run is judged by (the mean distance of the input
//! vertices to their regions' planes, [`super::input_distances`]). With the planes held, that
//! error is a sum over vertices of the mean distance to the planes of the regions around
//! them, so moving one border face from region A to its neighbour B changes only its three
//! vertices' terms: the move is taken when their sum drops. Two restrictions keep the
//! construction's guarantees: a face moves only when it is a leaf of A (one neighbour in A, so
//! A stays connected) and when none of its vertices is or becomes a junction of three regions
//! (the corners, where three planes meet, stay where they were). The polygons are built again
//! on the same planes and checked as every output is; regions a fault names get their moves
//! undone, and the whole is dropped after 8 builds or if a region ends in two pieces. Then
//! the planes are refitted to the moved vertex sets (stage 5 again).

use super::{build_checked, cluster, input_distances, outline, trace};

/// Moves faces on a region's border to the neighbouring region whose plane their vertices are
/// nearer to, when that lowers the headline error over the realised planes, and builds the
/// polygons again; returns whether the result was kept (valid and nearer the input). The
/// caller then refits the planes to the new vertex sets ([`super::refit`]).
pub(super) fn relabel(surface: &outline::Surface<'_>, r: &mut outline::Realised) -> bool {
    let (topo, faces, pos, diag) = (surface.topo, surface.faces, surface.pos, surface.diag);
    let mut labels = r.labels.clone();
    // Faces of each region at each vertex.
    let mut count: Vec<Vec<(u32, u32)>> = vec![Vec::new(); topo.n_vertices];
    for (f, tri) in faces.iter().enumerate() {
        for &v in tri {
            let c = &mut count[v as usize];
            match c.iter_mut().find(|e| e.0 == labels[f]) {
                Some(e) => e.1 += 1,
                None => c.push((labels[f], 1)),
            }
        }
    }
    let d = |v: u32, c: u32| r.planes[c as usize].signed_distance(pos[v as usize]).abs();
    let mean = |v: u32, cs: &mut dyn Iterator<Item = u32>| {
        let (mut s, mut n) = (0.0, 0);
        for c in cs {
            s += d(v, c);
            n += 1;
        }
        s / n.max(1) as f64
    };
    let mut moves: Vec<(usize, u32, u32)> = Vec::new();
    for _pass in 0..2 {
        for f in 0..faces.len() {
            let a = labels[f];
            let nbrs = || super::lloyd::neighbors(topo, f);
            // A leaf of its region (one neighbour in it): moving it cannot disconnect it.
            if nbrs().filter(|&g| labels[g] == a).count() != 1 {
                continue;
            }
            let mut best = (0.0, u32::MAX);
            for g in nbrs() {
                let b = labels[g];
                if b == a {
                    continue;
                }
                // Away from junctions: no vertex of the face on three regions before or after,
                // so the corners (where three planes meet) stay where they were.
                let junction = faces[f].iter().any(|&v| {
                    let c = &count[v as usize];
                    c.len() >= 3 || (c.len() == 2 && !c.iter().any(|e| e.0 == b))
                });
                if junction {
                    continue;
                }
                let mut delta = 0.0;
                for &v in &faces[f] {
                    let c = &count[v as usize];
                    let before = mean(v, &mut c.iter().map(|e| e.0));
                    let after = mean(
                        v,
                        &mut c
                            .iter()
                            .filter(|e| !(e.0 == a && e.1 == 1))
                            .map(|e| e.0)
                            .chain((!c.iter().any(|e| e.0 == b)).then_some(b)),
                    );
                    delta += after - before;
                }
                if delta < best.0 {
                    best = (delta, b);
                }
            }
            if best.1 == u32::MAX {
                continue;
            }
            let b = best.1;
            labels[f] = b;
            moves.push((f, a, b));
            for &v in &faces[f] {
                let c = &mut count[v as usize];
                if let Some(i) = c.iter().position(|e| e.0 == a) {
                    c[i].1 -= 1;
                    if c[i].1 == 0 {
                        c.remove(i);
                    }
                }
                match c.iter_mut().find(|e| e.0 == b) {
                    Some(e) => e.1 += 1,
                    None => c.push((b, 1)),
                }
            }
        }
    }
    let old_at = cluster::vertex_clusters(topo, &r.labels);
    let before = input_distances(pos, &old_at, &r.planes).0;
    let mut builds = 0;
    // The planes are held: a failed build names regions, whose moves are undone (each to the
    // label the move left; a face moved twice keeps its first move if only the second is named).
    while !moves.is_empty() && builds < 8 {
        builds += 1;
        let at = cluster::vertex_clusters(topo, &labels);
        let after = input_distances(pos, &at, &r.planes).0;
        if after >= before {
            break;
        }
        // Undoing a move can strand a face that moved in through it: every region must
        // still be one piece, or the whole is dropped.
        if !regions_connected(topo, &labels, r.planes.len()) {
            break;
        }
        let named = match build_checked(surface, &labels, &r.planes, r.closes_handles) {
            Ok(polygons) => {
                let (b, a, m) = (before / diag, after / diag, moves.len());
                trace(|| {
                    format!(
                        "relabel: {m} faces, mean distance {b:.4e} → {a:.4e}·diag, {builds} builds"
                    )
                });
                r.polygons = polygons;
                r.labels = labels;
                return true;
            }
            Err(named) => named,
        };
        moves.retain(|&(f, a, b)| {
            if named.contains(&a) || named.contains(&b) {
                labels[f] = a;
                false
            } else {
                true
            }
        });
    }
    trace(|| format!("relabel: not kept ({builds} builds)"));
    false
}

/// Whether the faces of the `n` regions of `labels` are `n` pieces connected across edges.
fn regions_connected(topo: &crate::mesh::Topology, labels: &[u32], n: usize) -> bool {
    outline::parts(topo, labels.len(), |_| true, |f, g| labels[f] == labels[g]).len() == n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approx::bad_triangles;
    use crate::init::test_grid::{bumpy, id};
    use crate::mesh::{Topology, TriMesh};
    use std::path::Path;

    /// A sheet folded along x = ½ (two planes), its regions the two halves but for one face
    /// of the flat half, on the crease, given to the sloped half: the move back is a leaf move
    /// away from junctions that lowers the error, and the mesh built after it is valid.
    #[test]
    fn a_border_face_goes_back_to_the_plane_it_lies_on() {
        let k = 20;
        let (positions, faces) = bumpy(k, |x, _| (x - 0.5).max(0.0));
        let mesh = TriMesh { positions, faces };
        let topo = Topology::build(&mesh, Path::new("generated")).unwrap();
        let surface = outline::Surface::new(&topo, &mesh);
        let mut labels: Vec<u32> = mesh
            .faces
            .iter()
            .map(|f| {
                let x: f64 = f.iter().map(|&v| mesh.positions[v as usize][0]).sum();
                u32::from(x / 3.0 > 0.5)
            })
            .collect();
        // Cell (9, 10)'s lower-right face: its edge (10, 10)–(10, 11) is on the crease.
        let f = 2 * (10 * k + 9);
        assert_eq!(mesh.faces[f], [id(k, 9, 10), id(k, 10, 10), id(k, 10, 11)]);
        labels[f] = 1;
        let mut r = outline::realise(&surface, labels, 2, 2, true, &Default::default()).unwrap();
        assert_eq!(r.labels[f], 1, "the realisation kept the partition");
        let before = input_distances(
            &mesh.positions,
            &cluster::vertex_clusters(&topo, &r.labels),
            &r.planes,
        )
        .0;
        assert!(relabel(&surface, &mut r));
        assert_eq!(r.labels[f], 0);
        let after = input_distances(
            &mesh.positions,
            &cluster::vertex_clusters(&topo, &r.labels),
            &r.planes,
        )
        .0;
        assert!(after < before, "{before} → {after}");
        // The output is built on the same planes and passes the independent check.
        assert!(bad_triangles(&r.polygons, &r.planes, surface.diag).is_empty());
        assert_eq!(r.polygons.polygons.len(), 2);
        assert!(regions_connected(&topo, &r.labels, 2));
        // A face of region 1 set apart inside region 0 is a second piece of region 1.
        let mut split = r.labels.clone();
        split[0] = 1;
        assert!(!regions_connected(&topo, &split, 2));
    }
}
