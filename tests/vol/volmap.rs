//! Volumetric maps (`foldfree::vol`): readers' located errors, the energy's derivatives, and
//! the pipeline on tiny tet meshes with known answers.

use std::path::Path;
use std::process::Command;

use crate::common::{data, TempDir};
use foldfree::vol::energy::mul3;
use foldfree::vol::newton::{corner_weights, Objective};
use foldfree::vol::untangle::{untangle, UntangleOptions};
use foldfree::vol::{evaluate, read_any, volmap, write_any, TetMesh, VolError, VolmapOptions};

/// A tet split into four around an interior vertex (index 4) at its centroid.
fn star_tet() -> TetMesh {
    let p = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.25, 0.25, 0.25],
    ];
    // Each sub-tet replaces one corner of (0, 1, 2, 3) by 4: orientation kept.
    let t = vec![[4, 1, 2, 3], [0, 4, 2, 3], [0, 1, 4, 3], [0, 1, 2, 4]];
    TetMesh::new(p, t)
}

/// The paper's pipeline only (the untangling stage has its own tests below).
fn quiet_options() -> VolmapOptions {
    VolmapOptions {
        untangle: None,
        ..VolmapOptions::default()
    }
}

#[test]
fn identity_stays_identity() {
    for name in ["single_tet.mesh", "cube_5tets.mesh"] {
        let m = read_any(&data(name)).unwrap();
        m.check_rest(&data(name)).unwrap();
        let targets: Vec<_> = m
            .boundary_vertices()
            .into_iter()
            .map(|v| (v, m.positions[v as usize]))
            .collect();
        let (x, r) = volmap(
            &m,
            &m.positions,
            &targets,
            &quiet_options(),
            &mut |_, _, _| {},
        )
        .unwrap();
        assert_eq!(r.inverted_output, 0);
        assert!(
            (r.quality.delta_t - 6.0).abs() < 1e-9,
            "{name}: {}",
            r.quality.delta_t
        );
        for (a, b) in x.iter().zip(&m.positions) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-9);
            }
        }
    }
    // With a free interior vertex the identity is still the optimum.
    let m = star_tet();
    let targets: Vec<_> = (0..4).map(|v| (v, m.positions[v as usize])).collect();
    let (x, r) = volmap(
        &m,
        &m.positions,
        &targets,
        &quiet_options(),
        &mut |_, _, _| {},
    )
    .unwrap();
    assert!((r.quality.delta_t - 6.0).abs() < 1e-8);
    assert!((x[4][0] - 0.25).abs() < 1e-6);
}

#[test]
fn single_inverted_tet_gets_fixed() {
    let m = star_tet();
    // Push the interior vertex through face (1, 2, 3): only tet 0 inverts.
    let mut init = m.positions.clone();
    init[4] = [0.5, 0.5, 0.5];
    assert_eq!(m.inverted(&init), vec![0]);
    let targets: Vec<_> = (0..4).map(|v| (v, init[v as usize])).collect();
    let (x, r) = volmap(&m, &init, &targets, &quiet_options(), &mut |_, _, _| {}).unwrap();
    assert_eq!(r.inverted_init, 1);
    assert_eq!(m.inverted(&x), Vec::<usize>::new());
    // The boundary is the identity, so the optimum is the identity: δ_t → 6.
    assert!(r.quality.delta_t < 6.0 + 1e-4, "{}", r.quality.delta_t);
    assert!(r.quality.rho < 1e-12);
}

#[test]
fn constraints_met_with_known_answer() {
    // Boundary mapped by the similarity 2·R (R a rotation about z): the optimum is that
    // similarity everywhere, D = 3·4 + 3/4 per tet, so δ_t = 12.75, the centroid maps to the
    // centroid.
    let m = star_tet();
    let (s, c) = (0.6f64.sin(), 0.6f64.cos());
    let r = [
        [2.0 * c, -2.0 * s, 0.0],
        [2.0 * s, 2.0 * c, 0.0],
        [0.0, 0.0, 2.0],
    ];
    let map = |p: [f64; 3]| {
        let q = mul3(&r, &[[p[0], 0.0, 0.0], [p[1], 0.0, 0.0], [p[2], 0.0, 0.0]]);
        [q[0][0] + 1.0, q[1][0] - 2.0, q[2][0] + 0.5]
    };
    let targets: Vec<_> = (0..4).map(|v| (v, map(m.positions[v as usize]))).collect();
    let (x, rep) = volmap(
        &m,
        &m.positions,
        &targets,
        &quiet_options(),
        &mut |_, _, _| {},
    )
    .unwrap();
    assert_eq!(rep.inverted_output, 0);
    assert!(rep.quality.rho < 1e-6, "ρ {}", rep.quality.rho);
    assert!(
        (rep.quality.delta_t - 12.75).abs() < 1e-6,
        "{}",
        rep.quality.delta_t
    );
    let want = map([0.25; 3]);
    for k in 0..3 {
        assert!((x[4][k] - want[k]).abs() < 1e-4);
    }
}

#[test]
fn objective_gradient_and_hessian_match_finite_differences() {
    let m = star_tet();
    // A guided objective with a non-trivial guide and ω > 0, at a stretched map (every
    // singular value > 1, so the projected Hessian equals the true one).
    let guide = [[1.1, 0.1, 0.0], [0.0, 0.9, 0.05], [0.02, 0.0, 1.05]];
    let ginv = foldfree::vol::energy::inv3(&guide).unwrap();
    let d_fit: Vec<_> = (0..4)
        .map(|t| corner_weights(&edge_inverse(&m, t)))
        .collect();
    let d_dist: Vec<_> = (0..4)
        .map(|t| corner_weights(&mul3(&edge_inverse(&m, t), &ginv)))
        .collect();
    let obj = Objective {
        tets: m.tets.clone(),
        weight: vec![0.25; 4],
        d_dist,
        d_fit,
        guide: vec![guide; 4],
        omega: 0.3,
        targets: vec![],
        lambda: 0.0,
        fixed: vec![false; 5],
        on_sphere: vec![],
    };
    let x: Vec<[f64; 3]> = m
        .positions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            [
                1.6 * p[0] + 0.01 * i as f64,
                1.5 * p[1],
                1.7 * p[2] - 0.01 * i as f64,
            ]
        })
        .collect();
    for t in 0..4 {
        let (e, g, h) = obj.tet_local(t, &x).unwrap();
        let tet = m.tets[t];
        let eval = |dx: usize, d: f64| {
            let mut y = x.clone();
            y[tet[dx / 3] as usize][dx % 3] += d;
            y
        };
        let single = |y: &[[f64; 3]]| {
            let mut o = obj.clone();
            o.weight = (0..4).map(|k| if k == t { 0.25 } else { 0.0 }).collect();
            o.value(y)
        };
        assert!((single(&x) - e).abs() < 1e-12 * e.abs().max(1.0));
        let eps = 1e-6;
        for i in 0..12 {
            let fd = (single(&eval(i, eps)) - single(&eval(i, -eps))) / (2.0 * eps);
            assert!(
                (fd - g[i]).abs() < 1e-6 * (1.0 + g[i].abs()),
                "grad {t} {i}: {fd} vs {}",
                g[i]
            );
            let gp = obj.tet_local(t, &eval(i, eps)).unwrap().1;
            let gm = obj.tet_local(t, &eval(i, -eps)).unwrap().1;
            for j in 0..12 {
                let fdh = (gp[j] - gm[j]) / (2.0 * eps);
                assert!(
                    (fdh - h[j][i]).abs() < 1e-5 * (1.0 + h[j][i].abs()),
                    "hess {t} {j} {i}: {fdh} vs {}",
                    h[j][i]
                );
            }
        }
    }
}

fn edge_inverse(m: &TetMesh, t: usize) -> foldfree::vol::energy::Mat3 {
    let tet = m.tets[t];
    let p = |k: usize| m.positions[tet[k] as usize];
    let mut d = [[0.0; 3]; 3];
    for c in 0..3 {
        for r in 0..3 {
            d[r][c] = p(c + 1)[r] - p(0)[r];
        }
    }
    foldfree::vol::energy::inv3(&d).unwrap()
}

#[test]
fn reader_errors_are_located() {
    let dir = TempDir::new("vol_reader_errors");
    let head = "MeshVersionFormatted 1\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n";
    let cases: Vec<(&str, String)> = vec![
        (
            "nan",
            format!("{head}0 0 NaN 0\nTetrahedra\n1\n1 2 3 4 0\nEnd\n"),
        ),
        (
            "trunc",
            format!("{head}0 0 1 0\nTetrahedra\n2\n1 2 3 4 0\n"),
        ),
        (
            "index",
            format!("{head}0 0 1 0\nTetrahedra\n1\n1 2 3 5 0\nEnd\n"),
        ),
        (
            "inverted",
            format!("{head}0 0 1 0\nTetrahedra\n1\n1 3 2 4 0\nEnd\n"),
        ),
        (
            "flat",
            format!("{head}1 1 0 0\nTetrahedra\n1\n1 2 3 4 0\nEnd\n"),
        ),
    ];
    for (name, text) in cases {
        let p = dir.join(&format!("{name}.mesh"));
        std::fs::write(&p, text).unwrap();
        let err = read_any(&p).and_then(|m| m.check_rest(&p));
        let msg = format!("{:?}", err);
        match (name, err) {
            (
                "nan",
                Err(VolError::NonFinite {
                    line: 8, vertex: 3, ..
                }),
            ) => {}
            ("trunc", Err(VolError::Truncated { .. })) => {}
            (
                "index",
                Err(VolError::BadIndex {
                    line: 11,
                    tet: 0,
                    index: 5,
                    ..
                }),
            ) => {}
            ("inverted", Err(VolError::InvertedRest { tet: 0, .. })) => {}
            ("flat", Err(VolError::ZeroVolume { tet: 0, .. })) => {}
            _ => panic!("{name}: unexpected {msg}"),
        }
        // Through the CLI: exit code 2 and the file named.
        let out = Command::new(env!("CARGO_BIN_EXE_foldfree"))
            .arg("volmap")
            .arg(&p)
            .arg("--init")
            .arg(&p)
            .arg("--fix-boundary")
            .arg("-o")
            .arg(dir.join("out.mesh"))
            .arg("-q")
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{name}");
        assert!(String::from_utf8_lossy(&out.stderr).contains(&format!("{name}.mesh")));
    }
}

#[test]
fn cli_writes_checked_output_and_report() {
    let dir = TempDir::new("vol_cli");
    let m = star_tet();
    let rest = dir.join("rest.mesh");
    let init = dir.join("init.node");
    write_any(&rest, &m, &m.positions).unwrap();
    let mut ip = m.positions.clone();
    ip[4] = [0.5, 0.5, 0.5];
    write_any(&init, &m, &ip).unwrap();
    let out = dir.join("out.mesh");
    let report = dir.join("r.json");
    let st = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .args(["volmap"])
        .arg(&rest)
        .arg("--init")
        .arg(&init)
        .arg("--fix-boundary")
        .arg("-o")
        .arg(&out)
        .arg("--report")
        .arg(&report)
        .arg("-q")
        .status()
        .unwrap();
    assert!(st.success());
    // Independent check from the written file.
    let written = read_any(&out).unwrap();
    assert_eq!(m.inverted(&written.positions).len(), 0);
    let targets: Vec<_> = (0..4).map(|v| (v, ip[v as usize])).collect();
    let q = evaluate(&m, &written.positions, &targets);
    assert!(q.rho < 1e-12 && q.delta_t < 6.0 + 1e-4);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["inverted_init"], 1);
    assert_eq!(r["inverted_output"], 0);
    assert!(r["phases"].as_array().unwrap().len() >= 2);
    // volcheck agrees and exits 0; on the folded init it exits 1.
    let ok = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .arg("volcheck")
        .arg(&out)
        .arg("--rest")
        .arg(&rest)
        .status()
        .unwrap();
    assert!(ok.success());
    let bad = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .arg("volcheck")
        .arg(&init)
        .arg("--rest")
        .arg(&rest)
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(1));
}

/// The default: untangling first.
fn untangle_options() -> VolmapOptions {
    VolmapOptions::default()
}

#[test]
fn untangle_stage_repairs_inverted_tet_with_boundary_exact() {
    // The interior vertex pushed through face (1, 2, 3): tets 0 inverted. The boundary is
    // the identity, so the untangled + post-optimised map is the identity (δ_t = 6), with
    // the constrained vertices bit-identical to their targets (ρ = 0, not just small).
    let m = star_tet();
    let mut init = m.positions.clone();
    init[4] = [0.5, 0.5, 0.5];
    assert_eq!(m.inverted(&init), vec![0]);
    let targets: Vec<_> = (0..4).map(|v| (v, init[v as usize])).collect();
    let (x, r) = volmap(&m, &init, &targets, &untangle_options(), &mut |_, _, _| {}).unwrap();
    assert!(r.phases[0].name.starts_with("untangle (0 inverted"));
    assert!(r.phases.iter().all(|p| !p.name.starts_with("deformation")));
    assert_eq!(r.inverted_output, 0);
    assert_eq!(r.quality.rho, 0.0);
    for (v, p) in &targets {
        assert_eq!(x[*v as usize], *p);
    }
    assert!(r.quality.delta_t < 6.0 + 1e-4, "{}", r.quality.delta_t);
    for k in 0..3 {
        assert!((x[4][k] - 0.25).abs() < 1e-2, "{:?}", x[4]);
    }
}

#[test]
fn untangle_reports_impossible_boundary() {
    // Corner 3 pushed through the opposite face: the boundary itself is inverted, so no
    // interior position makes all four tets positive and the untangler must say so
    // (and leave the fixed vertices alone).
    let m = star_tet();
    let mut x = m.positions.clone();
    x[3] = [0.2, 0.2, -1.0];
    let fixed = [true, true, true, true, false];
    let opts = UntangleOptions {
        max_outer: 20,
        ..UntangleOptions::default()
    };
    let s = untangle(&m, &mut x, &fixed, &opts).unwrap();
    assert!(s.inverted > 0);
    assert_eq!(m.inverted(&x).len(), s.inverted);
    assert_eq!(x[3], [0.2, 0.2, -1.0]);
    assert_eq!(x[0], [0.0, 0.0, 0.0]);
}

/// A fold no free vertex can repair, though one vertex is free: the six tets around the split
/// axis of a bipyramid, its poles pinned on the same side of the equator. The tets' dets sum
/// to six times the volume the pinned surface encloses, which is negative whatever the free
/// vertex does, so some tet stays inverted. The untangler must say so without running its
/// whole ε schedule (the stall test: no tet fixed over a decade of ε).
#[test]
fn untangle_stops_on_a_fold_no_free_vertex_can_repair() {
    // Equator 0–2, poles 3 (up) and 4 (down), the centre 5 on the split axis.
    let mut positions: Vec<[f64; 3]> = (0..3)
        .map(|k| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / 3.0;
            [a.cos(), a.sin(), 0.0]
        })
        .collect();
    positions.extend([[0., 0., 1.], [0., 0., -1.], [0., 0., 0.]]);
    let tets = [[3, 4, 1, 0], [3, 4, 2, 1], [3, 4, 0, 2]]
        .iter()
        .flat_map(|t| {
            [
                t.map(|v| if v == 4 { 5 } else { v }),
                t.map(|v| if v == 3 { 5 } else { v }),
            ]
        })
        .collect();
    let m = TetMesh::new(positions, tets);
    assert!(m.inverted(&m.positions).is_empty());
    let mut x = m.positions.clone();
    x[4] = [0., 0., 2.];
    let enclosed: f64 = (0..6).map(|t| m.volume_at(&x, t)).sum();
    assert!(enclosed < 0.0);
    let fixed = [true, true, true, true, true, false];
    let opts = UntangleOptions::default();
    let s = untangle(&m, &mut x, &fixed, &opts).unwrap();
    assert!(s.inverted > 0);
    assert_eq!(s.inverted, m.inverted(&x).len());
    assert!(s.outer < opts.max_outer, "{} ε rounds", s.outer);
    // Without the stall test the schedule runs to its cap.
    let mut y = m.positions.clone();
    y[4] = [0., 0., 2.];
    let never = UntangleOptions {
        stall_decades: f64::INFINITY,
        max_outer: 40,
        ..opts
    };
    assert_eq!(untangle(&m, &mut y, &fixed, &never).unwrap().outer, 40);
}

#[test]
fn untangle_gives_up_at_once_on_inverted_pinned_tet() {
    // Same folded boundary, but now every vertex is fixed: the inverted tets have all their
    // corners fixed and nothing can move, which the untangler reports without iterating.
    let m = star_tet();
    let mut x = m.positions.clone();
    x[3] = [0.2, 0.2, -1.0];
    let s = untangle(&m, &mut x, &[true; 5], &UntangleOptions::default()).unwrap();
    assert!(s.inverted_pinned > 0);
    assert_eq!(s.inverted, m.inverted(&x).len());
    assert_eq!(s.iterations, 0);
}

/// The ball target's boundary slides on the sphere: a start whose spherical embedding inverts
/// tets with all four corners on the boundary (no interior vertex can help) is untangled by
/// moving those corners along the sphere.
#[test]
fn ball_boundary_slides_to_untangle_all_boundary_tets() {
    use foldfree::vol::ball::{slide_on_sphere, sphere_deviation};
    let m = read_any(&data("cube_5tets.mesh")).unwrap();
    // The inscribed cube (a fold-free map onto the sphere), then corners 0 and 7 swapped:
    // every tet through either of them flips or degenerates.
    let s = 1.0 / 3f64.sqrt();
    let mut sphere: Vec<[f64; 3]> = m
        .positions
        .iter()
        .map(|p| p.map(|c| (2.0 * c - 1.0) * s))
        .collect();
    sphere.swap(0, 7);
    let targets: Vec<(u32, [f64; 3])> = (0..8).map(|v| (v, sphere[v as usize])).collect();
    assert!(!m.inverted(&sphere).is_empty(), "the test start must fold");
    let foldfree::vol::ball::Slid {
        mesh: refined,
        map: x,
        targets: slid,
        report: r,
    } = slide_on_sphere(
        &m,
        &sphere,
        &targets,
        &UntangleOptions::default(),
        None,
        8,
        None,
    )
    .unwrap();
    // No chord to split (every edge of the five tets is on the cube's surface).
    assert!(r.splits.is_empty());
    assert_eq!(refined, m);
    assert!(r.inverted_start > 0);
    assert_eq!(r.inverted_left, 0);
    assert!(m.inverted(&x).is_empty());
    assert!(sphere_deviation(&m, &x) < 1e-12);
    // The constraints returned are where the boundary ended, so the map meets them exactly.
    assert_eq!(evaluate(&m, &x, &slid).rho, 0.0);
    // With the sliding relaxation: still on the sphere and fold-free, distortion not higher.
    let relax = foldfree::vol::newton::NewtonOptions::default();
    let foldfree::vol::ball::Slid {
        map: y, report: r2, ..
    } = slide_on_sphere(
        &m,
        &sphere,
        &targets,
        &UntangleOptions::default(),
        Some(&relax),
        0,
        None,
    )
    .unwrap();
    assert!(m.inverted(&y).is_empty());
    assert!(sphere_deviation(&m, &y) < 1e-12);
    let before = r2.delta_t_before_relax.unwrap();
    let after = evaluate(&m, &y, &[]).delta_t;
    assert!(
        r2.relax_iterations > 0 && after < before,
        "{before} → {after}"
    );
}

#[test]
fn cli_ball_target_writes_constraints_volcheck_confirms() {
    let dir = TempDir::new("vol_ball");
    let m = star_tet();
    let rest = dir.join("rest.mesh");
    write_any(&rest, &m, &m.positions).unwrap();
    let out = dir.join("out.mesh");
    let cons = dir.join("c.txt");
    let st = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .arg("volmap")
        .arg(&rest)
        .args(["--target", "ball", "-q", "-o"])
        .arg(&out)
        .arg("--write-constraints")
        .arg(&cons)
        .arg("--write-rest")
        .arg(dir.join("rest_out.mesh"))
        .status()
        .unwrap();
    assert!(st.success());
    // `--no-refine` (refinement off) gives the same map where nothing needs refining.
    let out2 = dir.join("out2.mesh");
    let st = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .arg("volmap")
        .arg(&rest)
        .args(["--target", "ball", "--no-refine", "-q", "-o"])
        .arg(&out2)
        .status()
        .unwrap();
    assert!(st.success());
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        std::fs::read_to_string(&out2).unwrap()
    );
    // Nothing to refine here: the rest written is the input's tets and positions.
    let written_rest = read_any(&dir.join("rest_out.mesh")).unwrap();
    assert_eq!(written_rest.tets, m.tets);
    assert_eq!(written_rest.positions, m.positions);
    let check = |map: &Path| {
        Command::new(env!("CARGO_BIN_EXE_foldfree"))
            .arg("volcheck")
            .arg(map)
            .arg("--rest")
            .arg(&rest)
            .arg("--constraints")
            .arg(&cons)
            .arg("--sphere")
            .output()
            .unwrap()
    };
    let ok = check(&out);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let q: serde_json::Value = serde_json::from_slice(&ok.stdout).unwrap();
    assert_eq!(q["inverted"], 0);
    assert!(q["rho"].as_f64().unwrap() < 1e-20);
    assert!(q["sphere_max_deviation"].as_f64().unwrap() < 1e-12);
    // The rest shape is not on the sphere: volcheck --sphere refuses it.
    assert_eq!(check(&rest).status.code(), Some(1));
}

/// The ball target's surface relaxation spreads a crowded spherical embedding (here a Möbius
/// dilation of the inscribed octahedron, the kind of crowding a Tutte/stereographic map gives a
/// protrusion) back towards equal areas, keeping every chordal triangle positive and every
/// vertex on the sphere.
#[test]
fn sphere_relaxation_spreads_a_crowded_embedding() {
    use foldfree::vol::ball::relax_on_sphere;
    let rest: Vec<[f64; 3]> = vec![
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let faces: Vec<[u32; 3]> = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    // Stereographic coordinates from the north pole, scaled by 0.4, lifted back.
    let crowd = |p: [f64; 3]| -> [f64; 3] {
        let (a, b) = if p[2] > 0.999 {
            return p;
        } else {
            (0.4 * p[0] / (1.0 - p[2]), 0.4 * p[1] / (1.0 - p[2]))
        };
        let r2 = a * a + b * b;
        [
            2.0 * a / (1.0 + r2),
            2.0 * b / (1.0 + r2),
            (r2 - 1.0) / (r2 + 1.0),
        ]
    };
    let mut pos: Vec<[f64; 3]> = rest.iter().map(|&p| crowd(p)).collect();
    // Signed chordal areas: positive when the triangle faces away from the centre.
    let areas = |p: &[[f64; 3]]| -> Vec<f64> {
        use foldfree::vol::tet::{cross, dot, sub};
        faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|v| p[v as usize]);
                let n = cross(sub(b, a), sub(c, a));
                0.5 * dot(n, a).signum() * dot(n, n).sqrt()
            })
            .collect()
    };
    let spread = |a: &[f64]| {
        a.iter().cloned().fold(f64::MIN, f64::max) / a.iter().cloned().fold(f64::MAX, f64::min)
    };
    let before = areas(&pos);
    assert!(before.iter().all(|&a| a > 0.0));
    let it = relax_on_sphere(
        &rest,
        &faces,
        &[],
        &mut pos,
        foldfree::vol::ball::FaceReference::Rest,
        &foldfree::vol::newton::NewtonOptions::default(),
    )
    .unwrap();
    let after = areas(&pos);
    assert!(it > 0);
    assert!(after.iter().all(|&a| a > 0.0), "{after:?}");
    for p in &pos {
        let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        assert!((r - 1.0).abs() < 1e-12, "off the sphere: {r}");
    }
    assert!(
        spread(&after) < 1.05 && spread(&before) > 3.0,
        "area spread {} → {}",
        spread(&before),
        spread(&after)
    );
}

/// Protected tets keep the ε → 0 limit energy, a barrier: the untangler repairs the inverted
/// tet by moving the free vertex and never accepts a step that inverts a protected one; a tet
/// inverted at the start is not protected (its limit energy is infinite there).
#[test]
fn untangle_protected_keeps_protected_tets_positive() {
    use foldfree::vol::newton::corners_of;
    use foldfree::vol::untangle::untangle_protected;
    let m = star_tet();
    let mut x = m.positions.clone();
    x[4] = [0.5, 0.5, 0.5];
    assert_eq!(m.inverted(&x), vec![0]);
    let (d, vol): (Vec<_>, Vec<_>) = m
        .tets
        .iter()
        .map(|t| corners_of(t.map(|v| m.positions[v as usize])).unwrap())
        .map(|(c, det)| (c, det.abs()))
        .unzip();
    let fixed = [true, true, true, true, false];
    let s = untangle_protected(
        &m.tets,
        d,
        vol,
        &mut x,
        &fixed,
        &[],
        &[true; 4],
        &UntangleOptions::default(),
        None,
    )
    .unwrap();
    assert_eq!(s.inverted, 0);
    assert!(m.inverted(&x).is_empty());
    assert_eq!(x[0], [0.0, 0.0, 0.0]);
}

/// The coarse-to-fine spherical embedding of a subdivided octahedron stretched 200 times into
/// a long ellipsoid (a protrusion on either side, which a conformal map crowds exponentially):
/// every vertex on the unit sphere, every chordal triangle positive, with and without the
/// levels' relaxation, and with it no face crowded far below its share of the sphere.
#[test]
fn progressive_sphere_embedding_is_fold_free_and_uncrowded() {
    use foldfree::vol::progressive::{chordal_positive, progressive_embedding};
    use foldfree::vol::tet::{cross, dot, sub};
    let (p, f) = crate::common::glb::sphere(3);
    let rest: Vec<[f64; 3]> = p.iter().map(|q| [200.0 * q[0], q[1], q[2]]).collect();
    let area = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
        let n = cross(sub(b, a), sub(c, a));
        0.5 * dot(n, n).sqrt()
    };
    let total: f64 = f
        .iter()
        .map(|t| {
            area(
                rest[t[0] as usize],
                rest[t[1] as usize],
                rest[t[2] as usize],
            )
        })
        .sum();
    for relax in [None, Some(foldfree::vol::newton::NewtonOptions::default())] {
        let pos = progressive_embedding(&rest, &f, relax.as_ref())
            .unwrap()
            .expect("embedded");
        let mut smallest = f64::INFINITY;
        for q in &pos {
            assert!((dot(*q, *q).sqrt() - 1.0).abs() < 1e-12);
        }
        for t in &f {
            let [a, b, c] = t.map(|v| pos[v as usize]);
            assert!(chordal_positive(a, b, c), "face {t:?} not positive");
            let [ra, rb, rc] = t.map(|v| rest[v as usize]);
            let share = 4.0 * std::f64::consts::PI * area(ra, rb, rc) / total;
            smallest = smallest.min(area(a, b, c) / share);
        }
        if relax.is_some() {
            assert!(smallest > 1e-3, "smallest area / share {smallest:e}");
        }
    }
}
