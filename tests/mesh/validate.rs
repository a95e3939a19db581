//! Validation: each data file's documented verdict (tests/data/README.md) and one small mesh
//! per failure, including the order in which failures are reported.

use std::path::Path;

use foldfree::mesh::validate::{validate, validate_with_topology};
use foldfree::mesh::{load, MeshError, TriMesh, ValidateOptions};

use crate::common::{data, mem, Rng};

fn check(mesh: &TriMesh) -> Result<foldfree::mesh::ValidationReport, MeshError> {
    validate(mesh, mem(), &ValidateOptions::default())
}

/// Unit square as two counter-clockwise triangles.
fn square() -> TriMesh {
    TriMesh {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ],
        faces: vec![[0, 1, 2], [0, 2, 3]],
    }
}

// ---------------------------------------------------------------- data files

#[test]
fn valid_data_files_load_as_disks() {
    // (file, V, F, min face area, bbox diagonal)
    let cases = [
        ("single_triangle.obj", 3, 1, 0.5, 2f64.sqrt()),
        ("two_triangles.obj", 4, 2, 0.5, 2f64.sqrt()),
        ("square_grid_10x10.obj", 121, 200, 0.5, 200f64.sqrt()),
    ];
    for (name, v, f, min_area, diag) in cases {
        let (mesh, topo, report) = load(&data(name), &ValidateOptions::default()).unwrap();
        assert_eq!((mesh.positions.len(), mesh.faces.len()), (v, f), "{name}");
        assert!(topo.is_disk(), "{name}");
        assert!(report.unreferenced_vertices.is_empty(), "{name}");
        assert!((report.min_face_area - min_area).abs() < 1e-12, "{name}");
        assert!((report.bbox_diagonal - diag).abs() < 1e-12, "{name}");
    }
}

#[test]
fn camel_open_is_a_valid_disk() {
    let (mesh, topo, report) = load(&data("camel_open.obj"), &ValidateOptions::default()).unwrap();
    assert_eq!((mesh.positions.len(), mesh.faces.len()), (2032, 3576));
    assert_eq!(topo.boundary_loops.len(), 1);
    assert_eq!(topo.euler_characteristic, 1);
    assert_eq!(topo.genus(), Some(0));
    assert!(topo.is_disk());
    // README: min face area 0.0212 (3 significant digits).
    assert!(
        (report.min_face_area - 0.0212).abs() < 0.00006,
        "{}",
        report.min_face_area
    );
}

#[test]
fn unreferenced_vertex_is_valid_and_reported() {
    let (_, topo, report) = load(
        &data("unreferenced_vertex.obj"),
        &ValidateOptions::default(),
    )
    .unwrap();
    assert_eq!(report.unreferenced_vertices, vec![4]);
    // The unused vertex (0.5, 0.5, 1) does not enlarge the bounding box.
    assert!((report.bbox_diagonal - 2f64.sqrt()).abs() < 1e-15);
    assert!(topo.is_disk());
}

#[test]
fn bowtie_vertex_is_a_non_manifold_vertex() {
    match load(&data("bowtie_vertex.obj"), &ValidateOptions::default()) {
        Err(MeshError::NonManifoldVertex { file, vertex, fans }) => {
            assert_eq!(file, data("bowtie_vertex.obj"));
            assert_eq!((vertex, fans), (0, 2));
        }
        other => panic!("expected NonManifoldVertex, got {other:?}"),
    }
}

#[test]
fn nonmanifold_edge_fan_is_a_non_manifold_edge() {
    match load(
        &data("nonmanifold_edge_fan.obj"),
        &ValidateOptions::default(),
    ) {
        Err(e @ MeshError::NonManifoldEdge { .. }) => {
            let MeshError::NonManifoldEdge {
                v0,
                v1,
                count,
                ref faces,
                ..
            } = e
            else {
                unreachable!()
            };
            assert_eq!((v0, v1, count), (0, 1, 3));
            assert_eq!(faces, &vec![0, 1, 2]);
            let msg = e.to_string();
            assert!(
                msg.contains("nonmanifold_edge_fan.obj") && msg.contains("(0, 1)"),
                "{msg}"
            );
        }
        other => panic!("expected NonManifoldEdge, got {other:?}"),
    }
}

#[test]
fn grid_with_zero_area_face_names_the_face() {
    match load(
        &data("grid_with_zero_area_face.obj"),
        &ValidateOptions::default(),
    ) {
        Err(MeshError::Degenerate {
            face,
            area,
            threshold,
            ..
        }) => {
            assert_eq!(face, 32);
            assert_eq!(area, 0.0);
            assert!(threshold > 0.0 && threshold < 1e-9);
        }
        other => panic!("expected Degenerate, got {other:?}"),
    }
}

// ---------------------------------------------------------------- one mesh per failure

#[test]
fn empty_mesh() {
    let mesh = TriMesh {
        positions: vec![[0.0; 3]],
        faces: vec![],
    };
    assert!(matches!(check(&mesh), Err(MeshError::Empty { .. })));
}

#[test]
fn too_many_faces() {
    let opts = ValidateOptions {
        max_faces: Some(1),
        ..Default::default()
    };
    match validate(&square(), mem(), &opts) {
        Err(e @ MeshError::TooLarge { .. }) => assert!(e.to_string().contains("2 faces")),
        other => panic!("expected TooLarge, got {other:?}"),
    }
    let opts = ValidateOptions {
        max_faces: Some(2),
        ..Default::default()
    };
    assert!(validate(&square(), mem(), &opts).is_ok());
}

#[test]
fn nan_coordinate_names_the_vertex() {
    let mut mesh = square();
    mesh.positions[2][1] = f64::NAN;
    match check(&mesh) {
        Err(MeshError::NonFinite { vertex, value, .. }) => {
            assert_eq!(vertex, 2);
            assert!(value.is_nan());
        }
        other => panic!("expected NonFinite, got {other:?}"),
    }
}

#[test]
fn infinite_coordinate_on_an_unreferenced_vertex_is_rejected_too() {
    let mut mesh = square();
    mesh.positions.push([0.0, f64::NEG_INFINITY, 0.0]);
    assert!(matches!(
        check(&mesh),
        Err(MeshError::NonFinite { vertex: 4, value, .. }) if value == f64::NEG_INFINITY
    ));
}

#[test]
fn nan_in_an_obj_file_is_caught_by_load() {
    let dir = std::env::temp_dir().join(format!("foldfree-mesh-validate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("nan.obj");
    std::fs::write(&path, "v 0 0 0\nv 1 0 0\nv 0 NaN 0\nf 1 2 3\n").unwrap();
    let result = load(&path, &ValidateOptions::default());
    let _ = std::fs::remove_dir_all(&dir);
    assert!(matches!(
        result,
        Err(MeshError::NonFinite { vertex: 2, .. })
    ));
}

#[test]
fn index_out_of_range() {
    let mut mesh = square();
    mesh.faces[1] = [0, 2, 4];
    assert!(matches!(
        check(&mesh),
        Err(MeshError::IndexOutOfRange {
            face: 1,
            index: 4,
            count: 4,
            ..
        })
    ));
}

#[test]
fn repeated_vertex() {
    let mut mesh = square();
    mesh.faces[1] = [3, 2, 3];
    assert!(matches!(
        check(&mesh),
        Err(MeshError::RepeatedVertex {
            face: 1,
            vertex: 3,
            ..
        })
    ));
}

#[test]
fn degenerate_is_relative_to_the_bounding_box() {
    let mut mesh = square();
    // Sliver of area 0.5e-13 in a box of diagonal √2: below 1e-12 · 2.
    mesh.positions.push([0.5, 1e-13, 0.0]);
    mesh.faces.push([1, 0, 4]);
    assert!(matches!(
        check(&mesh),
        Err(MeshError::Degenerate { face: 2, .. })
    ));
    // The same shape scaled up by 1e6 is just as degenerate.
    let mut big = mesh.clone();
    for p in &mut big.positions {
        for c in p.iter_mut() {
            *c *= 1e6;
        }
    }
    assert!(matches!(
        check(&big),
        Err(MeshError::Degenerate { face: 2, .. })
    ));
    let loose = ValidateOptions {
        degenerate_rel_tol: 1e-15,
        ..Default::default()
    };
    assert!(!matches!(
        validate(&mesh, mem(), &loose),
        Err(MeshError::Degenerate { .. })
    ));
}

#[test]
fn duplicate_face_with_either_orientation() {
    let mut mesh = square();
    mesh.faces.push([2, 0, 1]);
    assert!(matches!(
        check(&mesh),
        Err(MeshError::DuplicateFace {
            face: 2,
            other: 0,
            ..
        })
    ));
    let mut mesh = square();
    mesh.faces.insert(1, [0, 3, 2]);
    assert!(matches!(
        check(&mesh),
        Err(MeshError::DuplicateFace {
            face: 2,
            other: 1,
            ..
        })
    ));
}

#[test]
fn flipped_face_is_inconsistent_orientation() {
    let mut mesh = square();
    mesh.faces[1] = [0, 3, 2];
    match check(&mesh) {
        Err(e @ MeshError::InconsistentOrientation { .. }) => {
            let MeshError::InconsistentOrientation { f0, f1, v0, v1, .. } = e else {
                unreachable!()
            };
            assert_eq!((f0, f1), (0, 1));
            // Both faces run from vertex 2 to vertex 0.
            assert_eq!((v0, v1), (2, 0));
            assert!(e.to_string().contains("faces 0 and 1"));
        }
        other => panic!("expected InconsistentOrientation, got {other:?}"),
    }
}

#[test]
fn pinched_closed_fans_are_a_non_manifold_vertex() {
    // Two tetrahedra touching only at vertex 0.
    let mut positions = vec![[0.0, 0.0, 0.0]];
    let mut faces = Vec::new();
    for s in [1.0, -1.0] {
        let b = positions.len() as u32;
        positions.extend([[s, 0.0, 0.0], [0.0, s, 0.0], [0.0, 0.0, s]]);
        let (x, y, z) = (b, b + 1, b + 2);
        if s > 0.0 {
            faces.extend([[0, y, x], [0, x, z], [0, z, y], [x, y, z]]);
        } else {
            faces.extend([[0, x, y], [0, z, x], [0, y, z], [x, z, y]]);
        }
    }
    let mesh = TriMesh { positions, faces };
    assert!(matches!(
        check(&mesh),
        Err(MeshError::NonManifoldVertex {
            vertex: 0,
            fans: 2,
            ..
        })
    ));
}

#[test]
fn failures_are_reported_in_the_documented_order() {
    // NaN beats index out of range.
    let mut mesh = square();
    mesh.positions[3][0] = f64::NAN;
    mesh.faces[0] = [0, 1, 9];
    assert!(matches!(check(&mesh), Err(MeshError::NonFinite { .. })));
    // Out of range beats a repeated vertex in an earlier face.
    let mut mesh = square();
    mesh.faces[0] = [0, 0, 1];
    mesh.faces[1] = [0, 2, 9];
    assert!(matches!(
        check(&mesh),
        Err(MeshError::IndexOutOfRange { .. })
    ));
    // Degenerate beats duplicate.
    let mut mesh = square();
    mesh.positions.push([2.0, 0.0, 0.0]);
    mesh.faces.extend([[0, 2, 3], [0, 1, 4]]);
    assert!(matches!(
        check(&mesh),
        Err(MeshError::Degenerate { face: 3, .. })
    ));
    // Duplicate beats the non-manifold edge the copy creates.
    let mut mesh = square();
    mesh.faces.push([0, 1, 2]);
    assert!(matches!(check(&mesh), Err(MeshError::DuplicateFace { .. })));
}

#[test]
fn validate_with_topology_returns_the_same_report() {
    let mesh = square();
    let (report, topo) = validate_with_topology(&mesh, mem(), &ValidateOptions::default()).unwrap();
    assert_eq!(report, check(&mesh).unwrap());
    assert!(topo.is_disk());
}

#[test]
fn read_errors_pass_through_load() {
    let missing = data("does_not_exist.obj");
    assert!(matches!(
        load(&missing, &ValidateOptions::default()),
        Err(MeshError::Read { file, .. }) if file == missing
    ));
}

/// (file, V, F, components, boundary loops, chi, genus, unreferenced)
type Row = (&'static str, usize, usize, usize, usize, i64, i64, usize);

/// Every surface mesh of ../shared/meshes against its README row (V, F, components, loops, chi,
/// genus). `cargo test --release --test mesh -- --ignored --nocapture shared_meshes`
#[test]
#[ignore = "needs /work/shared/meshes; reads ~40 MB"]
fn shared_meshes_match_their_readme() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes");
    let rows: [Row; 14] = [
        ("disk/camel_open.obj", 2032, 3576, 1, 1, 1, 0, 0),
        ("disk/camelhead.obj", 11381, 22704, 1, 1, 1, 0, 0),
        ("disk/face.obj", 25905, 51712, 1, 1, 1, 0, 0),
        ("disk/igea_open_249k.obj", 124856, 249302, 1, 1, 1, 0, 0),
        ("disk/lion_mask.obj", 8356, 16674, 1, 1, 1, 0, 0),
        ("disk/ogre_head.obj", 19985, 39856, 1, 1, 1, 0, 0),
        ("closed/bunny_npm.obj", 1839, 3674, 1, 0, 2, 0, 0),
        ("closed/cheburashka.obj", 6669, 13334, 1, 0, 2, 0, 0),
        ("closed/fertility.obj", 4494, 9000, 1, 0, -6, 4, 0),
        ("closed/spot.obj", 2930, 5856, 1, 0, 2, 0, 0),
        (
            "open/stanford_bunny_scan.obj",
            35947,
            69451,
            1,
            5,
            -3,
            0,
            1113,
        ),
        ("cad/block.obj", 2132, 4272, 1, 0, -4, 3, 0),
        ("cad/fandisk.obj", 6475, 12946, 1, 0, 2, 0, 0),
        ("cad/rocker_arm.obj", 10044, 20088, 1, 0, 0, 1, 0),
    ];
    for (name, v, f, comp, loops, chi, genus, unref) in rows {
        let t0 = std::time::Instant::now();
        let (mesh, topo, report) =
            load(&root.join(name), &ValidateOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        println!("{name}: {:?}, {}", t0.elapsed(), topo.describe());
        assert_eq!((mesh.positions.len(), mesh.faces.len()), (v, f), "{name}");
        assert_eq!(topo.components, comp, "{name}");
        assert_eq!(topo.boundary_loops.len(), loops, "{name}");
        assert_eq!(topo.euler_characteristic, chi, "{name}");
        assert_eq!(topo.genus(), Some(genus), "{name}");
        assert_eq!(report.unreferenced_vertices.len(), unref, "{name}");
        assert_eq!(topo.is_disk(), name.starts_with("disk/"), "{name}");
    }
}

#[test]
fn random_meshes_and_texts_never_panic() {
    use foldfree::mesh::obj::parse_obj;
    use foldfree::mesh::{frames, Topology};
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for _ in 0..2000 {
        let nv = rng.below(7) as usize;
        let nf = rng.below(7) as usize;
        let positions = (0..nv)
            .map(|_| [0, 1, 2].map(|_| (rng.below(5) as f64) - 2.0))
            .collect();
        let faces = (0..nf)
            .map(|_| [0, 1, 2].map(|_| rng.below(nv as u64 + 1) as u32))
            .collect();
        let mesh = TriMesh { positions, faces };
        let _ = check(&mesh);
        if let Ok(t) = Topology::build(&mesh, mem()) {
            let _ = (t.genus(), t.is_disk(), t.describe());
        }
        let _ = frames::compute(&mesh);
    }
    let pieces = [
        "v",
        "f",
        "vt",
        " ",
        "\n",
        "1",
        "-1",
        "0",
        "2/",
        "/3",
        "//",
        "#",
        "1.5e3",
        "nan",
        "\\\n",
        "-7",
        "99999999999",
        "x",
        "\r\n",
        "\u{e9}",
    ];
    for _ in 0..2000 {
        let text: String = (0..rng.below(40))
            .map(|_| pieces[rng.below(pieces.len() as u64) as usize])
            .collect();
        if let Ok(mesh) = parse_obj(&text, mem()) {
            let _ = check(&mesh);
        }
    }
}
