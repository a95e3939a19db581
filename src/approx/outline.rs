//! Polygons from a partition and its planes: every corner is where planes meet, so each
//! polygon is planar and neighbouring polygons share their corners exactly (watertight), by
//! construction rather than by pressing the input's vertices onto the planes.
//!
//! Where three regions meet at a vertex of the input, their polygons share one corner: the
//! common point of the three planes. Where `m > 3` regions meet, `m` planes have no common
//! point; the junction is split into `m − 2` corners of three planes each (a fan of the cyclic
//! order of the regions around the vertex, rooted at the region that keeps the corners closest
//! to the vertex), joined by short edges on plane–plane lines, as in a generic plane
//! arrangement. Between two corners, the boundary the regions share in the input becomes one
//! straight edge on the line where their planes meet. On the mesh's border a polygon keeps the
//! border vertices (projected into its plane); where two regions meet on the border, the
//! corner is the point of their line nearest to the border vertex.
//!
//! The construction can fail where the partition cannot be realised by its planes: planes
//! nearly parallel meet far from the surface, a loop of a region has fewer than three
//! corners (a region ringed by one neighbour), a region touches itself at a vertex, or an
//! outline crosses itself in its plane, two junctions put corners on one point, or two
//! polygons cross. [`build`] then names the regions involved ([`Defect`]) and [`realise`]
//! changes the partition (a split, or a merge), never the positions. `FOLDFREE_APPROX_TRACE`
//! set in the environment prints each defect met to stderr.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

// The keys are face and region numbers and partition hashes, looked up on every build, none
// from outside: foldhash, not SipHash.
use foldhash::{HashMap, HashMapExt, HashSet, HashSetExt};

use super::geom::{
    add, bounds, cross, dot, norm, normalize, principal_axis, scale, sub, Plane, PlaneRule, V3,
};
use super::intersect::first_crossing;
use super::polygons::{
    area2, basis, bridge_holes, ear_clip, orient, region_loops, segments_cross, PolygonMesh,
};
use super::trace;
use crate::linalg::small::sym_eigen;
use crate::mesh::{Topology, NO_FACE};

/// The region of nothing, beyond the mesh's border.
const OUTSIDE: u32 = u32::MAX;

/// The entries (i, j), i ≤ j, of a symmetric 3 × 3 matrix, by rows.
const UPPER: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// Area moments of a region's faces: the least-squares plane and its residual without
/// revisiting the faces, and those of two regions merged by adding.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Moments {
    area: f64,
    /// ∫ x dA.
    first: V3,
    /// ∫ x xᵀ dA, its upper triangle by rows (xx, xy, xz, yy, yz, zz): the matrix is
    /// symmetric to the bit (each entry is a sum of products `p_i p_j`, and a product does not
    /// depend on its order), so a sum of moments adds six entries, not nine.
    second: [f64; 6],
    /// Σ area-weighted normals (orients the plane).
    normal: V3,
    /// The input vertices' share of the faces (each vertex one, shared equally by its faces;
    /// set by [`Moments::of_faces`], zero for a lone triangle): what the headline error weighs
    /// them by.
    weight: f64,
}

impl Moments {
    /// Moments of triangle `a b c` (exact integrals over the triangle).
    pub fn triangle(a: V3, b: V3, c: V3) -> Moments {
        let an = scale(cross(sub(b, a), sub(c, a)), 0.5);
        let area = dot(an, an).sqrt();
        let s = add(add(a, b), c);
        let second = UPPER
            .map(|(i, j)| area / 12.0 * (a[i] * a[j] + b[i] * b[j] + c[i] * c[j] + s[i] * s[j]));
        Moments {
            area,
            first: scale(s, area / 3.0),
            second,
            normal: an,
            weight: 0.0,
        }
    }

    /// The moments of each face of `faces` (vertex indices into `pos`), each with its share of
    /// the input vertices (`weight`: each vertex weighs one, shared equally by its faces).
    pub fn of_faces(topo: &Topology, pos: &[V3], faces: &[[u32; 3]]) -> Vec<Moments> {
        faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| pos[i as usize]);
                let weight = f.iter().map(|&v| 1.0 / topo.vertex_faces(v).len() as f64);
                Moments {
                    weight: weight.sum(),
                    ..Moments::triangle(a, b, c)
                }
            })
            .collect()
    }

    /// A squared distance integrated over the faces (`residual`, per unit area) as the
    /// headline error weighs it: per input vertex, the faces' vertices taken as spread evenly
    /// over their area.
    fn per_vertex(&self, residual: f64) -> f64 {
        if self.area > 0.0 {
            residual * self.weight / self.area
        } else {
            0.0
        }
    }

    /// The area of the faces.
    pub fn area(&self) -> f64 {
        self.area
    }

    /// The area-weighted centroid (the origin for no area).
    pub fn centroid(&self) -> V3 {
        if self.area > 0.0 {
            scale(self.first, 1.0 / self.area)
        } else {
            [0.0; 3]
        }
    }

    /// The moments of the faces of `self` that are not those of `o` (a subset of them).
    pub fn sub(&self, o: &Moments) -> Moments {
        let neg = Moments {
            area: -o.area,
            first: scale(o.first, -1.0),
            second: o.second.map(|x| -x),
            normal: scale(o.normal, -1.0),
            weight: -o.weight,
        };
        self.add(&neg)
    }

    /// The integral of the squared distance to `p` over the faces.
    pub fn sq_distance(&self, p: &Plane) -> f64 {
        let mut c = p.d * p.d * self.area + 2.0 * p.d * dot(p.n, self.first);
        let second = self.second_matrix();
        for i in 0..3 {
            for j in 0..3 {
                c += p.n[i] * second[i][j] * p.n[j];
            }
        }
        c
    }

    /// ∫ x xᵀ dA as the full matrix.
    fn second_matrix(&self) -> [[f64; 3]; 3] {
        let [xx, xy, xz, yy, yz, zz] = self.second;
        [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]
    }

    pub fn add(&self, o: &Moments) -> Moments {
        let mut second = self.second;
        for (x, y) in second.iter_mut().zip(&o.second) {
            *x += y;
        }
        Moments {
            area: self.area + o.area,
            first: add(self.first, o.first),
            second,
            normal: add(self.normal, o.normal),
            weight: self.weight + o.weight,
        }
    }

    /// The principal plane of the faces that `rule` picks (under
    /// [`PlaneRule::LeastSquares`] the one minimising the integral of the squared distance over
    /// the faces), oriented along their normals, and that integral.
    pub fn fit(&self, rule: PlaneRule) -> Option<(Plane, f64)> {
        if self.area <= 0.0 {
            return None;
        }
        let c = scale(self.first, 1.0 / self.area);
        let mut cov = self.second_matrix();
        for (i, row) in cov.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x -= self.area * c[i] * c[j];
            }
        }
        let (vals, vecs) = sym_eigen::<3>(&cov);
        // The principal direction the faces face is the normal, its value the residual.
        let j = principal_axis(&vecs, self.normal, rule);
        let mut n = normalize([vecs[0][j], vecs[1][j], vecs[2][j]])?;
        if dot(n, self.normal) < 0.0 {
            n = scale(n, -1.0);
        }
        Some((Plane { n, d: -dot(n, c) }, vals[j].max(0.0)))
    }
}

/// Why a partition has no valid polygon mesh, with the regions to change (or why its
/// realisation ended without one).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Defect {
    /// The corner of these regions lies farther from its input vertex than the largest of
    /// them is wide (planes nearly parallel or nearly concurrent).
    #[error("the planes of regions {regions:?} meet farther from vertex {vertex} than the largest of them is wide")]
    Far { vertex: u32, regions: Vec<u32> },
    /// The corner of these regions lies on the point of another junction's corner (or the
    /// same three planes meet at two junctions).
    #[error(
        "the corner of regions {regions:?} at vertex {vertex} lies on another junction's corner"
    )]
    Corner { vertex: u32, regions: Vec<u32> },
    /// Two input vertices lie on one point (the input touches itself there) and so do their
    /// corners: their polygons would touch too.
    #[error("input vertices {vertices:?} lie on one point (the surface touches itself there), and so do the corners of regions {regions:?} on them")]
    Touching {
        vertices: [u32; 2],
        regions: Vec<u32>,
    },
    /// The region occurs twice around one vertex: its polygon would touch itself.
    #[error("regions {regions:?} meet at vertex {vertex} with region {twice} twice (its polygon would touch itself)")]
    Pinch {
        vertex: u32,
        twice: u32,
        regions: Vec<u32>,
    },
    /// A loop of the region has fewer than three corners (no neighbours: a loop along the
    /// mesh's border).
    #[error("a boundary loop of region {region} (ringed by regions {neighbors:?}) has fewer than three corners")]
    Loop { region: u32, neighbors: Vec<u32> },
    /// A loop between two regions has no corner while each has an outline elsewhere: a
    /// handle of the input passes through it, which their polygons would close.
    #[error("a loop between regions {regions:?} has no corner (a handle of the input passes through it)")]
    Handle { regions: [u32; 2] },
    /// The region is a whole closed component: a closed surface has no outline.
    #[error("region {region} covers a whole closed component, which no planar polygon can")]
    Closed { region: u32 },
    /// The region's outline crosses itself, or a hole lies outside it, in its plane; the
    /// regions placing the corners of the crossing edges (empty for a hole or orientation).
    #[error("the outline of region {region} crosses itself in its plane")]
    Outline { region: u32, regions: Vec<u32> },
    /// Two polygons cross each other.
    #[error("the polygons of regions {regions:?} cross each other")]
    Crossing { regions: [u32; 2] },
    /// The realisation was stopped before it ended: its result was no longer wanted.
    #[error("the realisation was stopped (its result was no longer wanted)")]
    Stopped,
}

impl Defect {
    /// The regions a split or merge should involve.
    pub fn regions(&self) -> Vec<u32> {
        let mut r = match self {
            Defect::Far { regions, .. }
            | Defect::Corner { regions, .. }
            | Defect::Touching { regions, .. }
            | Defect::Pinch { regions, .. } => regions.clone(),
            Defect::Loop { region, neighbors } => {
                let mut r = neighbors.clone();
                r.push(*region);
                r
            }
            Defect::Closed { region } => vec![*region],
            Defect::Outline { region, regions } if regions.is_empty() => vec![*region],
            Defect::Outline { regions, .. } => regions.clone(),
            Defect::Crossing { regions } | Defect::Handle { regions } => regions.to_vec(),
            Defect::Stopped => Vec::new(),
        };
        r.retain(|&x| x != OUTSIDE);
        r
    }
}

/// The faces around vertex `v` in counter-clockwise order (seen from the side the faces
/// face), and whether `v` is on the border (then the order runs from border to border).
fn star(topo: &Topology, faces: &[[u32; 3]], v: u32) -> (Vec<u32>, bool) {
    let around = topo.vertex_faces(v);
    let Some(&f0) = around.first() else {
        return (Vec::new(), false);
    };
    let slot = |f: u32| faces[f as usize].iter().position(|&x| x == v).unwrap_or(0);
    let across = |f: u32, side: usize| {
        let g = topo.face_faces[f as usize][side];
        (g != NO_FACE).then_some(g)
    };
    // Counter-clockwise from f = (v, p, q): the face across the side q → v.
    let next = |f: u32| across(f, (slot(f) + 2) % 3);
    // Clockwise: across the side v → p.
    let prev = |f: u32| across(f, slot(f));
    // Walk clockwise to the border (if any) so the order starts there.
    let mut start = f0;
    let mut border = false;
    for _ in 0..around.len() {
        match prev(start) {
            Some(g) if g != f0 => start = g,
            Some(_) => break,
            None => {
                border = true;
                break;
            }
        }
    }
    let mut out = vec![start];
    let mut f = start;
    while let Some(g) = next(f) {
        if g == start || out.len() > around.len() {
            break;
        }
        out.push(g);
        f = g;
    }
    (out, border)
}

/// A corner of the polygon mesh: three regions' planes (the first [`OUTSIDE`] on the border:
/// then a point of the other two planes' line), or one region's plane at a border vertex.
#[derive(Clone, Copy, Debug)]
enum Junction {
    Three([u32; 3]),
    Border(u32),
}

/// Corners at each input vertex, and each region's corners there in the order its outline
/// passes them.
struct Corners {
    positions: Vec<V3>,
    /// Input vertex each corner belongs to, and the regions whose planes place it (the
    /// junction's, [`OUTSIDE`] where there are fewer: [`Corners::regions`]).
    vertex: Vec<u32>,
    junction: Vec<[u32; 3]>,
    /// (vertex, region, first, end): that region's corners at the vertex, in outline order,
    /// are `at_corners[first..end]`; ascending by vertex (the order they are found in).
    at: Vec<(u32, u32, u32, u32)>,
    at_corners: Vec<u32>,
    /// Per input vertex, its first entry in `at` (`u32::MAX`: none). Every outline vertex is
    /// looked up on every build, most of them junction-free: a direct index, not a search.
    first_at: Vec<u32>,
}

impl Corners {
    /// The regions whose planes place corner `c`.
    fn regions(&self, c: u32) -> impl Iterator<Item = u32> + '_ {
        self.junction[c as usize]
            .into_iter()
            .filter(|&r| r != OUTSIDE)
    }

    /// Region `r`'s corners at vertex `v`, in outline order.
    fn at(&self, v: u32, r: u32) -> Option<&[u32]> {
        let first = self.first_at[v as usize];
        self.at
            .get(first as usize..)?
            .iter()
            .take_while(|e| e.0 == v)
            .find(|e| e.1 == r)
            .map(|e| &self.at_corners[e.2 as usize..e.3 as usize])
    }

    /// Records `r`'s corners at `v` (vertices in ascending order).
    fn set_at(&mut self, v: u32, r: u32, corners: impl IntoIterator<Item = u32>) {
        let first = self.at_corners.len() as u32;
        if self.first_at[v as usize] == u32::MAX {
            self.first_at[v as usize] = self.at.len() as u32;
        }
        self.at_corners.extend(corners);
        self.at.push((v, r, first, self.at_corners.len() as u32));
    }
}

/// Where the planes of `j` meet, nearest to `x`.
fn place(j: Junction, planes: &[Plane], x: V3) -> Option<V3> {
    match j {
        Junction::Border(r) => {
            let p = planes[r as usize];
            Some(sub(x, scale(p.n, p.signed_distance(x))))
        }
        Junction::Three([a, b, c]) if a == OUTSIDE => {
            // Nearest point of the line of b and c: x + λ nb + μ nc with both distances 0.
            let (pb, pc) = (planes[b as usize], planes[c as usize]);
            let g = dot(pb.n, pc.n);
            let det = 1.0 - g * g;
            if det <= 1e-12 {
                return None;
            }
            let (db, dc) = (-pb.signed_distance(x), -pc.signed_distance(x));
            let l = (db - g * dc) / det;
            let m = (dc - g * db) / det;
            Some(add(x, add(scale(pb.n, l), scale(pc.n, m))))
        }
        Junction::Three(r) => {
            let p = r.map(|i| planes[i as usize]);
            let det = dot(p[0].n, cross(p[1].n, p[2].n));
            if det.abs() <= 1e-12 {
                return None;
            }
            // Cramer: x = (−d0 (n1×n2) − d1 (n2×n0) − d2 (n0×n1)) / det.
            let s = add(
                add(
                    scale(cross(p[1].n, p[2].n), -p[0].d),
                    scale(cross(p[2].n, p[0].n), -p[1].d),
                ),
                scale(cross(p[0].n, p[1].n), -p[2].d),
            );
            Some(scale(s, 1.0 / det))
        }
    }
}

/// The corners of every vertex where regions meet (see the module doc); corners of one
/// junction closer than `tol` are one. `passes` counts the regions' boundary loops passing
/// through each vertex: only the vertices passed on the border, or passed three times or more,
/// are looked at. (An inner vertex is passed once for each run of one region's faces around
/// it, as each such run ends at one boundary edge of its region leaving the vertex: passed
/// twice, it lies on the boundary between two regions and has no corner; never, it lies inside
/// a region.)
fn corners(
    s: &Surface<'_>,
    labels: &[u32],
    planes: &[Plane],
    size: &[f64],
    passes: &[u8],
) -> Result<Corners, Defect> {
    let (pos, tol) = (s.pos, s.tol());
    let mut out = Corners {
        positions: Vec::new(),
        vertex: Vec::new(),
        junction: Vec::new(),
        at: Vec::new(),
        at_corners: Vec::new(),
        first_at: vec![u32::MAX; s.topo.n_vertices],
    };
    let mut triples: HashMap<[u32; 3], u32> = HashMap::new();
    // Per-vertex lists, kept to reuse their memory (most vertices where regions meet are
    // visited on every build).
    let (mut seq, mut sorted, mut cycle, mut ids, mut cs) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let junction = |v: usize| passes[v] >= 3 || (passes[v] > 0 && s.on_border[v]);
    for v in (0..s.topo.n_vertices as u32).filter(|&v| junction(v as usize)) {
        let (fs, border) = s.star(v);
        if fs.is_empty() {
            continue;
        }
        // Regions in counter-clockwise order, runs collapsed.
        seq.clear();
        for &f in fs {
            let r = labels[f as usize];
            if seq.last() != Some(&r) {
                seq.push(r);
            }
        }
        if !border && seq.len() > 1 && seq.first() == seq.last() {
            seq.pop();
        }
        let x = pos[v as usize];
        if border && seq.len() == 1 {
            let c = place(Junction::Border(seq[0]), planes, x).ok_or(Defect::Outline {
                region: seq[0],
                regions: Vec::new(),
            })?;
            let c_id = out.positions.len() as u32;
            out.set_at(v, seq[0], [c_id]);
            out.positions.push(c);
            out.vertex.push(v);
            out.junction.push([seq[0], OUTSIDE, OUTSIDE]);
            continue;
        }
        if !border && seq.len() < 3 {
            continue;
        }
        sorted.clone_from(&seq);
        sorted.sort_unstable();
        sorted.dedup();
        if sorted.len() < seq.len() {
            let twice = sorted
                .iter()
                .copied()
                .find(|r| seq.iter().filter(|&x| x == r).count() > 1)
                .unwrap_or(sorted[0]);
            return Err(Defect::Pinch {
                vertex: v,
                twice,
                regions: sorted.clone(),
            });
        }
        // The cycle of the fan: the border's outside first, else the root that keeps the
        // corners nearest to the vertex.
        cycle.clear();
        if border {
            cycle.push(OUTSIDE);
            cycle.extend_from_slice(&seq);
        } else {
            let m = seq.len();
            let spread = |root: usize| -> f64 {
                (1..m - 1)
                    .map(|t| {
                        let j = Junction::Three([
                            seq[root],
                            seq[(root + t) % m],
                            seq[(root + t + 1) % m],
                        ]);
                        place(j, planes, x).map_or(f64::INFINITY, |c| {
                            let d = sub(c, x);
                            dot(d, d)
                        })
                    })
                    .fold(0.0, f64::max)
            };
            let root = (0..m)
                .min_by(|&a, &b| spread(a).total_cmp(&spread(b)))
                .unwrap_or(0);
            cycle.extend((0..m).map(|t| seq[(root + t) % m]));
        }
        let m = cycle.len();
        let first = out.positions.len();
        // The corner of each fan triangle t = 1..m−1: (cycle[0], cycle[t], cycle[t + 1]).
        ids.clear();
        for t in 1..m - 1 {
            let regions = [cycle[0], cycle[t], cycle[t + 1]];
            let named = || regions.iter().copied().filter(|&r| r != OUTSIDE).collect();
            let bad = || Defect::Corner {
                vertex: v,
                regions: named(),
            };
            let far = || Defect::Far {
                vertex: v,
                regions: named(),
            };
            // The same three planes at two junctions would put two corners on one point.
            if !regions.contains(&OUTSIDE) {
                let mut key = regions;
                key.sort_unstable();
                if *triples.entry(key).or_insert(v) != v {
                    return Err(bad());
                }
            }
            let c = place(Junction::Three(regions), planes, x).ok_or_else(far)?;
            let reach = regions
                .iter()
                .filter(|&&r| r != OUTSIDE)
                .map(|&r| size[r as usize])
                .fold(0.0, f64::max);
            let d = sub(c, x);
            if dot(d, d).sqrt() > reach {
                return Err(far());
            }
            // Four or more planes through one point (a cube's corner cut by a fourth face,
            // an apex): the fan's corners coincide, and are one corner.
            let same = (first..out.positions.len()).find(|&i| {
                let e = sub(out.positions[i], c);
                dot(e, e).sqrt() <= tol
            });
            if let Some(i) = same {
                ids.push(i as u32);
                continue;
            }
            ids.push(out.positions.len() as u32);
            out.positions.push(c);
            out.vertex.push(v);
            out.junction.push(regions);
        }
        // Region cycle[j] passes its triangles from the side of its incoming neighbour (the
        // next region counter-clockwise) to its outgoing one: the root all of them ascending,
        // the others triangles j then j − 1.
        for (j, &r) in cycle.iter().enumerate() {
            if r == OUTSIDE {
                continue;
            }
            cs.clear();
            if j == 0 {
                cs.extend_from_slice(&ids);
            } else {
                cs.extend(
                    [j, j - 1]
                        .into_iter()
                        .filter(|&t| t >= 1 && t < m - 1)
                        .map(|t| ids[t - 1]),
                );
            }
            cs.dedup();
            out.set_at(v, r, cs.iter().copied());
        }
    }
    Ok(out)
}

/// How many times the regions' boundary `loops` pass through each vertex (at most 255).
fn loop_passes<'a>(n_vertices: usize, loops: impl Iterator<Item = &'a Vec<Vec<u32>>>) -> Vec<u8> {
    let mut passes = vec![0u8; n_vertices];
    for &v in loops.flatten().flatten() {
        passes[v as usize] = passes[v as usize].saturating_add(1);
    }
    passes
}

/// Even–odd point-in-polygon test.
fn inside(p: [f64; 2], poly: &[[f64; 2]]) -> bool {
    let mut w = false;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        if (a[1] > p[1]) != (b[1] > p[1])
            && p[0] < a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0])
        {
            w = !w;
        }
    }
    w
}

/// Two corners of different junctions closer than `tol`, as a defect ([`Defect::Touching`]
/// where their input vertices are that close too: the message then names the input's cause).
fn coincident(cs: &Corners, pos: &[V3], tol: f64) -> Option<Defect> {
    let mut order: Vec<usize> = (0..cs.positions.len()).collect();
    order.sort_by(|&a, &b| cs.positions[a][0].total_cmp(&cs.positions[b][0]));
    for (i, &a) in order.iter().enumerate() {
        for &b in &order[i + 1..] {
            let d = sub(cs.positions[b], cs.positions[a]);
            if d[0] > tol {
                break;
            }
            if cs.vertex[a] != cs.vertex[b] && norm(d) <= tol {
                let mut regions: Vec<u32> =
                    cs.regions(a as u32).chain(cs.regions(b as u32)).collect();
                regions.sort_unstable();
                regions.dedup();
                let (v, w) = (cs.vertex[a], cs.vertex[b]);
                if norm(sub(pos[v as usize], pos[w as usize])) <= tol {
                    let vertices = [v.min(w), v.max(w)];
                    return Some(Defect::Touching { vertices, regions });
                }
                return Some(Defect::Corner { vertex: v, regions });
            }
        }
    }
    None
}

/// One region's outline loops as corner cycles, or for a loop with fewer than three corners
/// the regions ringing it (`Err`); a border corner on the chord of its neighbours (to 1e-6 of
/// the chord's length) adds nothing to the outline and would give a zero-area triangle, and it
/// belongs to this polygon alone, so it is dropped (the mesh stays watertight).
fn region_outlines(
    s: &Surface<'_>,
    labels: &[u32],
    cs: &Corners,
    r: u32,
    region_loops: &[Vec<u32>],
) -> Loops {
    let mut outlines = Vec::new();
    for lp in region_loops {
        let mut ol: Vec<u32> = lp
            .iter()
            .filter_map(|&v| cs.at(v, r))
            .flatten()
            .copied()
            .collect();
        ol.dedup();
        if ol.len() > 1 && ol.first() == ol.last() {
            ol.pop();
        }
        let mut i = 0;
        while ol.len() > 3 && i < ol.len() {
            let m = ol.len();
            let (a, c, b) = (ol[(i + m - 1) % m], ol[i], ol[(i + 1) % m]);
            let p = |x: u32| cs.positions[x as usize];
            let chord = sub(p(b), p(a));
            let off = cross(chord, sub(p(c), p(a)));
            if cs.regions(c).count() == 1 && dot(off, off).sqrt() <= 1e-6 * dot(chord, chord) {
                ol.remove(i);
                i = i.saturating_sub(1);
            } else {
                i += 1;
            }
        }
        if ol.len() < 3 {
            // The regions across the loop's edges ring it.
            let mut nb: Vec<u32> = Vec::new();
            for (i, &v) in lp.iter().enumerate() {
                let b = lp[(i + 1) % lp.len()];
                nb.extend(
                    s.topo
                        .vertex_faces(v)
                        .iter()
                        .filter(|&&f| s.faces[f as usize].contains(&b) && labels[f as usize] != r)
                        .map(|&f| labels[f as usize]),
                );
            }
            nb.sort_unstable();
            nb.dedup();
            outlines.push(Err(nb));
        } else {
            outlines.push(Ok(ol));
        }
    }
    outlines
}

/// Region `r`'s polygon outlines out of each region's loops (`all`, [`region_outlines`]): its
/// loops with three corners or more. A loop with none, between two regions alone, each with
/// an outline elsewhere, is a [`Defect::Handle`] or, with `close_handles`, left out of both
/// polygons (by the orientation check of [`region_polygon`], it is then a hole of both): the
/// two polygons cover the hole, the mesh stays watertight (no edge of either lies on the
/// loop), and a handle of the input through it is closed — the realisation of a tunnel whose
/// wall has no plane of its own. Any other loop with fewer than three corners is a
/// [`Defect::Loop`]; a region with no loop, [`Defect::Closed`].
fn kept_outlines<'a>(
    all: &impl Fn(u32) -> &'a Loops,
    r: u32,
    close_handles: bool,
) -> Result<Vec<&'a [u32]>, Defect> {
    let has_outline = |r: u32| all(r).iter().any(|o| o.is_ok());
    let mut out = Vec::new();
    for lp in all(r) {
        match lp {
            Ok(ol) => out.push(&ol[..]),
            Err(nb) => match nb[..] {
                [c] if c != OUTSIDE && has_outline(r) && has_outline(c) => {
                    if !close_handles {
                        return Err(Defect::Handle { regions: [r, c] });
                    }
                }
                _ => {
                    return Err(Defect::Loop {
                        region: r,
                        neighbors: nb.clone(),
                    })
                }
            },
        }
    }
    if out.is_empty() {
        return Err(Defect::Closed { region: r });
    }
    Ok(out)
}

/// A region's loops: each its corner cycle, or the regions ringing it where it has fewer than
/// three corners.
type Loops = Vec<Result<Vec<u32>, Vec<u32>>>;

/// Checks that the outlines of region `r` bound a simple polygon with holes in its plane (the
/// outer loop, of largest area, counter-clockwise; holes clockwise and inside it; no two
/// edges crossing) and returns it with the holes bridged in, and its triangles.
fn region_polygon(
    cs: &Corners,
    plane: &Plane,
    r: u32,
    outlines: &[&[u32]],
) -> Result<(Vec<u32>, Vec<[u32; 3]>), Defect> {
    let (u, w) = basis(plane.n);
    let to2 = |c: u32| {
        let q = cs.positions[c as usize];
        [dot(q, u), dot(q, w)]
    };
    let p2: Vec<Vec<[f64; 2]>> = outlines
        .iter()
        .map(|l| l.iter().map(|&c| to2(c)).collect())
        .collect();
    let areas: Vec<f64> = p2.iter().map(|p| area2(p)).collect();
    let outer = (0..outlines.len())
        .max_by(|&a, &b| areas[a].abs().total_cmp(&areas[b].abs()))
        .unwrap_or(0);
    let bad = Defect::Outline {
        region: r,
        regions: Vec::new(),
    };
    if areas[outer] <= 0.0 {
        return Err(bad);
    }
    for (i, a) in areas.iter().enumerate() {
        if i != outer && (*a >= 0.0 || !inside(p2[i][0], &p2[outer])) {
            return Err(bad);
        }
    }
    let ids: Vec<(u32, u32)> = outlines
        .iter()
        .flat_map(|l| (0..l.len()).map(move |k| (l[k], l[(k + 1) % l.len()])))
        .collect();
    for i in 0..ids.len() {
        for j in i + 1..ids.len() {
            let (a, b) = (to2(ids[i].0), to2(ids[i].1));
            if segments_cross(a, b, to2(ids[j].0), to2(ids[j].1)) {
                let mut regions: Vec<u32> = [ids[i].0, ids[i].1, ids[j].0, ids[j].1]
                    .iter()
                    .flat_map(|&c| cs.regions(c))
                    .collect();
                regions.sort_unstable();
                regions.dedup();
                return Err(Defect::Outline { region: r, regions });
            }
        }
    }
    let holes = (0..outlines.len())
        .filter(|&i| i != outer)
        .map(|i| outlines[i].to_vec())
        .collect();
    let poly = bridge_holes(outlines[outer], holes, &to2);
    let pts: Vec<[f64; 2]> = poly.iter().map(|&c| to2(c)).collect();
    let mut tris = Vec::new();
    for t in ear_clip(&pts) {
        if orient(pts[t[0]], pts[t[1]], pts[t[2]]) <= 0.0 {
            return Err(bad);
        }
        tris.push(t.map(|k| poly[k]));
    }
    Ok((poly, tris))
}

/// The polygon mesh of a partition with its planes, and its triangles (in the polygons'
/// planes); corners index into one shared list.
pub fn build(
    s: &Surface<'_>,
    labels: &[u32],
    planes: &[Plane],
    close_handles: bool,
) -> Result<PolygonMesh, Defect> {
    let mut regions = Regions::of(s, labels, planes.len());
    regions.close_handles = close_handles;
    build_sized(s, planes, &mut regions)
}

/// [`build`] of the labels of `regions`' last update, with their bounding-box diagonals (how
/// far a corner may lie from its vertex) and boundary loops (traced here for the regions whose
/// faces changed since, kept for the next build).
fn build_sized(
    s: &Surface<'_>,
    planes: &[Plane],
    regions: &mut Regions,
) -> Result<PolygonMesh, Defect> {
    let size = regions.sizes();
    // Corners closer than the tolerance are one point at the output's precision: at one
    // junction they are merged, at two they are a defect (two corners on one point pinch the
    // polygons between them).
    regions.trace_loops(s);
    // Corners are only where regions meet or the surface ends: on the regions' boundary loops.
    let passes = loop_passes(s.topo.n_vertices, regions.loops.iter().flatten());
    let cs = corners(s, &regions.labels, planes, &size, &passes)?;
    if let Some(d) = coincident(&cs, s.pos, s.tol()) {
        return Err(d);
    }
    let mut mesh = PolygonMesh {
        positions: cs.positions.clone(),
        ..Default::default()
    };
    // Each region's loops, made when first asked for: by its own polygon, or by a neighbour's
    // handle (most builds end at a defect before the last region).
    let made: Vec<std::cell::OnceCell<Loops>> = vec![Default::default(); regions.loops.len()];
    let all = |r: u32| {
        made[r as usize].get_or_init(|| {
            let l = regions.loops[r as usize].as_deref().unwrap_or_default();
            region_outlines(s, &regions.labels, &cs, r, l)
        })
    };
    for r in 0..made.len() as u32 {
        let outlines = kept_outlines(&all, r, regions.close_handles)?;
        let (poly, t) = region_polygon(&cs, &planes[r as usize], r, &outlines)?;
        mesh.holes += outlines.len() - 1;
        mesh.triangle_region.extend(std::iter::repeat_n(r, t.len()));
        mesh.triangles.extend(t);
        mesh.polygons.push(poly);
        mesh.region.push(r);
    }
    let (m, tol) = (&mesh, s.tol());
    if let Some([a, b]) = first_crossing(&m.positions, &m.triangles, &m.triangle_region, tol) {
        return Err(Defect::Crossing { regions: [a, b] });
    }
    Ok(mesh)
}

/// A partition realised as a polygon mesh.
#[derive(Clone, Default)]
pub struct Realised {
    pub polygons: PolygonMesh,
    /// Region of each face, numbered `0..planes.len()`.
    pub labels: Vec<u32>,
    pub planes: Vec<Plane>,
    /// The defects met on the way, each answered by a split or a merge.
    pub defects: Vec<Defect>,
    pub splits: usize,
    pub merges: usize,
    /// Pinches answered by moving a wedge of faces to a neighbour (`unpinch`).
    pub unpinched: usize,
    /// Regions given away to their neighbours (`dissolve`; counted in `merges` too).
    pub dissolved: usize,
    /// Regions added by [`spend_on_two_planes`] (counted in `splits` too).
    pub plane_halvings: usize,
    /// Whether its polygons may close handles of the input ([`Defect::Handle`]).
    pub closes_handles: bool,
}

/// Each region's moments, plane fit and bounding box under the labels of the last
/// [`Regions::update`], kept across the builds of one realisation. A region whose faces are
/// exactly one region's faces of last time keeps that region's values: a split or a merge
/// changes one or two regions' faces, and the renumbering after a merge moves none. The
/// others are summed again from their own faces (each region keeps its list) in face order,
/// as a scan of every region sums them — the same values, without a pass over every face on
/// every build.
#[derive(Clone, Default)]
struct Regions {
    labels: Vec<u32>,
    moments: Vec<Moments>,
    fit: Vec<(Plane, f64)>,
    boxes: Vec<[V3; 2]>,
    /// Each region's faces, ascending.
    members: Vec<Vec<u32>>,
    /// Each region's faces with an edge neighbour in another region, ascending: what the
    /// pairs of adjacent regions are read from ([`Regions::adjacent_pairs`]), the same while
    /// the region's faces are.
    boundary: Vec<Vec<u32>>,
    /// Each region's boundary loops ([`region_loops`]), once a build has traced them.
    loops: Vec<Option<Vec<Vec<u32>>>>,
    /// Whether a loop with no corner between two regions is left out of both polygons (a
    /// handle closed, [`kept_outlines`]) rather than a [`Defect::Handle`]: set where
    /// [`realise`] resumes after a search that met a handle ended without a mesh.
    close_handles: bool,
    /// The surface's plane rule at the last update (by which `fit` was made).
    rule: PlaneRule,
    /// Each region's identity: kept while its faces are (its values with them), a new one
    /// when they change.
    ids: Vec<u64>,
    next_id: u64,
    /// [`Regions::merge_cost`] by the pair's identities (in the order asked): a search asks
    /// the cost of every adjacent pair at each defect, while a split or a merge changes one
    /// or two regions. The same values, without a plane fit per pair per defect.
    merge_costs: std::cell::RefCell<HashMap<(u64, u64), f64>>,
}

impl Regions {
    /// The values of the regions `0..n` of `labels` on `s`.
    fn of(s: &Surface<'_>, labels: &[u32], n: usize) -> Regions {
        let mut regions = Regions::default();
        regions.update(s, labels, n);
        regions
    }

    /// The values of `labels`' regions `0..n`.
    fn update(&mut self, s: &Surface<'_>, labels: &[u32], n: usize) {
        self.rule = s.rule;
        // Per old region the one new region all its faces are in, and per new region the one
        // old region all its faces come from (NONE: no face, MANY: more than one).
        const NONE: u32 = u32::MAX;
        const MANY: u32 = u32::MAX - 1;
        let mut from = vec![MANY; n];
        // The faces whose label changed (ascending); `None`: no earlier labels to compare.
        let mut changed = None;
        if self.labels.len() == labels.len() {
            // Over the faces whose label changed (few, but for a merge's renumbering); an old
            // region keeps faces (`stays`) when fewer than all of its faces left it.
            let m = self.moments.len();
            let (mut to, mut moved, mut left) = (vec![NONE; m], vec![NONE; n], vec![0; m]);
            let mut faces = Vec::new();
            for (face, (&a, &b)) in self.labels.iter().zip(labels).enumerate() {
                if a == b {
                    continue;
                }
                faces.push(face as u32);
                left[a as usize] += 1;
                let t = &mut to[a as usize];
                *t = if *t == NONE || *t == b { b } else { MANY };
                let f = &mut moved[b as usize];
                *f = if *f == NONE || *f == a { a } else { MANY };
            }
            let stays = |a: usize| self.members[a].len() > left[a];
            for (b, f) in from.iter_mut().enumerate() {
                let stays_b = b < m && stays(b);
                *f = match moved[b] {
                    // No face came to b: the old b, if none of its faces left.
                    NONE if stays_b && to[b] == NONE => b as u32,
                    // Every face of b came from a, and every face of a went to b.
                    a if a < MANY
                        && !stays_b
                        && !stays(a as usize)
                        && to[a as usize] == b as u32 =>
                    {
                        a
                    }
                    _ => MANY,
                };
            }
            changed = Some(faces);
        }
        // The old region whose values new region `b` keeps.
        let old = |b: usize| (from[b] < MANY).then_some(from[b] as usize);
        // Each new region's faces, ascending: a kept region's are the old region's; the others'
        // are what stays of the old region of their number and the faces that came to them.
        let mut old_members = std::mem::take(&mut self.members);
        let mut members: Vec<Vec<u32>> = vec![Vec::new(); n];
        match &changed {
            Some(faces) => {
                for &f in faces {
                    let b = labels[f as usize] as usize;
                    if old(b).is_none() {
                        members[b].push(f);
                    }
                }
                for (b, list) in members.iter_mut().enumerate() {
                    if let Some(a) = old(b) {
                        *list = std::mem::take(&mut old_members[a]);
                    } else if let Some(stayed) = old_members.get(b) {
                        // Two ascending runs: the stable sort merges them in one pass.
                        list.extend(stayed.iter().filter(|&&f| labels[f as usize] == b as u32));
                        list.sort();
                    }
                }
            }
            None => {
                for (f, &r) in labels.iter().enumerate() {
                    members[r as usize].push(f as u32);
                }
            }
        }
        // The others summed again in face order, as a scan of every region sums them.
        let empty = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
        let (mut moments, mut boxes) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for (b, list) in members.iter().enumerate() {
            let (mut m, mut bx) = old(b).map_or((Moments::default(), empty), |a| {
                (self.moments[a], self.boxes[a])
            });
            let summed: &[u32] = if old(b).is_none() { list } else { &[] };
            for &f in summed {
                m = m.add(&s.moments[f as usize]);
                let fb = &s.face_box[f as usize];
                for k in 0..3 {
                    bx[0][k] = bx[0][k].min(fb[0][k]);
                    bx[1][k] = bx[1][k].max(fb[1][k]);
                }
            }
            moments.push(m);
            boxes.push(bx);
        }
        self.fit = carried(std::mem::take(&mut self.fit), n, old, |b| {
            fit_or_flat(&moments[b], s.rule)
        });
        self.loops = carried(std::mem::take(&mut self.loops), n, old, |_| None);
        let next_id = &mut self.next_id;
        self.ids = carried(std::mem::take(&mut self.ids), n, old, |_| {
            *next_id += 1;
            *next_id
        });
        // Costs of pairs whose regions both live on (a region never comes back).
        let live: HashSet<u64> = self.ids.iter().copied().collect();
        self.merge_costs
            .get_mut()
            .retain(|(x, y), _| live.contains(x) && live.contains(y));
        self.boundary = carried(std::mem::take(&mut self.boundary), n, old, |b| {
            let outside = |f: &u32| {
                super::lloyd::neighbors(s.topo, *f as usize).any(|g| labels[g] != b as u32)
            };
            members[b].iter().copied().filter(outside).collect()
        });
        self.members = members;
        self.moments = moments;
        self.boxes = boxes;
        self.labels.clear();
        self.labels.extend_from_slice(labels);
    }

    /// Traces the boundary loops ([`region_loops`]) of the regions that have none since their
    /// faces last changed, looking at their faces only.
    fn trace_loops(&mut self, s: &Surface<'_>) {
        let want: Vec<bool> = self.loops.iter().map(Option::is_none).collect();
        if !want.contains(&true) {
            return;
        }
        let among: Vec<u32> = (0..want.len())
            .filter(|&r| want[r])
            .flat_map(|r| self.members[r].iter().copied())
            .collect();
        let traced = region_loops(s.topo, s.faces, &self.labels, want.len(), &want, &among);
        for ((cached, loops), want) in self.loops.iter_mut().zip(traced).zip(want) {
            if want {
                *cached = Some(loops);
            }
        }
    }

    /// The regions sharing an edge, as sorted pairs, ascending: read from the regions' faces
    /// along their boundaries, not from every edge of the mesh (a search asks for them at every
    /// defect).
    fn adjacent_pairs(&self, topo: &Topology) -> Vec<(u32, u32)> {
        let mut pairs = Vec::new();
        for (r, faces) in self.boundary.iter().enumerate() {
            let r = r as u32;
            for &f in faces {
                for g in super::lloyd::neighbors(topo, f as usize) {
                    let l = self.labels[g];
                    // Each pair from its lower region's side; a run along a boundary once.
                    if l > r && pairs.last() != Some(&(r, l)) {
                        pairs.push((r, l));
                    }
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        pairs
    }

    /// The plane of faces with moments `m` and its residual, by the regions' rule.
    fn fit_of(&self, m: &Moments) -> (Plane, f64) {
        fit_or_flat(m, self.rule)
    }

    fn planes(&self) -> Vec<Plane> {
        self.fit.iter().map(|f| f.0).collect()
    }

    /// How much worse the merged region fits than the two apart, per input vertex
    /// ([`Moments::per_vertex`]).
    ///
    /// Why per vertex: the run is judged by the mean distance of the input's vertices; on a
    /// mesh whose vertices are not spread evenly (CAD: fillets and small features finely
    /// meshed, large flat faces in a few triangles) the merge that costs least per unit area
    /// can be the one that costs most by that error.
    fn merge_cost(&self, (a, b): (u32, u32)) -> f64 {
        let key = (self.ids[a as usize], self.ids[b as usize]);
        *self.merge_costs.borrow_mut().entry(key).or_insert_with(|| {
            let (ma, mb) = (&self.moments[a as usize], &self.moments[b as usize]);
            let merged = ma.add(mb);
            merged.per_vertex(self.fit_of(&merged).1)
                - ma.per_vertex(self.fit[a as usize].1)
                - mb.per_vertex(self.fit[b as usize].1)
        })
    }

    /// The adjacent pair among `pairs` whose merge costs least (each cost a plane fit,
    /// computed once per pair).
    fn cheapest(&self, pairs: impl Iterator<Item = (u32, u32)>) -> Option<(u32, u32)> {
        pairs
            .map(|p| (self.merge_cost(p), p))
            .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)))
            .map(|(_, p)| p)
    }

    /// The regions' bounding-box diagonals.
    fn sizes(&self) -> Vec<f64> {
        self.boxes
            .iter()
            .map(|[lo, hi]| {
                let d = sub(*hi, *lo);
                dot(d, d).sqrt()
            })
            .collect()
    }
}

/// Each new region `b`'s value in [`Regions::update`]: the value in `prev` of the old region
/// it keeps (`old(b)`), or `fresh(b)` where its faces changed.
fn carried<T>(
    prev: Vec<T>,
    n: usize,
    old: impl Fn(usize) -> Option<usize>,
    mut fresh: impl FnMut(usize) -> T,
) -> Vec<T> {
    let mut prev: Vec<Option<T>> = prev.into_iter().map(Some).collect();
    (0..n)
        .map(|b| {
            old(b)
                .and_then(|a| prev.get_mut(a).and_then(Option::take))
                .unwrap_or_else(|| fresh(b))
        })
        .collect()
}

fn fit_or_flat(m: &Moments, rule: PlaneRule) -> (Plane, f64) {
    m.fit(rule).unwrap_or((
        Plane {
            n: [0.0, 0.0, 1.0],
            d: 0.0,
        },
        0.0,
    ))
}

/// The region a defect asks to split: an outline that crosses itself its own region (a
/// region that turns too much for one plane), otherwise the named region whose plane fits
/// worst.
fn split_target(
    defect: &Defect,
    named: &[u32],
    fits: &Regions,
    unsplittable: &[bool],
) -> Option<u32> {
    if let Defect::Outline { region, .. } = defect {
        if !unsplittable[*region as usize] {
            return Some(*region);
        }
    }
    named
        .iter()
        .copied()
        .filter(|&r| !unsplittable[r as usize])
        .max_by(|&a, &b| fits.fit[a as usize].1.total_cmp(&fits.fit[b as usize].1))
}

/// Makes region `r` touch vertex `v` once: the faces of its smallest run around `v` go to
/// the region before (or after) the run, whose faces there share an edge with them, with any
/// part of `r` that only the run held to the rest. False when `r` has one run at `v` (or the
/// run has no other region beside it), `labels` then unchanged.
///
/// A region that meets itself at one vertex only (a pinch) has no simple outline there;
/// moving one wedge of faces is the least change of the partition that removes it, where a
/// split of the region may leave the pinch in one half.
fn unpinch(s: &Surface<'_>, labels: &mut [u32], v: u32, r: u32) -> bool {
    let (fs, border) = s.star(v);
    let m = fs.len();
    let ls: Vec<u32> = fs.iter().map(|&f| labels[f as usize]).collect();
    let label = |i: usize| ls[i];
    // Maximal runs of r: (first index, length), cyclic unless on the border.
    let starts: Vec<usize> = (0..m)
        .filter(|&i| {
            label(i) == r && {
                if i == 0 {
                    border || label(m - 1) != r
                } else {
                    label(i - 1) != r
                }
            }
        })
        .collect();
    let mut runs: Vec<(usize, usize)> = starts
        .iter()
        .map(|&i| {
            let mut len = 0;
            while len < m && label((i + len) % m) == r && (!border || i + len < m) {
                len += 1;
            }
            (i, len)
        })
        .collect();
    if runs.len() < 2 {
        return false;
    }
    runs.sort_by_key(|&(_, len)| len);
    for (i, len) in runs {
        let before = (i > 0 || !border).then(|| label((i + m - 1) % m));
        let after = (i + len < m || !border).then(|| label((i + len) % m));
        for to in [before, after].into_iter().flatten() {
            if to == r {
                continue;
            }
            for t in 0..len {
                labels[fs[(i + t) % m] as usize] = to;
            }
            // The run may have held parts of r to the rest: those parts, now touching `to`
            // through the run, go with it, so both regions stay connected.
            let mut parts = region_parts(s.topo, labels, r);
            parts.sort_by_key(|p| std::cmp::Reverse(p.len()));
            for p in parts.iter().skip(1) {
                for &f in p {
                    labels[f as usize] = to;
                }
            }
            return true;
        }
    }
    false
}

/// The faces labelled `r`, by part connected across edges.
fn region_parts(topo: &Topology, labels: &[u32], r: u32) -> Vec<Vec<u32>> {
    parts(
        topo,
        labels.len(),
        |f| labels[f] == r,
        |_, g| labels[g] == r,
    )
}

/// The faces for which `include` holds, by part connected across the edges between faces
/// that `joined` joins (each part starts at its lowest face).
pub(super) fn parts(
    topo: &Topology,
    n_faces: usize,
    include: impl Fn(usize) -> bool,
    joined: impl Fn(usize, usize) -> bool,
) -> Vec<Vec<u32>> {
    let mut seen = vec![false; n_faces];
    let mut parts = Vec::new();
    for first in 0..n_faces {
        if seen[first] || !include(first) {
            continue;
        }
        seen[first] = true;
        let mut stack = vec![first as u32];
        let mut part = Vec::new();
        while let Some(f) = stack.pop() {
            part.push(f);
            for g in super::lloyd::neighbors(topo, f as usize) {
                if !seen[g] && joined(f as usize, g) {
                    seen[g] = true;
                    stack.push(g as u32);
                }
            }
        }
        parts.push(part);
    }
    parts
}

/// Region `r` of the partition `fits` holds given away to the regions around it, face by
/// face: each face goes to the region across one of its edges whose plane it is nearest
/// (integrated squared distance), nearest first (region growing into `r` with the
/// neighbours' planes as proxies, as VSA grows its regions). The labels with the regions
/// after `r` renumbered down by one, and how much the residual grows; `None` when `r` has no
/// neighbour.
///
/// Why: a merge keeps the union of two regions, and when the defect it answers comes back
/// the next merge grows the same region again — a cascade that ends in a few regions wrapped
/// around the part. Giving the faces away grows each neighbour by the faces nearest its
/// plane instead; the caller keeps whichever of the two costs less.
fn dissolve(s: &Surface<'_>, fits: &Regions, r: u32) -> Option<(Vec<u32>, f64)> {
    let (labels, face_moments) = (&fits.labels, &s.moments);
    let cost = |f: usize, q: u32| face_moments[f].sq_distance(&fits.fit[q as usize].0);
    let members: Vec<usize> = fits.members[r as usize]
        .iter()
        .map(|&f| f as usize)
        .collect();
    let given = hand_out(s.topo, labels, r, &members, cost)?;
    let mut out = labels.to_vec();
    // What each neighbour gains, summed in face order (`given` follows the ascending members).
    let mut gained = vec![Moments::default(); fits.moments.len()];
    for &(f, q) in &given {
        out[f] = q;
        gained[q as usize] = gained[q as usize].add(&face_moments[f]);
    }
    let m = &fits.moments;
    let mut grow = -m[r as usize].per_vertex(fits.fit[r as usize].1);
    for (q, g) in gained.iter().enumerate().filter(|(_, g)| g.area > 0.0) {
        let grown = m[q].add(g);
        grow += grown.per_vertex(fits.fit_of(&grown).1) - m[q].per_vertex(fits.fit[q].1);
    }
    for l in out.iter_mut() {
        if *l > r {
            *l -= 1;
        }
    }
    Some((out, grow))
}

/// Region growing of region `r`'s faces (`members`) into its neighbours: each face goes to
/// the region across one of its edges (a neighbour, or a face already handed out) for which
/// `cost(face, region)` is least, cheapest first. New labels of `members`, or `None` when
/// some face cannot be reached.
fn hand_out(
    topo: &Topology,
    fc: &[u32],
    r: u32,
    members: &[usize],
    cost: impl Fn(usize, u32) -> f64,
) -> Option<Vec<(usize, u32)>> {
    let mut label: HashMap<usize, u32> = HashMap::new();
    let mut heap: BinaryHeap<Reverse<(u64, usize, u32)>> = BinaryHeap::new();
    let push_from = |f: usize, label: &HashMap<usize, u32>, heap: &mut BinaryHeap<_>| {
        for g in super::lloyd::neighbors(topo, f) {
            if fc[g] != r || label.contains_key(&g) {
                continue;
            }
            let c = if fc[f] == r { label[&f] } else { fc[f] };
            // Non-negative floats order as their bits do.
            heap.push(Reverse((cost(g, c).max(0.0).to_bits(), g, c)));
        }
    };
    for &f in members {
        for g in super::lloyd::neighbors(topo, f) {
            if fc[g] != r {
                push_from(g, &label, &mut heap);
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

/// Merges region `gone` into `keep` and renumbers the regions after `gone` down by one.
fn merge(labels: &mut [u32], keep: u32, gone: u32) {
    let keep = if keep > gone { keep - 1 } else { keep };
    for l in labels.iter_mut() {
        if *l == gone {
            *l = keep;
        } else if *l > gone {
            *l -= 1;
        }
    }
}

/// The input surface: positions and faces, and the normals and areas splits follow; with
/// what every realisation of a partition reads and no partition changes, computed once (each
/// run builds hundreds of polygon meshes of one surface).
pub struct Surface<'a> {
    pub topo: &'a Topology,
    pub pos: &'a [V3],
    pub faces: &'a [[u32; 3]],
    /// The input's unit face normals and face areas.
    pub normals: Vec<V3>,
    pub areas: Vec<f64>,
    /// Each vertex's faces in counter-clockwise order ([`star`]): `star_faces` from
    /// `star_start[v]` to `star_start[v + 1]`, and whether the vertex is on the border.
    star_start: Vec<u32>,
    star_faces: Vec<u32>,
    on_border: Vec<bool>,
    /// Each face's bounding box (region sizes are unions of them).
    face_box: Vec<[V3; 2]>,
    /// Each face's area moments (region fits are sums of them).
    moments: Vec<Moments>,
    /// The bounding-box diagonal of the vertices the faces use (the unit of every tolerance
    /// and of the relative errors).
    pub diag: f64,
    /// Which principal plane of a region's faces is its plane.
    pub rule: PlaneRule,
    /// The splits made so far by any realisation of this surface ([`Surface::split`]): by the
    /// fingerprint of the region's faces, whether it could be halved and the faces of the new
    /// half. The realisations of one run split the same regions again and again (the two of
    /// one partition share their start; a cascade retries a region): a fifth of the splits on
    /// the slowest meshes. With the count of faces held, kept under 64 per input face.
    splits: Mutex<(HashMap<u64, Halves>, usize)>,
}

/// A split made: the region's face count, whether it could be halved, and the faces of the
/// new half.
type Halves = (usize, bool, Vec<u32>);

impl<'a> Surface<'a> {
    /// The surface of `mesh`.
    pub fn new(topo: &'a Topology, mesh: &'a crate::mesh::TriMesh) -> Surface<'a> {
        let (pos, faces) = (&mesh.positions[..], &mesh.faces[..]);
        let (normals, areas) = super::geom::face_normals_areas(pos, faces);
        let diag = super::geom::bbox_diagonal(mesh);
        let mut star_start = vec![0u32];
        let mut star_faces = Vec::new();
        let mut on_border = Vec::with_capacity(topo.n_vertices);
        for v in 0..topo.n_vertices as u32 {
            let (fs, border) = star(topo, faces, v);
            star_faces.extend(fs);
            star_start.push(star_faces.len() as u32);
            on_border.push(border);
        }
        let face_box = faces
            .iter()
            .map(|f| bounds(f.map(|v| pos[v as usize])))
            .collect();
        Surface {
            topo,
            pos,
            faces,
            normals,
            areas,
            star_start,
            star_faces,
            on_border,
            face_box,
            moments: Moments::of_faces(topo, pos, faces),
            diag,
            rule: PlaneRule::LeastSquares,
            splits: Mutex::default(),
        }
    }

    /// Splits region `r` of `labels` in two, the new half labelled `n` (Lloyd;
    /// [`super::lloyd::halve`] under [`super::lloyd::Normals`]). False when it cannot be halved.
    ///
    /// The halves depend on the region's faces alone (every new label is above every old
    /// one, so the two compare the same way in any partition): a split made before is
    /// replayed from `splits`, the same labels.
    fn split(&self, labels: &mut [u32], r: u32, n: usize) -> bool {
        let faces: Vec<usize> = (0..labels.len()).filter(|&f| labels[f] == r).collect();
        let key = hash_of(&faces);
        // Replayed under the lock, without a copy of the record. Another region with the same
        // fingerprint (a collision) would not match: its faces are made afresh.
        if let Ok(m) = self.splits.lock() {
            let matches =
                |h: &&Halves| h.0 == faces.len() && h.2.iter().all(|&f| labels[f as usize] == r);
            if let Some((_, halved, new)) = m.0.get(&key).filter(matches) {
                for &f in new {
                    labels[f as usize] = n as u32;
                }
                return *halved;
            }
        }
        let metric = self.normals_metric();
        let halved =
            super::lloyd::halve_members(self.topo, &metric, labels, &faces, r, n as u32, 0);
        let new: Vec<u32> = faces
            .iter()
            .filter(|&&f| labels[f] == n as u32)
            .map(|&f| f as u32)
            .collect();
        if let Ok(mut m) = self.splits.lock() {
            if m.1 + new.len() <= 64 * labels.len() {
                m.1 += new.len();
                m.0.insert(key, (faces.len(), halved, new));
            }
        }
        halved
    }

    /// Face `f`'s area moments (its area-weighted centroid: [`Moments::centroid`]).
    pub fn moments(&self, f: usize) -> &Moments {
        &self.moments[f]
    }

    /// Whether regions `a` and `b` of `labels` (a region just halved) fit two planes better
    /// than one by more than the output's precision: their squared distance to their planes
    /// is lower than the union's to its plane by more than the tolerance squared over the
    /// area. Else the two planes are one at that precision (a flat region halved), and the
    /// corners where they meet a third plane are ill-conditioned.
    pub fn adds_a_plane(&self, labels: &[u32], a: u32, b: u32) -> bool {
        let mut halves = [Moments::default(); 2];
        for (f, &l) in labels.iter().enumerate() {
            if l == a || l == b {
                let h = &mut halves[usize::from(l == b)];
                *h = h.add(&self.moments[f]);
            }
        }
        let whole = halves[0].add(&halves[1]);
        let residual = |m: &Moments| m.fit(self.rule).map_or(0.0, |(_, r)| r);
        residual(&whole) - residual(&halves[0]) - residual(&halves[1])
            > self.tol() * self.tol() * whole.area()
    }

    /// VSA's L2,1 metric on the input's faces (what the realisation's splits follow).
    pub(super) fn normals_metric(&self) -> super::lloyd::Normals<'_> {
        super::lloyd::Normals {
            normals: &self.normals,
            areas: &self.areas,
        }
    }

    /// Corners closer than this are one point: 1e-6 of the diagonal, the output's planarity
    /// tolerance.
    fn tol(&self) -> f64 {
        1e-6 * self.diag
    }

    /// The faces around `v` in counter-clockwise order and whether `v` is on the border
    /// ([`star`]).
    fn star(&self, v: u32) -> (&[u32], bool) {
        let (a, b) = (self.star_start[v as usize], self.star_start[v as usize + 1]);
        (
            &self.star_faces[a as usize..b as usize],
            self.on_border[v as usize],
        )
    }
}

/// A fingerprint of a list of labels or faces (64 bits), for the sets of partitions seen or
/// tried and the record of splits.
pub(super) fn hash_of<T: std::hash::Hash>(list: &[T]) -> u64 {
    use std::hash::BuildHasher;
    foldhash::quality::FixedState::with_seed(0).hash_one(list)
}

/// The polygon mesh of the partition `labels` (regions `0..n`, each connected) with the
/// least-squares plane of each region's input faces, using at most `k` regions.
///
/// Validity first. While the partition cannot be realised ([`Defect`]):
/// - a region that touches itself at a vertex ([`Defect::Pinch`]) gives the smallest wedge
///   of its faces there to the neighbour beside it (`unpinch`), unless that returns to a
///   partition seen before;
/// - with fewer than `k` regions, the region the defect points at (an outline crossing
///   itself: its region; otherwise the named region that fits worst) is split in two: a finer
///   partition turns less per region, the usual cause (a curved part with too few planes to
///   meet near the surface);
/// - with `k`, the budget is taken where it costs least — the adjacent pair anywhere whose
///   merged plane fits worst by the least is merged — for that split, unless this returns to
///   a partition seen before (it would cycle);
/// - otherwise the two regions named by the defect (or one of them and a neighbour) whose
///   merged plane fits worst by the least are merged — or, with `give_away`, for an outline
///   crossing itself, its region is given away face by face to the regions around it
///   (`dissolve`) when that raises the residual less.
///
/// After the first merge, splits go on only on partitions not seen before, at most `k` times
/// more with budget left and `k` more as swaps; every merge removes a region, so this ends.
/// Then the budget left goes, while the result stays valid (a split that breaks it is undone
/// and that region left alone), to the worst-fitting region while a split cuts its residual
/// to a quarter (a curved region's), then to the boundaries of the given partition that
/// merges removed (`resplit`), then to the worst-fitting region while a split lowers its
/// residual at all (`spend_budget`). `Err` when a defect involves no pair of adjacent
/// regions left to merge, or [`Defect::Stopped`] once `stop` is set (a realisation made
/// beside another whose result may make it unnecessary).
///
/// Where that ends without a mesh after meeting a [`Defect::Handle`] (typically merges moved
/// the corner-less loop along a tunnel, region after region: a cascade), the search resumes
/// where it first met one, with handles closed: the polygons on both sides of such a loop
/// cover it. Only then: a closed handle keeps the tunnel's wall on the plane of a region
/// around it, where the splits and merges that answer it may fit the tunnel better.
pub fn realise(
    s: &Surface<'_>,
    labels: Vec<u32>,
    n: usize,
    k: usize,
    give_away: bool,
    stop: &AtomicBool,
) -> Result<Realised, Defect> {
    let start = Search {
        labels: labels.clone(),
        n,
        unsplittable: vec![false; n],
        ..Default::default()
    };
    match search(s, &labels, start, k, give_away, stop) {
        Err((d, Some(resume))) => {
            trace(|| format!("outline: resumed with handles closed (it ended at: {d})"));
            search(s, &labels, *resume, k, give_away, stop)
        }
        r => r,
    }
    .map_err(|(d, _)| d)
}

/// Where [`realise`]'s search stands: the partition, what was done to it, and the regions'
/// values kept across builds.
#[derive(Clone, Default)]
struct Search {
    labels: Vec<u32>,
    n: usize,
    defects: Vec<Defect>,
    splits: usize,
    merges: usize,
    unpinched: usize,
    late_splits: usize,
    swaps: usize,
    dissolved: usize,
    seen: HashSet<u64>,
    unsplittable: Vec<bool>,
    regions: Regions,
}

/// [`realise`] from `st`, `start_labels` the partition it was given; on failure, where to
/// resume with handles closed (see [`realise`]), if a handle was met.
fn search(
    s: &Surface<'_>,
    start_labels: &[u32],
    mut st: Search,
    k: usize,
    give_away: bool,
    stop: &AtomicBool,
) -> Result<Realised, (Defect, Option<Box<Search>>)> {
    let topo = s.topo;
    let mut resume = None;
    let stopped = || stop.load(Ordering::Relaxed);
    let mut polygons = loop {
        if stopped() {
            return Err((Defect::Stopped, None));
        }
        st.regions.update(s, &st.labels, st.n);
        let defect = match build_sized(s, &st.regions.planes(), &mut st.regions) {
            Ok(x) => break x,
            Err(d) => d,
        };
        trace(|| format!("outline: {} regions: {defect}", st.n));
        let (named, fits) = (defect.regions(), &st.regions);
        let fresh = st.seen.insert(hash_of(&st.labels));
        // The seen set rules out cycles of wedge moves; the count (one per vertex) bounds a
        // long walk through partitions not seen before.
        if let Defect::Pinch { vertex, twice, .. } = defect {
            let mut trial = st.labels.clone();
            if st.unpinched < topo.n_vertices
                && unpinch(s, &mut trial, vertex, twice)
                && !st.seen.contains(&hash_of(&trial))
            {
                st.labels = trial;
                st.unpinched += 1;
                st.defects.push(defect);
                continue;
            }
        }
        // The first handle met: where to resume with handles closed should the search end
        // without a mesh.
        if matches!(defect, Defect::Handle { .. }) && resume.is_none() {
            let mut at = st.clone();
            at.regions.close_handles = true;
            at.defects.push(defect.clone());
            resume = Some(Box::new(at));
        }
        // Splits answer defects before the first merge, and after it on partitions not met
        // before, up to `k` more times with budget left and `k` more with none (a swap: the
        // cheapest merge elsewhere pays for the split): a region that turns too much is made
        // worse by merging its neighbours into it. The two are counted apart because they
        // are different moves — a swap keeps the region count, a late split raises it — and
        // the caps end the alternation of splits and merges.
        // The regions sharing an edge, made once per defect when first asked for.
        let pairs = std::cell::OnceCell::new();
        let pairs = || pairs.get_or_init(|| st.regions.adjacent_pairs(topo));
        let used = if st.n < k {
            &mut st.late_splits
        } else {
            &mut st.swaps
        };
        if st.merges == 0 || (fresh && *used < k) {
            if st.merges > 0 {
                *used += 1;
            }
            if let Some(r) = split_target(&defect, &named, fits, &st.unsplittable) {
                if st.n < k {
                    if s.split(&mut st.labels, r, st.n) {
                        st.n += 1;
                        st.splits += 1;
                        st.unsplittable.push(false);
                    } else {
                        st.unsplittable[r as usize] = true;
                    }
                    st.defects.push(defect);
                    continue;
                }
                let elsewhere = pairs()
                    .iter()
                    .copied()
                    .filter(|(a, b)| !named.contains(a) && !named.contains(b));
                if let (true, Some((keep, gone))) = (fresh, fits.cheapest(elsewhere)) {
                    let mut trial = st.labels.clone();
                    merge(&mut trial, keep, gone);
                    let moved = if r > gone { r - 1 } else { r };
                    if s.split(&mut trial, moved, st.n - 1) {
                        st.labels = trial;
                        st.unsplittable.remove(gone as usize);
                        st.unsplittable.push(false);
                        st.splits += 1;
                    } else {
                        st.unsplittable[r as usize] = true;
                    }
                    st.defects.push(defect);
                    continue;
                }
            }
        }
        let pairs = pairs();
        let both: Vec<(u32, u32)> = pairs
            .iter()
            .copied()
            .filter(|(a, b)| named.contains(a) && named.contains(b))
            .collect();
        let pick = if both.is_empty() {
            fits.cheapest(
                pairs
                    .iter()
                    .copied()
                    .filter(|(a, b)| named.contains(a) || named.contains(b)),
            )
        } else {
            fits.cheapest(both.into_iter())
        };
        // A region whose outline crosses itself turns too much for its plane, and so does
        // its union with a neighbour: it is given away to the regions around it instead,
        // where that costs less. (Other defects are in how several planes meet; a merge
        // takes one of them out of the junction.)
        let given = match &defect {
            Defect::Outline { region, .. } if give_away => {
                dissolve(s, fits, *region).map(|d| (*region, d))
            }
            _ => None,
        };
        let merge_cost = pick.map_or(f64::INFINITY, |p| fits.merge_cost(p));
        match (pick, given) {
            (_, Some((r, (trial, cost)))) if cost < merge_cost => {
                st.labels = trial;
                st.unsplittable.remove(r as usize);
                st.dissolved += 1;
                trace(|| format!("outline: region {r} given away"));
            }
            (Some((keep, gone)), _) => {
                merge(&mut st.labels, keep, gone);
                st.unsplittable.remove(gone as usize);
            }
            _ => return Err((defect, resume)),
        }
        st.n -= 1;
        st.merges += 1;
        st.defects.push(defect);
    };
    // The budget left: first where it removes curvature (a split that keeps at most a
    // quarter of the region's residual), then the boundaries the merges removed, then wherever
    // it lowers the residual at all.
    let before = st.n;
    let normals = s.normals_metric();
    let spend = |st: &mut Search, keep| spend_budget(s, st, k, keep, &normals, stop);
    polygons = spend(&mut st, 0.25).unwrap_or(polygons);
    // Then the boundaries of the given partition that the realisation merged away, where
    // they are realisable now.
    let mut tried = HashSet::new();
    while st.n < k && !stopped() {
        let Some(built) = resplit(s, &mut st, start_labels, &mut tried) else {
            break;
        };
        polygons = built;
    }
    // Regions left alone at a quarter are tried again at any gain.
    st.unsplittable = vec![false; st.n];
    polygons = spend(&mut st, 1.0).unwrap_or(polygons);
    // Stopped while spending the budget: the phases ended early, the result is not this
    // partition's realisation.
    if stopped() {
        return Err((Defect::Stopped, None));
    }
    st.regions.update(s, &st.labels, st.n);
    Ok(Realised {
        polygons,
        planes: st.regions.planes(),
        labels: st.labels,
        defects: st.defects,
        splits: st.splits + st.n - before,
        merges: st.merges,
        unpinched: st.unpinched,
        dissolved: st.dissolved,
        plane_halvings: 0,
        closes_handles: st.regions.close_handles,
    })
}

/// Spends the budget `r` left (fewer than `k` regions) on halvings of its regions into the
/// two planes that fit each best ([`super::lloyd::halve`] under [`super::lloyd::Planes`]: the
/// cut lies where the two planes meet, so the edge their polygons share is where the faces
/// were), worst fit first, each kept where the partition stays realisable; the number of
/// regions added (`r.plane_halvings`, counted in `r.splits` too). `r`'s planes become its
/// regions' least-squares planes where any was added.
///
/// Why a second halving: [`realise`] halves across the regions' normals (the cut where the
/// normal turns, which curvature asks for); when none of those can be realised, budget left is
/// error left on the table, and the two-plane halving of a region may be realisable where its
/// normals' is not — its cut follows where its planes meet.
/// A region whose halving across its main direction cannot be realised is halved across the
/// second one too (why: [`super::lloyd::Planes`]'s `AXES`).
pub fn spend_on_two_planes(s: &Surface<'_>, r: &mut Realised, k: usize) -> usize {
    let before = r.planes.len();
    let mut st = Search {
        labels: std::mem::take(&mut r.labels),
        n: before,
        unsplittable: vec![false; before],
        ..Default::default()
    };
    st.regions.close_handles = r.closes_handles;
    let planes = super::lloyd::Planes {
        moments: &s.moments,
        rule: s.rule,
    };
    if let Some(b) = spend_budget(s, &mut st, k, 1.0, &planes, &AtomicBool::new(false)) {
        r.polygons = b;
        r.planes = fit_planes(s, &st.labels, st.n);
    }
    r.labels = st.labels;
    let added = st.n - before;
    r.splits += added;
    r.plane_halvings += added;
    added
}

/// Spends the budget left (`st.n` of `k` regions used) on the worst-fitting region while its
/// halving under `metric` ([`super::lloyd::halve`], its [`super::lloyd::Metric::AXES`]
/// directions tried in turn) keeps at most `keep` of its residual and the partition stays
/// realisable; a region whose split fails either way is not tried again (`unsplittable`). The
/// polygon mesh of the last split kept.
///
/// Why `keep`: a region curved in one direction, halved across it, keeps 1/16 of its
/// residual (the sagitta of a half is a quarter); a flat noisy one keeps most of it (each
/// half's plane fits three more degrees of freedom of the noise: 0.75 on the noisy cube's
/// sides, BENCHMARKS round 10). With `keep` = 1/4 the budget goes to curvature first; with 1
/// what is left goes wherever it lowers the error — which is what the error at K planes asks
/// for, once curvature and the boundaries the merges removed have had theirs.
fn spend_budget<M: super::lloyd::Metric>(
    s: &Surface<'_>,
    st: &mut Search,
    k: usize,
    keep: f64,
    metric: &M,
    stop: &AtomicBool,
) -> Option<PolygonMesh> {
    let Search {
        labels,
        n,
        unsplittable,
        regions,
        ..
    } = st;
    let mut last = None;
    regions.update(s, labels, *n);
    let mut fit = regions.fit.clone();
    while *n < k && !stop.load(Ordering::Relaxed) {
        let Some(worst) = (0..*n)
            .filter(|&r| !unsplittable[r] && fit[r].1 > 0.0)
            .max_by(|&a, &b| fit[a].1.total_cmp(&fit[b].1))
        else {
            break;
        };
        let was = fit[worst].1;
        let tried = (0..M::AXES).find_map(|axis| {
            let (mut trial, c, new) = (labels.clone(), worst as u32, *n as u32);
            if !super::lloyd::halve(s.topo, metric, &mut trial, c, new, axis) {
                return None;
            }
            regions.update(s, &trial, *n + 1);
            let kept = regions.fit[worst].1 + regions.fit[*n].1;
            if kept > keep * was || kept >= was {
                return None;
            }
            let built = build_sized(s, &regions.planes(), regions).ok()?;
            // The residuals of the kept split (building does not change them).
            Some((trial, built, regions.fit.clone()))
        });
        match tried {
            Some((trial, b, after)) => {
                *labels = trial;
                *n += 1;
                fit = after;
                unsplittable.push(false);
                last = Some(b);
            }
            None => unsplittable[worst] = true,
        }
    }
    last
}

/// Restores one boundary of the given partition `start` inside a region of `st.labels`
/// (`st.n` regions) that keeps the partition realisable: the part of a region of `start` that
/// a region of `st.labels` holds, connected, with the rest of that region connected, becomes
/// region `st.n` (one more region). Candidates go by the residual they remove, largest
/// first; each is built once (`tried`, keyed by its faces). The polygon mesh of the first
/// valid one, `None` when none is.
///
/// Why: the realisation answers a defect with a merge when no split is left to answer it,
/// and each merge makes a larger region whose next defect is likelier (the cascade). The
/// partition given to it fits like VSA's; once the partition is valid, the boundaries the
/// merges removed are the natural splits to spend the budget on — many of them are
/// realisable in the new surroundings, where the defect that removed them is gone.
fn resplit(
    s: &Surface<'_>,
    st: &mut Search,
    start: &[u32],
    tried: &mut HashSet<u64>,
) -> Option<PolygonMesh> {
    let face_moments = &s.moments[..];
    let Search {
        labels, regions, ..
    } = st;
    let n = st.n;
    regions.update(s, labels, n);
    let fits = &*regions;
    // Each connected part of a given region that one region holds, unless it is all of it
    // (whether the rest stays connected is checked when the candidate is tried).
    let pieces = parts(
        s.topo,
        labels.len(),
        |_| true,
        |f, g| labels[f] == labels[g] && start[f] == start[g],
    );
    let mut candidates: Vec<(f64, Vec<u32>)> = Vec::new();
    for part in pieces {
        let r = labels[part[0] as usize] as usize;
        let pm = part
            .iter()
            .fold(Moments::default(), |m, &f| m.add(&face_moments[f as usize]));
        if pm.area >= fits.moments[r].area * (1.0 - 1e-12) {
            continue; // the whole region
        }
        let rest = fits.moments[r].sub(&pm);
        let gain = fits.fit[r].1 - fits.fit_of(&pm).1 - fits.fit_of(&rest).1;
        candidates.push((gain, part));
    }
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    for (gain, part) in candidates {
        if gain.is_nan() || gain <= 0.0 {
            break;
        }
        let key = {
            let mut p = part.clone();
            p.sort_unstable();
            hash_of(&p)
        };
        if !tried.insert(key) {
            continue;
        }
        let r = labels[part[0] as usize];
        let mut trial = labels.to_vec();
        for &f in &part {
            trial[f as usize] = n as u32;
        }
        if region_parts(s.topo, &trial, r).len() != 1 {
            continue;
        }
        regions.update(s, &trial, n + 1);
        if let Ok(built) = build_sized(s, &regions.planes(), regions) {
            *labels = trial;
            st.n += 1;
            return Some(built);
        }
    }
    None
}

/// Each region's plane: its faces' principal plane that the surface's rule picks (the
/// least-squares one unless the draws fell back to [`PlaneRule::Facing`]).
pub fn fit_planes(s: &Surface<'_>, labels: &[u32], n: usize) -> Vec<Plane> {
    Regions::of(s, labels, n).planes()
}

/// Connected components of the mesh without and with a border: a polygon mesh of it needs at
/// least four polygons per closed one (a tetrahedron) and one per open one, since a region is
/// connected.
pub fn components(topo: &Topology) -> (usize, usize) {
    let mut open = vec![false; topo.components];
    for &e in &topo.boundary_edges {
        let f = topo.edge_faces[e as usize][0];
        open[topo.component_of_face[f as usize] as usize] = true;
    }
    let n_open = open.iter().filter(|&&o| o).count();
    (topo.components - n_open, n_open)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `test` on the unit cube's surface (3×3 squares a side) with the side of each face.
    fn on_cube(test: impl FnOnce(&Surface<'_>, &[u32])) {
        let (m, t, sides) = crate::approx::testing::cube(3);
        test(&Surface::new(&t, &m), &sides);
    }

    /// A split replayed from the surface's record gives the labels the split gave, and a
    /// region of the same faces under other labels (another partition) is split alike.
    #[test]
    fn a_replayed_split_is_the_split_made() {
        on_cube(|s, sides| {
            // Two sides as one region: a bent region, split across its edge.
            let bent = |r: u32| -> Vec<u32> {
                sides
                    .iter()
                    .map(|&x| if x <= 1 { r } else { x + 10 })
                    .collect()
            };
            let mut first = bent(0);
            assert!(s.split(&mut first, 0, 20));
            let halves = |l: &[u32], a: u32| -> Vec<bool> { l.iter().map(|&x| x == a).collect() };
            assert!(halves(&first, 20).contains(&true) && halves(&first, 0).contains(&true));
            let mut again = bent(0);
            assert!(s.split(&mut again, 0, 20));
            assert_eq!(again, first);
            // Another label, made afresh on a surface with no record.
            on_cube(|fresh, _| {
                let mut other = bent(5);
                assert!(fresh.split(&mut other, 5, 30));
                assert_eq!(halves(&other, 30), halves(&first, 20));
            });
        });
    }

    /// `Regions` kept across label changes gives exactly (bit for bit) what summing every
    /// region afresh gives, the merge costs pricing every pair afresh gives, the pairs of
    /// adjacent regions every edge gives, and the boundary loops that tracing every region
    /// afresh gives
    /// (traced again only where a region's faces changed): after a split (two regions
    /// change), a merge (one region grows, the ones after the removed one are renumbered), a
    /// relabelling that swaps two regions' numbers, and a face moved between regions.
    #[test]
    fn regions_kept_across_changes_equal_regions_summed_afresh() {
        on_cube(|s, sides| {
            let mut regions = Regions::default();
            let same = |regions: &mut Regions, labels: &[u32], n: usize| {
                regions.update(s, labels, n);
                // Summed here, face by face, not by `Regions`.
                let mut fresh = vec![Moments::default(); n];
                for (f, &r) in labels.iter().enumerate() {
                    fresh[r as usize] = fresh[r as usize].add(&s.moments[f]);
                }
                let kept = &*regions;
                for r in 0..n {
                    let faces: Vec<u32> = (0..labels.len() as u32)
                        .filter(|&f| labels[f as usize] == r as u32)
                        .collect();
                    assert_eq!(kept.members[r], faces, "region {r}'s faces");
                    assert_eq!(kept.moments[r], fresh[r], "region {r}");
                    let fit = fit_or_flat(&fresh[r], s.rule);
                    assert_eq!(kept.fit[r].1.to_bits(), fit.1.to_bits());
                    assert_eq!(kept.fit[r].0.n, fit.0.n);
                }
                let sizes: Vec<f64> = (0..n as u32)
                    .map(|r| {
                        let mut b = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
                        for (fb, _) in s.face_box.iter().zip(labels).filter(|x| *x.1 == r) {
                            for k in 0..3 {
                                b[0][k] = b[0][k].min(fb[0][k]);
                                b[1][k] = b[1][k].max(fb[1][k]);
                            }
                        }
                        let d = sub(b[1], b[0]);
                        dot(d, d).sqrt()
                    })
                    .collect();
                assert_eq!(regions.sizes(), sizes);
                // Every pair's merge cost (cached across updates) as priced afresh.
                let afresh = Regions::of(s, labels, n);
                // The pairs, from every edge of the mesh.
                let mut pairs: Vec<(u32, u32)> = (s.topo.interior_edges.iter())
                    .map(|&e| s.topo.edge_faces[e as usize].map(|f| labels[f as usize]))
                    .filter(|[a, b]| a != b)
                    .map(|[a, b]| (a.min(b), a.max(b)))
                    .collect();
                pairs.sort_unstable();
                pairs.dedup();
                assert_eq!(regions.adjacent_pairs(s.topo), pairs);
                for pair in pairs {
                    let (c, d) = (regions.merge_cost(pair), afresh.merge_cost(pair));
                    assert_eq!(c.to_bits(), d.to_bits(), "pair {pair:?}");
                }
                regions.trace_loops(s);
                let all: Vec<u32> = (0..labels.len() as u32).collect();
                let traced = region_loops(s.topo, s.faces, labels, n, &vec![true; n], &all);
                for (r, loops) in traced.iter().enumerate() {
                    assert_eq!(regions.loops[r].as_ref(), Some(loops), "region {r}'s loops");
                }
            };
            let mut labels = sides.to_vec();
            same(&mut regions, &labels, 6);
            // Region 2 split: every other face of it becomes region 6.
            for (f, l) in labels.iter_mut().enumerate() {
                if *l == 2 && f % 2 == 0 {
                    *l = 6;
                }
            }
            same(&mut regions, &labels, 7);
            merge(&mut labels, 0, 1);
            same(&mut regions, &labels, 6);
            for l in labels.iter_mut() {
                *l = match *l {
                    3 => 4,
                    4 => 3,
                    x => x,
                };
            }
            same(&mut regions, &labels, 6);
            let f = labels.iter().position(|&l| l == 5).unwrap();
            labels[f] = 0;
            same(&mut regions, &labels, 6);
        });
    }

    /// Two triangles on different planes whose corners 2 and 3 are one point: the polygons
    /// would touch there, and the defect names the input's two vertices.
    #[test]
    fn corners_on_touching_input_vertices_name_them() {
        let (o, x, y, z) = ([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]);
        let positions = vec![x, y, o, o, scale(y, -1.0), z];
        let faces = vec![[0, 1, 2], [3, 4, 5]];
        let m = crate::mesh::TriMesh { positions, faces };
        let t = Topology::build(&m, std::path::Path::new("touching")).unwrap();
        let s = Surface::new(&t, &m);
        let (labels, regions) = ([0, 1], vec![0, 1]);
        let planes = fit_planes(&s, &labels, 2);
        let touching = Defect::Touching {
            vertices: [2, 3],
            regions,
        };
        assert_eq!(build(&s, &labels, &planes, false).err(), Some(touching));
    }

    /// The boundary loops pass through each inner vertex once per run of one region's faces
    /// around it (what `corners` relies on to skip the vertices between two regions): on the
    /// cube's sides (three runs at a corner, two along an edge), and under labels that make
    /// regions meet themselves around vertices.
    #[test]
    fn loops_pass_each_vertex_once_per_run_of_a_region_around_it() {
        on_cube(|s, sides| {
            let mixed: Vec<u32> = (0..sides.len() as u32).map(|f| f % 3).collect();
            let halves: Vec<u32> = sides.iter().map(|&x| x % 2).collect();
            // Runs met (the cube's corners and edges, and pinches under the mixed labels).
            let mut met = HashSet::new();
            for labels in [sides.to_vec(), mixed, halves] {
                let n = labels.iter().max().map_or(0, |&m| m as usize + 1);
                let all: Vec<u32> = (0..labels.len() as u32).collect();
                let loops = region_loops(s.topo, s.faces, &labels, n, &vec![true; n], &all);
                let passes = loop_passes(s.topo.n_vertices, loops.iter());
                for v in 0..s.topo.n_vertices as u32 {
                    let (fs, border) = s.star(v);
                    assert!(!border);
                    let mut runs: Vec<u32> = fs.iter().map(|&f| labels[f as usize]).collect();
                    runs.dedup();
                    if runs.len() > 1 && runs.first() == runs.last() {
                        runs.pop();
                    }
                    let runs = if runs.len() == 1 { 0 } else { runs.len() };
                    assert_eq!(passes[v as usize] as usize, runs, "vertex {v}");
                    met.insert(runs);
                }
            }
            let many = met.iter().any(|&r| r > 3);
            assert!([0, 2, 3].iter().all(|r| met.contains(r)) && many, "{met:?}");
        });
    }

    /// A realisation whose stop flag is set gives no polygon mesh (its result is not wanted);
    /// the same partition unstopped gives the cube.
    #[test]
    fn a_stopped_realisation_gives_no_mesh() {
        on_cube(|s, sides| {
            let stopped = realise(s, sides.to_vec(), 6, 6, true, &AtomicBool::new(true));
            assert_eq!(stopped.err(), Some(Defect::Stopped));
            let r = realise(s, sides.to_vec(), 6, 6, true, &AtomicBool::new(false)).unwrap();
            assert_eq!(r.polygons.polygons.len(), 6);
        });
    }

    /// A side of the cube cut in two adds no plane (both halves lie on the side's plane); two
    /// sides that meet at an edge, as the halves of one region, do.
    #[test]
    fn a_flat_region_halved_adds_no_plane_and_a_bent_one_does() {
        on_cube(|s, sides| {
            let mut labels = sides.to_vec();
            for (f, l) in labels.iter_mut().enumerate() {
                if *l == 0 && f % 2 == 0 {
                    *l = 6;
                }
            }
            assert!(labels.contains(&6) && labels.contains(&0));
            assert!(!s.adds_a_plane(&labels, 0, 6));
            assert!(s.adds_a_plane(sides, 0, 1));
        });
    }

    /// The cube with two sides that meet at an edge (x = 0 and y = 0) merged into one region,
    /// realised at K = 5, then one more region allowed: the two-plane halving splits the bent
    /// region at the cube's edge (its faces' centroids spread most across it), each half on
    /// its side's plane; with every region exact, nothing is left to gain.
    #[test]
    fn two_plane_halving_splits_a_bent_region_at_its_edge() {
        on_cube(|s, sides| {
            let merged: Vec<u32> = sides
                .iter()
                .map(|&x| [0, 1, 0, 2, 3, 4][x as usize])
                .collect();
            let mut r = realise(s, merged, 5, 5, true, &Default::default()).unwrap();
            assert_eq!(r.planes.len(), 5);
            assert_eq!(spend_on_two_planes(s, &mut r, 6), 1);
            assert_eq!((r.planes.len(), r.plane_halvings, r.splits), (6, 1, 1));
            assert_eq!(r.polygons.polygons.len(), 6);
            // The regions are the sides: one label per side, six different ones.
            let mut label_of = [u32::MAX; 6];
            for (f, face) in s.faces.iter().enumerate() {
                let l = &mut label_of[sides[f] as usize];
                if *l == u32::MAX {
                    *l = r.labels[f];
                }
                assert_eq!(*l, r.labels[f], "face {f}");
                let plane = r.planes[r.labels[f] as usize];
                for &v in face {
                    let d = plane.signed_distance(s.pos[v as usize]);
                    assert!(d.abs() < 1e-9, "face {f} vertex {v}: {d}");
                }
            }
            label_of.sort_unstable();
            assert!(label_of.windows(2).all(|w| w[0] < w[1]), "{label_of:?}");
            assert_eq!(spend_on_two_planes(s, &mut r, 7), 0);
        });
    }

    /// The Euler characteristic of a polygon mesh, counted on its bridged polygons, is the
    /// surface's: the cube's six squares give 2 (a sphere); a square with a square hole, one
    /// polygon with the hole bridged in, gives 0 (an annulus: 8 corners, 8 edges, one face with
    /// one hole).
    #[test]
    fn euler_characteristic_counts_a_bridged_hole_as_a_hole() {
        on_cube(|s, sides| {
            let poly = build(s, sides, &fit_planes(s, sides, 6), false).unwrap();
            assert_eq!(poly.euler_characteristic(), 2);
        });
        let square = |r: f64| [[-r, -r], [r, -r], [r, r], [-r, r]];
        let pts: Vec<[f64; 2]> = square(2.0)
            .into_iter()
            .chain(square(1.0).into_iter().rev())
            .collect();
        let bridged = bridge_holes(&[0, 1, 2, 3], vec![vec![4, 5, 6, 7]], &|c| pts[c as usize]);
        assert_eq!(bridged.len(), 10);
        let mesh = PolygonMesh {
            positions: pts.iter().map(|p| [p[0], p[1], 0.0]).collect(),
            polygons: vec![bridged],
            region: vec![0],
            holes: 1,
            ..Default::default()
        };
        assert_eq!(mesh.euler_characteristic(), 0);
    }

    /// The cube's six sides given, two of them merged in the partition realised: the lost
    /// boundary is restored (the six squares on the cube's eight corners), then nothing is
    /// left to restore.
    #[test]
    fn resplit_restores_a_boundary_the_realisation_merged_away() {
        on_cube(|s, sides| {
            // Sides 0 (x = 0) and 2 (y = 0) share an edge: one region, the others after it.
            let labels: Vec<u32> = sides
                .iter()
                .map(|&q| match q {
                    0 | 2 => 0,
                    1 => 1,
                    q => q - 1,
                })
                .collect();
            let (mut st, mut tried) = (Search::default(), HashSet::new());
            (st.labels, st.n) = (labels, 5);
            let poly = resplit(s, &mut st, sides, &mut tried).unwrap();
            assert_eq!(poly.polygons.len(), 6);
            assert_eq!(poly.positions.len(), 8);
            assert!(poly.polygons.iter().all(|p| p.len() == 4));
            // The same partition as the sides, up to numbering.
            let pairs: HashSet<(u32, u32)> = st
                .labels
                .iter()
                .copied()
                .zip(sides.iter().copied())
                .collect();
            assert_eq!((pairs.len(), st.n), (6, 6), "{pairs:?}");
            assert!(resplit(s, &mut st, sides, &mut tried).is_none());
        });
    }

    /// A band of faces folded over the cube's edge between the sides x = 1 and z = 1, given
    /// away: each face returns to its own side (whose plane holds it exactly), and the
    /// residual falls by the band's.
    #[test]
    fn dissolve_gives_each_face_to_the_neighbour_whose_plane_it_is_on() {
        on_cube(|s, sides| {
            let centroid = |f: &[u32; 3]| {
                let p = f.map(|v| s.pos[v as usize]);
                [0, 1, 2].map(|i| (p[0][i] + p[1][i] + p[2][i]) / 3.0)
            };
            let labels: Vec<u32> = s
                .faces
                .iter()
                .zip(sides)
                .map(|(f, &q)| {
                    let c = centroid(f);
                    match q {
                        1 if c[2] > 2.0 / 3.0 => 6,
                        5 if c[0] > 2.0 / 3.0 => 6,
                        q => q,
                    }
                })
                .collect();
            let fits = Regions::of(s, &labels, 7);
            assert!(fits.fit[6].1 > 1e-4, "{:?}", fits.fit[6]);
            // The band's residual, per input vertex as the costs compare it.
            let band = fits.moments[6].per_vertex(fits.fit[6].1);
            let (out, grow) = dissolve(s, &fits, 6).unwrap();
            assert_eq!(out, sides);
            assert!((grow + band).abs() < 1e-9 * band, "{grow} {band}");
        });
    }

    #[test]
    fn the_faces_share_out_each_input_vertex_once() {
        on_cube(|s, _| {
            let total: f64 = s.moments.iter().map(|m| m.weight).sum();
            assert!((total - s.pos.len() as f64).abs() < 1e-9 * total, "{total}");
            // Per vertex: the residual per unit area times the vertices per unit area.
            let all = s.moments.iter().fold(Moments::default(), |a, m| a.add(m));
            assert_eq!(all.per_vertex(2.0), 2.0 * total / all.area());
        });
    }

    #[test]
    fn unpinch_moves_one_wedge_and_keeps_every_region_connected() {
        // 5×5 vertices: vertex 12, the centre, has six faces around it and a ring around those.
        let (m, t) = crate::approx::testing::grid(5);
        let (s, v) = (Surface::new(&t, &m), 12);
        let (fs, border) = s.star(v);
        assert!(!border);
        assert_eq!(fs.len(), 6);
        // Region 0 is the ring around the star and two single faces of it, opposite each
        // other: connected through the ring, touching itself at v.
        let mut labels = vec![0u32; m.faces.len()];
        for (&f, l) in fs.iter().zip([1, 1, 0, 2, 2, 0]) {
            labels[f as usize] = l;
        }
        for r in 0..3 {
            assert_eq!(region_parts(&t, &labels, r).len(), 1, "region {r}");
        }
        assert!(unpinch(&s, &mut labels, v, 0));
        let around: Vec<u32> = fs.iter().map(|&f| labels[f as usize]).collect();
        let runs_of_0 = (0..6)
            .filter(|&i| around[i] == 0 && around[(i + 5) % 6] != 0)
            .count();
        assert_eq!(runs_of_0, 1, "around v: {around:?}");
        for r in 0..3 {
            assert_eq!(region_parts(&t, &labels, r).len(), 1, "region {r}");
        }
        // Only one face changed region: the wedge, to a neighbour beside it.
        let moved = fs
            .iter()
            .zip([1, 1, 0, 2, 2, 0])
            .filter(|(&f, l)| labels[f as usize] != *l)
            .count();
        assert_eq!(moved, 1);
    }

    #[test]
    fn a_region_touching_itself_once_is_left_alone() {
        // 5×5 vertices: vertex 12, the centre, has six faces around it and a ring around those.
        let (m, t) = crate::approx::testing::grid(5);
        let s = Surface::new(&t, &m);
        let (fs, _) = s.star(12);
        let mut labels = vec![0u32; m.faces.len()];
        for (&f, l) in fs.iter().zip([1, 1, 1, 2, 2, 0]) {
            labels[f as usize] = l;
        }
        let before = labels.clone();
        assert!(!unpinch(&s, &mut labels, 12, 0));
        assert_eq!(labels, before);
    }
}
