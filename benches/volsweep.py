#!/usr/bin/env python3
"""Constraints corpus for `foldfree volmap`: every tet mesh × {ball target, 90° twist, fixed boundary}.

Usage:
  python3 benches/volsweep.py --bin PATH_TO_foldfree --out DIR [--jobs 2] [--timeout 900] \\
      [--cases ball,twist90,fix] [--label TEXT] MESH_OR_FOLDER... [-- EXTRA_VOLMAP_ARGS...]
  python3 benches/volsweep.py --table DIR     # rebuild DIR/volsweep.md from DIR/volsweep.jsonl

A folder stands for every `*.mesh` in it, except `*_init.mesh` files: those are the initial maps of
the rest mesh named `*_rest.mesh` beside them, and give that mesh the `fix` case. Cases:
  ball     volmap REST --target ball --write-constraints C      (boundary onto the unit sphere)
  twist90  dev volmap-constraints REST --twist 90 -o C; volmap REST --constraints C
  fix      volmap REST --init INIT --fix-boundary               (only where an init exists)
each with `-o DIR/out/NAME.CASE.mesh --report DIR/reports/NAME.CASE.json -q EXTRA_VOLMAP_ARGS`, as its
own process group, `--jobs` at a time, killed after `--timeout` s.

The harness does not trust the report: it re-reads the written MEDIT file and counts tets with
det ≤ 0 against the rest mesh's orientation (`check_inverted`), the largest |‖x‖ − 1| over the
boundary vertices (`check_sphere`, ball), and ρ = Σ‖x_v − target_v‖² over the constraints file or
the init's boundary (`check_rho`). A run passes iff it exits 0, writes the map, check_inverted is 0,
check_rho ≤ 1e-6 and (ball) check_sphere ≤ 1e-9. Where the ball target split chords (the report's
`sphere_sliding.splits`), the harness applies those splits to the rest's tets itself and requires
the written tets to be exactly that refinement. A run that exits 2 is `refused` (bad input, e.g.
a ball target for a boundary of genus > 0) and is neither a pass nor a silent failure; every
other outcome fails.
"""
import argparse
import concurrent.futures
import datetime
import json
import math
import shlex
import statistics
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sweep import fmt as sweep_fmt, kill_group, last_error_line  # noqa: E402  (one copy of each)

RHO_MAX, SPHERE_MAX = 1e-6, 1e-9


# ---------------------------------------------------------------- independent MEDIT check

def read_medit(path):
    """(positions, tets 0-based) of a MEDIT `.mesh` (Vertices and Tetrahedra sections only)."""
    toks = Path(path).read_text(encoding="utf-8", errors="replace").split()
    pos, tets, i = [], [], 0
    while i < len(toks):
        t = toks[i]
        if t == "Vertices":
            n = int(toks[i + 1])
            i += 2
            for _ in range(n):
                pos.append(tuple(float(toks[i + k]) for k in range(3)))
                i += 4
        elif t == "Tetrahedra":
            n = int(toks[i + 1])
            i += 2
            for _ in range(n):
                tets.append(tuple(int(toks[i + k]) - 1 for k in range(4)))
                i += 5
        else:
            i += 1
    return pos, tets


def det6(p, t):
    a, b, c, d = (p[v] for v in t)
    u = [b[k] - a[k] for k in range(3)]
    v = [c[k] - a[k] for k in range(3)]
    w = [d[k] - a[k] for k in range(3)]
    return (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
            + u[2] * (v[0] * w[1] - v[1] * w[0]))


def boundary_vertices(tets):
    count = Counter()
    for t in tets:
        for f in ((t[1], t[2], t[3]), (t[0], t[3], t[2]), (t[0], t[1], t[3]), (t[0], t[2], t[1])):
            count[tuple(sorted(f))] += 1
    return sorted({v for f, n in count.items() if n == 1 for v in f})


def read_constraints(path):
    out = []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        s = line.split("#", 1)[0].split()
        if len(s) == 4:
            out.append((int(s[0]), tuple(map(float, s[1:]))))
    return out


def refine(tets, splits):
    """The rest tets after the ball target's chord splits ([m, a, b] in order: every tet on
    edge a–b replaced by its halves, b → m in place and a → m appended), re-done here from
    the report so the written tets are checked against the rest, not against themselves."""
    tets = list(tets)
    for m, a, b in splits:
        for i in range(len(tets)):
            t = tets[i]
            if a in t and b in t:
                tets[i] = tuple(m if v == b else v for v in t)
                tets.append(tuple(m if v == a else v for v in t))
    return tets


def check_map(rest, out, case, constraints=None, init=None, splits=()):
    rp, rt = read_medit(rest)
    xp, xt = read_medit(out)
    rt = refine(rt, splits)
    if len(xp) != len(rp) + len(splits) or xt != rt:
        raise ValueError("the written map does not have the rest mesh's vertices and tets"
                         + (f" (refined by the report's {len(splits)} splits)" if splits else ""))
    row = {"check_inverted": sum(1 for t in rt if not det6(xp, t) > 0.0)}
    if case == "ball":
        row["check_sphere"] = max(abs(math.sqrt(sum(c * c for c in xp[v])) - 1.0)
                                  for v in boundary_vertices(rt))
    if constraints is not None:
        targets = read_constraints(constraints)
    elif init is not None:
        ip, _ = read_medit(init)
        targets = [(v, ip[v]) for v in boundary_vertices(rt)]
    else:
        targets = []
    row["check_rho"] = sum(sum((xp[v][k] - q[k]) ** 2 for k in range(3)) for v, q in targets)
    row["check_constrained"] = len(targets)
    return row


# ---------------------------------------------------------------- runs

class VolSweep:
    def __init__(self, opts, extra, runs, cmdline):
        self.opts, self.extra, self.runs = opts, extra, runs
        self.out = Path(opts.out)
        self.meta = {"label": opts.label, "cmdline": cmdline, "bin": opts.bin,
                     "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")}
        for sub in ("out", "reports", "logs", "constraints"):
            (self.out / sub).mkdir(parents=True, exist_ok=True)
        jl = self.out / "volsweep.jsonl"
        if jl.exists() and jl.stat().st_size:
            jl.rename(self.out / f"volsweep-{time.strftime('%Y%m%dT%H%M%S')}.jsonl")
        self.jsonl = open(jl, "a", encoding="utf-8")
        self.lock = threading.Lock()
        self.finished = 0

    def call(self, cmd, log, timeout):
        with open(log, "ab") as lf:
            lf.write(("$ " + shlex.join(cmd) + "\n").encode())
            lf.flush()
            proc = subprocess.Popen(cmd, stdout=lf, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                    start_new_session=True)
            try:
                return proc.wait(timeout=timeout or None), False
            except subprocess.TimeoutExpired:
                kill_group(proc.pid)
                proc.wait()
                return None, True

    def run_one(self, name, rest, case, init):
        tag = f"{name}.{case}"
        outp, rep = self.out / "out" / f"{tag}.mesh", self.out / "reports" / f"{tag}.json"
        cons, log = self.out / "constraints" / f"{tag}.txt", self.out / "logs" / f"{tag}.txt"
        for p in (outp, rep, cons, log):
            p.unlink(missing_ok=True)
        b = self.opts.bin
        cmd = [b, "volmap", str(rest), "-o", str(outp), "--report", str(rep), "-q"]
        if case == "ball":
            cmd += ["--target", "ball", "--write-constraints", str(cons)]
        elif case == "twist90":
            code, _ = self.call([b, "dev", "volmap-constraints", str(rest), "--twist", "90", "-o", str(cons)], log, 60)
            if code != 0:
                cmd = None
            else:
                cmd += ["--constraints", str(cons)]
        else:
            cmd += ["--init", str(init), "--fix-boundary"]
        t0 = time.monotonic()
        code, timed_out = self.call(cmd + self.extra, log, self.opts.timeout) if cmd else (None, False)
        wall = time.monotonic() - t0
        row = {"mesh": rest.name, "name": name, "case": case, "exit": code, "timeout": timed_out,
               "wall_s": round(wall, 3), "written": outp.exists(), "label": self.opts.label,
               "args": self.extra}
        try:
            report = json.loads(rep.read_text())
        except (OSError, ValueError):
            report = {}
        w = report.get("written") or {}
        row.update({"tets": report.get("tets"), "seconds": report.get("seconds"),
                    "delta_t": w.get("delta_t"), "rho": w.get("rho"), "inverted": w.get("inverted"),
                    "inverted_init": report.get("inverted_init"),
                    "constraints_met": report.get("constraints_met"),
                    "phases": [(p.get("name"), p.get("iterations"), round(p.get("seconds") or 0, 3))
                               for p in report.get("phases") or []]})
        row["splits"] = (report.get("sphere_sliding") or {}).get("splits") or []
        row["n_splits"] = len(row["splits"])
        row["error"] = last_error_line(log) if code != 0 else None
        if row["written"]:
            try:
                row.update(check_map(rest, outp, case,
                                     constraints=cons if case != "fix" and cons.exists() else None,
                                     init=init if case == "fix" else None,
                                     splits=row["splits"]))
            except (OSError, ValueError, IndexError) as e:
                row["check_error"] = f"{type(e).__name__}: {e}"
        row["pass"] = bool(code == 0 and row["written"] and row.get("check_inverted") == 0
                           and (row.get("check_rho") is not None and row["check_rho"] <= RHO_MAX)
                           and (case != "ball" or (row.get("check_sphere") or 1.0) <= SPHERE_MAX))
        row["outcome"] = "pass" if row["pass"] else ("refused" if code == 2 else "fail")
        row.update(self.meta)
        with self.lock:
            self.finished += 1
            self.jsonl.write(json.dumps(row) + "\n")
            self.jsonl.flush()
            print(f"[{self.finished}/{len(self.runs)}] {tag}: {row['outcome']} "
                  f"(exit {'timeout' if timed_out else code}), {wall:.1f} s", file=sys.stderr, flush=True)


# ---------------------------------------------------------------- table

def fmt(x, kind=""):
    """sweep.fmt, plus `e` (3 significant digits, exponent) and `g` (4 significant digits)."""
    if x is not None and kind in ("e", "g"):
        return f"{x:.2e}" if kind == "e" else f"{x:#.4g}"
    return sweep_fmt(x, kind)


def write_table(out):
    rows = []
    jl = Path(out) / "volsweep.jsonl"
    for line in jl.read_text(encoding="utf-8").splitlines() if jl.exists() else []:
        try:
            rows.append(json.loads(line))
        except ValueError:
            pass
    meta = rows[0] if rows else {}
    md = [f"# Volmap sweep: {meta.get('label') or '(no label)'}", "",
          f"- command: `{meta.get('cmdline', '–')}`", f"- date: {meta.get('date', '–')}", "", "## Summary", ""]
    for case in sorted({r["case"] for r in rows}):
        rs = [r for r in rows if r["case"] == case]
        oc = Counter(r["outcome"] for r in rs)
        walls = [r["wall_s"] for r in rs if r["pass"]]
        dts = [r["delta_t"] for r in rs if r["pass"] and r.get("delta_t")]
        md.append(f"- {case}: {len(rs)} runs, pass {oc['pass']}, refused (exit 2) {oc['refused']}, "
                  f"fail {oc['fail']}; passing runs: median wall {fmt(statistics.median(walls), 's') if walls else '–'} s, "
                  f"median δ_t {fmt(statistics.median(dts), 'g') if dts else '–'}"
                  + "".join(f"; FAIL {r['name']} (exit {r['exit']}: {r.get('error') or r.get('check_error') or ''})"
                            for r in rs if r["outcome"] == "fail"))
    cols = [("mesh", "name", ""), ("case", "case", ""), ("tets", "tets", ""), ("exit", "exit", ""),
            ("outcome", "outcome", ""), ("inverted (check)", "check_inverted", ""), ("ρ (check)", "check_rho", "e"),
            ("sphere dev. (check)", "check_sphere", "e"), ("δ_t", "delta_t", "g"), ("init inverted", "inverted_init", ""),
            ("edges split", "n_splits", ""), ("s (report)", "seconds", "s"), ("wall s", "wall_s", "s")]
    md += ["", "## Runs", "", "| " + " | ".join(c for c, _, _ in cols) + " |", "|" + "---|" * len(cols)]
    for r in sorted(rows, key=lambda r: (r["name"], r["case"])):
        md.append("| " + " | ".join(("timeout" if k == "exit" and r.get("timeout") else fmt(r.get(k), kind))
                                    for _, k, kind in cols) + " |")
    fails = [r for r in rows if r["outcome"] != "pass"]
    if fails:
        md += ["", "## Messages of the runs that did not pass", ""]
        md += [f"- {r['name']}.{r['case']}: {r.get('error') or r.get('check_error') or '(none)'}" for r in fails]
    (Path(out) / "volsweep.md").write_text("\n".join(md) + "\n", encoding="utf-8")
    return len(rows)


def collect(inputs, cases):
    runs = []
    for inp in map(Path, inputs):
        files = sorted(inp.glob("*.mesh")) if inp.is_dir() else [inp]
        for p in files:
            if p.name.endswith("_init.mesh"):
                continue
            init = p.with_name(p.name.replace("_rest.mesh", "_init.mesh")) if p.name.endswith("_rest.mesh") else None
            for case in cases:
                if case == "fix" and not (init and init.exists()):
                    continue
                runs.append((p.stem, p, case, init))
    return runs


def main(argv):
    own, extra = (argv[:argv.index("--")], argv[argv.index("--") + 1:]) if "--" in argv else (argv, [])
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="*")
    ap.add_argument("--bin")
    ap.add_argument("--out")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=900)
    ap.add_argument("--cases", default="ball,twist90,fix")
    ap.add_argument("--label", default="")
    ap.add_argument("--table", metavar="DIR")
    opts = ap.parse_args(own)
    if opts.table:
        n = write_table(opts.table)
        print(f"volsweep: {n} runs → {Path(opts.table) / 'volsweep.md'}", file=sys.stderr)
        return 0
    if not (opts.bin and opts.out and opts.inputs):
        ap.error("a sweep needs --bin, --out and at least one mesh or folder")
    cases = [c for c in opts.cases.split(",") if c]
    if any(c not in ("ball", "twist90", "fix") for c in cases):
        ap.error(f"unknown case in --cases {opts.cases}")
    runs = collect(opts.inputs, cases)
    sweep = VolSweep(opts, extra, runs, shlex.join(["python3", "benches/volsweep.py", *argv]))
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, opts.jobs)) as pool:
        for fut in concurrent.futures.as_completed([pool.submit(sweep.run_one, *r) for r in runs]):
            if fut.exception():
                print(f"volsweep: internal error: {fut.exception()!r}", file=sys.stderr)
    n = write_table(opts.out)
    print(f"volsweep: {n} runs → {Path(opts.out) / 'volsweep.md'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
