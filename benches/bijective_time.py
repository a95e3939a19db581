#!/usr/bin/env python3
"""Solve time of the bijective default against the unconstrained solve, interleaved per mesh.

Usage:
  python3 benches/bijective_time.py --bin BIN [--base BASE_BIN] --out FILE.jsonl [--reps 2] \\
      [--timeout 600] MESH_OR_FOLDER... [-- EXTRA_PARAM_ARGS...]

For each mesh (a folder stands for its `*.obj`, sorted), `--reps` rounds of, one after the other:
  BIN param MESH -o T.obj --report T.json -q                                   (bijective, default)
  BIN param MESH ... --no-bijective --tuning T.toml   with [cut] overlap_splits = 0 (unconstrained)
  BASE param MESH ... (both again, when --base is given: a change measured beside its parent)
and the median of each mode's report `seconds_solve` (the solver alone: cutting, packing and I/O
are the same in both modes), `seconds` (the whole run) and the atlas's `seconds_cut`. Interleaving per mesh is what makes the ratio trustworthy on this
box: whole sweeps run minutes apart drift by up to ~25 % per mesh (BENCHMARKS.md, bijective
round 3). One JSON line per mesh goes to FILE as it finishes: seconds, iterations, SD energy and
`boundary_self_intersections` of each mode, and `ratio` (= bijective / unconstrained; `ratio_base`
= BASE's bijective / BASE's unconstrained). The summary (stdout) gives the medians of the ratios and the worst meshes.

The issue-21 acceptance is checked on the way: the first bijective OBJ of each mesh is re-read by
`sweep.py`'s independent check (`check_overlaps`, `check_flips`: crossing pairs of UV boundary
edges and non-positive UV triangles, not the report's counts), the atlas report's
`overlap_splits` (seams added to split an overlapping chart) is kept, and the summary counts the
meshes whose unconstrained map had no crossing and whose bijective energy (the optimised one:
`energy` names it) is more than 0.5 % above it.
"""
import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sweep import check_obj  # noqa: E402  (the corpus harness's independent UV checks)


def collect(inputs):
    out = []
    for i in inputs:
        p = Path(i)
        out.extend(sorted(p.glob("*.obj")) if p.is_dir() else [p])
    return out


def run(binary, mesh, extra, tmp, timeout, check=False):
    obj, rep = Path(tmp) / "o.obj", Path(tmp) / "r.json"
    rep.unlink(missing_ok=True)
    obj.unlink(missing_ok=True)
    cmd = [binary, "param", str(mesh), "-o", str(obj), "--report", str(rep), "-q", *extra]
    try:
        p = subprocess.run(cmd, capture_output=True, timeout=timeout or None)
    except subprocess.TimeoutExpired:
        return None
    if p.returncode != 0 or not rep.exists():
        return None
    r = json.loads(rep.read_text())
    energy = r.get("energy")
    out = {
        "seconds": r.get("seconds_solve"),
        "seconds_total": r.get("seconds"),
        "seconds_cut": (r.get("atlas") or {}).get("seconds_cut"),
        "iterations": r.get("iterations"),
        "sd": r.get("metrics", {}).get("sd_energy", r.get("sd_energy")),
        "crossings": r.get("boundary_self_intersections"),
        "solver_path": r.get("solver_path"),
        "energy": energy,
        "value": r.get("mips_energy" if energy == "mips" else "sd_energy"),
        "overlap_splits": (r.get("atlas") or {}).get("overlap_splits", 0),
    }
    if check:
        out.update(check_obj(obj))
    return out


def main():
    argv = sys.argv[1:]
    extra = []
    if "--" in argv:
        k = argv.index("--")
        argv, extra = argv[:k], argv[k + 1 :]
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", required=True)
    ap.add_argument("--base")
    ap.add_argument("--out", required=True)
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=600)
    ap.add_argument("inputs", nargs="+")
    a = ap.parse_args(argv)
    meshes = collect(a.inputs)
    rows = []
    with tempfile.TemporaryDirectory() as tmp, open(a.out, "w") as out:
        toml = Path(tmp) / "unconstrained.toml"
        toml.write_text("[cut]\noverlap_splits = 0\n")
        unconstrained = [*extra, "--no-bijective", "--tuning", str(toml)]
        modes = [("bijective", a.bin, extra), ("unconstrained", a.bin, unconstrained)]
        if a.base:
            modes += [("base", a.base, extra), ("base_unconstrained", a.base, unconstrained)]
        for i, mesh in enumerate(meshes):
            runs = {m: [] for m, _, _ in modes}
            for rep in range(a.reps):
                for m, binary, args in modes:
                    r = run(binary, mesh, args, tmp, a.timeout, check=rep == 0 and m == "bijective")
                    if r is not None:
                        runs[m].append(r)
            row = {"mesh": mesh.stem, "path": str(mesh)}
            for m in runs:
                if runs[m]:
                    # Times: medians over the rounds; the rest from the first round.
                    row[m] = {
                        **runs[m][0],
                        **{k: statistics.median(r[k] for r in runs[m])
                           for k in ("seconds", "seconds_total", "seconds_cut")
                           if runs[m][0][k] is not None},
                    }
            for m, un, key in (
                ("bijective", "unconstrained", "ratio"),
                ("base", "base_unconstrained", "ratio_base"),
            ):
                s, u = row.get(m, {}).get("seconds"), row.get(un, {}).get("seconds")
                if s is not None and u:
                    row[key] = s / u
            rows.append(row)
            out.write(json.dumps(row) + "\n")
            out.flush()
            print(f"[{i + 1}/{len(meshes)}] {mesh.stem}: ratio {row.get('ratio', float('nan')):.2f}"
                  + (f" (base {row.get('ratio_base', float('nan')):.2f})" if a.base else ""), file=sys.stderr)
    for key in ("ratio", "ratio_base"):
        vals = [r[key] for r in rows if key in r]
        if vals:
            print(f"{key}: median {statistics.median(vals):.3f} over {len(vals)} meshes, "
                  f"max {max(vals):.2f}, above 1.5: {sum(v > 1.5 for v in vals)}")
    tot = {
        m: sum(r[m]["seconds"] for r in rows if m in r)
        for m in ("bijective", "unconstrained", "base", "base_unconstrained")
    }
    print("total seconds_solve: " + ", ".join(f"{m} {s:.2f}" for m, s in tot.items() if s))
    for key in ("seconds_total", "seconds_cut"):
        tot = {m: sum(r[m].get(key) or 0 for r in rows if m in r) for m in ("bijective", "base")}
        print(f"total {key} (report), bijective: " + ", ".join(f"{m} {s:.2f}" for m, s in tot.items() if s))
    bij = [r for r in rows if "bijective" in r]
    print(f"written (bijective): {len(bij)} of {len(rows)}; independent check: "
          f"{sum(r['bijective'].get('check_overlaps', 0) > 0 for r in bij)} with crossings, "
          f"{sum(r['bijective'].get('check_flips', 0) > 0 for r in bij)} with flips; "
          f"overlap splits added on {sum((r['bijective'].get('overlap_splits') or 0) > 0 for r in bij)}")
    clean = [r for r in bij if "unconstrained" in r and r["unconstrained"].get("check_overlaps", r["unconstrained"]["crossings"]) == 0]
    cost = sorted(((r["bijective"]["value"] / r["unconstrained"]["value"] - 1, r["mesh"]) for r in clean), reverse=True)
    if cost:
        print(f"unconstrained map without crossings: {len(clean)}; bijective energy > 0.5 % above it: "
              f"{sum(c > 0.005 for c, _ in cost)}; largest {cost[0][0] * 100:+.3f} % ({cost[0][1]})")
    worst = sorted((r for r in rows if "ratio" in r), key=lambda r: -r["ratio"])[:8]
    for r in worst:
        b, u = r["bijective"], r["unconstrained"]
        print(f"  {r['mesh']}: {r['ratio']:.2f} ({b['seconds']:.3f} s, {b['iterations']} its / "
              f"{u['seconds']:.3f} s, {u['iterations']} its)")


if __name__ == "__main__":
    main()
