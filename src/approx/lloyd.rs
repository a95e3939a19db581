//! Lloyd relaxation of a face partition under the L2,1 (normal) metric, or the L2 (distance to
//! the plane) one, as in Variational Shape Approximation (Cohen-Steiner, Alliez & Desbrun 2004).
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
//!
//! The round is written once over a [`Metric`]: VSA's L2,1 ([`Normals`]) for the clustering
//! and the realisation's splits, and its L2 ([`Planes`], each face to the region whose
//! least-squares plane is nearest) for the two-plane split of a region whose normal split
//! cannot be realised ([`halve`]).

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::geom::{add, normalize, scale, sub, Plane, PlaneRule, V3};
use super::outline::Moments;
use crate::mesh::{Topology, NO_FACE};

/// Edge-neighbour faces of `f`.
pub(super) fn neighbors(topo: &Topology, f: usize) -> impl Iterator<Item = usize> + '_ {
    topo.face_faces[f]
        .iter()
        .filter_map(|&g| (g != NO_FACE).then_some(g as usize))
}

/// What a Lloyd round fits to each region (its proxy) and how far a face is from a proxy.
pub trait Metric {
    type Proxy: Clone;
    /// How many directions of a region's spread a budget halving tries, in turn (see
    /// `outline::spend_budget`).
    const AXES: usize;
    /// The proxies of regions `0..count` fitted to the faces `members` (each with its label).
    fn proxies(&self, labels: &[u32], members: &[usize], count: usize) -> Vec<Self::Proxy>;
    /// The error of face `f` against proxy `p` (non-negative).
    fn err(&self, f: usize, p: &Self::Proxy) -> f64;
    /// The point of face `f` a region is halved by ([`halve`]: across a direction of
    /// their spread) and its weight.
    fn key(&self, f: usize) -> V3;
    fn weight(&self, f: usize) -> f64;
    /// Whether a region whose weighted keys sum to `sum` can be halved.
    fn halvable(&self, _sum: V3) -> bool {
        true
    }
}

/// VSA's L2,1 metric: the proxy is the region's area-weighted mean normal, a face's error
/// its area times the squared difference of its normal from it.
pub struct Normals<'a> {
    pub normals: &'a [V3],
    pub areas: &'a [f64],
}

impl Metric for Normals<'_> {
    type Proxy = V3;
    /// The main direction only: the normals of a region turn most along it (a curved
    /// region's cut); the second was not measured for them.
    const AXES: usize = 1;
    fn proxies(&self, labels: &[u32], members: &[usize], count: usize) -> Vec<V3> {
        let mut sums = vec![[0.0; 3]; count];
        for &f in members {
            let c = labels[f] as usize;
            sums[c] = add(sums[c], scale(self.normals[f], self.areas[f]));
        }
        sums.iter()
            .map(|&s| normalize(s).unwrap_or([0.0; 3]))
            .collect()
    }
    fn err(&self, f: usize, p: &V3) -> f64 {
        let d = sub(self.normals[f], *p);
        self.areas[f] * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    }
    fn key(&self, f: usize) -> V3 {
        self.normals[f]
    }
    fn weight(&self, f: usize) -> f64 {
        self.areas[f]
    }
    /// Normals that cancel have no mean direction to spread about.
    fn halvable(&self, sum: V3) -> bool {
        normalize(sum).is_some()
    }
}

/// VSA's L2 metric: the proxy is the region's least-squares plane, a face's error the
/// integral of the squared distance of its points to it. The one the polygons are built on:
/// a boundary where two regions' planes are equally near a face lies along the line where
/// the planes meet, and a junction where three are lies near their common point.
pub struct Planes<'a> {
    pub moments: &'a [Moments],
    pub rule: PlaneRule,
}

impl Metric for Planes<'_> {
    type Proxy = Option<Plane>;
    /// Both directions of the centroids' spread: a twisted region (its normal turning about
    /// the direction it is long in) halved across that direction gives two planes that meet
    /// along a line running across the cut, which their polygons cannot share; halved along
    /// it, they may (BENCHMARKS, planar approximation round 18).
    const AXES: usize = 2;
    fn proxies(&self, labels: &[u32], members: &[usize], count: usize) -> Vec<Option<Plane>> {
        let mut sums = vec![Moments::default(); count];
        for &f in members {
            let c = labels[f] as usize;
            sums[c] = sums[c].add(&self.moments[f]);
        }
        sums.iter()
            .map(|m| m.fit(self.rule).map(|(p, _)| p))
            .collect()
    }
    fn err(&self, f: usize, p: &Option<Plane>) -> f64 {
        p.map_or(f64::INFINITY, |p| self.moments[f].sq_distance(&p).max(0.0))
    }
    fn key(&self, f: usize) -> V3 {
        self.moments[f].centroid()
    }
    fn weight(&self, f: usize) -> f64 {
        self.moments[f].area()
    }
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
    let all: Vec<usize> = (0..labels.len()).collect();
    relax_subset(topo, &Normals { normals, areas }, labels, &all, rounds)
}

/// [`relax`] where only the faces `members` (ascending) may change region; the regions
/// holding them compete for them and the rest of the partition is left as it is. Each
/// region's proxy is taken from its members (all faces for [`relax`]; for a split, the two
/// halves), and the round works on arrays indexed by member, so a round costs the members,
/// not the mesh — a split of a small region is as cheap as the region.
pub fn relax_subset<M: Metric>(
    topo: &Topology,
    metric: &M,
    labels: &mut [u32],
    members: &[usize],
    rounds: usize,
) -> usize {
    debug_assert!(
        members.windows(2).all(|w| w[0] < w[1]),
        "members must ascend"
    );
    let count = members
        .iter()
        .map(|&f| labels[f] as usize + 1)
        .max()
        .unwrap_or(0);
    // Members' edge neighbours among the members, as member indices (u32::MAX: none).
    let local = |g: usize| members.binary_search(&g).map_or(u32::MAX, |i| i as u32);
    let adjacent: Vec<[u32; 3]> = members
        .iter()
        .map(|&f| {
            let mut a = [u32::MAX; 3];
            for (slot, g) in a.iter_mut().zip(neighbors(topo, f)) {
                *slot = local(g);
            }
            a
        })
        .collect();
    // The label each member gets this round (u32::MAX: not reached yet).
    let mut next: Vec<u32> = vec![u32::MAX; members.len()];
    // Regions each member has been offered to this round (a face has three neighbours).
    let mut offered: Vec<[u32; 3]> = vec![[u32::MAX; 3]; members.len()];
    // (error bits, member, region) packed in one u128, which orders as the triple does: an
    // entry of 16 bytes compared in one step (the flood is the heap's pushes and pops);
    // members order as the face indices do (members ascend).
    let mut heap: BinaryHeap<Reverse<u128>> = BinaryHeap::new();
    let mut changed_rounds = 0;
    // The members' labels one and two rounds back: a round is a function of the labels, so
    // labels equal to those two rounds back repeat with period two from then on.
    let snapshot = |labels: &[u32]| members.iter().map(|&f| labels[f]).collect::<Vec<u32>>();
    let mut back1 = snapshot(labels);
    let mut back2: Vec<u32> = Vec::new();
    for round in 0..rounds {
        let proxy = metric.proxies(labels, members, count);
        let mut seed: Vec<Option<(f64, usize)>> = vec![None; count];
        for (i, &f) in members.iter().enumerate() {
            let c = labels[f];
            let e = metric.err(f, &proxy[c as usize]);
            let s = &mut seed[c as usize];
            if s.is_none_or(|(be, _)| e < be) {
                *s = Some((e, i));
            }
        }
        next.fill(u32::MAX);
        offered.fill([u32::MAX; 3]);
        // Keys are non-negative floats, whose bit patterns order like the values. A face is
        // offered to a region once: its key for that region is fixed within the round, so a
        // second entry (from another neighbour in the same region) would pop right after the
        // first and be skipped.
        heap.clear();
        let mut offer = |heap: &mut BinaryHeap<Reverse<u128>>, i: u32, c: u32| {
            let o = &mut offered[i as usize];
            if o.contains(&c) {
                return;
            }
            if let Some(slot) = o.iter_mut().find(|x| **x == u32::MAX) {
                *slot = c;
            }
            let e = metric.err(members[i as usize], &proxy[c as usize]);
            let key = (u128::from(e.to_bits()) << 64) | (u128::from(i) << 32) | u128::from(c);
            heap.push(Reverse(key));
        };
        for (c, s) in seed.iter().enumerate() {
            if let Some((_, i)) = *s {
                next[i] = c as u32;
                for &j in &adjacent[i] {
                    if j != u32::MAX {
                        offer(&mut heap, j, c as u32);
                    }
                }
            }
        }
        while let Some(Reverse(key)) = heap.pop() {
            let (i, c) = ((key >> 32) as u32, key as u32);
            let i = i as usize;
            if next[i] != u32::MAX {
                continue;
            }
            next[i] = c;
            for &j in &adjacent[i] {
                if j != u32::MAX && next[j as usize] == u32::MAX {
                    offer(&mut heap, j, c);
                }
            }
        }
        // Every face is reached: each connected component holds at least one region, hence one
        // seed. Faces of a component without a seed (not possible for a valid partition) keep
        // their label.
        let mut changed = false;
        for (i, &f) in members.iter().enumerate() {
            if next[i] != u32::MAX && next[i] != labels[f] {
                labels[f] = next[i];
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

/// Splits region `c` in two: halved across the `axis`-th direction (0 = the main one, 1 = the
/// next) of the weighted spread of its faces' [`Metric::key`]s — faces on the positive side
/// (about the weighted mean) get label `new_label` — then the two halves relaxed against each
/// other under `metric` for at most [`HALVING_ROUNDS`] (the rest of the partition is left as
/// it is). False when the region has no spread along that direction or a half ends empty.
///
/// With [`Normals`] (the realisation's split): a region that folds when flattened usually
/// turns too much in one direction (a half-cylinder), and its two halves each turn half as
/// much. About the mean normal, not the unit one: a region that turns far (a "C") has all
/// its deviations from the unit mean on one side. With [`Planes`] (keys the face centroids):
/// each face ends in the half whose least-squares plane is nearer — a two-plane fit of the
/// region, whose cut lies where the two planes meet (the line their polygons share), which
/// may be realisable where the normals' cut is not.
pub fn halve<M: Metric>(
    topo: &Topology,
    metric: &M,
    labels: &mut [u32],
    c: u32,
    new_label: u32,
    axis: usize,
) -> bool {
    let members: Vec<usize> = (0..labels.len()).filter(|&f| labels[f] == c).collect();
    halve_members(topo, metric, labels, &members, c, new_label, axis)
}

/// Lloyd rounds of a halving's two halves: the flood from a straight cut between two
/// proxies settles within a few rounds (and a two-cycle ends at once, [`relax_subset`]); the
/// cap bounds the cost of one that does not.
pub const HALVING_ROUNDS: usize = 10;

/// [`halve`] of region `c` whose faces, ascending, are `members` (a caller that has them).
pub fn halve_members<M: Metric>(
    topo: &Topology,
    metric: &M,
    labels: &mut [u32],
    members: &[usize],
    c: u32,
    new_label: u32,
    axis: usize,
) -> bool {
    let (key, area) = (|f| metric.key(f), |f| metric.weight(f));
    let sum = members
        .iter()
        .fold([0.0; 3], |s, &f| add(s, scale(key(f), area(f))));
    let total: f64 = members.iter().map(|&f| area(f)).sum();
    if total <= 0.0 || !metric.halvable(sum) {
        return false;
    }
    let mean = scale(sum, 1.0 / total);
    let mut cov = [[0.0; 3]; 3];
    for &f in members {
        let d = sub(key(f), mean);
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += area(f) * d[i] * d[j];
            }
        }
    }
    let (vals, vecs) = crate::linalg::small::sym_eigen::<3>(&cov);
    // Largest eigenvalue's vector (sym_eigen's order is not assumed).
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| vals[b].total_cmp(&vals[a]));
    let Some(&k) = order.get(axis) else {
        return false;
    };
    if vals[k] <= 0.0 || !vals[k].is_finite() {
        return false;
    }
    let dir = [vecs[0][k], vecs[1][k], vecs[2][k]];
    let mut n_new = 0;
    for &f in members {
        let d = sub(key(f), mean);
        if d[0] * dir[0] + d[1] * dir[1] + d[2] * dir[2] > 0.0 {
            labels[f] = new_label;
            n_new += 1;
        }
    }
    if n_new == 0 || n_new == members.len() {
        for &f in members {
            labels[f] = c;
        }
        return false;
    }
    relax_subset(topo, metric, labels, members, HALVING_ROUNDS);
    let kept = members.iter().filter(|&&f| labels[f] == c).count();
    kept > 0 && kept < members.len()
}

/// VSA's incremental insertion: while fewer than `k` regions, the region of largest error
/// under `metric` is halved ([`halve`] across its main direction) where
/// `worth(labels, region, new)` says the halving adds something; a region that cannot be
/// halved so is passed over. Returns the region count reached.
///
/// Why: the corner merges leave most partitions below K (a region swallowed where its planes
/// could not meet), and a region the budget could still split is error left on the table.
pub fn fill<M: Metric>(
    topo: &Topology,
    metric: &M,
    labels: &mut [u32],
    mut n: usize,
    k: usize,
    worth: impl Fn(&[u32], u32, u32) -> bool,
) -> usize {
    let all: Vec<usize> = (0..labels.len()).collect();
    let mut stuck = vec![false; n];
    while n < k {
        let proxy = metric.proxies(labels, &all, n);
        let mut err = vec![0.0; n];
        for &f in &all {
            let c = labels[f] as usize;
            err[c] += metric.err(f, &proxy[c]);
        }
        let Some(worst) = (0..n)
            .filter(|&r| !stuck[r] && err[r] > 0.0)
            .max_by(|&a, &b| err[a].total_cmp(&err[b]))
        else {
            break;
        };
        let (c, new) = (worst as u32, n as u32);
        if halve(topo, metric, labels, c, new, 0) && worth(labels, c, new) {
            n += 1;
            stuck.push(false);
        } else {
            for l in labels.iter_mut().filter(|l| **l == new) {
                *l = c;
            }
            stuck[worst] = true;
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;

    /// A strip of 2n faces folded into a roof along its middle ([`crate::approx::testing::roof`]),
    /// with its face normals and areas: the left half's normal tilted one way, the right
    /// half's the other.
    fn roof(n: usize) -> (TriMesh, Topology, Vec<V3>, Vec<f64>) {
        let (mesh, topo) = crate::approx::testing::roof(n as u32, n as u32 / 2);
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
        assert!(halve(
            &topo,
            &Normals {
                normals: &normals,
                areas: &areas
            },
            &mut labels,
            0,
            1,
            0
        ));
        let ridge: Vec<bool> = (0..2 * n).map(|f| f >= n).collect();
        let first_half = labels[0];
        assert!(labels
            .iter()
            .zip(&ridge)
            .all(|(&l, &right)| (l == first_half) != right));
    }

    /// A roof whose ridge is a quarter of the way along (strips 0..3 rise, 3..12 fall): the
    /// halving across the centroids' extent cuts in the middle, and the two planes' relaxation
    /// moves the cut to the ridge, where each half lies on one plane exactly.
    #[test]
    fn two_plane_split_moves_the_cut_to_an_off_centre_ridge() {
        let (n, r) = (12usize, 3usize);
        let (mesh, topo) = crate::approx::testing::roof(n as u32, r as u32);
        let moments = Moments::of_faces(&topo, &mesh.positions, &mesh.faces);
        let mut labels = vec![0u32; 2 * n];
        assert!(halve(
            &topo,
            &Planes {
                moments: &moments,
                rule: PlaneRule::LeastSquares,
            },
            &mut labels,
            0,
            1,
            0
        ));
        let rising = labels[0];
        for (f, &l) in labels.iter().enumerate() {
            assert_eq!(l == rising, f < 2 * r, "face {f}: {labels:?}");
        }
    }

    /// One region over a roof, filled to two: the halving cuts at the ridge; where the
    /// halving is not worth a region, the partition is left as it was.
    #[test]
    fn fill_halves_a_roof_at_its_ridge_where_the_halving_is_worth_it() {
        let n = 8;
        let (_, topo, normals, areas) = roof(n);
        let metric = Normals {
            normals: &normals,
            areas: &areas,
        };
        let mut labels = vec![0u32; 2 * n];
        assert_eq!(fill(&topo, &metric, &mut labels, 1, 2, |_, _, _| false), 1);
        assert!(labels.iter().all(|&l| l == 0));
        assert_eq!(fill(&topo, &metric, &mut labels, 1, 2, |_, _, _| true), 2);
        for (f, &l) in labels.iter().enumerate() {
            assert_eq!(l == labels[0], f < n, "face {f}: {labels:?}");
        }
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
        let metric = Normals {
            normals: &normals,
            areas: &areas,
        };
        assert!(!halve(&topo, &metric, &mut labels, 0, 1, 0));
        assert!(labels.iter().all(|&l| l == 0));
    }
}
