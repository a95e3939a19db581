//! Tuning files (`--tuning FILE.toml`): the solver knobs the command line no longer has. A file
//! with every default written out reproduces a run without one byte for byte; a non-default
//! file gives the bytes the library gives with the same options; a bad file is bad input
//! (exit 2) naming file, line and key, with nothing written.

use std::fs;
use std::path::Path;
use std::process::{Command, Output};

use crate::common::{data, TempDir};
use foldfree::init::InitMethod;
use foldfree::param::admm::{Accel, AdmmOptions};
use foldfree::param::recover::Recovery;
use foldfree::param::{BackendChoice, ParamJob, SolverChoice};
use foldfree::tuning::Tuning;

fn foldfree(dir: &TempDir, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .current_dir(&dir.0)
        .args(args)
        .output()
        .expect("run foldfree")
}

fn ok(out: &Output) {
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `foldfree dev tuning` prints a complete file; run with it, `param` (disk and atlas) and
/// `volmap` write the same bytes as without it.
#[test]
fn the_default_tuning_file_changes_nothing() {
    let dir = TempDir::new("tuning_defaults");
    let printed = foldfree(&dir, &["dev", "tuning"]);
    ok(&printed);
    fs::write(dir.join("defaults.toml"), &printed.stdout).expect("write");
    assert_eq!(
        String::from_utf8_lossy(&printed.stdout),
        Tuning::default_toml()
    );
    let grid = data("square_grid_10x10.obj");
    let cube = data("cube_5tets.mesh");
    let grid = grid.to_str().expect("utf-8");
    let cube = cube.to_str().expect("utf-8");
    ok(&foldfree(
        &dir,
        &["dev", "volmap-constraints", cube, "-o", "c.txt"],
    ));
    let runs: [(&str, Vec<&str>); 4] = [
        ("grid.obj", vec!["param", grid, "--backend", "cpu"]),
        (
            "sd.obj",
            vec!["param", grid, "--backend", "cpu", "--energy", "sd"],
        ),
        (
            "atlas.obj",
            vec!["param", grid, "--cut", "always", "--backend", "cpu"],
        ),
        ("cube.mesh", vec!["volmap", cube, "--constraints", "c.txt"]),
    ];
    for (out, args) in runs {
        let plain = format!("plain-{out}");
        let tuned = format!("tuned-{out}");
        let mut a = args.clone();
        a.extend(["-q", "-o", &plain]);
        ok(&foldfree(&dir, &a));
        let mut a = args.clone();
        a.extend(["-q", "-o", &tuned, "--tuning", "defaults.toml"]);
        ok(&foldfree(&dir, &a));
        assert_eq!(
            fs::read(dir.join(&plain)).expect("read"),
            fs::read(dir.join(&tuned)).expect("read"),
            "{out}: the default tuning file changed the output"
        );
    }
}

/// A non-default `[admm]` table through the CLI gives the bytes of the library's `run_param`
/// with the same options.
#[test]
fn a_tuning_file_gives_the_library_run_with_its_options() {
    let dir = TempDir::new("tuning_library");
    let grid = data("square_grid_10x10.obj");
    fs::write(
        dir.join("t.toml"),
        "[admm]\nmu = 300.0\nrecovery = \"bfs\"\naccel = \"anderson\"\ncheck_every = 10\n\n\
         [cut]\nseam_curvature = 0.5\n",
    )
    .expect("write");
    ok(&foldfree(
        &dir,
        &[
            "param",
            grid.to_str().expect("utf-8"),
            "-o",
            "cli.obj",
            "-q",
            "--tuning",
            "t.toml",
        ],
    ));
    let mut job = ParamJob::new(&grid, dir.join("lib.obj"));
    job.admm = AdmmOptions {
        mu_rel: Some(300.0),
        recovery: Recovery::BreadthFirst,
        accel: Accel::Anderson,
        check_every: 10,
        ..AdmmOptions::default()
    };
    job.cut_options.curvature_weight = 0.5;
    // Anderson acceleration runs on the CPU: the CLI's `--backend auto` means the CPU then.
    job.backend = BackendChoice::Cpu;
    job.init = InitMethod::Lscm;
    job.solver = SolverChoice::Admm;
    foldfree::param::run_param(&job, &mut |_| {}).expect("library run");
    let cli = fs::read(dir.join("cli.obj")).expect("read");
    assert_eq!(cli, fs::read(dir.join("lib.obj")).expect("read"));
    // And the knobs did something: the default run's map differs.
    ok(&foldfree(
        &dir,
        &[
            "param",
            grid.to_str().expect("utf-8"),
            "-o",
            "default.obj",
            "-q",
        ],
    ));
    assert_ne!(cli, fs::read(dir.join("default.obj")).expect("read"));
}

/// Unknown keys, wrong types and values outside their range: exit 2, `FILE:LINE:` and the key
/// in the one error line, no output.
#[test]
fn a_bad_tuning_file_is_bad_input_naming_file_line_and_key() {
    let dir = TempDir::new("tuning_bad");
    let grid = data("square_grid_10x10.obj");
    let cube = data("cube_5tets.mesh");
    let cases: [(&str, &str, usize, &str); 8] = [
        (
            "param",
            "[admm]\nmu = 100.0\nmux = 3\n",
            3,
            "unknown field `mux`",
        ),
        (
            "param",
            "# knobs\n[admm]\ntol_dual = 2.0\n",
            3,
            "tol_dual = 2 is outside its range",
        ),
        ("param", "[cut]\nextra_seams = \"many\"\n", 2, "extra_seams"),
        ("param", "[solver]\nmu = 1.0\n", 1, "unknown field `solver`"),
        (
            "volmap",
            "[volmap]\n\nmax_rounds = 0\n",
            3,
            "max_rounds = 0 is outside its range",
        ),
        (
            "volmap",
            "[volmap.post]\nmax_iters = 0\n",
            2,
            "post.max_iters = 0",
        ),
        (
            "volmap",
            "[volmap]\nball_refine_rounds = 1001\n",
            2,
            "ball_refine_rounds = 1001 is outside its range",
        ),
        (
            "volmap",
            "[volmap.untangle]\nstall_decades = 0.0\n",
            2,
            "untangle.stall_decades = 0",
        ),
    ];
    for (i, (cmd, text, line, needle)) in cases.into_iter().enumerate() {
        let file = format!("bad{i}.toml");
        fs::write(dir.join(&file), text).expect("write");
        let input = if cmd == "param" { &grid } else { &cube };
        let mut args = vec![cmd, input.to_str().expect("utf-8"), "-o", "out.obj", "-q"];
        if cmd == "volmap" {
            args[3] = "out.mesh";
            args.extend(["--target", "ball"]);
        }
        args.extend(["--tuning", &file]);
        let out = foldfree(&dir, &args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{text}: {err}");
        assert!(err.contains(&format!("{file}:{line}:")), "{text}: {err}");
        assert!(err.contains(needle), "{text}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
    }
    let left: Vec<_> = dir
        .entries()
        .into_iter()
        .filter(|f| !f.ends_with(".toml"))
        .collect();
    assert!(left.is_empty(), "written on bad input: {left:?}");
    // A missing file is bad input too.
    let out = foldfree(
        &dir,
        &[
            "param",
            grid.to_str().expect("utf-8"),
            "-o",
            "out.obj",
            "--tuning",
            "nope.toml",
        ],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(!dir.join("out.obj").exists());
}

/// The bound: `param --help` lists at most 25 options (the solver knobs are in the
/// tuning file).
#[test]
fn param_help_lists_at_most_25_options() {
    let dir = TempDir::new("tuning_help");
    let out = foldfree(&dir, &["param", "--help"]);
    ok(&out);
    let help = String::from_utf8_lossy(&out.stdout);
    let options = help
        .lines()
        .filter(|l| {
            // Option lines are indented; the text after the options is not.
            let t = l.trim_start();
            l.starts_with("  ")
                && (t.starts_with("--") || (t.starts_with('-') && t.get(2..4) == Some(", ")))
        })
        .count();
    assert!(options <= 25, "{options} options:\n{help}");
    assert!(help.contains("--tuning"));
}

/// The library side: `Tuning::default_toml` reads back as the defaults; errors carry
/// `FILE:LINE:` and the key for unknown keys, wrong types and values outside their range, at
/// any depth; an optional phase is switched off with `false`.
#[test]
fn the_library_tuning_type_reads_checks_and_locates() {
    let text = Tuning::default_toml();
    let t = Tuning::from_toml(&text, Path::new("d.toml")).expect("defaults");
    let defaults = toml::to_string(&Tuning::default()).expect("serialize");
    assert_eq!(toml::to_string(&t).expect("serialize"), defaults);
    assert!(text.ends_with(&defaults));
    for (text, at, key) in [
        ("[admm]\nmu = 1.0\nmux = 2\n", "t.toml:3:", "mux"),
        ("[admm]\n\ntol_dual = 2.0\n", "t.toml:3:", "tol_dual"),
        (
            "[volmap.post]\nmax_iters = 0\n",
            "t.toml:2:",
            "post.max_iters",
        ),
        (
            "[volmap]\npost = { max_iters = 0 }\n",
            "t.toml:2:",
            "post.max_iters",
        ),
        (
            "[volmap.newton.cg]\npreconditioner = \"ilu\"\n",
            "t.toml:2:",
            "preconditioner",
        ),
        ("[cut]\nextra_seams = \"x\"\n", "t.toml:2:", "extra_seams"),
        ("admm.aa_depth = 0\n", "t.toml:1:", "aa_depth"),
    ] {
        let e = Tuning::from_toml(text, Path::new("t.toml"))
            .expect_err(text)
            .to_string();
        assert!(e.starts_with(at) && e.contains(key), "{text}: {e}");
    }
    let t = Tuning::from_toml("[volmap]\npost = false\n", Path::new("t.toml")).expect("off");
    assert!(t.volmap.post.is_none() && t.volmap.untangle.is_some());
    let t = Tuning::from_toml(
        "[volmap.newton.cg]\npreconditioner = { amg = { block_size = 3 } }\n",
        Path::new("t.toml"),
    )
    .expect("amg");
    assert_eq!(
        t.volmap.newton.cg.preconditioner,
        foldfree::linalg::precond::Preconditioner::Amg { block_size: 3 }
    );
}
