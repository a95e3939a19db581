//! Lloyd relaxation of a face partition under the L2,1 (normal) metric, as in Variational
//! Shape Approximation (Cohen-Steiner, Alliez & Desbrun 2004).
//!
//! Why: region growing with a threshold leaves jagged, elongated regions whose shared
//! boundaries run in arbitrary directions. Once each region is made planar, a boundary shared
//! by regions a and b must lie on the line where their planes meet, whose direction is
//! n_a × n_b. On curved parts a boundary that does not run along that direction is squashed onto
//! the line and the faces next to it fold. The L2,1 partition puts the boundary between a and b
//! where a face normal is equally far from both proxy normals, i.e. where n·(n_a − n_b) = 0:
//! normals change across such a boundary, not along it, which is the direction of n_a × n_b.
//! Regions also become compact, so three-region corners are where the three planes nearly meet.
//!
//! Each round: the proxy of each region is its area-weighted mean normal; its seed is its face
//! of least error area·|n_f − N_c|²; regions are then re-grown from the seeds by one global
//! priority flood (least error first). Flooding keeps every region connected and non-empty and
//! never changes the region count.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::geom::{add, normalize, scale, sub, V3};
use crate::mesh::{Topology, NO_FACE};

/// Edge-neighbour faces of `f`.
pub(super) fn neighbors(topo: &Topology, f: usize) -> impl Iterator<Item = usize> + '_ {
    topo.face_edges[f].iter().filter_map(move |&e| {
        let [a, b] = topo.edge_faces[e as usize];
        let g = if a as usize == f { b } else { a };
        (g != NO_FACE).then_some(g as usize)
    })
}

/// L2,1 error of face `f` against proxy normal `p`.
fn err(normals: &[V3], areas: &[f64], f: usize, p: V3) -> f64 {
    let d = sub(normals[f], p);
    areas[f] * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
}

/// Relaxes `labels` (regions 0..count, each connected) for at most `rounds` rounds, stopping
/// when a round changes no face. Returns how many rounds changed something.
pub fn relax(
    topo: &Topology,
    normals: &[V3],
    areas: &[f64],
    labels: &mut [u32],
    rounds: usize,
) -> usize {
    relax_subset(
        topo,
        normals,
        areas,
        labels,
        &vec![true; labels.len()],
        rounds,
    )
}

/// [`relax`] where only faces with `movable[f]` may change region; the regions holding them
/// compete for them and the rest of the partition is left as it is. Each region's proxy is
/// taken from its movable faces (all of them for [`relax`]; for a split, the two halves are
/// all movable), so a round costs the movable faces, not the mesh.
pub fn relax_subset(
    topo: &Topology,
    normals: &[V3],
    areas: &[f64],
    labels: &mut [u32],
    movable: &[bool],
    rounds: usize,
) -> usize {
    let members: Vec<usize> = (0..labels.len()).filter(|&f| movable[f]).collect();
    let count = members
        .iter()
        .map(|&f| labels[f] as usize + 1)
        .max()
        .unwrap_or(0);
    // Faces not movable keep their label; movable ones are cleared each round.
    let mut next: Vec<u32> = labels.to_vec();
    // Regions each face has been offered to this round (a face has three neighbours).
    let mut offered: Vec<[u32; 3]> = vec![[u32::MAX; 3]; labels.len()];
    let mut heap: BinaryHeap<Reverse<(u64, usize, u32)>> = BinaryHeap::new();
    let mut changed_rounds = 0;
    // The members' labels one and two rounds back: a round is a function of the labels, so
    // labels equal to those two rounds back repeat with period two from then on.
    let snapshot = |labels: &[u32]| members.iter().map(|&f| labels[f]).collect::<Vec<u32>>();
    let mut back1 = snapshot(labels);
    let mut back2: Vec<u32> = Vec::new();
    for round in 0..rounds {
        let mut sums = vec![[0.0; 3]; count];
        for &f in &members {
            let c = labels[f] as usize;
            sums[c] = add(sums[c], scale(normals[f], areas[f]));
        }
        let proxy: Vec<V3> = sums
            .iter()
            .map(|&s| normalize(s).unwrap_or([0.0; 3]))
            .collect();
        let mut seed: Vec<Option<(f64, usize)>> = vec![None; count];
        for &f in &members {
            let c = labels[f];
            let e = err(normals, areas, f, proxy[c as usize]);
            let s = &mut seed[c as usize];
            if s.is_none_or(|(be, _)| e < be) {
                *s = Some((e, f));
            }
        }
        for &f in &members {
            next[f] = u32::MAX;
            offered[f] = [u32::MAX; 3];
        }
        // Keys are non-negative floats, whose bit patterns order like the values. A face is
        // offered to a region once: its key for that region is fixed within the round, so a
        // second entry (from another neighbour in the same region) would pop right after the
        // first and be skipped.
        heap.clear();
        let mut offer = |heap: &mut BinaryHeap<Reverse<(u64, usize, u32)>>, g: usize, c: u32| {
            let o = &mut offered[g];
            if o.contains(&c) {
                return;
            }
            if let Some(slot) = o.iter_mut().find(|x| **x == u32::MAX) {
                *slot = c;
            }
            let e = err(normals, areas, g, proxy[c as usize]);
            heap.push(Reverse((e.to_bits(), g, c)));
        };
        for (c, s) in seed.iter().enumerate() {
            if let Some((_, f)) = *s {
                next[f] = c as u32;
                for g in neighbors(topo, f) {
                    offer(&mut heap, g, c as u32);
                }
            }
        }
        while let Some(Reverse((_, f, c))) = heap.pop() {
            if next[f] != u32::MAX {
                continue;
            }
            next[f] = c;
            for g in neighbors(topo, f) {
                if next[g] == u32::MAX {
                    offer(&mut heap, g, c);
                }
            }
        }
        // Every face is reached: each connected component holds at least one region, hence one
        // seed. Faces of a component without a seed (not possible for a valid partition) keep
        // their label.
        let mut changed = false;
        for &f in &members {
            if next[f] == u32::MAX {
                next[f] = labels[f];
            } else if next[f] != labels[f] {
                labels[f] = next[f];
                changed = true;
            }
        }
        if !changed {
            break;
        }
        changed_rounds += 1;
        // A two-cycle (faces on the boundary swapping back and forth) changes every round
        // left, ending on these labels after an even number of rounds, else on the last
        // ones: the same result without the rounds.
        let now = snapshot(labels);
        if now == back2 {
            let left = rounds - 1 - round;
            if left % 2 == 1 {
                for (&f, &l) in members.iter().zip(&back1) {
                    labels[f] = l;
                }
            }
            return changed_rounds + left;
        }
        back2 = std::mem::replace(&mut back1, now);
    }
    changed_rounds
}

/// Splits region `c` in two along the main direction in which its normals spread: faces whose
/// normal lies on the positive side of that direction (about the mean) get label `new_label`,
/// then the two halves are relaxed against each other (the rest of the partition is left as
/// it is). A region that folds when flattened usually turns too much in one direction (a
/// half-cylinder); its two halves each turn half as much. Returns false when the region has
/// no spread to split along (all normals equal) or a half ends empty.
pub fn split_region(
    topo: &Topology,
    normals: &[V3],
    areas: &[f64],
    labels: &mut [u32],
    c: u32,
    new_label: u32,
    rounds: usize,
) -> bool {
    let members: Vec<usize> = (0..labels.len()).filter(|&f| labels[f] == c).collect();
    let sum = members
        .iter()
        .fold([0.0; 3], |s, &f| add(s, scale(normals[f], areas[f])));
    let total: f64 = members.iter().map(|&f| areas[f]).sum();
    if total <= 0.0 || normalize(sum).is_none() {
        return false;
    }
    // The centroid of the normals (not the unit mean normal): the area-weighted deviations
    // from it sum to zero, so faces lie on both sides of it along any direction. About the
    // unit mean, a region that turns far (a "C") has all its deviations on one side.
    let mean = scale(sum, 1.0 / total);
    let mut cov = [[0.0; 3]; 3];
    for &f in &members {
        let d = sub(normals[f], mean);
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += areas[f] * d[i] * d[j];
            }
        }
    }
    let (vals, vecs) = crate::linalg::small::sym_eigen::<3>(&cov);
    // Largest eigenvalue's vector (sym_eigen's order is not assumed).
    let Some(k) = (0..3).max_by(|&a, &b| vals[a].total_cmp(&vals[b])) else {
        return false;
    };
    if vals[k] <= 0.0 || !vals[k].is_finite() {
        return false;
    }
    let dir = [vecs[0][k], vecs[1][k], vecs[2][k]];
    let mut movable = vec![false; labels.len()];
    let mut n_new = 0;
    for &f in &members {
        movable[f] = true;
        let d = sub(normals[f], mean);
        if d[0] * dir[0] + d[1] * dir[1] + d[2] * dir[2] > 0.0 {
            labels[f] = new_label;
            n_new += 1;
        }
    }
    if n_new == 0 || n_new == members.len() {
        for &f in &members {
            labels[f] = c;
        }
        return false;
    }
    relax_subset(topo, normals, areas, labels, &movable, rounds);
    let kept = members.iter().filter(|&&f| labels[f] == c).count();
    kept > 0 && kept < members.len()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;

    /// A strip of 2·n triangles folded along x = n/2 into a roof: left half normal tilted one
    /// way, right half the other. The relaxed partition must split exactly at the ridge.
    /// A strip of 2n faces folded into a roof along its middle, with its topology (a manifold
    /// strip by construction), face normals and areas.
    fn roof(n: usize) -> (TriMesh, Topology, Vec<V3>, Vec<f64>) {
        let mut positions = Vec::new();
        for i in 0..=n {
            let x = i as f64;
            let z = if 2 * i <= n { x } else { n as f64 - x };
            positions.push([x, 0.0, z]);
            positions.push([x, 1.0, z]);
        }
        let mut faces = Vec::new();
        for i in 0..n as u32 {
            let (a, b, c, d) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
            faces.push([a, c, b]);
            faces.push([b, c, d]);
        }
        let mesh = TriMesh { positions, faces };
        let topo = Topology::build(&mesh, std::path::Path::new("roof")).unwrap();
        let (nr, ar) = super::super::geom::face_normals_areas(&mesh.positions, &mesh.faces);
        (mesh, topo, nr, ar)
    }

    #[test]
    fn relax_moves_boundary_to_the_ridge() {
        let n = 8;
        let (_, topo, normals, areas) = roof(n);
        // Start with a wrong split: only the first two faces in region 0.
        let mut labels: Vec<u32> = (0..2 * n).map(|f| u32::from(f >= 2)).collect();
        let rounds = relax(&topo, &normals, &areas, &mut labels, 20);
        assert!(rounds >= 1);
        let want: Vec<u32> = (0..2 * n).map(|f| u32::from(f >= n)).collect();
        assert_eq!(labels, want);
    }

    /// Relaxing R rounds at once (which stops early on a two-cycle) gives the labels of R
    /// single rounds one after the other (which never can), on noisy grids where the two
    /// halves' boundary faces swap back and forth; at least one grid must cycle.
    #[test]
    fn a_two_cycle_ends_where_the_rounds_would() {
        let mut cycled = 0;
        for trial in 0..40u64 {
            let (mut m, topo) = crate::approx::testing::grid(12);
            // Deterministic noise in z, one stream per trial.
            let mut rng = crate::linalg::rng::SplitMix(trial);
            for p in &mut m.positions {
                p[2] = 0.4 * rng.symmetric();
            }
            let (normals, areas) = super::super::geom::face_normals_areas(&m.positions, &m.faces);
            let start: Vec<u32> = (0..m.faces.len())
                .map(|f| u32::from(f % 22 >= 11))
                .collect();
            let mut at_once = start.clone();
            relax(&topo, &normals, &areas, &mut at_once, 10);
            let mut one_by_one = start.clone();
            let mut seen = vec![one_by_one.clone()];
            for _ in 0..10 {
                if relax(&topo, &normals, &areas, &mut one_by_one, 1) == 0 {
                    break;
                }
                seen.push(one_by_one.clone());
            }
            if seen.windows(3).any(|w| w[0] == w[2]) {
                cycled += 1;
            }
            assert_eq!(at_once, one_by_one, "trial {trial}");
        }
        assert!(cycled > 0, "no grid cycled: the shortcut was not exercised");
    }

    #[test]
    fn relax_keeps_a_settled_partition() {
        let n = 6;
        let (_, topo, normals, areas) = roof(n);
        let mut labels: Vec<u32> = (0..2 * n).map(|f| u32::from(f >= n)).collect();
        let before = labels.clone();
        assert_eq!(relax(&topo, &normals, &areas, &mut labels, 20), 0);
        assert_eq!(labels, before);
    }

    #[test]
    fn split_cuts_a_roof_region_at_its_ridge() {
        let n = 8;
        let (_, topo, normals, areas) = roof(n);
        let mut labels = vec![0u32; 2 * n];
        assert!(split_region(&topo, &normals, &areas, &mut labels, 0, 1, 10));
        let ridge: Vec<bool> = (0..2 * n).map(|f| f >= n).collect();
        let first_half = labels[0];
        assert!(labels
            .iter()
            .zip(&ridge)
            .all(|(&l, &right)| (l == first_half) != right));
    }

    #[test]
    fn split_refuses_a_flat_region() {
        let n = 4;
        let (mut mesh, _, _, _) = roof(n);
        for p in &mut mesh.positions {
            p[2] = 0.0;
        }
        let (normals, areas) = super::super::geom::face_normals_areas(&mesh.positions, &mesh.faces);
        // A flat strip is still a manifold strip.
        let topo = Topology::build(&mesh, std::path::Path::new("flat")).unwrap();
        let mut labels = vec![0u32; 2 * n];
        assert!(!split_region(
            &topo,
            &normals,
            &areas,
            &mut labels,
            0,
            1,
            10
        ));
        assert!(labels.iter().all(|&l| l == 0));
    }
}
