//! Cutting any manifold, oriented mesh into topological disks (charts) along seams.
//!
//! A fixed-boundary or free-boundary planar map needs a disk. Every connected component is cut
//! by a *cut graph* computed with a tree–cotree decomposition (Eppstein 2003; Erickson &
//! Whittlesey 2005), with each boundary loop closed by a virtual cap face:
//!
//! 1. **Primal tree T** (shortest paths): a multi-source Dijkstra from every boundary vertex (one
//!    region per loop; each loop minus one edge is put in T) or, on a closed component, from one
//!    root; then the regions are joined by the cheapest bridge edges (Kruskal on
//!    `dist(u) + w(uv) + dist(v)`), i.e. the shortest paths between holes.
//! 2. **Dual tree T\*** over faces and caps, using only edges not in T, as a *maximum* spanning
//!    tree of the loop lengths `dist(u) + w(uv) + dist(v)`: the edges left out of both trees
//!    close the 2g shortest generator loops of the handles. Because each loop has exactly one
//!    edge outside T, each cap is a leaf of T\*, so removing the caps leaves T\* spanning the
//!    real faces: cutting every interior edge not in T\* leaves one tree of triangles, a disk.
//! 3. **Pruning**: a seam edge ending at an interior vertex with no other seam edge is zipped
//!    closed (this keeps a disk a disk), until none is left. What remains is the 2g handle loops
//!    and the paths between holes.
//! 4. A closed genus-0 component prunes to nothing; it is cut along the shortest path between
//!    two far-apart vertices (a double sweep of Dijkstra), which makes a sphere a disk.
//!
//! Edge weights are 3D lengths divided by `1 + β·κ̂`, κ̂ being the mean normalised absolute
//! angle defect of the edge's ends: seams prefer to run through curved regions (ridges, tips),
//! where they are less visible and where cutting relieves the most distortion.
//!
//! Vertices are then split into one copy per *wedge* (the faces around a vertex between two
//! consecutive cut or boundary edges), so positions are copied and faces re-indexed; the charts
//! are the connected components of the split mesh, each checked to be a disk.
#![forbid(unsafe_code)]

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::path::Path;

use crate::init::vec3;
use crate::mesh::{MeshError, Topology, TriMesh, NO_FACE};

/// How seams are chosen.
/// The `[cut]` table of a tuning file ([`crate::tuning`]; `curvature_weight` spelt
/// `seam_curvature`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CutOptions {
    /// β: how strongly seams prefer curved regions (0 = shortest seams).
    #[serde(rename = "seam_curvature")]
    pub curvature_weight: f64,
    /// At most this many extra seams, each to the vertex whose conformal start map is shrunk
    /// the most, while that shrink exceeds `stretch_limit`.
    pub extra_seams: usize,
    /// Area ratio (chart-normalised 3D area over UV area around a vertex) above which a vertex
    /// gets an extra seam.
    pub stretch_limit: f64,
    /// At most this many splitting seams across charts whose map's boundary overlaps itself;
    /// a chart that still overlaps after them is cut into pieces that do not, keeping its map
    /// ([`crate::param::injective`]). 0: overlapping charts are kept as they are.
    pub overlap_splits: usize,
}

impl Default for CutOptions {
    fn default() -> Self {
        CutOptions {
            curvature_weight: 1.0,
            extra_seams: 8,
            stretch_limit: 16.0,
            overlap_splits: 16,
        }
    }
}

impl CutOptions {
    /// Checks every setting against its range (usage errors, exit 2 in the CLI; hosts get the
    /// same): each extra or splitting seam costs a map of the charts, so their counts are
    /// capped where more could only turn a long run into a hang; the weights are finite.
    pub fn validate(&self) -> Result<(), crate::OptionError> {
        let w = self.curvature_weight;
        if !(w.is_finite() && (0.0..=1e6).contains(&w)) {
            return crate::OptionError::reject("cut", "seam_curvature", w, "[0, 1e6]");
        }
        if self.extra_seams > 1000 {
            return crate::OptionError::reject("cut", "extra_seams", self.extra_seams, "[0, 1000]");
        }
        let s = self.stretch_limit;
        if !(s.is_finite() && s >= 1.0) {
            return crate::OptionError::reject("cut", "stretch_limit", s, "[1, ∞), finite");
        }
        if self.overlap_splits > 1000 {
            return crate::OptionError::reject(
                "cut",
                "overlap_splits",
                self.overlap_splits,
                "[0, 1000]",
            );
        }
        Ok(())
    }
}

/// A mesh cut open along seams into disk charts.
#[derive(Clone, Debug)]
pub struct CutMesh {
    /// The split mesh: one vertex per wedge, faces in the input's order (face `f` here is face
    /// `f` of the input). Vertices used by no face in the input do not appear.
    pub mesh: TriMesh,
    /// Input vertex of each split vertex.
    pub origin: Vec<u32>,
    /// Interior edges of the input that were cut (indices into the input topology's `edges`).
    pub seam_edges: Vec<u32>,
    /// Total 3D length of the seams.
    pub seam_length: f64,
    /// The charts: faces (input face indices, ascending) of each disk.
    pub charts: Vec<Vec<u32>>,
}

/// Cuts every component of `mesh` into a disk. `topo` must be `Topology::build(mesh)`. Errors
/// name the element when the mesh is not a manifold, oriented surface (the cut is undefined).
pub fn cut_to_disks(
    mesh: &TriMesh,
    topo: &Topology,
    opts: &CutOptions,
    file: &Path,
) -> Result<CutMesh, crate::Error> {
    cut_to_disks_through(mesh, topo, opts, file, &[])
}

/// [`cut_to_disks`], then a seam from the cut (or the boundary) to each vertex of `extra`, in
/// order: the shortest path that meets the existing cut only at its start, so every chart stays
/// a disk. This is how a chart whose map is badly stretched is relieved (Gu, Gortler & Hoppe
/// 2002 cut to the point of worst stretch); vertices already on the cut are skipped.
pub fn cut_to_disks_through(
    mesh: &TriMesh,
    topo: &Topology,
    opts: &CutOptions,
    file: &Path,
    extra: &[u32],
) -> Result<CutMesh, crate::Error> {
    cut_to_disks_split(mesh, topo, opts, file, extra, &[])
}

/// A seam across one chart, from one point of its boundary to another: the chart becomes two
/// disks. Used when a chart's map overlaps itself (local injectivity, 0 flips, does not stop
/// a long boundary from folding over the chart in UV): the two overlapping boundary parts end
/// up in different charts, which packing keeps apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Split {
    /// Input vertices on the chart's boundary (the cut or the mesh boundary).
    pub a: u32,
    pub b: u32,
    /// An input face of the chart to split.
    pub face: u32,
}

/// [`cut_to_disks_through`], then the splitting seams `splits`, in order; a split whose
/// endpoints are not both on its chart's boundary, or that finds no path through the chart's
/// interior, is skipped (the chart stays whole).
pub fn cut_to_disks_split(
    mesh: &TriMesh,
    topo: &Topology,
    opts: &CutOptions,
    file: &Path,
    extra: &[u32],
    splits: &[Split],
) -> Result<CutMesh, crate::Error> {
    let mut base = base_cut(mesh, topo, opts, file, extra)?;
    for sp in splits {
        base.try_split(topo, sp);
    }
    base.finish(mesh, topo, file)
}

/// The cut edges before they are turned into charts, so splitting seams can be tried one by
/// one without recomputing the cut graph (tree–cotree and extra seams) for each.
#[derive(Clone, Debug)]
pub struct BaseCut {
    cut: Vec<bool>,
    weights: Vec<f64>,
}

/// The cut graph of [`cut_to_disks_through`] with its `extra` seams, not yet split apart.
pub fn base_cut(
    mesh: &TriMesh,
    topo: &Topology,
    opts: &CutOptions,
    file: &Path,
    extra: &[u32],
) -> Result<BaseCut, crate::Error> {
    require_cuttable(mesh, topo, file)?;
    let weights = edge_weights(mesh, topo, opts.curvature_weight);
    let mut cut = vec![false; topo.edges.len()];
    if topo.components > 0 {
        let in_tree = primal_tree(mesh, topo, &weights);
        let in_cotree = dual_tree(mesh, topo, &weights, &in_tree);
        for &e in &topo.interior_edges {
            cut[e as usize] = !in_cotree.kept[e as usize];
        }
        prune(topo, &mut cut);
        cut_closed_spheres(mesh, topo, &weights, &mut cut);
    }
    for &target in extra {
        add_seam_to(topo, &weights, &mut cut, target);
    }
    Ok(BaseCut { cut, weights })
}

impl BaseCut {
    /// Adds the splitting seam `sp` when a path exists (see [`Split`]); a seam that is cut is
    /// a chord of its disk chart, so the chart count grows by one exactly when this is true.
    pub fn try_split(&mut self, topo: &Topology, sp: &Split) -> bool {
        add_split_seam(topo, &self.weights, &mut self.cut, sp)
    }

    /// Cuts the interior edge `e` (an index into the topology's `edges`): a seam between two
    /// pieces of a chart ([`crate::param::injective`]), which keeps every chart a disk when the
    /// pieces are disks.
    pub fn cut_edge(&mut self, e: u32) {
        self.cut[e as usize] = true;
    }

    /// Splits the mesh along the cut into charts and checks each is a disk.
    pub fn finish(
        &self,
        mesh: &TriMesh,
        topo: &Topology,
        file: &Path,
    ) -> Result<CutMesh, crate::Error> {
        let cut = &self.cut;
        let seam_edges: Vec<u32> = (0..topo.edges.len() as u32)
            .filter(|&e| cut[e as usize])
            .collect();
        let seam_length = seam_edges
            .iter()
            .map(|&e| edge_length(mesh, topo.edges[e as usize]))
            .sum();
        let (split, origin) = split_vertices(mesh, topo, cut);
        let split_topo = Topology::build(&split, file)?;
        let mut charts = vec![Vec::new(); split_topo.components];
        for (f, &c) in split_topo.component_of_face.iter().enumerate() {
            charts[c as usize].push(f as u32);
        }
        let out = CutMesh {
            mesh: split,
            origin,
            seam_edges,
            seam_length,
            charts,
        };
        for (c, faces) in out.charts.iter().enumerate() {
            let (sub, _) = out.chart_mesh(faces);
            let t = Topology::build(&sub, file)?;
            if !t.is_disk() {
                return Err(crate::linalg::SolveError::Failed {
                    what: format!(
                        "{}: cutting produced chart {c} ({} faces) that is a {}, not a disk",
                        file.display(),
                        faces.len(),
                        t.describe()
                    ),
                }
                .into());
            }
        }
        Ok(out)
    }
}

impl CutMesh {
    /// The sub-mesh of one chart with its own vertex numbering, and for each of its vertices the
    /// split-mesh vertex it is.
    pub fn chart_mesh(&self, faces: &[u32]) -> (TriMesh, Vec<u32>) {
        let mut local = vec![u32::MAX; self.mesh.positions.len()];
        let mut global = Vec::new();
        let mut sub = TriMesh::default();
        for &f in faces {
            let mut tri = [0u32; 3];
            for (k, &v) in self.mesh.faces[f as usize].iter().enumerate() {
                if local[v as usize] == u32::MAX {
                    local[v as usize] = global.len() as u32;
                    global.push(v);
                    sub.positions.push(self.mesh.positions[v as usize]);
                }
                tri[k] = local[v as usize];
            }
            sub.faces.push(tri);
        }
        (sub, global)
    }
}

/// Refuses meshes the cut is not defined on, naming the vertex or edge.
fn require_cuttable(mesh: &TriMesh, topo: &Topology, file: &Path) -> Result<(), MeshError> {
    if mesh.faces.is_empty() {
        return Err(MeshError::Empty {
            file: file.to_path_buf(),
        });
    }
    if let Some(&v) = topo.nonmanifold_vertices.first() {
        return Err(MeshError::NonManifoldVertex {
            file: file.to_path_buf(),
            vertex: v as usize,
            fans: topo.fan_count(v),
        });
    }
    if !topo.consistently_oriented {
        for &e in &topo.interior_edges {
            let [f0, f1] = topo.edge_faces[e as usize];
            let [a, b] = topo.edges[e as usize];
            if traverses(mesh.faces[f0 as usize], a, b) == traverses(mesh.faces[f1 as usize], a, b)
            {
                return Err(MeshError::InconsistentOrientation {
                    file: file.to_path_buf(),
                    f0: f0 as usize,
                    f1: f1 as usize,
                    v0: a as usize,
                    v1: b as usize,
                });
            }
        }
    }
    Ok(())
}

/// Whether face `f` walks the directed edge a → b.
fn traverses(f: [u32; 3], a: u32, b: u32) -> bool {
    (0..3).any(|k| f[k] == a && f[(k + 1) % 3] == b)
}

fn edge_length(mesh: &TriMesh, e: [u32; 2]) -> f64 {
    vec3::norm(vec3::sub(
        mesh.positions[e[0] as usize],
        mesh.positions[e[1] as usize],
    ))
}

/// |angle defect| per vertex (2π − Σθ inside, π − Σθ on the boundary).
fn angle_defects(mesh: &TriMesh, topo: &Topology) -> Vec<f64> {
    let mut sum = vec![0.0f64; mesh.positions.len()];
    for f in &mesh.faces {
        let p = f.map(|v| mesh.positions[v as usize]);
        for k in 0..3 {
            let a = p[k];
            let b = p[(k + 1) % 3];
            let c = p[(k + 2) % 3];
            let (u, w) = (vec3::sub(b, a), vec3::sub(c, a));
            sum[f[k] as usize] += vec3::norm(vec3::cross(u, w)).atan2(vec3::dot(u, w));
        }
    }
    let mut on_boundary = vec![false; mesh.positions.len()];
    for &e in &topo.boundary_edges {
        for v in topo.edges[e as usize] {
            on_boundary[v as usize] = true;
        }
    }
    sum.iter()
        .zip(&on_boundary)
        .enumerate()
        .map(|(v, (&s, &b))| {
            if topo.vertex_faces(v as u32).is_empty() {
                0.0
            } else if b {
                (std::f64::consts::PI - s).abs()
            } else {
                (2.0 * std::f64::consts::PI - s).abs()
            }
        })
        .collect()
}

/// Seam cost per edge: length / (1 + β·κ̂), κ̂ = |defect| over its mean, capped at 10.
fn edge_weights(mesh: &TriMesh, topo: &Topology, beta: f64) -> Vec<f64> {
    let defect = angle_defects(mesh, topo);
    let used = (0..mesh.positions.len())
        .filter(|&v| !topo.vertex_faces(v as u32).is_empty())
        .count()
        .max(1);
    let mean = defect.iter().sum::<f64>() / used as f64;
    let norm = |v: u32| {
        if mean > 0.0 {
            (defect[v as usize] / mean).min(10.0)
        } else {
            0.0
        }
    };
    topo.edges
        .iter()
        .map(|&e| {
            let k = 0.5 * (norm(e[0]) + norm(e[1]));
            // A tiny floor keeps Dijkstra's distances strictly increasing on zero-length edges.
            edge_length(mesh, e) / (1.0 + beta.max(0.0) * k) + 1e-300
        })
        .collect()
}

/// Min-heap entry for Dijkstra.
#[derive(PartialEq)]
struct Item(f64, u32);
impl Eq for Item {}
impl PartialOrd for Item {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Item {
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}

/// Multi-source Dijkstra. Returns (distance, parent edge, source region) per vertex.
fn dijkstra(
    topo: &Topology,
    weights: &[f64],
    sources: &[(u32, u32)],
) -> (Vec<f64>, Vec<u32>, Vec<u32>) {
    let n = topo.n_vertices;
    let mut dist = vec![f64::INFINITY; n];
    let mut parent = vec![u32::MAX; n];
    let mut region = vec![u32::MAX; n];
    let mut heap = BinaryHeap::new();
    for &(v, r) in sources {
        dist[v as usize] = 0.0;
        region[v as usize] = r;
        heap.push(Item(0.0, v));
    }
    while let Some(Item(d, v)) = heap.pop() {
        if d > dist[v as usize] {
            continue;
        }
        for (&w, &e) in topo.neighbors(v).iter().zip(topo.neighbor_edges(v)) {
            let nd = d + weights[e as usize];
            if nd < dist[w as usize] {
                dist[w as usize] = nd;
                parent[w as usize] = e;
                region[w as usize] = region[v as usize];
                heap.push(Item(nd, w));
            }
        }
    }
    (dist, parent, region)
}

struct UnionFind(Vec<u32>);
impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind((0..n as u32).collect())
    }
    fn find(&mut self, mut x: u32) -> u32 {
        while self.0[x as usize] != x {
            let p = self.0[self.0[x as usize] as usize];
            self.0[x as usize] = p;
            x = p;
        }
        x
    }
    fn union(&mut self, a: u32, b: u32) -> bool {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return false;
        }
        // Smaller root wins: deterministic whatever the merge order.
        let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
        self.0[hi as usize] = lo;
        true
    }
}

/// The primal tree and the distances its loops are measured with.
struct PrimalTree {
    in_tree: Vec<bool>,
    dist: Vec<f64>,
}

fn primal_tree(mesh: &TriMesh, topo: &Topology, weights: &[f64]) -> PrimalTree {
    let mut in_tree = vec![false; topo.edges.len()];
    let mut sources = Vec::new();
    let mut has_boundary = vec![false; topo.components];
    for (l, lp) in topo.boundary_loops.iter().enumerate() {
        for (i, &v) in lp.iter().enumerate() {
            sources.push((v, l as u32));
            // Each loop minus its closing edge goes into the tree: its cap is then a leaf of
            // the dual tree, so removing the caps cannot split the chart.
            if i + 1 < lp.len() {
                if let Some(e) = topo.edge_between(v, lp[i + 1]) {
                    in_tree[e as usize] = true;
                }
            }
        }
        if let Some(&f) = lp.first().and_then(|&v| topo.vertex_faces(v).first()) {
            has_boundary[topo.component_of_face[f as usize] as usize] = true;
        }
    }
    // One root per closed component: its first face's first vertex.
    let mut seen = vec![false; topo.components];
    let mut next_region = topo.boundary_loops.len() as u32;
    for (f, &c) in topo.component_of_face.iter().enumerate() {
        if !has_boundary[c as usize] && !seen[c as usize] {
            seen[c as usize] = true;
            sources.push((mesh.faces[f][0], next_region));
            next_region += 1;
        }
    }
    let (dist, parent, region) = dijkstra(topo, weights, &sources);
    for &e in &parent {
        if e != u32::MAX {
            in_tree[e as usize] = true;
        }
    }
    // Join the regions (holes) of each component by the cheapest bridges.
    let mut bridges: Vec<(f64, u32)> = topo
        .edges
        .iter()
        .enumerate()
        .filter(|(_, &[a, b])| {
            region[a as usize] != u32::MAX
                && region[b as usize] != u32::MAX
                && region[a as usize] != region[b as usize]
        })
        .map(|(e, &[a, b])| (dist[a as usize] + weights[e] + dist[b as usize], e as u32))
        .collect();
    bridges.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    let mut uf = UnionFind::new(next_region as usize);
    for (_, e) in bridges {
        let [a, b] = topo.edges[e as usize];
        if uf.union(region[a as usize], region[b as usize]) {
            in_tree[e as usize] = true;
        }
    }
    PrimalTree { in_tree, dist }
}

/// Which edges the dual tree keeps (crosses): they stay glued.
struct DualTree {
    kept: Vec<bool>,
}

fn dual_tree(mesh: &TriMesh, topo: &Topology, weights: &[f64], primal: &PrimalTree) -> DualTree {
    let nf = mesh.faces.len();
    // Cap node of each boundary loop.
    let mut loop_of_vertex = vec![u32::MAX; topo.n_vertices];
    for (l, lp) in topo.boundary_loops.iter().enumerate() {
        for &v in lp {
            loop_of_vertex[v as usize] = l as u32;
        }
    }
    let mut candidates: Vec<(f64, u32)> = (0..topo.edges.len())
        .filter(|&e| !primal.in_tree[e])
        .map(|e| {
            let [a, b] = topo.edges[e];
            (
                primal.dist[a as usize] + weights[e] + primal.dist[b as usize],
                e as u32,
            )
        })
        .collect();
    // Maximum spanning tree: the shortest loops are the ones left out.
    candidates.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
    let mut uf = UnionFind::new(nf + topo.boundary_loops.len());
    let mut kept = vec![false; topo.edges.len()];
    for (_, e) in candidates {
        let [f0, f1] = topo.edge_faces[e as usize];
        let n1 = if f1 == NO_FACE {
            let v = topo.edges[e as usize][0];
            let l = loop_of_vertex[v as usize];
            if l == u32::MAX {
                continue;
            }
            nf as u32 + l
        } else {
            f1
        };
        if uf.union(f0, n1) {
            kept[e as usize] = true;
        }
    }
    DualTree { kept }
}

/// Zips seam edges hanging from interior vertices until none is left.
fn prune(topo: &Topology, cut: &mut [bool]) {
    let n = topo.n_vertices;
    let mut on_boundary = vec![false; n];
    for &e in &topo.boundary_edges {
        for v in topo.edges[e as usize] {
            on_boundary[v as usize] = true;
        }
    }
    let mut degree = vec![0u32; n];
    for (e, &c) in cut.iter().enumerate() {
        if c {
            for v in topo.edges[e] {
                degree[v as usize] += 1;
            }
        }
    }
    let mut stack: Vec<u32> = (0..n as u32)
        .filter(|&v| degree[v as usize] == 1 && !on_boundary[v as usize])
        .collect();
    while let Some(v) = stack.pop() {
        if degree[v as usize] != 1 {
            continue;
        }
        let Some((&w, &e)) = topo
            .neighbors(v)
            .iter()
            .zip(topo.neighbor_edges(v))
            .find(|&(_, &e)| cut[e as usize])
        else {
            continue;
        };
        cut[e as usize] = false;
        degree[v as usize] -= 1;
        degree[w as usize] -= 1;
        if degree[w as usize] == 1 && !on_boundary[w as usize] {
            stack.push(w);
        }
    }
}

/// Closed components with no seam left (genus 0) get the shortest path between two far-apart
/// vertices as their seam (at least two edges, so the cut opens a proper boundary loop).
fn cut_closed_spheres(mesh: &TriMesh, topo: &Topology, weights: &[f64], cut: &mut [bool]) {
    let mut has_cut_or_boundary = vec![false; topo.components];
    for (e, &[f0, f1]) in topo.edge_faces.iter().enumerate() {
        if cut[e] || f1 == NO_FACE {
            has_cut_or_boundary[topo.component_of_face[f0 as usize] as usize] = true;
        }
    }
    let mut done = vec![false; topo.components];
    for (f, &c) in topo.component_of_face.iter().enumerate() {
        let c = c as usize;
        if has_cut_or_boundary[c] || done[c] {
            continue;
        }
        done[c] = true;
        let start = mesh.faces[f][0];
        let (d0, _, _) = dijkstra(topo, weights, &[(start, 0)]);
        let a = farthest(&d0);
        let (d1, parent, _) = dijkstra(topo, weights, &[(a, 0)]);
        let b = farthest(&d1);
        let mut path = Vec::new();
        let mut v = b;
        while v != a {
            let e = parent[v as usize];
            if e == u32::MAX {
                break;
            }
            path.push(e);
            let [x, y] = topo.edges[e as usize];
            v = if x == v { y } else { x };
        }
        if path.len() == 1 {
            // Route a single-edge path through a common neighbour of its ends.
            let [x, y] = topo.edges[path[0] as usize];
            if let Some(&m) = topo.neighbors(x).iter().find(|&&m| {
                m != y && topo.edge_between(m, y).is_some() && topo.edge_between(m, x).is_some()
            }) {
                path.clear();
                path.extend(topo.edge_between(x, m));
                path.extend(topo.edge_between(m, y));
            }
        }
        for e in path {
            cut[e as usize] = true;
        }
    }
}

/// Adds the shortest path from the cut graph ∪ boundary of `target`'s component to `target`.
fn add_seam_to(topo: &Topology, weights: &[f64], cut: &mut [bool], target: u32) {
    let mut on_cut = vec![false; topo.n_vertices];
    for (e, &[_, f1]) in topo.edge_faces.iter().enumerate() {
        if cut[e] || f1 == NO_FACE {
            for v in topo.edges[e] {
                on_cut[v as usize] = true;
            }
        }
    }
    if target as usize >= topo.n_vertices || on_cut[target as usize] {
        return;
    }
    // Search from the target outwards; the first cut vertex settled is the nearest.
    let (dist, parent, _) = dijkstra(topo, weights, &[(target, 0)]);
    let Some(end) = (0..topo.n_vertices as u32)
        .filter(|&v| on_cut[v as usize] && dist[v as usize].is_finite())
        .min_by(|&a, &b| {
            dist[a as usize]
                .total_cmp(&dist[b as usize])
                .then(a.cmp(&b))
        })
    else {
        return;
    };
    let mut v = end;
    while v != target {
        let e = parent[v as usize];
        if e == u32::MAX {
            return;
        }
        cut[e as usize] = true;
        let [x, y] = topo.edges[e as usize];
        v = if x == v { y } else { x };
    }
}

/// Cuts the shortest path from `sp.a` to `sp.b` through the interior of the chart holding
/// `sp.face` (its inner vertices touch neither the cut nor the boundary, its edges are uncut
/// edges between two faces of the chart): a chord of a disk, so the chart becomes two disks.
/// Returns whether it cut.
fn add_split_seam(topo: &Topology, weights: &[f64], cut: &mut [bool], sp: &Split) -> bool {
    let nf = topo.face_edges.len();
    let (a, b) = (sp.a, sp.b);
    if a == b || sp.face as usize >= nf || a as usize >= topo.n_vertices {
        return false;
    }
    if b as usize >= topo.n_vertices {
        return false;
    }
    // The chart: faces reachable from sp.face across uncut interior edges.
    let mut in_chart = vec![false; nf];
    let mut stack = vec![sp.face];
    in_chart[sp.face as usize] = true;
    while let Some(f) = stack.pop() {
        for &e in &topo.face_edges[f as usize] {
            let [f0, f1] = topo.edge_faces[e as usize];
            if cut[e as usize] || f1 == NO_FACE {
                continue;
            }
            let g = if f0 == f { f1 } else { f0 };
            if !in_chart[g as usize] {
                in_chart[g as usize] = true;
                stack.push(g);
            }
        }
    }
    let mut on_cut = vec![false; topo.n_vertices];
    for (e, &[_, f1]) in topo.edge_faces.iter().enumerate() {
        if cut[e] || f1 == NO_FACE {
            for v in topo.edges[e] {
                on_cut[v as usize] = true;
            }
        }
    }
    let touches = |v: u32| topo.vertex_faces(v).iter().any(|&f| in_chart[f as usize]);
    if !on_cut[a as usize] || !on_cut[b as usize] || !touches(a) || !touches(b) {
        return false;
    }
    let inner =
        |v: u32| !on_cut[v as usize] && topo.vertex_faces(v).iter().all(|&f| in_chart[f as usize]);
    let edge_ok = |e: u32| {
        let [f0, f1] = topo.edge_faces[e as usize];
        !cut[e as usize] && f1 != NO_FACE && in_chart[f0 as usize] && in_chart[f1 as usize]
    };
    let n = topo.n_vertices;
    let mut dist = vec![f64::INFINITY; n];
    let mut parent = vec![u32::MAX; n];
    let mut heap = BinaryHeap::new();
    dist[a as usize] = 0.0;
    heap.push(Item(0.0, a));
    let mut reached = false;
    while let Some(Item(d, v)) = heap.pop() {
        if d > dist[v as usize] {
            continue;
        }
        if v == b {
            reached = true;
            break;
        }
        if v != a && !inner(v) {
            continue; // only a and interior vertices are passed through
        }
        for (&w, &e) in topo.neighbors(v).iter().zip(topo.neighbor_edges(v)) {
            if !edge_ok(e) || !(w == b || inner(w)) {
                continue;
            }
            let nd = d + weights[e as usize];
            if nd < dist[w as usize] {
                dist[w as usize] = nd;
                parent[w as usize] = e;
                heap.push(Item(nd, w));
            }
        }
    }
    if !reached {
        return false;
    }
    let mut v = b;
    while v != a {
        let e = parent[v as usize];
        cut[e as usize] = true;
        let [x, y] = topo.edges[e as usize];
        v = if x == v { y } else { x };
    }
    true
}

fn farthest(dist: &[f64]) -> u32 {
    let mut best = (0u32, -1.0f64);
    for (v, &d) in dist.iter().enumerate() {
        if d.is_finite() && d > best.1 {
            best = (v as u32, d);
        }
    }
    best.0
}

/// One vertex per wedge: corners of two faces sharing a vertex stay together when the faces
/// share an uncut interior edge at that vertex.
fn split_vertices(mesh: &TriMesh, topo: &Topology, cut: &[bool]) -> (TriMesh, Vec<u32>) {
    let nf = mesh.faces.len();
    let mut uf = UnionFind::new(3 * nf);
    let corner = |f: u32, v: u32| -> u32 {
        let k = mesh.faces[f as usize]
            .iter()
            .position(|&x| x == v)
            .unwrap_or(0);
        3 * f + k as u32
    };
    for &e in &topo.interior_edges {
        if cut[e as usize] {
            continue;
        }
        let [f0, f1] = topo.edge_faces[e as usize];
        for v in topo.edges[e as usize] {
            uf.union(corner(f0, v), corner(f1, v));
        }
    }
    let mut id = vec![u32::MAX; 3 * nf];
    let mut out = TriMesh::default();
    let mut origin = Vec::new();
    for f in 0..nf {
        let mut tri = [0u32; 3];
        for (k, t) in tri.iter_mut().enumerate() {
            let r = uf.find((3 * f + k) as u32) as usize;
            if id[r] == u32::MAX {
                id[r] = origin.len() as u32;
                let v = mesh.faces[f][k];
                origin.push(v);
                out.positions.push(mesh.positions[v as usize]);
            }
            *t = id[r];
        }
        out.faces.push(tri);
    }
    (out, origin)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An octahedron: closed, genus 0.
    fn octahedron() -> TriMesh {
        TriMesh {
            positions: vec![
                [1.0, 0.0, 0.0],
                [-1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, -1.0, 0.0],
                [0.0, 0.0, 1.0],
                [0.0, 0.0, -1.0],
            ],
            faces: vec![
                [0, 2, 4],
                [2, 1, 4],
                [1, 3, 4],
                [3, 0, 4],
                [2, 0, 5],
                [1, 2, 5],
                [3, 1, 5],
                [0, 3, 5],
            ],
        }
    }

    fn torus(n: usize, m: usize) -> TriMesh {
        let mut mesh = TriMesh::default();
        for i in 0..n {
            for j in 0..m {
                let (u, v) = (
                    i as f64 / n as f64 * std::f64::consts::TAU,
                    j as f64 / m as f64 * std::f64::consts::TAU,
                );
                let r = 2.0 + 0.7 * v.cos();
                mesh.positions
                    .push([r * u.cos(), r * u.sin(), 0.7 * v.sin()]);
            }
        }
        let id = |i: usize, j: usize| ((i % n) * m + (j % m)) as u32;
        for i in 0..n {
            for j in 0..m {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                mesh.faces.push([a, b, c]);
                mesh.faces.push([a, c, d]);
            }
        }
        mesh
    }

    fn check(mesh: &TriMesh, charts: usize) -> CutMesh {
        let file = Path::new("<memory>");
        let topo = Topology::build(mesh, file).unwrap();
        let cut = cut_to_disks(mesh, &topo, &CutOptions::default(), file).unwrap();
        assert_eq!(cut.charts.len(), charts);
        assert_eq!(cut.mesh.faces.len(), mesh.faces.len());
        for (f, tri) in cut.mesh.faces.iter().enumerate() {
            for k in 0..3 {
                assert_eq!(cut.origin[tri[k] as usize], mesh.faces[f][k]);
            }
        }
        cut
    }

    #[test]
    fn sphere_is_cut_along_one_path() {
        let cut = check(&octahedron(), 1);
        assert!(cut.seam_edges.len() >= 2, "{:?}", cut.seam_edges);
        // A path of k edges splits its k−1 inner vertices in two.
        assert_eq!(
            cut.mesh.positions.len(),
            6 + cut.seam_edges.len() - 1,
            "{:?}",
            cut.seam_edges
        );
    }

    #[test]
    fn torus_gets_two_loops() {
        let mesh = torus(12, 8);
        let cut = check(&mesh, 1);
        // Two generator loops through a common root: at least 8 + 12 − ... edges, and the
        // split mesh is a disk (checked inside cut_to_disks).
        assert!(cut.seam_edges.len() >= 8, "{}", cut.seam_edges.len());
    }

    #[test]
    fn disk_is_not_cut() {
        let mut mesh = TriMesh::default();
        for j in 0..4 {
            for i in 0..4 {
                mesh.positions.push([i as f64, j as f64, 0.0]);
            }
        }
        for j in 0..3u32 {
            for i in 0..3u32 {
                let a = j * 4 + i;
                mesh.faces.push([a, a + 1, a + 5]);
                mesh.faces.push([a, a + 5, a + 4]);
            }
        }
        let cut = check(&mesh, 1);
        assert!(cut.seam_edges.is_empty());
        assert_eq!(cut.mesh.positions.len(), mesh.positions.len());
    }

    #[test]
    fn annulus_gets_one_bridge() {
        // A 8x3 grid wrapped around: an annulus (2 boundary loops).
        let (n, m) = (8usize, 3usize);
        let mut mesh = TriMesh::default();
        for j in 0..m {
            for i in 0..n {
                let t = i as f64 / n as f64 * std::f64::consts::TAU;
                let r = 1.0 + j as f64;
                mesh.positions.push([r * t.cos(), r * t.sin(), 0.0]);
            }
        }
        let id = |i: usize, j: usize| (j * n + i % n) as u32;
        for j in 0..m - 1 {
            for i in 0..n {
                mesh.faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                mesh.faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let cut = check(&mesh, 1);
        // The shortest bridge between the two circles is the 2-edge radial path.
        assert_eq!(cut.seam_edges.len(), 2, "{:?}", cut.seam_edges);
    }

    #[test]
    fn two_components_give_two_charts() {
        let a = octahedron();
        let mut b = torus(10, 6);
        let off = a.positions.len() as u32;
        let mut mesh = a.clone();
        mesh.positions.append(&mut b.positions);
        mesh.faces
            .extend(b.faces.iter().map(|f| f.map(|v| v + off)));
        check(&mesh, 2);
    }

    #[test]
    fn non_manifold_vertex_is_named() {
        let mesh = TriMesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [-1.0, 0.0, 0.0],
                [0.0, -1.0, 0.0],
            ],
            faces: vec![[0, 1, 2], [0, 3, 4]],
        };
        let file = Path::new("<memory>");
        let topo = Topology::build(&mesh, file).unwrap();
        let err = cut_to_disks(&mesh, &topo, &CutOptions::default(), file).unwrap_err();
        assert!(err.to_string().contains("vertex 0"), "{err}");
    }
}
