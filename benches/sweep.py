#!/usr/bin/env python3
"""Corpus sweep: run `foldfree param` on many meshes, check every written OBJ, tabulate.

Usage:
  python3 benches/sweep.py --bin PATH_TO_foldfree --out DIR [--jobs 2] [--timeout 600] \\
      [--slim ../shared/meshes/sweep/slim.jsonl] [--label TEXT] MESH_OR_FOLDER... [-- EXTRA_PARAM_ARGS...]
  python3 benches/sweep.py --table DIR        # rebuild DIR/sweep.md from DIR/sweep.jsonl only
  python3 benches/sweep.py --check-obj FILE   # print the independent UV checks of one OBJ as JSON

A folder stands for every `*.obj` directly in it (sorted). Each mesh NAME (the file stem, prefixed
with its parent folder's name when two inputs share a stem) runs as its own process group:
  BIN param MESH -o DIR/out/NAME.obj --report DIR/reports/NAME.json -q EXTRA_PARAM_ARGS...
with stdout+stderr in DIR/logs/NAME.txt, `--jobs` at a time, killed after `--timeout` seconds of wall
clock (0 = none). Each finished run appends one JSON line to DIR/sweep.jsonl at once (an existing
sweep.jsonl is first renamed to sweep-<time>.jsonl), and DIR/sweep.md is written at the end.
Ctrl-C kills the running meshes, writes the table from the runs that finished and exits with 130.

The harness does not trust the report: it re-reads the written OBJ and counts UV triangles with
signed area <= 0 (`check_flips`), non-finite `vt` (`check_uv_nonfinite`) and pairs of UV boundary
edges that cross properly (`check_overlaps`). A run passes iff it exits 0, writes the OBJ, and both
check_flips and check_uv_nonfinite are 0. `--slim` adds the ratio to libigl SLIM's energy on the
same mesh (SD: sd_energy / sd_avg_area of `slim_sd_conv`; MIPS: delta_con_mean / delta_con_avg of
`slim_conformal_conv`) and SLIM's solve time.
"""
import argparse
import concurrent.futures
import datetime
import json
import math
import os
import shlex
import signal
import statistics
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

REPORT_FIELDS = ["faces", "flips", "boundary_self_intersections", "delta_con_mean", "sd_energy",
                 "mips_energy", "iterations", "seconds", "solver", "solver_path", "converged", "energy"]
CHECK_FIELDS = ["check_flips", "check_uv_nonfinite", "check_overlaps"]
SLIM_METHOD = {"sd": ("slim_sd_conv", "sd_energy", "sd_avg_area"),
               "mips": ("slim_conformal_conv", "delta_con_mean", "delta_con_avg")}


# ---------------------------------------------------------------- independent OBJ check

def read_obj_uv(path):
    """The vt list and the faces as vt-index triangles (polygons fan-triangulated).

    A corner without a vt (`f a b c`, `a//n`) uses its vertex index as vt index, the usual
    convention of files with one vt per vertex; an index outside the vt list raises ValueError."""
    uv, tris = [], []
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            tag = parts[0]
            if tag == "vt":
                uv.append((float(parts[1]), float(parts[2]) if len(parts) > 2 else 0.0))
            elif tag == "f":
                t = []
                for c in parts[1:]:
                    s = c.split("/")
                    t.append(int(s[1] if len(s) > 1 and s[1] else s[0]) - 1)
                for k in range(1, len(t) - 1):
                    tris.append((t[0], t[k], t[k + 1]))
    n = len(uv)
    for tri in tris:
        if min(tri) < 0 or max(tri) >= n:
            raise ValueError(f"face {tri[0] + 1}/{tri[1] + 1}/{tri[2] + 1} refers to a missing vt "
                             f"({n} vt; negative indices are not supported)")
    return uv, tris


def check_obj(path):
    uv, tris = read_obj_uv(path)
    finite = [math.isfinite(u) and math.isfinite(v) for u, v in uv]
    flips = 0
    count = {}
    n = len(uv)
    for a, b, c in tris:
        (ua, va), (ub, vb), (uc, vc) = uv[a], uv[b], uv[c]
        # `not > 0` so that a NaN area counts as flipped too.
        if not (ub - ua) * (vc - va) - (uc - ua) * (vb - va) > 0:
            flips += 1
        for p, q in ((a, b), (b, c), (c, a)):
            if p != q:
                key = p * n + q if p < q else q * n + p
                count[key] = count.get(key, 0) + 1
    edges = [divmod(k, n) for k, m in count.items() if m == 1]
    edges = [(p, q) for p, q in edges if finite[p] and finite[q]]
    return {"check_flips": flips, "check_uv_nonfinite": finite.count(False),
            "check_overlaps": count_crossings(uv, edges)}


def count_crossings(uv, edges):
    """Pairs of segments (without a common endpoint index) that cross properly, via a uniform grid."""
    m = len(edges)
    if m < 2:
        return 0
    seg = [(uv[p][0], uv[p][1], uv[q][0], uv[q][1]) for p, q in edges]
    x0 = min(min(s[0], s[2]) for s in seg)
    y0 = min(min(s[1], s[3]) for s in seg)
    w = max(max(s[0], s[2]) for s in seg) - x0
    h_ = max(max(s[1], s[3]) for s in seg) - y0
    # Cell side: the median edge extent, but never so small that the grid has more than ~4 cells per
    # edge over the bounding box (a few very long edges then cannot blow up the cell count).
    ext = sorted(max(abs(s[2] - s[0]), abs(s[3] - s[1])) for s in seg)[m // 2]
    h = max(ext, math.sqrt(w * h_ / (4 * m)), max(w, h_) / 4096.0)
    if not h > 0:
        return 0  # all endpoints coincide: nothing crosses properly
    eps = 1e-9
    grid = {}
    for e, (ax, ay, bx, by) in enumerate(seg):
        i0, i1 = sorted((int((ax - x0) / h), int((bx - x0) / h)))
        j0, j1 = sorted((int((ay - y0) / h), int((by - y0) / h)))
        if (i1 - i0 + 1) * (j1 - j0 + 1) <= 4:
            cols = [(i, j0, j1) for i in range(i0, i1 + 1)]
        else:
            # Long edge: per grid column, only the rows the segment actually passes (plus a margin).
            cols, dx = [], bx - ax
            for i in range(i0, i1 + 1):
                xa = max(min(ax, bx), x0 + i * h) - ax
                xb = min(max(ax, bx), x0 + (i + 1) * h) - ax
                ya, yb = (ay + (by - ay) * xa / dx, ay + (by - ay) * xb / dx) if dx else (ay, by)
                lo, hi = (ya, yb) if ya < yb else (yb, ya)
                cols.append((i, max(j0, int((lo - y0) / h - eps)), min(j1, int((hi - y0) / h + eps))))
        for i, ja, jb in cols:
            for j in range(ja, jb + 1):
                grid.setdefault((i, j), []).append(e)
    found = set()
    for cell in grid.values():
        for k, e in enumerate(cell):
            pa, pb = edges[e]
            ax, ay, bx, by = seg[e]
            for f in cell[k + 1:]:
                qa, qb = edges[f]
                if pa == qa or pa == qb or pb == qa or pb == qb:
                    continue
                cx, cy, dx, dy = seg[f]
                if (max(ax, bx) < min(cx, dx) or max(cx, dx) < min(ax, bx)
                        or max(ay, by) < min(cy, dy) or max(cy, dy) < min(ay, by)):
                    continue
                o1 = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
                o2 = (bx - ax) * (dy - ay) - (by - ay) * (dx - ax)
                if not o1 * o2 < 0:  # strict: touching or collinear does not count
                    continue
                o3 = (dx - cx) * (ay - cy) - (dy - cy) * (ax - cx)
                o4 = (dx - cx) * (by - cy) - (dy - cy) * (bx - cx)
                if o3 * o4 < 0:
                    found.add((e, f) if e < f else (f, e))  # a pair may share several cells
    return len(found)


# ---------------------------------------------------------------- one run

def last_error_line(log):
    try:
        lines = Path(log).read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return None
    return next((ln.strip() for ln in reversed(lines) if "error:" in ln), None)


def energy_of(report, extra):
    if report.get("energy"):
        return report["energy"]
    for k, a in enumerate(extra):
        if a == "--energy" and k + 1 < len(extra):
            return extra[k + 1]
        if a.startswith("--energy="):
            return a.split("=", 1)[1]
    return "mips"


class Sweep:
    def __init__(self, opts, extra, meshes, cmdline):
        self.opts, self.extra, self.meshes = opts, extra, meshes
        self.out = Path(opts.out)
        self.meta = {"label": opts.label, "cmdline": cmdline, "bin": opts.bin,
                     "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")}
        self.slim = {}
        if opts.slim:
            with open(opts.slim) as f:
                for line in f:
                    if line.strip():
                        r = json.loads(line)
                        self.slim[(r["mesh"], r["method"])] = r
        self.lock = threading.Lock()
        self.running, self.killed = {}, set()
        self.stop = threading.Event()
        self.finished = 0
        for sub in ("out", "reports", "logs"):
            (self.out / sub).mkdir(parents=True, exist_ok=True)
        jl = self.out / "sweep.jsonl"
        if jl.exists() and jl.stat().st_size:
            old = self.out / f"sweep-{time.strftime('%Y%m%dT%H%M%S')}.jsonl"
            jl.rename(old)
            print(f"sweep: kept the previous {jl} as {old}", file=sys.stderr)
        self.jsonl = open(jl, "a", encoding="utf-8")

    def interrupt(self):
        with self.lock:
            self.stop.set()
            for pid in self.running:
                self.killed.add(pid)
                kill_group(pid)

    def run_one(self, name, path):
        outp, rep = self.out / "out" / f"{name}.obj", self.out / "reports" / f"{name}.json"
        log = self.out / "logs" / f"{name}.txt"
        for p in (outp, rep):
            p.unlink(missing_ok=True)  # so that "written" means written by this run
        cmd = [self.opts.bin, "param", str(path), "-o", str(outp), "--report", str(rep), "-q", *self.extra]
        t0 = time.monotonic()
        with open(log, "wb") as lf:
            with self.lock:
                if self.stop.is_set():
                    return
                proc = subprocess.Popen(cmd, stdout=lf, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                        start_new_session=True)
                self.running[proc.pid] = proc
            try:
                code, timed_out = proc.wait(timeout=self.opts.timeout or None), False
            except subprocess.TimeoutExpired:
                kill_group(proc.pid)
                proc.wait()
                code, timed_out = None, True
            finally:
                with self.lock:
                    self.running.pop(proc.pid, None)
                    interrupted = proc.pid in self.killed
        if interrupted:
            return  # killed by Ctrl-C: not a finished run
        row = self.row(name, path, code, timed_out, time.monotonic() - t0, outp, rep, log)
        with self.lock:
            self.finished += 1
            self.jsonl.write(json.dumps(row) + "\n")
            self.jsonl.flush()
            status = "timeout" if timed_out else f"exit {code}"
            extra = "" if not row["check_flips"] else f", check_flips {row['check_flips']}"
            print(f"[{self.finished}/{len(self.meshes)}] {name}: {status}, "
                  f"{'written' if row['written'] else 'not written'}{extra}, {row['wall_s']:.1f} s",
                  file=sys.stderr, flush=True)

    def row(self, name, path, code, timed_out, wall, outp, rep, log):
        row = {"mesh": path.name, "name": name, "path": str(path), "label": self.opts.label,
               "args": self.extra, "exit": code, "timeout": timed_out, "wall_s": round(wall, 3),
               "written": outp.exists()}
        try:
            report = json.loads(rep.read_text())
        except (OSError, ValueError):
            report = {}
        row.update({k: report.get(k) for k in REPORT_FIELDS})
        atlas = report.get("atlas") or {}
        charts = atlas.get("charts")
        row["charts"] = len(charts) if isinstance(charts, list) else charts
        row["packing_efficiency"] = atlas.get("packing_efficiency")
        row["error"] = last_error_line(log) if code != 0 else None
        row.update(dict.fromkeys(CHECK_FIELDS))
        if row["written"]:
            try:
                row.update(check_obj(outp))
            except (OSError, ValueError, IndexError) as e:
                row["check_error"] = f"{type(e).__name__}: {e}"
        row["slim_ratio"] = row["slim_time_s"] = row["slim_converged"] = None
        method, ours, theirs = SLIM_METHOD.get(energy_of(report, self.extra), (None, None, None))
        ref = self.slim.get((path.name, method))
        if ref:
            row["slim_time_s"], row["slim_converged"] = ref.get("time_s"), ref.get("converged")
            if row[ours] is not None and ref.get(theirs):
                row["slim_ratio"] = row[ours] / ref[theirs]
        row["pass"] = (code == 0 and row["written"] and row["check_flips"] == 0
                       and row["check_uv_nonfinite"] == 0)
        row.update(self.meta)
        return row


def kill_group(pid):
    try:
        os.killpg(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


# ---------------------------------------------------------------- table

def fmt(x, kind=""):
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if kind == "ratio":
        return f"{x:.4f}"
    if kind == "energy":
        return f"{x:#.4g}"
    if kind == "s":
        return f"{x:.1f}"
    return str(x)


def display(r):
    """The mesh's file name, plus the run's NAME when a shared stem made them differ."""
    name = r.get("name")
    return r["mesh"] + (f" ({name})" if name and name != Path(r["mesh"]).stem else "")


def summary(rows):
    n = len(rows)
    ok = sum(1 for r in rows if r.get("pass"))
    codes = Counter("timeout" if r.get("timeout") else r.get("exit") for r in rows)
    shown = [0, 1, 2, 3, "timeout"]
    other = sum(v for k, v in codes.items() if k not in shown)
    paths = Counter(r.get("solver_path") or "–" for r in rows)
    lines = [f"- runs: {n}, pass: {ok} ({100.0 * ok / n if n else 0:.1f} %)",
             "- exit codes: " + ", ".join(f"{k}: {codes.get(k, 0)}" for k in shown) + f", other: {other}",
             "- solver_path: " + ", ".join(f"`{k}`: {v}" for k, v in sorted(paths.items()))]
    ratios = sorted(((r["slim_ratio"], display(r)) for r in rows
                     if r.get("slim_ratio") is not None and math.isfinite(r["slim_ratio"])), reverse=True)
    if ratios:
        lines.append(f"- ×SLIM energy ratio ({len(ratios)} meshes): median "
                     f"{statistics.median(x for x, _ in ratios):.4f}, worst {ratios[0][0]:.4f}; worst 5: "
                     + ", ".join(f"{m} {x:.4f}" for x, m in ratios[:5]))
    else:
        lines.append("- ×SLIM energy ratio: –")
    # Report `seconds` is the whole run (load + init + solve); SLIM's time_s is its solve only.
    tr = [r["slim_time_s"] / r["seconds"] for r in rows
          if (r.get("slim_time_s") or 0) > 0 and (r.get("seconds") or 0) > 0]
    lines.append("- time ratio SLIM time_s / report seconds (geometric mean, > 1 = faster than SLIM): "
                 + (f"{math.exp(sum(map(math.log, tr)) / len(tr)):.4f} over {len(tr)} meshes" if tr else "–"))
    walls = [r["wall_s"] for r in rows if r.get("wall_s") is not None]
    lines.append(f"- median wall time: {fmt(statistics.median(walls), 's') if walls else '–'} s")
    lines.append(f"- check_flips total: {sum(r.get('check_flips') or 0 for r in rows)}; "
                 f"meshes with check_overlaps > 0: {sum(1 for r in rows if (r.get('check_overlaps') or 0) > 0)}; "
                 f"with non-finite vt: {sum(1 for r in rows if (r.get('check_uv_nonfinite') or 0) > 0)}; "
                 f"report flips ≠ check_flips: "
                 f"{sum(1 for r in rows if r.get('check_flips') is not None and r.get('flips') is not None and r['flips'] != r['check_flips'])}")
    bad = [r for r in rows if r.get("check_error")]
    if bad:
        lines.append("- OBJ check failed on: " + ", ".join(f"{r['mesh']} ({r['check_error']})" for r in bad))
    return lines


COLUMNS = [("mesh", None, ""), ("F", "faces", ""), ("exit", None, ""), ("written", "written", ""),
           ("flips (check)", "check_flips", ""), ("overlaps (check)", "check_overlaps", ""),
           ("δcon", "delta_con_mean", "ratio"), ("SD", "sd_energy", "energy"), ("iterations", "iterations", ""),
           ("s", "seconds", "s"), ("path", "solver_path", ""), ("×SLIM", "slim_ratio", "ratio"),
           ("charts", "charts", ""), ("packing", "packing_efficiency", "ratio")]


def write_table(out, meta=None):
    rows = []
    jl = Path(out) / "sweep.jsonl"
    if jl.exists():
        for line in jl.read_text(encoding="utf-8").splitlines():
            try:
                rows.append(json.loads(line))
            except ValueError:
                pass  # a torn last line
    meta = rows[0] if rows else (meta or {})
    md = [f"# Sweep: {meta.get('label') or '(no label)'}", "",
          f"- command: `{meta.get('cmdline', '–')}`", f"- date: {meta.get('date', '–')}",
          f"- binary: `{meta.get('bin', '–')}`", "", "## Summary", "", *summary(rows), "", "## Runs", "",
          "| " + " | ".join(c for c, _, _ in COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in sorted(rows, key=lambda r: (r["mesh"], r.get("name", ""))):
        cells = []
        for col, key, kind in COLUMNS:
            if col == "mesh":
                cells.append(display(r))
            elif col == "exit":
                cells.append("timeout" if r.get("timeout") else fmt(r.get("exit")))
            else:
                cells.append(fmt(r.get(key), kind))
        md.append("| " + " | ".join(cells) + " |")
    (Path(out) / "sweep.md").write_text("\n".join(md) + "\n", encoding="utf-8")
    return len(rows)


# ---------------------------------------------------------------- main

def collect(inputs):
    """(name, path) per mesh: folders expanded, duplicates dropped, shared stems disambiguated."""
    paths, seen = [], set()
    for inp in map(Path, inputs):
        found = sorted(inp.glob("*.obj")) if inp.is_dir() else [inp]
        if inp.is_dir() and not found:
            print(f"sweep: no *.obj in {inp}", file=sys.stderr)
        for p in found:
            if not p.is_file():
                sys.exit(f"sweep: not a file: {p}")
            if p.resolve() not in seen:
                seen.add(p.resolve())
                paths.append(p)
    stems = Counter(p.stem for p in paths)
    named, used = [], set()
    for p in paths:
        name = p.stem if stems[p.stem] == 1 else f"{p.resolve().parent.name}_{p.stem}"
        base, k = name, 2
        while name in used:
            name, k = f"{base}_{k}", k + 1
        used.add(name)
        named.append((name, p))
    return named


def main(argv):
    own, extra = (argv[:argv.index("--")], argv[argv.index("--") + 1:]) if "--" in argv else (argv, [])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="Arguments after `--` are passed to `foldfree param` unchanged.")
    ap.add_argument("inputs", nargs="*", metavar="MESH_OR_FOLDER", help=".obj files or folders of them")
    ap.add_argument("--bin", help="the foldfree binary")
    ap.add_argument("--out", help="output folder (out/, reports/, logs/, sweep.jsonl, sweep.md)")
    ap.add_argument("--jobs", type=int, default=2, help="meshes run at the same time (default 2)")
    ap.add_argument("--timeout", type=float, default=600, help="wall-clock seconds per mesh, 0 = none (default 600)")
    ap.add_argument("--slim", help="SLIM reference rows (slim.jsonl) for the ×SLIM columns")
    ap.add_argument("--label", default="", help="free text recorded with every run")
    ap.add_argument("--table", metavar="DIR", help="only rebuild DIR/sweep.md from DIR/sweep.jsonl")
    ap.add_argument("--check-obj", metavar="FILE", help="only print the UV checks of FILE as JSON")
    opts = ap.parse_args(own)
    if opts.check_obj:
        print(json.dumps(check_obj(opts.check_obj)))
        return 0
    if opts.table:
        if not (Path(opts.table) / "sweep.jsonl").is_file():
            ap.error(f"no sweep.jsonl in {opts.table}")
        n = write_table(opts.table)
        print(f"sweep: {n} runs → {Path(opts.table) / 'sweep.md'}", file=sys.stderr)
        return 0
    if not (opts.bin and opts.out and opts.inputs):
        ap.error("a sweep needs --bin, --out and at least one mesh or folder")
    if not os.access(opts.bin, os.X_OK):
        ap.error(f"--bin {opts.bin} is not an executable file")
    meshes = collect(opts.inputs)
    sweep = Sweep(opts, extra, meshes, shlex.join(["python3", "benches/sweep.py", *argv]))
    pool = concurrent.futures.ThreadPoolExecutor(max_workers=max(1, opts.jobs))
    futures = [pool.submit(sweep.run_one, name, path) for name, path in meshes]
    try:
        for fut in concurrent.futures.as_completed(futures):
            if fut.exception():
                print(f"sweep: internal error: {fut.exception()!r}", file=sys.stderr)
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not break the cleanup
        print("sweep: interrupted, killing the running meshes", file=sys.stderr)
        sweep.interrupt()
        pool.shutdown(wait=True, cancel_futures=True)
        write_table(opts.out, sweep.meta)
        return 130
    pool.shutdown()
    n = write_table(opts.out, sweep.meta)
    print(f"sweep: {n} runs → {Path(opts.out) / 'sweep.md'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
