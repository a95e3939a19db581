//! Coarse-to-fine spherical embedding of a genus-0 surface (Praun & Hoppe 2003, "Spherical
//! parametrization and remeshing"; the crowding it avoids: Saba, Yavneh, Gotsman & Sheffer
//! 2005, "Practical spherical embedding of manifold triangle meshes").
//!
//! Why: a Tutte or conformal embedding shrinks a protrusion's area exponentially in its
//! length-to-width ratio, and on long ones (a tail, a horn) the chordal triangles fall below
//! the resolution of f64 coordinates on the unit sphere: their orientation is lost, and no
//! relaxation can start from them. Built coarse to fine, no triangle is ever much smaller than
//! its neighbours at its own level: the surface is simplified by edge collapses to a
//! tetrahedron, which is embedded exactly, and the vertices come back in reverse order, each
//! placed inside its ring (where every triangle around it is positive), the whole level
//! relaxed towards equal areas whenever the vertex count has doubled (the last level is left
//! to the caller, who relaxes it against the rest faces).
//!
//! The construction cannot produce a folded embedding: a vertex is only placed where all its
//! triangles are positive (such a place exists next to the vertex it was collapsed into, whose
//! triangles are positive, unless the two faces they share are exactly opposite there), and
//! the relaxation takes only fold-free steps. It can fail only by running out of resolution
//! in that search (None), and the caller then falls back to another embedding.

use super::ball::{relax_on_sphere, FaceReference};
use super::newton::NewtonOptions;
use super::tet::{cross, dot, is_positive, sub, to_unit_sphere};
use super::VolError;

/// One half-edge collapse u → v and what it changed: the faces it killed and the faces whose
/// corner u became v, each with its triple before the collapse.
struct Collapse {
    u: u32,
    v: u32,
    faces: Vec<(usize, [u32; 3])>,
}

/// Whether the chordal triangle (a, b, c) of points on the unit sphere is positive seen from
/// the centre. det[a, b, c] = det[b − a, c − a, a]: edge vectors keep the digits of a small
/// triangle that the cancellation in a·(b × c) would lose.
pub fn chordal_positive(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> bool {
    is_positive(dot(a, cross(sub(b, a), sub(c, a))))
}

/// The spherical embedding of the closed genus-0 surface (`rest`, `faces`): one point on the
/// unit sphere per vertex with every chordal triangle positive seen from the centre, or None
/// when a vertex found no such place (resolution exhausted) or the surface could not be
/// simplified to a tetrahedron (not a genus-0 closed manifold). `relax` is the Newton budget
/// of each level's relaxation ([`relax_on_sphere`], cones only).
pub fn progressive_embedding(
    rest: &[[f64; 3]],
    faces: &[[u32; 3]],
    relax: Option<&NewtonOptions>,
) -> Result<Option<Vec<[f64; 3]>>, VolError> {
    let nv = rest.len();
    let mut tri = faces.to_vec();
    let mut alive_face = vec![true; tri.len()];
    let mut vf: Vec<Vec<usize>> = vec![Vec::new(); nv];
    for (f, t) in tri.iter().enumerate() {
        for &v in t {
            vf[v as usize].push(f);
        }
    }
    let mut alive = nv;
    let mut rounds: Vec<Vec<Collapse>> = Vec::new();
    // Coarsening: rounds of independent collapses (a collapse locks its two ends and u's ring,
    // so the collapses of one round can be undone in any order), shortest rest edges first.
    while alive > 4 {
        let mut edges: Vec<(f64, u32, u32)> = Vec::new();
        for (f, t) in tri.iter().enumerate() {
            if !alive_face[f] {
                continue;
            }
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if a < b {
                    let d = sub(rest[a as usize], rest[b as usize]);
                    edges.push((dot(d, d), a, b));
                }
            }
        }
        edges.sort_by(|x, y| x.0.total_cmp(&y.0));
        let mut locked = vec![false; nv];
        let mut round = Vec::new();
        for &(_, a, b) in &edges {
            if alive - round.len() <= 4 {
                break;
            }
            if locked[a as usize] || locked[b as usize] {
                continue;
            }
            // u goes, v stays (the link condition below is symmetric in them).
            let (u, v) = (a, b);
            let ring_u = ring(&tri, &vf[u as usize], u);
            let ring_v = ring(&tri, &vf[v as usize], v);
            // Link condition: u and v share exactly the two vertices opposite their edge;
            // then the collapse leaves a triangulated sphere (Dey, Edelsbrunner, Guha &
            // Nekhayev 1999).
            if ring_u.iter().filter(|w| ring_v.contains(w)).count() != 2 {
                continue;
            }
            for &w in &ring_u {
                locked[w as usize] = true;
            }
            locked[u as usize] = true;
            locked[v as usize] = true;
            let mut changed = Vec::new();
            for f in std::mem::take(&mut vf[u as usize]) {
                changed.push((f, tri[f]));
                if tri[f].contains(&v) {
                    alive_face[f] = false;
                    for &w in &tri[f] {
                        if w != u {
                            vf[w as usize].retain(|&g| g != f);
                        }
                    }
                } else {
                    for c in tri[f].iter_mut() {
                        if *c == u {
                            *c = v;
                        }
                    }
                    vf[v as usize].push(f);
                }
            }
            round.push(Collapse {
                u,
                v,
                faces: changed,
            });
        }
        if round.is_empty() {
            return Ok(None);
        }
        alive -= round.len();
        rounds.push(round);
    }
    // The tetrahedron, exactly: its four vertices at a regular tetrahedron's, mirrored if the
    // assignment made it negative.
    let mut pos = vec![[0.0f64; 3]; nv];
    let mut present = vec![false; nv];
    let base: Vec<u32> = (0..nv as u32)
        .filter(|&v| !vf[v as usize].is_empty())
        .collect();
    if base.len() != 4 {
        return Ok(None);
    }
    let s = 1.0 / 3.0f64.sqrt();
    let corners = [[s, s, s], [s, -s, -s], [-s, s, -s], [-s, -s, s]];
    for (&v, c) in base.iter().zip(corners) {
        pos[v as usize] = c;
        present[v as usize] = true;
    }
    let Some(first) = (0..tri.len()).find(|&f| alive_face[f]) else {
        return Ok(None);
    };
    let t0 = tri[first].map(|v| pos[v as usize]);
    if !chordal_positive(t0[0], t0[1], t0[2]) {
        for p in pos.iter_mut() {
            p[0] = -p[0];
        }
    }
    let mut relaxed_at = 4;
    let mut count = 4;
    for round in rounds.iter().rev() {
        for c in round.iter().rev() {
            for &(f, t) in &c.faces {
                tri[f] = t;
                alive_face[f] = true;
            }
            let Some(p) = place(&tri, &c.faces, c.u, c.v, &pos) else {
                return Ok(None);
            };
            pos[c.u as usize] = p;
            present[c.u as usize] = true;
        }
        count += round.len();
        // The last level is the caller's, relaxed against the rest faces.
        if let Some(opts) = relax.filter(|_| count >= 2 * relaxed_at && count < nv) {
            relax_level(rest, &tri, &alive_face, &present, &mut pos, opts)?;
            relaxed_at = count;
        }
    }
    Ok(Some(pos))
}

/// The vertices of `u`'s faces other than u (each once).
fn ring(tri: &[[u32; 3]], faces: &[usize], u: u32) -> Vec<u32> {
    let mut r: Vec<u32> = faces
        .iter()
        .flat_map(|&f| tri[f])
        .filter(|&w| w != u)
        .collect();
    r.sort_unstable();
    r.dedup();
    r
}

/// A place on the sphere for `u` (collapsed into `v`) where all its faces are positive, the
/// best shaped one among a few candidates (largest smallest det / Σ edge², a scale-free
/// shape measure: placing u changes only u's faces, so a good place leaves no sliver for
/// later insertions to be trapped by).
///
/// Candidates: the centre of u's ring; points next to v — the faces u does not share with v
/// tend to v's faces there, which are positive, and the two it shares with v are positive to
/// first order exactly when the step from v has a positive component along the gradient of
/// each one's determinant (det[u, b, c] = u·(b × c), gradient b × c), which their sum of unit
/// tangent gradients has — and points between the first of those and the centre.
fn place(
    tri: &[[u32; 3]],
    changed: &[(usize, [u32; 3])],
    u: u32,
    v: u32,
    pos: &[[f64; 3]],
) -> Option<[f64; 3]> {
    let faces: Vec<usize> = changed.iter().map(|c| c.0).collect();
    let ring_u = ring(tri, &faces, u);
    let mut m = [0.0; 3];
    for &w in &ring_u {
        for r in 0..3 {
            m[r] += pos[w as usize][r];
        }
    }
    let centre = to_unit_sphere(m);
    let quality = |p: [f64; 3]| {
        faces
            .iter()
            .map(|&f| {
                let [a, b, c] = tri[f].map(|w| if w == u { p } else { pos[w as usize] });
                let det = dot(a, cross(sub(b, a), sub(c, a)));
                let e2 = |x: [f64; 3], y: [f64; 3]| dot(sub(x, y), sub(x, y));
                if is_positive(det) {
                    det / (e2(a, b) + e2(b, c) + e2(c, a))
                } else {
                    f64::NEG_INFINITY
                }
            })
            .fold(f64::INFINITY, f64::min)
    };
    let mut best: Option<([f64; 3], f64)> = None;
    let mut consider = |p: [f64; 3]| {
        let q = quality(p);
        if q > 0.0 && best.is_none_or(|b| q > b.1) {
            best = Some((p, q));
        }
        q > 0.0
    };
    if let Some(c) = centre {
        consider(c);
    }
    let pv = pos[v as usize];
    let mut d = [0.0; 3];
    for &f in faces.iter().filter(|&&f| tri[f].contains(&v)) {
        let t = tri[f];
        let k = t.iter().position(|&w| w == u)?;
        let g = cross(pos[t[(k + 1) % 3] as usize], pos[t[(k + 2) % 3] as usize]);
        let gn = dot(g, pv);
        let tangent = [0, 1, 2].map(|r| g[r] - gn * pv[r]);
        let len = dot(tangent, tangent).sqrt();
        if len > 0.0 {
            for r in 0..3 {
                d[r] += tangent[r] / len;
            }
        }
    }
    let dl = dot(d, d).sqrt();
    let reach = ring_u
        .iter()
        .map(|&w| {
            let e = sub(pos[w as usize], pv);
            dot(e, e).sqrt()
        })
        .sum::<f64>()
        / ring_u.len().max(1) as f64;
    if dl > 0.0 && reach > 0.0 {
        let mut first = None;
        let mut t = 0.5 * reach / dl;
        while t > 1e-17 * reach / dl {
            if let Some(q) = to_unit_sphere([0, 1, 2].map(|r| pv[r] + t * d[r])) {
                if consider(q) && first.is_none() {
                    first = Some(q);
                }
            }
            if first.is_some() && t < 1e-3 * reach / dl {
                break;
            }
            t *= 0.5;
        }
        if let (Some(p), Some(c)) = (first, centre) {
            for k in 1..8 {
                let s = k as f64 / 8.0;
                if let Some(q) = to_unit_sphere([0, 1, 2].map(|r| p[r] + s * (c[r] - p[r]))) {
                    consider(q);
                }
            }
        }
    }
    best.map(|b| b.0)
}

/// Relaxes the present vertices' embedding ([`relax_on_sphere`], cones only) on the live faces.
fn relax_level(
    rest: &[[f64; 3]],
    tri: &[[u32; 3]],
    alive_face: &[bool],
    present: &[bool],
    pos: &mut [[f64; 3]],
    opts: &NewtonOptions,
) -> Result<(), VolError> {
    let verts: Vec<u32> = (0..pos.len() as u32)
        .filter(|&v| present[v as usize])
        .collect();
    let mut local = vec![u32::MAX; pos.len()];
    for (i, &v) in verts.iter().enumerate() {
        local[v as usize] = i as u32;
    }
    let lf: Vec<[u32; 3]> = tri
        .iter()
        .zip(alive_face)
        .filter(|(_, &a)| a)
        .map(|(t, _)| t.map(|v| local[v as usize]))
        .collect();
    let lr: Vec<[f64; 3]> = verts.iter().map(|&v| rest[v as usize]).collect();
    let mut lp: Vec<[f64; 3]> = verts.iter().map(|&v| pos[v as usize]).collect();
    relax_on_sphere(&lr, &lf, &[], &mut lp, FaceReference::EqualAreas, opts)?;
    for (&v, p) in verts.iter().zip(lp) {
        pos[v as usize] = p;
    }
    Ok(())
}
