//! Nothing lost, nothing silent: one test per finding of the input/output audit, named for it,
//! through the release binary as a user runs it. Each pins the exit code (the README's table),
//! that inputs are never changed, and that a failed run leaves no file behind.

use std::fs;
use std::process::Command;

use crate::common::{data, TempDir};

struct Run {
    code: Option<i32>,
    stderr: String,
    what: String,
}

fn run(dir: &TempDir, args: &[&str]) -> Run {
    let out = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .current_dir(&dir.0)
        .args(args)
        .output()
        .expect("run foldfree");
    Run {
        code: out.status.code(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        what: format!("foldfree {}", args.join(" ")),
    }
}

impl Run {
    fn expect(&self, code: i32, needle: &str) -> &Run {
        assert_eq!(
            self.code,
            Some(code),
            "{}: expected exit {code}\n{}",
            self.what,
            self.stderr
        );
        assert!(
            self.stderr.contains(needle),
            "{}: stderr does not mention {needle:?}:\n{}",
            self.what,
            self.stderr
        );
        self
    }
}

/// A scratch folder holding copies of the named test files.
fn scratch(test: &str, files: &[&str]) -> TempDir {
    let dir = TempDir::new(test);
    for f in files {
        fs::copy(data(f), dir.join(f)).expect("copy test data");
    }
    dir
}

/// Runs `args` in a scratch folder with `files`, expects `code` and `needle`, and checks that
/// every input is unchanged and no other file appeared.
fn refused(test: &str, files: &[&str], args: &[&str], code: i32, needle: &str) {
    let dir = scratch(test, files);
    let before: Vec<Vec<u8>> = files
        .iter()
        .map(|f| fs::read(dir.join(f)).unwrap())
        .collect();
    run(&dir, args).expect(code, needle);
    for (f, b) in files.iter().zip(&before) {
        assert_eq!(&fs::read(dir.join(f)).unwrap(), b, "{f} changed");
    }
    let expected: std::collections::BTreeSet<String> =
        files.iter().map(|s| s.to_string()).collect();
    assert_eq!(dir.entries(), expected, "files appeared or vanished");
}

/// A tuning file holding `text`, in a folder of its own (the run's folder then holds only the
/// run's files); its path for `--tuning`. Keep the folder alive while the file is used.
fn tuning_file(test: &str, text: &str) -> (TempDir, String) {
    let dir = TempDir::new(&format!("{test}-tuning"));
    let path = dir.join("t.toml");
    fs::write(&path, text).expect("write the tuning file");
    let path = path.to_str().expect("utf-8 path").to_string();
    (dir, path)
}

/// `foldfree volmap REST --target ball` plus `extra`.
fn ball<'a>(rest: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec!["volmap", rest, "--target", "ball"];
    a.extend(extra);
    a
}

const TUTTE: [&str; 4] = ["--init", "tutte", "--solver", "none"];

fn param_args<'a>(extra: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec!["param", "camel_open.obj", "-o", "out.obj", "-q"];
    a.extend(TUTTE);
    a.extend(extra);
    a
}

// ------------------------------------------------------------------ inputs overwritten

#[test]
fn param_report_naming_the_input_is_refused() {
    let args = param_args(&["--report", "./camel_open.obj"]);
    refused("rep_in", &["camel_open.obj"], &args, 2, "report");
}

#[test]
fn param_picture_naming_the_input_is_refused() {
    for flag in ["--svg", "--png", "--plot"] {
        // Same file by identity, whatever the extension check says first.
        let args = param_args(&[flag, "camel_open.obj"]);
        refused("pic_in", &["camel_open.obj"], &args, 2, "camel_open.obj");
    }
    let dir = scratch("pic_link", &["camel_open.obj"]);
    fs::hard_link(dir.join("camel_open.obj"), dir.join("link.svg")).unwrap();
    run(&dir, &param_args(&["--svg", "link.svg"])).expect(2, "refusing to overwrite the input");
    assert_eq!(
        fs::read(dir.join("camel_open.obj")).unwrap(),
        fs::read(data("camel_open.obj")).unwrap()
    );
}

#[test]
fn param_report_naming_the_output_is_refused() {
    let dir = scratch("rep_out", &["camel_open.obj"]);
    let mut args = param_args(&[]);
    args[3] = "out.json";
    args.extend(["--report", "./out.json"]);
    run(&dir, &args).expect(2, "out.json");
    assert!(!dir.join("out.json").exists());
}

#[test]
fn approx_output_naming_the_input_by_another_spelling_is_refused() {
    refused(
        "approx_in",
        &["block.obj"],
        &["approx", "block.obj", "-k", "24", "-q", "-o", "./block.obj"],
        2,
        "refusing to overwrite the input",
    );
    refused(
        "approx_rep",
        &["block.obj"],
        &[
            "approx",
            "block.obj",
            "-k",
            "24",
            "-q",
            "-o",
            "o.obj",
            "--report",
            "block.obj",
        ],
        2,
        "report",
    );
}

#[test]
fn volmap_output_naming_the_rest_is_refused() {
    let v = [
        "volmap",
        "cube_5tets.mesh",
        "--target",
        "ball",
        "-q",
        "-o",
        "./cube_5tets.mesh",
    ];
    refused(
        "vol_in",
        &["cube_5tets.mesh"],
        &v,
        2,
        "refusing to overwrite the input",
    );
    let v = [
        "volmap",
        "cube_5tets.mesh",
        "--target",
        "ball",
        "-q",
        "-o",
        "o.mesh",
        "--report",
        "cube_5tets.mesh",
    ];
    refused("vol_rep", &["cube_5tets.mesh"], &v, 2, "report");
}

#[test]
fn volmap_tetgen_output_naming_one_file_of_the_input_pair_is_refused() {
    let dir = TempDir::new("vol_pair");
    // A TetGen pair written by foldfree itself from the cube.
    let m = foldfree::vol::read_any(&data("cube_5tets.mesh")).unwrap();
    foldfree::vol::write_any(&dir.join("a.node"), &m, &m.positions).unwrap();
    let before = (
        fs::read(dir.join("a.node")).unwrap(),
        fs::read(dir.join("a.ele")).unwrap(),
    );
    run(&dir, &ball("a.node", &["-q", "-o", "a.ele"])).expect(2, "refusing to overwrite the input");
    assert_eq!(fs::read(dir.join("a.node")).unwrap(), before.0);
    assert_eq!(fs::read(dir.join("a.ele")).unwrap(), before.1);
}

#[test]
fn volmap_constraints_output_naming_the_rest_is_refused() {
    refused(
        "volc_in",
        &["cube_5tets.mesh"],
        &[
            "dev",
            "volmap-constraints",
            "cube_5tets.mesh",
            "-o",
            "cube_5tets.mesh",
        ],
        2,
        "refusing to overwrite the input",
    );
}

#[test]
fn write_constraints_naming_the_constraints_input_is_refused() {
    let dir = scratch("wc_in", &["cube_5tets.mesh"]);
    run(
        &dir,
        &[
            "dev",
            "volmap-constraints",
            "cube_5tets.mesh",
            "-o",
            "c.txt",
        ],
    )
    .expect(0, "wrote");
    let before = fs::read(dir.join("c.txt")).unwrap();
    run(
        &dir,
        &[
            "volmap",
            "cube_5tets.mesh",
            "--constraints",
            "c.txt",
            "-q",
            "-o",
            "o.mesh",
            "--write-constraints",
            "./c.txt",
        ],
    )
    .expect(2, "refusing to overwrite the input");
    assert_eq!(fs::read(dir.join("c.txt")).unwrap(), before);
    assert!(!dir.join("o.mesh").exists());
}

// ------------------------------------------------------------------ the TetGen reader

fn tetgen_pair(dir: &TempDir, node: &str, ele: &str) {
    fs::write(dir.join("t.node"), node).unwrap();
    fs::write(dir.join("t.ele"), ele).unwrap();
}

const NODE: &str = "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n";

#[test]
fn tetgen_header_count_of_u64_max_is_a_located_error_not_a_panic() {
    for (node, ele, needle) in [
        (
            "18446744073709551615 3 0 0\n1 0 0 0\n",
            "1 4 0\n1 1 2 3 4\n",
            "t.node:",
        ),
        (NODE, "18446744073709551615 4 0\n1 1 2 3 4\n", "t.ele:"),
        (
            "4 3 18446744073709551615 1\n1 0 0 0\n",
            "1 4 0\n1 1 2 3 4\n",
            "t.node:1",
        ),
        (NODE, "1 4 18446744073709551615\n1 1 2 3 4\n", "t.ele:1"),
    ] {
        let dir = TempDir::new("tg_max");
        tetgen_pair(&dir, node, ele);
        run(&dir, &["volcheck", "t.node", "--rest", "t.node"]).expect(2, needle);
    }
}

#[test]
fn tetgen_records_must_have_the_fields_their_header_announces() {
    for (node, ele, needle) in [
        // 10 nodes per tet announced, 4 given.
        (
            NODE,
            "1 10 0\n1 1 2 3 4\n",
            "has 5 fields, the header announces 11",
        ),
        // A point with a missing coordinate, and one with an extra field.
        (
            "2 3 0 0\n1 0 0\n2 1 0 0\n",
            "1 4 0\n1 1 2 3 4\n",
            "has 3 fields",
        ),
        (NODE, "1 4 0\n1 1 2 3 4 7\n", "has 6 fields"),
        // Records past the announced count.
        (
            NODE,
            "1 4 0\n1 1 2 3 4\n2 1 2 4 3\n",
            "a record after the 1 tets",
        ),
    ] {
        let dir = TempDir::new("tg_fields");
        tetgen_pair(&dir, node, ele);
        run(&dir, &["volcheck", "t.node", "--rest", "t.node"]).expect(2, needle);
    }
}

// ------------------------------------------------------------------ partial outputs

#[test]
fn a_bad_side_output_is_found_before_the_work_and_nothing_is_written() {
    for extra in [
        ["--report", "no/such/dir/r.json"],
        ["--report", "r.txt"],
        ["--svg", "no/such/dir/l.svg"],
    ] {
        let args = param_args(&extra);
        refused("side_out", &["camel_open.obj"], &args, 2, extra[1]);
    }
    refused(
        "side_out_vol",
        &["cube_5tets.mesh"],
        &ball("cube_5tets.mesh", &["-q", "-o", "o.obj"]),
        2,
        "o.obj",
    );
}

#[test]
fn a_tetgen_output_pair_is_written_together() {
    let dir = scratch("pair_out", &["cube_5tets.mesh"]);
    run(
        &dir,
        &ball(
            "cube_5tets.mesh",
            &["-q", "-o", "m.node", "--report", "r.json"],
        ),
    )
    .expect(0, "");
    let e = dir.entries();
    for f in ["m.node", "m.ele", "r.json"] {
        assert!(e.contains(f), "{f} missing: {e:?}");
    }
    dir.assert_no_temp_files("volmap m.node");
}

// ------------------------------------------------------------------ resource limits

#[test]
fn special_files_are_refused_not_read_for_ever() {
    let dir = TempDir::new("special");
    for args in [
        vec!["stats", "/dev/zero"],
        vec!["param", "/dev/zero", "-o", "o.obj"],
        vec!["approx", "/dev/zero", "-k", "4", "-o", "o.obj"],
        vec!["volcheck", "/dev/zero.mesh", "--rest", "/dev/zero.mesh"],
    ] {
        let r = run(&dir, &args);
        assert_eq!(r.code, Some(2), "{}: {}", r.what, r.stderr);
    }
    #[cfg(unix)]
    {
        // A FIFO with no writer: opening it would block; it is refused at once.
        let fifo = dir.join("pipe.obj");
        let ok = Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .is_ok_and(|s| s.success());
        if ok {
            run(&dir, &["stats", "pipe.obj"]).expect(2, "not a regular file");
        }
    }
}

#[test]
fn every_command_has_a_size_limit() {
    let dir = scratch(
        "limits",
        &["camel_open.obj", "cube_5tets.mesh", "block.obj"],
    );
    run(&dir, &["stats", "camel_open.obj", "--max-faces", "10"]).expect(2, "limit");
    run(
        &dir,
        &[
            "param",
            "camel_open.obj",
            "-o",
            "o.obj",
            "--max-faces",
            "10",
        ],
    )
    .expect(2, "limit");
    run(
        &dir,
        &[
            "approx",
            "block.obj",
            "-k",
            "8",
            "-o",
            "o.obj",
            "--max-faces",
            "10",
        ],
    )
    .expect(2, "limit");
    run(
        &dir,
        &ball("cube_5tets.mesh", &["-o", "o.mesh", "--max-tets", "2"]),
    )
    .expect(2, "--max-tets");
    run(
        &dir,
        &[
            "volcheck",
            "cube_5tets.mesh",
            "--rest",
            "cube_5tets.mesh",
            "--max-tets",
            "2",
        ],
    )
    .expect(2, "--max-tets");
    run(
        &dir,
        &[
            "render",
            "block.obj",
            "-o",
            "o.png",
            "--shade",
            "normals",
            "--max-elements",
            "3",
        ],
    )
    .expect(2, "--max-elements");
    assert!(!dir.join("o.obj").exists() && !dir.join("o.mesh").exists());
}

// ------------------------------------------------------------------ option ranges

#[test]
fn numeric_options_outside_their_range_are_usage_errors() {
    let dir = scratch(
        "ranges",
        &["camel_open.obj", "block.obj", "cube_5tets.mesh"],
    );
    run(
        &dir,
        &[
            "param",
            "camel_open.obj",
            "-o",
            "o.obj",
            "-q",
            "--max-iters",
            "0",
        ],
    )
    .expect(2, "outside its range");
    // The solver knobs are the tuning file's; a value outside its range names file:line, key.
    for (i, (text, key)) in [
        ("[admm]\nnewton_iters = 4294967295\n", "newton_iters"),
        ("[admm]\nmu = 0.0\n", "mu = 0 is outside its range"),
        ("[admm]\nmu = nan\n", "mu = NaN is outside its range"),
        ("[admm]\nmu = inf\n", "mu = inf is outside its range"),
        (
            "[admm]\ntol_primal = nan\n",
            "tol_primal = NaN is outside its range",
        ),
        (
            "[admm]\ntol_dual = 2.0\n",
            "tol_dual = 2 is outside its range",
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let (_t, tuning) = tuning_file(&format!("ranges{i}"), text);
        let r = run(
            &dir,
            &[
                "param",
                "camel_open.obj",
                "-o",
                "o.obj",
                "-q",
                "--tuning",
                &tuning,
            ],
        );
        r.expect(2, key).expect(2, &format!("{tuning}:2:"));
    }
    run(
        &dir,
        &[
            "approx",
            "block.obj",
            "-k",
            "8",
            "-o",
            "o.obj",
            "--restarts",
            "1000000",
        ],
    )
    .expect(2, "[0, 100]");
    let (_t, tuning) = tuning_file("ranges-growth", "[volmap]\nlambda_growth = 1.0\n");
    run(
        &dir,
        &ball("cube_5tets.mesh", &["-o", "o.mesh", "--tuning", &tuning]),
    )
    .expect(2, "lambda_growth");
    let (_t, tuning) = tuning_file("ranges-cg", "[volmap.newton.cg]\ntolerance = nan\n");
    run(
        &dir,
        &ball("cube_5tets.mesh", &["-o", "o.mesh", "--tuning", &tuning]),
    )
    .expect(2, "newton.cg.tolerance");
    assert!(!dir.join("o.obj").exists() && !dir.join("o.mesh").exists());
}

#[test]
fn library_option_types_check_their_own_ranges() {
    let mut a = foldfree::param::admm::AdmmOptions::default();
    assert!(a.validate().is_ok());
    a.newton_iters = u32::MAX;
    assert!(a.validate().is_err());
    let mut v = foldfree::vol::VolmapOptions::default();
    assert!(v.validate().is_ok());
    v.theta = f64::NAN;
    assert!(v.validate().is_err());
    let mut o = foldfree::approx::ApproxOptions::new(8);
    assert!(o.validate().is_ok());
    o.restarts = 1_000_000;
    assert!(o.validate().is_err());
}

// ------------------------------------------------------------------ wrong results, exit 0

#[test]
fn volmap_on_a_mesh_without_tets_is_bad_input() {
    let dir = TempDir::new("no_tets");
    fs::write(
        dir.join("e.mesh"),
        "MeshVersionFormatted 1\nDimension 3\nVertices\n1\n0 0 0 0\nTetrahedra\n0\nEnd\n",
    )
    .unwrap();
    run(&dir, &ball("e.mesh", &["-o", "o.mesh"])).expect(2, "no tetrahedra");
    assert!(!dir.join("o.mesh").exists());
}

#[test]
fn duplicate_tets_and_repeated_sections_are_bad_input() {
    let head =
        "MeshVersionFormatted 1\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n";
    for (text, needle) in [
        (
            format!("{head}Tetrahedra\n2\n1 2 3 4 0\n2 1 4 3 0\nEnd\n"),
            "duplicate of tet 0",
        ),
        (
            format!("{head}Vertices\n1\n5 5 5 0\nTetrahedra\n1\n1 2 3 4 0\nEnd\n"),
            "a second Vertices section",
        ),
        (
            format!("{head}Tetrahedra\n1\n1 2 3 3 0\nEnd\n"),
            "uses vertex 2 twice",
        ),
    ] {
        let dir = TempDir::new("dup_tets");
        fs::write(dir.join("d.mesh"), text).unwrap();
        run(&dir, &["volcheck", "d.mesh", "--rest", "d.mesh"]).expect(2, needle);
    }
}

#[test]
fn constraints_the_map_cannot_meet_exit_3() {
    let dir = scratch("unmet", &["cube_5tets.mesh"]);
    run(
        &dir,
        &[
            "dev",
            "volmap-constraints",
            "cube_5tets.mesh",
            "-o",
            "c.txt",
            "--twist",
            "170",
        ],
    )
    .expect(0, "wrote");
    run(
        &dir,
        &[
            "volmap",
            "cube_5tets.mesh",
            "--constraints",
            "c.txt",
            "-q",
            "-o",
            "o.mesh",
        ],
    )
    .expect(3, "position constraints NOT met");
    // Written (fold-free) and the report says so: exit 3 is "written, not the requested map".
    assert!(dir.join("o.mesh").exists());
}

#[test]
fn approx_refuses_fewer_planes_than_the_mesh_needs() {
    // One plane cannot bound a closed surface (a closed component needs four): refused up
    // front, nothing written. (A partition no seed realises exits 1, nothing written:
    // tests/approx.rs, `cli_writes_nothing_when_no_partition_is_realised`.)
    refused(
        "approx_k1",
        &["bunny_npm.obj"],
        &[
            "approx",
            "bunny_npm.obj",
            "-k",
            "1",
            "-q",
            "-o",
            "o.obj",
            "--report",
            "r.json",
        ],
        2,
        "needs at least",
    );
}

#[test]
fn a_named_device_or_validation_never_falls_back_to_the_cpu() {
    let dir = scratch("device", &["camel_open.obj"]);
    run(
        &dir,
        &[
            "param",
            "camel_open.obj",
            "-o",
            "o.obj",
            "-q",
            "--device",
            "no-such-gpu-xyz",
        ],
    )
    .expect(2, "no-such-gpu-xyz");
    let out = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .current_dir(&dir.0)
        .env("FOLDFREE_DEVICE", "no-such-gpu-xyz")
        .args(["param", "camel_open.obj", "-o", "o.obj", "-q"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "FOLDFREE_DEVICE was ignored");
    // The loader finds no validation layer in an empty layer path.
    let empty = dir.join("no-layers");
    fs::create_dir(&empty).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .current_dir(&dir.0)
        .env("VK_LAYER_PATH", &empty)
        .args([
            "param",
            "camel_open.obj",
            "-o",
            "o.obj",
            "-q",
            "--validation",
        ])
        .output()
        .unwrap();
    assert_ne!(
        out.status.code(),
        Some(0),
        "--validation without the layer ran anyway"
    );
    assert!(!dir.join("o.obj").exists());
}

// ------------------------------------------------------------------ scale

/// UVs of `param` on the camel scaled by `s` (its `vt` lines).
fn camel_uv_at_scale(dir: &TempDir, s: f64, tag: &str) -> Vec<[f64; 2]> {
    let text = fs::read_to_string(data("camel_open.obj")).unwrap();
    let mut out = String::new();
    for l in text.lines() {
        if let Some(rest) = l.strip_prefix("v ") {
            let c: Vec<f64> = rest
                .split_whitespace()
                .map(|x| x.parse().unwrap())
                .collect();
            out.push_str(&format!("v {:e} {:e} {:e}\n", c[0] * s, c[1] * s, c[2] * s));
        } else {
            out.push_str(l);
            out.push('\n');
        }
    }
    let input = format!("{tag}.obj");
    let output = format!("{tag}.out.obj");
    fs::write(dir.join(&input), out).unwrap();
    run(
        dir,
        &[
            "param",
            &input,
            "-o",
            &output,
            "-q",
            "--backend",
            "cpu",
            "--max-iters",
            "200",
        ],
    )
    .expect(0, "converged");
    fs::read_to_string(dir.join(&output))
        .unwrap()
        .lines()
        .filter_map(|l| l.strip_prefix("vt "))
        .map(|r| {
            let c: Vec<f64> = r.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [c[0], c[1]]
        })
        .collect()
}

/// The tolerance is relative to the map's size: a scale of 1e±100 is not a power of two, so the
/// positions the solver sees at unit scale differ from the unit mesh's in their last bits, and
/// ~70 iterations of two solvers (ADMM, then the bijective global solver's Newton steps with
/// a scaffold whose weight goes down to 1e-8 of the energy) amplify that to ~5e-9 of the size
/// (measured; the same iterations and stop on both). A scale that leaked into the solver would
/// move the map by orders of magnitude more.
#[test]
fn meshes_at_any_scale_give_the_unit_scale_map_scaled() {
    let dir = TempDir::new("scale");
    let unit = camel_uv_at_scale(&dir, 1.0, "unit");
    let size = unit.iter().flatten().fold(0.0f64, |m, c| m.max(c.abs()));
    for s in [1e-100, 1e100] {
        let uv = camel_uv_at_scale(&dir, s, &format!("s{s:e}"));
        assert_eq!(uv.len(), unit.len());
        let worst = uv
            .iter()
            .zip(&unit)
            .map(|(a, b)| (a[0] / s - b[0]).abs().max((a[1] / s - b[1]).abs()))
            .fold(0.0f64, f64::max);
        assert!(
            worst <= 1e-7 * size,
            "scale {s:e}: UVs differ by {worst:e} (size {size})"
        );
    }
    // Near the top of the range: valid, not "area inf, below inf".
    let text = fs::read_to_string(data("block.obj")).unwrap();
    let big: String = text
        .lines()
        .map(|l| match l.strip_prefix("v ") {
            Some(r) => {
                let c: Vec<f64> = r.split_whitespace().map(|x| x.parse().unwrap()).collect();
                format!(
                    "v {:e} {:e} {:e}\n",
                    c[0] * 1e308,
                    c[1] * 1e308,
                    c[2] * 1e308
                )
            }
            None => format!("{l}\n"),
        })
        .collect();
    fs::write(dir.join("big.obj"), big).unwrap();
    run(&dir, &["stats", "big.obj"]).expect(0, "");
}

// ------------------------------------------------------------------ exit codes

#[test]
fn a_missing_input_is_exit_2_for_every_command() {
    let dir = TempDir::new("missing");
    for args in [
        vec!["stats", "nope.obj"],
        vec!["param", "nope.obj", "-o", "o.obj"],
        vec!["approx", "nope.obj", "-k", "4", "-o", "o.obj"],
        vec!["volmap", "nope.mesh", "--target", "ball", "-o", "o.mesh"],
        vec!["volcheck", "nope.mesh", "--rest", "nope.mesh"],
        vec!["dev", "volmap-constraints", "nope.mesh", "-o", "c.txt"],
        vec!["render", "nope.obj", "-o", "o.png"],
    ] {
        let r = run(&dir, &args);
        r.expect(2, "nope.");
    }
    let dir = scratch("missing_c", &["cube_5tets.mesh"]);
    run(
        &dir,
        &[
            "volmap",
            "cube_5tets.mesh",
            "--constraints",
            "nope.txt",
            "-o",
            "o.mesh",
        ],
    )
    .expect(2, "nope.txt");
    assert!(dir.entries().len() == 1);
}

#[test]
fn volmap_at_any_scale_gives_the_unit_scale_map_scaled() {
    let m = foldfree::vol::read_any(&data("cube_5tets.mesh")).unwrap();
    let mut delta = Vec::new();
    for s in [1.0, 1e-100, 1e100] {
        let dir = TempDir::new(&format!("volscale{s:e}"));
        let p: Vec<[f64; 3]> = m.positions.iter().map(|q| q.map(|c| c * s)).collect();
        foldfree::vol::write_any(&dir.join("r.mesh"), &m, &p).unwrap();
        run(
            &dir,
            &[
                "dev",
                "volmap-constraints",
                "r.mesh",
                "-o",
                "c.txt",
                "--twist",
                "60",
            ],
        )
        .expect(0, "wrote");
        run(
            &dir,
            &[
                "volmap",
                "r.mesh",
                "--constraints",
                "c.txt",
                "-q",
                "-o",
                "o.mesh",
                "--report",
                "j.json",
            ],
        )
        .expect(0, "");
        let j: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(dir.join("j.json")).unwrap()).unwrap();
        assert_eq!(j["written"]["inverted"], 0, "scale {s:e}");
        assert_eq!(j["constraints_met"], true, "scale {s:e}");
        delta.push(j["written"]["delta_t"].as_f64().unwrap());
    }
    for d in &delta[1..] {
        assert!((d - delta[0]).abs() <= 1e-6 * delta[0], "δ_t {delta:?}");
    }
}

// ------------------------------------------------------------------ found by the audit

#[test]
fn a_texel_density_out_of_reach_is_a_usage_error_not_a_panic() {
    // 1e300 asked the packer for a bitmap as large as the scaled chart (a capacity-overflow
    // panic); 1e-300 collapsed every chart below a texel (exit 1, "flipped faces").
    for (density, needle) in [("1e300", "more than 16384"), ("1e-300", "under one texel")] {
        refused(
            "texel",
            &["two_triangles.obj"],
            &[
                "param",
                "two_triangles.obj",
                "-o",
                "o.obj",
                "-q",
                "--cut",
                "always",
                "--texel-density",
                density,
            ],
            2,
            needle,
        );
    }
}

#[test]
fn cut_and_pack_options_have_ranges_in_the_library() {
    // `--extra-seams 18446744073709551615` ran for ever; the seam options were checked by
    // the CLI only.
    let mut c = foldfree::param::cut::CutOptions::default();
    assert!(c.validate().is_ok());
    c.extra_seams = usize::MAX;
    assert!(c.validate().is_err());
    c = Default::default();
    c.curvature_weight = f64::NAN;
    assert!(c.validate().is_err());
    let mut p = foldfree::param::pack::PackOptions::default();
    assert!(p.validate().is_ok());
    p.padding = 10_000;
    assert!(p.validate().is_err());
    // (A tuning file's integers are TOML's, at most 2^63 − 1.)
    let (_t, tuning) = tuning_file("seams", "[cut]\nextra_seams = 9223372036854775807\n");
    refused(
        "seams",
        &["block.obj"],
        &[
            "param",
            "block.obj",
            "-o",
            "o.obj",
            "-q",
            "--tuning",
            &tuning,
        ],
        2,
        "extra_seams = 9223372036854775807 is outside its range [0, 1000]",
    );
}

#[test]
fn every_option_range_error_has_the_readme_shape() {
    let dir = scratch("shape", &["block.obj", "cube_5tets.mesh"]);
    let (_c, curvature) = tuning_file("shape-curvature", "[cut]\nseam_curvature = nan\n");
    let (_s, stretch) = tuning_file("shape-stretch", "[cut]\nstretch_limit = 0.5\n");
    for args in [
        vec!["param", "block.obj", "-o", "o.obj", "--padding", "1000"],
        vec!["param", "block.obj", "-o", "o.obj", "--resolution", "8"],
        vec!["param", "block.obj", "-o", "o.obj", "--max-pages", "0"],
        vec!["param", "block.obj", "-o", "o.obj", "--tuning", &curvature],
        vec!["param", "block.obj", "-o", "o.obj", "--tuning", &stretch],
        vec!["approx", "block.obj", "-o", "o.obj", "-k", "0"],
        vec![
            "approx",
            "block.obj",
            "-o",
            "o.obj",
            "-k",
            "4",
            "--angle",
            "NaN",
        ],
        vec![
            "dev",
            "volmap-constraints",
            "cube_5tets.mesh",
            "-o",
            "c.txt",
            "--twist",
            "inf",
        ],
        vec![
            "dev",
            "volmap-constraints",
            "cube_5tets.mesh",
            "-o",
            "c.txt",
            "--fraction",
            "0.5",
        ],
    ] {
        run(&dir, &args).expect(2, "is outside its range");
    }
    assert_eq!(dir.entries().len(), 2, "nothing written");
}

/// `cube_5tets.mesh` with every coordinate multiplied by `s`, written as `name`.
fn scaled_cube(dir: &TempDir, s: f64, name: &str) {
    let m = foldfree::vol::read_any(&data("cube_5tets.mesh")).unwrap();
    let p: Vec<[f64; 3]> = m.positions.iter().map(|q| q.map(|c| c * s)).collect();
    foldfree::vol::write_any(&dir.join(name), &m, &p).unwrap();
}

#[test]
fn tet_meshes_at_1e308_and_1e_300_are_checked_at_unit_scale() {
    // Was "rest tet 0 has zero volume (inf)" at 1e308 and "(0.000e0)" at 1e-300.
    for s in [1e308, 1e-300] {
        let dir = TempDir::new("tetscale");
        scaled_cube(&dir, s, "r.mesh");
        run(&dir, &["volcheck", "r.mesh", "--rest", "r.mesh"]).expect(0, "");
        run(
            &dir,
            &["dev", "volmap-constraints", "r.mesh", "-o", "c.txt"],
        )
        .expect(0, "wrote");
        run(
            &dir,
            &[
                "volmap",
                "r.mesh",
                "--constraints",
                "c.txt",
                "-q",
                "-o",
                "o.mesh",
            ],
        )
        .expect(0, "no free tets");
    }
}

#[test]
fn ball_target_at_1e100_is_measured_at_unit_scale_and_refused_beyond() {
    // At 1e100 the map was fold-free but its δ_t overflowed (inf), so it was not written.
    let dir = TempDir::new("ballscale");
    scaled_cube(&dir, 1e100, "r.mesh");
    run(
        &dir,
        &ball("r.mesh", &["-q", "-o", "o.mesh", "--report", "j.json"]),
    )
    .expect(0, "");
    let j: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(dir.join("j.json")).unwrap()).unwrap();
    assert!(j["written"]["delta_t"].as_f64().is_some_and(f64::is_finite));
    // Beyond 1e±100 the unit sphere is not representable against the rest: exit 2, up front.
    scaled_cube(&dir, 1e300, "big.mesh");
    run(&dir, &ball("big.mesh", &["-q", "-o", "b.mesh"])).expect(2, "big.mesh: --target ball");
    assert!(!dir.join("b.mesh").exists());
}

#[test]
fn ball_target_boundary_errors_name_the_rest_file() {
    let dir = TempDir::new("balltopo");
    fs::write(
        dir.join("two.mesh"),
        "MeshVersionFormatted 1\nDimension 3\nVertices\n8\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n\
         5 0 0 0\n6 0 0 0\n5 1 0 0\n5 0 1 0\nTetrahedra\n2\n1 2 3 4 0\n5 6 7 8 0\nEnd\n",
    )
    .unwrap();
    let r = run(&dir, &ball("two.mesh", &["-q", "-o", "o.mesh"]));
    r.expect(
        2,
        "foldfree: error: two.mesh: --target ball needs a connected",
    );
}

#[test]
fn render_refuses_non_finite_positions_and_texture_coordinates() {
    let dir = TempDir::new("render_nan");
    fs::write(
        dir.join("p.obj"),
        "v 0 0 0\nv nan 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n",
    )
    .unwrap();
    run(
        &dir,
        &["render", "p.obj", "-o", "p.png", "--shade", "normals"],
    )
    .expect(2, "p.obj: vertex 1 has a non-finite coordinate (NaN)");
    // A glTF TEXCOORD_0 with a NaN (an OBJ `vt nan` is refused by the OBJ reader).
    let mut bytes = Vec::new();
    for c in [0f32, 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.] {
        bytes.extend(c.to_le_bytes());
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        bytes.extend(i.to_le_bytes());
    }
    for c in [f32::NAN, 0., 1., 0., 1., 1., 0., 1.] {
        bytes.extend(c.to_le_bytes());
    }
    use base64::Engine as _;
    let b64 = base64::engine::general_purpose::STANDARD.encode(&bytes);
    let doc = format!(
        r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"byteLength":{},"uri":"data:application/octet-stream;base64,{b64}"}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":48}},{{"buffer":0,"byteOffset":48,"byteLength":12}},{{"buffer":0,"byteOffset":60,"byteLength":32}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},{{"bufferView":1,"componentType":5123,"count":6,"type":"SCALAR"}},{{"bufferView":2,"componentType":5126,"count":4,"type":"VEC2"}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"TEXCOORD_0":2}},"indices":1}}]}}]}}"#,
        bytes.len()
    );
    fs::write(dir.join("t.gltf"), doc).unwrap();
    // The reader refuses it for every command (glTF forbids non-finite accessor data, and
    // `param` would otherwise write the file's other attributes back as they were).
    let nan = "TEXCOORD_0: element 0 is not a finite number";
    run(&dir, &["render", "t.gltf", "-o", "t.png"]).expect(2, nan);
    run(&dir, &["param", "t.gltf", "-o", "u.gltf", "--uv-set", "1"]).expect(2, nan);
    assert!(!dir.join("p.png").exists() && !dir.join("t.png").exists());
    assert!(!dir.join("u.gltf").exists());
}

#[test]
fn bench_never_overwrites_an_input_and_a_failed_run_is_not_exit_0() {
    // `bench a.obj a-mips-cpu.obj` replaced the second input with the first's map, exit 0;
    // a missing mesh was a table row with exit 0.
    let dir = scratch("bench", &["camel_open.obj"]);
    fs::copy(data("camel_open.obj"), dir.join("camel_open-mips-cpu.obj")).unwrap();
    let args = [
        "dev",
        "bench",
        "camel_open.obj",
        "camel_open-mips-cpu.obj",
        "--backend",
        "cpu",
        "--energy",
        "mips",
        "--max-iters",
        "5",
        "--out-dir",
        ".",
    ];
    run(&dir, &args).expect(2, "refusing to overwrite the input camel_open-mips-cpu.obj");
    assert_eq!(
        fs::read(dir.join("camel_open-mips-cpu.obj")).unwrap(),
        fs::read(data("camel_open.obj")).unwrap()
    );
    run(
        &dir,
        &[
            "dev",
            "bench",
            "nope.obj",
            "--backend",
            "cpu",
            "--out-dir",
            "o",
        ],
    )
    .expect(2, "nope.obj: cannot read");
    run(
        &dir,
        &[
            "dev",
            "bench",
            "camel_open.obj",
            "--backend",
            "cpu",
            "--out-dir",
            "camel_open.obj",
        ],
    )
    .expect(2, "camel_open.obj: cannot write the output folder here");
    assert_eq!(dir.entries().len(), 2, "nothing written");
}

#[test]
fn a_map_that_overflows_the_file_units_is_bad_input_not_a_solver_failure() {
    // Corners at ±1.7e308: the unit-scale map, scaled back, is not representable (was exit 1
    // after the solve).
    let dir = TempDir::new("f64max");
    fs::write(
        dir.join("s.obj"),
        "v -1.7e308 -1.7e308 0\nv 1.7e308 -1.7e308 0\nv 1.7e308 1.7e308 0\nv -1.7e308 1.7e308 0\nf 1 2 3\nf 1 3 4\n",
    )
    .unwrap();
    run(&dir, &["param", "s.obj", "-o", "o.obj", "-q"])
        .expect(2, "s.obj: the map has the mesh's size");
    assert!(!dir.join("o.obj").exists());
    run(&dir, &["stats", "s.obj"]).expect(0, "");
}

#[test]
fn a_constraint_target_beyond_1e100_times_the_mesh_is_bad_input() {
    // Was exit 1 after the work ("Newton start has ... a non-finite value").
    let dir = scratch("far_target", &["cube_5tets.mesh"]);
    fs::write(dir.join("c.txt"), "0 0 0 0\n7 1e300 1e300 1e300\n").unwrap();
    run(
        &dir,
        &[
            "volmap",
            "cube_5tets.mesh",
            "--constraints",
            "c.txt",
            "-q",
            "-o",
            "o.mesh",
        ],
    )
    .expect(2, "c.txt: the target of vertex 7");
    assert!(!dir.join("o.mesh").exists());
}

/// `--max-faces 0` / `--max-tets 0` mean "no limit" for every command (param already read it
/// so; stats, approx and the tet commands refused every mesh).
#[test]
fn a_size_limit_of_zero_means_no_limit_for_every_command() {
    let dir = scratch("limit_zero", &["two_triangles.obj", "cube_5tets.mesh"]);
    run(&dir, &["stats", "two_triangles.obj", "--max-faces", "0"]).expect(0, "");
    run(&dir, &["stats", "two_triangles.obj", "--max-faces", "1"]).expect(2, "limit of 1");
    let tets = ["volcheck", "--rest", "cube_5tets.mesh", "cube_5tets.mesh"];
    run(&dir, &[&tets[..], &["--max-tets", "0"]].concat()).expect(0, "");
    run(&dir, &[&tets[..], &["--max-tets", "1"]].concat()).expect(2, "limit of 1");
}
