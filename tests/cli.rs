//! The `foldfree` binary end to end: exit codes, error messages, what is (not) written, and the
//! JSON report checked against an independent recomputation from the written OBJ
//! (tests/common/objcheck.rs). Uses only tests/data.

// The rest of the CLI harness, in tests/cli/.
mod cli {
    mod bad_inputs;
    mod determinism;
    mod nothing_lost;
    mod tuning;
}

mod common;
use common::objcheck;

use std::collections::BTreeSet;
use std::fs;
use std::path::Path;
use std::process::Command;

use serde_json::Value;

use common::{data_obj as data, TempDir};

/// Valid disks: `param` writes a map, `stats` says "disk: yes".
const VALID: [&str; 5] = [
    "single_triangle",
    "two_triangles",
    "square_grid_10x10",
    "unreferenced_vertex",
    "camel_open",
];

/// Valid meshes that are not disks: `param` cuts them into charts (checked in tests/param/atlas.rs).
const CUT: [&str; 2] = ["bunny_npm", "block"];

/// Invalid meshes and the words their one-line error must contain (besides the file name).
const INVALID: [(&str, &[&str]); 2] = [
    ("nonmanifold_edge_fan", &["non-manifold", "edge"]),
    ("grid_with_zero_area_face", &["degenerate", "face 32"]),
];

/// Meshes with a pinched (non-manifold) vertex: `stats` rejects them (its verdict is about the
/// mesh as it is), `param` splits the vertex into one per fan and maps the result.
const PINCHED: [&str; 1] = ["bowtie_vertex"];

/// Relative tolerance of report vs recomputation (the OBJ holds round-trip f64 text).
const REL_TOL: f64 = 1e-6;

/// What a run of the binary did.
struct Run {
    code: Option<i32>,
    stdout: String,
    stderr: String,
    what: String,
}

impl Run {
    fn assert_code(&self, code: i32) {
        assert_eq!(
            self.code,
            Some(code),
            "{}: expected exit {code}\nstdout:\n{}\nstderr:\n{}",
            self.what,
            self.stdout,
            self.stderr
        );
    }

    /// Asserts stderr is exactly one line `foldfree: error: ...` containing every word of
    /// `needles`; returns that line.
    fn assert_one_error_line(&self, needles: &[&str]) -> &str {
        let lines: Vec<&str> = self.stderr.lines().collect();
        assert_eq!(
            lines.len(),
            1,
            "{}: stderr should be one line:\n{}",
            self.what,
            self.stderr
        );
        let line = lines[0];
        assert!(
            line.starts_with("foldfree: error:"),
            "{}: stderr line does not start with `foldfree: error:`: {line}",
            self.what
        );
        for n in needles {
            assert!(
                line.contains(n),
                "{}: error line does not mention {n:?}: {line}",
                self.what
            );
        }
        line
    }
}

fn run<I, S>(args: I) -> Run
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    let args: Vec<std::ffi::OsString> = args.into_iter().map(|a| a.as_ref().into()).collect();
    let what = format!(
        "foldfree {}",
        args.iter()
            .map(|a| a.to_string_lossy())
            .collect::<Vec<_>>()
            .join(" ")
    );
    let out = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .args(&args)
        .output()
        .expect("spawn the foldfree binary");
    Run {
        code: out.status.code(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        what,
    }
}

/// `foldfree param IN -o OUT --report REPORT` plus `extra`.
fn param(input: &Path, out: &Path, report: &Path, extra: &[&str]) -> Run {
    let mut args: Vec<std::ffi::OsString> = vec![
        "param".into(),
        input.into(),
        "-o".into(),
        out.into(),
        "--report".into(),
        report.into(),
    ];
    args.extend(extra.iter().map(Into::into));
    run(args)
}

const TUTTE_ONLY: &[&str] = &["--init", "tutte", "--solver", "none"];

fn read_report(path: &Path) -> Value {
    let text = fs::read_to_string(path).expect("read the JSON report");
    serde_json::from_str(&text).expect("parse the JSON report")
}

fn field_f64(report: &Value, key: &str) -> f64 {
    report[key]
        .as_f64()
        .unwrap_or_else(|| panic!("report field {key:?} is not a number: {}", report[key]))
}

fn field_usize(report: &Value, key: &str) -> usize {
    report[key]
        .as_u64()
        .unwrap_or_else(|| panic!("report field {key:?} is not an integer: {}", report[key]))
        as usize
}

fn read_obj(path: &Path) -> objcheck::Obj {
    let text = fs::read_to_string(path).expect("read an OBJ file");
    objcheck::parse_obj(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Checks the written OBJ against its input (same v records and f order, one vt per v, vt
/// indices equal to v indices), recomputes the metrics from it, asserts they match the report
/// and returns them with the largest relative deviation seen.
fn check_output(input: &Path, out: &Path, report: &Value) -> (objcheck::Metrics, f64) {
    let ctx = out.display();
    let src = read_obj(input);
    let obj = read_obj(out);
    assert_eq!(obj.v.len(), src.v.len(), "{ctx}: v count");
    for (i, (a, b)) in obj.v.iter().zip(&src.v).enumerate() {
        assert_eq!(a, b, "{ctx}: v record {i} differs from the input");
    }
    assert_eq!(obj.f_v, src.f_v, "{ctx}: faces differ from the input's");
    assert_eq!(obj.vt.len(), obj.v.len(), "{ctx}: one vt per v");
    for (i, (fv, ft)) in obj.f_v.iter().zip(&obj.f_vt).enumerate() {
        assert_eq!(
            ft.as_ref(),
            Some(fv),
            "{ctx}: face {i}: vt indices != v indices"
        );
    }

    let m = objcheck::metrics(&obj).unwrap_or_else(|e| panic!("{ctx}: {e}"));
    assert_eq!(m.flips, 0, "{ctx}: flipped faces in the written map");
    for (key, mine) in [
        ("vertices", m.vertices),
        ("faces", m.faces),
        ("interior_edges", m.interior_edges),
        ("boundary_loops", m.boundary_loops),
        ("flips", m.flips),
    ] {
        assert_eq!(field_usize(report, key), mine, "{ctx}: report {key}");
    }
    let mut worst: f64 = 0.0;
    for (key, mine) in [
        ("delta_con_mean", m.delta_con_mean),
        ("delta_con_area_mean", m.delta_con_area_mean),
        ("delta_con_max", m.delta_con_max),
        ("mips_energy", m.mips_energy),
        ("sd_energy", m.sd_energy),
    ] {
        let theirs = field_f64(report, key);
        assert!(mine.is_finite(), "{ctx}: recomputed {key} = {mine}");
        let rel = (theirs - mine).abs() / mine.abs().max(theirs.abs()).max(f64::MIN_POSITIVE);
        assert!(
            rel <= REL_TOL,
            "{ctx}: report {key} = {theirs}, recomputed {mine} (relative {rel:.3e})"
        );
        worst = worst.max(rel);
    }
    for key in ["seconds", "backend", "device"] {
        assert!(
            report.get(key).is_some(),
            "{ctx}: report lacks the {key:?} key"
        );
    }
    (m, worst)
}

/// Pins the checker itself on known maps: a similarity scores δ = 1, MIPS = 2, SD = 4; a
/// stretch by 2 along x scores δ = 2; a mirror image flips every face.
#[test]
fn objcheck_scores_known_maps() {
    let square = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";
    let faces = "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n";
    let score = |vt: &str| {
        let obj = objcheck::parse_obj(&format!("{square}{vt}{faces}")).expect("parse");
        objcheck::metrics(&obj).expect("metrics")
    };
    // Rotation by 30° and scale 3.
    let (c, s) = (
        3.0 * 30f64.to_radians().cos(),
        3.0 * 30f64.to_radians().sin(),
    );
    let rot: String = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
        .iter()
        .map(|p: &[f64; 2]| format!("vt {} {}\n", c * p[0] - s * p[1], s * p[0] + c * p[1]))
        .collect();
    let m = score(&rot);
    assert_eq!((m.flips, m.interior_edges, m.boundary_loops), (0, 1, 1));
    for (got, want) in [
        (m.delta_con_mean, 1.0),
        (m.delta_con_max, 1.0),
        (m.mips_energy, 2.0),
        (m.sd_energy, 4.0),
    ] {
        assert!((got - want).abs() < 1e-12, "similarity: {m:?}");
    }
    let m = score("vt 0 0\nvt 2 0\nvt 2 1\nvt 0 1\n");
    assert!((m.delta_con_mean - 2.0).abs() < 1e-12, "stretch: {m:?}");
    assert!((m.mips_energy - 2.5).abs() < 1e-12, "stretch: {m:?}");
    // Scaled to unit area: σ = (√2, 1/√2), SD = 2 + 1/2 + 1/2 + 2.
    assert!((m.sd_energy - 5.0).abs() < 1e-12, "stretch: {m:?}");
    let m = score("vt 0 0\nvt -1 0\nvt -1 1\nvt 0 1\n");
    assert_eq!(m.flips, 2, "mirror: {m:?}");
}

// ---------------------------------------------------------------------------------------------
// 1. Every data file through the Tutte-only path and `stats`.

/// Pins that every tests/data/*.obj has an expectation here, so a new file cannot be skipped.
#[test]
fn every_data_file_has_an_expected_verdict() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let on_disk: BTreeSet<String> = fs::read_dir(&dir)
        .expect("list tests/data")
        .map(|e| e.expect("read a tests/data entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "obj"))
        .map(|p| {
            p.file_stem()
                .expect("a file stem")
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    let known: BTreeSet<String> = VALID
        .iter()
        .copied()
        .chain(INVALID.iter().map(|(n, _)| *n))
        .chain(CUT.iter().copied())
        .chain(PINCHED.iter().copied())
        .map(String::from)
        .collect();
    assert_eq!(
        on_disk, known,
        "tests/data/*.obj vs the lists in tests/cli.rs"
    );
}

/// Pins: the Tutte-only path succeeds (exit 0) on each valid disk and writes OUT and the report.
#[test]
fn param_tutte_succeeds_on_valid_disks() {
    let tmp = TempDir::new("param_tutte_succeeds_on_valid_disks");
    for name in VALID {
        let out = tmp.join(&format!("{name}.out.obj"));
        let rep = tmp.join(&format!("{name}.json"));
        let r = param(&data(name), &out, &rep, TUTTE_ONLY);
        r.assert_code(0);
        assert!(
            out.is_file(),
            "{}: {} was not written",
            r.what,
            out.display()
        );
        assert!(
            rep.is_file(),
            "{}: {} was not written",
            r.what,
            rep.display()
        );
        assert!(
            !r.stderr.contains("error"),
            "{}: success printed an error:\n{}",
            r.what,
            r.stderr
        );
    }
}

/// Pins: invalid meshes exit 2 with one `foldfree: error:` line naming the file and the
/// problem, and nothing (output, report, temporary) is written.
#[test]
fn param_rejects_invalid_meshes_with_one_error_line_and_no_output() {
    let tmp = TempDir::new("param_rejects_invalid_meshes");
    for (name, words) in INVALID {
        let out = tmp.join(&format!("{name}.out.obj"));
        let rep = tmp.join(&format!("{name}.json"));
        let r = param(&data(name), &out, &rep, TUTTE_ONLY);
        r.assert_code(2);
        let file = data(name).display().to_string();
        let mut needles = vec![file.as_str()];
        needles.extend_from_slice(words);
        r.assert_one_error_line(&needles);
        assert!(
            tmp.entries().is_empty(),
            "{}: files were written: {:?}",
            r.what,
            tmp.entries()
        );
    }
}

/// Pins: `stats` exits 0 and says "disk: yes" for valid disks, exits 2 for invalid meshes.
#[test]
fn stats_accepts_valid_disks_and_rejects_invalid_meshes() {
    for name in VALID {
        let r = run([Path::new("stats"), &data(name)]);
        r.assert_code(0);
        assert!(
            r.stdout.contains("disk: yes"),
            "{}: stdout lacks \"disk: yes\":\n{}",
            r.what,
            r.stdout
        );
    }
    for (name, words) in INVALID {
        let r = run([Path::new("stats"), &data(name)]);
        r.assert_code(2);
        let file = data(name).display().to_string();
        let mut needles = vec![file.as_str()];
        needles.extend_from_slice(words);
        r.assert_one_error_line(&needles);
    }
}

// ---------------------------------------------------------------------------------------------
// 2. Report vs independent recomputation (Tutte start maps).

/// Pins: OUT keeps the input's v and f records, adds one vt per v, and the report's counts and
/// distortion numbers equal an independent f64 recomputation from OUT.
#[test]
fn tutte_report_matches_independent_recomputation() {
    let tmp = TempDir::new("tutte_report_matches_recomputation");
    let mut worst: f64 = 0.0;
    for name in VALID {
        let out = tmp.join(&format!("{name}.out.obj"));
        let rep = tmp.join(&format!("{name}.json"));
        let r = param(&data(name), &out, &rep, TUTTE_ONLY);
        r.assert_code(0);
        let report = read_report(&rep);
        let (_, rel) = check_output(&data(name), &out, &report);
        worst = worst.max(rel);
    }
    eprintln!("largest relative deviation report vs recomputation: {worst:.3e}");
}

// ---------------------------------------------------------------------------------------------
// 3. ADMM on the CPU backend.

/// Runs ADMM (CPU backend, default options) and checks output and report; returns the
/// recomputed metrics and the report.
fn admm(tmp: &TempDir, name: &str, energy: &str) -> (objcheck::Metrics, Value) {
    let out = tmp.join(&format!("{name}.{energy}.obj"));
    let rep = tmp.join(&format!("{name}.{energy}.json"));
    let r = param(
        &data(name),
        &out,
        &rep,
        &["--backend", "cpu", "--energy", energy, "-q"],
    );
    r.assert_code(0);
    let report = read_report(&rep);
    let (m, _) = check_output(&data(name), &out, &report);
    assert_eq!(report["backend"], "cpu", "{}: report backend", r.what);
    assert_eq!(report["solver"], "admm", "{}: report solver", r.what);
    assert_eq!(report["energy"], energy, "{}: report energy", r.what);
    tmp.assert_no_temp_files(&r.what);
    eprintln!(
        "{name} {energy}: δcon mean {:.5} (area {:.5}, max {:.4})  MIPS {:.6}  SD {:.6}  \
         iterations {}  converged {}  {:.2} s",
        m.delta_con_mean,
        m.delta_con_area_mean,
        m.delta_con_max,
        m.mips_energy,
        m.sd_energy,
        report["iterations"],
        report["converged"],
        field_f64(&report, "seconds")
    );
    (m, report)
}

/// Pins: on a flat square both energies recover the identity up to similarity.
#[test]
fn admm_cpu_flat_square_grid_is_a_similarity() {
    let tmp = TempDir::new("admm_cpu_flat_square_grid");
    for energy in ["mips", "sd"] {
        let (m, _) = admm(&tmp, "square_grid_10x10", energy);
        assert!(
            m.delta_con_mean < 1.0001,
            "{energy}: δcon mean {} on a flat square",
            m.delta_con_mean
        );
        assert!(
            m.sd_energy < 4.0001,
            "{energy}: SD {} on a flat square",
            m.sd_energy
        );
    }
}

/// Pins a regression bound for MIPS on the camel (best tools: δcon mean 1.136).
#[test]
fn admm_cpu_camel_mips_is_flip_free_and_conformal_enough() {
    let tmp = TempDir::new("admm_cpu_camel_mips");
    let (m, _) = admm(&tmp, "camel_open", "mips");
    assert!(
        m.delta_con_mean < 1.25,
        "camel MIPS: δcon mean {}",
        m.delta_con_mean
    );
}

/// Pins a regression bound for symmetric Dirichlet on the camel (best tools: SD 4.0915).
#[test]
fn admm_cpu_camel_sd_is_flip_free_and_isometric_enough() {
    let tmp = TempDir::new("admm_cpu_camel_sd");
    let (m, _) = admm(&tmp, "camel_open", "sd");
    assert!(m.sd_energy < 4.3, "camel SD: SD {}", m.sd_energy);
}

// ---------------------------------------------------------------------------------------------
// 4. Usage and I/O errors.

/// Pins: an unknown flag is a usage error (exit 2).
#[test]
fn unknown_flag_exits_2() {
    let tmp = TempDir::new("unknown_flag_exits_2");
    let r = run([
        Path::new("param"),
        &data("two_triangles"),
        Path::new("-o"),
        &tmp.join("out.obj"),
        Path::new("--no-such-flag"),
    ]);
    r.assert_code(2);
    assert!(
        r.stderr.contains("--no-such-flag"),
        "{}: {}",
        r.what,
        r.stderr
    );
    assert!(
        tmp.entries().is_empty(),
        "{}: wrote {:?}",
        r.what,
        tmp.entries()
    );
}

/// Pins: a missing input file is bad input (exit 2) and the message names the path.
#[test]
fn missing_input_exits_2_naming_the_path() {
    let tmp = TempDir::new("missing_input_exits_2");
    let input = tmp.join("does_not_exist.obj");
    let r = param(&input, &tmp.join("out.obj"), &tmp.join("r.json"), &[]);
    r.assert_code(2);
    r.assert_one_error_line(&[&input.display().to_string()]);
    assert!(
        tmp.entries().is_empty(),
        "{}: wrote {:?}",
        r.what,
        tmp.entries()
    );
}

/// Pins: `-o` naming the input (same or other spelling) is refused (exit 2) and the input
/// stays byte-identical.
#[test]
fn output_equal_to_input_is_refused_and_input_unchanged() {
    let tmp = TempDir::new("output_equal_to_input");
    let input = tmp.join("in.obj");
    fs::copy(data("square_grid_10x10"), &input).expect("copy the input into the temp dir");
    let before = fs::read(&input).expect("read the input");
    let dir_name = tmp.0.file_name().expect("temp dir name").to_owned();
    let other_spelling = tmp.0.join("..").join(dir_name).join("in.obj");
    for out in [input.clone(), other_spelling] {
        let r = param(&input, &out, &tmp.join("r.json"), TUTTE_ONLY);
        r.assert_code(2);
        r.assert_one_error_line(&["refusing to overwrite"]);
        assert_eq!(
            fs::read(&input).expect("read the input"),
            before,
            "{}: the input changed",
            r.what
        );
        assert_eq!(
            tmp.entries(),
            BTreeSet::from(["in.obj".to_string()]),
            "{}: unexpected files",
            r.what
        );
    }
}

/// Pins: an output in a directory that does not exist is found before any work (exit 2, bad
/// request) with a one-line message naming the output path and the folder.
#[test]
fn output_in_missing_directory_exits_2_before_any_work() {
    let tmp = TempDir::new("output_in_missing_directory");
    let out = tmp.join("no_such_dir").join("out.obj");
    let r = param(
        &data("two_triangles"),
        &out,
        &tmp.join("r.json"),
        TUTTE_ONLY,
    );
    r.assert_code(2);
    r.assert_one_error_line(&[&out.display().to_string(), "does not exist"]);
    assert!(
        tmp.entries().is_empty(),
        "{}: wrote {:?}",
        r.what,
        tmp.entries()
    );
}

/// Pins: a 0-byte OBJ is bad input (exit 2), with a message naming it.
#[test]
fn empty_obj_exits_2() {
    let tmp = TempDir::new("empty_obj_exits_2");
    let input = tmp.join("empty.obj");
    fs::write(&input, b"").expect("write the empty OBJ");
    let r = param(
        &input,
        &tmp.join("out.obj"),
        &tmp.join("r.json"),
        TUTTE_ONLY,
    );
    r.assert_code(2);
    r.assert_one_error_line(&["empty.obj"]);
    assert_eq!(tmp.entries(), BTreeSet::from(["empty.obj".to_string()]));
}

/// Pins: binary garbage named .obj is bad input (exit 2), with a message naming it.
#[test]
fn binary_garbage_obj_exits_2() {
    let tmp = TempDir::new("binary_garbage_obj_exits_2");
    let input = tmp.join("garbage.obj");
    // Deterministic pseudo-random bytes, including NULs and invalid UTF-8.
    let mut x: u32 = 0x1234_5678;
    let bytes: Vec<u8> = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x >> 24) as u8
        })
        .collect();
    fs::write(&input, &bytes).expect("write the garbage OBJ");
    let r = param(
        &input,
        &tmp.join("out.obj"),
        &tmp.join("r.json"),
        TUTTE_ONLY,
    );
    r.assert_code(2);
    r.assert_one_error_line(&["garbage.obj"]);
    assert_eq!(tmp.entries(), BTreeSet::from(["garbage.obj".to_string()]));
}

// ---------------------------------------------------------------------------------------------
// 5. Atomic writes.

/// Pins: a successful run leaves exactly OUT and the report in the output directory, no
/// temporary (dot) files.
#[test]
fn successful_run_leaves_no_temp_files() {
    let tmp = TempDir::new("successful_run_leaves_no_temp_files");
    let r = param(
        &data("camel_open"),
        &tmp.join("out.obj"),
        &tmp.join("r.json"),
        TUTTE_ONLY,
    );
    r.assert_code(0);
    tmp.assert_no_temp_files(&r.what);
    assert_eq!(
        tmp.entries(),
        BTreeSet::from(["out.obj".to_string(), "r.json".to_string()]),
        "{}",
        r.what
    );
}

/// The synthetic tetrahedral meshes (shipped beside the OBJ ones in ../shared) are refused with
/// exit 2 and a message that says why, instead of "no faces".
#[test]
fn tet_mesh_input_is_refused_with_a_reason() {
    let dir = std::env::temp_dir().join(format!("foldfree-cli-tet-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let input = dir.join("single_tet.mesh");
    std::fs::write(
        &input,
        "MeshVersionFormatted 1\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\nTetrahedra\n1\n1 2 3 4 0\nEnd\n",
    )
    .expect("write input");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .args(["param", input.to_str().expect("utf8 path"), "-o"])
        .arg(dir.join("out.obj"))
        .output()
        .expect("run foldfree");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("tetrahedral") && stderr.contains("single_tet.mesh"),
        "{stderr}"
    );
    assert!(!dir.join("out.obj").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--max-faces` refuses a mesh over the limit with exit 2 and a one-line error, writing
/// nothing; 0 lifts the limit.
#[test]
fn face_limit_is_enforced() {
    let dir = TempDir::new("max_faces");
    let out = dir.join("out.obj");
    let run = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .arg("param")
        .arg(data("camel_open"))
        .arg("-o")
        .arg(&out)
        .args(["--max-faces", "1000"])
        .output()
        .expect("run foldfree");
    assert_eq!(run.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("3576 faces, more than the limit of 1000"),
        "{stderr}"
    );
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(!out.exists());
    let run = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .arg("param")
        .arg(data("two_triangles"))
        .arg("-o")
        .arg(&out)
        .args(["--max-faces", "0", "-q"])
        .output()
        .expect("run foldfree");
    assert_eq!(
        run.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

/// `[admm] recovery = "bfs"` in a tuning file (the seed's breadth-first recovery) runs ADMM to
/// convergence on the flat grid and writes a flip-free map that the independent checker scores.
/// (The global solver has no per-face maps to recover from; `--solver global` does not read the
/// `[admm]` table.)
#[test]
fn param_with_breadth_first_recovery() {
    let tmp = TempDir::new("param_with_breadth_first_recovery");
    let input = data("square_grid_10x10");
    let out = tmp.join("grid_bfs.obj");
    let rep = tmp.join("grid_bfs.json");
    let tuning = tmp.join("bfs.toml");
    fs::write(&tuning, "[admm]\nrecovery = \"bfs\"\n").expect("write tuning");
    let r = param(
        &input,
        &out,
        &rep,
        &[
            "--backend",
            "cpu",
            "--tuning",
            tuning.to_str().expect("utf-8"),
        ],
    );
    r.assert_code(0);
    let report = read_report(&rep);
    let (metrics, _) = check_output(&input, &out, &report);
    assert_eq!(metrics.flips, 0, "{}", r.what);
}

/// Pins: a pinched vertex is bad input for `stats` (exit 2, named) and split by `param`: exit 0,
/// the input's `v` kept, one more `vt` per extra fan, no flipped face, the report counts it.
#[test]
fn param_splits_pinched_vertices_and_stats_names_them() {
    let tmp = TempDir::new("pinched");
    for name in PINCHED {
        let r = run([Path::new("stats"), &data(name)]);
        r.assert_code(2);
        r.assert_one_error_line(&["non-manifold", "vertex"]);
        let out = tmp.join(&format!("{name}.out.obj"));
        let report = tmp.join(&format!("{name}.json"));
        let r = param(&data(name), &out, &report, &[]);
        r.assert_code(0);
        let rep = read_report(&report);
        assert!(field_usize(&rep, "pinched_vertices_split") >= 1);
        assert_eq!(field_usize(&rep, "flips"), 0);
        let text = fs::read_to_string(&out).expect("read the output");
        let v = text.lines().filter(|l| l.starts_with("v ")).count();
        let vt = text.lines().filter(|l| l.starts_with("vt ")).count();
        let input_v = fs::read_to_string(data(name))
            .expect("read the input")
            .lines()
            .filter(|l| l.starts_with("v "))
            .count();
        assert_eq!(v, input_v, "the input's v are kept");
        assert!(vt > v, "the pinched vertex has one vt per fan");
    }
}
