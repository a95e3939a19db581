//! Stage 3: group faces into at most K connected regions of nearly equal normal.
//!
//! Region growing from seed faces taken in a seeded random order (so runs are reproducible
//! with `--seed`): a neighbour joins when its normal is within θ of the region's area-weighted
//! mean normal. Then the smallest region is merged into the adjacent region with the closest
//! mean normal until at most K remain; a merge whose angle exceeds θ is skipped (as in the
//! paper), and only when every remaining merge is above θ is the single cheapest merge above θ
//! made (the caller asked for at most K regions), after which smallest-first resumes. Finally regions that cannot become a proper polygon
//! (fewer than three neighbouring regions on a closed surface: their whole boundary would lie
//! on one or two plane–plane lines and collapse) are merged away too.

use std::cmp::Reverse;
use std::collections::{BTreeSet, BinaryHeap};

use super::geom::{add, dot, fit_plane, normalize, scale, Plane, SplitMix, V3};
use super::outline::Surface;
use crate::mesh::{Topology, NO_FACE};

/// Parameters of [`cluster_faces`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ClusterOptions {
    /// Largest number of regions wanted.
    pub k: usize,
    /// θ in degrees.
    pub angle_deg: f64,
    pub seed: u64,
    /// Largest normal cone (degrees, half-angle about the region's mean normal) a merge may
    /// create; merges that would exceed it are made only when no other merge is left. A region
    /// whose faces turn by more than this cannot be flattened onto one plane without folding.
    pub max_cone_deg: f64,
}

/// A partition of the faces.
#[derive(Clone, Debug, PartialEq)]
pub struct Clustering {
    /// Region of each face, 0..count.
    pub face_cluster: Vec<u32>,
    pub count: usize,
    /// Regions after region growing, before merging.
    pub grown: usize,
    /// Largest merge angle used (degrees; larger than θ when merges had to be forced).
    pub final_angle_deg: f64,
}

/// Region growing then merging; `normals` unit per face, `areas` per face.
pub fn cluster_faces(
    topo: &Topology,
    normals: &[V3],
    areas: &[f64],
    opts: &ClusterOptions,
) -> Clustering {
    let nf = normals.len();
    let mut order: Vec<usize> = (0..nf).collect();
    let mut rng = SplitMix(opts.seed);
    for i in (1..nf).rev() {
        let j = rng.below(i + 1);
        order.swap(i, j);
    }
    let cos_t = opts.angle_deg.to_radians().cos();
    let cos_cone = opts.max_cone_deg.to_radians().cos();
    let mut label = vec![u32::MAX; nf];
    let mut sums: Vec<V3> = Vec::new();
    let mut area: Vec<f64> = Vec::new();
    let mut queue = std::collections::VecDeque::new();
    for &s in &order {
        if label[s] != u32::MAX {
            continue;
        }
        let c = sums.len() as u32;
        label[s] = c;
        let mut sum = scale(normals[s], areas[s]);
        let mut a = areas[s];
        queue.push_back(s);
        while let Some(f) = queue.pop_front() {
            for g in super::lloyd::neighbors(topo, f) {
                if label[g] != u32::MAX {
                    continue;
                }
                let mean = normalize(sum).unwrap_or(normals[s]);
                // Anchored at the seed too: the mean drifts as the region grows, and without an
                // anchor a region can creep around a cylinder until it holds opposite normals.
                if dot(mean, normals[g]) >= cos_t && dot(normals[s], normals[g]) >= cos_cone {
                    label[g] = c;
                    sum = add(sum, scale(normals[g], areas[g]));
                    a += areas[g];
                    queue.push_back(g);
                }
            }
        }
        sums.push(sum);
        area.push(a);
    }
    let grown = sums.len();
    // Half-angle of each grown region's normal cone about its mean normal (radians).
    let mut cone = vec![0.0f64; grown];
    for f in 0..nf {
        let c = label[f] as usize;
        let mean = normalize(sums[c]).unwrap_or(normals[f]);
        cone[c] = cone[c].max(angle_between(mean, normals[f]));
    }
    let max_cone = opts.max_cone_deg.to_radians();
    let total_area: f64 = area.iter().sum();

    let (mut adj, mut open) = region_adjacency(topo, &label, grown);
    let mut parent: Vec<u32> = (0..grown as u32).collect();
    let mut alive = vec![true; grown];
    let mut n_alive = grown;
    let mut angle = opts.angle_deg;
    let key = |a: f64| a.to_bits();
    let mut merge = |c: usize,
                     into: usize,
                     adj: &mut Vec<BTreeSet<u32>>,
                     sums: &mut Vec<V3>,
                     area: &mut Vec<f64>,
                     alive: &mut Vec<bool>,
                     open: &mut Vec<bool>,
                     cone: &mut Vec<f64>| {
        cone[into] = merged_cone(sums[c], cone[c], sums[into], cone[into]);
        parent[c] = into as u32;
        alive[c] = false;
        sums[into] = add(sums[into], sums[c]);
        area[into] += area[c];
        open[into] |= open[c];
        let nb = std::mem::take(&mut adj[c]);
        for &m in &nb {
            adj[m as usize].remove(&(c as u32));
            if m as usize != into {
                adj[m as usize].insert(into as u32);
                adj[into].insert(m);
            }
        }
        adj[into].remove(&(c as u32));
        adj[into].remove(&(into as u32));
    };
    let closest = |c: usize,
                   adj: &Vec<BTreeSet<u32>>,
                   sums: &Vec<V3>,
                   cone: Option<&Vec<f64>>|
     -> Option<(usize, f64)> {
        let nc = normalize(sums[c]).unwrap_or([0.0; 3]);
        adj[c]
            .iter()
            .filter(|&&m| {
                cone.is_none_or(|k| {
                    merged_cone(sums[c], k[c], sums[m as usize], k[m as usize]) <= max_cone
                })
            })
            .map(|&m| {
                let nm = normalize(sums[m as usize]).unwrap_or([0.0; 3]);
                (m as usize, dot(nc, nm))
            })
            .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
    };
    // Each region's `closest` neighbour within the cone limit, and its cheapest merge above θ
    // (cost, neighbour, cosine; the first of least cost in its neighbour order), kept until a
    // merge changes the region or a neighbour (then `None`): both read only the region's and
    // its neighbours' sums, cones, areas and neighbour sets, which a merge changes for the
    // merged region and the regions around it alone. Each merge above θ would otherwise
    // recompute them for every region.
    type Closest = Option<(usize, f64)>;
    type Cheapest = Option<(f64, usize, f64)>;
    let mut near: Vec<Option<Closest>> = vec![None; grown];
    let mut cheap: Vec<Option<Cheapest>> = vec![None; grown];
    let changed = |into: usize,
                   adj: &[BTreeSet<u32>],
                   near: &mut [Option<Closest>],
                   cheap: &mut [Option<Cheapest>]| {
        for c in std::iter::once(into).chain(adj[into].iter().map(|&m| m as usize)) {
            near[c] = None;
            cheap[c] = None;
        }
    };
    while n_alive > opts.k.max(1) {
        let cos_a = angle.to_radians().cos();
        let mut heap: BinaryHeap<Reverse<(u64, usize)>> = (0..grown)
            .filter(|&c| alive[c])
            .map(|c| Reverse((key(area[c]), c)))
            .collect();
        let mut merged_any = false;
        while n_alive > opts.k.max(1) {
            let Some(Reverse((k, c))) = heap.pop() else {
                break;
            };
            if !alive[c] || k != key(area[c]) {
                continue;
            }
            let found = *near[c].get_or_insert_with(|| closest(c, &adj, &sums, Some(&cone)));
            let Some((m, cos)) = found else {
                continue; // isolated, or every merge would widen the cone too much
            };
            if cos < cos_a {
                continue; // above θ: skipped, as in the paper
            }
            merge(
                c, m, &mut adj, &mut sums, &mut area, &mut alive, &mut open, &mut cone,
            );
            changed(m, &adj, &mut near, &mut cheap);
            n_alive -= 1;
            merged_any = true;
            heap.push(Reverse((key(area[m]), m)));
            for &nb in &adj[m] {
                heap.push(Reverse((key(area[nb as usize]), nb as usize)));
            }
        }
        if n_alive > opts.k.max(1) && !merged_any {
            // Every merge left is above θ: do the single cheapest one, cost = (1 − cos) × the
            // smaller area (the normal deviation it introduces, weighted by how much surface
            // must turn), then return to smallest-first under θ. Relaxing θ for all merges at
            // once instead lets tiny regions swallow steep neighbours.
            let mut best: Option<(f64, usize, usize, f64)> = None;
            for c in (0..grown).filter(|&c| alive[c]) {
                let of_c = *cheap[c].get_or_insert_with(|| {
                    let nc = normalize(sums[c]).unwrap_or([0.0; 3]);
                    let mut first: Cheapest = None;
                    for &m in &adj[c] {
                        let m = m as usize;
                        let cos = dot(nc, normalize(sums[m]).unwrap_or([0.0; 3]));
                        let wide = merged_cone(sums[c], cone[c], sums[m], cone[m]) > max_cone;
                        // Any merge within the limit beats every wider one: add a constant
                        // above every possible cost (a cost is at most 2 × the whole area).
                        let cost = (1.0 - cos) * area[c].min(area[m])
                            + if wide { 4.0 * total_area } else { 0.0 };
                        if first.is_none_or(|b| cost < b.0) {
                            first = Some((cost, m, cos));
                        }
                    }
                    first
                });
                if let Some((cost, m, cos)) = of_c {
                    if best.is_none_or(|b| cost < b.0) {
                        best = Some((cost, c, m, cos));
                    }
                }
            }
            let Some((_, c, m, cos)) = best else {
                break; // only separate components remain
            };
            let (small, big) = if area[c] <= area[m] { (c, m) } else { (m, c) };
            merge(
                small, big, &mut adj, &mut sums, &mut area, &mut alive, &mut open, &mut cone,
            );
            changed(big, &adj, &mut near, &mut cheap);
            n_alive -= 1;
            angle = angle.max(cos.clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    // Regions that would collapse: closed regions with fewer than three neighbours.
    loop {
        let bad =
            (0..grown).find(|&c| alive[c] && !open[c] && adj[c].len() < 3 && !adj[c].is_empty());
        let Some(c) = bad else { break };
        let Some((m, _)) = closest(c, &adj, &sums, None) else {
            break;
        };
        merge(
            c, m, &mut adj, &mut sums, &mut area, &mut alive, &mut open, &mut cone,
        );
    }
    let find = |mut c: usize| {
        while parent[c] as usize != c {
            c = parent[c] as usize;
        }
        c
    };
    let mut remap = vec![u32::MAX; grown];
    let mut count = 0u32;
    let face_cluster = label
        .iter()
        .map(|&l| {
            let r = find(l as usize);
            if remap[r] == u32::MAX {
                remap[r] = count;
                count += 1;
            }
            remap[r]
        })
        .collect();
    Clustering {
        face_cluster,
        count: count as usize,
        grown,
        final_angle_deg: angle,
    }
}

/// Area-weighted normal sum of each region of `labels` (regions `0..=max label`; the mean
/// normal is its direction).
pub fn region_normal_sums(labels: &[u32], normals: &[V3], areas: &[f64]) -> Vec<V3> {
    let n = labels.iter().map(|&c| c as usize + 1).max().unwrap_or(0);
    let mut sums = vec![[0.0; 3]; n];
    for (f, &c) in labels.iter().enumerate() {
        sums[c as usize] = add(sums[c as usize], scale(normals[f], areas[f]));
    }
    sums
}

/// Angle (radians) between unit vectors.
fn angle_between(a: V3, b: V3) -> f64 {
    dot(a, b).clamp(-1.0, 1.0).acos()
}

/// Upper bound of the normal-cone half-angle of the union of two regions with area-weighted
/// normal sums `sa`, `sb` and cones `ca`, `cb`: every member normal is within its old cone of
/// its old mean, which is a known angle from the new mean.
fn merged_cone(sa: V3, ca: f64, sb: V3, cb: f64) -> f64 {
    let (Some(na), Some(nb), Some(n)) = (normalize(sa), normalize(sb), normalize(add(sa, sb)))
    else {
        return std::f64::consts::PI;
    };
    (ca + angle_between(n, na)).max(cb + angle_between(n, nb))
}

/// Sorted distinct regions around each vertex.
pub fn vertex_clusters(topo: &Topology, face_cluster: &[u32]) -> Vec<Vec<u32>> {
    let at = |v: u32| {
        topo.vertex_faces(v)
            .iter()
            .map(|&f| face_cluster[f as usize])
    };
    (0..topo.n_vertices as u32)
        .map(|v| {
            let mut c: Vec<u32> = at(v).collect();
            c.sort_unstable();
            c.dedup();
            c
        })
        .collect()
}

/// Reassigns faces whose three vertices all lie in another region too (a one-face spike into
/// it, touching it along an edge): the spike's outline turns back on itself within one face.
/// Written for the earlier design (faces pressed onto planes); measured in this one, the
/// realisation does worse without it (BENCHMARKS, planar approximation round 28). Returns how
/// many faces were moved (bounded passes).
pub fn fix_collapsing_faces(s: &Surface<'_>, face_cluster: &mut [u32]) -> usize {
    let (topo, faces) = (s.topo, s.faces);
    until_settled(8, || {
        let vc = vertex_clusters(topo, face_cluster);
        let mut moved = 0;
        for (f, face) in faces.iter().enumerate() {
            let own = face_cluster[f];
            let common = vc[face[0] as usize].iter().copied().find(|&c| {
                c != own
                    && vc[face[1] as usize].binary_search(&c).is_ok()
                    && vc[face[2] as usize].binary_search(&c).is_ok()
            });
            if let Some(c) = common {
                // Only move when the face touches c along an edge, so regions stay connected.
                let touches = super::lloyd::neighbors(topo, f).any(|g| face_cluster[g] == c);
                if touches {
                    face_cluster[f] = c;
                    moved += 1;
                }
            }
        }
        moved
    })
}

/// Runs `pass` (which returns how many changes it made) until a pass makes none, at most
/// `max_passes` times; the changes made.
fn until_settled(max_passes: usize, mut pass: impl FnMut() -> usize) -> usize {
    let mut changes = 0;
    for _ in 0..max_passes {
        match pass() {
            0 => break,
            c => changes += c,
        }
    }
    changes
}

/// Merges each listed region into the adjacent region with the closest mean normal (`sums`
/// are area-weighted normal sums per region). A region that receives a merge in this call is
/// not merged itself, so chains of merges cannot cycle. `adj`: each region's neighbours
/// ([`region_adjacency`]).
fn merge_regions(face_cluster: &mut [u32], regions: &[u32], sums: &[V3], adj: &[BTreeSet<u32>]) {
    let n = sums.len();
    let mut target: Vec<u32> = (0..n as u32).collect();
    let mut receives = vec![false; n];
    let mut merged = vec![false; n];
    for &c in regions {
        let c = c as usize;
        if receives[c] {
            continue;
        }
        let nc = normalize(sums[c]).unwrap_or([0.0; 3]);
        let best = adj[c]
            .iter()
            .filter(|&&m| !merged[m as usize])
            .max_by(|&&a, &&b| {
                let da = dot(nc, normalize(sums[a as usize]).unwrap_or([0.0; 3]));
                let db = dot(nc, normalize(sums[b as usize]).unwrap_or([0.0; 3]));
                da.total_cmp(&db).then(b.cmp(&a))
            });
        if let Some(&m) = best {
            target[c] = m;
            merged[c] = true;
            receives[m as usize] = true;
        }
    }
    for l in face_cluster.iter_mut() {
        *l = target[*l as usize];
    }
}

/// Distance from `x` to the point nearest to it that lies on all `planes` (least squares
/// when they have no common point; `None` when they do not pin a point down at all).
fn corner_reach(x: V3, planes: &[Plane]) -> Option<f64> {
    let (mut a, mut b) = ([[0.0; 3]; 3], [0.0; 3]);
    for p in planes {
        let r = p.signed_distance(x);
        for i in 0..3 {
            b[i] -= p.n[i] * r;
            for j in 0..3 {
                a[i][j] += p.n[i] * p.n[j];
            }
        }
    }
    // A nearly singular system (its smallest eigenvalue) means a corner far away or at infinity.
    let (vals, vecs) = crate::linalg::small::sym_eigen::<3>(&a);
    if vals[2] < 1e-9 {
        return None;
    }
    // The step solving A s = b, in A's orthonormal eigenvectors: its length.
    let along = |j: usize| dot([vecs[0][j], vecs[1][j], vecs[2][j]], b) / vals[j];
    Some((0..3).map(|j| along(j).powi(2)).sum::<f64>().sqrt())
}

/// Where three or more regions meet at a vertex, the vertex must go to their planes' common
/// point; when that point is far from the vertex (nearly dependent normals, e.g. three strips
/// of a cylinder meeting in a T) the surface folds to reach it. Such corners cannot be
/// realised, so the two edge-adjacent regions there with the closest normals are merged, until
/// every corner's common point is within max(`max_reach`, `amplification` × the vertex's
/// largest distance to those planes) of the vertex (planes fitted to the regions' vertices,
/// chosen by the surface's rule), or 64 passes. Returns the number of merges.
pub fn merge_unreachable_corners(
    s: &Surface<'_>,
    face_cluster: &mut [u32],
    max_reach: f64,
    amplification: f64,
) -> usize {
    let (topo, faces, pos, rule) = (s.topo, s.faces, s.pos, s.rule);
    until_settled(64, || {
        let sums = region_normal_sums(face_cluster, &s.normals, &s.areas);
        let n = sums.len();
        let mean: Vec<V3> = sums
            .iter()
            .map(|&s| normalize(s).unwrap_or([0.0; 3]))
            .collect();
        let vc = vertex_clusters(topo, face_cluster);
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (v, cs) in vc.iter().enumerate() {
            for &c in cs {
                members[c as usize].push(v);
            }
        }
        let planes: Vec<Option<Plane>> = (0..n)
            .map(|c| fit_plane(members[c].iter().map(|&v| (pos[v], 1.0)), mean[c], rule))
            .collect();
        let mut target: Vec<u32> = (0..n as u32).collect();
        let mut touched = vec![false; n];
        let mut merges = 0;
        for (v, cs) in vc.iter().enumerate() {
            if cs.len() < 3 || cs.iter().any(|&c| touched[c as usize]) {
                continue;
            }
            let ps: Vec<Plane> = cs.iter().filter_map(|&c| planes[c as usize]).collect();
            // Far in absolute terms and far relative to how far the planes already are from
            // the vertex (the amplification of a nearly dependent triple).
            let resid = ps
                .iter()
                .map(|p| p.signed_distance(pos[v]).abs())
                .fold(0.0, f64::max);
            if corner_reach(pos[v], &ps).is_some_and(|d| d <= max_reach.max(amplification * resid))
            {
                continue;
            }
            // Edge-adjacent region pairs around v.
            let mut best: Option<(f64, u32, u32)> = None;
            for &f in topo.vertex_faces(v as u32) {
                for g in super::lloyd::neighbors(topo, f as usize) {
                    let (a, b) = (face_cluster[f as usize], face_cluster[g]);
                    if a == b || !faces[g].contains(&(v as u32)) {
                        continue;
                    }
                    let d = dot(mean[a as usize], mean[b as usize]);
                    if best.is_none_or(|x| d > x.0) {
                        best = Some((d, a.min(b), a.max(b)));
                    }
                }
            }
            if let Some((_, a, b)) = best {
                target[b as usize] = a;
                for &c in cs {
                    touched[c as usize] = true;
                }
                merges += 1;
            }
        }
        if merges > 0 {
            for l in face_cluster.iter_mut() {
                *l = target[*l as usize];
            }
        }
        merges
    })
}

/// Each region's neighbours (regions across an edge) and whether it touches the mesh's
/// border, for `labels` numbered `0..n`.
fn region_adjacency(topo: &Topology, labels: &[u32], n: usize) -> (Vec<BTreeSet<u32>>, Vec<bool>) {
    let mut adj: Vec<BTreeSet<u32>> = vec![BTreeSet::new(); n];
    let mut open = vec![false; n];
    for ef in &topo.edge_faces {
        let a = labels[ef[0] as usize];
        if ef[1] == NO_FACE {
            open[a as usize] = true;
            continue;
        }
        let b = labels[ef[1] as usize];
        if a != b {
            adj[a as usize].insert(b);
            adj[b as usize].insert(a);
        }
    }
    (adj, open)
}

/// Merges closed regions with fewer than three neighbouring regions (their whole boundary would
/// lie on one or two plane–plane lines and collapse) into their closest neighbour, at face
/// level, until none is left; needed again after merges made by later steps. Returns the
/// number of merges.
pub fn merge_collapsing_regions(s: &Surface<'_>, face_cluster: &mut [u32]) -> usize {
    until_settled(64, || {
        let sums = region_normal_sums(face_cluster, &s.normals, &s.areas);
        let n = sums.len();
        let (adj, open) = region_adjacency(s.topo, face_cluster, n);
        let bad: Vec<u32> = (0..n)
            .filter(|&c| !open[c] && !adj[c].is_empty() && adj[c].len() < 3)
            .map(|c| c as u32)
            .collect();
        if !bad.is_empty() {
            merge_regions(face_cluster, &bad, &sums, &adj);
        }
        bad.len()
    })
}

/// Majority filter on region boundaries: a face with two of its three edge-neighbours in one
/// other region joins that region. Region growing leaves jagged, one-face-wide spikes along
/// boundaries; every spike face has all three corners on region boundaries, i.e. on plane–plane
/// lines, and folds or collapses once the regions are made planar. Returns faces moved.
pub fn smooth_boundaries(topo: &Topology, face_cluster: &mut [u32], max_passes: usize) -> usize {
    until_settled(max_passes, || {
        let mut moved = 0;
        for f in 0..face_cluster.len() {
            let own = face_cluster[f];
            let nb: Vec<u32> = super::lloyd::neighbors(topo, f)
                .map(|g| face_cluster[g])
                .collect();
            let other = nb
                .iter()
                .copied()
                .find(|&c| c != own && nb.iter().filter(|&&d| d == c).count() >= 2);
            if let Some(c) = other {
                face_cluster[f] = c;
                moved += 1;
            }
        }
        moved
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merged_cone_of_two_flat_regions_at_right_angles_is_half_their_angle() {
        let c = merged_cone([2.0, 0.0, 0.0], 0.0, [0.0, 2.0, 0.0], 0.0);
        assert!((c - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        // A region's own cone adds on top; the larger region pulls the mean its way.
        let c = merged_cone([3.0, 0.0, 0.0], 0.1, [0.0, 1.0, 0.0], 0.0);
        let to_small = (1.0f64).atan2(3.0);
        let expect = (0.1 + to_small).max(std::f64::consts::FRAC_PI_2 - to_small);
        assert!((c - expect).abs() < 1e-12);
    }

    #[test]
    fn corner_reach_is_the_distance_to_the_common_point_and_none_for_parallel_planes() {
        let plane = |n: V3, d: f64| Plane { n, d };
        let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        // x = 1, y = 2, z = 2 meet at (1, 2, 2), 3 from the origin.
        let three = [plane(x, -1.0), plane(y, -2.0), plane(z, -2.0)];
        let d = corner_reach([0.0; 3], &three).unwrap();
        assert!((d - 3.0).abs() < 1e-12, "{d}");
        // Two planes meet in a line: no point is pinned down.
        assert!(corner_reach([0.0; 3], &three[..2]).is_none());
    }
}
