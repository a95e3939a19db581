//! Same input and options → byte-identical output OBJ: `foldfree param` on
//! tests/data/camel_open.obj twice per configuration (CPU MIPS, CPU SD, CPU with different rayon
//! thread counts, Vulkan), compared byte for byte. The iteration cap is small so each run takes
//! well under a second on the CPU; the JSON report is not compared (it holds timings).
//!
//! Vulkan: skipped when this machine has none, unless `REQUIRE_VULKAN=1` (then it fails).

use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use crate::common::gpu::vulkan_available;
use crate::common::TempDir;

/// A run that takes longer is a hang.
const TIMEOUT: Duration = Duration::from_secs(180);

fn camel() -> PathBuf {
    crate::common::data("camel_open.obj")
}

/// `foldfree param camel_open.obj -o OUT --max-iters 300 -q EXTRA…` with `env` set; panics
/// unless it exits 0 within [`TIMEOUT`]. Returns the bytes written to OUT.
fn param(out: &Path, extra: &[&str], env: &[(&str, &str)]) -> Vec<u8> {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_foldfree"));
    cmd.arg("param")
        .arg(camel())
        .arg("-o")
        .arg(out)
        .args(["--max-iters", "300", "-q"])
        .args(extra)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let mut child = cmd.spawn().expect("start foldfree");
    let mut pipe = child.stderr.take().expect("piped stderr");
    let drain = thread::spawn(move || {
        let mut s = String::new();
        let _ = pipe.read_to_string(&mut s);
        s
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait for foldfree") {
            break status;
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("foldfree param {extra:?} still running after {TIMEOUT:?}; killed");
        }
        thread::sleep(Duration::from_millis(10));
    };
    let stderr = drain.join().unwrap_or_default();
    // A 300-iteration ADMM budget hands off to the global solver; exit 3 (map written) if that
    // too stops short.
    let kept = status.code() == Some(3) && stderr.contains("best flip-free map was written");
    assert!(
        status.success() || kept,
        "foldfree param {extra:?} failed ({status}):\n{stderr}"
    );
    fs::read(out).unwrap_or_else(|e| panic!("read {}: {e}", out.display()))
}

/// Asserts `a == b`, naming the first differing line (1-based) of the two OBJ texts.
fn assert_same_bytes(a: &[u8], b: &[u8], what: &str) {
    if a == b {
        return;
    }
    let (ta, tb) = (String::from_utf8_lossy(a), String::from_utf8_lossy(b));
    let differing = ta
        .lines()
        .zip(tb.lines())
        .enumerate()
        .filter(|(_, (x, y))| x != y)
        .map(|(i, _)| i + 1)
        .collect::<Vec<_>>();
    let first = differing.first().copied();
    let line = |t: &str, n: Option<usize>| {
        n.and_then(|n| t.lines().nth(n - 1))
            .unwrap_or("")
            .to_string()
    };
    panic!(
        "{what}: outputs differ ({} vs {} bytes, {} differing lines); first at line {first:?}:\n  \
         run 1: {}\n  run 2: {}",
        a.len(),
        b.len(),
        differing.len(),
        line(&ta, first),
        line(&tb, first)
    );
}

/// Runs the same configuration twice and compares the outputs.
fn assert_reproducible(test: &str, extra: &[&str]) {
    let dir = TempDir::new(test);
    let a = param(&dir.join("a.obj"), extra, &[]);
    let b = param(&dir.join("b.obj"), extra, &[]);
    assert_same_bytes(&a, &b, &format!("param {extra:?}"));
}

#[test]
fn cpu_mips_output_is_byte_identical_across_runs() {
    assert_reproducible("cpu-mips", &["--backend", "cpu", "--energy", "mips"]);
}

#[test]
fn cpu_sd_output_is_byte_identical_across_runs() {
    assert_reproducible("cpu-sd", &["--backend", "cpu", "--energy", "sd"]);
}

/// Stronger than run-to-run: the CPU result does not depend on how many rayon threads share
/// the work (reductions are summed in fixed chunks, in order).
#[test]
fn cpu_output_does_not_depend_on_the_thread_count() {
    let dir = TempDir::new("threads");
    let extra = ["--backend", "cpu"];
    let one = param(&dir.join("t1.obj"), &extra, &[("RAYON_NUM_THREADS", "1")]);
    for threads in ["2", "3"] {
        let out = dir.join(&format!("t{threads}.obj"));
        let many = param(&out, &extra, &[("RAYON_NUM_THREADS", threads)]);
        assert_same_bytes(&one, &many, &format!("RAYON_NUM_THREADS 1 vs {threads}"));
    }
}

#[test]
fn vulkan_output_is_byte_identical_across_runs() {
    if !vulkan_available() {
        return;
    }
    assert_reproducible("vulkan-mips", &["--backend", "vulkan"]);
}
