//! Starting maps for the solvers: the Tutte embedding (flip-free on a convex boundary, the
//! foldover-free start) and the least-squares conformal map (low distortion, may fold).
//!
//! Inputs are flat arrays: positions #V×3, faces #F×3 (0-based, counter-clockwise), and the
//! boundary loop as an ordered vertex cycle in the direction the faces traverse it. Vertices
//! used by no face are left out of every system and get UV (0, 0).
#![forbid(unsafe_code)]

pub mod lscm;
pub mod tutte;

pub use lscm::{lscm, lscm_pinned, lscm_pins, lscm_report};
pub use tutte::{tutte, tutte_report, TutteWeights};

use crate::linalg::SolveError;
use crate::linalg::{krylov::CgOptions, precond::Preconditioner};
use crate::mesh::{Topology, TriMesh};

/// A starting map with what it cost and how valid it is.
#[derive(Clone, Debug, PartialEq)]
pub struct InitReport {
    /// #V×2 UV coordinates, total signed area > 0.
    pub uv: Vec<[f64; 2]>,
    /// Faces with signed UV area ≤ 0.
    pub flips: usize,
    /// Krylov iterations of the slowest UV column.
    pub iterations: usize,
    /// Largest true relative residual ‖b − Ax‖/‖b‖ over the UV columns.
    pub relative_residual: f64,
    /// Preconditioner actually used (after any fallback).
    pub preconditioner: Preconditioner,
}

/// Solver options the starting maps use by default: algebraic multigrid (Tutte on 125k
/// vertices in about a second) and a tight tolerance, because thin triangles of a Tutte map
/// flip when the solve is only roughly right.
pub fn default_solve_options() -> CgOptions {
    CgOptions {
        tolerance: 1e-12,
        max_iterations: 20_000,
        preconditioner: Preconditioner::Amg { block_size: 1 },
    }
}

/// Unsigned area of face `f` in the plane `uv`.
pub fn face_area_2d(uv: &[[f64; 2]], f: &[u32; 3]) -> f64 {
    signed_area2(uv[f[0] as usize], uv[f[1] as usize], uv[f[2] as usize]).abs() / 2.0
}

/// Twice the signed area of the UV triangle (a, b, c): (b − a) × (c − a).
#[inline]
pub fn signed_area2(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
}

/// Number of faces whose signed UV area is ≤ 0 (flipped or collapsed).
pub fn count_flips(faces: &[[u32; 3]], uv: &[[f64; 2]]) -> usize {
    faces
        .iter()
        .filter(|f| {
            let a = signed_area2(uv[f[0] as usize], uv[f[1] as usize], uv[f[2] as usize]);
            a.is_nan() || a <= 0.0
        })
        .count()
}

/// Total signed UV area Σ_f area_f (positive for a counter-clockwise map).
pub fn total_signed_area(faces: &[[u32; 3]], uv: &[[f64; 2]]) -> f64 {
    0.5 * faces
        .iter()
        .map(|f| signed_area2(uv[f[0] as usize], uv[f[1] as usize], uv[f[2] as usize]))
        .sum::<f64>()
}

/// Mirrors v (v → −v) when the total signed area is negative, so the map is counter-clockwise.
pub(crate) fn orient_ccw(faces: &[[u32; 3]], uv: &mut [[f64; 2]]) {
    if total_signed_area(faces, uv) < 0.0 {
        for p in uv.iter_mut() {
            p[1] = -p[1];
        }
    }
}

/// Checks index ranges and the boundary loop; returns which vertices some face uses.
pub(crate) fn check_input(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    boundary: &[u32],
) -> Result<Vec<bool>, SolveError> {
    let used = check_faces(positions, faces)?;
    if boundary.len() < 3 {
        return Err(SolveError::InvalidInput {
            what: format!(
                "boundary loop has {} vertices; a disk needs at least 3",
                boundary.len()
            ),
        });
    }
    let mut seen = vec![false; positions.len()];
    for &v in boundary {
        let vi = v as usize;
        if vi >= positions.len() || !used[vi] {
            return Err(SolveError::InvalidInput {
                what: format!("boundary vertex {v} is not a vertex of any face"),
            });
        }
        if seen[vi] {
            return Err(SolveError::InvalidInput {
                what: format!("boundary loop visits vertex {v} twice"),
            });
        }
        seen[vi] = true;
    }
    Ok(used)
}

/// Checks that positions are finite and face indices in range; returns which vertices some
/// face uses.
pub(crate) fn check_faces(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
) -> Result<Vec<bool>, SolveError> {
    let n = positions.len();
    if let Some(v) = positions
        .iter()
        .position(|p| p.iter().any(|x| !x.is_finite()))
    {
        return Err(SolveError::NonFinite {
            what: format!("position of vertex {v}"),
        });
    }
    let mut used = vec![false; n];
    for (fi, f) in faces.iter().enumerate() {
        for &v in f {
            if v as usize >= n {
                return Err(SolveError::InvalidInput {
                    what: format!("face {fi} uses vertex {v}, but there are {n} vertices"),
                });
            }
            used[v as usize] = true;
        }
    }
    Ok(used)
}

/// Unique undirected edges (i < j) of the faces, sorted.
pub(crate) fn unique_edges(faces: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut edges: Vec<[u32; 2]> = faces
        .iter()
        .flat_map(|f| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]])
        .map(|[a, b]| if a < b { [a, b] } else { [b, a] })
        .collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// Vertices that some face uses but that no path of edges links to a `source` vertex:
/// on them the systems below would be singular.
pub(crate) fn unreached(n: usize, edges: &[[u32; 2]], used: &[bool], sources: &[u32]) -> usize {
    // CSR adjacency: count → prefix sum → fill.
    let mut start = vec![0usize; n + 1];
    for e in edges {
        start[e[0] as usize + 1] += 1;
        start[e[1] as usize + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut adj = vec![0u32; start[n]];
    for e in edges {
        for (a, b) in [(e[0], e[1]), (e[1], e[0])] {
            adj[fill[a as usize]] = b;
            fill[a as usize] += 1;
        }
    }
    let mut seen = vec![false; n];
    let mut stack: Vec<u32> = Vec::new();
    for &s in sources {
        if !seen[s as usize] {
            seen[s as usize] = true;
            stack.push(s);
        }
    }
    while let Some(v) = stack.pop() {
        for &w in &adj[start[v as usize]..start[v as usize + 1]] {
            if !seen[w as usize] {
                seen[w as usize] = true;
                stack.push(w);
            }
        }
    }
    (0..n).filter(|&v| used[v] && !seen[v]).count()
}

/// 3D vector helpers (the crate's one copy lives in [`crate::linalg::vec3`]).
pub use crate::linalg::vec3;

/// Which start map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InitMethod {
    /// Tutte embedding (uniform or mean-value weights): flip-free, high distortion.
    Tutte(TutteWeights),
    /// Least-squares conformal map: near-optimal for MIPS, may flip a few faces (ADMM repairs).
    Lscm,
}

/// The start map of a disk mesh.
pub fn initial_map(
    mesh: &TriMesh,
    topo: &Topology,
    init: InitMethod,
) -> crate::Result<Vec<[f64; 2]>> {
    let boundary = topo
        .boundary_loops
        .first()
        .ok_or_else(|| crate::Error::Usage("the mesh has no boundary loop".into()))?;
    let uv = match init {
        InitMethod::Tutte(w) => tutte(&mesh.positions, &mesh.faces, boundary, w)?,
        InitMethod::Lscm => lscm::lscm(&mesh.positions, &mesh.faces, boundary)?,
    };
    Ok(uv)
}

/// Scales `uv` about its centroid so its total |area| equals the 3D area: Jacobians are then
/// O(1), which keeps the device's f32 arithmetic well inside its range.
pub fn normalize_area(mesh: &TriMesh, uv: &mut [[f64; 2]], area_3d: f64) {
    let a = total_signed_area(&mesh.faces, uv).abs();
    if !(a > 0.0 && a.is_finite() && area_3d > 0.0) {
        return;
    }
    let s = (area_3d / a).sqrt();
    let n = uv.len().max(1) as f64;
    let c = uv
        .iter()
        .fold([0.0, 0.0], |acc, p| [acc[0] + p[0] / n, acc[1] + p[1] / n]);
    for p in uv.iter_mut() {
        *p = [(p[0] - c[0]) * s, (p[1] - c[1]) * s];
    }
}

impl InitMethod {
    /// The name the CLI and the report use.
    pub fn name(self) -> &'static str {
        match self {
            InitMethod::Tutte(TutteWeights::Uniform) => "tutte",
            InitMethod::Tutte(TutteWeights::MeanValue) => "tutte_mean_value",
            InitMethod::Lscm => "lscm",
        }
    }
}

/// Test meshes shared by the start maps' unit tests.
#[cfg(test)]
pub(crate) mod test_grid {
    /// A (k+1)² vertex grid over the unit square lifted to the height `z(x, y)`, two triangles
    /// per cell.
    pub fn bumpy(k: usize, z: impl Fn(f64, f64) -> f64) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let mut p = Vec::new();
        for j in 0..=k {
            for i in 0..=k {
                let (x, y) = (i as f64 / k as f64, j as f64 / k as f64);
                p.push([x, y, z(x, y)]);
            }
        }
        let mut f = Vec::new();
        for j in 0..k {
            for i in 0..k {
                f.push([id(k, i, j), id(k, i + 1, j), id(k, i + 1, j + 1)]);
                f.push([id(k, i, j), id(k, i + 1, j + 1), id(k, i, j + 1)]);
            }
        }
        (p, f)
    }

    /// Vertex (i, j) of [`bumpy`]`(k, …)`.
    pub fn id(k: usize, i: usize, j: usize) -> u32 {
        (j * (k + 1) + i) as u32
    }

    /// Largest coordinate difference of two maps.
    pub fn max_diff(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
        a.iter()
            .zip(b)
            .flat_map(|(x, y)| [x[0] - y[0], x[1] - y[1]])
            .fold(0.0f64, |m, d| m.max(d.abs()))
    }
}
