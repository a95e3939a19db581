//! The block-sparse pattern of a Hessian assembled from per-simplex blocks: `D` unknowns per
//! vertex (interleaved, row `D·v + r`), simplices of `K` corners (triangles, K = 3, in the
//! global UV solver with D = 2; tets, K = 4, in the volumetric Newton solver with D = 3).
//! Finite-element assembly as in e.g. Saad, *Iterative Methods for Sparse Linear Systems*
//! (2003), §2.3: the row of vertex a holds a D×D block for every vertex sharing a simplex
//! with a. It exists so both Newton solvers build the CSR structure once per mesh and scatter
//! every per-simplex block by precomputed positions, with no search per entry.
#![forbid(unsafe_code)]

use sprs::CsMat;

/// The vertices sharing a simplex with each vertex, ascending, deduplicated; with the vertex
/// itself when `with_self` (Hessian rows), without it (graph Laplacians).
pub fn neighbours<const K: usize>(
    nv: usize,
    simplices: &[[u32; K]],
    with_self: bool,
) -> Vec<Vec<u32>> {
    let mut nb: Vec<Vec<u32>> = if with_self {
        (0..nv as u32).map(|v| vec![v]).collect()
    } else {
        vec![Vec::new(); nv]
    };
    for s in simplices {
        for &a in s {
            for &b in s {
                if a != b {
                    nb[a as usize].push(b);
                }
            }
        }
    }
    for l in &mut nb {
        l.sort_unstable();
        l.dedup();
    }
    nb
}

/// CSR structure of the (D·#V)² Hessian: row `D·a + r` holds columns `D·b + s` for every
/// vertex b sharing a simplex with a (a itself included), b ascending.
#[derive(Clone, Debug)]
pub struct BlockPattern<const D: usize, const K: usize> {
    /// Number of rows (= columns) D·#V.
    pub n: usize,
    pub indptr: Vec<usize>,
    pub indices: Vec<usize>,
    /// Per simplex, per corner pair (i, j): position of `s[j]` in `s[i]`'s neighbour list.
    pub slot: Vec<[[u32; K]; K]>,
    /// Per vertex: its position in its own neighbour list (the diagonal block).
    pub diag_slot: Vec<u32>,
}

impl<const D: usize, const K: usize> BlockPattern<D, K> {
    /// The pattern of `simplices` over `nv` vertices (indices must be < `nv`).
    pub fn new(nv: usize, simplices: &[[u32; K]]) -> Self {
        let nb = neighbours(nv, simplices, true);
        let n = D * nv;
        let mut indptr = Vec::with_capacity(n + 1);
        let mut indices = Vec::new();
        indptr.push(0);
        for l in &nb {
            for _ in 0..D {
                for &b in l {
                    for s in 0..D {
                        indices.push(D * b as usize + s);
                    }
                }
                indptr.push(indices.len());
            }
        }
        // binary_search cannot fail: every corner was inserted into every other's list, and
        // every vertex into its own.
        let find = |a: u32, b: u32| nb[a as usize].binary_search(&b).unwrap_or(0) as u32;
        let slot = simplices
            .iter()
            .map(|t| {
                let mut s = [[0u32; K]; K];
                for i in 0..K {
                    for j in 0..K {
                        s[i][j] = find(t[i], t[j]);
                    }
                }
                s
            })
            .collect();
        let diag_slot = (0..nv as u32).map(|v| find(v, v)).collect();
        BlockPattern {
            n,
            indptr,
            indices,
            slot,
            diag_slot,
        }
    }

    /// Index in the value array of entry (D·a + r, D·b + s), b the `k`-th neighbour of a.
    #[inline]
    pub fn pos(&self, a: u32, r: usize, k: u32, s: usize) -> usize {
        self.indptr[D * a as usize + r] + D * k as usize + s
    }

    /// Index of the diagonal entry (D·v + r, D·v + r).
    #[inline]
    pub fn diag(&self, v: u32, r: usize) -> usize {
        self.pos(v, r, self.diag_slot[v as usize], r)
    }

    /// The CSR matrix of this pattern with the values `data` (one per stored entry).
    pub fn matrix(&self, data: Vec<f64>) -> CsMat<f64> {
        CsMat::new(
            (self.n, self.n),
            self.indptr.clone(),
            self.indices.clone(),
            data,
        )
    }
}
