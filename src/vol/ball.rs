//! The unit-ball target: the boundary surface onto the unit sphere, the interior harmonic,
//! then untangled with the boundary sliding on the sphere.
//!
//! The spherical embedding is built coarse to fine ([`super::progressive`]), so no protrusion
//! is crowded below the resolution of the coordinates, and relaxed on the sphere
//! ([`relax_on_sphere`]); a Tutte/stereographic embedding is the fallback should the
//! progressive one run out of resolution. Where the untangler finds no room for a few tets,
//! the mesh is refined there ([`slide_on_sphere`]: interior edges split, the surface kept).

use std::collections::HashSet;
use std::path::Path;

use super::energy::IDENTITY;
use super::harmonic::harmonic_extension;
use super::newton::{corners_of, newton, NewtonOptions, Objective, Pattern};
use super::progressive::{chordal_positive, progressive_embedding};
use super::tet::{cross, dot, is_positive, sub, TetMesh};
use super::untangle::{untangle_cells, untangle_sliding_protected, UntangleOptions};
use super::volmap::distortion_objective;
use super::Targets;
use super::VolError;
use crate::init::{tutte, TutteWeights};
use crate::mesh::{Topology, TriMesh};
use serde::Serialize;
use std::time::Instant;

/// The sphere positions of the boundary vertices (mesh indices) and the number of boundary
/// triangles whose chordal triangle is not positive seen from the centre (after the
/// relaxation, when `relax` is given).
pub fn sphere_embedding(
    mesh: &TetMesh,
    relax: Option<&NewtonOptions>,
) -> Result<(Targets, usize), VolError> {
    let faces = mesh.boundary_faces();
    let verts = mesh.boundary_vertices();
    let mut local = vec![u32::MAX; mesh.positions.len()];
    for (i, &v) in verts.iter().enumerate() {
        local[v as usize] = i as u32;
    }
    let lf: Vec<[u32; 3]> = faces.iter().map(|f| f.map(|v| local[v as usize])).collect();
    let lp: Vec<[f64; 3]> = verts.iter().map(|&v| mesh.positions[v as usize]).collect();
    let surf = TriMesh {
        positions: lp.clone(),
        faces: lf.clone(),
    };
    let topo = Topology::build(&surf, Path::new("boundary surface"))
        .map_err(|e| VolError::Input(e.to_string()))?;
    if topo.components != 1 || !topo.boundary_loops.is_empty() || topo.genus() != Some(0) {
        return Err(VolError::Input(format!(
            "--target ball needs a connected genus-0 boundary surface; this one is {}",
            topo.describe()
        )));
    }
    let t0 = Instant::now();
    let mut pos = match progressive_embedding(&lp, &lf, relax)? {
        Some(p) => p,
        None => tutte_stereographic(&lp, &lf, &topo)?,
    };
    let mut nbad = non_positive(&lf, &pos);
    if trace() {
        // Smallest chordal area of a face against its share of the sphere (4π · rest area /
        // total): how far the start crowds a protrusion.
        let area = |p: &[[f64; 3]], f: &[u32; 3]| {
            let [a, b, c] = f.map(|v| p[v as usize]);
            let nrm = cross(sub(b, a), sub(c, a));
            0.5 * dot(nrm, nrm).sqrt()
        };
        let total: f64 = lf.iter().map(|f| area(&lp, f)).sum();
        let crowd = lf
            .iter()
            .map(|f| area(&pos, f) * total / (4.0 * std::f64::consts::PI * area(&lp, f)))
            .fold(f64::INFINITY, f64::min);
        eprintln!(
            "sphere embedding: {nbad} non-positive faces, smallest area / share {crowd:.3e}, {:.2} s",
            t0.elapsed().as_secs_f64()
        );
    }
    if let Some(nopts) = relax {
        // Tets whose four corners are all on the boundary are placed by the surface
        // embedding alone: they belong to the surface problem.
        let surface_tets: Vec<[u32; 4]> = mesh
            .tets
            .iter()
            .filter(|t| t.iter().all(|&v| local[v as usize] != u32::MAX))
            .map(|t| t.map(|v| local[v as usize]))
            .collect();
        relax_on_sphere(
            &lp,
            &lf,
            &surface_tets,
            &mut pos,
            FaceReference::Rest,
            nopts,
        )?;
        nbad = non_positive(&lf, &pos);
    }
    Ok((verts.iter().zip(pos).map(|(&v, p)| (v, p)).collect(), nbad))
}

/// The number of faces whose chordal triangle is not positive seen from the centre.
fn non_positive(faces: &[[u32; 3]], p: &[[f64; 3]]) -> usize {
    faces
        .iter()
        .filter(|f| {
            let [a, b, c] = f.map(|v| p[v as usize]);
            !chordal_positive(a, b, c)
        })
        .count()
}

/// The fallback embedding, for a surface the progressive one cannot resolve: remove one
/// vertex's star (leaving a disk), Tutte-embed the disk in the unit disk (bijective, Tutte
/// 1963), and lift it to the sphere by inverse stereographic projection with the removed
/// vertex at the pole. Stereographic projection is a conformal bijection, so the spherical
/// triangles keep their orientation; a scale s of the disk (a Möbius dilation) is chosen by
/// bisection so the vertices' mean height is 0, otherwise the Tutte map crowds everything near
/// one pole. Long protrusions still crowd below f64 resolution (the reason for the
/// progressive embedding), so the faces left non-positive are counted by the caller.
fn tutte_stereographic(
    lp: &[[f64; 3]],
    lf: &[[u32; 3]],
    topo: &Topology,
) -> Result<Vec<[f64; 3]>, VolError> {
    // Pole: the vertex of highest degree (its removal leaves the roundest hole).
    let pole = (0..lp.len() as u32)
        .max_by_key(|&v| topo.vertex_faces(v).len())
        .unwrap_or(0);
    let disk: Vec<[u32; 3]> = lf.iter().copied().filter(|f| !f.contains(&pole)).collect();
    let dmesh = TriMesh {
        positions: lp.to_vec(),
        faces: disk.clone(),
    };
    let dtopo = Topology::build(&dmesh, Path::new("boundary surface minus a star"))
        .map_err(|e| VolError::Input(e.to_string()))?;
    let Some(lp_loop) = dtopo.boundary_loops.first() else {
        return Err(VolError::Input(
            "boundary surface: no disk after removing a star".into(),
        ));
    };
    let uv = tutte(lp, &disk, lp_loop, TutteWeights::MeanValue)?;
    let lift = |s: f64, mirror: bool| -> Vec<[f64; 3]> {
        (0..lp.len())
            .map(|i| {
                if i as u32 == pole {
                    return [0.0, 0.0, 1.0];
                }
                let a = s * uv[i][0];
                let b = s * uv[i][1] * if mirror { -1.0 } else { 1.0 };
                let r2 = a * a + b * b;
                [
                    2.0 * a / (1.0 + r2),
                    2.0 * b / (1.0 + r2),
                    (r2 - 1.0) / (r2 + 1.0),
                ]
            })
            .collect()
    };
    let mean_z = |p: &[[f64; 3]]| p.iter().map(|q| q[2]).sum::<f64>() / p.len() as f64;
    // Mean height grows with s: bisect log s.
    let (mut lo, mut hi) = (-12.0f64, 12.0f64);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if mean_z(&lift(mid.exp(), false)) > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let s = (0.5 * (lo + hi)).exp();
    let (p0, p1) = (lift(s, false), lift(s, true));
    Ok(if non_positive(lf, &p0) <= non_positive(lf, &p1) {
        p0
    } else {
        p1
    })
}

/// The reference shape of every face in [`relax_on_sphere`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaceReference {
    /// The rest face, scaled so that the rest surface has the sphere's area.
    Rest,
    /// An equilateral triangle of an equal share of the sphere's area: for faces whose shape
    /// means nothing, such as the coarse levels of [`super::progressive`], whose triangles
    /// join vertices far apart on the surface (a sliver there would be copied, not meant).
    EqualAreas,
}

/// Lowers the distortion of a fold-free spherical embedding `pos` of the surface (`rest`,
/// `faces`), every vertex sliding on the unit sphere, and keeps it fold-free.
///
/// Why: a Tutte or conformal embedding shrinks a protrusion's area exponentially in its
/// length-to-width ratio, to areas below the resolution of the coordinates), and tets
/// there are then numerically degenerate: det J and its gradient (the cofactors of a rank ≤ 1
/// Jacobian) both vanish, so no untangler can move them. Minimising a distortion that
/// penalises compression as much as stretch spreads every region to about its share of the
/// sphere's area.
///
/// How, with the machinery of the volume map: each face becomes the "cone" tet (centre, a, b,
/// c), positive exactly when the chordal triangle is positive seen from the centre, measured
/// against a reference tet made of the rest face scaled to the sphere's total area with the
/// apex at distance 1 below its centroid (the distance of a small chordal face from the
/// centre). Newton on that symmetric Dirichlet energy, with the centre fixed and the surface
/// vertices sliding, takes only fold-free steps (the flip-free line search of every tet), so
/// stopping at any iteration leaves a valid embedding: the cap is a time budget.
pub fn relax_on_sphere(
    rest: &[[f64; 3]],
    faces: &[[u32; 3]],
    surface_tets: &[[u32; 4]],
    pos: &mut [[f64; 3]],
    reference: FaceReference,
    opts: &NewtonOptions,
) -> Result<usize, VolError> {
    let n = pos.len();
    let centre = n as u32;
    let area = |f: &[u32; 3]| {
        let [a, b, c] = f.map(|v| rest[v as usize]);
        0.5 * dot(cross(sub(b, a), sub(c, a)), cross(sub(b, a), sub(c, a))).sqrt()
    };
    let total: f64 = faces.iter().map(area).sum();
    if !(total > 0.0 && total.is_finite()) {
        return Ok(0);
    }
    let k = (4.0 * std::f64::consts::PI / total).sqrt();
    // An equilateral triangle of an equal share of the sphere's area.
    let side = (16.0 * std::f64::consts::PI / (3f64.sqrt() * faces.len() as f64)).sqrt();
    let equilateral = [
        [0.0, 0.0, 0.0],
        [side, 0.0, 0.0],
        [0.5 * side, 0.5 * 3f64.sqrt() * side, 0.0],
    ];
    let mut d_dist = Vec::with_capacity(faces.len());
    let mut weight = Vec::with_capacity(faces.len());
    for f in faces {
        let [a, b, c] = match reference {
            FaceReference::Rest => f.map(|v| rest[v as usize]).map(|p| p.map(|q| k * q)),
            FaceReference::EqualAreas => equilateral,
        };
        let nrm = cross(sub(b, a), sub(c, a));
        let len = dot(nrm, nrm).sqrt();
        let apex = if len > 0.0 {
            let cen = [0, 1, 2].map(|r| (a[r] + b[r] + c[r]) / 3.0);
            [0, 1, 2].map(|r| cen[r] - nrm[r] / len)
        } else {
            return Ok(0); // a degenerate rest face: no reference shape, keep the embedding
        };
        // The tet (a, c, b, o): det[c − a, b − a, o − a] = det[a, b, c] for o = 0, computed
        // from edge vectors at a, so the sign of a tiny chordal triangle is not lost to the
        // cancellation of three unit vectors' determinant (the orientation checks and the
        // flip-free step bound use the first corner's edges).
        let Some((d, det)) = corners_of([a, c, b, apex]) else {
            return Ok(0);
        };
        d_dist.push(d);
        weight.push(det / 6.0);
    }
    let mut tets: Vec<[u32; 4]> = faces.iter().map(|f| [f[0], f[2], f[1], centre]).collect();
    // The mesh's tets with four boundary corners, against their rest shapes at the same scale
    // k: the embedding must make them positive too, or no interior can (an "ear" tet with two
    // boundary faces is positive only where the embedding is locally Delaunay across their
    // shared edge).
    for t in surface_tets {
        let Some((d, det)) = corners_of(t.map(|v| rest[v as usize].map(|q| k * q))) else {
            return Ok(0);
        };
        d_dist.push(d);
        weight.push(det.abs() / 6.0);
        tets.push(*t);
    }
    let mut x = pos.to_vec();
    x.push([0.0; 3]);
    let mut fixed = vec![false; n + 1];
    fixed[n] = true;
    let mut on_sphere = vec![true; n + 1];
    on_sphere[n] = false;
    // First the cones alone (their start is positive unless rounding flipped a crowded
    // triangle), then with the surface tets, which the relaxed embedding makes far easier to
    // untangle than the crowded one; a stage that cannot end fold-free keeps the previous one.
    let cones = faces.len();
    let mut iterations = 0;
    let stages = if tets.len() > cones {
        vec![cones, tets.len()]
    } else {
        vec![cones]
    };
    for cells in stages {
        let wsum: f64 = weight[..cells].iter().sum();
        let obj = Objective {
            tets: tets[..cells].to_vec(),
            weight: weight[..cells].iter().map(|w| w / wsum).collect(),
            d_fit: d_dist[..cells].to_vec(),
            d_dist: d_dist[..cells].to_vec(),
            guide: vec![IDENTITY; cells],
            omega: 0.0,
            targets: Vec::new(),
            lambda: 0.0,
            fixed: fixed.clone(),
            on_sphere: on_sphere.clone(),
        };
        let mut y = x.clone();
        if !obj.value(&y).is_finite() {
            // Inverted cells: untangle them, sliding, with the energy that is finite for
            // inverted cells.
            let s = untangle_cells(
                &obj.tets,
                obj.d_dist.clone(),
                obj.weight.clone(),
                &mut y,
                &obj.fixed,
                &obj.on_sphere,
                &UntangleOptions::default(),
                None,
            )?;
            if s.inverted > 0 || !obj.value(&y).is_finite() {
                if trace() {
                    eprintln!("sphere relax: the stage of {cells} cells was not untangled");
                    trace_surface_tets(faces, &tets[cones..cells.max(cones)], &y);
                }
                break;
            }
        }
        let pattern = Pattern::new(n + 1, &obj.tets);
        iterations += newton(&obj, &pattern, &mut y, opts, &mut |_, _| {})?.iterations;
        x = y;
        if trace() {
            trace_surface_tets(faces, &tets[cones..], &x);
        }
    }
    pos.copy_from_slice(&x[..n]);
    Ok(iterations)
}

fn trace() -> bool {
    std::env::var_os("FOLDFREE_VOL_TRACE").is_some()
}

/// Trace (`FOLDFREE_VOL_TRACE`): the tets with four boundary corners by their number of
/// boundary faces (0–4), and how many of each are inverted at `x`.
fn trace_surface_tets(faces: &[[u32; 3]], tets: &[[u32; 4]], x: &[[f64; 3]]) {
    let key = |mut f: [u32; 3]| {
        f.sort_unstable();
        f
    };
    let bset: std::collections::HashSet<[u32; 3]> = faces.iter().map(|f| key(*f)).collect();
    let (mut total, mut inverted) = ([0usize; 5], [0usize; 5]);
    for t in tets {
        let nb = [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]
            .iter()
            .filter(|c| bset.contains(&key(c.map(|i| t[i]))))
            .count();
        total[nb] += 1;
        if !is_positive(super::tet::det6(x, t)) {
            inverted[nb] += 1;
        }
    }
    eprintln!("sphere relax: surface tets by boundary faces {total:?}, inverted {inverted:?}");
}

/// Start map and constraints of the ball target: sphere boundary, harmonic interior.
pub fn ball_target(
    mesh: &TetMesh,
    relax: Option<&NewtonOptions>,
) -> Result<(Vec<[f64; 3]>, Targets, usize), VolError> {
    let (targets, nbad) = sphere_embedding(mesh, relax)?;
    let zero = vec![[0.0; 3]; mesh.positions.len()];
    let init = harmonic_extension(mesh, &zero, &targets)?;
    Ok((init, targets, nbad))
}

/// What the sliding untangler of the ball target did.
#[derive(Clone, Debug, Serialize)]
pub struct SlideReport {
    /// Inverted tets of the start (harmonic interior, boundary on the fixed embedding).
    pub inverted_start: usize,
    pub inverted_left: usize,
    pub iterations: usize,
    pub eps_updates: usize,
    pub seconds: f64,
    /// Newton steps of the distortion relaxation with the boundary sliding.
    pub relax_iterations: usize,
    pub relax_seconds: f64,
    /// δ_t of the untangled map, before the relaxation.
    pub delta_t_before_relax: Option<f64>,
    /// Interior edges split where the untangler left tets inverted, in order, as
    /// `[new vertex, a, b]`: the new vertex is appended, its rest position the midpoint of
    /// `a` and `b`, and every tet on the edge replaced by its halves
    /// ([`TetMesh::split_edges`]); empty: the output has the input's vertices and tets.
    pub splits: Vec<[u32; 3]>,
}

/// What [`slide_on_sphere`] returns.
#[derive(Clone, Debug)]
pub struct Slid {
    /// The mesh the map is of: the input, or the input refined (vertices and tets appended,
    /// see [`SlideReport::splits`]).
    pub mesh: TetMesh,
    pub map: Vec<[f64; 3]>,
    /// Where the boundary vertices ended: the constraints the map meets exactly.
    pub targets: Targets,
    pub report: SlideReport,
}

/// Largest |‖x‖ − 1| over the boundary vertices of `x`: 0 up to rounding when the boundary
/// lies on the unit sphere (the independent check of a ball map).
pub fn sphere_deviation(mesh: &TetMesh, x: &[[f64; 3]]) -> f64 {
    mesh.boundary_vertices()
        .iter()
        .map(|&v| (dot(x[v as usize], x[v as usize]).sqrt() - 1.0).abs())
        .fold(0.0, f64::max)
}

/// Untangles a start map of the ball target with the boundary vertices sliding on the unit
/// sphere (interior free), from `start` with its boundary put on the sphere targets first.
/// Returns the mesh the map is of, the map and its boundary positions — the constraints of
/// the rest of the pipeline, which it meets exactly — when no tet is left inverted
/// ([`Slid`]).
///
/// Where the sliding untangler stalls, up to `refine_rounds` rounds split interior edges
/// next to the folds ([`TetMesh::split_edges`], [`SlideReport::splits`]); the returned mesh is
/// then `mesh` refined (vertices and tets appended, the boundary surface unchanged), else
/// `mesh` itself.
///
/// Why: a fixed spherical embedding can invert tets whose four corners are all boundary
/// vertices (tets spanning a thin protrusion, placed by the surface embedding alone), and then
/// no map with that boundary exists. The sphere is the target, not one parametrisation of it,
/// so the boundary slides; the tets with three or four boundary corners that are positive at
/// the start are protected (see the comment at the call).
pub fn slide_on_sphere(
    mesh: &TetMesh,
    start: &[[f64; 3]],
    targets: &Targets,
    opts: &UntangleOptions,
    relax: Option<&NewtonOptions>,
    refine_rounds: usize,
    device: Option<&crate::gpu::Context>,
) -> Result<Slid, VolError> {
    let mut x = start.to_vec();
    let mut on_sphere = vec![false; x.len()];
    for (v, p) in targets {
        x[*v as usize] = *p;
        on_sphere[*v as usize] = true;
    }
    let inverted_start = mesh.inverted(&x).len();
    let boundary_edges = boundary_edges(mesh);
    let mut mesh = mesh.clone();
    let mut splits = Vec::new();
    let (mut iterations, mut outer, mut seconds) = (0, 0, 0.0);
    let mut untangle =
        |mesh: &TetMesh, x: &mut [[f64; 3]], on_sphere: &[bool], sliding: bool, full: bool| {
            // Tets with three or four boundary corners that are positive at the start keep the
            // barrier of the untangling energy's ε → 0 limit: sliding spreads the boundary where
            // the interior needs room, and without the barrier it also flattens such tets through
            // zero (a tet with four corners on the sphere, or three and an interior corner in the
            // thin lens under a small cap, has no interior side to escape to), after which no ε
            // brings them back.
            let protect: Vec<bool> = mesh
                .tets
                .iter()
                .map(|t| t.iter().filter(|&&v| on_sphere[v as usize]).count() >= 3)
                .collect();
            let fixed = if sliding {
                vec![false; x.len()]
            } else {
                on_sphere.to_vec()
            };
            // The fixed-boundary pass runs its whole ε schedule (no stall test): the tets it
            // leaves are the ones refined, so it should leave only those with no room.
            let o = UntangleOptions {
                stall_decades: if sliding && !full {
                    opts.stall_decades
                } else {
                    f64::INFINITY
                },
                ..*opts
            };
            let s = untangle_sliding_protected(mesh, x, &fixed, on_sphere, &protect, &o, device)?;
            (iterations, outer, seconds) = (
                iterations + s.iterations,
                outer + s.outer,
                seconds + s.seconds,
            );
            if trace() && s.inverted > 0 {
                let mut by = [0usize; 5];
                for t in mesh.inverted(x) {
                    by[mesh.tets[t]
                        .iter()
                        .filter(|&&v| on_sphere[v as usize])
                        .count()] += 1;
                }
                eprintln!(
                    "ball: the {} untangler left {} inverted tet(s); by boundary corners {by:?}",
                    if sliding { "sliding" } else { "fixed-boundary" },
                    s.inverted
                );
            }
            Ok::<_, VolError>(s)
        };
    let (input, x_start) = (mesh.clone(), x.clone());
    let mut s = untangle(&mesh, &mut x, &on_sphere, true, false)?;
    // Where the sliding untangler stalls, refine where the sphere leaves no room: the
    // interior edges of the tets it left inverted are split, and it goes on from there. When
    // a round does not reduce the folds (the sliding boundary can crush a boundary edge next
    // to a fold, measured 1/240 of its neighbours, and interior splits then only chase the
    // fold towards it), the refinement starts again from the input: the untangler with the
    // boundary fixed on the embedding, which cannot push a fold onto the surface, runs its
    // whole ε schedule, the interior edges of the tets it leaves inverted are split, and the
    // sliding untangler goes on from that result. Each round splits at least one edge and
    // the restart happens once, so the rounds end; their cap is a time budget (each is
    // another untangling).
    let (mut last, mut restarted) = (usize::MAX, false);
    for round in 0..refine_rounds {
        if s.inverted == 0 {
            break;
        }
        if s.inverted >= last && !restarted {
            // Splits next to the folds did not reduce them: start again from the input and
            // the start map, and let the untangler with the boundary fixed name the tets.
            restarted = true;
            mesh.clone_from(&input);
            x.clone_from(&x_start);
            on_sphere.truncate(x.len());
            splits.clear();
            let f = untangle(&mesh, &mut x, &on_sphere, false, true)?;
            if f.inverted == 0 {
                s = f;
                break;
            }
        }
        last = s.inverted;
        let edges = edges_to_split(&mesh, &mesh.inverted(&x), &boundary_edges);
        if edges.is_empty() {
            break;
        }
        let done = mesh.split_edges(&edges, &mut [&mut x]);
        if trace() {
            eprintln!(
                "ball: refinement round {round}: {} edge(s) split",
                done.len()
            );
        }
        on_sphere.resize(x.len(), false);
        splits.extend(done);
        s = untangle(&mesh, &mut x, &on_sphere, true, false)?;
    }
    if s.inverted > 0 {
        // Nothing (more) to refine: the stall test only hands over to refinement, so where
        // there is none the sliding untangler runs its whole ε schedule from here.
        s = untangle(&mesh, &mut x, &on_sphere, true, true)?;
    }
    let mut report = SlideReport {
        inverted_start,
        inverted_left: s.inverted,
        iterations,
        eps_updates: outer,
        seconds,
        splits,
        relax_iterations: 0,
        relax_seconds: 0.0,
        delta_t_before_relax: None,
    };
    // Then the distortion itself, boundary still sliding: the untangler stops at the first
    // fold-free map, whose tets at the tips of protrusions are squeezed on the sphere.
    if let (Some(nopts), 0) = (relax, s.inverted) {
        let t0 = Instant::now();
        let obj = distortion_objective(&mesh, vec![false; x.len()], on_sphere.clone())?;
        if !obj.value(&x).is_finite() {
            // The untangler's last ε left a tet positive by its own test but with a
            // distortion that overflows: keep the untangled map unrelaxed.
            let targets = targets.iter().map(|(v, _)| (*v, x[*v as usize])).collect();
            return Ok(Slid {
                mesh,
                map: x,
                targets,
                report,
            });
        }
        let pattern = Pattern::new(x.len(), &mesh.tets);
        report.delta_t_before_relax = Some(obj.tet_energy(&x));
        let st = newton(&obj, &pattern, &mut x, nopts, &mut |_, _| {})?;
        report.relax_iterations = st.iterations;
        report.relax_seconds = t0.elapsed().as_secs_f64();
    }
    let targets = targets.iter().map(|(v, _)| (*v, x[*v as usize])).collect();
    Ok(Slid {
        mesh,
        map: x,
        targets,
        report,
    })
}

/// The edges of the boundary surface, each as `[min, max]`.
fn boundary_edges(mesh: &TetMesh) -> HashSet<[u32; 2]> {
    mesh.boundary_faces()
        .iter()
        .flat_map(|f| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]])
        .map(|[a, b]| [a.min(b), a.max(b)])
        .collect()
}

/// The edges of the tets `near` that are not on the boundary surface, each once, ascending.
///
/// Why these: the untangler stalls with a few tets whose det tends to 0⁻ while ε shrinks,
/// the signature of a configuration with no room rather than a slow one. The tightest is a
/// chord (an interior edge with both ends on the sphere): its ends are pinned to the sphere,
/// and every tet around it must fit between the segment and the sphere, a lens of depth
/// ~ℓ²/8 for a chord of length ℓ. Split at its midpoint, an interior edge becomes two with
/// a free end, and every tet on it two halves with a free corner: refinement adds room where
/// the untangler found none, and (a map of a fine enough subdivision exists for any
/// homeomorphism) enough of it always does. Boundary edges are never split: the surface and
/// the constraints stay the input's (splitting them was tried: the folds next to a crushed
/// boundary edge only doubled). Only tets the untangler left inverted are refined, so a mesh
/// that maps without it is unchanged.
fn edges_to_split(
    mesh: &TetMesh,
    near: &[usize],
    boundary_edges: &HashSet<[u32; 2]>,
) -> Vec<[u32; 2]> {
    let mut out: Vec<[u32; 2]> = near
        .iter()
        .flat_map(|&t| {
            let t = mesh.tets[t];
            [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
                .map(|(i, j)| [t[i].min(t[j]), t[i].max(t[j])])
        })
        .filter(|e| !boundary_edges.contains(e))
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three tets around the axis 3–4 of a triangular bipyramid (all five vertices on the
    /// boundary, the axis a chord), one of them inverted in `x`.
    #[test]
    fn refinement_splits_interior_edges_of_the_folds_never_boundary_ones() {
        let mut m = crate::vol::tet::tests::bipyramid();
        let be = boundary_edges(&m);
        assert_eq!(be.len(), 9);
        assert!(!be.contains(&[3, 4]));
        let mut x = m.positions.clone();
        // The axis moved off the equator triangle past edge 0–1: tet 0 folds.
        x[4] = [0.6, 0.6, -0.5];
        let folds = m.inverted(&x);
        assert_eq!(folds, vec![0]);
        let edges = edges_to_split(&m, &folds, &be);
        assert_eq!(edges, vec![[3, 4]]);
        let done = m.split_edges(&edges, &mut [&mut x]);
        assert_eq!(done, vec![[5, 3, 4]]);
        // The same surface, and the new interior vertex gives the fold room: from a point
        // the (star-shaped) boundary is seen from, every tet is positive.
        assert_eq!(boundary_edges(&m), be);
        x[5] = [-0.1, -0.1, 0.1];
        assert!(m.inverted(&x).is_empty(), "{:?}", m.inverted(&x));
    }
}
