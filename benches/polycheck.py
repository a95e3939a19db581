#!/usr/bin/env python3
"""Independent check of a planar-polygon OBJ written by `foldfree approx ... --polygons POLY.obj`.

Usage:
  python3 benches/polycheck.py POLY.obj [--diag D] [--allow-boundary]   # prints one JSON object
  python3 benches/polycheck.py --selftest
As a module: `check(path, diag=None, allow_boundary=False)` returns the same dict.

The file holds one `f` line per planar region (a hole is bridged into its outer loop: the bridge
is walked once in each direction, so its end vertices appear twice in the corner list). Only `v`
and `f` lines are read; corners may be `i`, `i/t`, `i/t/n` or `i//n`, negative indices count back
from the last `v` read so far. Vertices with identical coordinates are merged first, because the
checks are about the geometry, not about how the writer numbered it.

Reported fields (lengths relative to `diag`, the INPUT mesh's bounding-box diagonal; without
--diag, the polygon mesh's own):
  polygons             number of `f` lines
  max_planarity_rel    max over polygons of the largest corner distance to the polygon's plane
                       (Newell normal through the corner centroid), / diag
  watertight           every undirected edge is used exactly twice, once in each direction
                       (directed uses counted over the whole file, so a hole's bridge, walked
                       both ways by one polygon, is fine). With allow_boundary (the input has a
                       boundary): every directed edge at most once, every undirected one at most twice
  open_edges           undirected edges used once
  nonmanifold_edges    undirected edges used more than twice
  misoriented_edges    undirected edges used twice in the same direction
  bad_polygons         fewer than 3 distinct corners, area <= 1e-12 diag^2, outline crossing itself
                       in its plane, ear clipping stuck, or its own triangles overlapping
  triangles            triangles of the ear-clipping triangulations of the good polygons
  degenerate_triangles triangles with area <= 1e-12 diag^2 (left out of the intersection test)
  self_intersections   pairs of triangles of DIFFERENT polygons whose interiors intersect, the sum
                       of: intersections_disjoint (no common vertex), intersections_shared_vertex
                       (one common vertex, yet they overlap beyond it) and overlaps_shared_edge
                       (one common edge, folded flat onto each other)
  duplicate_corners    consecutive equal corners (after merging), dropped before everything else
Tolerance: distances of 1e-9 diag count as zero (touching is not intersecting).
"""
import argparse
import json
import math
import os
import sys
import tempfile
from collections import Counter

TOL_REL = 1e-9        # lengths below TOL_REL * diag count as zero
AREA_REL = 1e-12      # areas below AREA_REL * diag^2 count as zero (the corpus' "degenerate")
MAX_CELLS_PER_TRI = 64  # a triangle whose box spans more grid cells is tested against all boxes


# ---------------------------------------------------------------- small vector helpers

def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def norm(a):
    return math.sqrt(dot(a, a))


def orient2(a, b, c):
    """Twice the signed area of the 2D triangle abc (> 0: counter-clockwise)."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def side2(a, b, p):
    """Signed distance of p from the line through a, b (> 0: left of a→b); 0 if a == b."""
    ln = math.hypot(b[0] - a[0], b[1] - a[1])
    return orient2(a, b, p) / ln if ln > 0 else 0.0


def newell(pts):
    """Newell's normal: twice the vector area; exact for planar polygons, holes bridged or not."""
    nx = ny = nz = 0.0
    m = len(pts)
    for i in range(m):
        (x0, y0, z0), (x1, y1, z1) = pts[i], pts[(i + 1) % m]
        nx += (y0 - y1) * (z0 + z1)
        ny += (z0 - z1) * (x0 + x1)
        nz += (x0 - x1) * (y0 + y1)
    return (nx, ny, nz)


def projector(n):
    """2D coordinates dropping n's dominant axis, ordered so that n's side sees them counter-clockwise."""
    ax = max(range(3), key=lambda k: abs(n[k]))
    u, v = [(1, 2), (2, 0), (0, 1)][ax]
    if n[ax] < 0:
        u, v = v, u
    return lambda p: (p[u], p[v])


# ---------------------------------------------------------------- reading

def read_obj(path):
    """(positions, faces as lists of 0-based v ids) of an OBJ, vertices as written."""
    raw, faces = [], []
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                raw.append((float(parts[1]), float(parts[2]), float(parts[3])))
            elif parts[0] == "f":
                face = []
                for c in parts[1:]:
                    i = int(c.split("/")[0])
                    i = i - 1 if i > 0 else len(raw) + i  # OBJ: -1 is the last v read so far
                    if not 0 <= i < len(raw):
                        raise ValueError(f"{path}: face corner {c} refers to a missing v ({len(raw)} read)")
                    face.append(i)
                faces.append(face)
    return raw, faces


def read_polygons(path):
    """(merged positions, polygons as lists of merged vertex ids, number of dropped duplicate corners)."""
    raw, faces = read_obj(path)
    # Merge by exact coordinates (0.0 and -0.0 hash alike): a writer may duplicate a vertex per
    # polygon, and the edge pairing below has to see through that.
    ids, pos, remap = {}, [], []
    for p in raw:
        if p not in ids:
            ids[p] = len(pos)
            pos.append(p)
        remap.append(ids[p])
    polys, dups = [], 0
    for face in faces:
        poly = [remap[i] for i in face]
        clean = [v for k, v in enumerate(poly) if v != poly[k - 1]] if len(poly) > 1 else poly
        if len(clean) > 1 and clean[0] == clean[-1]:
            clean.pop()
        dups += len(poly) - len(clean)
        polys.append(clean)
    return pos, polys, dups


def bbox_diagonal(points):
    if not points:
        return 0.0
    lo = [min(p[k] for p in points) for k in range(3)]
    hi = [max(p[k] for p in points) for k in range(3)]
    return math.sqrt(sum((hi[k] - lo[k]) ** 2 for k in range(3)))


def input_boundary(path):
    """(boundary edge count, bbox diagonal) of a triangle/polygon OBJ, vertices NOT merged
    (the input's own connectivity decides whether it has a boundary)."""
    pos, faces = read_obj(path)
    count = Counter()
    for face in faces:
        for k in range(len(face)):
            a, b = face[k - 1], face[k]
            if a != b:
                count[(a, b) if a < b else (b, a)] += 1
    return sum(1 for m in count.values() if m == 1), bbox_diagonal(pos)


# ---------------------------------------------------------------- per-polygon triangulation

def outline_crosses(q, ids, tol):
    """Whether two edges of the closed 2D outline q cross properly (edges sharing an endpoint
    vertex are skipped: a bridge meets its own end vertices, and collinear overlap is not a crossing)."""
    m = len(q)
    edges = []
    for i in range(m):
        a, b = q[i], q[(i + 1) % m]
        edges.append((ids[i], ids[(i + 1) % m], a, b, min(a[0], b[0]), max(a[0], b[0]),
                      min(a[1], b[1]), max(a[1], b[1])))
    edges.sort(key=lambda e: e[4])
    for i, (p0, p1, a, b, x0, x1, y0, y1) in enumerate(edges):
        for q0, q1, c, d, u0, u1, v0, v1 in edges[i + 1:]:
            if u0 > x1:
                break  # sorted by min x: no later edge reaches back to this one
            if v0 > y1 or v1 < y0 or p0 in (q0, q1) or p1 in (q0, q1):
                continue
            if crosses2(a, b, c, d, tol):
                return True
    return False


def crosses2(a, b, c, d, tol):
    """Segments ab and cd cross at a point interior to both, by more than tol on each side."""
    o1, o2 = side2(a, b, c), side2(a, b, d)
    if not ((o1 > tol and o2 < -tol) or (o1 < -tol and o2 > tol)):
        return False
    o3, o4 = side2(c, d, a), side2(c, d, b)
    return (o3 > tol and o4 < -tol) or (o3 < -tol and o4 > tol)


def ear_clip(q, ids, tol):
    """Triangles (index triples into q) of the counter-clockwise 2D polygon q, or None when stuck.

    Bridged holes repeat vertices; the inside test therefore skips every corner with the same
    vertex id as the ear's corners (mapbox/earcut does the same by coordinates)."""
    idx = list(range(len(q)))
    tris = []
    i = 0
    stall = 0
    while len(idx) > 3:
        m = len(idx)
        i %= m
        a, b, c = idx[i - 1], idx[i], idx[(i + 1) % m]
        pa, pb, pc = q[a], q[b], q[c]
        ac = math.hypot(pc[0] - pa[0], pc[1] - pa[1])
        is_ear = orient2(pa, pb, pc) > tol * max(ac, tol)
        if is_ear:
            ear = (ids[a], ids[b], ids[c])
            x0, x1 = min(pa[0], pb[0], pc[0]), max(pa[0], pb[0], pc[0])
            y0, y1 = min(pa[1], pb[1], pc[1]), max(pa[1], pb[1], pc[1])
            for j in idx:
                p = q[j]
                if ids[j] in ear or p[0] < x0 or p[0] > x1 or p[1] < y0 or p[1] > y1:
                    continue
                # Closed test: a corner on the ear's boundary also blocks it (it would leave a T-junction).
                if side2(pa, pb, p) >= -tol and side2(pb, pc, p) >= -tol and side2(pc, pa, p) >= -tol:
                    is_ear = False
                    break
        if is_ear:
            tris.append((a, b, c))
            del idx[i]
            i = max(i - 1, 0)  # the neighbours may have just become ears
            stall = 0
            continue
        i += 1
        stall += 1
        if stall >= len(idx):
            # No convex ear left: drop one corner that lies on the segment of its neighbours (a
            # straight corner, or a zero-width spike); that removes no area.
            for k in range(len(idx)):
                a, b, c = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
                if abs(side2(q[a], q[c], q[b])) <= tol or ids[a] == ids[c]:
                    del idx[k]
                    break
            else:
                return None
            stall = 0
    tris.append(tuple(idx))
    return tris


def tri_overlap2(A, B, ia, ib, tol):
    """Whether the 2D triangles A and B (vertex ids ia, ib) overlap with positive area: an edge
    crossing, a non-shared vertex strictly inside the other, or a centroid strictly inside (nested)."""
    for i in range(3):
        for j in range(3):
            a, b, c, d = ia[i], ia[(i + 1) % 3], ib[j], ib[(j + 1) % 3]
            if a in (c, d) or b in (c, d):
                continue
            if crosses2(A[i], A[(i + 1) % 3], B[j], B[(j + 1) % 3], tol):
                return True

    def inside(p, T):
        s = [side2(T[k], T[(k + 1) % 3], p) for k in range(3)]
        return all(x > tol for x in s) or all(x < -tol for x in s)

    for P, ip, T in ((B, ib, A), (A, ia, B)):
        other = ia if T is A else ib
        for k in range(3):
            if ip[k] not in other and inside(P[k], T):
                return True
        cen = ((P[0][0] + P[1][0] + P[2][0]) / 3, (P[0][1] + P[1][1] + P[2][1]) / 3)
        if inside(cen, T):
            return True
    return False


# ---------------------------------------------------------------- triangle pairs in 3D

def tri_pair_intersect(A, B, ia, ib, tol):
    """Whether the 3D triangles A, B (vertex ids ia, ib) intersect beyond touching.

    Möller 1997's interval test with a tolerance: each triangle's vertices are snapped onto the
    other's plane within tol, and the two intervals on the planes' common line must overlap by
    more than tol. Touching at a shared vertex gives zero overlap; sharing an edge is only an
    intersection when the two lie flat on each other (coplanar case, 2D test)."""
    shared = len(set(ia) & set(ib))
    if shared == 3:
        return True  # the same triangle in two polygons
    nA = cross(sub(A[1], A[0]), sub(A[2], A[0]))
    nB = cross(sub(B[1], B[0]), sub(B[2], B[0]))
    la, lb = norm(nA), norm(nB)
    if la == 0 or lb == 0:
        return False
    nA = (nA[0] / la, nA[1] / la, nA[2] / la)
    nB = (nB[0] / lb, nB[1] / lb, nB[2] / lb)

    def dists(n, o, T):
        out = []
        for p in T:
            d = dot(n, sub(p, o))
            out.append(0.0 if abs(d) <= tol else d)
        return out

    dB = dists(nA, A[0], B)
    if all(d > 0 for d in dB) or all(d < 0 for d in dB):
        return False
    dA = dists(nB, B[0], A)
    if all(d > 0 for d in dA) or all(d < 0 for d in dA):
        return False
    D = cross(nA, nB)
    ld = norm(D)
    if (all(d == 0 for d in dA) and all(d == 0 for d in dB)) or ld < 1e-12:
        proj = projector(nA)
        return tri_overlap2([proj(p) for p in A], [proj(p) for p in B], ia, ib, tol)
    if shared == 2:
        return False  # two planes through a common edge meet exactly on that edge
    D = (D[0] / ld, D[1] / ld, D[2] / ld)

    def interval(T, d):
        p = [dot(D, v) for v in T]
        ts = [p[k] for k in range(3) if d[k] == 0]
        for k in range(3):
            j = (k + 1) % 3
            if d[k] * d[j] < 0:
                ts.append(p[k] + (p[j] - p[k]) * d[k] / (d[k] - d[j]))
        return min(ts), max(ts)

    a0, a1 = interval(A, dA)
    b0, b1 = interval(B, dB)
    return min(a1, b1) - max(a0, b0) > tol


def count_intersections(pos, tris, owner, tol):
    """(disjoint, shared_vertex, shared_edge) counts of intersecting triangle pairs of different
    polygons; candidate pairs from a uniform grid over the triangles' boxes."""
    n = len(tris)
    if n < 2:
        return 0, 0, 0
    boxes = []
    for t in tris:
        ps = [pos[v] for v in t]
        boxes.append(tuple(min(p[k] for p in ps) - tol for k in range(3))
                     + tuple(max(p[k] for p in ps) + tol for k in range(3)))
    lo = [min(b[k] for b in boxes) for k in range(3)]
    hi = [max(b[k + 3] for b in boxes) for k in range(3)]
    span = max(hi[k] - lo[k] for k in range(3))
    # Cell side: the median box extent (approximation polygons come in very different sizes; the
    # few triangles much larger than that go to `big` instead of flooding the grid), but not so
    # small that the grid gets more than 256 cells along the longest side.
    ext = sorted(max(b[k + 3] - b[k] for k in range(3)) for b in boxes)[n // 2]
    h = max(ext, span / 256.0, 1e-300)
    grid, big = {}, []
    for t, b in enumerate(boxes):
        r = [(int((b[k] - lo[k]) / h), int((b[k + 3] - lo[k]) / h)) for k in range(3)]
        if (r[0][1] - r[0][0] + 1) * (r[1][1] - r[1][0] + 1) * (r[2][1] - r[2][0] + 1) > MAX_CELLS_PER_TRI:
            big.append(t)
            continue
        for i in range(r[0][0], r[0][1] + 1):
            for j in range(r[1][0], r[1][1] + 1):
                for k in range(r[2][0], r[2][1] + 1):
                    grid.setdefault((i, j, k), []).append(t)
    cand = set()
    for cell in grid.values():
        for x, s in enumerate(cell):
            for t in cell[x + 1:]:
                cand.add((s, t) if s < t else (t, s))
    for s in big:
        for t in range(n):
            if t != s:
                cand.add((s, t) if s < t else (t, s))
    counts = [0, 0, 0]
    for s, t in cand:
        if owner[s] == owner[t]:
            continue
        bs, bt = boxes[s], boxes[t]
        if any(bs[k] > bt[k + 3] or bt[k] > bs[k + 3] for k in range(3)):
            continue
        ia, ib = tris[s], tris[t]
        if tri_pair_intersect([pos[v] for v in ia], [pos[v] for v in ib], ia, ib, tol):
            counts[min(len(set(ia) & set(ib)), 2)] += 1
    return tuple(counts)


# ---------------------------------------------------------------- the check

def check(path, diag=None, allow_boundary=False):
    pos, polys, dups = read_polygons(path)
    used = sorted({v for p in polys for v in p})
    if not diag or not diag > 0:
        diag = bbox_diagonal([pos[v] for v in used])
    tol = TOL_REL * diag if diag > 0 else 0.0
    min_area = AREA_REL * diag * diag

    # Edges: directed uses over the whole file.
    directed = Counter()
    for p in polys:
        for k in range(len(p)):
            if p[k - 1] != p[k]:
                directed[(p[k - 1], p[k])] += 1
    open_e = nonman = misor = 0
    for (a, b), m in directed.items():
        if a > b and (b, a) in directed:
            continue  # counted with (b, a)
        r = directed.get((b, a), 0)
        total = m + r
        if total == 1:
            open_e += 1
        elif total > 2:
            nonman += 1
        elif m == 2 or r == 2:
            misor += 1
    if allow_boundary:
        watertight = nonman == 0 and misor == 0
    else:
        watertight = open_e == 0 and nonman == 0 and misor == 0

    max_plan = 0.0
    bad = degenerate = 0
    tris, owner = [], []
    bad_list = []
    for pi, p in enumerate(polys):
        pts = [pos[v] for v in p]
        if len(set(p)) < 3:
            bad += 1
            bad_list.append((pi, "fewer than 3 corners"))
            continue
        n = newell(pts)
        ln = norm(n)
        if ln / 2 <= min_area:
            bad += 1
            bad_list.append((pi, "zero area"))
            continue
        nu = (n[0] / ln, n[1] / ln, n[2] / ln)
        c = tuple(sum(q[k] for q in pts) / len(pts) for k in range(3))
        max_plan = max(max_plan, max(abs(dot(nu, sub(q, c))) for q in pts))
        proj = projector(n)
        q2 = [proj(q) for q in pts]
        if outline_crosses(q2, p, tol):
            bad += 1
            bad_list.append((pi, "outline crosses itself"))
            continue
        local = ear_clip(q2, p, tol)
        if local is None:
            bad += 1
            bad_list.append((pi, "ear clipping stuck"))
            continue
        own = []
        for a, b, cc in local:
            t = (p[a], p[b], p[cc])
            if norm(cross(sub(pos[t[1]], pos[t[0]]), sub(pos[t[2]], pos[t[0]]))) / 2 <= min_area:
                degenerate += 1
                continue
            own.append((t, (q2[a], q2[b], q2[cc])))
        # Ear clipping always ends with triangles summing to the signed area, even for a hole
        # walked the wrong way round (winding 2); only overlapping triangles reveal that.
        if any(tri_overlap2(own[x][1], own[y][1], own[x][0], own[y][0], tol)
               for x in range(len(own)) for y in range(x + 1, len(own))):
            bad += 1
            bad_list.append((pi, "own triangles overlap"))
            continue
        for t, _ in own:
            tris.append(t)
            owner.append(pi)
    disjoint, shared_v, shared_e = count_intersections(pos, tris, owner, tol)
    return {"polygons": len(polys), "diag": diag, "max_planarity_rel": max_plan / diag if diag > 0 else None,
            "watertight": watertight, "allow_boundary": bool(allow_boundary), "open_edges": open_e,
            "nonmanifold_edges": nonman, "misoriented_edges": misor,
            "self_intersections": disjoint + shared_v + shared_e, "intersections_disjoint": disjoint,
            "intersections_shared_vertex": shared_v, "overlaps_shared_edge": shared_e,
            "bad_polygons": bad, "bad_polygon_reasons": [f"f#{i + 1}: {why}" for i, why in bad_list[:10]],
            "triangles": len(tris), "degenerate_triangles": degenerate, "duplicate_corners": dups,
            "vertices": len(used)}


# ---------------------------------------------------------------- self-tests

CUBE_V = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
CUBE_F = [(1, 4, 3, 2), (5, 6, 7, 8), (1, 2, 6, 5), (2, 3, 7, 6), (3, 4, 8, 7), (4, 1, 5, 8)]  # outward


def obj_text(verts, faces):
    return "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in verts) + \
        "".join("f " + " ".join(map(str, f)) + "\n" for f in faces)


def boss_cube():
    """A 4-cube with a 2x2x1 box on top: the top face is a frame whose hole is bridged in, and the
    box's walls close it (watertight only if the bridge is counted as walked both ways)."""
    v = [(0, 0, 0), (4, 0, 0), (4, 4, 0), (0, 4, 0), (0, 0, 4), (4, 0, 4), (4, 4, 4), (0, 4, 4),
         (1, 1, 4), (3, 1, 4), (3, 3, 4), (1, 3, 4), (1, 1, 5), (3, 1, 5), (3, 3, 5), (1, 3, 5)]
    f = [(1, 4, 3, 2), (1, 2, 6, 5), (2, 3, 7, 6), (3, 4, 8, 7), (4, 1, 5, 8),
         (5, 6, 7, 8, 5, 9, 12, 11, 10, 9),                  # top frame: outer CCW, hole CW, bridge 5-9
         (9, 10, 14, 13), (10, 11, 15, 14), (11, 12, 16, 15), (12, 9, 13, 16), (13, 14, 15, 16)]
    return v, f


def selftest():
    cases = []
    pushed = list(CUBE_V)
    pushed[6] = (1.0, 1.0, 1.1)  # off the planes of 3 quads
    shifted = [(x + 0.3, y + 0.45, z + 0.6) for x, y, z in CUBE_V]
    two = CUBE_V + shifted
    bv, bf = boss_cube()
    wrong_hole = list(bf)
    wrong_hole[5] = (5, 6, 7, 8, 5, 9, 10, 11, 12, 9)  # hole walked the same way as the outline
    bowtie = [(1, 4, 2, 3)] + CUBE_F[1:]
    neg = "".join(f"v {x} {y} {z}\n" for x, y, z in CUBE_V) + \
        "".join("f " + " ".join(f"{i - 9}/{i}/{i}" for i in f) + "\n" for f in CUBE_F)
    cases = [
        ("cube", obj_text(CUBE_V, CUBE_F), {}, lambda r: r["watertight"] and r["self_intersections"] == 0
         and r["max_planarity_rel"] == 0 and r["bad_polygons"] == 0 and r["triangles"] == 12),
        ("cube, negative i/t/n indices", neg, {}, lambda r: r["watertight"] and r["triangles"] == 12),
        ("cube, corner pushed off-plane", obj_text(pushed, CUBE_F), {},
         lambda r: r["max_planarity_rel"] > 0.01 and r["watertight"]),
        ("two overlapping cubes", obj_text(two, CUBE_F + [tuple(i + 8 for i in f) for f in CUBE_F]), {},
         lambda r: r["self_intersections"] > 0 and r["intersections_disjoint"] > 0 and r["watertight"]),
        ("cube, one face removed", obj_text(CUBE_V, CUBE_F[1:]), {},
         lambda r: not r["watertight"] and r["open_edges"] == 4 and r["self_intersections"] == 0),
        ("cube, one face removed, --allow-boundary", obj_text(CUBE_V, CUBE_F[1:]), {"allow_boundary": True},
         lambda r: r["watertight"] and r["open_edges"] == 4),
        ("cube, one face reversed", obj_text(CUBE_V, [CUBE_F[0][::-1]] + CUBE_F[1:]), {},
         lambda r: not r["watertight"] and r["misoriented_edges"] == 4),
        ("cube, bow-tie face", obj_text(CUBE_V, bowtie), {},
         lambda r: r["bad_polygons"] == 1 and not r["watertight"]),
        ("cube with a box on top (bridged hole)", obj_text(bv, bf), {},
         lambda r: r["watertight"] and r["self_intersections"] == 0 and r["bad_polygons"] == 0
         and r["max_planarity_rel"] == 0 and r["triangles"] == 10 + 8 + 10),
        ("bridged hole walked the wrong way", obj_text(bv, wrong_hole), {},
         lambda r: r["bad_polygons"] == 1 and not r["watertight"]),
        ("flat fold: one face's copy folded onto another", obj_text(CUBE_V, CUBE_F + [(1, 2, 3)]), {},
         lambda r: r["overlaps_shared_edge"] > 0 and not r["watertight"]),
    ]
    failed = 0
    with tempfile.TemporaryDirectory() as d:
        for name, text, kw, ok in cases:
            p = os.path.join(d, "t.obj")
            with open(p, "w") as f:
                f.write(text)
            r = check(p, **kw)
            good = bool(ok(r))
            failed += not good
            keys = ("watertight", "open_edges", "misoriented_edges", "self_intersections", "bad_polygons",
                    "triangles", "max_planarity_rel")
            print(f"{'ok  ' if good else 'FAIL'} {name}: " + ", ".join(f"{k} {r[k]}" for k in keys))
            if not good:
                print("     " + json.dumps(r))
    print(f"polycheck selftest: {len(cases) - failed}/{len(cases)} passed")
    return 1 if failed else 0


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("obj", nargs="?", help="polygon OBJ written by `foldfree approx --polygons`")
    ap.add_argument("--diag", type=float, help="the input mesh's bounding-box diagonal (default: the polygons')")
    ap.add_argument("--allow-boundary", action="store_true", help="the input mesh has a boundary")
    ap.add_argument("--selftest", action="store_true", help="run the built-in cases and exit")
    opts = ap.parse_args(argv)
    if opts.selftest:
        return selftest()
    if not opts.obj:
        ap.error("give a polygon OBJ or --selftest")
    print(json.dumps(check(opts.obj, opts.diag, opts.allow_boundary)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
