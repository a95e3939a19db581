//! OBJ reading/writing, topology and face frames, checked against the documented facts of the
//! meshes in tests/data (see tests/data/README.md) and against small meshes built here.

use std::path::Path;

use foldfree::mesh::obj::{
    obj_text_with_corner_uv, obj_text_with_uv, parse_obj, parse_obj_with_info, read_obj,
    read_obj_with_info,
};
use foldfree::mesh::{frames, MeshError, Topology, TriMesh, NO_FACE};

use crate::common::{data, mem, TempDir};

fn topo_of(mesh: &TriMesh) -> Topology {
    Topology::build(mesh, mem()).unwrap()
}

/// Structural invariants every topology must satisfy.
fn check_invariants(mesh: &TriMesh, t: &Topology) {
    let nv = mesh.positions.len();
    let nf = mesh.faces.len();
    assert_eq!(t.n_vertices, nv);
    assert_eq!(t.vf_offsets.len(), nv + 1);
    assert_eq!(t.vf_faces.len(), 3 * nf);
    assert_eq!(t.vv_offsets.len(), nv + 1);
    assert_eq!(t.vv_neighbors.len(), 2 * t.edges.len());
    assert_eq!(t.face_edges.len(), nf);
    assert_eq!(t.edge_faces.len(), t.edges.len());
    assert_eq!(t.component_of_face.len(), nf);
    assert_eq!(
        t.interior_edges.len() + t.boundary_edges.len(),
        t.edges.len()
    );
    assert!(
        t.edges.windows(2).all(|w| w[0] < w[1]),
        "edges sorted, unique"
    );
    assert!(t.edges.iter().all(|e| e[0] < e[1]));
    for v in 0..nv as u32 {
        let vf = t.vertex_faces(v);
        assert!(vf.windows(2).all(|w| w[0] < w[1]));
        assert!(vf.iter().all(|&f| mesh.faces[f as usize].contains(&v)));
        let nb = t.neighbors(v);
        assert!(nb.windows(2).all(|w| w[0] < w[1]), "neighbours sorted");
        for (&u, &e) in nb.iter().zip(t.neighbor_edges(v)) {
            assert_eq!(
                t.edges[e as usize],
                [v.min(u), v.max(u)],
                "edge to each neighbour"
            );
            assert_eq!(t.edge_between(v, u), Some(e));
            assert_eq!(t.edge_between(u, v), Some(e));
        }
        for &u in nb {
            let key = [v.min(u), v.max(u)];
            assert!(t.edges.binary_search(&key).is_ok());
        }
    }
    for (f, tri) in mesh.faces.iter().enumerate() {
        for k in 0..3 {
            let e = t.face_edges[f][k] as usize;
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            assert_eq!(t.edges[e], [a.min(b), a.max(b)]);
            assert!(t.edge_faces[e].contains(&(f as u32)));
        }
    }
    for (e, ef) in t.edge_faces.iter().enumerate() {
        assert!(ef[1] == NO_FACE || ef[0] < ef[1]);
        let is_boundary = ef[1] == NO_FACE;
        assert_eq!(
            t.boundary_edges.binary_search(&(e as u32)).is_ok(),
            is_boundary
        );
    }
    let boundary_vertices: usize = t.boundary_loops.iter().map(Vec::len).sum();
    if t.nonmanifold_vertices.is_empty() && t.consistently_oriented {
        assert_eq!(boundary_vertices, t.boundary_edges.len());
    }
    assert!(t
        .boundary_loops
        .windows(2)
        .all(|w| w[0].len() >= w[1].len()));
}

/// A mesh's documented facts.
struct Facts {
    v: usize,
    f: usize,
    components: usize,
    loops: usize,
    chi: i64,
    genus: Option<i64>,
}

fn assert_facts(name: &str, facts: Facts) -> (TriMesh, Topology) {
    let mesh = read_obj(&data(name)).unwrap();
    let t = Topology::build(&mesh, &data(name)).unwrap();
    check_invariants(&mesh, &t);
    assert_eq!(mesh.positions.len(), facts.v, "{name}: V");
    assert_eq!(mesh.faces.len(), facts.f, "{name}: F");
    assert_eq!(t.components, facts.components, "{name}: components");
    assert_eq!(t.boundary_loops.len(), facts.loops, "{name}: loops");
    assert_eq!(t.euler_characteristic, facts.chi, "{name}: chi");
    assert_eq!(t.genus(), facts.genus, "{name}: genus");
    (mesh, t)
}

// ---------------------------------------------------------------- data files

#[test]
fn single_triangle_is_the_smallest_disk() {
    let (_, t) = assert_facts(
        "single_triangle.obj",
        Facts {
            v: 3,
            f: 1,
            components: 1,
            loops: 1,
            chi: 1,
            genus: Some(0),
        },
    );
    assert!(t.is_disk());
    assert_eq!(t.boundary_loops, vec![vec![0, 1, 2]]);
    assert_eq!(t.edges, vec![[0, 1], [0, 2], [1, 2]]);
    assert_eq!(t.face_edges, vec![[0, 2, 1]]);
    assert!(t.interior_edges.is_empty());
    assert!(t.require_disk(mem()).is_ok());
}

#[test]
fn two_triangles_csr_and_edges() {
    let (_, t) = assert_facts(
        "two_triangles.obj",
        Facts {
            v: 4,
            f: 2,
            components: 1,
            loops: 1,
            chi: 1,
            genus: Some(0),
        },
    );
    assert!(t.is_disk());
    assert_eq!(t.edges, vec![[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]);
    assert_eq!(t.interior_edges, vec![1]);
    assert_eq!(t.edge_faces[1], [0, 1]);
    assert_eq!(t.edge_faces[0], [0, NO_FACE]);
    assert_eq!(t.vertex_faces(0), &[0, 1]);
    assert_eq!(t.vertex_faces(1), &[0]);
    assert_eq!(t.neighbors(0), &[1, 2, 3]);
    assert_eq!(t.neighbors(2), &[0, 1, 3]);
    assert_eq!(t.vf_offsets, vec![0, 2, 3, 5, 6]);
    // Faces (0,1,2) and (0,2,3) are counter-clockwise: the boundary runs 0→1→2→3.
    assert_eq!(t.boundary_loops, vec![vec![0, 1, 2, 3]]);
    assert_eq!(t.describe(), "open surface of genus 0 with 1 boundary loop");
}

#[test]
fn square_grid_10x10_facts() {
    let (mesh, t) = assert_facts(
        "square_grid_10x10.obj",
        Facts {
            v: 121,
            f: 200,
            components: 1,
            loops: 1,
            chi: 1,
            genus: Some(0),
        },
    );
    assert!(t.is_disk());
    assert_eq!(t.edges.len(), 320);
    assert_eq!(t.boundary_edges.len(), 40);
    assert_eq!(t.boundary_loops[0].len(), 40);
    assert_eq!(
        t.boundary_loops[0][0], 0,
        "loop starts at its smallest vertex"
    );
    // Counter-clockwise faces (+z normal) give a counter-clockwise outer loop: positive area.
    assert!(loop_signed_area(&mesh, &t.boundary_loops[0]) > 0.0);
}

#[test]
fn camel_open_facts() {
    let (_, t) = assert_facts(
        "camel_open.obj",
        Facts {
            v: 2032,
            f: 3576,
            components: 1,
            loops: 1,
            chi: 1,
            genus: Some(0),
        },
    );
    assert!(t.is_disk());
    assert!(t.unreferenced.is_empty());
    assert!(t.consistently_oriented);
    assert!(t.nonmanifold_vertices.is_empty());
}

#[test]
fn grid_with_zero_area_face_topology_is_still_a_disk() {
    let (_, t) = assert_facts(
        "grid_with_zero_area_face.obj",
        Facts {
            v: 26,
            f: 33,
            components: 1,
            loops: 1,
            chi: 1,
            genus: Some(0),
        },
    );
    assert!(t.is_disk());
}

#[test]
fn unreferenced_vertex_is_kept_and_listed() {
    let (mesh, t) = assert_facts(
        "unreferenced_vertex.obj",
        Facts {
            v: 5,
            f: 2,
            components: 1,
            loops: 1,
            chi: 1,
            genus: Some(0),
        },
    );
    assert_eq!(t.unreferenced, vec![4]);
    assert_eq!(mesh.positions[4], [0.5, 0.5, 1.0]);
    assert!(t.neighbors(4).is_empty());
    assert!(t.is_disk());
}

#[test]
fn bowtie_vertex_builds_but_has_no_genus() {
    let mesh = read_obj(&data("bowtie_vertex.obj")).unwrap();
    let t = Topology::build(&mesh, mem()).unwrap();
    check_invariants(&mesh, &t);
    assert_eq!((mesh.positions.len(), mesh.faces.len()), (5, 2));
    assert_eq!(t.components, 1);
    assert_eq!(t.nonmanifold_vertices, vec![0]);
    assert_eq!(t.fan_count(0), 2);
    assert_eq!(t.fan_count(1), 1);
    assert_eq!(t.genus(), None);
    assert!(!t.is_disk());
    // The boundary-edge graph is one figure eight through the pinch vertex.
    assert_eq!(t.boundary_loops.len(), 1);
    assert!(t.describe().contains("non-manifold"), "{}", t.describe());
}

#[test]
fn nonmanifold_edge_fan_is_rejected_by_topology() {
    let mesh = read_obj(&data("nonmanifold_edge_fan.obj")).unwrap();
    match Topology::build(&mesh, mem()) {
        Err(MeshError::NonManifoldEdge {
            v0,
            v1,
            count,
            faces,
            ..
        }) => {
            assert_eq!((v0, v1, count), (0, 1, 3));
            assert_eq!(faces, vec![0, 1, 2]);
        }
        other => panic!("expected NonManifoldEdge, got {other:?}"),
    }
}

#[test]
fn tobj_agrees_on_faces_and_positions() {
    let opts = tobj::LoadOptions {
        triangulate: true,
        ..Default::default()
    };
    for name in [
        "two_triangles.obj",
        "square_grid_10x10.obj",
        "camel_open.obj",
    ] {
        let ours = read_obj(&data(name)).unwrap();
        let (models, _) = tobj::load_obj(data(name), &opts).unwrap();
        assert_eq!(models.len(), 1, "{name}");
        let m = &models[0].mesh;
        assert_eq!(m.indices.len(), 3 * ours.faces.len(), "{name}");
        // tobj may renumber vertices; the position at every face corner must agree anyway.
        for (c, &ti) in m.indices.iter().enumerate() {
            let p = ours.positions[ours.faces[c / 3][c % 3] as usize];
            for d in 0..3 {
                let q = f64::from(m.positions[3 * ti as usize + d]);
                assert!(
                    (p[d] - q).abs() <= 1e-6 * (1.0 + p[d].abs()),
                    "{name}: corner {c}"
                );
            }
        }
        if name == "two_triangles.obj" {
            // Vertices are used in file order here, so even the indices coincide.
            let flat: Vec<u32> = ours.faces.iter().flatten().copied().collect();
            assert_eq!(m.indices, flat);
        }
    }
}

// ---------------------------------------------------------------- literal meshes

fn tetrahedron() -> TriMesh {
    TriMesh {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ],
        // Outward (counter-clockwise seen from outside).
        faces: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    }
}

/// An n×m grid wrapped in both directions, embedded as a torus of radii 2 and 1.
fn torus(n: u32, m: u32) -> TriMesh {
    let mut positions = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (u, v) = (
                std::f64::consts::TAU * f64::from(i) / f64::from(n),
                std::f64::consts::TAU * f64::from(j) / f64::from(m),
            );
            let r = 2.0 + v.cos();
            positions.push([r * u.cos(), r * u.sin(), v.sin()]);
        }
    }
    let id = |i: u32, j: u32| (i % n) * m + (j % m);
    let mut faces = Vec::new();
    for i in 0..n {
        for j in 0..m {
            faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh { positions, faces }
}

/// A k×k grid of unit squares in the z=0 plane, counter-clockwise, minus the cells in `holes`.
fn grid(k: u32, holes: &[(u32, u32)]) -> TriMesh {
    let mut positions = Vec::new();
    for y in 0..=k {
        for x in 0..=k {
            positions.push([f64::from(x), f64::from(y), 0.0]);
        }
    }
    let id = |x: u32, y: u32| y * (k + 1) + x;
    let mut faces = Vec::new();
    for y in 0..k {
        for x in 0..k {
            if holes.contains(&(x, y)) {
                continue;
            }
            faces.push([id(x, y), id(x + 1, y), id(x + 1, y + 1)]);
            faces.push([id(x, y), id(x + 1, y + 1), id(x, y + 1)]);
        }
    }
    TriMesh { positions, faces }
}

fn loop_signed_area(mesh: &TriMesh, lp: &[u32]) -> f64 {
    let mut a = 0.0;
    for i in 0..lp.len() {
        let p = mesh.positions[lp[i] as usize];
        let q = mesh.positions[lp[(i + 1) % lp.len()] as usize];
        a += p[0] * q[1] - q[0] * p[1];
    }
    0.5 * a
}

#[test]
fn tetrahedron_is_a_closed_genus_0_surface() {
    let mesh = tetrahedron();
    let t = topo_of(&mesh);
    check_invariants(&mesh, &t);
    assert_eq!(t.edges.len(), 6);
    assert!(t.boundary_edges.is_empty());
    assert!(t.boundary_loops.is_empty());
    assert_eq!(t.euler_characteristic, 2);
    assert_eq!(t.genus(), Some(0));
    assert!(!t.is_disk());
    assert_eq!(t.describe(), "closed surface of genus 0");
    match t.require_disk(Path::new("tet.obj")) {
        Err(e @ MeshError::NotDisk { .. }) => {
            let msg = e.to_string();
            assert!(
                msg.contains("tet.obj") && msg.contains("closed surface of genus 0"),
                "{msg}"
            );
        }
        other => panic!("expected NotDisk, got {other:?}"),
    }
}

#[test]
fn torus_has_genus_1() {
    let mesh = torus(6, 4);
    let t = topo_of(&mesh);
    check_invariants(&mesh, &t);
    assert_eq!(t.euler_characteristic, 0);
    assert_eq!(t.genus(), Some(1));
    assert_eq!(t.describe(), "closed surface of genus 1");
    assert!(t.require_disk(mem()).is_err());
}

#[test]
fn two_disjoint_triangles_are_two_components() {
    let mesh = TriMesh {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [5.0, 0.0, 0.0],
            [6.0, 0.0, 0.0],
            [5.0, 1.0, 0.0],
        ],
        faces: vec![[3, 4, 5], [0, 1, 2]],
    };
    let t = topo_of(&mesh);
    check_invariants(&mesh, &t);
    assert_eq!(t.components, 2);
    assert_eq!(t.component_of_face, vec![0, 1]);
    assert_eq!(t.genus(), Some(0));
    assert_eq!(t.boundary_loops.len(), 2);
    assert!(!t.is_disk());
    assert!(t.describe().starts_with("2 components"), "{}", t.describe());
}

#[test]
fn annulus_loops_longest_first_with_face_direction() {
    // 4×4 grid without the 2×2 middle cells: outer loop of 16 vertices, inner of 8.
    let mesh = grid(4, &[(1, 1), (2, 1), (1, 2), (2, 2)]);
    let t = topo_of(&mesh);
    check_invariants(&mesh, &t);
    assert_eq!(t.boundary_loops.len(), 2);
    assert_eq!(t.boundary_loops[0].len(), 16);
    assert_eq!(t.boundary_loops[1].len(), 8);
    assert_eq!(t.genus(), Some(0));
    assert!(!t.is_disk());
    assert_eq!(
        t.describe(),
        "open surface of genus 0 with 2 boundary loops"
    );
    // Faces traverse the outer boundary counter-clockwise and the hole clockwise.
    assert!(loop_signed_area(&mesh, &t.boundary_loops[0]) > 0.0);
    assert!(loop_signed_area(&mesh, &t.boundary_loops[1]) < 0.0);
    for lp in &t.boundary_loops {
        assert_eq!(lp[0], *lp.iter().min().unwrap());
    }
}

#[test]
fn inconsistent_orientation_leaves_genus_undefined() {
    let mut mesh = grid(2, &[]);
    mesh.faces[3].swap(1, 2);
    let t = topo_of(&mesh);
    assert!(!t.consistently_oriented);
    assert_eq!(t.genus(), None);
    assert!(!t.is_disk());
}

#[test]
fn topology_rejects_bad_indices_without_panicking() {
    let mut mesh = grid(1, &[]);
    mesh.faces[1] = [0, 9, 2];
    assert!(matches!(
        Topology::build(&mesh, mem()),
        Err(MeshError::IndexOutOfRange {
            face: 1,
            index: 9,
            count: 4,
            ..
        })
    ));
    mesh.faces[1] = [0, 2, 2];
    assert!(matches!(
        Topology::build(&mesh, mem()),
        Err(MeshError::RepeatedVertex {
            face: 1,
            vertex: 2,
            ..
        })
    ));
    let empty = Topology::build(&TriMesh::default(), mem()).unwrap();
    assert_eq!(empty.components, 0);
    assert!(!empty.is_disk());
}

// ---------------------------------------------------------------- OBJ parsing

fn parse(text: &str) -> Result<TriMesh, MeshError> {
    parse_obj(text, Path::new("t.obj"))
}

fn read_err_reason(text: &[u8]) -> String {
    match parse_obj(text, Path::new("t.obj")) {
        Err(MeshError::Read { reason, .. }) => reason,
        other => panic!("expected Read error, got {other:?}"),
    }
}

#[test]
fn obj_keeps_vertex_and_face_order_and_unused_vertices() {
    let text = "# test\nv 0 0 0\nv 9 9 9\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 4 5 1\nf 3 4 1\n";
    let mesh = parse(text).unwrap();
    assert_eq!(mesh.positions.len(), 5);
    assert_eq!(mesh.positions[1], [9.0, 9.0, 9.0]);
    assert_eq!(mesh.faces, vec![[3, 4, 0], [2, 3, 0]]);
}

#[test]
fn obj_corner_forms_negative_indices_and_skipped_records() {
    let text = "mtllib a.mtl\no thing\nv 0 0 0 1\nv 1 0 0 0.5 0.5 0.5\nv 1 1 0\nv 0 1 0\n\
                vt 0 0\nvn 0 0 1\ng grp\ns off\nusemtl m\nf 1/1/1 2/2/1 3//1\nf -4 -2/7 -1\n\
                l 1 2\np 3\n";
    let (mesh, info) = parse_obj_with_info(text, Path::new("t.obj")).unwrap();
    assert_eq!(mesh.faces, vec![[0, 1, 2], [0, 2, 3]]);
    assert_eq!(info.ignored_records, 9);
    assert_eq!(info.source_face_count, 2);
    assert_eq!(info.polygons_triangulated, 0);
}

#[test]
fn obj_negative_indices_are_relative_to_vertices_read_so_far() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 5 5\nf -4 -3 -1\n";
    let mesh = parse(text).unwrap();
    assert_eq!(mesh.faces, vec![[0, 1, 2], [0, 1, 3]]);
}

#[test]
fn obj_polygons_are_fan_triangulated() {
    let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv -1 0.5 0\nf 1 2 3 4\nf 1 4 5\n\
                f 1 2 3 4 5\n";
    let (mesh, info) = parse_obj_with_info(text, Path::new("t.obj")).unwrap();
    assert_eq!(
        mesh.faces,
        vec![
            [0, 1, 2],
            [0, 2, 3],
            [0, 3, 4],
            [0, 1, 2],
            [0, 2, 3],
            [0, 3, 4]
        ]
    );
    assert_eq!(info.polygons_triangulated, 2);
    assert_eq!(info.source_face_count, 3);
}

#[test]
fn obj_tolerates_crlf_tabs_bom_trailing_comments_and_continuations() {
    let text = "\u{feff}v\t0 0 0\r\nv 1 0 0 # right\r\nv 0 1 0\r\nf 1 2 \\\r\n 3\r\n";
    let mesh = parse(text).unwrap();
    assert_eq!(mesh.positions[1], [1.0, 0.0, 0.0]);
    assert_eq!(mesh.faces, vec![[0, 1, 2]]);
}

#[test]
fn obj_face_with_two_vertices_names_the_line() {
    let reason = read_err_reason(b"v 0 0 0\nv 1 0 0\nv 0 1 0\n# c\nf 1 2\n");
    assert_eq!(reason, "line 5: face has 2 vertices, need at least 3");
}

#[test]
fn obj_index_zero_and_bad_numbers_are_read_errors() {
    let reason = read_err_reason(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
    assert!(
        reason.starts_with("line 4:") && reason.contains("index 0"),
        "{reason}"
    );
    let reason = read_err_reason(b"v 0 0 0\nv 1 zero 0\nv 0 1 0\nf 1 2 3\n");
    assert!(
        reason.starts_with("line 2:") && reason.contains("zero"),
        "{reason}"
    );
    let reason = read_err_reason(b"v 0 0\n");
    assert!(reason.starts_with("line 1:"), "{reason}");
    let reason = read_err_reason(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n");
    assert!(reason.starts_with("line 4:"), "{reason}");
}

#[test]
fn obj_index_out_of_range_names_the_face() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 3 7\n";
    match parse(text) {
        Err(MeshError::IndexOutOfRange {
            face, index, count, ..
        }) => {
            assert_eq!((face, index, count), (1, 7, 3));
        }
        other => panic!("expected IndexOutOfRange, got {other:?}"),
    }
    match parse("v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n") {
        Err(MeshError::IndexOutOfRange {
            face, index, count, ..
        }) => {
            assert_eq!((face, index, count), (0, -3, 2));
        }
        other => panic!("expected IndexOutOfRange, got {other:?}"),
    }
}

#[test]
fn obj_forward_references_are_resolved_at_the_end() {
    let mesh = parse("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap();
    assert_eq!(mesh.faces, vec![[0, 1, 2]]);
}

#[test]
fn obj_empty_inputs_are_empty_errors() {
    assert!(matches!(parse(""), Err(MeshError::Empty { .. })));
    assert!(matches!(
        parse("# nothing\nv 0 0 0\nv 1 0 0\n"),
        Err(MeshError::Empty { .. })
    ));
    let dir = TempDir::new("topology_empty");
    let path = dir.join("zero.obj");
    std::fs::write(&path, b"").unwrap();
    assert!(matches!(read_obj(&path), Err(MeshError::Empty { file, .. }) if file == path));
}

#[test]
fn obj_binary_and_non_utf8_files_are_read_errors() {
    let dir = TempDir::new("topology_binary");
    let garbage: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let path = dir.join("garbage.obj");
    std::fs::write(&path, &garbage).unwrap();
    match read_obj(&path) {
        Err(MeshError::Read { file, reason }) => {
            assert_eq!(file, path);
            assert!(reason.starts_with("line "), "{reason}");
        }
        other => panic!("expected Read error, got {other:?}"),
    }
    let reason = read_err_reason(b"v 0 0 0\nv 1 0 \xff 0\n");
    assert!(
        reason.starts_with("line 2:") && reason.contains("UTF-8"),
        "{reason}"
    );
    let reason = read_err_reason(b"solid x\n\0\0\0\x01");
    assert!(
        reason.starts_with("line 2:") && reason.contains("binary"),
        "{reason}"
    );
}

#[test]
fn obj_missing_file_is_a_read_error() {
    let path = TempDir::new("topology_missing").join("nope.obj");
    match read_obj(&path) {
        Err(e @ MeshError::Read { .. }) => assert!(e.to_string().contains("nope.obj")),
        other => panic!("expected Read error, got {other:?}"),
    }
}

#[test]
fn obj_non_finite_coordinates_are_parsed_for_validation() {
    let mesh = parse("v 0 0 0\nv nan 0 0\nv 0 inf 0\nf 1 2 3\n").unwrap();
    assert!(mesh.positions[1][0].is_nan());
    assert_eq!(mesh.positions[2][1], f64::INFINITY);
}

#[test]
fn read_obj_with_info_on_a_data_file() {
    let (mesh, info) = read_obj_with_info(&data("square_grid_10x10.obj"), 1000).unwrap();
    assert_eq!(mesh.faces.len(), 200);
    assert_eq!(info.source_face_count, 200);
    assert_eq!(info.polygons_triangulated, 0);
    assert_eq!(info.ignored_records, 0);
}

// ---------------------------------------------------------------- OBJ writing

fn vt_lines(text: &str) -> Vec<[f64; 2]> {
    text.lines()
        .filter_map(|l| l.strip_prefix("vt "))
        .map(|l| {
            let mut it = l.split(' ').map(|x| x.parse::<f64>().unwrap());
            [it.next().unwrap(), it.next().unwrap()]
        })
        .collect()
}

#[test]
fn write_obj_with_uv_round_trips_exactly() {
    let dir = TempDir::new("topology_write_uv");
    let path = dir.join("out.obj");
    let mut mesh = read_obj(&data("unreferenced_vertex.obj")).unwrap();
    mesh.positions[1] = [0.1 + 0.2, -0.0, 1e-300];
    mesh.positions[2] = [1e22, 123_456.789_012_345_67, f64::MIN_POSITIVE];
    let uv = vec![
        [0.0, 0.0],
        [1.0 / 3.0, 2.0 / 3.0],
        [1e-7, -4.5e17],
        [0.5, 0.25],
        [7.0, 8.0],
    ];
    std::fs::write(&path, "old contents").unwrap();
    std::fs::write(&path, obj_text_with_uv(&mesh, &uv).unwrap()).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.starts_with("# written by foldfree\n"));
    let back = read_obj(&path).unwrap();
    assert_eq!(back.faces, mesh.faces);
    for (a, b) in back.positions.iter().zip(&mesh.positions) {
        for d in 0..3 {
            assert_eq!(a[d].to_bits(), b[d].to_bits());
        }
    }
    assert_eq!(
        vt_lines(&text),
        uv,
        "one vt per vertex, unreferenced included"
    );
    assert!(text.contains("\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"));
    // Only the target is left in the directory.
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("out.obj")]);
}

#[test]
fn write_obj_with_corner_uv_writes_per_corner_indices() {
    let dir = TempDir::new("topology_write_corner_uv");
    let path = dir.join("seams.obj");
    let mesh = read_obj(&data("two_triangles.obj")).unwrap();
    let uv = vec![
        [0.0, 0.0],
        [1.0, 0.0],
        [1.0, 1.0],
        [0.0, 1.0],
        [2.0, 2.0],
        [3.0, 3.0],
    ];
    let corner = vec![[0, 1, 2], [4, 5, 3]];
    std::fs::write(&path, obj_text_with_corner_uv(&mesh, &uv, &corner).unwrap()).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(vt_lines(&text).len(), 6);
    assert!(text.ends_with("f 1/1 2/2 3/3\nf 1/5 3/6 4/4\n"), "{text}");
    assert_eq!(read_obj(&path).unwrap(), mesh);
    // Index past the uv list: refused.
    let err = obj_text_with_corner_uv(&mesh, &uv, &[[0, 1, 2], [0, 1, 6]]).unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput);
}

#[test]
fn obj_text_refuses_wrong_uv_count_and_non_finite_numbers() {
    let mesh = read_obj(&data("two_triangles.obj")).unwrap();
    let err = obj_text_with_uv(&mesh, &[[0.0, 0.0]]).unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput);
    let mut uv = vec![[0.0, 0.0]; mesh.positions.len()];
    uv[1][0] = f64::NAN;
    assert!(
        obj_text_with_uv(&mesh, &uv).is_err(),
        "nothing non-finite is written"
    );
}

#[test]
fn outputs_replace_existing_files_and_report_missing_directories() {
    let dir = TempDir::new("topology_atomic");
    let path = dir.join("report.json");
    for text in [&b"first"[..], b"second"] {
        let mut o = foldfree::files::Outputs::new();
        o.output(&path, "report", &["json"]).unwrap();
        o.set(&path, text.to_vec());
        o.commit().unwrap();
    }
    assert_eq!(std::fs::read(&path).unwrap(), b"second");
    let mut o = foldfree::files::Outputs::new();
    assert!(o
        .output(&dir.join("no/such/dir/x.json"), "report", &["json"])
        .is_err());
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
}

// ---------------------------------------------------------------- frames

#[test]
fn frames_are_isometric_and_positively_oriented() {
    let mesh = read_obj(&data("camel_open.obj")).unwrap();
    let fr = frames::compute(&mesh);
    assert_eq!(fr.len(), mesh.faces.len());
    for (f, tri) in mesh.faces.iter().enumerate() {
        let p = tri.map(|v| mesh.positions[v as usize]);
        let l = fr.local[f];
        assert_eq!(l[0], [0.0, 0.0]);
        assert_eq!(l[1][1], 0.0);
        assert!(l[2][1] > 0.0, "face {f}");
        let scale = (0..3).map(|d| (p[1][d] - p[0][d]).abs()).sum::<f64>() + 1.0;
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            let e3: [f64; 3] = std::array::from_fn(|d| p[j][d] - p[i][d]);
            let len3 = e3.iter().map(|x| x * x).sum::<f64>().sqrt();
            let len2 = ((l[j][0] - l[i][0]).powi(2) + (l[j][1] - l[i][1]).powi(2)).sqrt();
            assert!((len3 - len2).abs() <= 1e-12 * scale * 10.0, "face {f}");
            let e2 = fr.to_local(f, e3);
            assert!((e2[0] - (l[j][0] - l[i][0])).abs() <= 1e-11 * scale);
            assert!((e2[1] - (l[j][1] - l[i][1])).abs() <= 1e-11 * scale);
        }
        let area2 = 0.5 * l[1][0] * l[2][1];
        assert!((area2 - fr.area[f]).abs() <= 1e-12 * fr.area[f].max(1.0));
        let [ex, ey] = fr.axes[f];
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        assert!((dot(ex, ex) - 1.0).abs() < 1e-14 && (dot(ey, ey) - 1.0).abs() < 1e-14);
        assert!(dot(ex, ey).abs() < 1e-14);
    }
}

#[test]
fn frames_of_a_right_triangle_and_a_degenerate_face() {
    let mesh = TriMesh {
        positions: vec![
            [1.0, 1.0, 1.0],
            [1.0, 1.0, 4.0],
            [1.0, 5.0, 1.0],
            [2.0, 2.0, 2.0],
        ],
        faces: vec![[0, 1, 2], [3, 3, 1]],
    };
    let fr = frames::compute(&mesh);
    assert_eq!(fr.local[0], [[0.0, 0.0], [3.0, 0.0], [0.0, 4.0]]);
    assert_eq!(fr.area[0], 6.0);
    assert_eq!(fr.axes[0], [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]);
    assert_eq!(fr.to_local(0, [7.0, 2.0, 3.0]), [3.0, 2.0]);
    assert_eq!(fr.local[1], [[0.0; 2]; 3]);
    assert_eq!(fr.area[1], 0.0);
}

// ---------------------------------------------------------------- timing

/// `cargo test --release --test mesh -- --ignored --nocapture topology_timing`
#[test]
#[ignore = "needs /work/shared/meshes and a release build"]
fn topology_timing_on_igea_249k() {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes/disk/igea_open_249k.obj");
    let t0 = std::time::Instant::now();
    let mesh = read_obj(&path).unwrap();
    let t1 = std::time::Instant::now();
    let t = Topology::build(&mesh, &path).unwrap();
    let t2 = std::time::Instant::now();
    println!(
        "igea: read {:?}, Topology::build {:?} ({} faces)",
        t1 - t0,
        t2 - t1,
        mesh.faces.len()
    );
    assert_eq!((mesh.positions.len(), mesh.faces.len()), (124_856, 249_302));
    assert!(t.is_disk());
    assert!(t2 - t1 < std::time::Duration::from_secs(1));
}
