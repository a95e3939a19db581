//! Maps whose scale spans many decades: a "finger" (a tube on an annulus) stands in for the
//! corpus disks whose conformal start shrinks protrusions by orders of magnitude.

use std::path::Path;

use foldfree::init::InitMethod;
use foldfree::mesh::{self, Topology, TriMesh};
use foldfree::param::admm::{AdmmOptions, AdmmProblem};
use foldfree::param::Energy;

use crate::common::start_map;

/// A disk whose conformal map spans many orders of magnitude in scale: a flat annulus (radii
/// 3..1) with a tube of radius 1 and length `len` standing on its inner circle, closed by a
/// hemisphere, `n` vertices per ring. The conformal map shrinks the tube by about `e^−len`
/// (log-polar: one unit of tube length is one unit of log radius), so its faces' MIPS
/// curvature is ~`e^{2 len}` times the annulus's.
fn finger(n: usize, len: f64) -> TriMesh {
    use std::f64::consts::{FRAC_PI_2, TAU};
    let step = TAU / n as f64;
    let mut rings: Vec<(f64, f64)> = Vec::new();
    let na = ((2.0 / step) as usize).max(2);
    rings.extend((0..=na).map(|i| (3.0 - 2.0 * i as f64 / na as f64, 0.0)));
    let nt = (len / step) as usize;
    rings.extend((1..=nt).map(|i| (1.0, len * i as f64 / nt as f64)));
    let nc = ((FRAC_PI_2 / step) as usize).max(2);
    rings.extend((1..nc).map(|i| {
        let phi = FRAC_PI_2 * i as f64 / nc as f64;
        (phi.cos(), len + phi.sin())
    }));
    let mut positions = Vec::new();
    for &(r, z) in &rings {
        for k in 0..n {
            let a = step * k as f64;
            positions.push([r * a.cos(), r * a.sin(), z]);
        }
    }
    let apex = positions.len() as u32;
    positions.push([0.0, 0.0, len + 1.0]);
    let mut faces = Vec::new();
    let n32 = n as u32;
    for j in 0..rings.len() as u32 - 1 {
        for k in 0..n32 {
            let (a, b) = (j * n32 + k, j * n32 + (k + 1) % n32);
            let (c, d) = (a + n32, b + n32);
            faces.push([a, b, d]);
            faces.push([a, d, c]);
        }
    }
    let last = (rings.len() as u32 - 1) * n32;
    for k in 0..n32 {
        faces.push([last + k, last + (k + 1) % n32, apex]);
    }
    TriMesh { positions, faces }
}

/// The default pipeline (LSCM start, ADMM with the hand-off) on `finger(16, 8)`.
fn finger_map(energy: Energy) -> (TriMesh, Topology, foldfree::param::MapOutput) {
    let m = finger(16, 8.0);
    let (_, t) = mesh::validate::validate_with_topology(
        &m,
        Path::new("finger"),
        &mesh::ValidateOptions::default(),
    )
    .expect("the finger is a valid disk");
    let out = foldfree::param::compute_map(
        &m,
        &t,
        InitMethod::Lscm,
        foldfree::param::SolverChoice::Admm,
        true,
        &AdmmOptions::for_energy(energy),
        None,
        &mut |_| {},
    )
    .expect("map");
    (m, t, out)
}

// Found by the corpus sweep (benches/sweep.py): 24 of its 61 MIPS disks stalled at the μ cap and needed the hand-off (28254d1).
/// Per-face penalties ([`admm::cpu::penalty_factors`]): on a finger whose conformal map shrinks
/// the tube by ~e^−8 (faces 1e-7 of the annulus's area), MIPS ADMM from LSCM meets its own stop
/// test — no hand-off to the global solver — with a flip-free map. With one penalty for all
/// faces, the tube's faces (curvature ~1e7 × the annulus's) stayed uncoupled and the run
/// stalled at its μ cap (measured: 2 757 iterations, then the hand-off).
#[test]
fn admm_alone_converges_where_the_conformal_scale_spans_seven_decades() {
    use foldfree::param::SolverPath;
    let (m, t, out) = finger_map(Energy::Mips);
    let admm = out.admm.as_ref().expect("ADMM ran");
    let tube_scale = {
        let frames = mesh::frames::compute(&m);
        let p = AdmmProblem::new(&m, &t, &frames);
        let start = start_map(&m, &t, InitMethod::Lscm);
        let dets: Vec<f64> = (0..m.faces.len())
            .map(|f| foldfree::param::energy::det(&p.jacobian(&m.faces, &start, f)))
            .collect();
        dets.iter().copied().fold(f64::INFINITY, f64::min)
            / dets.iter().copied().fold(0.0, f64::max)
    };
    assert!(
        tube_scale < 1e-6,
        "the start map spans {tube_scale:e} in area scale"
    );
    assert_eq!(out.path, SolverPath::Admm, "{}", admm.stop_summary());
    assert!(admm.converged());
    assert_eq!(foldfree::init::count_flips(&m.faces, &out.uv), 0);
}

// Found by the corpus sweep (benches/sweep.py): 22 of its 61 SD disks needed the hand-off from the conformal start (bce5cd7).
/// SD's ADMM start ([`foldfree::param::compute_map`]): from the finger's conformal start, whose
/// tube SD wants ~e^8 times larger, a few proxy steps of the global solver move the area back
/// (each lowering the energy by more than 10 %), and ADMM converges from there without the
/// hand-off (measured: 7 proxy steps, then 1 125 ADMM iterations instead of 3 650 from the
/// conformal start).
#[test]
fn sd_admm_starts_from_proxy_steps_and_converges_alone() {
    use foldfree::param::SolverPath;
    let (m, _, out) = finger_map(Energy::SymmetricDirichlet);
    assert!(
        (1..=50).contains(&out.start_proxy_iterations),
        "{} proxy steps",
        out.start_proxy_iterations
    );
    assert_eq!(out.path, SolverPath::Admm, "{}", out.stop_summary());
    assert!(out.stop_summary().starts_with("start: "));
    assert_eq!(foldfree::init::count_flips(&m.faces, &out.uv), 0);
    let admm = out.admm.as_ref().expect("ADMM ran");
    assert!(
        admm.iterations < 3000,
        "{} ADMM iterations",
        admm.iterations
    );
}
