//! Connectivity of a triangle mesh in flat arrays (CSR), built once and shared by every stage.
//!
//! Everything is built in O(F log d) (d = largest vertex degree) by bucketing half-edges by
//! their smaller vertex, so a 250k-face mesh takes a few tens of milliseconds.

use std::path::Path;

use super::{MeshError, TriMesh, NO_FACE};

/// Adjacency, edges, boundary loops and topological invariants of a triangle mesh.
///
/// Indices are `u32` like the faces; `NO_FACE` marks the missing face of a boundary edge.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Topology {
    /// #V, including vertices used by no face (they simply have no faces or neighbours).
    pub n_vertices: usize,
    /// (#V+1) CSR offsets: the faces around vertex `v` are `vf_faces[vf_offsets[v]..vf_offsets[v+1]]`.
    pub vf_offsets: Vec<u32>,
    /// (3·#F) faces incident to each vertex, ascending face index within a vertex.
    pub vf_faces: Vec<u32>,
    /// (#V+1) CSR offsets into `vv_neighbors`.
    pub vv_offsets: Vec<u32>,
    /// (2·#E) vertices sharing an edge with each vertex, ascending within a vertex.
    pub vv_neighbors: Vec<u32>,
    /// (2·#E) the edge to each of those neighbours (`vv_neighbors[i]` is reached by edge
    /// `vv_edges[i]`): graph searches over the edges need no edge lookup per step.
    pub vv_edges: Vec<u32>,
    /// (#E) unique undirected edges `[v0, v1]` with `v0 < v1`, sorted lexicographically, so edge
    /// indices do not depend on face order.
    pub edges: Vec<[u32; 2]>,
    /// (#E) the faces on each edge in ascending face index; the second is `NO_FACE` on the boundary.
    pub edge_faces: Vec<[u32; 2]>,
    /// (#F) edge index of side `k` of face `f`, the side from `f[k]` to `f[(k+1)%3]`.
    pub face_edges: Vec<[u32; 3]>,
    /// (#F) the face across side `k` of face `f` (`NO_FACE` on the boundary): face adjacency
    /// without an edge lookup per step, for floods and scans over faces.
    pub face_faces: Vec<[u32; 3]>,
    /// Edges with two faces, ascending.
    pub interior_edges: Vec<u32>,
    /// Edges with one face, ascending.
    pub boundary_edges: Vec<u32>,
    /// Boundary vertex cycles, each walked in the direction its faces traverse their boundary
    /// edges (counter-clockwise around a disk whose faces are counter-clockwise), starting at the
    /// loop's smallest vertex; longest loop first. On a mesh with a pinched vertex or inconsistent
    /// orientation a "loop" may visit a vertex twice or be an open chain.
    pub boundary_loops: Vec<Vec<u32>>,
    /// Connected components, faces being connected when they share a vertex.
    pub components: usize,
    /// (#F) component of each face, numbered in order of each component's first face.
    pub component_of_face: Vec<u32>,
    /// Vertices used by no face, ascending.
    pub unreferenced: Vec<u32>,
    /// χ = V_referenced − E + F over the whole mesh.
    pub euler_characteristic: i64,
    /// Every interior edge is traversed in opposite directions by its two faces. Without this the
    /// genus formula and the boundary loop directions mean nothing.
    pub consistently_oriented: bool,
    /// Vertices whose faces form more than one fan (pinch points), ascending.
    pub nonmanifold_vertices: Vec<u32>,
}

impl Topology {
    /// Builds the connectivity. Fails on a face index out of range, a repeated vertex in a face,
    /// an edge with more than two faces, or a mesh too large for `u32` offsets; any other input
    /// (pinched vertices, inconsistent orientation, degenerate geometry) is accepted and described
    /// by the fields.
    pub fn build(mesh: &TriMesh, file: &Path) -> Result<Topology, MeshError> {
        let n = mesh.positions.len();
        let nf = mesh.faces.len();
        // CSR offsets hold up to 3·#F; NO_FACE must stay distinct from every face index.
        if n >= u32::MAX as usize || nf >= (u32::MAX / 3) as usize {
            return Err(MeshError::TooLarge {
                file: file.to_path_buf(),
                what: format!("{n} vertices and {nf} faces exceed the 32-bit index range"),
            });
        }
        for (fi, f) in mesh.faces.iter().enumerate() {
            if let Some(&v) = f.iter().find(|&&v| v as usize >= n) {
                return Err(MeshError::IndexOutOfRange {
                    file: file.to_path_buf(),
                    face: fi,
                    index: i64::from(v),
                    count: n,
                });
            }
            if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
                let v = if f[0] == f[1] || f[0] == f[2] {
                    f[0]
                } else {
                    f[1]
                };
                return Err(MeshError::RepeatedVertex {
                    file: file.to_path_buf(),
                    face: fi,
                    vertex: v as usize,
                });
            }
        }

        let (vf_offsets, vf_faces) = vertex_faces(n, &mesh.faces);
        let (edges, edge_faces, face_edges) = build_edges(n, &mesh.faces, file)?;
        let (vv_offsets, vv_neighbors, vv_edges) = vertex_neighbors(n, &edges);

        let mut interior_edges = Vec::new();
        let mut boundary_edges = Vec::new();
        for (e, ef) in edge_faces.iter().enumerate() {
            if ef[1] == NO_FACE {
                boundary_edges.push(e as u32);
            } else {
                interior_edges.push(e as u32);
            }
        }

        let (components, component_of_face) = face_components(n, nf, &vf_offsets, &vf_faces);
        let unreferenced: Vec<u32> = (0..n as u32)
            .filter(|&v| vf_offsets[v as usize] == vf_offsets[v as usize + 1])
            .collect();
        let euler_characteristic = (n - unreferenced.len()) as i64 - edges.len() as i64 + nf as i64;

        let consistently_oriented = interior_edges.iter().all(|&e| {
            let [f0, f1] = edge_faces[e as usize];
            directed_side(mesh, &face_edges, f0, e) != directed_side(mesh, &face_edges, f1, e)
        });

        let face_faces = face_edges
            .iter()
            .enumerate()
            .map(|(f, sides)| {
                sides.map(|e| {
                    let [g0, g1] = edge_faces[e as usize];
                    if g0 as usize == f {
                        g1
                    } else {
                        g0
                    }
                })
            })
            .collect();
        let mut topo = Topology {
            n_vertices: n,
            vf_offsets,
            vf_faces,
            vv_offsets,
            vv_neighbors,
            vv_edges,
            edges,
            edge_faces,
            face_edges,
            face_faces,
            interior_edges,
            boundary_edges,
            boundary_loops: Vec::new(),
            components,
            component_of_face,
            unreferenced,
            euler_characteristic,
            consistently_oriented,
            nonmanifold_vertices: Vec::new(),
        };
        let mut scratch = Vec::new();
        topo.nonmanifold_vertices = (0..n as u32)
            .filter(|&v| topo.fan_count_with(v, &mut scratch) > 1)
            .collect();
        topo.boundary_loops = boundary_loops(mesh, &topo);
        Ok(topo)
    }

    /// Faces around vertex `v`, ascending.
    pub fn vertex_faces(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.vf_faces[self.vf_offsets[v] as usize..self.vf_offsets[v + 1] as usize]
    }

    /// Neighbour vertices of `v`, ascending.
    pub fn neighbors(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.vv_neighbors[self.vv_offsets[v] as usize..self.vv_offsets[v + 1] as usize]
    }

    /// The edges from `v` to its [`Topology::neighbors`], in the same order.
    pub fn neighbor_edges(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.vv_edges[self.vv_offsets[v] as usize..self.vv_offsets[v + 1] as usize]
    }

    /// The edge between `a` and `b`, if they are neighbours (a search in `a`'s sorted list).
    pub fn edge_between(&self, a: u32, b: u32) -> Option<u32> {
        let i = self.neighbors(a).binary_search(&b).ok()?;
        Some(self.neighbor_edges(a)[i])
    }

    /// Number of fans the faces around `v` form (faces joined through shared edges at `v`):
    /// 0 for an unreferenced vertex, 1 for a manifold one.
    pub fn fan_count(&self, v: u32) -> usize {
        self.fan_count_with(v, &mut Vec::new())
    }

    /// The fans of `v`: for each face of [`Topology::vertex_faces`]`(v)`, the position in that
    /// list of the first face of its fan (faces are in one fan when they share an edge at `v`).
    pub fn fans(&self, v: u32) -> Vec<u32> {
        let mut parent = Vec::new();
        self.fan_count_with(v, &mut parent);
        (0..parent.len() as u32)
            .map(|i| find(&mut parent, i))
            .collect()
    }

    /// `fan_count` with a reusable union-find buffer, indexed by position in `vertex_faces(v)`
    /// (left holding the fans: the smallest position is each fan's root).
    fn fan_count_with(&self, v: u32, parent: &mut Vec<u32>) -> usize {
        let faces = self.vertex_faces(v);
        parent.clear();
        parent.extend(0..faces.len() as u32);
        let mut fans = faces.len();
        for (i, &f) in faces.iter().enumerate() {
            for &e in &self.face_edges[f as usize] {
                let [a, b] = self.edges[e as usize];
                if a != v && b != v {
                    continue;
                }
                let [g0, g1] = self.edge_faces[e as usize];
                let other = if g0 == f { g1 } else { g0 };
                if other == NO_FACE {
                    continue;
                }
                // `other` contains v (it shares an edge at v), so it is in the sorted list.
                if let Ok(j) = faces.binary_search(&other) {
                    if union(parent, i as u32, j as u32) {
                        fans -= 1;
                    }
                }
            }
        }
        fans
    }

    /// Genus summed over components, each `(2 − χ_i − b_i) / 2`. `None` when it is not defined
    /// from these counts: pinched vertices, inconsistent orientation (possibly non-orientable),
    /// or a component whose count is negative or odd.
    pub fn genus(&self) -> Option<i64> {
        if !self.consistently_oriented || !self.nonmanifold_vertices.is_empty() {
            return None;
        }
        let c = self.components;
        let mut chi = vec![0i64; c];
        let mut loops = vec![0i64; c];
        for &comp in &self.component_of_face {
            chi[comp as usize] += 1;
        }
        for v in 0..self.n_vertices as u32 {
            if let Some(&f) = self.vertex_faces(v).first() {
                chi[self.component_of_face[f as usize] as usize] += 1;
            }
        }
        for ef in &self.edge_faces {
            chi[self.component_of_face[ef[0] as usize] as usize] -= 1;
        }
        for lp in &self.boundary_loops {
            let first_face = lp.first().and_then(|&v| self.vertex_faces(v).first());
            if let Some(&f) = first_face {
                loops[self.component_of_face[f as usize] as usize] += 1;
            }
        }
        let mut genus = 0;
        for i in 0..c {
            let twice = 2 - chi[i] - loops[i];
            if twice < 0 || twice % 2 != 0 {
                return None;
            }
            genus += twice / 2;
        }
        Some(genus)
    }

    /// One connected component, one boundary loop, genus 0: what a fixed-boundary
    /// parameterization needs.
    pub fn is_disk(&self) -> bool {
        self.components == 1 && self.boundary_loops.len() == 1 && self.genus() == Some(0)
    }

    /// Human-readable topology for error messages, e.g. "closed surface of genus 4".
    pub fn describe(&self) -> String {
        let loops = self.boundary_loops.len();
        let plural = |n: usize, word: &str| {
            if n == 1 {
                format!("{n} {word}")
            } else {
                format!("{n} {word}s")
            }
        };
        if self.components == 0 {
            return "empty mesh (no faces)".to_string();
        }
        if self.components > 1 {
            return format!(
                "{} with {} in total",
                plural(self.components, "component"),
                plural(loops, "boundary loop")
            );
        }
        if !self.nonmanifold_vertices.is_empty() {
            return match self.nonmanifold_vertices.len() {
                1 => "non-manifold surface (1 pinched vertex)".to_string(),
                k => format!("non-manifold surface ({k} pinched vertices)"),
            };
        }
        if !self.consistently_oriented {
            return "surface that is not consistently oriented".to_string();
        }
        match self.genus() {
            None => format!(
                "surface with inconsistent counts (Euler characteristic {}, {})",
                self.euler_characteristic,
                plural(loops, "boundary loop")
            ),
            Some(g) if loops == 0 => format!("closed surface of genus {g}"),
            Some(g) => format!(
                "open surface of genus {g} with {}",
                plural(loops, "boundary loop")
            ),
        }
    }

    /// `Ok` for a disk, otherwise `MeshError::NotDisk` with [`Topology::describe`].
    pub fn require_disk(&self, file: &Path) -> Result<(), MeshError> {
        if self.is_disk() {
            Ok(())
        } else {
            Err(MeshError::NotDisk {
                file: file.to_path_buf(),
                what: self.describe(),
            })
        }
    }
}

/// Vertex → faces CSR: [`corner_incidence`] with corners mapped to their face.
fn vertex_faces(n: usize, faces: &[[u32; 3]]) -> (Vec<u32>, Vec<u32>) {
    let (offsets, mut list) = corner_incidence(n, faces);
    list.iter_mut().for_each(|c| *c /= 3);
    (offsets, list)
}

/// Vertex → corner CSR of cells with `K` vertices (triangles, tets): the corners `K·cell + k`
/// at vertex `v` are `list[offsets[v]..offsets[v + 1]]`, in cell order (count, prefix sum,
/// fill). `n` is the vertex count; every index must be below it.
pub fn corner_incidence<const K: usize>(n: usize, cells: &[[u32; K]]) -> (Vec<u32>, Vec<u32>) {
    let mut offsets = vec![0u32; n + 1];
    for c in cells {
        for &v in c {
            offsets[v as usize + 1] += 1;
        }
    }
    for v in 0..n {
        offsets[v + 1] += offsets[v];
    }
    let mut cursor: Vec<u32> = offsets[..n].to_vec();
    let mut list = vec![0u32; K * cells.len()];
    for (ci, c) in cells.iter().enumerate() {
        for (k, &v) in c.iter().enumerate() {
            list[cursor[v as usize] as usize] = (K * ci + k) as u32;
            cursor[v as usize] += 1;
        }
    }
    (offsets, list)
}

type Edges = (Vec<[u32; 2]>, Vec<[u32; 2]>, Vec<[u32; 3]>);

/// Unique edges from half-edges bucketed by their smaller vertex and sorted by (larger vertex,
/// face) within a bucket: lexicographic edge order with no global sort.
fn build_edges(n: usize, faces: &[[u32; 3]], file: &Path) -> Result<Edges, MeshError> {
    let mut offsets = vec![0u32; n + 1];
    for f in faces {
        for k in 0..3 {
            let lo = f[k].min(f[(k + 1) % 3]);
            offsets[lo as usize + 1] += 1;
        }
    }
    for v in 0..n {
        offsets[v + 1] += offsets[v];
    }
    let mut cursor: Vec<u32> = offsets[..n].to_vec();
    // (larger vertex, face, side)
    let mut half: Vec<(u32, u32, u8)> = vec![(0, 0, 0); 3 * faces.len()];
    for (fi, f) in faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            let lo = a.min(b) as usize;
            half[cursor[lo] as usize] = (a.max(b), fi as u32, k as u8);
            cursor[lo] += 1;
        }
    }

    let mut edges = Vec::with_capacity(3 * faces.len() / 2 + 1);
    let mut edge_faces = Vec::with_capacity(3 * faces.len() / 2 + 1);
    let mut face_edges = vec![[0u32; 3]; faces.len()];
    for lo in 0..n {
        let bucket = &mut half[offsets[lo] as usize..offsets[lo + 1] as usize];
        bucket.sort_unstable();
        let mut i = 0;
        while i < bucket.len() {
            let hi = bucket[i].0;
            let mut j = i + 1;
            while j < bucket.len() && bucket[j].0 == hi {
                j += 1;
            }
            let group = &bucket[i..j];
            if group.len() > 2 {
                return Err(MeshError::NonManifoldEdge {
                    file: file.to_path_buf(),
                    v0: lo,
                    v1: hi as usize,
                    count: group.len(),
                    faces: group.iter().map(|h| h.1 as usize).collect(),
                });
            }
            let e = edges.len() as u32;
            edges.push([lo as u32, hi]);
            edge_faces.push([group[0].1, group.get(1).map_or(NO_FACE, |h| h.1)]);
            for &(_, f, k) in group {
                face_edges[f as usize][k as usize] = e;
            }
            i = j;
        }
    }
    Ok((edges, edge_faces, face_edges))
}

/// Vertex → neighbour CSR from the sorted edge list. Filling in edge order gives each vertex
/// first its smaller neighbours (edges where it is `v1`, ascending `v0`), then its larger ones
/// (edges where it is `v0`, ascending `v1`), so every list comes out sorted.
fn vertex_neighbors(n: usize, edges: &[[u32; 2]]) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
    let mut offsets = vec![0u32; n + 1];
    for &[a, b] in edges {
        offsets[a as usize + 1] += 1;
        offsets[b as usize + 1] += 1;
    }
    for v in 0..n {
        offsets[v + 1] += offsets[v];
    }
    let mut cursor: Vec<u32> = offsets[..n].to_vec();
    let mut list = vec![0u32; 2 * edges.len()];
    let mut via = vec![0u32; 2 * edges.len()];
    for (e, &[a, b]) in edges.iter().enumerate() {
        for (v, w) in [(a, b), (b, a)] {
            let c = &mut cursor[v as usize];
            list[*c as usize] = w;
            via[*c as usize] = e as u32;
            *c += 1;
        }
    }
    (offsets, list, via)
}

/// Union-find root with path halving.
fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let grand = parent[parent[x as usize] as usize];
        parent[x as usize] = grand;
        x = grand;
    }
    x
}

/// Joins the sets of `a` and `b`; true when they were separate.
fn union(parent: &mut [u32], a: u32, b: u32) -> bool {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra == rb {
        return false;
    }
    // Smaller root wins, so roots (and component numbering) are deterministic.
    let (keep, drop) = if ra < rb { (ra, rb) } else { (rb, ra) };
    parent[drop as usize] = keep;
    true
}

/// Components of faces joined through shared vertices, numbered by first face.
fn face_components(n: usize, nf: usize, vf_offsets: &[u32], vf_faces: &[u32]) -> (usize, Vec<u32>) {
    let mut parent: Vec<u32> = (0..nf as u32).collect();
    for v in 0..n {
        let faces = &vf_faces[vf_offsets[v] as usize..vf_offsets[v + 1] as usize];
        if let Some((&first, rest)) = faces.split_first() {
            for &f in rest {
                union(&mut parent, first, f);
            }
        }
    }
    let mut label = vec![u32::MAX; nf];
    let mut comp = vec![0u32; nf];
    let mut count = 0u32;
    for f in 0..nf {
        let r = find(&mut parent, f as u32) as usize;
        if label[r] == u32::MAX {
            label[r] = count;
            count += 1;
        }
        comp[f] = label[r];
    }
    (count as usize, comp)
}

/// The direction `(from, to)` in which face `f` traverses its edge `e`.
fn directed_side(mesh: &TriMesh, face_edges: &[[u32; 3]], f: u32, e: u32) -> (u32, u32) {
    let fv = mesh.faces[f as usize];
    // `e` was assigned to one side of every face listed on it, so some k matches.
    let k = face_edges[f as usize]
        .iter()
        .position(|&x| x == e)
        .unwrap_or(0);
    (fv[k], fv[(k + 1) % 3])
}

/// Walks boundary half-edges (the direction their one face traverses them) into loops.
/// At each vertex the walk continues along any unused outgoing boundary half-edge, so on a
/// manifold consistently oriented mesh each loop is a simple cycle and elsewhere the walk still
/// terminates, using every boundary edge exactly once.
fn boundary_loops(mesh: &TriMesh, topo: &Topology) -> Vec<Vec<u32>> {
    let n = topo.n_vertices;
    let nb = topo.boundary_edges.len();
    // Directed boundary half-edge b: from[b] → to[b], for boundary edge boundary_edges[b].
    let mut from = Vec::with_capacity(nb);
    let mut to = Vec::with_capacity(nb);
    for &e in &topo.boundary_edges {
        let (a, b) = directed_side(mesh, &topo.face_edges, topo.edge_faces[e as usize][0], e);
        from.push(a);
        to.push(b);
    }
    // Outgoing half-edges per vertex (CSR), each list ascending.
    let mut offsets = vec![0u32; n + 1];
    for &a in &from {
        offsets[a as usize + 1] += 1;
    }
    for v in 0..n {
        offsets[v + 1] += offsets[v];
    }
    let mut cursor: Vec<u32> = offsets[..n].to_vec();
    let mut out = vec![0u32; nb];
    for (b, &a) in from.iter().enumerate() {
        out[cursor[a as usize] as usize] = b as u32;
        cursor[a as usize] += 1;
    }
    // Reuse `cursor` as "next possibly unused outgoing half-edge" per vertex.
    cursor.copy_from_slice(&offsets[..n]);
    let mut used = vec![false; nb];
    let mut next_unused = |v: u32, used: &[bool]| -> Option<u32> {
        let v = v as usize;
        while cursor[v] < offsets[v + 1] {
            let b = out[cursor[v] as usize];
            if !used[b as usize] {
                return Some(b);
            }
            cursor[v] += 1;
        }
        None
    };

    let mut loops = Vec::new();
    for seed in 0..nb {
        if used[seed] {
            continue;
        }
        // The smallest unused edge belongs to a loop whose smallest vertex is its v0.
        let smallest = topo.edges[topo.boundary_edges[seed] as usize][0];
        let mut b = next_unused(smallest, &used).unwrap_or(seed as u32);
        let mut lp = Vec::new();
        loop {
            used[b as usize] = true;
            lp.push(from[b as usize]);
            let end = to[b as usize];
            match next_unused(end, &used) {
                Some(nb) => b = nb,
                None => {
                    if lp.first() != Some(&end) {
                        lp.push(end);
                    }
                    break;
                }
            }
        }
        loops.push(lp);
    }
    loops.sort_by_key(|lp| std::cmp::Reverse(lp.len()));
    loops
}

/// The mesh with every pinched vertex split into one vertex per fan (the first fan keeps the
/// vertex, each other fan gets a copy at the same position, appended in order), faces in the
/// same order. A pinch point is where separate sheets of surface touch; a UV map has no reason
/// to keep them together, and after the split every vertex is manifold, so the mesh can be
/// parameterized like any other (the seams of the split are where the sheets touched).
pub fn split_pinched(mesh: &TriMesh, topo: &Topology) -> TriMesh {
    let mut out = mesh.clone();
    for &v in &topo.nonmanifold_vertices {
        let faces = topo.vertex_faces(v);
        let fans = topo.fans(v);
        let mut copy_of_root: Vec<(u32, u32)> = Vec::new();
        for (i, &f) in faces.iter().enumerate() {
            let root = fans[i];
            if root == fans[0] {
                continue;
            }
            let nv = match copy_of_root.iter().find(|(r, _)| *r == root) {
                Some(&(_, nv)) => nv,
                None => {
                    let nv = out.positions.len() as u32;
                    out.positions.push(mesh.positions[v as usize]);
                    copy_of_root.push((root, nv));
                    nv
                }
            };
            for c in &mut out.faces[f as usize] {
                if *c == v {
                    *c = nv;
                }
            }
        }
    }
    out
}
