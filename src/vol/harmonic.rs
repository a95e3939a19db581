//! Harmonic extension over the tet graph (uniform weights): the interior of a start map when
//! only some vertices are prescribed. Cheap and smooth, but it may invert tets — which the
//! volmap pipeline is designed to repair.

use sprs::TriMat;

use super::tet::TetMesh;
use super::VolError;
use crate::linalg::krylov::pcg_multi;
use crate::linalg::pattern::neighbours;

/// Positions `base + u` where u is harmonic (graph Laplacian of the tet edges) with
/// u = target − base on the constrained vertices. `base` = rest positions extends a
/// displacement; `base` = 0 gives a harmonic map. Every connected part of the mesh needs a
/// constrained vertex.
pub fn harmonic_extension(
    mesh: &TetMesh,
    base: &[[f64; 3]],
    targets: &[(u32, [f64; 3])],
) -> Result<Vec<[f64; 3]>, VolError> {
    let nv = mesh.positions.len();
    let mut known: Vec<Option<[f64; 3]>> = vec![None; nv];
    for (v, t) in targets {
        let b = base[*v as usize];
        known[*v as usize] = Some([t[0] - b[0], t[1] - b[1], t[2] - b[2]]);
    }
    let nb = neighbours(nv, &mesh.tets, false);
    let mut index = vec![usize::MAX; nv];
    let mut free = Vec::new();
    for v in 0..nv {
        if known[v].is_none() && !nb[v].is_empty() {
            index[v] = free.len();
            free.push(v);
        }
    }
    let n = free.len();
    let mut u = vec![[0.0; 3]; nv];
    for v in 0..nv {
        if let Some(k) = known[v] {
            u[v] = k;
        }
    }
    if n > 0 {
        let mut tri = TriMat::new((n, n));
        let mut rhs = vec![vec![0.0; n]; 3];
        for (i, &v) in free.iter().enumerate() {
            tri.add_triplet(i, i, nb[v].len() as f64);
            for &w in &nb[v] {
                match known[w as usize] {
                    Some(k) => {
                        for c in 0..3 {
                            rhs[c][i] += k[c];
                        }
                    }
                    None => tri.add_triplet(i, index[w as usize], -1.0),
                }
            }
        }
        let a = tri.to_csr();
        let mut sol = vec![vec![0.0; n]; 3];
        pcg_multi(&a, &rhs, &mut sol, &crate::init::default_solve_options()).map_err(|e| {
            VolError::Input(format!(
                "harmonic extension failed ({e}); does every part of the mesh have a constrained vertex?"
            ))
        })?;
        for (i, &v) in free.iter().enumerate() {
            u[v] = [sol[0][i], sol[1][i], sol[2][i]];
        }
    }
    Ok((0..nv)
        .map(|v| {
            let b = base[v];
            [b[0] + u[v][0], b[1] + u[v][1], b[2] + u[v][2]]
        })
        .collect())
}
