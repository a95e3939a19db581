//! The unit-ball target: the boundary surface onto the unit sphere, the interior harmonic.
//!
//! Spherical embedding of a genus-0 surface: remove one vertex's star (leaving a disk),
//! Tutte-embed the disk in the unit disk (bijective, Tutte 1963), and lift it to the sphere by
//! inverse stereographic projection with the removed vertex at the pole. Stereographic
//! projection is a conformal bijection, so the spherical triangles keep their orientation; a
//! scale s of the disk (a Möbius dilation) is chosen by bisection so the vertices' mean height
//! is 0, otherwise the Tutte map crowds everything near one pole. Chordal (flat) triangles of
//! a fine embedding are positive seen from the centre; the few that may not be are counted.

use std::path::Path;

use super::harmonic::harmonic_extension;
use super::newton::{newton, NewtonOptions, Pattern};
use super::tet::{cross, dot, is_positive, TetMesh};
use super::untangle::{untangle_sliding, UntangleOptions};
use super::volmap::distortion_objective;
use super::Targets;
use super::VolError;
use crate::init::{tutte, TutteWeights};
use crate::mesh::{Topology, TriMesh};
use serde::Serialize;
use std::time::Instant;

/// The sphere positions of the boundary vertices (mesh indices) and the number of boundary
/// triangles whose chordal triangle is not positive seen from the centre.
pub fn sphere_embedding(mesh: &TetMesh) -> Result<(Targets, usize), VolError> {
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
    let topo = Topology::build(&surf, Path::new("<boundary surface>"))
        .map_err(|e| VolError::Input(format!("boundary surface: {e}")))?;
    if topo.components != 1 || !topo.boundary_loops.is_empty() || topo.genus() != Some(0) {
        return Err(VolError::Input(format!(
            "--target ball needs a connected genus-0 boundary surface; this one is {}",
            topo.describe()
        )));
    }
    // Pole: the vertex of highest degree (its removal leaves the roundest hole).
    let pole = (0..lp.len() as u32)
        .max_by_key(|&v| topo.vertex_faces(v).len())
        .unwrap_or(0);
    let disk: Vec<[u32; 3]> = lf.iter().copied().filter(|f| !f.contains(&pole)).collect();
    let dmesh = TriMesh {
        positions: lp.clone(),
        faces: disk.clone(),
    };
    let dtopo = Topology::build(&dmesh, Path::new("<boundary surface minus a star>"))
        .map_err(|e| VolError::Input(format!("boundary surface: {e}")))?;
    let Some(lp_loop) = dtopo.boundary_loops.first() else {
        return Err(VolError::Input(
            "boundary surface: no disk after removing a star".into(),
        ));
    };
    let uv = tutte(&lp, &disk, lp_loop, TutteWeights::MeanValue)?;
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
    let bad = |p: &[[f64; 3]]| {
        lf.iter()
            .filter(|f| {
                let [a, b, c] = f.map(|v| p[v as usize]);
                !is_positive(dot(a, cross(b, c)))
            })
            .count()
    };
    let (p0, p1) = (lift(s, false), lift(s, true));
    let (b0, b1) = (bad(&p0), bad(&p1));
    let (pos, nbad) = if b0 <= b1 { (p0, b0) } else { (p1, b1) };
    Ok((verts.iter().zip(pos).map(|(&v, p)| (v, p)).collect(), nbad))
}

/// Start map and constraints of the ball target: sphere boundary, harmonic interior.
pub fn ball_target(mesh: &TetMesh) -> Result<(Vec<[f64; 3]>, Targets, usize), VolError> {
    let (targets, nbad) = sphere_embedding(mesh)?;
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
/// Returns the map and its boundary positions — the constraints of the rest of the pipeline,
/// which it meets exactly — when no tet is left inverted.
///
/// Why: a fixed spherical embedding can invert tets whose four corners are all boundary
/// vertices (tets spanning a thin protrusion, placed by the surface embedding alone), and then
/// no map with that boundary exists. The sphere is the target, not one parametrisation of it, so the boundary slides.
pub fn slide_on_sphere(
    mesh: &TetMesh,
    start: &[[f64; 3]],
    targets: &Targets,
    opts: &UntangleOptions,
    relax: Option<&NewtonOptions>,
) -> Result<(Vec<[f64; 3]>, Targets, SlideReport), VolError> {
    let mut x = start.to_vec();
    let mut on_sphere = vec![false; x.len()];
    for (v, p) in targets {
        x[*v as usize] = *p;
        on_sphere[*v as usize] = true;
    }
    let fixed = vec![false; x.len()];
    let inverted_start = mesh.inverted(&x).len();
    let s = untangle_sliding(mesh, &mut x, &fixed, &on_sphere, opts)?;
    let mut report = SlideReport {
        inverted_start,
        inverted_left: s.inverted,
        iterations: s.iterations,
        eps_updates: s.outer,
        seconds: s.seconds,
        relax_iterations: 0,
        relax_seconds: 0.0,
        delta_t_before_relax: None,
    };
    // Then the distortion itself, boundary still sliding: the untangler stops at the first
    // fold-free map, whose tets at the tips of protrusions are squeezed on the sphere.
    if let (Some(nopts), 0) = (relax, s.inverted) {
        let t0 = Instant::now();
        let obj = distortion_objective(mesh, fixed, on_sphere)?;
        let pattern = Pattern::new(x.len(), &mesh.tets);
        report.delta_t_before_relax = Some(obj.tet_energy(&x));
        let st = newton(&obj, &pattern, &mut x, nopts, &mut |_, _| {})?;
        report.relax_iterations = st.iterations;
        report.relax_seconds = t0.elapsed().as_secs_f64();
    }
    let slid = targets.iter().map(|(v, _)| (*v, x[*v as usize])).collect();
    Ok((x, slid, report))
}
