//! Untangling across region boundaries: every vertex near a fold moves inside the set that keeps
//! all of its planes exact, jointly with its neighbours.
//!
//! The per-region repairs of [`super::untangle`] move only interior vertices and keep each
//! region's outline; a fold whose outline crosses itself, or a face whose corners all lie on
//! region boundaries, is out of their reach. Here a vertex of one region has two degrees of
//! freedom (its plane), a vertex of two regions one (the line where the two planes meet), and a
//! vertex of three or more regions or on the mesh border none. The unknowns are those offsets;
//! every face that touches a moving vertex is measured in its own region's plane, against its
//! input shape, by the barrier energy of [`super::untangle2d`] — so a chain vertex sliding along
//! its line is pulled by the faces of both regions at once, and the outline itself untangles.
//! Moves are kept per neighbourhood only when that neighbourhood has fewer bad faces afterwards.

use super::cluster::vertex_clusters;
use super::geom::{add, cross, dot, norm, scale, sub, Frame, Plane, V3};
use super::untangle::{bad_faces, bad_faces_among, border_vertices, Layout};
use super::untangle2d::{
    minimise_rounds, triangle_det, triangle_energy, Barrier, Reference, Untangle2dOptions,
};
use crate::mesh::Topology;

/// A moving vertex: its start position and the 3D directions of its one or two unknowns.
struct Mover {
    vertex: usize,
    start: V3,
    dirs: Vec<V3>,
    /// Index of its first unknown in the flat vector.
    first: usize,
}

/// A face of the energy: corners as mover index or fixed position, region frame, reference.
struct Face {
    corners: [Result<usize, V3>; 3],
    frame: Frame,
    reference: Reference,
}

struct Problem<'a> {
    movers: &'a [Mover],
    faces: &'a [Face],
    theta: f64,
}

impl Problem<'_> {
    fn position(&self, x: &[f64], m: &Mover) -> V3 {
        m.dirs
            .iter()
            .enumerate()
            .fold(m.start, |p, (k, &d)| add(p, scale(d, x[m.first + k])))
    }

    fn corners(&self, x: &[f64], f: &Face) -> [[f64; 2]; 3] {
        f.corners.map(|c| {
            let p = match c {
                Ok(i) => self.position(x, &self.movers[i]),
                Err(p) => p,
            };
            f.frame.coords(p)
        })
    }
}

impl Barrier for Problem<'_> {
    fn eval(&self, x: &[f64], eps: f64, mut grad: Option<&mut [f64]>) -> f64 {
        if let Some(g) = grad.as_deref_mut() {
            g.iter_mut().for_each(|v| *v = 0.0);
        }
        let mut e = 0.0;
        let mut gq = [[0.0; 2]; 3];
        for f in self.faces {
            let q = self.corners(x, f);
            let Some(g) = grad.as_deref_mut() else {
                e += triangle_energy(&q, &f.reference, self.theta, eps, None);
                continue;
            };
            e += triangle_energy(&q, &f.reference, self.theta, eps, Some(&mut gq));
            for (c, corner) in f.corners.iter().enumerate() {
                let Ok(i) = *corner else { continue };
                // Chain rule: 2D corner gradient → 3D (in the face's plane) → the unknowns.
                let g3 = add(scale(f.frame.u, gq[c][0]), scale(f.frame.v, gq[c][1]));
                let m = &self.movers[i];
                for (k, &d) in m.dirs.iter().enumerate() {
                    g[m.first + k] += dot(g3, d);
                }
            }
        }
        e
    }

    fn min_det(&self, x: &[f64]) -> (f64, usize) {
        let mut m = f64::INFINITY;
        let mut inv = 0;
        for f in self.faces {
            let d = triangle_det(&self.corners(x, f), &f.reference);
            m = m.min(d);
            inv += usize::from(d <= 0.0);
        }
        (m, inv)
    }
}

/// What [`slide`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Slid {
    /// Neighbourhoods tried and kept.
    pub tried: usize,
    pub kept: usize,
}

/// Groups of bad faces whose `radius`-ring vertex neighbourhoods overlap, with those vertices.
fn neighbourhoods(
    topo: &Topology,
    faces: &[[u32; 3]],
    bad: &[usize],
    radius: usize,
) -> Vec<Vec<usize>> {
    let n = topo.n_vertices;
    let mut parent: Vec<usize> = (0..bad.len()).collect();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    let mut owner = vec![usize::MAX; n];
    let mut rings: Vec<Vec<usize>> = Vec::with_capacity(bad.len());
    for (b, &f) in bad.iter().enumerate() {
        let mut seen: Vec<usize> = faces[f].iter().map(|&v| v as usize).collect();
        let mut frontier = seen.clone();
        for _ in 0..radius {
            let mut next = Vec::new();
            for &v in &frontier {
                for &w in topo.neighbors(v as u32) {
                    if !seen.contains(&(w as usize)) {
                        seen.push(w as usize);
                        next.push(w as usize);
                    }
                }
            }
            frontier = next;
        }
        for &v in &seen {
            if owner[v] == usize::MAX {
                owner[v] = b;
            } else {
                let (ra, rb) = (root(&mut parent, owner[v]), root(&mut parent, b));
                parent[ra] = rb;
            }
        }
        rings.push(seen);
    }
    let mut groups: Vec<Vec<usize>> = vec![Vec::new(); bad.len()];
    for (b, ring) in rings.into_iter().enumerate() {
        let r = root(&mut parent, b);
        groups[r].extend(ring);
    }
    groups
        .into_iter()
        .filter(|g| !g.is_empty())
        .map(|mut g| {
            g.sort_unstable();
            g.dedup();
            g
        })
        .collect()
}

/// Moves the vertices within `radius` rings of each bad face inside their constraint sets (see
/// module doc); `input` gives the reference shapes. Planes and regions do not change. The
/// barrier runs are short (20 rounds of 100 L-BFGS iterations, ending after 4 without
/// progress): on the acceptance runs the default budget fixed no more faces, and a hopeless
/// neighbourhood (faces on fixed corners) would spend all of it.
#[allow(clippy::too_many_arguments)]
pub fn slide(
    topo: &Topology,
    faces: &[[u32; 3]],
    fc: &[u32],
    planes: &[Option<Plane>],
    input: &[V3],
    pos: &mut [V3],
    min_area: f64,
    radius: usize,
) -> Slid {
    let bad = bad_faces(pos, faces, fc, planes, min_area);
    if bad.is_empty() {
        return Slid::default();
    }
    let vc = vertex_clusters(topo, fc);
    let on_border = border_vertices(topo);
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
    slide_near(
        &layout,
        pos,
        &bad,
        radius,
        &Untangle2dOptions {
            max_rounds: 20,
            iterations: 100,
            stall_rounds: 4,
            ..Untangle2dOptions::default()
        },
    )
}

/// [`slide`] around the given `bad` faces of `layout`.
pub(crate) fn slide_near(
    layout: &Layout,
    pos: &mut [V3],
    bad: &[usize],
    radius: usize,
    opts: &Untangle2dOptions,
) -> Slid {
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
    let mut out = Slid::default();
    let frames: Vec<Option<Frame>> = planes
        .iter()
        .map(|p| p.and_then(|p| Frame::of(&p)))
        .collect();
    // Per region: input triangles scaled to the region's signed area in its plane, the area a
    // fold-free layout of it must cover.
    let (mut signed, mut area) = (vec![0.0; planes.len()], vec![0.0; planes.len()]);
    for (f, &c) in fc.iter().enumerate() {
        let c = c as usize;
        let [a, b, d] = faces[f].map(|v| input[v as usize]);
        area[c] += 0.5 * norm(cross(sub(b, a), sub(d, a)));
        if let Some(p) = planes[c] {
            let [a, b, d] = faces[f].map(|v| pos[v as usize]);
            signed[c] += 0.5 * dot(cross(sub(b, a), sub(d, a)), p.n);
        }
    }
    let region_scale: Vec<f64> = signed
        .iter()
        .zip(&area)
        .map(|(&s, &a)| {
            if s > 0.0 && a > 0.0 {
                (s / a).sqrt()
            } else {
                1.0
            }
        })
        .collect();
    for group in neighbourhoods(topo, faces, bad, radius) {
        let mut movers: Vec<Mover> = Vec::new();
        let mut mover_of = std::collections::HashMap::new();
        let mut unknowns = 0;
        for &v in &group {
            if on_border[v] {
                continue;
            }
            let dirs: Vec<V3> = match vc[v].as_slice() {
                [r] => match frames[*r as usize] {
                    Some(fr) => vec![fr.u, fr.v],
                    None => continue,
                },
                [a, b] => match (planes[*a as usize], planes[*b as usize]) {
                    (Some(pa), Some(pb)) => {
                        let d = cross(pa.n, pb.n);
                        // Nearly parallel planes: their line is ill-defined, keep the vertex.
                        if norm(d) < 1e-3 {
                            continue;
                        }
                        vec![scale(d, 1.0 / norm(d))]
                    }
                    _ => continue,
                },
                _ => continue,
            };
            mover_of.insert(v, movers.len());
            movers.push(Mover {
                vertex: v,
                start: pos[v],
                first: unknowns,
                dirs: dirs.clone(),
            });
            unknowns += dirs.len();
        }
        if movers.is_empty() {
            continue;
        }
        // Every face touching a mover, each once.
        let mut scope: Vec<usize> = movers
            .iter()
            .flat_map(|m| {
                topo.vertex_faces(m.vertex as u32)
                    .iter()
                    .map(|&f| f as usize)
            })
            .collect();
        scope.sort_unstable();
        scope.dedup();
        let mut efaces = Vec::with_capacity(scope.len());
        let mut usable = true;
        for &f in &scope {
            let c = fc[f] as usize;
            let (Some(frame), Some(reference)) = (frames[c], {
                let [a, b, d] = faces[f].map(|v| input[v as usize]);
                Reference::from_triangle(a, b, d, region_scale[c])
            }) else {
                usable = false;
                break;
            };
            efaces.push(Face {
                corners: faces[f]
                    .map(|v| mover_of.get(&(v as usize)).copied().ok_or(pos[v as usize])),
                frame,
                reference,
            });
        }
        if !usable {
            continue;
        }
        out.tried += 1;
        let before = bad_faces_among(pos, faces, fc, planes, min_area, &scope).len();
        let problem = Problem {
            movers: &movers,
            faces: &efaces,
            theta: opts.theta,
        };
        let mut x = vec![0.0; unknowns];
        minimise_rounds(&problem, &mut x, opts);
        for m in &movers {
            pos[m.vertex] = problem.position(&x, m);
        }
        let after = bad_faces_among(pos, faces, fc, planes, min_area, &scope).len();
        if after < before {
            out.kept += 1;
        } else {
            for m in &movers {
                pos[m.vertex] = m.start;
            }
        }
    }
    out
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::mesh::{Topology, TriMesh};

    /// The planes of the test "books": page A in z = 0 seen from +z, page B in y = 0 from +y.
    fn book_planes() -> Vec<Option<Plane>> {
        let p = |n: V3| Some(Plane { n, d: 0.0 });
        vec![p([0.0, 0.0, 1.0]), p([0.0, 1.0, 0.0])]
    }

    /// Two square regions meeting at a right angle along the x axis (a "book" of two pages,
    /// each a fan of 4 triangles around an interior vertex). The shared chain's middle vertex is
    /// pushed past its end along the crease line, which flips faces of both pages; neither
    /// page's interior can fix it, sliding the chain vertex back along the line does, and all
    /// vertices stay on their planes.
    #[test]
    fn slides_a_chain_vertex_back_along_its_line() {
        // Page A in the plane z = 0 (y ≥ 0), page B in the plane y = 0 (z ≥ 0).
        let positions = vec![
            [0.0, 0.0, 0.0], // 0 chain end
            [1.0, 0.0, 0.0], // 1 chain middle
            [2.0, 0.0, 0.0], // 2 chain end
            [0.0, 2.0, 0.0], // 3 page A
            [2.0, 2.0, 0.0], // 4 page A
            [1.0, 1.0, 0.0], // 5 page A centre
            [0.0, 0.0, 2.0], // 6 page B
            [2.0, 0.0, 2.0], // 7 page B
            [1.0, 0.0, 1.0], // 8 page B centre
        ];
        let faces: Vec<[u32; 3]> = vec![
            // page A, normal +z
            [0, 1, 5],
            [1, 2, 5],
            [2, 4, 5],
            [4, 3, 5],
            [3, 0, 5],
            // page B, normal +y
            [1, 0, 8],
            [2, 1, 8],
            [7, 2, 8],
            [6, 7, 8],
            [0, 6, 8],
        ];
        let mesh = TriMesh {
            positions: positions.clone(),
            faces: faces.clone(),
        };
        let topo = Topology::build(&mesh, std::path::Path::new("book")).unwrap();
        let fc = vec![0, 0, 0, 0, 0, 1, 1, 1, 1, 1];
        let planes = book_planes();
        let mut pos = positions.clone();
        pos[1] = [2.6, 0.0, 0.0];
        let min_area = 1e-12;
        let before = bad_faces(&pos, &faces, &fc, &planes, min_area).len();
        assert!(before >= 2, "{before}");
        let s = slide(
            &topo, &faces, &fc, &planes, &positions, &mut pos, min_area, 2,
        );
        assert_eq!(s.kept, 1);
        assert!(bad_faces(&pos, &faces, &fc, &planes, min_area).is_empty());
        assert!(pos[1][0] > 0.0 && pos[1][0] < 2.0, "{:?}", pos[1]);
        assert_eq!((pos[1][1], pos[1][2]), (0.0, 0.0));
        for (v, p) in pos.iter().enumerate() {
            for &c in &vertex_clusters(&topo, &fc)[v] {
                let d = planes[c as usize].unwrap().signed_distance(*p);
                assert!(d.abs() < 1e-12, "vertex {v} off plane {c}: {d}");
            }
        }
    }

    /// Deterministic numbers in [-1, 1) for random tangles.
    pub(crate) fn uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut rng = crate::linalg::rng::SplitMix(seed);
        move || rng.symmetric()
    }

    /// Positions, faces, face regions and region planes of a test layout.
    pub(crate) type Book = (Vec<V3>, Vec<[u32; 3]>, Vec<u32>, Vec<Option<Plane>>);

    /// A "book" of two n×n grid pages meeting at a right angle along the x axis.
    pub(crate) fn grid_book(n: usize) -> Book {
        let mut pos = Vec::new();
        // Row j = 0 is the shared spine; page A rows go +y (z = 0), page B rows go +z (y = 0).
        for i in 0..=n {
            pos.push([i as f64, 0.0, 0.0]);
        }
        for page in 0..2 {
            for j in 1..=n {
                for i in 0..=n {
                    let (x, t) = (i as f64, j as f64);
                    pos.push(if page == 0 { [x, t, 0.0] } else { [x, 0.0, t] });
                }
            }
        }
        let id = |page: usize, i: usize, j: usize| -> u32 {
            if j == 0 {
                i as u32
            } else {
                ((n + 1) * (1 + page * n + j - 1) + i) as u32
            }
        };
        let (mut faces, mut fc) = (Vec::new(), Vec::new());
        for page in 0..2 {
            for j in 0..n {
                for i in 0..n {
                    let (a, b, c, d) = (
                        id(page, i, j),
                        id(page, i + 1, j),
                        id(page, i + 1, j + 1),
                        id(page, i, j + 1),
                    );
                    // Page A is seen from +z, page B from +y: opposite windings along the spine.
                    if page == 0 {
                        faces.extend([[a, b, c], [a, c, d]]);
                    } else {
                        faces.extend([[b, a, c], [c, a, d]]);
                    }
                    fc.extend([page as u32; 2]);
                }
            }
        }
        let planes = book_planes();
        (pos, faces, fc, planes)
    }

    /// Random in-plane and along-the-spine perturbations: the bad-face count never goes up,
    /// every vertex stays on its planes, and moderate tangles are removed completely.
    #[test]
    fn never_adds_folds_and_keeps_planes() {
        let n = 6;
        let (input, faces, fc, planes) = grid_book(n);
        let mesh = TriMesh {
            positions: input.clone(),
            faces: faces.clone(),
        };
        let topo = Topology::build(&mesh, std::path::Path::new("grid book")).unwrap();
        let vc = vertex_clusters(&topo, &fc);
        let border = border_vertices(&topo);
        let mut rnd = uniform(12345);
        let mut cleared = 0;
        for trial in 0..12 {
            let amp = if trial < 6 { 0.9 } else { 2.5 };
            let mut pos = input.clone();
            for v in 0..pos.len() {
                if border[v] {
                    continue;
                }
                let mut d = [rnd() * amp, 0.0, 0.0];
                if vc[v].len() == 1 {
                    // In the page's plane: y for page A, z for page B.
                    d[if vc[v][0] == 0 { 1 } else { 2 }] = rnd() * amp;
                }
                pos[v] = add(pos[v], d);
            }
            let before = bad_faces(&pos, &faces, &fc, &planes, 1e-12).len();
            slide(&topo, &faces, &fc, &planes, &input, &mut pos, 1e-12, 2);
            let after = bad_faces(&pos, &faces, &fc, &planes, 1e-12).len();
            assert!(after <= before, "trial {trial}: {before} -> {after}");
            cleared += usize::from(before > 0 && after == 0);
            for (v, p) in pos.iter().enumerate() {
                for &c in &vc[v] {
                    let d = planes[c as usize].unwrap().signed_distance(*p);
                    assert!(
                        d.abs() < 1e-12,
                        "trial {trial}: vertex {v} off plane {c}: {d}"
                    );
                }
            }
        }
        assert!(
            cleared >= 3,
            "only {cleared} of the tangled trials were cleared"
        );
    }
}
