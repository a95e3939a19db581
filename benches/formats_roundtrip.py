#!/usr/bin/env python3
"""Every OBJ of a folder converted to PLY (ASCII, binary little and big endian), OFF and STL
(ASCII, binary) reads back as the same mesh (issue 22).

Usage: python3 benches/formats_roundtrip.py --bin target/release/foldfree FOLDER_OR_OBJ...

For each OBJ (folders: every `*.obj` below them, recursively) this writes the five conversions
into a temporary folder with its own writers (not foldfree's), runs `foldfree stats` on the OBJ
and on each conversion, and compares the reports line by line except `file:`. PLY and OFF keep
the vertex order and the polygons (the readers fan-triangulate them as the OBJ reader does), with
coordinates written as the shortest decimal that round-trips (ASCII) or as IEEE doubles (binary),
so every line must match, bounding-box diagonal and smallest face area included. STL has no
shared vertices: the reader welds equal positions, so its report must match the OBJ's except for
the vertex count where the OBJ has unreferenced or coincident vertices (reported, not a failure:
STL cannot express them). Prints one line per mesh and format, and a summary; exits 1 on any
mismatch or reader error.
"""
import argparse
import os
import re
import struct
import subprocess
import sys
import tempfile
from pathlib import Path


def read_obj(path):
    verts, polys = [], []
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            p = line.split()
            if not p:
                continue
            if p[0] == "v":
                verts.append(tuple(float(x) for x in p[1:4]))
            elif p[0] == "f":
                idx = []
                for tok in p[1:]:
                    i = int(tok.split("/")[0])
                    idx.append(i - 1 if i > 0 else len(verts) + i)
                polys.append(idx)
    return verts, polys


def fan(polys):
    for p in polys:
        for i in range(1, len(p) - 1):
            yield (p[0], p[i], p[i + 1])


def write_ply_ascii(path, v, polys):
    with open(path, "w") as f:
        f.write(f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty double x\n"
                f"property double y\nproperty double z\nelement face {len(polys)}\n"
                "property list uchar int vertex_indices\nend_header\n")
        for p in v:
            f.write(" ".join(repr(x) for x in p) + "\n")
        for p in polys:
            f.write(f"{len(p)} " + " ".join(map(str, p)) + "\n")


def write_ply_binary(path, v, polys, big):
    e = ">" if big else "<"
    with open(path, "wb") as f:
        fmt = "binary_big_endian" if big else "binary_little_endian"
        f.write((f"ply\nformat {fmt} 1.0\nelement vertex {len(v)}\nproperty double x\n"
                 f"property double y\nproperty double z\nelement face {len(polys)}\n"
                 "property list uchar int vertex_indices\nend_header\n").encode())
        for p in v:
            f.write(struct.pack(e + "ddd", *p))
        for p in polys:
            f.write(struct.pack(e + "B" + "i" * len(p), len(p), *p))


def write_off(path, v, polys):
    with open(path, "w") as f:
        f.write(f"OFF\n{len(v)} {len(polys)} 0\n")
        for p in v:
            f.write(" ".join(repr(x) for x in p) + "\n")
        for p in polys:
            f.write(f"{len(p)} " + " ".join(map(str, p)) + "\n")


def write_stl_ascii(path, v, tris):
    with open(path, "w") as f:
        f.write("solid roundtrip\n")
        for t in tris:
            f.write("facet normal 0 0 0\nouter loop\n")
            for i in t:
                f.write("vertex " + " ".join(repr(x) for x in v[i]) + "\n")
            f.write("endloop\nendfacet\n")
        f.write("endsolid roundtrip\n")


def write_stl_binary(path, v, tris):
    # Binary STL stores f32: only meshes whose coordinates are f32-exact can round-trip.
    with open(path, "wb") as f:
        f.write(b"\0" * 80)
        f.write(struct.pack("<I", len(tris)))
        for t in tris:
            f.write(struct.pack("<3f", 0, 0, 0))
            for i in t:
                f.write(struct.pack("<3f", *v[i]))
            f.write(b"\0\0")


def f32_exact(v):
    return all(struct.unpack("<f", struct.pack("<f", x))[0] == x for p in v for x in p)


def stats(binary, path):
    p = subprocess.run([binary, "stats", str(path)], capture_output=True, text=True, timeout=600)
    lines = [l for l in p.stdout.splitlines() if not l.startswith("file:")]
    return p.returncode, lines, p.stderr.strip()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    ap.add_argument("inputs", nargs="+")
    a = ap.parse_args()
    objs = []
    for i in a.inputs:
        p = Path(i)
        objs += sorted(p.rglob("*.obj")) if p.is_dir() else [p]
    failures, checked, notes = 0, 0, 0
    for obj in objs:
        v, polys = read_obj(obj)
        tris = list(fan(polys))
        used = {i for t in tris for i in t}
        # STL can express this mesh: every vertex used, no two at the same position.
        weldable = len(used) == len(v) and len(set(v)) == len(v)
        rc0, ref, err0 = stats(a.bin, obj)
        with tempfile.TemporaryDirectory() as d:
            d = Path(d)
            conv = {
                "ply-ascii": (d / "m.ply", lambda p: write_ply_ascii(p, v, polys)),
                "ply-le": (d / "le.ply", lambda p: write_ply_binary(p, v, polys, False)),
                "ply-be": (d / "be.ply", lambda p: write_ply_binary(p, v, polys, True)),
                "off": (d / "m.off", lambda p: write_off(p, v, polys)),
                "stl-ascii": (d / "m.stl", lambda p: write_stl_ascii(p, v, tris)),
            }
            if f32_exact(v):
                conv["stl-binary"] = (d / "b.stl", lambda p: write_stl_binary(p, v, tris))
            for name, (path, write) in conv.items():
                write(path)
                rc, got, err = stats(a.bin, path)
                checked += 1
                if rc != rc0 and name.startswith("stl") and not weldable:
                    notes += 1
                    print(f"note {obj.name} {name}: welded STL refused: {err}")
                    continue
                if rc != rc0:
                    failures += 1
                    print(f"FAIL {obj.name} {name}: exit {rc} (OBJ {rc0}) {err or err0}")
                    continue
                if rc != 0:
                    # Both refused: the same reason must be given (the mesh itself is invalid).
                    # The message after the file name must be the same (for STL up to the
                    # numbers: its vertices are numbered in first-appearance order).
                    msg, msg0 = err.split(f"{path}: ", 1)[-1], err0.split(f"{obj}: ", 1)[-1]
                    if name.startswith("stl"):
                        msg, msg0 = re.sub(r"\d+", "#", msg), re.sub(r"\d+", "#", msg0)
                    same = msg == msg0
                    if not same and name.startswith("stl") and not weldable:
                        notes += 1
                    elif not same:
                        failures += 1
                        print(f"FAIL {obj.name} {name}: '{err}' vs OBJ '{err0}'")
                    continue
                diff = [(x, y) for x, y in zip(ref, got) if x != y]
                if name.startswith("stl") and diff and not weldable:
                    notes += 1
                    print(f"note {obj.name} {name}: STL welds the OBJ's coincident or drops its "
                          f"unreferenced vertices ({diff[0][0]} -> {diff[0][1]})")
                    continue
                if diff or len(ref) != len(got):
                    failures += 1
                    print(f"FAIL {obj.name} {name}: {diff[:3]}")
        print(f"{obj}: {len(conv)} formats checked", flush=True)
    print(f"summary: {len(objs)} meshes, {checked} conversions, {failures} mismatches, "
          f"{notes} STL welds or STL-only refusals")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
