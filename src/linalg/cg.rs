//! Krylov solvers over `sprs` CSR matrices: preconditioned conjugate gradient (Hestenes &
//! Stiefel 1952) for symmetric positive definite systems, and BiCGSTAB (van der Vorst 1992)
//! for the non-symmetric ones (mean-value Tutte embeddings).
//!
//! Preconditioners: Jacobi (diagonal) by default; incomplete Cholesky IC(0) for CG and its
//! non-symmetric sibling ILU(0) for BiCGSTAB on request. Incomplete factorisations can break
//! down (non-positive pivot) on matrices that are not M-matrices (cotangent weights with
//! obtuse angles, LSCM); we then retry with a diagonal shift A + α·diag(A) (Manteuffel 1980)
//! and, if that fails too, fall back to Jacobi, so asking for `Ic0` never makes a solve fail.
//!
//! Convergence is judged on the relative residual ‖b − Ax‖/‖b‖. When the recurrence residual
//! says "converged", the true residual is recomputed: recurrences drift on long solves, and an
//! initial map that is a little off can flip thin triangles.
#![forbid(unsafe_code)]

use std::borrow::Cow;

use rayon::prelude::*;
use sprs::CsMat;

use super::SolveError;

/// Matrices with at least this many rows get a rayon-parallel sparse matrix–vector product.
pub const PARALLEL_ROWS: usize = 20_000;

/// Which preconditioner a Krylov solve uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Preconditioner {
    /// No preconditioning (useful only for tests and comparisons).
    None,
    /// M = diag(A).
    #[default]
    Jacobi,
    /// Incomplete factorisation with the sparsity of A: IC(0) (M = LLᵀ) in [`pcg`], ILU(0)
    /// (M = LU) in [`bicgstab`]. Falls back to a shifted factorisation, then to Jacobi, on
    /// breakdown; [`CgStats::preconditioner`] reports what was used.
    Ic0,
    /// Smoothed-aggregation algebraic multigrid V-cycle (Vaněk, Mandel & Brezina 1996), for
    /// Laplacian-like systems (Tutte, LSCM, Poisson recovery): the iteration count barely grows
    /// with the mesh size, where IC(0)'s grows like √n. `block_size` unknowns per mesh vertex
    /// are aggregated together and keep separate coarse unknowns (2 for an interleaved u, v
    /// system). Falls back to IC(0)/ILU(0), then Jacobi, if the hierarchy cannot be built.
    Amg { block_size: usize },
}

/// Options of a Krylov solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CgOptions {
    /// Stop when ‖b − Ax‖ ≤ tolerance·‖b‖.
    pub tolerance: f64,
    /// Give up (with [`SolveError::CgNoConvergence`]) after this many iterations.
    pub max_iterations: usize,
    pub preconditioner: Preconditioner,
}

impl Default for CgOptions {
    fn default() -> Self {
        CgOptions {
            tolerance: 1e-10,
            max_iterations: 10_000,
            preconditioner: Preconditioner::Jacobi,
        }
    }
}

/// What a successful solve did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CgStats {
    /// Krylov iterations (one SpMV each for CG, two for BiCGSTAB).
    pub iterations: usize,
    /// True relative residual ‖b − Ax‖/‖b‖ at exit (0 when b = 0).
    pub relative_residual: f64,
    /// The preconditioner actually applied (differs from the request after a fallback).
    pub preconditioner: Preconditioner,
    /// Diagonal shift α of an incomplete factorisation (0 when none was needed).
    pub shift: f64,
}

/// A square CSR matrix with a proper (zero-based) row pointer.
struct Csr<'a> {
    n: usize,
    indptr: Cow<'a, [usize]>,
    indices: &'a [usize],
    data: &'a [f64],
}

impl<'a> Csr<'a> {
    fn new(a: &'a CsMat<f64>) -> Result<Csr<'a>, SolveError> {
        if !a.is_csr() {
            return Err(SolveError::InvalidInput {
                what: "Krylov solvers take a CSR matrix (got CSC)".into(),
            });
        }
        if a.rows() != a.cols() {
            return Err(SolveError::InvalidInput {
                what: format!("matrix is {}x{}, not square", a.rows(), a.cols()),
            });
        }
        let indptr = Cow::Owned(a.indptr().to_proper().into_owned());
        Ok(Csr {
            n: a.rows(),
            indptr,
            indices: a.indices(),
            data: a.data(),
        })
    }

    #[inline]
    fn row(&self, i: usize) -> (&[usize], &[f64]) {
        let (s, e) = (self.indptr[i], self.indptr[i + 1]);
        (&self.indices[s..e], &self.data[s..e])
    }

    #[inline]
    fn row_dot(&self, i: usize, x: &[f64]) -> f64 {
        let (cols, vals) = self.row(i);
        cols.iter().zip(vals).map(|(&j, &v)| v * x[j]).sum()
    }

    /// y = A·x, parallel over rows when the matrix is large.
    fn spmv(&self, x: &[f64], y: &mut [f64]) {
        if self.n >= PARALLEL_ROWS {
            y.par_iter_mut()
                .enumerate()
                .with_min_len(4096)
                .for_each(|(i, yi)| *yi = self.row_dot(i, x));
        } else {
            for (i, yi) in y.iter_mut().enumerate() {
                *yi = self.row_dot(i, x);
            }
        }
    }

    fn diagonal(&self) -> Vec<f64> {
        (0..self.n)
            .map(|i| {
                let (cols, vals) = self.row(i);
                cols.binary_search(&i).map_or(0.0, |p| vals[p])
            })
            .collect()
    }
}

#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[inline]
fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// r = b − A·x, returns ‖r‖.
fn residual(a: &Csr, b: &[f64], x: &[f64], r: &mut [f64]) -> f64 {
    a.spmv(x, r);
    for (ri, bi) in r.iter_mut().zip(b) {
        *ri = bi - *ri;
    }
    norm(r)
}

/// Incomplete Cholesky IC(0) with the pattern of tril(A), A ≈ LLᵀ.
///
/// Right-looking on the lower triangle stored by columns: column k of tril(A) is row k of
/// triu(A), so the CSR rows of a symmetric A give it without a transpose.
struct Ic0 {
    colptr: Vec<usize>,
    /// Row indices per column, ascending; the first entry of each column is the diagonal.
    rows: Vec<usize>,
    values: Vec<f64>,
}

impl Ic0 {
    /// Factorises A + shift·diag(A); `None` on a non-positive or non-finite pivot.
    fn factor(a: &Csr, shift: f64) -> Option<Ic0> {
        let n = a.n;
        let mut colptr = Vec::with_capacity(n + 1);
        let mut rows = Vec::new();
        let mut values = Vec::new();
        let mut orig_diag = Vec::with_capacity(n);
        colptr.push(0);
        for k in 0..n {
            let (cols, vals) = a.row(k);
            let first = cols.partition_point(|&j| j < k);
            if cols.get(first) != Some(&k) {
                return None; // no diagonal entry
            }
            orig_diag.push(vals[first]);
            rows.push(k);
            values.push(vals[first] * (1.0 + shift));
            rows.extend_from_slice(&cols[first + 1..]);
            values.extend_from_slice(&vals[first + 1..]);
            colptr.push(rows.len());
        }
        for k in 0..n {
            let (s, e) = (colptr[k], colptr[k + 1]);
            let d = values[s];
            let positive = d.is_finite() && d > 1e-12 * orig_diag[k].abs();
            if !positive {
                return None;
            }
            // l_kk = √d_k; l_ik = a_ik / l_kk
            let lkk = d.sqrt();
            values[s] = lkk;
            for p in s + 1..e {
                values[p] /= lkk;
            }
            // Schur update of the trailing matrix on the pattern: a_ij −= l_ik·l_jk.
            for q in s + 1..e {
                let (j, ljk) = (rows[q], values[q]);
                values[colptr[j]] -= ljk * ljk;
                for p in q + 1..e {
                    let (i, lik) = (rows[p], values[p]);
                    let (cs, ce) = (colptr[j] + 1, colptr[j + 1]);
                    if let Ok(pos) = rows[cs..ce].binary_search(&i) {
                        values[cs + pos] -= lik * ljk;
                    }
                }
            }
        }
        Some(Ic0 {
            colptr,
            rows,
            values,
        })
    }

    /// z = (LLᵀ)⁻¹ r: L y = r column by column, then Lᵀ z = y row by row (row k of Lᵀ is
    /// column k of L).
    fn apply(&self, r: &[f64], z: &mut [f64]) {
        let n = r.len();
        z.copy_from_slice(r);
        for k in 0..n {
            let (s, e) = (self.colptr[k], self.colptr[k + 1]);
            let yk = z[k] / self.values[s];
            z[k] = yk;
            for p in s + 1..e {
                z[self.rows[p]] -= self.values[p] * yk;
            }
        }
        for k in (0..n).rev() {
            let (s, e) = (self.colptr[k], self.colptr[k + 1]);
            let mut acc = z[k];
            for p in s + 1..e {
                acc -= self.values[p] * z[self.rows[p]];
            }
            z[k] = acc / self.values[s];
        }
    }
}

/// Incomplete LU ILU(0) with the pattern of A (unit lower L, upper U stored together).
struct Ilu0<'a> {
    a: &'a Csr<'a>,
    values: Vec<f64>,
    /// Position of the diagonal entry in each row.
    diag: Vec<usize>,
}

impl<'a> Ilu0<'a> {
    /// Factorises A + shift·diag(A) (IKJ variant); `None` on a zero or non-finite pivot.
    fn factor(a: &'a Csr<'a>, shift: f64) -> Option<Ilu0<'a>> {
        let n = a.n;
        let mut values = a.data.to_vec();
        let mut diag = vec![usize::MAX; n];
        for i in 0..n {
            let (s, e) = (a.indptr[i], a.indptr[i + 1]);
            let p = a.indices[s..e].binary_search(&i).ok()? + s;
            diag[i] = p;
            values[p] *= 1.0 + shift;
        }
        let mut pos = vec![usize::MAX; n];
        for i in 0..n {
            let (s, e) = (a.indptr[i], a.indptr[i + 1]);
            for p in s..e {
                pos[a.indices[p]] = p;
            }
            for p in s..diag[i] {
                let k = a.indices[p];
                // l_ik = a_ik / u_kk; then row_i −= l_ik · row_k (U part, pattern-restricted).
                let lik = values[p] / values[diag[k]];
                values[p] = lik;
                for q in diag[k] + 1..a.indptr[k + 1] {
                    let pj = pos[a.indices[q]];
                    if pj != usize::MAX {
                        values[pj] -= lik * values[q];
                    }
                }
            }
            let d = values[diag[i]];
            if !d.is_finite() || d.abs() <= 1e-14 * a.data[diag[i]].abs() {
                return None;
            }
            for p in s..e {
                pos[a.indices[p]] = usize::MAX;
            }
        }
        Some(Ilu0 { a, values, diag })
    }

    /// z = (LU)⁻¹ r.
    fn apply(&self, r: &[f64], z: &mut [f64]) {
        let (ip, ix) = (&self.a.indptr, self.a.indices);
        let n = r.len();
        for i in 0..n {
            let mut acc = r[i];
            for p in ip[i]..self.diag[i] {
                acc -= self.values[p] * z[ix[p]];
            }
            z[i] = acc;
        }
        for i in (0..n).rev() {
            let mut acc = z[i];
            for p in self.diag[i] + 1..ip[i + 1] {
                acc -= self.values[p] * z[ix[p]];
            }
            z[i] = acc / self.values[self.diag[i]];
        }
    }
}

enum Precond<'a> {
    Identity,
    Jacobi(Vec<f64>),
    Ic0(Ic0),
    Ilu0(Ilu0<'a>),
    Amg(Amg),
}

impl Precond<'_> {
    fn apply(&self, r: &[f64], z: &mut [f64]) {
        match self {
            Precond::Identity => z.copy_from_slice(r),
            Precond::Jacobi(inv) => {
                for ((zi, ri), di) in z.iter_mut().zip(r).zip(inv) {
                    *zi = ri * di;
                }
            }
            Precond::Ic0(f) => f.apply(r, z),
            Precond::Ilu0(f) => f.apply(r, z),
            Precond::Amg(m) => m.apply(r, z),
        }
    }
}

/// An owned CSR matrix (rows × cols): the levels of the multigrid hierarchy.
struct Mat {
    rows: usize,
    cols: usize,
    indptr: Vec<usize>,
    indices: Vec<usize>,
    data: Vec<f64>,
}

impl Mat {
    fn from_csr(a: &Csr) -> Mat {
        Mat { rows: a.n, cols: a.n, indptr: a.indptr.to_vec(), indices: a.indices.to_vec(), data: a.data.to_vec() }
    }

    #[inline]
    fn row(&self, i: usize) -> (&[usize], &[f64]) {
        let (s, e) = (self.indptr[i], self.indptr[i + 1]);
        (&self.indices[s..e], &self.data[s..e])
    }

    /// y = A·x, parallel over rows when the matrix is large.
    fn spmv(&self, x: &[f64], y: &mut [f64]) {
        let row_dot = |i: usize| -> f64 {
            let (cols, vals) = self.row(i);
            cols.iter().zip(vals).map(|(&j, &v)| v * x[j]).sum()
        };
        if self.rows >= PARALLEL_ROWS {
            y.par_iter_mut().enumerate().with_min_len(4096).for_each(|(i, yi)| *yi = row_dot(i));
        } else {
            for (i, yi) in y.iter_mut().enumerate() {
                *yi = row_dot(i);
            }
        }
    }

    /// Aᵀ (count → prefix sum → fill; rows come out sorted).
    fn transpose(&self) -> Mat {
        let mut indptr = vec![0usize; self.cols + 1];
        for &j in &self.indices {
            indptr[j + 1] += 1;
        }
        for j in 0..self.cols {
            indptr[j + 1] += indptr[j];
        }
        let mut fill = indptr.clone();
        let mut indices = vec![0usize; self.indices.len()];
        let mut data = vec![0.0; self.data.len()];
        for i in 0..self.rows {
            let (cols, vals) = self.row(i);
            for (&j, &v) in cols.iter().zip(vals) {
                indices[fill[j]] = i;
                data[fill[j]] = v;
                fill[j] += 1;
            }
        }
        Mat { rows: self.cols, cols: self.rows, indptr, indices, data }
    }

    /// A·B by rows with a dense accumulator (Gustavson 1978); rows come out sorted.
    fn mul(&self, b: &Mat) -> Mat {
        let mut indptr = Vec::with_capacity(self.rows + 1);
        let mut indices = Vec::new();
        let mut data = Vec::new();
        let mut acc = vec![0.0; b.cols];
        let mut mark = vec![usize::MAX; b.cols];
        let mut cols_here: Vec<usize> = Vec::new();
        indptr.push(0);
        for i in 0..self.rows {
            cols_here.clear();
            let (ac, av) = self.row(i);
            for (&k, &a_ik) in ac.iter().zip(av) {
                let (bc, bv) = b.row(k);
                for (&j, &b_kj) in bc.iter().zip(bv) {
                    if mark[j] != i {
                        mark[j] = i;
                        acc[j] = 0.0;
                        cols_here.push(j);
                    }
                    acc[j] += a_ik * b_kj;
                }
            }
            cols_here.sort_unstable();
            for &j in &cols_here {
                indices.push(j);
                data.push(acc[j]);
            }
            indptr.push(indices.len());
        }
        Mat { rows: self.rows, cols: b.cols, indptr, indices, data }
    }
}

/// Dense LU with partial pivoting: the coarsest multigrid level.
struct DenseLu {
    n: usize,
    lu: Vec<f64>,
    piv: Vec<usize>,
}

impl DenseLu {
    /// `None` when a pivot is negligible against the matrix scale (singular coarse matrix).
    fn factor(a: &Mat) -> Option<DenseLu> {
        let n = a.rows;
        let mut lu = vec![0.0; n * n];
        for i in 0..n {
            let (cols, vals) = a.row(i);
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

/// One level of the multigrid hierarchy: its matrix, and the prolongator to it from the next
/// coarser level (with its transpose, the restriction).
struct AmgLevel {
    a: Mat,
    inv_diag: Vec<f64>,
    p: Mat,
    r: Mat,
}

/// Smoothed-aggregation AMG used as a preconditioner: one V(1,1)-cycle with a forward
/// Gauss–Seidel pre-smoothing and a backward Gauss–Seidel post-smoothing sweep, so the cycle
/// is a symmetric operator for a symmetric A (as CG requires).
struct Amg {
    levels: Vec<AmgLevel>,
    coarse: DenseLu,
}

/// Strength-of-connection threshold: |a_IJ| ≥ θ·√(|a_II|·|a_JJ|).
const AMG_THETA: f64 = 0.08;
/// Stop coarsening at this many unknowns (solved densely).
const AMG_COARSEST: usize = 400;

impl Amg {
    fn build(a: &Csr, block: usize) -> Option<Amg> {
        if block == 0 || a.n % block != 0 || a.n == 0 {
            return None;
        }
        let mut levels = Vec::new();
        let mut cur = Mat::from_csr(a);
        while cur.rows > AMG_COARSEST && levels.len() < 30 {
            let inv_diag = inverse_diagonal(&cur)?;
            let (agg, n_agg) = aggregate(&cur, block);
            if n_agg * block * 10 > cur.rows * 9 {
                break; // coarsening stalled
            }
            let p = smoothed_prolongator(&cur, &inv_diag, &agg, block, n_agg * block);
            let r = p.transpose();
            // Galerkin coarse operator A_c = Pᵀ·A·P.
            let coarse = r.mul(&cur.mul(&p));
            levels.push(AmgLevel { a: cur, inv_diag, p, r });
            cur = coarse;
        }
        if cur.rows > 4 * AMG_COARSEST {
            return None; // a dense solve this large would cost more than it saves
        }
        if std::env::var_os("FOLDFREE_AMG_DEBUG").is_some() {
            for l in &levels {
                eprintln!("amg level rows {} nnz {}", l.a.rows, l.a.data.len());
            }
            eprintln!("amg coarse rows {} nnz {}", cur.rows, cur.data.len());
        }
        let coarse = DenseLu::factor(&cur)?;
        Some(Amg { levels, coarse })
    }

    fn apply(&self, r: &[f64], z: &mut [f64]) {
        self.cycle(0, r, z);
    }

    fn cycle(&self, l: usize, b: &[f64], x: &mut [f64]) {
        let Some(lev) = self.levels.get(l) else {
            self.coarse.solve(b, x);
            return;
        };
        x.fill(0.0);
        gauss_seidel(lev, b, x, false);
        // Coarse correction: x += P·cycle(Pᵀ(b − A x)).
        let mut res = vec![0.0; lev.a.rows];
        lev.a.spmv(x, &mut res);
        for (ri, bi) in res.iter_mut().zip(b) {
            *ri = bi - *ri;
        }
        let mut bc = vec![0.0; lev.r.rows];
        lev.r.spmv(&res, &mut bc);
        let mut xc = vec![0.0; lev.r.rows];
        self.cycle(l + 1, &bc, &mut xc);
        lev.p.spmv(&xc, &mut res);
        for (xi, ci) in x.iter_mut().zip(&res) {
            *xi += ci;
        }
        gauss_seidel(lev, b, x, true);
    }
}

/// 1/a_ii for every row; `None` if a diagonal is zero or not finite.
fn inverse_diagonal(a: &Mat) -> Option<Vec<f64>> {
    (0..a.rows)
        .map(|i| {
            let (cols, vals) = a.row(i);
            let d = cols.iter().position(|&j| j == i).map_or(0.0, |p| vals[p]);
            (d != 0.0 && d.is_finite()).then(|| 1.0 / d)
        })
        .collect()
}

/// One Gauss–Seidel sweep x_i ← (b_i − Σ_{j≠i} a_ij x_j)/a_ii, forward or backward.
fn gauss_seidel(lev: &AmgLevel, b: &[f64], x: &mut [f64], backward: bool) {
    let sweep = |i: usize, x: &mut [f64]| {
        let (cols, vals) = lev.a.row(i);
        let mut s = b[i];
        for (&j, &v) in cols.iter().zip(vals) {
            if j != i {
                s -= v * x[j];
            }
        }
        x[i] = s * lev.inv_diag[i];
    };
    if backward {
        for i in (0..lev.a.rows).rev() {
            sweep(i, x);
        }
    } else {
        for i in 0..lev.a.rows {
            sweep(i, x);
        }
    }
}

/// Greedy aggregation of the strong-connection graph between nodes (blocks of `block`
/// unknowns): (1) a node whose strong neighbours are all free seeds an aggregate with them,
/// (2) left-over nodes join a neighbouring aggregate of step 1, (3) the rest seed new
/// aggregates with their free neighbours. Returns node → aggregate and the aggregate count.
fn aggregate(a: &Mat, block: usize) -> (Vec<usize>, usize) {
    let nn = a.rows / block;
    // Node diagonal scale d_I = max_c |a_(I,c),(I,c)|.
    let mut diag = vec![0.0f64; nn];
    for i in 0..a.rows {
        let (cols, vals) = a.row(i);
        for (&j, &v) in cols.iter().zip(vals) {
            if j == i {
                diag[i / block] = diag[i / block].max(v.abs());
            }
        }
    }
    // Strong neighbours: max block entry |a_IJ| ≥ θ·√(d_I·d_J).
    let mut sptr = vec![0usize; nn + 1];
    let mut sidx = Vec::new();
    let mut mag = vec![0.0f64; nn];
    let mut touched = Vec::new();
    for node in 0..nn {
        for i in node * block..(node + 1) * block {
            let (cols, vals) = a.row(i);
            for (&j, &v) in cols.iter().zip(vals) {
                let other = j / block;
                if other != node {
                    if mag[other] == 0.0 {
                        touched.push(other);
                    }
                    mag[other] = mag[other].max(v.abs()).max(f64::MIN_POSITIVE);
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
            if let Some(&o) = sidx[sptr[node]..sptr[node + 1]].iter().find(|&&o| first[o] != FREE) {
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
fn smoothed_prolongator(a: &Mat, inv_diag: &[f64], agg: &[usize], block: usize, nc: usize) -> Mat {
    let coarse_of = |j: usize| agg[j / block] * block + j % block;
    let rho = (0..a.rows)
        .map(|i| a.row(i).1.iter().map(|v| v.abs()).sum::<f64>() * inv_diag[i].abs())
        .fold(0.0f64, f64::max);
    let omega = if rho > 0.0 { 4.0 / (3.0 * rho) } else { 0.0 };
    let mut indptr = Vec::with_capacity(a.rows + 1);
    let mut indices = Vec::new();
    let mut data = Vec::new();
    let mut acc = vec![0.0; nc];
    let mut mark = vec![usize::MAX; nc];
    let mut cols_here = Vec::new();
    indptr.push(0);
    for i in 0..a.rows {
        cols_here.clear();
        let mut put = |c: usize, v: f64, cols_here: &mut Vec<usize>| {
            if mark[c] != i {
                mark[c] = i;
                acc[c] = 0.0;
                cols_here.push(c);
            }
            acc[c] += v;
        };
        put(coarse_of(i), 1.0, &mut cols_here);
        let (cols, vals) = a.row(i);
        for (&j, &v) in cols.iter().zip(vals) {
            put(coarse_of(j), -omega * inv_diag[i] * v, &mut cols_here);
        }
        cols_here.sort_unstable();
        for &c in &cols_here {
            indices.push(c);
            data.push(acc[c]);
        }
        indptr.push(indices.len());
    }
    Mat { rows: a.rows, cols: nc, indptr, indices, data }
}

/// Diagonal shifts tried, in order, when an incomplete factorisation breaks down.
const SHIFTS: [f64; 4] = [0.0, 1e-3, 1e-2, 1e-1];

/// Builds the requested preconditioner (`spd`: IC(0), else ILU(0)); returns it with the kind
/// and shift actually used.
fn build_precond<'a>(
    a: &'a Csr<'a>,
    kind: Preconditioner,
    spd: bool,
) -> Result<(Precond<'a>, Preconditioner, f64), SolveError> {
    if kind == Preconditioner::None {
        return Ok((Precond::Identity, Preconditioner::None, 0.0));
    }
    if let Preconditioner::Amg { block_size } = kind {
        if let Some(amg) = Amg::build(a, block_size) {
            return Ok((Precond::Amg(amg), kind, 0.0));
        }
    }
    if matches!(kind, Preconditioner::Ic0 | Preconditioner::Amg { .. }) {
        for shift in SHIFTS {
            let built = if spd {
                Ic0::factor(a, shift).map(Precond::Ic0)
            } else {
                Ilu0::factor(a, shift).map(Precond::Ilu0)
            };
            if let Some(p) = built {
                return Ok((p, Preconditioner::Ic0, shift));
            }
        }
    }
    let diag = a.diagonal();
    let mut inv = Vec::with_capacity(diag.len());
    for (i, &d) in diag.iter().enumerate() {
        if !d.is_finite() {
            return Err(SolveError::NonFinite {
                what: format!("matrix diagonal at row {i}"),
            });
        }
        if spd && d < 0.0 {
            return Err(SolveError::Failed {
                what: format!("matrix is not positive definite: diagonal entry {d:e} at row {i}"),
            });
        }
        // A zero diagonal gets no scaling (an SPD matrix has none; BiCGSTAB copes).
        inv.push(if d == 0.0 { 1.0 } else { 1.0 / d });
    }
    Ok((Precond::Jacobi(inv), Preconditioner::Jacobi, 0.0))
}

fn check_inputs(a: &Csr, b: &[f64], x: &[f64]) -> Result<(), SolveError> {
    if b.len() != a.n || x.len() != a.n {
        return Err(SolveError::InvalidInput {
            what: format!(
                "matrix has {} rows but b has {} and x has {} entries",
                a.n,
                b.len(),
                x.len()
            ),
        });
    }
    if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite {
            what: format!("matrix entry {i}"),
        });
    }
    if let Some(i) = b.iter().position(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite {
            what: format!("right-hand side at row {i}"),
        });
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite {
            what: format!("initial guess at row {i}"),
        });
    }
    Ok(())
}

/// Solves the symmetric positive definite system A·x = b by preconditioned conjugate
/// gradient, starting from (warm start) and overwriting `x`.
///
/// `a` is n×n CSR and must be symmetric positive definite (only checked through the CG
/// recurrences: a non-positive curvature pᵀAp ≤ 0 is reported as [`SolveError::Failed`]).
/// b = 0 returns x = 0 at once.
pub fn pcg(
    a: &CsMat<f64>,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<CgStats, SolveError> {
    let m = Csr::new(a)?;
    check_inputs(&m, b, x)?;
    let (pre, kind, shift) = build_precond(&m, opts.preconditioner, true)?;
    pcg_with(&m, &pre, b, x, opts).map(|(iterations, relative_residual)| CgStats {
        iterations,
        relative_residual,
        preconditioner: kind,
        shift,
    })
}

/// [`pcg`] for several right-hand sides sharing one matrix (e.g. the u and v columns of a
/// map): the preconditioner is built once and the columns are solved in parallel.
pub fn pcg_multi(
    a: &CsMat<f64>,
    b: &[Vec<f64>],
    x: &mut [Vec<f64>],
    opts: &CgOptions,
) -> Result<Vec<CgStats>, SolveError> {
    if b.len() != x.len() {
        return Err(SolveError::InvalidInput {
            what: format!(
                "{} right-hand sides but {} solution vectors",
                b.len(),
                x.len()
            ),
        });
    }
    let m = Csr::new(a)?;
    for (bi, xi) in b.iter().zip(x.iter()) {
        check_inputs(&m, bi, xi)?;
    }
    let (pre, kind, shift) = build_precond(&m, opts.preconditioner, true)?;
    b.par_iter()
        .zip(x.par_iter_mut())
        .map(|(bi, xi)| {
            pcg_with(&m, &pre, bi, xi, opts).map(|(iterations, relative_residual)| CgStats {
                iterations,
                relative_residual,
                preconditioner: kind,
                shift,
            })
        })
        .collect()
}

/// The CG iteration proper; returns (iterations, true relative residual).
fn pcg_with(
    a: &Csr,
    pre: &Precond,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<(usize, f64), SolveError> {
    let n = a.n;
    let bnorm = norm(b);
    if bnorm == 0.0 {
        x.fill(0.0);
        return Ok((0, 0.0));
    }
    let tol = opts.tolerance * bnorm;
    let mut r = vec![0.0; n];
    let mut rnorm = residual(a, b, x, &mut r);
    if rnorm <= tol {
        return Ok((0, rnorm / bnorm));
    }
    let mut z = vec![0.0; n];
    let mut q = vec![0.0; n];
    pre.apply(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    // Consecutive "converged by recurrence, not by true residual" restarts allowed.
    let mut restarts = 0;
    for it in 1..=opts.max_iterations {
        a.spmv(&p, &mut q);
        let pq = dot(&p, &q);
        if !pq.is_finite() || !rz.is_finite() {
            return Err(SolveError::NonFinite {
                what: format!("conjugate gradient iterate {it}"),
            });
        }
        if pq <= 0.0 {
            return Err(SolveError::Failed { what: format!("conjugate gradient: non-positive curvature pᵀAp = {pq:e} at iteration {it} (matrix not positive definite)") });
        }
        // α = rᵀz / pᵀAp; x += αp; r −= αAp
        let alpha = rz / pq;
        for i in 0..n {
            x[i] += alpha * p[i];
            r[i] -= alpha * q[i];
        }
        rnorm = norm(&r);
        if !rnorm.is_finite() {
            return Err(SolveError::NonFinite {
                what: format!("conjugate gradient residual at iteration {it}"),
            });
        }
        if rnorm <= tol {
            let true_norm = residual(a, b, x, &mut r);
            if true_norm <= tol {
                return Ok((it, true_norm / bnorm));
            }
            restarts += 1;
            if restarts > 8 {
                return Err(SolveError::CgNoConvergence {
                    iterations: it,
                    residual: true_norm / bnorm,
                    tolerance: opts.tolerance,
                });
            }
            // Restart from the true residual (the recurrence had drifted).
            pre.apply(&r, &mut z);
            p.copy_from_slice(&z);
            rz = dot(&r, &z);
            continue;
        }
        pre.apply(&r, &mut z);
        let rz_new = dot(&r, &z);
        // β = r₊ᵀz₊ / rᵀz; p = z + βp
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
    }
    let true_norm = residual(a, b, x, &mut r);
    if true_norm <= tol {
        return Ok((opts.max_iterations, true_norm / bnorm));
    }
    Err(SolveError::CgNoConvergence {
        iterations: opts.max_iterations,
        residual: true_norm / bnorm,
        tolerance: opts.tolerance,
    })
}

/// Solves a general (non-symmetric) square system A·x = b by right-preconditioned BiCGSTAB,
/// warm-started from `x`.
///
/// Chosen for the mean-value Tutte system: its rows are convex-combination weights, so the
/// matrix is a non-symmetric, diagonally dominant M-matrix on which BiCGSTAB with ILU(0)
/// converges in a few dozen iterations, at the cost of two SpMVs per iteration and no
/// growing Krylov basis (GMRES) or squared condition number (normal equations).
/// `Preconditioner::Ic0` selects ILU(0) here. Breakdowns (ρ = 0 or ω = 0) restart the
/// iteration from the current iterate.
pub fn bicgstab(
    a: &CsMat<f64>,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<CgStats, SolveError> {
    let m = Csr::new(a)?;
    check_inputs(&m, b, x)?;
    let (pre, kind, shift) = build_precond(&m, opts.preconditioner, false)?;
    bicgstab_with(&m, &pre, b, x, opts).map(|(iterations, relative_residual)| CgStats {
        iterations,
        relative_residual,
        preconditioner: kind,
        shift,
    })
}

/// [`bicgstab`] for several right-hand sides sharing one matrix, solved in parallel.
pub fn bicgstab_multi(
    a: &CsMat<f64>,
    b: &[Vec<f64>],
    x: &mut [Vec<f64>],
    opts: &CgOptions,
) -> Result<Vec<CgStats>, SolveError> {
    if b.len() != x.len() {
        return Err(SolveError::InvalidInput {
            what: format!(
                "{} right-hand sides but {} solution vectors",
                b.len(),
                x.len()
            ),
        });
    }
    let m = Csr::new(a)?;
    for (bi, xi) in b.iter().zip(x.iter()) {
        check_inputs(&m, bi, xi)?;
    }
    let (pre, kind, shift) = build_precond(&m, opts.preconditioner, false)?;
    b.par_iter()
        .zip(x.par_iter_mut())
        .map(|(bi, xi)| {
            bicgstab_with(&m, &pre, bi, xi, opts).map(|(iterations, relative_residual)| CgStats {
                iterations,
                relative_residual,
                preconditioner: kind,
                shift,
            })
        })
        .collect()
}

fn bicgstab_with(
    a: &Csr,
    pre: &Precond,
    b: &[f64],
    x: &mut [f64],
    opts: &CgOptions,
) -> Result<(usize, f64), SolveError> {
    let n = a.n;
    let bnorm = norm(b);
    if bnorm == 0.0 {
        x.fill(0.0);
        return Ok((0, 0.0));
    }
    let tol = opts.tolerance * bnorm;
    let mut r = vec![0.0; n];
    let rnorm0 = residual(a, b, x, &mut r);
    if rnorm0 <= tol {
        return Ok((0, rnorm0 / bnorm));
    }
    let mut r_hat = r.clone();
    let (mut rho, mut alpha, mut omega) = (1.0, 1.0, 1.0);
    let mut v = vec![0.0; n];
    let mut p = vec![0.0; n];
    let mut p_hat = vec![0.0; n];
    let mut s = vec![0.0; n];
    let mut s_hat = vec![0.0; n];
    let mut t = vec![0.0; n];
    let mut restarts = 0;
    let mut it = 0;
    while it < opts.max_iterations {
        it += 1;
        let rho_new = dot(&r_hat, &r);
        if !rho_new.is_finite() {
            return Err(SolveError::NonFinite {
                what: format!("BiCGSTAB iterate {it}"),
            });
        }
        if rho_new.abs() < 1e-300 || omega == 0.0 {
            // Breakdown: restart with the shadow residual r̂ = r.
            restarts += 1;
            if restarts > 20 {
                break;
            }
            residual(a, b, x, &mut r);
            r_hat.copy_from_slice(&r);
            (rho, alpha, omega) = (1.0, 1.0, 1.0);
            v.fill(0.0);
            p.fill(0.0);
            continue;
        }
        // β = (ρ₊/ρ)(α/ω); p = r + β(p − ωv)
        let beta = (rho_new / rho) * (alpha / omega);
        rho = rho_new;
        for i in 0..n {
            p[i] = r[i] + beta * (p[i] - omega * v[i]);
        }
        pre.apply(&p, &mut p_hat);
        a.spmv(&p_hat, &mut v);
        let rv = dot(&r_hat, &v);
        if rv == 0.0 || !rv.is_finite() {
            rho = 0.0;
            omega = 0.0;
            continue;
        }
        // α = ρ / r̂ᵀv; s = r − αv
        alpha = rho / rv;
        for i in 0..n {
            s[i] = r[i] - alpha * v[i];
        }
        if norm(&s) <= tol {
            for i in 0..n {
                x[i] += alpha * p_hat[i];
            }
            let true_norm = residual(a, b, x, &mut r);
            if true_norm <= tol {
                return Ok((it, true_norm / bnorm));
            }
            omega = 0.0; // forces a restart from the true residual
            continue;
        }
        pre.apply(&s, &mut s_hat);
        a.spmv(&s_hat, &mut t);
        let tt = dot(&t, &t);
        // ω = tᵀs / tᵀt; x += αp̂ + ωŝ; r = s − ωt
        omega = if tt > 0.0 { dot(&t, &s) / tt } else { 0.0 };
        for i in 0..n {
            x[i] += alpha * p_hat[i] + omega * s_hat[i];
            r[i] = s[i] - omega * t[i];
        }
        let rnorm = norm(&r);
        if !rnorm.is_finite() {
            return Err(SolveError::NonFinite {
                what: format!("BiCGSTAB residual at iteration {it}"),
            });
        }
        if rnorm <= tol {
            let true_norm = residual(a, b, x, &mut r);
            if true_norm <= tol {
                return Ok((it, true_norm / bnorm));
            }
            omega = 0.0;
        }
    }
    let true_norm = residual(a, b, x, &mut r);
    if true_norm <= tol {
        return Ok((it, true_norm / bnorm));
    }
    Err(SolveError::CgNoConvergence {
        iterations: it,
        residual: true_norm / bnorm,
        tolerance: opts.tolerance,
    })
}
