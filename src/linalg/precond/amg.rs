//! Smoothed-aggregation algebraic multigrid (Vaněk, Mandel & Brezina 1996) as a
//! preconditioner: one V(1,1)-cycle with symmetric Gauss–Seidel smoothing. It exists for the
//! largest meshes, where IC(0)'s iteration count grows like √n and the V-cycle's hardly grows.
#![forbid(unsafe_code)]

use crate::linalg::sparse::{residual, Csr, CsrOps, RowBuilder};

/// Strength-of-connection threshold: node J is a strong neighbour of I when the largest
/// |a_ij| between their unknowns is ≥ θ·√(d_I·d_J), d the largest diagonal magnitude.
const AMG_THETA: f64 = 0.08;
/// Stop coarsening at this many unknowns; the coarsest level is solved densely.
const AMG_COARSEST: usize = 400;

/// One level of the hierarchy (level 0 is the input matrix, held by the solver): the
/// prolongator P from the next coarser level, the restriction R = Pᵀ, and the next level's
/// Galerkin matrix Pᵀ·A·P.
struct AmgLevel {
    p: Csr,
    r: Csr,
    coarse: Csr,
    coarse_inv_diag: Vec<f64>,
}

/// Smoothed-aggregation AMG as a preconditioner: one V(1,1)-cycle, forward Gauss–Seidel
/// before and backward Gauss–Seidel after the coarse correction, so the cycle is a
/// symmetric operator when A is (as CG requires).
pub(crate) struct Amg {
    fine_inv_diag: Vec<f64>,
    levels: Vec<AmgLevel>,
    coarsest: DenseLu,
}

impl Amg {
    /// `None` when the block size does not divide the matrix, a diagonal is zero, or the
    /// coarsest matrix is singular or too large.
    pub(crate) fn build(a: &Csr, block: usize) -> Option<Amg> {
        if block == 0 || a.rows() % block != 0 || a.rows() == 0 {
            return None;
        }
        let fine_inv_diag = inverse_diagonal(a)?;
        let mut levels: Vec<AmgLevel> = Vec::new();
        loop {
            let (cur, inv_diag) = match levels.last() {
                Some(l) => (&l.coarse, &l.coarse_inv_diag),
                None => (a, &fine_inv_diag),
            };
            if cur.rows() <= AMG_COARSEST || levels.len() >= 30 {
                break;
            }
            let (agg, n_agg) = aggregate(cur, block);
            if n_agg * block * 10 > cur.rows() * 9 {
                break; // coarsening stalled
            }
            let p = smoothed_prolongator(cur, inv_diag, &agg, block, n_agg * block);
            let r = p.transpose_view().to_csr();
            // Galerkin coarse operator A_c = Pᵀ·A·P.
            let coarse = r.product(&cur.product(&p));
            let coarse_inv_diag = inverse_diagonal(&coarse)?;
            levels.push(AmgLevel {
                p,
                r,
                coarse,
                coarse_inv_diag,
            });
        }
        let last = levels.last().map_or(a, |l| &l.coarse);
        if last.rows() > 2 * AMG_COARSEST {
            return None; // a dense solve this large would cost more than it saves
        }
        let coarsest = DenseLu::factor(last)?;
        Some(Amg {
            fine_inv_diag,
            levels,
            coarsest,
        })
    }

    pub(crate) fn apply(&self, a: &Csr, r: &[f64], z: &mut [f64]) {
        self.cycle(0, a, &self.fine_inv_diag, r, z);
    }

    /// x ≈ A_l⁻¹ b on level l (x is overwritten).
    fn cycle(&self, l: usize, a: &Csr, inv_diag: &[f64], b: &[f64], x: &mut [f64]) {
        let Some(lev) = self.levels.get(l) else {
            self.coarsest.solve(b, x);
            return;
        };
        x.fill(0.0);
        gauss_seidel(a, inv_diag, b, x, false);
        // Coarse correction: x += P·cycle(Pᵀ(b − A x)).
        let mut res = vec![0.0; a.rows()];
        residual(a, b, x, &mut res);
        let mut bc = vec![0.0; lev.r.rows()];
        lev.r.spmv(&res, &mut bc);
        let mut xc = vec![0.0; lev.r.rows()];
        self.cycle(l + 1, &lev.coarse, &lev.coarse_inv_diag, &bc, &mut xc);
        lev.p.spmv(&xc, &mut res);
        for (xi, ci) in x.iter_mut().zip(&res) {
            *xi += ci;
        }
        gauss_seidel(a, inv_diag, b, x, true);
    }
}

/// 1/a_ii for every row; `None` if a diagonal is missing, zero or not finite.
fn inverse_diagonal(a: &Csr) -> Option<Vec<f64>> {
    let pos = a.diagonal_positions()?;
    pos.iter()
        .map(|&p| {
            let d = a.data()[p];
            (d != 0.0 && d.is_finite()).then(|| 1.0 / d)
        })
        .collect()
}

/// One Gauss–Seidel sweep x_i ← (b_i − Σ_{j≠i} a_ij x_j)/a_ii, forward or backward.
fn gauss_seidel(a: &Csr, inv_diag: &[f64], b: &[f64], x: &mut [f64], backward: bool) {
    let update = |i: usize, x: &mut [f64]| {
        let (cols, vals) = a.row_of(i);
        let mut s = b[i];
        for (&j, &v) in cols.iter().zip(vals) {
            if j != i {
                s -= v * x[j];
            }
        }
        x[i] = s * inv_diag[i];
    };
    if backward {
        for i in (0..a.rows()).rev() {
            update(i, x);
        }
    } else {
        for i in 0..a.rows() {
            update(i, x);
        }
    }
}

/// Greedy aggregation of the strong-connection graph between nodes (blocks of `block`
/// consecutive unknowns): (1) a node whose strong neighbours are all free seeds an aggregate
/// with them, (2) left-over nodes join a neighbouring aggregate of step 1, (3) the rest seed
/// new aggregates with their free neighbours. Returns node → aggregate and the count.
fn aggregate(a: &Csr, block: usize) -> (Vec<usize>, usize) {
    let nn = a.rows() / block;
    // Node diagonal scale d_I = max_c |a_(I,c),(I,c)|.
    let mut diag = vec![0.0f64; nn];
    for i in 0..a.rows() {
        let (cols, vals) = a.row_of(i);
        if let Ok(p) = cols.binary_search(&i) {
            diag[i / block] = diag[i / block].max(vals[p].abs());
        }
    }
    let mut sptr = vec![0usize; nn + 1];
    let mut sidx = Vec::new();
    let mut mag = vec![0.0f64; nn];
    let mut touched = Vec::new();
    for node in 0..nn {
        for i in node * block..(node + 1) * block {
            let (cols, vals) = a.row_of(i);
            for (&j, &v) in cols.iter().zip(vals) {
                let other = j / block;
                if other != node && v != 0.0 {
                    if mag[other] == 0.0 {
                        touched.push(other);
                    }
                    mag[other] = mag[other].max(v.abs());
                }
            }
        }
        for &other in &touched {
            if mag[other] >= AMG_THETA * (diag[node] * diag[other]).sqrt() {
                sidx.push(other);
            }
            mag[other] = 0.0;
        }
        touched.clear();
        sptr[node + 1] = sidx.len();
    }
    const FREE: usize = usize::MAX;
    let mut agg = vec![FREE; nn];
    let mut n_agg = 0;
    for node in 0..nn {
        let nb = &sidx[sptr[node]..sptr[node + 1]];
        if agg[node] == FREE && !nb.is_empty() && nb.iter().all(|&o| agg[o] == FREE) {
            agg[node] = n_agg;
            for &o in nb {
                agg[o] = n_agg;
            }
            n_agg += 1;
        }
    }
    let first = agg.clone();
    for node in 0..nn {
        if agg[node] == FREE {
            if let Some(&o) = sidx[sptr[node]..sptr[node + 1]]
                .iter()
                .find(|&&o| first[o] != FREE)
            {
                agg[node] = first[o];
            }
        }
    }
    for node in 0..nn {
        if agg[node] == FREE {
            agg[node] = n_agg;
            for &o in &sidx[sptr[node]..sptr[node + 1]] {
                if agg[o] == FREE {
                    agg[o] = n_agg;
                }
            }
            n_agg += 1;
        }
    }
    (agg, n_agg)
}

/// P = (I − ω D⁻¹A)·P_tent, P_tent the piecewise-constant injection (unknown c of node I →
/// coarse unknown c of aggregate(I)), ω = 4/(3ρ) with ρ ≥ ρ(D⁻¹A) by Gershgorin.
fn smoothed_prolongator(a: &Csr, inv_diag: &[f64], agg: &[usize], block: usize, nc: usize) -> Csr {
    let coarse_of = |j: usize| agg[j / block] * block + j % block;
    let rho = (0..a.rows())
        .map(|i| a.row_of(i).1.iter().map(|v| v.abs()).sum::<f64>() * inv_diag[i].abs())
        .fold(0.0f64, f64::max);
    let omega = if rho > 0.0 { 4.0 / (3.0 * rho) } else { 0.0 };
    let mut out = RowBuilder::new(a.rows(), nc);
    for i in 0..a.rows() {
        out.add(coarse_of(i), 1.0);
        let (cols, vals) = a.row_of(i);
        for (&j, &v) in cols.iter().zip(vals) {
            out.add(coarse_of(j), -omega * inv_diag[i] * v);
        }
        out.finish_row();
    }
    out.build()
}

/// Dense LU with partial pivoting: the coarsest multigrid level.
struct DenseLu {
    n: usize,
    lu: Vec<f64>,
    piv: Vec<usize>,
}

impl DenseLu {
    /// `None` when a pivot is negligible against the matrix scale (singular matrix).
    fn factor(a: &Csr) -> Option<DenseLu> {
        let n = a.rows();
        let mut lu = vec![0.0; n * n];
        for i in 0..n {
            let (cols, vals) = a.row_of(i);
            for (&j, &v) in cols.iter().zip(vals) {
                lu[i * n + j] += v;
            }
        }
        let scale = lu.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if scale == 0.0 || !scale.is_finite() {
            return None;
        }
        let mut piv: Vec<usize> = (0..n).collect();
        for k in 0..n {
            let p = (k..n).max_by(|&x, &y| lu[x * n + k].abs().total_cmp(&lu[y * n + k].abs()))?;
            if lu[p * n + k].abs() <= 1e-13 * scale {
                return None;
            }
            if p != k {
                for j in 0..n {
                    lu.swap(k * n + j, p * n + j);
                }
                piv.swap(k, p);
            }
            let pivot = lu[k * n + k];
            for i in k + 1..n {
                let l = lu[i * n + k] / pivot;
                lu[i * n + k] = l;
                if l != 0.0 {
                    for j in k + 1..n {
                        lu[i * n + j] -= l * lu[k * n + j];
                    }
                }
            }
        }
        Some(DenseLu { n, lu, piv })
    }

    fn solve(&self, b: &[f64], x: &mut [f64]) {
        let n = self.n;
        for i in 0..n {
            x[i] = b[self.piv[i]];
        }
        for i in 0..n {
            let s: f64 = (0..i).map(|j| self.lu[i * n + j] * x[j]).sum();
            x[i] -= s;
        }
        for i in (0..n).rev() {
            let s: f64 = (i + 1..n).map(|j| self.lu[i * n + j] * x[j]).sum();
            x[i] = (x[i] - s) / self.lu[i * n + i];
        }
    }
}
