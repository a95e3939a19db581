#!/usr/bin/env python3
"""Acceptance sweep of `foldfree approx`: every mesh × K × seed, each polygon OBJ checked independently.

Usage:
  python3 benches/approxsweep.py --bin target/release/foldfree --out DIR [--jobs 2] [--timeout 60] \\
      [--k 24,60,100] [--seeds 1,2,3] [--vsa ../shared/meshes/sweep/vsa.jsonl] [--peers ../shared/peers.md] \\
      [--label TEXT] [--force] [MESH_OR_FOLDER...] [-- EXTRA_APPROX_ARGS...]
  python3 benches/approxsweep.py --out DIR --summary-only     # summary of DIR/runs.jsonl only

A folder stands for every `*.obj` directly in it (sorted; shared stems disambiguated as in sweep.py).
Without meshes the default set is used (paths relative to the repository's parent folder):
  ../shared/meshes/sweep/cad/*.obj, ../shared/meshes/cad/*.obj, ../shared/meshes/closed/bunny_npm.obj,
  ../shared/meshes/sweep/closed/{cgal_cow,cgal_elk,cgal_homer,oded_goathead}.obj
i.e. the meshes that have a CGAL VSA reference, plus cgal_b9_mesh (none). Seed 1 is approx's default.

Each run NAME-k<K>-s<S> is its own process group,
  BIN approx MESH -k K --seed S -q -o DIR/runs/T.obj --polygons DIR/runs/T-poly.obj --report DIR/runs/T.json
      EXTRA_APPROX_ARGS...
with stdout / stderr in DIR/runs/T.out.txt / T.err.txt, `--jobs` at a time, killed after `--timeout`
seconds of wall clock (0 = none). Then `benches/polycheck.py` (its own process, so a slow check runs
beside the next approx) re-reads the polygon OBJ with the report's `bbox_diagonal` (else the input's)
and `--allow-boundary` when the input OBJ has boundary edges. Each finished run appends one JSON line
to DIR/runs.jsonl at once; runs already in it (same NAME, K, seed and extra arguments) are skipped
unless --force (the summary then keeps the newest line of each run). Ctrl-C kills the running
processes, prints the summary of what finished and exits with 130. The Markdown summary goes to
stdout and DIR/summary.md.

VSA reference (CGAL Variational Shape Approximation, by mesh file name and K): `--vsa` JSON lines
{"mesh", "K", "time_s", "mean_dist_rel_diag"}, and the table of `--peers`' section "Planar
approximation: CGAL Variational Shape Approximation" (time_s = the first number of "s (+extract)",
mean_dist_rel_diag = "rel. to diag"). Both default to the shared files when they exist; pass an
empty string to leave one out. Per run:
  err_ratio  = report mean_input_distance_rel / VSA mean_dist_rel_diag
  time_ratio = wall seconds of the approx process / VSA time_s          (null without a reference)
A run passes iff it exits 0 (no timeout), writes the report and the polygon OBJ, and polycheck finds
polygons ≤ K, max_planarity_rel ≤ 1e-6 (the report's max_planarity_deviation_rel too), watertight,
0 self-intersections, 0 bad polygons, and the report has flipped_faces = degenerate_faces = 0 and
err_ratio ≤ 1.25 (when known). `fail_reasons` lists every criterion a run misses.
Issue targets shown in the summary: ≥ 75 % of the runs with a reference at err_ratio ≤ 1, max
err_ratio ≤ 1.25, median time_ratio ≤ 10, max wall time ≤ 10 s.
"""
import argparse
import concurrent.futures
import datetime
import json
import os
import re
import shlex
import signal
import statistics
import subprocess
import sys
import threading
import time
import traceback
from collections import Counter
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from polycheck import input_boundary  # noqa: E402
from sweep import collect, kill_group  # noqa: E402  (same mesh naming and process-group kill)

SHARED = HERE.parent.parent / "shared"
DEFAULT_INPUTS = [SHARED / "meshes/sweep/cad", SHARED / "meshes/cad", SHARED / "meshes/closed/bunny_npm.obj"] + \
    [SHARED / f"meshes/sweep/closed/{m}.obj" for m in ("cgal_cow", "cgal_elk", "cgal_homer", "oded_goathead")]
DEFAULT_VSA = SHARED / "meshes/sweep/vsa.jsonl"
DEFAULT_PEERS = SHARED / "peers.md"
PEERS_SECTION = "Planar approximation: CGAL Variational Shape Approximation"

PLANARITY_MAX, ERR_RATIO_MAX = 1e-6, 1.25
TARGET_ERR_SHARE, TARGET_TIME_RATIO, TARGET_WALL_S = 0.75, 10.0, 10.0

# Report field → row field ("runs" renamed: in a row of a sweep it would read as the sweep's runs).
REPORT_FIELDS = {"faces": "faces", "k_obtained": "k_obtained", "polygons": "polygons",
                 "mean_input_distance_rel": "mean_input_distance_rel",
                 "max_input_distance_rel": "max_input_distance_rel", "flipped_faces": "flipped_faces",
                 "degenerate_faces": "degenerate_faces", "max_planarity_deviation_rel": "max_planarity_deviation_rel",
                 "seconds_all_runs": "seconds_all_runs", "seed_used": "seed_used", "runs": "runs_tried",
                 "bbox_diagonal": "bbox_diagonal", "corners": "corners", "polygon_holes": "polygon_holes",
                 "notes": "notes"}
CHECK_FIELDS = ["polygons", "max_planarity_rel", "watertight", "open_edges", "nonmanifold_edges",
                "misoriented_edges", "self_intersections", "intersections_disjoint",
                "intersections_shared_vertex", "overlaps_shared_edge", "bad_polygons", "bad_polygon_reasons",
                "triangles", "degenerate_triangles", "duplicate_corners", "allow_boundary"]


# ---------------------------------------------------------------- VSA reference

def read_vsa(vsa_path, peers_path):
    """{(mesh file name, K): {"time_s", "mean_dist_rel_diag", "source"}}."""
    ref = {}
    if vsa_path:
        for line in Path(vsa_path).read_text(encoding="utf-8").splitlines():
            if line.strip():
                r = json.loads(line)
                ref[(r["mesh"], int(r["K"]))] = {"time_s": r["time_s"], "mean_dist_rel_diag": r["mean_dist_rel_diag"],
                                                 "source": "vsa.jsonl"}
    if peers_path:
        ref.update(read_peers(peers_path))
    return ref


def read_peers(path):
    """The VSA table of peers.md: the first Markdown table after the section heading."""
    out, header, in_section = {}, None, False
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            if in_section and header:
                break  # next section
            in_section = PEERS_SECTION in line
            continue
        if not in_section or not line.startswith("|"):
            if in_section and header and line.strip():
                break  # the text after the table
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if header is None:
            header = cells
            continue
        if set(cells[0]) <= set("-: "):
            continue  # the |---| row
        row = dict(zip(header, cells))
        first = re.match(r"[-+0-9.eE]+", row["s (+extract)"])
        out[(row["mesh"], int(row["K"]))] = {"time_s": float(first.group(0)),
                                            "mean_dist_rel_diag": float(row["rel. to diag"]), "source": "peers.md"}
    if not out:
        print(f"approxsweep: no VSA table found in {path}", file=sys.stderr)
    return out


# ---------------------------------------------------------------- runs

def tail(path, lines=5):
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return None
    return "\n".join(text[-lines:]) or None


def run_key(row):
    return (row["name"], row["K"], row["seed"], tuple(row.get("args") or ()))


class ApproxSweep:
    def __init__(self, opts, extra, runs, cmdline):
        self.opts, self.extra, self.runs = opts, extra, runs
        self.out = Path(opts.out)
        self.meta = {"label": opts.label, "cmdline": cmdline, "bin": opts.bin,
                     "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")}
        self.vsa = read_vsa(opts.vsa, opts.peers)
        (self.out / "runs").mkdir(parents=True, exist_ok=True)
        self.jsonl = open(self.out / "runs.jsonl", "a", encoding="utf-8")
        self.lock = threading.Lock()
        self.running, self.killed = {}, set()
        self.stop = threading.Event()
        self.finished = 0
        self.inputs = {}  # mesh path → (boundary edges, bbox diagonal), read once per mesh

    def interrupt(self):
        with self.lock:
            self.stop.set()
            for pid in self.running:
                self.killed.add(pid)
                kill_group(pid)

    def call(self, cmd, out, err, timeout):
        """(exit code, timed out, interrupted) of cmd as its own process group."""
        with open(out, "wb") as fo, open(err, "wb") as fe:
            with self.lock:
                if self.stop.is_set():
                    return None, False, True
                proc = subprocess.Popen(cmd, stdout=fo, stderr=fe, stdin=subprocess.DEVNULL, start_new_session=True)
                self.running[proc.pid] = proc
            try:
                code, timed_out = proc.wait(timeout=timeout or None), False
            except subprocess.TimeoutExpired:
                kill_group(proc.pid)
                proc.wait()
                code, timed_out = None, True
            finally:
                with self.lock:
                    self.running.pop(proc.pid, None)
                    interrupted = proc.pid in self.killed
        return code, timed_out, interrupted

    def input_facts(self, path):
        with self.lock:
            if path in self.inputs:
                return self.inputs[path]
        facts = (None, None)
        if path.suffix.lower() == ".obj":
            try:
                facts = input_boundary(path)
            except (OSError, ValueError, IndexError):
                pass
        with self.lock:
            self.inputs[path] = facts
        return facts

    def run_one(self, name, path, k, seed):
        tag = f"{name}-k{k}-s{seed}"
        d = self.out / "runs"
        objp, poly, rep = d / f"{tag}.obj", d / f"{tag}-poly.obj", d / f"{tag}.json"
        outt, errt = d / f"{tag}.out.txt", d / f"{tag}.err.txt"
        for p in (objp, poly, rep):
            p.unlink(missing_ok=True)  # so that "written" means written by this run
        cmd = [self.opts.bin, "approx", str(path), "-k", str(k), "--seed", str(seed), "-q", "-o", str(objp),
               "--polygons", str(poly), "--report", str(rep), *self.extra]
        t0 = time.monotonic()
        code, timed_out, interrupted = self.call(cmd, outt, errt, self.opts.timeout)
        wall = time.monotonic() - t0
        if interrupted:
            return  # killed by Ctrl-C: not a finished run
        row = {"mesh": path.name, "name": name, "path": str(path), "K": k, "seed": seed, "args": self.extra,
               "label": self.opts.label, "exit": code, "timeout": timed_out, "wall_s": round(wall, 3),
               "written_obj": objp.exists(), "written_poly": poly.exists(), "report": rep.exists(),
               "stderr_tail": tail(errt)}
        try:
            report = json.loads(rep.read_text())
        except (OSError, ValueError):
            report = {}
        row.update({ours: report.get(theirs) for theirs, ours in REPORT_FIELDS.items()})
        row["seconds_kept_run"] = (report.get("seconds") or {}).get("total")
        boundary_edges, input_diag = self.input_facts(path)
        row["input_boundary_edges"], row["input_diag"] = boundary_edges, input_diag
        row.update({f"check_{f}": None for f in CHECK_FIELDS})
        row["check_error"] = row["check_seconds"] = None
        if row["written_poly"]:
            if not self.check(row, tag, poly, report.get("bbox_diagonal") or input_diag, boundary_edges):
                return
        ref = self.vsa.get((path.name, k))
        row["vsa_time_s"] = ref["time_s"] if ref else None
        row["vsa_mean_dist_rel_diag"] = ref["mean_dist_rel_diag"] if ref else None
        row["vsa_source"] = ref["source"] if ref else None
        mean = row["mean_input_distance_rel"]
        # An exact VSA (a cube: error 0) is matched only by an exact fit, to rounding.
        row["err_ratio"] = (None if not ref or mean is None else
                            mean / ref["mean_dist_rel_diag"] if ref["mean_dist_rel_diag"] > 0 else
                            1.0 if mean <= 1e-12 else 1e9)
        # A timed-out run's ratio is a lower bound; it is kept so that slow meshes are not hidden.
        row["time_ratio"] = wall / ref["time_s"] if ref and ref["time_s"] else None
        row["fail_reasons"] = fail_reasons(row)
        row["pass"] = not row["fail_reasons"]
        row.update(self.meta)
        with self.lock:
            self.finished += 1
            self.jsonl.write(json.dumps(row) + "\n")
            self.jsonl.flush()
            status = "timeout" if timed_out else f"exit {code}"
            why = "" if row["pass"] else " (" + "; ".join(row["fail_reasons"]) + ")"
            print(f"[{self.finished}/{len(self.runs)}] {tag}: {status}, {'pass' if row['pass'] else 'FAIL'}"
                  f"{why}, {wall:.1f} s", file=sys.stderr, flush=True)

    def check(self, row, tag, poly, diag, boundary_edges):
        """polycheck's fields into row; False when interrupted."""
        d = self.out / "runs"
        cmd = [sys.executable, str(HERE / "polycheck.py"), str(poly)]
        if diag:
            cmd += ["--diag", repr(float(diag))]
        if boundary_edges:
            cmd.append("--allow-boundary")
        t0 = time.monotonic()
        code, timed_out, interrupted = self.call(cmd, d / f"{tag}.check.json", d / f"{tag}.check-err.txt",
                                                 max(120.0, self.opts.timeout or 0))
        row["check_seconds"] = round(time.monotonic() - t0, 3)
        if interrupted:
            return False
        if code != 0 or timed_out:
            row["check_error"] = "timeout" if timed_out else (tail(d / f"{tag}.check-err.txt", 1) or f"exit {code}")
            return True
        try:
            res = json.loads((d / f"{tag}.check.json").read_text())
        except (OSError, ValueError) as e:
            row["check_error"] = f"{type(e).__name__}: {e}"
            return True
        row.update({f"check_{f}": res.get(f) for f in CHECK_FIELDS})
        return True


def fail_reasons(r):
    """Every pass criterion the run misses, as "what: detail" (empty = pass)."""
    why = []
    if r.get("timeout"):
        why.append("timeout")
    elif r.get("exit") != 0:
        why.append(f"exit {r.get('exit')}")
    if not r.get("report"):
        why.append("no report")
    if not r.get("written_poly"):
        why.append("no polygon OBJ")
    elif r.get("check_error"):
        why.append(f"polycheck error: {r['check_error']}")
    elif r.get("check_polygons") is not None:
        if r["check_polygons"] > r["K"]:
            why.append(f"polygons > K: {r['check_polygons']}")
        if not r["check_max_planarity_rel"] <= PLANARITY_MAX:
            why.append(f"planarity: {r['check_max_planarity_rel']:.2e}")
        if not r["check_watertight"]:
            why.append(f"not watertight: open {r['check_open_edges']}, non-manifold {r['check_nonmanifold_edges']}, "
                       f"misoriented {r['check_misoriented_edges']}")
        if r["check_self_intersections"]:
            why.append(f"self-intersections: {r['check_self_intersections']}")
        if r["check_bad_polygons"]:
            why.append(f"bad polygons: {r['check_bad_polygons']}")
    if r.get("report"):
        plan = r.get("max_planarity_deviation_rel")
        if plan is None or not plan <= PLANARITY_MAX:
            why.append(f"report planarity: {plan}")
        for f in ("flipped_faces", "degenerate_faces"):
            if r.get(f) != 0:
                why.append(f"{f.split('_')[0]}: {r.get(f)}")
    if r.get("err_ratio") is not None and not r["err_ratio"] <= ERR_RATIO_MAX:
        why.append(f"err_ratio > {ERR_RATIO_MAX}: {r['err_ratio']:.3f}")
    return why


# ---------------------------------------------------------------- summary

def read_rows(out):
    """The newest row of every run in DIR/runs.jsonl (a --force rerun appends a newer one)."""
    rows = {}
    jl = Path(out) / "runs.jsonl"
    for line in jl.read_text(encoding="utf-8").splitlines() if jl.exists() else []:
        try:
            r = json.loads(line)
        except ValueError:
            continue  # a torn last line
        rows[run_key(r)] = r
    return list(rows.values())


def f3(x, kind="g"):
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if kind == "s":
        return f"{x:.1f}"
    if kind == "e":
        return f"{x:.1e}"
    return f"{x:.3f}" if isinstance(x, float) else str(x)


def target(ok):
    return "met" if ok else "**NOT met**"


def summary(rows):
    n = len(rows)
    if not n:
        return "# Approx sweep\n\nno runs\n"
    meta = max(rows, key=lambda r: r.get("date") or "")
    ok = sum(1 for r in rows if r.get("pass"))
    codes = Counter("timeout" if r.get("timeout") else r.get("exit") for r in rows)
    shown = [0, 1, 2, "timeout"]
    other = sum(v for c, v in codes.items() if c not in shown)
    reported = [r for r in rows if r.get("report")]
    checked = [r for r in rows if r.get("check_polygons") is not None]
    foldfree = sum(1 for r in reported if r.get("flipped_faces") == 0 and r.get("degenerate_faces") == 0)
    watertight = sum(1 for r in checked if r.get("check_watertight"))
    si_free = sum(1 for r in checked if r.get("check_self_intersections") == 0)
    bad_free = sum(1 for r in checked if r.get("check_bad_polygons") == 0)
    planar = sum(1 for r in checked if (r.get("check_max_planarity_rel") or 0) <= PLANARITY_MAX
                 and (r.get("max_planarity_deviation_rel") or 0) <= PLANARITY_MAX)
    within_k = sum(1 for r in checked if r["check_polygons"] <= r["K"])
    with_ref = [r for r in rows if r.get("vsa_mean_dist_rel_diag") is not None]
    errs = [r for r in with_ref if r.get("err_ratio") is not None]
    at_most_1 = sum(1 for r in errs if r["err_ratio"] <= 1.0)
    share = at_most_1 / len(with_ref) if with_ref else None
    worst_err = max(errs, key=lambda r: r["err_ratio"], default=None)
    trs = [r["time_ratio"] for r in rows if r.get("time_ratio") is not None]
    slowest = max(rows, key=lambda r: r["wall_s"])
    meshes = sorted({r["name"] for r in rows})
    reasons = Counter(w.split(":")[0] for r in rows for w in r.get("fail_reasons") or [])
    md = [f"# Approx sweep: {meta.get('label') or '(no label)'}", "",
          f"- command: `{meta.get('cmdline', '–')}`", f"- date: {meta.get('date', '–')}",
          f"- binary: `{meta.get('bin', '–')}`", "", "## Summary", "",
          f"- runs: {n} ({len(meshes)} mesh{'es' if len(meshes) != 1 else ''}; K {', '.join(map(str, sorted({r['K'] for r in rows})))}; "
          f"seeds {', '.join(map(str, sorted({r['seed'] for r in rows})))}), "
          f"passed: {ok} ({100.0 * ok / n:.1f} %)",
          "- exit codes: " + ", ".join(f"{c}: {codes.get(c, 0)}" for c in shown) + f", other: {other}",
          f"- fold-free (report flipped = degenerate = 0): {foldfree} of {len(reported)} runs with a report",
          f"- polycheck on {len(checked)} polygon OBJs: watertight {watertight}, self-intersection-free {si_free}, "
          f"no bad polygon {bad_free}, planar (≤ {PLANARITY_MAX:g}·diag, polycheck and report) {planar}, "
          f"polygons ≤ K {within_k}",
          f"- err_ratio ≤ 1: {at_most_1} of {len(with_ref)} runs with a VSA reference"
          + (f" ({100.0 * share:.1f} %; target ≥ {100 * TARGET_ERR_SHARE:.0f} %: {target(share >= TARGET_ERR_SHARE)})"
             if share is not None else "") + " (runs without a report count as misses)",
          "- max err_ratio: " + (f"{worst_err['err_ratio']:.3f} ({worst_err['name']} K {worst_err['K']} "
                                 f"seed {worst_err['seed']}; target ≤ {ERR_RATIO_MAX}: "
                                 f"{target(worst_err['err_ratio'] <= ERR_RATIO_MAX)})" if worst_err else "–"),
          "- median time_ratio (wall / VSA time_s): " + (f"{statistics.median(trs):.1f} over {len(trs)} runs "
                                                         f"(target ≤ {TARGET_TIME_RATIO:g}: "
                                                         f"{target(statistics.median(trs) <= TARGET_TIME_RATIO)})"
                                                         if trs else "–"),
          f"- max wall time: {slowest['wall_s']:.1f} s{' (timeout)' if slowest.get('timeout') else ''} "
          f"({slowest['name']} K {slowest['K']} seed {slowest['seed']}; target ≤ {TARGET_WALL_S:g} s: "
          f"{target(slowest['wall_s'] <= TARGET_WALL_S)}); median {statistics.median(r['wall_s'] for r in rows):.1f} s",
          "- failure reasons (runs): " + (", ".join(f"{w}: {c}" for w, c in reasons.most_common()) or "none")]
    cols = [("run", None, ""), ("faces", "faces", ""), ("exit", None, ""), ("polygons", "check_polygons", ""),
            ("err_ratio", "err_ratio", ""), ("mean dist/diag", "mean_input_distance_rel", "e"),
            ("VSA", "vsa_mean_dist_rel_diag", "e"), ("wall s", "wall_s", "s"), ("time_ratio", "time_ratio", "s"),
            ("runs tried", "runs_tried", ""), ("watertight", "check_watertight", ""),
            ("self-int.", "check_self_intersections", ""), ("planarity", "check_max_planarity_rel", "e"),
            ("flipped", "flipped_faces", ""), ("pass", "pass", "")]

    def table(title, rs):
        out = ["", f"## {title}", "", "| " + " | ".join(c for c, _, _ in cols) + " |", "|" + "---|" * len(cols)]
        for r in rs:
            cells = []
            for c, key, kind in cols:
                if c == "run":
                    cells.append(f"{r['name']} K{r['K']} s{r['seed']}")
                elif c == "exit":
                    cells.append("timeout" if r.get("timeout") else str(r.get("exit")))
                else:
                    cells.append(f3(r.get(key), kind))
            out.append("| " + " | ".join(cells) + " |")
        return out

    md += table("Worst 10 by err_ratio", sorted(errs, key=lambda r: -r["err_ratio"])[:10])
    md += table("10 slowest", sorted(rows, key=lambda r: -r["wall_s"])[:10])
    fails = sorted((r for r in rows if not r.get("pass")), key=lambda r: (r["name"], r["K"], r["seed"]))
    if fails:
        md += ["", f"## Failed runs ({len(fails)})", ""]
        md += [f"- {r['name']} K{r['K']} s{r['seed']}: " + "; ".join(r.get("fail_reasons") or [])
               + (f" — stderr: `{r['stderr_tail'].splitlines()[-1]}`"
                  if r.get("stderr_tail") and r.get("exit") not in (0, None) else "")
               for r in fails[:50]]
        if len(fails) > 50:
            md.append(f"- … {len(fails) - 50} more in runs.jsonl")
    return "\n".join(md) + "\n"


def write_summary(out):
    text = summary(read_rows(out))
    (Path(out) / "summary.md").write_text(text, encoding="utf-8")
    sys.stdout.write(text)


# ---------------------------------------------------------------- main

def int_list(text):
    return [int(x) for x in text.split(",") if x.strip()]


def main(argv):
    own, extra = (argv[:argv.index("--")], argv[argv.index("--") + 1:]) if "--" in argv else (argv, [])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="Arguments after `--` are passed to `foldfree approx` unchanged.")
    ap.add_argument("inputs", nargs="*", metavar="MESH_OR_FOLDER",
                    help=".obj files or folders of them (default: the set in the module docstring)")
    ap.add_argument("--bin", help="the foldfree binary")
    ap.add_argument("--out", help="output folder (runs/, runs.jsonl, summary.md)")
    ap.add_argument("--jobs", type=int, default=2, help="runs at the same time (default 2)")
    ap.add_argument("--timeout", type=float, default=60, help="wall-clock seconds per run, 0 = none (default 60)")
    ap.add_argument("--k", default="24,60,100", help="comma-separated K values (default 24,60,100)")
    ap.add_argument("--seeds", default="1,2,3", help="comma-separated seeds (default 1,2,3)")
    ap.add_argument("--vsa", default=str(DEFAULT_VSA) if DEFAULT_VSA.exists() else "",
                    help="VSA reference JSON lines ('' = none)")
    ap.add_argument("--peers", default=str(DEFAULT_PEERS) if DEFAULT_PEERS.exists() else "",
                    help="peers.md with the VSA table of the CAD meshes and bunny_npm ('' = none)")
    ap.add_argument("--label", default="", help="free text recorded with every run")
    ap.add_argument("--force", action="store_true", help="rerun runs already in DIR/runs.jsonl")
    ap.add_argument("--summary-only", action="store_true", help="only print the summary of DIR/runs.jsonl")
    opts = ap.parse_args(own)
    if opts.summary_only:
        if not (opts.out and (Path(opts.out) / "runs.jsonl").is_file()):
            ap.error("--summary-only needs --out DIR with a runs.jsonl")
        write_summary(opts.out)
        return 0
    if not (opts.bin and opts.out):
        ap.error("a sweep needs --bin and --out")
    if not os.access(opts.bin, os.X_OK):
        ap.error(f"--bin {opts.bin} is not an executable file")
    ks, seeds = int_list(opts.k), int_list(opts.seeds)
    meshes = collect(opts.inputs or [str(p) for p in DEFAULT_INPUTS])
    done = {run_key(r) for r in read_rows(opts.out)} if not opts.force else set()
    runs = [(name, path, k, s) for name, path in meshes for k in ks for s in seeds
            if (name, k, s, tuple(extra)) not in done]
    skipped = len(meshes) * len(ks) * len(seeds) - len(runs)
    if skipped:
        print(f"approxsweep: {skipped} runs already in {Path(opts.out) / 'runs.jsonl'} (--force reruns them)",
              file=sys.stderr)
    sweep = ApproxSweep(opts, extra, runs, shlex.join(["python3", "benches/approxsweep.py", *argv]))
    pool = concurrent.futures.ThreadPoolExecutor(max_workers=max(1, opts.jobs))
    futures = [pool.submit(sweep.run_one, *r) for r in runs]
    try:
        for fut in concurrent.futures.as_completed(futures):
            if fut.exception():
                e = fut.exception()
                print(f"approxsweep: internal error: {e!r}", file=sys.stderr)
                traceback.print_exception(type(e), e, e.__traceback__, file=sys.stderr)
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not break the cleanup
        print("approxsweep: interrupted, killing the running processes", file=sys.stderr)
        sweep.interrupt()
        pool.shutdown(wait=True, cancel_futures=True)
        write_summary(opts.out)
        return 130
    pool.shutdown()
    write_summary(opts.out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
