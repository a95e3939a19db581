#!/usr/bin/env python3
"""foldfree's texel packer against xatlas's brute-force packer, on the same charts.

Reads a sweep's output folder (benches/sweep.py: DIR/out/NAME.obj and DIR/reports/NAME.json of
`foldfree param` atlas runs), takes each written atlas's charts (UV islands of the OBJ), packs
them again with xatlas (pip `xatlas`; `PackOptions(bruteForce=True, padding=P,
resolution=R)`, rotations on, charts passed as a UV mesh), and compares:

- area efficiency (Σ chart UV area / resolution² texture) — foldfree's from the OBJ itself,
  xatlas's from its output UVs (xatlas crops its atlas to the rows it used; its efficiency of
  that cropped atlas is shown too); texel coverage (foldfree: the report; xatlas: its
  utilization of the cropped atlas);
- packing time: foldfree's `atlas.seconds_pack` from the report, xatlas's `generate` wall time
  here (xatlas also rebuilds its charts from the UV mesh inside `generate`, which is counted);
- foldfree's layout checked independently: every UV in [0, 1], no mirrored face, no texel (by
  sampling each triangle 4× per texel) holding two charts or two charts closer than P texels.

  python3 benches/pack_peer.py DIR [--resolution 1024] [--padding 2] [--md OUT.md]

Run it on an idle machine: the xatlas times are measured here, one mesh at a time.
"""
import argparse
import json
import pathlib
import statistics
import sys
import time

import numpy as np
import xatlas


def read_obj(path):
    vt, faces = [], []
    for line in open(path):
        if line.startswith("vt "):
            vt.append([float(x) for x in line.split()[1:3]])
        elif line.startswith("f "):
            faces.append([int(c.split("/")[1]) - 1 for c in line.split()[1:4]])
    return np.array(vt, dtype=np.float64), np.array(faces, dtype=np.int64)


def islands(faces, n):
    parent = list(range(n))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for f in faces:
        a = find(f[0])
        for b in f[1:]:
            b = find(b)
            if a != b:
                parent[b] = a
    roots = np.array([find(f[0]) for f in faces])
    _, label = np.unique(roots, return_inverse=True)
    return label


def signed_areas(uv, faces):
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))


def check_layout(uv, faces, label, n, pad):
    """Problems found in foldfree's layout (empty list: none)."""
    problems = []
    if uv.min() < 0.0 or uv.max() > 1.0:
        problems.append("UV outside [0,1]")
    if (signed_areas(uv, faces) <= 0.0).any():
        problems.append(f"{int((signed_areas(uv, faces) <= 0).sum())} mirrored/degenerate faces")
    owner = np.full(n * n, -1, dtype=np.int64)
    for f, c in zip(faces, label):
        t = uv[f] * n
        span = max(np.linalg.norm(t[0] - t[1]), np.linalg.norm(t[1] - t[2]), np.linalg.norm(t[2] - t[0]))
        steps = max(1, int(np.ceil(span * 4)))
        i, j = np.meshgrid(np.arange(steps + 1), np.arange(steps + 1))
        keep = i + j <= steps
        a, b = i[keep] / steps, j[keep] / steps
        p = (1 - a - b)[:, None] * t[0] + a[:, None] * t[1] + b[:, None] * t[2]
        cells = np.unique(np.clip(np.floor(p).astype(np.int64), 0, n - 1) @ np.array([1, n]))
        clash = owner[cells][(owner[cells] >= 0) & (owner[cells] != c)]
        if clash.size:
            problems.append(f"charts {c} and {clash[0]} share a texel")
            return problems
        owner[cells] = c
    grid = owner.reshape(n, n)
    for dy in range(-pad, pad + 1):
        for dx in range(-pad, pad + 1):
            if dx == 0 and dy == 0:
                continue
            a = grid[max(0, dy):n + min(0, dy), max(0, dx):n + min(0, dx)]
            b = grid[max(0, -dy):n + min(0, -dy), max(0, -dx):n + min(0, -dx)]
            bad = (a >= 0) & (b >= 0) & (a != b)
            if bad.any():
                problems.append(f"two charts closer than {pad} texels")
                return problems
    return problems


def xatlas_pack(uv, faces, resolution, padding):
    atlas = xatlas.Atlas()
    atlas.add_uv_mesh(uv.astype(np.float32), faces.astype(np.uint32))
    po = xatlas.PackOptions()
    po.bruteForce = True
    po.padding = padding
    po.resolution = resolution
    t = time.perf_counter()
    atlas.generate(xatlas.ChartOptions(), po)
    seconds = time.perf_counter() - t
    _, idx, out = atlas.get_mesh(0)
    out = out.astype(np.float64)
    # xatlas crops the atlas to the rows (or columns) it used, and may also make it *larger*
    # than the resolution (it does when charts do not fit): its UVs are normalised to its
    # width × height. Compared: the chart area over the texture that holds its layout,
    # max(width, R) × max(height, R) — the R² texture when the layout fits in it.
    cropped = float(np.abs(signed_areas(out, idx.astype(np.int64).reshape(-1, 3))).sum())
    w, h = atlas.width, atlas.height
    full = cropped * w * h / float(max(w, resolution) * max(h, resolution))
    util = atlas.utilization
    util = float(util if isinstance(util, float) else list(util)[0])
    return full, cropped, util, seconds, atlas.atlas_count, atlas.chart_count, (w, h)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir", help="a sweep's output folder (out/, reports/)")
    ap.add_argument("--resolution", type=int, default=1024)
    ap.add_argument("--padding", type=int, default=2)
    ap.add_argument("--md", help="write the Markdown table here too")
    args = ap.parse_args()
    root = pathlib.Path(args.dir)
    rows = []
    for rep in sorted((root / "reports").glob("*.json")):
        report = json.loads(rep.read_text())
        atlas = report.get("atlas")
        obj = root / "out" / f"{rep.stem}.obj"
        if not atlas or not obj.exists():
            continue
        uv, faces = read_obj(obj)
        label = islands(faces, len(uv))
        ours_eff = float(np.abs(signed_areas(uv, faces)).sum())
        problems = check_layout(uv, faces, label, args.resolution, args.padding)
        x_eff, x_crop, x_util, x_s, pages, x_charts, x_size = xatlas_pack(
            uv, faces, args.resolution, args.padding)
        rows.append(dict(mesh=rep.stem, charts=int(label.max()) + 1, ours=ours_eff,
                         ours_cov=atlas.get("texel_coverage"), ours_s=atlas.get("seconds_pack"),
                         xatlas=x_eff, xatlas_cropped=x_crop, xatlas_util=x_util, xatlas_s=x_s, pages=pages,
                         xatlas_charts=x_charts, xatlas_size=x_size, problems=problems))
        r = rows[-1]
        print(f"{r['mesh']}: {r['charts']} charts, ours {r['ours']:.3f} ({r['ours_s']:.3f} s), "
              f"xatlas {r['xatlas']:.3f} ({r['xatlas_s']:.3f} s){' ' + '; '.join(problems) if problems else ''}",
              file=sys.stderr)
    if not rows:
        sys.exit("pack_peer: no atlas reports in " + str(root))
    lines = [f"| mesh | charts | foldfree efficiency | texel coverage | pack s | xatlas charts | xatlas atlas | xatlas efficiency | xatlas efficiency (its cropped atlas) | xatlas utilization (cropped) | xatlas s | check |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['mesh']} | {r['charts']} | {r['ours']:.3f} | {r['ours_cov']:.3f} | {r['ours_s']:.3f} | "
                     f"{r['xatlas_charts']} | {r['xatlas_size'][0]}×{r['xatlas_size'][1]}{' (> R)' if max(r['xatlas_size']) > args.resolution else ''} | "
                     f"{r['xatlas']:.3f} | {r['xatlas_cropped']:.3f} | {r['xatlas_util']:.3f} | {r['xatlas_s']:.3f} | "
                     f"{'; '.join(r['problems']) or 'ok'} |")
    ge = sum(r["ours"] >= r["xatlas"] for r in rows)
    faster = sum(r["ours_s"] <= r["xatlas_s"] for r in rows)
    ratio = [r["ours"] / r["xatlas"] for r in rows if r["xatlas"] > 0]
    lines += ["",
              f"- meshes: {len(rows)}; foldfree efficiency ≥ xatlas on {ge} ({100 * ge / len(rows):.0f} %); "
              f"median efficiency foldfree {statistics.median(r['ours'] for r in rows):.3f}, "
              f"xatlas {statistics.median(r['xatlas'] for r in rows):.3f}; "
              f"ratio foldfree/xatlas median {statistics.median(ratio):.3f}, worst {min(ratio):.3f}",
              f"- packing time: foldfree ≤ xatlas on {faster}; median foldfree {statistics.median(r['ours_s'] for r in rows):.3f} s, "
              f"xatlas {statistics.median(r['xatlas_s'] for r in rows):.3f} s",
              f"- xatlas atlases larger than {args.resolution} on a side: {sum(max(r['xatlas_size']) > args.resolution for r in rows)}; "
              f"xatlas re-charted (chart count differs): {sum(r['xatlas_charts'] != r['charts'] for r in rows)}",
              f"- layout check failures: {sum(bool(r['problems']) for r in rows)}"]
    text = "\n".join(lines)
    print(text)
    if args.md:
        pathlib.Path(args.md).write_text(text + "\n")


if __name__ == "__main__":
    main()
