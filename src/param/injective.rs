//! The last resort of the atlas against charts whose map overlaps itself: split the chart into
//! pieces whose UV images do not overlap, keeping the map.
//!
//! A flip-free map is locally injective, but a long boundary can still fold over the rest of
//! its chart. The atlas first tries seams across the overlap and re-maps the halves
//! ([`super::atlas`]); when that runs out (no seam separates the overlapping parts, or the
//! split budget is spent) this partition cannot fail: every single triangle of a flip-free map
//! is an injective piece, so greedy growth always ends with a cover. Each piece keeps the
//! chart's UVs, so distortion is unchanged; the cost is seams, and packing keeps the pieces
//! apart.
#![forbid(unsafe_code)]

use std::collections::HashMap;

/// Piece index of every face of a flip-free chart map (`faces` over `uv`, counter-clockwise):
/// pieces are edge-connected, topological disks, and no two faces of one piece overlap in UV
/// (their interiors are disjoint). Pieces are numbered in the order they were grown, each from
/// the lowest-numbered face not yet taken, in breadth-first order over shared edges.
///
/// The disk rule: a face joins a piece across one shared edge only when its third vertex is
/// not already in the piece (otherwise the piece would close around a hole or touch itself at
/// a vertex); across two or three shared edges it fills a notch and the piece stays a disk.
pub fn injective_pieces(uv: &[[f64; 2]], faces: &[[u32; 3]]) -> Vec<u32> {
    let nf = faces.len();
    let tri = |f: usize| faces[f].map(|v| uv[v as usize]);
    // Face neighbours across each edge.
    let mut edge_face: HashMap<(u32, u32), u32> = HashMap::with_capacity(3 * nf);
    let mut nbr = vec![[u32::MAX; 3]; nf];
    for (f, t) in faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if let Some(&g) = edge_face.get(&(b, a)) {
                nbr[f][k] = g;
                let kg = (0..3)
                    .find(|&j| faces[g as usize][j] == b)
                    .expect("the twin edge starts at b");
                nbr[g as usize][kg] = f as u32;
            } else {
                edge_face.insert((a, b), f as u32);
            }
        }
    }
    let grid = Grid::new(uv, faces);
    let mut piece = vec![u32::MAX; nf];
    // Piece that last took each vertex (a vertex can be in several pieces over time).
    let mut vertex_piece = vec![u32::MAX; uv.len()];
    let mut next = 0u32;
    let mut queue = std::collections::VecDeque::new();
    let mut nearby = Vec::new();
    for seed in 0..nf {
        if piece[seed] != u32::MAX {
            continue;
        }
        let p = next;
        next += 1;
        queue.clear();
        queue.push_back(seed as u32);
        while let Some(f) = queue.pop_front() {
            let f = f as usize;
            if piece[f] != u32::MAX {
                continue;
            }
            if f != seed {
                let shared = nbr[f]
                    .iter()
                    .filter(|&&g| g != u32::MAX && piece[g as usize] == p)
                    .count();
                if shared == 0 {
                    continue;
                }
                if shared == 1 {
                    let k = (0..3)
                        .find(|&k| nbr[f][k] != u32::MAX && piece[nbr[f][k] as usize] == p)
                        .expect("one shared edge");
                    let opposite = faces[f][(k + 2) % 3];
                    if vertex_piece[opposite as usize] == p {
                        continue;
                    }
                }
                let t = tri(f);
                grid.faces_near(&t, &mut nearby);
                let overlaps = nearby.iter().any(|&g| {
                    let g = g as usize;
                    piece[g] == p && !nbr[f].contains(&(g as u32)) && overlap(&t, &tri(g))
                });
                if overlaps {
                    continue;
                }
            }
            piece[f] = p;
            for &v in &faces[f] {
                vertex_piece[v as usize] = p;
            }
            for &g in &nbr[f] {
                if g != u32::MAX && piece[g as usize] == u32::MAX {
                    queue.push_back(g);
                }
            }
        }
    }
    merge_pieces(uv, faces, &nbr, &grid, &mut piece, next as usize);
    piece
}

/// Greedy growth leaves fragments: faces a piece passed over (their third vertex was already
/// in it, or they overlapped it) that became pieces of their own once their neighbours were
/// taken. Merges each piece, smallest first, into an edge-adjacent piece (largest first) when
/// the union is still a disk that does not overlap itself, until nothing merges. Two disks
/// glued along their common boundary make a disk exactly when that common part is one arc:
/// shared vertices − shared edges = 1 (the Euler characteristic of a path), with at least one
/// shared edge (a lone shared vertex would pinch).
fn merge_pieces(
    uv: &[[f64; 2]],
    faces: &[[u32; 3]],
    nbr: &[[u32; 3]],
    grid: &Grid,
    piece: &mut [u32],
    n: usize,
) {
    let tri = |f: usize| faces[f].map(|v| uv[v as usize]);
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (f, &p) in piece.iter().enumerate() {
        members[p as usize].push(f as u32);
    }
    // Vertices of the candidate piece, marked with the number of the check.
    let mut stamp = vec![u32::MAX; uv.len()];
    let mut counted = vec![u32::MAX; uv.len()];
    let mut check = 0u32;
    let mut nearby = Vec::new();
    loop {
        let mut order: Vec<usize> = (0..n).filter(|&p| !members[p].is_empty()).collect();
        order.sort_by_key(|&p| (members[p].len(), p));
        let mut merged = false;
        for p in order {
            if members[p].is_empty() {
                continue;
            }
            // Edge-adjacent pieces and the edges shared with each.
            let mut adjacent: HashMap<u32, usize> = HashMap::new();
            for &f in &members[p] {
                for &g in &nbr[f as usize] {
                    if g != u32::MAX && piece[g as usize] != p as u32 {
                        *adjacent.entry(piece[g as usize]).or_default() += 1;
                    }
                }
            }
            let mut candidates: Vec<(u32, usize)> = adjacent.into_iter().collect();
            candidates.sort_by_key(|&(q, _)| (std::cmp::Reverse(members[q as usize].len()), q));
            for (q, shared_edges) in candidates {
                let q = q as usize;
                check += 1;
                for &f in &members[q] {
                    for &v in &faces[f as usize] {
                        stamp[v as usize] = check;
                    }
                }
                let mut shared_vertices = 0usize;
                for &f in &members[p] {
                    for &v in &faces[f as usize] {
                        if stamp[v as usize] == check && counted[v as usize] != check {
                            counted[v as usize] = check;
                            shared_vertices += 1;
                        }
                    }
                }
                if shared_vertices != shared_edges + 1 {
                    continue;
                }
                let overlaps = members[p].iter().any(|&f| {
                    let t = tri(f as usize);
                    grid.faces_near(&t, &mut nearby);
                    nearby.iter().any(|&g| {
                        piece[g as usize] == q as u32
                            && !nbr[f as usize].contains(&g)
                            && overlap(&t, &tri(g as usize))
                    })
                });
                if overlaps {
                    continue;
                }
                let moved = std::mem::take(&mut members[p]);
                for &f in &moved {
                    piece[f as usize] = q as u32;
                }
                members[q].extend(moved);
                merged = true;
                break;
            }
        }
        if !merged {
            break;
        }
    }
    // Renumber the surviving pieces in order of their lowest face.
    let mut new_id = vec![u32::MAX; n];
    let mut next = 0;
    for p in piece.iter_mut() {
        if new_id[*p as usize] == u32::MAX {
            new_id[*p as usize] = next;
            next += 1;
        }
        *p = new_id[*p as usize];
    }
}

/// Whether two counter-clockwise triangles' interiors intersect (separating axis test over
/// the six edge lines). Touching along an edge or at a vertex is not an overlap: a shared
/// vertex gives exactly zero on the edge lines through it, whose side test is `≤ 0`.
fn overlap(t1: &[[f64; 2]; 3], t2: &[[f64; 2]; 3]) -> bool {
    let separates = |t: &[[f64; 2]; 3], o: &[[f64; 2]; 3]| {
        (0..3).any(|k| {
            let (p, q) = (t[k], t[(k + 1) % 3]);
            let d = [q[0] - p[0], q[1] - p[1]];
            o.iter()
                .all(|v| d[0] * (v[1] - p[1]) - d[1] * (v[0] - p[0]) <= 0.0)
        })
    };
    !(separates(t1, t2) || separates(t2, t1))
}

/// Faces bucketed by the cells of a uniform grid their bounding boxes cover (cell side: the
/// mean face's bounding box, so a face covers O(1) cells).
struct Grid {
    min: [f64; 2],
    cell: f64,
    dims: [usize; 2],
    cells: Vec<Vec<u32>>,
}

impl Grid {
    fn new(uv: &[[f64; 2]], faces: &[[u32; 3]]) -> Grid {
        let bbox = |t: &[u32; 3]| {
            let p = t.map(|v| uv[v as usize]);
            [
                p[0][0].min(p[1][0]).min(p[2][0]),
                p[0][1].min(p[1][1]).min(p[2][1]),
                p[0][0].max(p[1][0]).max(p[2][0]),
                p[0][1].max(p[1][1]).max(p[2][1]),
            ]
        };
        let mut min = [f64::INFINITY; 2];
        let mut max = [f64::NEG_INFINITY; 2];
        let mut extent = 0.0;
        for t in faces {
            let b = bbox(t);
            min = [min[0].min(b[0]), min[1].min(b[1])];
            max = [max[0].max(b[2]), max[1].max(b[3])];
            extent += (b[2] - b[0]).max(b[3] - b[1]);
        }
        let span = (max[0] - min[0])
            .max(max[1] - min[1])
            .max(f64::MIN_POSITIVE);
        // At most ~4 cells per face overall, and never more than 4096 per axis.
        let mean = extent / faces.len().max(1) as f64;
        let cell = mean.max(span / 4096.0).max(f64::MIN_POSITIVE);
        let dims = [
            (((max[0] - min[0]) / cell) as usize + 1).min(4097),
            (((max[1] - min[1]) / cell) as usize + 1).min(4097),
        ];
        let mut grid = Grid {
            min,
            cell,
            dims,
            cells: vec![Vec::new(); dims[0] * dims[1]],
        };
        for (f, t) in faces.iter().enumerate() {
            let b = bbox(t);
            let (lo, hi) = (grid.index([b[0], b[1]]), grid.index([b[2], b[3]]));
            for i in lo[0]..=hi[0] {
                for j in lo[1]..=hi[1] {
                    grid.cells[j * dims[0] + i].push(f as u32);
                }
            }
        }
        grid
    }

    fn index(&self, p: [f64; 2]) -> [usize; 2] {
        let i =
            |k: usize| (((p[k] - self.min[k]) / self.cell).max(0.0) as usize).min(self.dims[k] - 1);
        [i(0), i(1)]
    }

    /// Faces whose cells meet the bounding box of `t` (with repeats removed).
    fn faces_near(&self, t: &[[f64; 2]; 3], out: &mut Vec<u32>) {
        out.clear();
        let lo = [
            t[0][0].min(t[1][0]).min(t[2][0]),
            t[0][1].min(t[1][1]).min(t[2][1]),
        ];
        let hi = [
            t[0][0].max(t[1][0]).max(t[2][0]),
            t[0][1].max(t[1][1]).max(t[2][1]),
        ];
        let (lo, hi) = (self.index(lo), self.index(hi));
        for i in lo[0]..=hi[0] {
            for j in lo[1]..=hi[1] {
                out.extend_from_slice(&self.cells[j * self.dims[0] + i]);
            }
        }
        out.sort_unstable();
        out.dedup();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A strip of `n` quads (2n triangles) along a circle arc of `turn` × 2π: with turn > 1 its
    /// end lies over its start.
    fn spiral_strip(n: usize, turn: f64) -> (Vec<[f64; 2]>, Vec<[u32; 3]>) {
        let mut uv = Vec::new();
        for i in 0..=n {
            let a = turn * std::f64::consts::TAU * i as f64 / n as f64;
            for r in [1.0, 1.5] {
                uv.push([r * a.cos(), r * a.sin()]);
            }
        }
        let mut faces = Vec::new();
        for i in 0..n as u32 {
            let (a, b, c, d) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
            faces.push([a, d, c]);
            faces.push([a, b, d]);
        }
        (uv, faces)
    }

    fn area(uv: &[[f64; 2]], t: &[u32; 3]) -> f64 {
        let [a, b, c] = t.map(|v| uv[v as usize]);
        (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
    }

    #[test]
    fn an_injective_map_is_one_piece() {
        let (uv, faces) = spiral_strip(40, 0.9);
        assert!(faces.iter().all(|t| area(&uv, t) > 0.0));
        let p = injective_pieces(&uv, &faces);
        assert!(p.iter().all(|&x| x == 0));
    }

    #[test]
    fn a_strip_wound_over_itself_splits_into_pieces_that_do_not_overlap() {
        let (uv, faces) = spiral_strip(60, 1.7);
        assert!(faces.iter().all(|t| area(&uv, t) > 0.0));
        let p = injective_pieces(&uv, &faces);
        let n = *p.iter().max().expect("faces") + 1;
        assert_eq!(n, 2, "one wind and the rest");
        for f in 0..faces.len() {
            for g in 0..faces.len() {
                if f != g && p[f] == p[g] {
                    let (t1, t2) = (
                        faces[f].map(|v| uv[v as usize]),
                        faces[g].map(|v| uv[v as usize]),
                    );
                    let shares = faces[f].iter().filter(|v| faces[g].contains(v)).count();
                    assert!(
                        shares == 2 || !overlap(&t1, &t2),
                        "faces {f} and {g} overlap"
                    );
                }
            }
        }
    }

    #[test]
    fn touching_is_not_overlapping() {
        let a = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        let shared_edge = [[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let shared_vertex = [[1.0, 0.0], [2.0, 0.0], [1.0, 1.0]];
        let crossing = [[0.2, 0.2], [2.0, 0.2], [0.2, 2.0]];
        assert!(!overlap(&a, &shared_edge));
        assert!(!overlap(&a, &shared_vertex));
        assert!(overlap(&a, &crossing));
        assert!(overlap(&crossing, &a));
    }
}
