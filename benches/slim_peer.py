#!/usr/bin/env python3
"""The libigl SLIM side of BENCHMARKS.md, run on the same machine as `foldfree dev bench`.

Usage: python3 benches/slim_peer.py MESH.obj [sd|conformal] [max_iters]
Needs `pip install libigl scipy`. Start map: Tutte (uniform) on the unit circle, as libigl's
tutorial does; SLIM iterates until the energy changes by < 1e-6 relative (or max_iters),
one `slim_solve(data, 1)` call per iteration so each iteration is timed (the energy for the
stopping rule is computed outside the timed calls). Prints one JSON line:
seconds per iteration, total solve seconds, iterations, and the same metrics foldfree reports
(δcon mean over faces, SD area-weighted after scaling UV area to the 3D area).
"""
import json
import sys
import time

import igl
import numpy as np


def energy_of(v, f, uv, kind):
    """SLIM's objective (area-weighted, unscaled): SD or MIPS; +inf when a face flips."""
    s, det, area = singular_values(v, f, uv)
    if (det <= 0).any():
        return float("inf")
    e = (s ** 2 + s ** -2).sum(1) if kind == "sd" else s[:, 0] / s[:, 1] + s[:, 1] / s[:, 0]
    return float((area * e).sum() / area.sum())


def singular_values(v, f, uv):
    p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    e1, e2 = p1 - p0, p2 - p0
    n = np.cross(e1, e2)
    area = 0.5 * np.linalg.norm(n, axis=1)
    x = e1 / np.linalg.norm(e1, axis=1)[:, None]
    y = np.cross(n / np.linalg.norm(n, axis=1)[:, None], x)
    m = np.stack([np.stack([(e1 * x).sum(1), (e2 * x).sum(1)], 1),
                  np.stack([(e1 * y).sum(1), (e2 * y).sum(1)], 1)], 1)
    u = np.stack([uv[f[:, 1]] - uv[f[:, 0]], uv[f[:, 2]] - uv[f[:, 0]]], 2)
    j = u @ np.linalg.inv(m)
    return np.linalg.svd(j, compute_uv=False), np.linalg.det(j), area


def metrics(v, f, uv):
    s, det, area = singular_values(v, f, uv)
    scale = np.sqrt(area.sum() / (det * area).sum())
    s2 = s * scale
    sd = (area * (s2 ** 2 + s2 ** -2).sum(1)).sum() / area.sum()
    return int((det <= 0).sum()), float((s[:, 0] / s[:, 1]).mean()), float(sd)


def main():
    path = sys.argv[1]
    kind = sys.argv[2] if len(sys.argv) > 2 else "sd"
    max_iters = int(sys.argv[3]) if len(sys.argv) > 3 else 2000
    v, _, _, f, _, _ = igl.readOBJ(path)
    v = np.asarray(v, dtype=np.float64)
    f = np.asarray(f, dtype=np.int32)
    bnd = igl.boundary_loop(f)
    bnd_uv = igl.map_vertices_to_circle(v, bnd)
    uv0 = igl.harmonic(v, f, bnd, bnd_uv, 1)
    energy = (igl.MappingEnergyType.SYMMETRIC_DIRICHLET if kind == "sd"
              else igl.MappingEnergyType.CONFORMAL)
    t0 = time.perf_counter()
    data = igl.slim_precompute(v, f, uv0, energy, np.zeros(0, dtype=np.int32),
                               np.zeros((0, 2)), 0.0)
    t_pre = time.perf_counter() - t0
    prev = None
    its = 0
    t_solve = 0.0
    while its < max_iters:
        t1 = time.perf_counter()
        uv = igl.slim_solve(data, 1)
        t_solve += time.perf_counter() - t1
        its += 1
        e = energy_of(v, f, np.asarray(uv)[:, :2], kind)
        if prev is not None and abs(prev - e) <= 1e-6 * abs(e):
            break
        prev = e
    flips, dcon, sd = metrics(v, f, np.asarray(uv)[:, :2])
    print(json.dumps({"mesh": path.split("/")[-1], "energy": kind, "faces": len(f),
                      "iterations": its, "precompute_s": round(t_pre, 3),
                      "solve_s": round(t_solve, 3), "s_per_iteration": round(t_solve / its, 4),
                      "flips": flips, "delta_con_mean": round(dcon, 4), "sd": round(sd, 4)}))


if __name__ == "__main__":
    main()
