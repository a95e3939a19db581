//! PLY, OFF and STL in: every mesh of tests/data/*.obj written by the small writers below
//! (independent of the library's readers) reads back as the same mesh — PLY and OFF with the
//! same vertices and faces in the same order, positions bit-equal (binary `double`, and ASCII
//! written as shortest round-trip decimals); STL with the same triangles by position after
//! welding, vertices in first-appearance order. Then the CLI on generated files: `param` and
//! `stats` on the camel as PLY, OFF and STL.

use std::fmt::Write as _;
use std::fs;
use std::path::Path;

use foldfree::mesh::formats::{parse_surface, Encoding, SurfaceFormat};
use foldfree::mesh::{read_obj, read_surface, MeshError, TriMesh};

use crate::common::{data_dir, TempDir};

/// Every `tests/data/*.obj` (valid or not for the solvers: reading does not validate).
fn data_meshes() -> Vec<(String, TriMesh)> {
    let mut names: Vec<String> = fs::read_dir(data_dir())
        .expect("list tests/data")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.ends_with(".obj"))
        .collect();
    names.sort();
    assert!(names.len() >= 8, "tests/data has {} OBJ files", names.len());
    names
        .into_iter()
        .map(|n| {
            let mesh = read_obj(&data_dir().join(&n)).expect("data OBJ reads");
            (n, mesh)
        })
        .collect()
}

// ---- writers (test-only, deliberately plain) ----

/// ASCII PLY with extra properties before, between and after the used ones, an extra element
/// and float colours for a `uchar` property, all of which the reader must skip.
fn ply_ascii(m: &TriMesh) -> Vec<u8> {
    let mut s = String::new();
    let _ = write!(
        s,
        "ply\nformat ascii 1.0\ncomment test writer\nobj_info nothing\n\
         element vertex {}\nproperty float confidence\nproperty double x\nproperty double y\n\
         property float nx\nproperty double z\nproperty uchar red\nproperty list uchar float uv\n\
         element face {}\nproperty list uchar int vertex_indices\nproperty int flags\n\
         element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n",
        m.positions.len(),
        m.faces.len()
    );
    for p in &m.positions {
        let _ = writeln!(s, "0.5 {} {} 0 {} 255 2 0.25 0.75", p[0], p[1], p[2]);
    }
    for f in &m.faces {
        let _ = writeln!(s, "3 {} {} {} 7", f[0], f[1], f[2]);
    }
    s.push_str("0 1\n");
    s.into_bytes()
}

/// Binary PLY: `double` positions, a float normal and uchar colours skipped, `uint` indices.
fn ply_binary(m: &TriMesh, big_endian: bool) -> Vec<u8> {
    let order = if big_endian { "big" } else { "little" };
    let mut out = format!(
        "ply\nformat binary_{order}_endian 1.0\nelement vertex {}\nproperty double x\n\
         property double y\nproperty double z\nproperty float nx\nproperty uchar red\n\
         property uchar green\nelement face {}\nproperty list uchar uint vertex_indices\n\
         end_header\n",
        m.positions.len(),
        m.faces.len()
    )
    .into_bytes();
    for p in &m.positions {
        for c in p {
            out.extend(if big_endian {
                c.to_be_bytes()
            } else {
                c.to_le_bytes()
            });
        }
        out.extend(if big_endian {
            1.5f32.to_be_bytes()
        } else {
            1.5f32.to_le_bytes()
        });
        out.extend([200, 100]);
    }
    for f in &m.faces {
        out.push(3);
        for &v in f {
            out.extend(if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }
    }
    out
}

/// OFF with comments, the counts after the keyword, and a colour after each face.
fn off(m: &TriMesh, keyword: &str) -> Vec<u8> {
    let mut s = format!("{keyword}\n# a comment\n\n");
    let _ = writeln!(s, "{} {} 0  # counts", m.positions.len(), m.faces.len());
    for p in &m.positions {
        let _ = write!(s, "{} {} {}", p[0], p[1], p[2]);
        if keyword == "COFF" {
            s.push_str(" 0.1 0.2 0.3 1");
        }
        s.push('\n');
    }
    for f in &m.faces {
        let _ = writeln!(s, "3 {} {} {} 255 0 0", f[0], f[1], f[2]);
    }
    s.into_bytes()
}

fn stl_ascii(m: &TriMesh) -> Vec<u8> {
    let mut s = String::from("solid test mesh\n");
    for f in &m.faces {
        // A NaN normal, as some exporters write: the reader ignores normals.
        s.push_str("  facet normal nan 0 1\n    outer loop\n");
        for &v in f {
            let p = m.positions[v as usize];
            let _ = writeln!(s, "      vertex {} {} {}", p[0], p[1], p[2]);
        }
        s.push_str("    endloop\n  endfacet\n");
    }
    s.push_str("endsolid test mesh\n");
    s.into_bytes()
}

/// Binary STL; the header starts with "solid" on purpose (many exporters do that).
fn stl_binary(m: &TriMesh) -> Vec<u8> {
    let mut out = vec![b' '; 80];
    out[..11].copy_from_slice(b"solid bytes");
    out.extend((m.faces.len() as u32).to_le_bytes());
    for f in &m.faces {
        for _ in 0..3 {
            out.extend(0f32.to_le_bytes());
        }
        for &v in f {
            for c in m.positions[v as usize] {
                out.extend((c as f32).to_le_bytes());
            }
        }
        out.extend([0, 0]);
    }
    out
}

// ---- checks ----

fn parse(bytes: &[u8], name: &str, format: SurfaceFormat) -> TriMesh {
    match parse_surface(bytes, Path::new(name), format) {
        Ok((m, _)) => m,
        Err(e) => panic!("{name}: {e}"),
    }
}

/// Same vertices (bit-equal) and faces, in the same order.
fn assert_same(name: &str, got: &TriMesh, want: &TriMesh) {
    assert_eq!(got.faces, want.faces, "{name}: faces");
    assert_eq!(
        got.positions.len(),
        want.positions.len(),
        "{name}: vertex count"
    );
    for (i, (a, b)) in got.positions.iter().zip(&want.positions).enumerate() {
        assert_eq!(
            a.map(f64::to_bits),
            b.map(f64::to_bits),
            "{name}: vertex {i}"
        );
    }
}

/// STL: face `i` has the corners of face `i` by position (`round` maps a source coordinate to
/// what the file stores), and the vertices are the distinct corner positions in order of first
/// appearance.
fn assert_same_triangles(name: &str, got: &TriMesh, want: &TriMesh, round: fn(f64) -> f64) {
    assert_eq!(got.faces.len(), want.faces.len(), "{name}: triangle count");
    let mut seen: Vec<[u64; 3]> = Vec::new();
    for (t, (g, w)) in got.faces.iter().zip(&want.faces).enumerate() {
        for k in 0..3 {
            let gp = got.positions[g[k] as usize];
            let wp = want.positions[w[k] as usize].map(round);
            assert_eq!(
                gp.map(f64::to_bits),
                wp.map(f64::to_bits),
                "{name}: face {t} corner {k}"
            );
            let key = wp.map(|c| (c + 0.0).to_bits());
            if !seen.contains(&key) {
                assert_eq!(
                    g[k] as usize,
                    seen.len(),
                    "{name}: face {t}: first-appearance order"
                );
                seen.push(key);
            }
        }
    }
    assert_eq!(
        got.positions.len(),
        seen.len(),
        "{name}: welded vertex count"
    );
}

fn as_f32(c: f64) -> f64 {
    f64::from(c as f32)
}

#[test]
fn every_data_mesh_round_trips_through_ply_off_and_stl() {
    for (name, mesh) in data_meshes() {
        let ply = parse(&ply_ascii(&mesh), &name, SurfaceFormat::Ply);
        assert_same(&format!("{name} as ASCII PLY"), &ply, &mesh);
        for big in [false, true] {
            let ply = parse(&ply_binary(&mesh, big), &name, SurfaceFormat::Ply);
            assert_same(
                &format!("{name} as binary PLY (big endian: {big})"),
                &ply,
                &mesh,
            );
        }
        for keyword in ["OFF", "COFF", "NOFF"] {
            let got = parse(&off(&mesh, keyword), &name, SurfaceFormat::Off);
            assert_same(&format!("{name} as {keyword}"), &got, &mesh);
        }
        let stl = parse(&stl_ascii(&mesh), &name, SurfaceFormat::Stl);
        assert_same_triangles(&format!("{name} as ASCII STL"), &stl, &mesh, |c| c);
        let stl = parse(&stl_binary(&mesh), &name, SurfaceFormat::Stl);
        assert_same_triangles(&format!("{name} as binary STL"), &stl, &mesh, as_f32);
    }
}

#[test]
fn files_are_read_by_extension_with_format_and_encoding_reported() {
    let dir = TempDir::new("formats_by_extension");
    let mesh = read_obj(&data_dir().join("two_triangles.obj")).expect("reads");
    let cases: [(&str, Vec<u8>, SurfaceFormat, Encoding); 5] = [
        (
            "a.PLY",
            ply_ascii(&mesh),
            SurfaceFormat::Ply,
            Encoding::Text,
        ),
        (
            "b.ply",
            ply_binary(&mesh, true),
            SurfaceFormat::Ply,
            Encoding::BinaryBigEndian,
        ),
        (
            "c.off",
            off(&mesh, "OFF"),
            SurfaceFormat::Off,
            Encoding::Text,
        ),
        (
            "d.stl",
            stl_ascii(&mesh),
            SurfaceFormat::Stl,
            Encoding::Text,
        ),
        (
            "e.Stl",
            stl_binary(&mesh),
            SurfaceFormat::Stl,
            Encoding::BinaryLittleEndian,
        ),
    ];
    for (file, bytes, format, encoding) in cases {
        let path = dir.join(file);
        fs::write(&path, bytes).expect("write");
        let (got, info) = read_surface(&path, 1000).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((info.format, info.encoding), (format, encoding), "{file}");
        assert_eq!(got.faces.len(), 2, "{file}");
        assert_eq!(info.source_face_count, 2, "{file}");
    }
    // STL welded 6 corners into 4 vertices.
    let (_, info) = read_surface(&dir.join("d.stl"), 1000).expect("reads");
    assert_eq!(info.skipped, 2);
}

#[test]
fn polygons_are_fan_triangulated_like_obj() {
    let pentagon = "OFF\n5 1 0\n0 0 0\n2 0 0\n3 1 0\n1 2 0\n-1 1 0\n5 0 1 2 3 4\n";
    let (m, info) = parse_surface(pentagon.as_bytes(), Path::new("p.off"), SurfaceFormat::Off)
        .expect("pentagon");
    assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
    assert_eq!((info.source_face_count, info.polygons_triangulated), (1, 1));
    let ply = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
               property float z\nelement face 1\nproperty list uchar int vertex_index\nend_header\n\
               0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
    let (m, _) =
        parse_surface(ply.as_bytes(), Path::new("q.ply"), SurfaceFormat::Ply).expect("quad");
    assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3]]);
    let obj = foldfree::mesh::obj::parse_obj(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n",
        Path::new("q.obj"),
    )
    .expect("quad obj");
    assert_eq!(m.faces, obj.faces);
    // Elements in any order: faces before the vertices they name.
    let faces_first =
        "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
                       element vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                       end_header\n3 2 1 0\n0 0 0\n1 0 0\n0 1 0\n";
    let (m, _) = parse_surface(
        faces_first.as_bytes(),
        Path::new("r.ply"),
        SurfaceFormat::Ply,
    )
    .expect("faces first");
    assert_eq!((m.faces, m.positions.len()), (vec![[2, 1, 0]], 3));
    let e = error(
        faces_first.replace("3 2 1 0", "3 2 1 -1").as_bytes(),
        SurfaceFormat::Ply,
    );
    assert!(
        e.contains("face 0 refers to vertex -1, but there are only 3 vertices"),
        "{e}"
    );
}

/// The error of parsing `bytes` as `format`, as the CLI prints it (after `foldfree: error: `).
fn error(bytes: &[u8], format: SurfaceFormat) -> String {
    match parse_surface(bytes, Path::new("t"), format) {
        Ok(_) => panic!("parsed: {:?}", String::from_utf8_lossy(bytes)),
        Err(e) => e.to_string(),
    }
}

#[test]
fn malformed_files_give_located_errors() {
    let mesh = read_obj(&data_dir().join("square_grid_10x10.obj")).expect("reads");
    // Binary PLY cut anywhere inside the body: a located error, never a panic.
    let full = ply_binary(&mesh, false);
    let body = full
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("header")
        + 11;
    for cut in [body, body + 1, body + 100, full.len() - 1] {
        let e = error(&full[..cut], SurfaceFormat::Ply);
        assert!(e.starts_with("t: cannot read: "), "{e}");
        assert!(e.contains("byte ") || e.contains("line "), "{e}");
    }
    let e = error(&full[..full.len() - 1], SurfaceFormat::Ply);
    assert!(
        e.contains("face 199, property `vertex_indices`: a list of 3 items does not fit"),
        "{e}"
    );
    let e = error(&full[..body + 100], SurfaceFormat::Ply);
    assert!(
        e.contains("line 3: the header announces 121 `vertex` elements of at least 30 bytes each, but only 100 bytes follow"),
        "{e}"
    );
    // ASCII PLY with a vertex index past the end.
    let bad = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
               property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
               end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n";
    let e = error(bad.as_bytes(), SurfaceFormat::Ply);
    assert!(
        e.contains("face 0 refers to vertex 7, but there are only 3 vertices"),
        "{e}"
    );
    // A header count far beyond the file is refused before anything is reserved.
    let huge = bad.replace("element vertex 3", "element vertex 4000000000000");
    let e = error(huge.as_bytes(), SurfaceFormat::Ply);
    assert!(
        e.contains("line 3: the header announces 4000000000000 `vertex` elements"),
        "{e}"
    );
    // OFF: fewer faces than announced; a face with too few indices.
    let e = error(
        b"OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        SurfaceFormat::Off,
    );
    assert!(
        e.contains("line 6: file ends after 1 of the 2 faces announced"),
        "{e}"
    );
    let e = error(
        b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n",
        SurfaceFormat::Off,
    );
    assert!(
        e.contains("line 6: face 0 announces 4 vertices, the line gives 3"),
        "{e}"
    );
    let e = error(b"OFF BINARY\n", SurfaceFormat::Off);
    assert!(e.contains("line 1: binary OFF is not read"), "{e}");
    // STL: a binary count larger than the file; ASCII garbage.
    let mut stl = stl_binary(&mesh);
    stl[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = error(&stl, SurfaceFormat::Stl);
    assert!(
        e.contains("byte 80: the header announces 4294967295 triangles"),
        "{e}"
    );
    let e = error(
        b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 zero\n",
        SurfaceFormat::Stl,
    );
    assert!(
        e.contains("line 4: facet 0: vertex coordinate \"zero\" is not a number"),
        "{e}"
    );
    // No faces: the same error as an OBJ without faces.
    for (bytes, format) in [
        (&b"OFF\n0 0 0\n"[..], SurfaceFormat::Off),
        (&b"solid empty\nendsolid empty\n"[..], SurfaceFormat::Stl),
    ] {
        let e = parse_surface(bytes, Path::new("t"), format).expect_err("empty");
        assert!(matches!(e, MeshError::Empty { .. }), "{e}");
    }
}

/// A small deterministic stand-in for the fuzzer (`fuzz/fuzz_targets/surface_reader.rs`): every
/// prefix of each encoding of a small mesh, and every byte replaced by a few values, parses to a
/// mesh with in-range indices or to an error naming the file; never a panic. The same for the
/// glTF square of tests/data/bad as `.glb` and `.gltf` (`fuzz_targets/gltf_reader.rs`).
#[test]
fn every_prefix_and_byte_mutation_is_a_mesh_or_a_located_error() {
    let mesh = read_obj(&data_dir().join("unreferenced_vertex.obj")).expect("reads");
    let files = [
        (ply_ascii(&mesh), SurfaceFormat::Ply),
        (ply_binary(&mesh, false), SurfaceFormat::Ply),
        (ply_binary(&mesh, true), SurfaceFormat::Ply),
        (off(&mesh, "COFF"), SurfaceFormat::Off),
        (stl_ascii(&mesh), SurfaceFormat::Stl),
        (stl_binary(&mesh), SurfaceFormat::Stl),
    ];
    let check =
        |bytes: &[u8], format: SurfaceFormat| match parse_surface(bytes, Path::new("m"), format) {
            Ok((m, _)) => {
                let n = m.positions.len();
                assert!(m.faces.iter().flatten().all(|&v| (v as usize) < n));
            }
            Err(e) => assert!(e.to_string().starts_with("m: "), "{e}"),
        };
    let bad = data_dir().join("bad");
    let gltf_files = ["glb_square_valid.glb", "gltf_square_valid.gltf"].map(|n| {
        (
            std::fs::read(bad.join(n)).expect("reads"),
            SurfaceFormat::Gltf,
        )
    });
    for (bytes, format) in files.iter().chain(&gltf_files) {
        for cut in 0..bytes.len() {
            check(&bytes[..cut], *format);
        }
        let mut mutated = bytes.clone();
        for i in 0..bytes.len() {
            for b in [0u8, b'9', b'\n', b'-', 0xff] {
                mutated[i] = b;
                check(&mutated, *format);
            }
            mutated[i] = bytes[i];
        }
    }
}

#[test]
fn tet_and_scene_formats_are_refused_by_name() {
    for (file, fragment) in [
        ("a.mesh", "tetrahedral mesh format"),
        ("a.fbx", "not read by foldfree"),
    ] {
        let e = read_surface(Path::new(file), 10).expect_err("refused");
        assert!(e.to_string().contains(fragment), "{e}");
    }
}

// ---- the CLI on generated files ----

fn foldfree(args: &[&Path]) -> (Option<i32>, String, String) {
    let out = crate::common::foldfree(args);
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The camel as binary PLY: `param` (default engine) writes a full map; the Tutte maps of the
/// PLY, OFF and OBJ files are byte-identical (same mesh, same order); `stats` agrees on every
/// format. STL on the 10×10 grid and the bunny, which have no two vertices at one position: the
/// camel has 243 (its opening is a cut whose two sides share positions), and welding them
/// makes an STL of it non-manifold, as every STL reader would.
#[test]
fn cli_reads_ply_off_and_stl() {
    let dir = TempDir::new("formats_cli");
    let obj = data_dir().join("camel_open.obj");
    let mesh = read_obj(&obj).expect("camel");
    let ply = dir.join("camel_open.ply");
    fs::write(&ply, ply_binary(&mesh, false)).expect("write ply");
    let out = dir.join("out.obj");
    let (code, _, stderr) = foldfree(&[Path::new("param"), &ply, Path::new("-o"), &out]);
    assert_eq!(code, Some(0), "param camel_open.ply: {stderr}");
    let text = fs::read_to_string(&out).expect("map written");
    let count = |tag: &str| {
        text.lines()
            .filter(|l| l.split_ascii_whitespace().next() == Some(tag))
            .count()
    };
    assert_eq!(count("v"), mesh.positions.len());
    assert_eq!(count("vt"), mesh.positions.len());
    assert_eq!(count("f"), mesh.faces.len());

    let off_path = dir.join("camel_open.off");
    fs::write(&off_path, off(&mesh, "OFF")).expect("write off");
    let tutte = |input: &Path, name: &str| {
        let out = dir.join(name);
        let args = [
            Path::new("param"),
            input,
            Path::new("-o"),
            &out,
            Path::new("--init"),
            Path::new("tutte"),
            Path::new("--solver"),
            Path::new("none"),
        ];
        let (code, _, stderr) = foldfree(&args);
        assert_eq!(code, Some(0), "{}: {stderr}", input.display());
        fs::read(&out).expect("written")
    };
    let reference = tutte(&obj, "obj.obj");
    assert!(
        tutte(&ply, "ply.obj") == reference,
        "PLY map differs from the OBJ map"
    );
    assert!(
        tutte(&off_path, "off.obj") == reference,
        "OFF map differs from the OBJ map"
    );

    let stats = |input: &Path| {
        let (code, stdout, stderr) = foldfree(&[Path::new("stats"), input]);
        assert_eq!(code, Some(0), "stats {}: {stderr}", input.display());
        // Everything but the `file:` line.
        stdout
            .lines()
            .filter(|l| !l.starts_with("file:"))
            .collect::<Vec<_>>()
            .join("\n")
    };
    let want = stats(&obj);
    for p in [&ply, &off_path] {
        assert_eq!(stats(p), want, "stats of {}", p.display());
    }
    for name in ["square_grid_10x10", "bunny_npm"] {
        let obj = data_dir().join(format!("{name}.obj"));
        let mesh = read_obj(&obj).expect("reads");
        let ascii = dir.join(&format!("{name}.stl"));
        fs::write(&ascii, stl_ascii(&mesh)).expect("write stl");
        assert_eq!(stats(&ascii), stats(&obj), "stats of {}", ascii.display());
    }
}
