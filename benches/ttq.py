#!/usr/bin/env python3
"""Time to quality against libigl SLIM, side by side (BENCHMARKS.md, issue 20).

Usage: python3 benches/ttq.py --bin target/release/foldfree [--energy mips|sd] [--runs N] MESH.obj...

For every mesh, alternately (so both see the same machine state): libigl SLIM to convergence
(benches/slim_peer.py: harmonic start, change of the energy < 1e-6 relative per iteration, or
the iteration count of its converged reference run with `--slim-ref`) and
`foldfree param` with default options on the CPU backend. Repeats `--runs` times and keeps the
median of each. Prints one JSON line per mesh and a markdown table: SLIM precompute + solve
seconds, foldfree init + solve seconds (the report's `seconds_init + seconds_solve`; loading the
OBJ is excluded on both sides), the quality of each (mean δcon for MIPS, SD for SD, scored by the
same metric definitions), the speed-up SLIM / foldfree, and its geometric mean.
Needs `pip install libigl scipy`. Run it on an idle machine: nothing else may run meanwhile.
"""
import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def slim(mesh, energy, max_iters):
    kind = "conformal" if energy == "mips" else "sd"
    out = subprocess.run([sys.executable, os.path.join(HERE, "slim_peer.py"), mesh, kind,
                          str(max_iters)],
                         check=True, capture_output=True, text=True).stdout
    r = json.loads(out.strip().splitlines()[-1])
    quality = r["delta_con_mean"] if energy == "mips" else r["sd"]
    return r["precompute_s"] + r["solve_s"], quality, r["iterations"]


def ours(binary, mesh, energy, tmp):
    out, rep = os.path.join(tmp, "out.obj"), os.path.join(tmp, "r.json")
    p = subprocess.run([binary, "param", mesh, "-o", out, "--report", rep, "--backend", "cpu",
                        "--energy", energy, "-q"], capture_output=True, text=True)
    r = json.load(open(rep))
    quality = r["delta_con_mean"] if energy == "mips" else r["sd_energy"]
    return (r["seconds_init"] + r["seconds_solve"], quality, r["iterations"], p.returncode,
            r.get("solver_path"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", required=True)
    ap.add_argument("--energy", default="mips", choices=["mips", "sd"])
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--slim-ref", help="slim.jsonl: run SLIM for the iterations its converged "
                    "reference run took on the mesh (the same work, timed here side by side)")
    ap.add_argument("--slim-max", type=int, default=5000,
                    help="SLIM iteration cap for meshes without a reference row")
    ap.add_argument("meshes", nargs="+")
    a = ap.parse_args()
    ref = {}
    if a.slim_ref:
        method = "slim_conformal_conv" if a.energy == "mips" else "slim_sd_conv"
        for line in open(a.slim_ref):
            r = json.loads(line)
            if r["method"] == method:
                ref[r["mesh"]] = r["iterations"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for m in a.meshes:
            cap = ref.get(os.path.basename(m), a.slim_max)
            s_runs, o_runs = [], []
            for _ in range(a.runs):
                s_runs.append(slim(m, a.energy, cap))
                o_runs.append(ours(a.bin, m, a.energy, tmp))
            s_t = statistics.median(r[0] for r in s_runs)
            o_t = statistics.median(r[0] for r in o_runs)
            row = {"mesh": os.path.basename(m), "energy": a.energy, "runs": a.runs,
                   "slim_s": round(s_t, 3), "slim_quality": s_runs[-1][1],
                   "slim_iterations": s_runs[-1][2], "foldfree_s": round(o_t, 3),
                   "foldfree_quality": o_runs[-1][1], "foldfree_iterations": o_runs[-1][2],
                   "foldfree_exit": o_runs[-1][3], "solver_path": o_runs[-1][4],
                   "speedup": round(s_t / o_t, 3) if o_t > 0 else None,
                   "quality_ratio": round(o_runs[-1][1] / s_runs[-1][1], 5)}
            print(json.dumps(row), flush=True)
            rows.append(row)
    print(f"\n| mesh | SLIM s | SLIM {a.energy} | foldfree s | foldfree {a.energy} | path | "
          "quality ratio | speed-up |\n|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['mesh']} | {r['slim_s']:.2f} | {r['slim_quality']:.4f} | {r['foldfree_s']:.2f} | "
              f"{r['foldfree_quality']:.4f} | {r['solver_path']} | {r['quality_ratio']:.4f} | "
              f"{r['speedup']:.2f}× |")
    sp = [r["speedup"] for r in rows if r["speedup"]]
    if sp:
        print(f"\ngeometric mean speed-up: {math.exp(sum(map(math.log, sp)) / len(sp)):.3f}×")


if __name__ == "__main__":
    main()
