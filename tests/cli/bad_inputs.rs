//! The malformed-input corpus (tests/data/bad, described row by row in its README.md) through the
//! `foldfree` binary: `param FILE -o OUT --init tutte --solver none` and `stats FILE` on every
//! surface file in the directory (OBJ, PLY, OFF, STL: read by extension), `volmap`/`volcheck`
//! on the tet files. Bad input exits 2 with exactly one stderr line
//! `foldfree: error: FILE: …` and writes nothing; valid input exits 0; nothing panics or hangs.
//!
//! The directory is listed, not the table, so a new file without a table row fails the test.
//! Two regression tests below pin bugs this corpus found (an index beyond i64 was called "not an
//! integer"; CR-only line endings made a file look empty).

use std::collections::BTreeSet;
use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::thread;
use std::time::{Duration, Instant};

/// A run that takes longer is a hang: the child is killed and the case fails.
const TIMEOUT: Duration = Duration::from_secs(20);

/// What one command must do with one file.
#[derive(Clone, Copy, Debug)]
enum Expect {
    /// Exit 0.
    Valid,
    /// Exit 0, and `param` wrote an atlas: the mesh was cut into charts (`f v/vt` with `vt`
    /// split along seams, so the counts of `v` and `vt` differ).
    Atlas,
    /// This exit code, and one stderr line `foldfree: error: FILE: …` containing the fragment.
    Error(i32, &'static str),
}

use Expect::{Atlas, Error, Valid};

use crate::common::TempDir;

struct Case {
    file: &'static str,
    param: Expect,
    stats: Expect,
}

/// Bad for both commands, exit 2.
const fn bad(file: &'static str, fragment: &'static str) -> Case {
    Case {
        file,
        param: Error(2, fragment),
        stats: Error(2, fragment),
    }
}

/// Valid for both commands.
const fn valid(file: &'static str) -> Case {
    Case {
        file,
        param: Valid,
        stats: Valid,
    }
}

/// A valid mesh that is not a disk: `stats` describes it, `param` cuts it into disk charts.
const fn not_disk(file: &'static str) -> Case {
    Case {
        file,
        param: Atlas,
        stats: Valid,
    }
}

/// One row per file in tests/data/bad (same order as its README).
const CASES: &[Case] = &[
    bad(
        "binary_garbage.obj",
        "cannot read: line 1: binary data (byte 0x1a), not an OBJ text file",
    ),
    bad(
        "non_utf8_bytes.obj",
        "cannot read: line 4: not UTF-8 text (binary file?)",
    ),
    bad("empty_0_bytes.obj", "the mesh has no faces"),
    bad("only_comments.obj", "the mesh has no faces"),
    bad("no_faces.obj", "the mesh has no faces"),
    bad(
        "truncated_mid_line.obj",
        "cannot read: line 8: vertex coordinate \"1.25e\" is not a number",
    ),
    bad(
        "truncated_mid_face.obj",
        "cannot read: line 7: face has 2 vertices",
    ),
    bad(
        "vertex_with_two_coordinates.obj",
        "cannot read: line 3: vertex has 2 coordinates, need 3",
    ),
    bad(
        "trailing_garbage_after_number.obj",
        "cannot read: line 3: vertex coordinate \"3abc\" is not a number",
    ),
    bad(
        "trailing_garbage_after_index.obj",
        "cannot read: line 5: face vertex \"3x\" does not start with an integer index",
    ),
    bad(
        "nan_coordinate.obj",
        "vertex 1 has a non-finite coordinate (NaN)",
    ),
    bad(
        "inf_coordinate.obj",
        "vertex 2 has a non-finite coordinate (inf)",
    ),
    bad(
        "overflowing_coordinate_1e400.obj",
        "vertex 1 has a non-finite coordinate (inf)",
    ),
    bad(
        "index_zero.obj",
        "cannot read: line 5: face vertex index 0 (OBJ indices start at 1)",
    ),
    bad(
        "huge_index.obj",
        "face 0 refers to vertex 99999999999, but there are only 3 vertices",
    ),
    bad(
        "index_overflows_i64.obj",
        "face vertex index 99999999999999999999999 is out of range",
    ),
    bad(
        "negative_index_before_start.obj",
        "face 0 refers to vertex -10, but there are only 3 vertices",
    ),
    // "1 vertices": the fragment stops before the plural so a grammar fix does not break it.
    bad(
        "face_with_one_vertex.obj",
        "cannot read: line 5: face has 1 vert",
    ),
    bad(
        "face_with_two_vertices.obj",
        "cannot read: line 5: face has 2 vertices",
    ),
    bad("face_repeated_vertex.obj", "face 0 uses vertex 1 twice"),
    valid("quad_valid.obj"),
    valid("pentagon_valid.obj"),
    bad("duplicate_face.obj", "face 2 is a duplicate of face 0"),
    bad(
        "duplicate_face_reversed.obj",
        "face 2 is a duplicate of face 0",
    ),
    bad(
        "nonmanifold_edge_three_faces.obj",
        "edge (0, 1) is non-manifold: it is shared by 3 faces (faces [0, 1, 2])",
    ),
    // A pinched vertex: `stats` names it, `param` splits it into one vertex per fan.
    Case {
        file: "nonmanifold_bowtie_vertex.obj",
        param: Atlas,
        stats: Error(
            2,
            "vertex 0 is non-manifold: its faces form 2 separate fans",
        ),
    },
    bad(
        "inconsistent_orientation.obj",
        "inconsistent orientation: faces 0 and 1 traverse edge (0, 1) in the same direction",
    ),
    bad(
        "zero_area_face.obj",
        "face 2 is degenerate (area 0.000e0, below",
    ),
    bad(
        "needle_face_below_tolerance.obj",
        "face 2 is degenerate (area 5.000e-13, below 2.000e-12",
    ),
    valid("needle_face_above_tolerance.obj"),
    // PLY, OFF and STL: the same commands, read by extension.
    bad(
        "ply_binary_truncated.ply",
        "cannot read: byte 274: face 1, property `vertex_indices`: a list of 3 items does not fit in the 5 bytes left",
    ),
    bad(
        "ply_face_index_out_of_range.ply",
        "face 1 refers to vertex 9, but there are only 4 vertices",
    ),
    bad(
        "ply_vertex_count_too_large.ply",
        "cannot read: line 4: the header announces 1000000 `vertex` elements",
    ),
    valid("ply_quad_with_normals_valid.ply"),
    valid("ply_binary_big_endian_valid.ply"),
    bad(
        "off_fewer_faces_than_announced.off",
        "cannot read: line 9: file ends after 2 of the 3 faces announced",
    ),
    bad(
        "off_more_faces_than_announced.off",
        "cannot read: line 9: a record past the counts of line 3 (vertices 4, faces 1)",
    ),
    bad(
        "off_face_with_two_vertices.off",
        "cannot read: line 8: face 1 has 2 vertices, need at least 3",
    ),
    valid("coff_quad_valid.off"),
    bad(
        "stl_binary_count_larger_than_file.stl",
        "cannot read: byte 80: the header announces 1000 triangles (84 + 50·1000 = 50084 bytes), the file has 134 bytes",
    ),
    bad(
        "stl_ascii_garbage.stl",
        "cannot read: line 2: expected `facet` or `endsolid`, found",
    ),
    bad(
        "stl_ascii_misspelt_keyword.stl",
        "cannot read: line 6: facet 0: expected `vertex` or `endloop`, found \"vertxe\"",
    ),
    bad(
        "stl_ascii_truncated.stl",
        "cannot read: line 12: file ends inside facet 1",
    ),
    valid("stl_binary_square_valid.stl"),
    valid("gltf_square_valid.gltf"),
    valid("glb_square_valid.glb"),
    bad(
        "gltf_triangle_strip.gltf",
        "cannot read: meshes[0].primitives[0]: mode 5 (TriangleStrip); only TRIANGLES (4) is read",
    ),
    bad(
        "gltf_sparse_accessor.gltf",
        "cannot read: meshes[0].primitives[0].attributes.POSITION (accessor 0): sparse accessors are not supported",
    ),
    bad(
        "gltf_missing_bin.gltf",
        "cannot read: buffers[0]: external buffer \"gltf_missing_bin_absent.bin\"",
    ),
    bad(
        "gltf_index_out_of_range.gltf",
        "cannot read: meshes[0].primitives[0].indices: triangle 1 refers to vertex 7, but there are only 4 vertices",
    ),
    bad(
        "gltf_buffer_too_short.gltf",
        "cannot read: buffers[0]: byteLength is 60, but the data has 36 bytes",
    ),
    bad(
        "gltf_unsupported_data_uri.gltf",
        "cannot read: buffers[0]: unsupported data URI \"data:text/plain,hello\"",
    ),
    bad(
        "gltf_accessor_past_view.gltf",
        "cannot read: meshes[0].primitives[0].attributes.POSITION (accessor 0): 5 elements of 12 bytes (stride 12) from byte 0 run past bufferView 0 (48 bytes)",
    ),
    bad(
        "gltf_no_position.gltf",
        "cannot read: meshes[0].primitives[0].attributes[\"POSITION\"]: Missing data",
    ),
    bad(
        "gltf_not_json.gltf",
        "cannot read: not valid JSON: EOF while parsing a list at line 2 column 0",
    ),
    bad(
        "gltf_degenerate_triangle_second_primitive.gltf",
        "meshes[0].primitives[1] triangle 0: face 2 is degenerate (area 0.000e0",
    ),
    bad(
        "glb_truncated.glb",
        "cannot read: byte 8: GLB: the header says 574 bytes, the file has 554",
    ),
    bad("binary_garbage.mesh", ":1: not UTF-8 text (binary file?)"),
    bad(
        "empty_0_bytes.mesh",
        ":1: file truncated: no Vertices section",
    ),
    bad(
        "truncated_vertices.mesh",
        ":6: file truncated: expected a coordinate",
    ),
    bad(
        "nan_vertex.mesh",
        ":6: vertex 1 has a non-finite coordinate",
    ),
    bad(
        "tet_index_out_of_range.mesh",
        ":11: tet 0 uses vertex index 9, but there are 4 vertices",
    ),
    bad("tet_index_zero.mesh", ":11: tet 0 uses vertex index 0"),
    bad(
        "no_tetrahedra.mesh",
        "file truncated: no Tetrahedra section",
    ),
    bad("inverted_rest_tet.mesh", "rest tet 0 is inverted"),
    bad("zero_volume_tet.mesh", "rest tet 0 has zero volume"),
    // TetGen pairs: each file of a pair names the pair, so both rows give the same error.
    bad("tetgen_count_u64_max.node", "points announced, 1 found"),
    bad("tetgen_count_u64_max.ele", "points announced, 1 found"),
    bad(
        "tetgen_ten_nodes_four_given.node",
        "a tet has 5 fields, the header announces 11",
    ),
    bad(
        "tetgen_ten_nodes_four_given.ele",
        "a tet has 5 fields, the header announces 11",
    ),
    bad("tetgen_attribute_count_overflow.node", "overflow"),
    bad("tetgen_attribute_count_overflow.ele", "overflow"),
    not_disk("two_disjoint_disks.obj"),
    not_disk("closed_tetrahedron.obj"),
    valid("very_long_line.obj"),
    valid("crlf_line_endings.obj"),
    valid("cr_only_line_endings.obj"),
    valid("utf8_bom.obj"),
    // The issue-25 audit: counts and indices at the integer limits, for every reader.
    bad(
        "index_2pow32_plus_4.obj",
        "face 1 refers to vertex 4294967300, but there are only 4 vertices",
    ),
    bad(
        "huge_and_tiny_coordinates.obj",
        "face 0 is degenerate (area 0.000e0 x bbox diagonal^2, below the tolerance 1.000e-12",
    ),
    bad(
        "ply_vertex_count_u64_max.ply",
        "cannot read: line 3: element `vertex` count \"18446744073709551615\" is not a non-negative integer",
    ),
    bad(
        "ply_binary_list_count_u32_max.ply",
        "cannot read: byte 220: face 0, property `vertex_indices`: a list of 4294967295 items does not fit",
    ),
    bad(
        "off_vertex_count_u64_max.off",
        "cannot read: line 2: vertex count \"18446744073709551615\" is not a non-negative integer",
    ),
    valid("off_face_colour_valid.off"),
    // A valid mesh whose map, at the mesh's size, does not fit in f64 (was exit 1 after the
    // solve, "texture coordinate 0 is not finite").
    Case {
        file: "square_near_f64_max.obj",
        param: Error(2, "in this file's units (coordinates up to"),
        stats: Valid,
    },
    bad(
        "stl_binary_count_u32_max.stl",
        "cannot read: byte 80: the header announces 4294967295 triangles",
    ),
    valid("stl_binary_header_says_solid_valid.stl"),
    bad(
        "glb_json_chunk_length_past_end.glb",
        "cannot read: byte 12: GLB: a chunk of 4294967280 bytes runs past the file's 552",
    ),
    bad(
        "gltf_view_length_u64_max.gltf",
        "bufferView 0 (bytes 0 + 18446744073709551615) runs past buffer 0",
    ),
    bad(
        "gltf_nested_1000_deep.gltf",
        "cannot read: not valid JSON: recursion limit exceeded",
    ),
    bad(
        "vertex_count_u64_max.mesh",
        ":9: expected a coordinate, found `Tetrahedra`",
    ),
    bad(
        "tet_index_2pow32_plus_4.mesh",
        ":11: tet 0 uses vertex index 4294967300, but there are 4 vertices",
    ),
    bad(
        "unknown_section_count_u64_max.mesh",
        ":15: file truncated: section Whatever announces 18446744073709551615 records",
    ),
    bad(
        "tetgen_point_attribute_not_a_number.node",
        ":2: expected a point attribute, found `abc`",
    ),
    bad(
        "tetgen_point_attribute_not_a_number.ele",
        ":2: expected a point attribute, found `abc`",
    ),
    bad(
        "tetgen_tet_index_i64_max.node",
        "tet 0 uses vertex index 9223372036854775807, but there are 4 vertices",
    ),
    bad(
        "tetgen_tet_index_i64_max.ele",
        "tet 0 uses vertex index 9223372036854775807, but there are 4 vertices",
    ),
];

fn bad_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bad")
}

/// The corpus files (everything in the directory but README.md), sorted.
fn corpus_files() -> BTreeSet<String> {
    fs::read_dir(bad_dir())
        .expect("list tests/data/bad")
        .map(|e| {
            e.expect("read a tests/data/bad entry")
                .file_name()
                .to_string_lossy()
                .into_owned()
        })
        .filter(|n| n != "README.md")
        .collect()
}

fn case(file: &str) -> &'static Case {
    CASES
        .iter()
        .find(|c| c.file == file)
        .unwrap_or_else(|| panic!("{file}: no row in CASES"))
}

/// What a finished run of the binary produced.
struct Run {
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

/// Runs the binary with `args`, killing it after [`TIMEOUT`] (`Err` then). Output is drained
/// on threads so a chatty child cannot block on a full pipe.
fn run_foldfree(args: &[&Path]) -> Result<Run, String> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start foldfree: {e}"))?;
    let drain = |mut pipe: Box<dyn Read + Send>| {
        thread::spawn(move || {
            let mut buf = Vec::new();
            let _ = pipe.read_to_end(&mut buf);
            String::from_utf8_lossy(&buf).into_owned()
        })
    };
    let out = drain(Box::new(child.stdout.take().expect("piped stdout")));
    let err = drain(Box::new(child.stderr.take().expect("piped stderr")));
    let start = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if start.elapsed() > TIMEOUT => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!("hang: still running after {TIMEOUT:?}, killed"));
            }
            Ok(None) => thread::sleep(Duration::from_millis(5)),
            Err(e) => return Err(format!("waiting for foldfree failed: {e}")),
        }
    };
    Ok(Run {
        code: status.code(),
        stdout: out.join().unwrap_or_default(),
        stderr: err.join().unwrap_or_default(),
    })
}

/// Properties of every run, whatever the file: no panic text, a normal exit (not a signal),
/// never exit 1 (that is for machine or solver failures, not for input).
fn universal_problems(run: &Run) -> Vec<String> {
    let mut problems = Vec::new();
    for text in [&run.stdout, &run.stderr] {
        for bad in ["panicked", "RUST_BACKTRACE"] {
            if text.contains(bad) {
                problems.push(format!("output contains {bad:?}"));
            }
        }
    }
    match run.code {
        None => problems.push("killed by a signal".to_string()),
        Some(1) => problems.push("exit 1 (machine/solver failure) for an input file".to_string()),
        Some(_) => {}
    }
    problems
}

/// For an error: stderr is exactly one line `foldfree: error: FILE…` containing `fragment`,
/// stdout is empty.
fn error_line_problems(run: &Run, file: &Path, fragment: &str) -> Vec<String> {
    let mut problems = Vec::new();
    let lines: Vec<&str> = run.stderr.lines().collect();
    if lines.len() != 1 || !run.stderr.ends_with('\n') {
        problems.push(format!(
            "stderr is not exactly one line ({} lines)",
            lines.len()
        ));
    }
    let first = lines.first().copied().unwrap_or("");
    // A TetGen pair's error names the file of the pair where it is: match the common stem.
    let named = match file.extension().and_then(|e| e.to_str()) {
        Some("node" | "ele") => file.with_extension(""),
        _ => file.to_path_buf(),
    };
    let prefix = format!("foldfree: error: {}", named.display());
    if !first.starts_with(&prefix) {
        problems.push(format!("stderr does not begin with {prefix:?}"));
    }
    if !first.contains(fragment) {
        problems.push(format!("stderr does not contain {fragment:?}"));
    }
    if !run.stdout.is_empty() {
        problems.push(format!("stdout is not empty: {:?}", run.stdout));
    }
    problems
}

/// `v` and `vt` records in a written OBJ: one `vt` per `v`, and at least one `f`.
fn output_problems(out: &Path) -> Vec<String> {
    let Ok(text) = fs::read_to_string(out) else {
        return vec![format!("no readable output at {}", out.display())];
    };
    let count = |tag: &str| {
        text.lines()
            .filter(|l| l.split_ascii_whitespace().next() == Some(tag))
            .count()
    };
    let (v, vt, f) = (count("v"), count("vt"), count("f"));
    if v == 0 || v != vt || f == 0 {
        vec![format!("output has {v} v, {vt} vt, {f} f records")]
    } else {
        Vec::new()
    }
}

/// An atlas: `v`, `vt` and `f` records, every face with texture indices (`a/t`).
fn atlas_problems(out: &Path) -> Vec<String> {
    let Ok(text) = fs::read_to_string(out) else {
        return vec![format!("no readable output at {}", out.display())];
    };
    let lines: Vec<&str> = text.lines().collect();
    let tagged = |tag: &str| -> Vec<&str> {
        lines
            .iter()
            .copied()
            .filter(|l| l.split_ascii_whitespace().next() == Some(tag))
            .collect()
    };
    let faces = tagged("f");
    let (v, vt, f) = (tagged("v").len(), tagged("vt").len(), faces.len());
    let untextured = faces
        .iter()
        .filter(|l| l.split_ascii_whitespace().skip(1).any(|c| !c.contains('/')))
        .count();
    if v == 0 || vt == 0 || f == 0 || untextured > 0 {
        vec![format!(
            "atlas has {v} v, {vt} vt, {f} f records, {untextured} faces without vt"
        )]
    } else {
        Vec::new()
    }
}

/// glTF: `.gltf` and `.glb`.
fn is_gltf(path: &Path) -> bool {
    matches!(
        path.extension().and_then(|e| e.to_str()),
        Some("gltf" | "glb")
    )
}

/// A written `.glb` reads back with one TEXCOORD set (the map) in every primitive.
fn glb_problems(out: &Path) -> Vec<String> {
    let Ok(bytes) = fs::read(out) else {
        return vec![format!("no readable output at {}", out.display())];
    };
    let mut none = |_: &str| Err("no external buffers expected".to_string());
    match foldfree::mesh::formats::gltf::parse_gltf(&bytes, out, &mut none) {
        Ok(scene) if scene.primitives.iter().all(|p| p.texcoord_sets == [0]) => Vec::new(),
        Ok(_) => vec!["the output glb lacks the new TEXCOORD_0".to_string()],
        Err(e) => vec![format!("the output glb does not read back: {e}")],
    }
}

/// Tet mesh formats: MEDIT `.mesh` and TetGen `.node` / `.ele`.
fn is_tet(path: &Path) -> bool {
    matches!(
        path.extension().and_then(|e| e.to_str()),
        Some("mesh" | "node" | "ele")
    )
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Cmd {
    Param,
    Stats,
}

/// `foldfree param INPUT -o OUT --init tutte --solver none` or `foldfree stats INPUT`; for a
/// tet mesh (`.mesh`) `foldfree volmap INPUT --init INPUT --fix-boundary -o OUT` or
/// `foldfree volcheck INPUT --rest INPUT`.
fn run_cmd(cmd: Cmd, input: &Path, out: &Path) -> Result<Run, String> {
    if is_tet(input) {
        return match cmd {
            Cmd::Param => run_foldfree(&[
                Path::new("volmap"),
                input,
                Path::new("--init"),
                input,
                Path::new("--fix-boundary"),
                Path::new("-q"),
                Path::new("-o"),
                out,
            ]),
            Cmd::Stats => run_foldfree(&[Path::new("volcheck"), input, Path::new("--rest"), input]),
        };
    }
    match cmd {
        Cmd::Param => run_foldfree(&[
            Path::new("param"),
            input,
            Path::new("-o"),
            out,
            Path::new("--init"),
            Path::new("tutte"),
            Path::new("--solver"),
            Path::new("none"),
        ]),
        Cmd::Stats => run_foldfree(&[Path::new("stats"), input]),
    }
}

/// The `param` output of `file`. Its extension is checked before the input is read: a tet
/// map is a `.mesh`; a glTF input is written back as a `.glb`.
fn out_name(file: &str) -> String {
    let ext = if is_tet(Path::new(file)) {
        "mesh"
    } else if is_gltf(Path::new(file)) {
        "glb"
    } else {
        "obj"
    };
    format!("{file}.out.{ext}")
}

/// Runs `cmd` on `file` (output, for `param`, in `dir`) and lists every violated expectation.
fn check(cmd: Cmd, file: &str, expect: Expect, dir: &TempDir) -> Vec<String> {
    let input = bad_dir().join(file);
    let out = dir.join(&out_name(file));
    let run = match run_cmd(cmd, &input, &out) {
        Ok(run) => run,
        Err(e) => return vec![e],
    };
    let mut problems = universal_problems(&run);
    let failed = run.code != Some(0);
    if cmd == Cmd::Param && failed && out.exists() {
        problems.push("an output file was written although the run failed".to_string());
    }
    match expect {
        Valid => {
            if failed {
                problems.push(format!("exit {:?}, expected 0", run.code));
            } else if cmd == Cmd::Param && is_gltf(&out) {
                problems.extend(glb_problems(&out));
            } else if cmd == Cmd::Param {
                problems.extend(output_problems(&out));
            } else if !run.stdout.contains("valid: yes") {
                problems.push("stats did not print \"valid: yes\"".to_string());
            }
        }
        Atlas => {
            if failed {
                problems.push(format!("exit {:?}, expected 0", run.code));
            } else if cmd == Cmd::Param {
                problems.extend(atlas_problems(&out));
            }
        }
        Error(code, fragment) => {
            if run.code != Some(code) {
                problems.push(format!("exit {:?}, expected {code}", run.code));
            }
            problems.extend(error_line_problems(&run, &input, fragment));
        }
    }
    let name = match cmd {
        Cmd::Param => "param",
        Cmd::Stats => "stats",
    };
    problems
        .into_iter()
        .map(|p| {
            format!(
                "{file} ({name}): {p}\n    stderr: {}",
                run.stderr.trim_end()
            )
        })
        .collect()
}

#[test]
fn every_corpus_file_gives_its_documented_result_without_panic_or_hang() {
    let dir = TempDir::new("corpus");
    let files = corpus_files();
    assert!(files.len() >= CASES.len(), "corpus files missing");
    let mut problems = Vec::new();
    for file in &files {
        let Some(case) = CASES.iter().find(|c| c.file == file) else {
            problems.push(format!(
                "{file}: no row in CASES (add one, and one to the README)"
            ));
            continue;
        };
        problems.extend(check(Cmd::Param, file, case.param, &dir));
        problems.extend(check(Cmd::Stats, file, case.stats, &dir));
    }
    // Only the outputs of valid runs remain: no temporaries, nothing from failed runs.
    let expected_outputs: BTreeSet<String> = CASES
        .iter()
        .filter(|c| matches!(c.param, Valid | Atlas))
        .map(|c| out_name(c.file))
        .collect();
    let leftovers: Vec<String> = dir
        .entries()
        .into_iter()
        .filter(|n| !expected_outputs.contains(n))
        .collect();
    if !leftovers.is_empty() {
        problems.push(format!("unexpected files in the output dir: {leftovers:?}"));
    }
    assert!(problems.is_empty(), "\n{}", problems.join("\n"));
}

#[test]
fn every_table_row_names_an_existing_file() {
    let files = corpus_files();
    let stale: Vec<&str> = CASES
        .iter()
        .map(|c| c.file)
        .filter(|f| !files.contains(*f))
        .collect();
    assert!(stale.is_empty(), "rows without a file: {stale:?}");
    let mut seen = BTreeSet::new();
    for c in CASES {
        assert!(seen.insert(c.file), "{}: two rows", c.file);
    }
}

#[test]
fn every_corpus_file_has_a_readme_row() {
    let readme =
        fs::read_to_string(bad_dir().join("README.md")).expect("read tests/data/bad/README.md");
    let missing: Vec<String> = corpus_files()
        .into_iter()
        .filter(|f| !readme.contains(&format!("| `{f}` |")))
        .collect();
    assert!(missing.is_empty(), "no README row for {missing:?}");
}

/// `f 1 2 99999999999999999999999`: the index does not fit in i64, so parsing it fails and the
/// message claims the token "does not start with an integer index". It does; the problem is
/// the range, and `huge_index.obj` (99999999999) gets "refers to vertex …, but there are only 3
/// vertices". Regression test: the message names the index as out of range.
#[test]
fn index_beyond_i64_is_reported_as_out_of_range() {
    let dir = TempDir::new("i64");
    let file = "index_overflows_i64.obj";
    assert!(
        matches!(case(file).param, Error(2, _)),
        "table and regression test disagree"
    );
    let input = bad_dir().join(file);
    for cmd in [Cmd::Param, Cmd::Stats] {
        let out = dir.join("out.obj");
        let run = run_cmd(cmd, &input, &out).expect("run foldfree");
        let mut problems = universal_problems(&run);
        if run.code != Some(2) {
            problems.push(format!("exit {:?}, expected 2", run.code));
        }
        problems.extend(error_line_problems(&run, &input, "99999999999999999999999"));
        if out.exists() {
            problems.push("an output file was written".to_string());
        }
        if run.stderr.contains("does not start with an integer") {
            problems.push("misleading: the token does start with an integer".to_string());
        }
        if !(run.stderr.contains("only 3 vertices") || run.stderr.contains("out of range")) {
            problems.push("the message does not say the index is out of range".to_string());
        }
        assert!(
            problems.is_empty(),
            "{}\n    stderr: {}",
            problems.join("\n"),
            run.stderr.trim_end()
        );
    }
}

/// A file with `\r`-only (classic Mac) line endings is one line to the parser; when it starts
/// with a comment, everything is commented out and the error says "the mesh has no faces",
/// which is false (the file has 2). Regression test: `\r` is read as a line break (exit 0), or
/// the file is refused naming its line endings.
#[test]
fn cr_only_line_endings_are_not_reported_as_having_no_faces() {
    let dir = TempDir::new("cr");
    let file = "cr_only_line_endings.obj";
    assert!(
        matches!(case(file).param, Valid),
        "table and regression test disagree"
    );
    for cmd in [Cmd::Param, Cmd::Stats] {
        let accepted = check(cmd, file, Valid, &dir);
        let named = check(cmd, file, Error(2, "line ending"), &dir);
        assert!(
            accepted.is_empty() || named.is_empty(),
            "neither read nor refused naming the line endings:\n{}",
            accepted.join("\n")
        );
    }
}
