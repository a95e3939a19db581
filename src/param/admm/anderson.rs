//! Anderson acceleration of the ADMM fixed-point map (Zhang, Peng, Ouyang, Deng 2019,
//! "Accelerating ADMM for efficient simulation and optimization").
//!
//! One ADMM iteration is a map `G` of the edge state: the face step reads only `Y` and `Λ` (its
//! warm start `A` has no influence on the exact minimiser), the edge and dual steps then produce
//! the next `(Y, Λ)`, which the CPU backend reduces to `w = Y − Λ/μ` (see
//! `cpu::pack_state`: `Y` and `Λ/μ` are the two orthogonal components of `w`). Plain ADMM is the fixed-point iteration `x ← G(x)`,
//! which converges linearly and, for symmetric Dirichlet on large meshes, slowly: the consensus
//! moves information about one face per iteration. Anderson acceleration extrapolates from the
//! last `m` iterates, `x⁺ = G(x) − Σ_j θ_j ΔG_j` with `θ = argmin ‖f − Σ_j θ_j Δf_j‖`
//! (`f = G(x) − x`), solved here through the `m×m` normal equations with a small ridge, the
//! form the device port would use (partial dot products by reduction, one tiny solve).
//!
//! The dual enters scaled by `1/μ` so it is in the units of a Jacobian. A change of `μ` changes
//! `G` itself, so the history must be discarded then ([`Anderson::reset`]).

#![forbid(unsafe_code)]

use rayon::prelude::*;

/// Elements per partial dot product (fixed, so sums do not depend on work stealing and runs
/// are reproducible bit for bit).
const DOT_CHUNK: usize = 8192;

/// Relative ridge added to the normal equations' diagonal: Δf columns become nearly collinear
/// as the iteration converges, and an unregularised solve then returns huge, cancelling θ.
const RIDGE: f64 = 1e-10;

/// History of differences and the Gram matrix of the `Δf` columns.
#[derive(Clone, Debug)]
pub struct Anderson {
    depth: usize,
    /// Ring buffer of `ΔG_j = G(x_j+1) − G(x_j)`. f64: the combination `Σ θ_j ΔG_j` has large
    /// θ of both signs when the Δf are nearly collinear, so it cancels, and f32 differences
    /// lose the digits the extrapolation needs (measured: 1.7× the iterations, BENCHMARKS.md).
    dg: Vec<Vec<f64>>,
    /// Ring buffer of `Δf_j = f_j+1 − f_j`.
    df: Vec<Vec<f64>>,
    /// `gram[i·depth + j] = Δf_i · Δf_j` over the stored columns.
    gram: Vec<f64>,
    /// Stored columns (≤ depth) and the ring position of the next one.
    count: usize,
    head: usize,
    prev_g: Vec<f64>,
    prev_f: Vec<f64>,
    has_prev: bool,
}

impl Anderson {
    /// `depth` = number of stored differences `m` (≥ 1).
    pub fn new(depth: usize) -> Anderson {
        let depth = depth.max(1);
        Anderson {
            depth,
            dg: vec![Vec::new(); depth],
            df: vec![Vec::new(); depth],
            gram: vec![0.0; depth * depth],
            count: 0,
            head: 0,
            prev_g: Vec::new(),
            prev_f: Vec::new(),
            has_prev: false,
        }
    }

    pub fn depth(&self) -> usize {
        self.depth
    }

    /// Forgets the history (after a rejected step or a change of the map).
    pub fn reset(&mut self) {
        self.count = 0;
        self.head = 0;
        self.has_prev = false;
    }

    /// The last plain (unaccelerated) output `G(x)` given to [`Anderson::step`]: it is kept for
    /// the next difference anyway, so the caller's safeguard can fall back to it without a copy
    /// of its own. Empty before the first step.
    pub fn last_plain(&self) -> &[f64] {
        &self.prev_g
    }

    /// Given the input `x` of one ADMM iteration and its output `g = G(x)`, writes the
    /// accelerated next input into `g` (in place). With no stored difference yet the plain step
    /// `G(x)` is left unchanged. Two passes over the data: the differences fused with all Gram
    /// and right-hand-side dot products (chunk by chunk, while the chunk is in cache), then the
    /// combination.
    pub fn step(&mut self, x: &[f64], g: &mut [f64]) {
        let n = x.len();
        debug_assert_eq!(g.len(), n);
        let slot = self.head;
        let with_prev = self.has_prev && self.prev_f.len() == n;
        let mut prev_f = std::mem::take(&mut self.prev_f);
        let mut prev_g = std::mem::take(&mut self.prev_g);
        prev_f.resize(n, 0.0);
        prev_g.resize(n, 0.0);
        if !with_prev {
            prev_f
                .par_chunks_mut(DOT_CHUNK)
                .zip(prev_g.par_chunks_mut(DOT_CHUNK))
                .zip(x.par_chunks(DOT_CHUNK).zip(g.par_chunks(DOT_CHUNK)))
                .for_each(|((pf, pg), (x, g))| {
                    for i in 0..x.len() {
                        pf[i] = g[i] - x[i];
                        pg[i] = g[i];
                    }
                });
            self.prev_f = prev_f;
            self.prev_g = prev_g;
            self.has_prev = true;
            return;
        }
        let mut new_df = std::mem::take(&mut self.df[slot]);
        let mut new_dg = std::mem::take(&mut self.dg[slot]);
        new_df.resize(n, 0.0);
        new_dg.resize(n, 0.0);
        self.head = (self.head + 1) % self.depth;
        self.count = (self.count + 1).min(self.depth);
        let m = self.count;
        // Per chunk: the new differences, then [gram row (m) | rhs (m)] against the stored
        // columns (the slot being refilled is read from the new chunk) and f = g − x.
        let cols = &self.df[..m];
        let sums = prev_f
            .par_chunks_mut(DOT_CHUNK)
            .zip(prev_g.par_chunks_mut(DOT_CHUNK))
            .zip(new_df.par_chunks_mut(DOT_CHUNK))
            .zip(new_dg.par_chunks_mut(DOT_CHUNK))
            .zip(x.par_chunks(DOT_CHUNK).zip(g.par_chunks(DOT_CHUNK)))
            .enumerate()
            .map(|(c, ((((pf, pg), df), dg), (x, g)))| {
                for i in 0..x.len() {
                    let f = g[i] - x[i];
                    df[i] = f - pf[i];
                    dg[i] = g[i] - pg[i];
                    pf[i] = f;
                    pg[i] = g[i];
                }
                let o = c * DOT_CHUNK;
                let mut acc = vec![0.0; 2 * m];
                for (j, col) in cols.iter().enumerate() {
                    let col: &[f64] = if j == slot { df } else { &col[o..o + x.len()] };
                    let (mut gj, mut rj) = (0.0, 0.0);
                    for i in 0..col.len() {
                        gj += df[i] * col[i];
                        rj += col[i] * pf[i];
                    }
                    acc[j] = gj;
                    acc[m + j] = rj;
                }
                acc
            })
            .collect::<Vec<_>>()
            .iter()
            .fold(vec![0.0; 2 * m], |mut a, b| {
                for (a, b) in a.iter_mut().zip(b) {
                    *a += b;
                }
                a
            });
        self.df[slot] = new_df;
        self.dg[slot] = new_dg;
        self.prev_f = prev_f;
        self.prev_g = prev_g;
        for j in 0..m {
            self.gram[slot * self.depth + j] = sums[j];
            self.gram[j * self.depth + slot] = sums[j];
        }
        let Some(theta) = solve_ridge(&self.gram, self.depth, m, &sums[m..]) else {
            return;
        };
        let dg = &self.dg[..m];
        g.par_chunks_mut(DOT_CHUNK)
            .enumerate()
            .for_each(|(c, out)| {
                let o = c * DOT_CHUNK;
                for (t, d) in theta.iter().zip(dg) {
                    let d = &d[o..o + out.len()];
                    for (v, d) in out.iter_mut().zip(d) {
                        *v -= t * d;
                    }
                }
            });
    }
}

/// Solves `(G + ridge·I) θ = rhs` for the leading `m×m` block of the `stride`-wide `gram` by
/// Cholesky; `None` when it is not positive definite even with the ridge or θ is not finite.
pub fn solve_ridge(gram: &[f64], stride: usize, m: usize, rhs: &[f64]) -> Option<Vec<f64>> {
    let scale = (0..m).map(|i| gram[i * stride + i]).fold(0.0, f64::max);
    if !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    let ridge = RIDGE * scale;
    // Lower-triangular factor, row-major m×m.
    let mut l = vec![0.0; m * m];
    for i in 0..m {
        for j in 0..=i {
            let mut s = gram[i * stride + j] + if i == j { ridge } else { 0.0 };
            for k in 0..j {
                s -= l[i * m + k] * l[j * m + k];
            }
            if i == j {
                if s <= 0.0 {
                    return None;
                }
                l[i * m + i] = s.sqrt();
            } else {
                l[i * m + j] = s / l[j * m + j];
            }
        }
    }
    let mut y = vec![0.0; m];
    for i in 0..m {
        let mut s = rhs[i];
        for k in 0..i {
            s -= l[i * m + k] * y[k];
        }
        y[i] = s / l[i * m + i];
    }
    let mut t = vec![0.0; m];
    for i in (0..m).rev() {
        let mut s = y[i];
        for k in i + 1..m {
            s -= l[k * m + i] * t[k];
        }
        t[i] = s / l[i * m + i];
    }
    t.iter().all(|v| v.is_finite()).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ridge_solve_matches_a_known_system() {
        // G = [[4, 2], [2, 3]], θ = [1, -2] → rhs = [0, -4].
        let g = [4.0, 2.0, 2.0, 3.0];
        let t = solve_ridge(&g, 2, 2, &[0.0, -4.0]).expect("positive definite");
        assert!(
            (t[0] - 1.0).abs() < 1e-8 && (t[1] + 2.0).abs() < 1e-8,
            "{t:?}"
        );
        assert!(solve_ridge(&[0.0; 4], 2, 2, &[1.0, 1.0]).is_none());
    }

    /// On a linear contraction `G(x) = Mx + b` Anderson reaches the fixed point far sooner
    /// than the plain iteration (for a linear map of dimension ≤ m it is exact after m+1 steps).
    #[test]
    fn accelerates_a_linear_contraction() {
        let n = 5;
        // Symmetric M with eigenvalues near 1 (slow plain iteration).
        let eig = [0.99, 0.95, 0.9, 0.5, -0.3];
        let b: Vec<f64> = (0..n).map(|i| 1.0 + i as f64).collect();
        let g_of = |x: &[f64]| -> Vec<f64> { (0..n).map(|i| eig[i] * x[i] + b[i]).collect() };
        let fixed: Vec<f64> = (0..n).map(|i| b[i] / (1.0 - eig[i])).collect();
        let err = |x: &[f64]| -> f64 {
            x.iter()
                .zip(&fixed)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let mut aa = Anderson::new(6);
        let mut x = vec![0.0; n];
        let mut plain = vec![0.0; n];
        for _ in 0..12 {
            let mut g = g_of(&x);
            aa.step(&x, &mut g);
            x = g;
            plain = g_of(&plain);
        }
        assert!(err(&x) < 1e-6, "anderson error {}", err(&x));
        assert!(err(&plain) > 1.0, "plain error {}", err(&plain));
    }
}
