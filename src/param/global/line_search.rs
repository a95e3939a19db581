//! Step length: the largest step that flips no face, then Armijo backtracking.
//!
//! Along `x + t d` each face's Jacobian is `A + t D`, so `det(A + t D)` is a quadratic in `t`
//! and its first positive root bounds the step for that face (Smith & Schaefer 2015). Taking
//! a fixed fraction of the minimum over faces keeps every face strictly positive; the energies
//! are +∞ at `det ≤ 0` besides, so backtracking could never accept a fold even if the
//! rounding of the root were off.

use rayon::prelude::*;

use super::assembly::{jacobian, FaceGradient};
use crate::param::energy::max_flip_free_step;

/// Fraction of the largest flip-free step taken at most.
pub const FLIP_FREE_FRACTION: f64 = 0.85;

/// Armijo sufficient-decrease constant.
pub const ARMIJO: f64 = 1e-4;

/// Halvings before the search gives up.
pub const MAX_HALVINGS: usize = 50;

/// Largest `t` such that no face of `x + τ d`, τ ∈ [0, t), is degenerate or flipped
/// (∞ when no face ever flips along `d`).
pub fn max_flip_free(grads: &[FaceGradient], faces: &[[u32; 3]], x: &[f64], d: &[f64]) -> f64 {
    faces
        .par_iter()
        .zip(grads.par_iter())
        .map(|(f, g)| max_flip_free_step(&jacobian(g, f, x), &jacobian(g, f, d)))
        .reduce(|| f64::INFINITY, f64::min)
}

/// What [`armijo`] accepted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Accepted {
    pub step: f64,
    pub value: f64,
}

/// Backtracks from `t0` by halving until `f(x + t d) ≤ f0 + c t slope`; `None` when no step
/// in [`MAX_HALVINGS`] halvings decreases enough (or `slope` is not a descent slope).
pub fn armijo(
    f: &dyn Fn(&[f64]) -> f64,
    x: &[f64],
    d: &[f64],
    f0: f64,
    slope: f64,
    t0: f64,
) -> Option<Accepted> {
    if !(slope < 0.0 && t0 > 0.0 && t0.is_finite() && f0.is_finite()) {
        return None;
    }
    let mut t = t0;
    let mut y = vec![0.0; x.len()];
    for _ in 0..MAX_HALVINGS {
        y.par_iter_mut()
            .zip(x.par_iter().zip(d.par_iter()))
            .for_each(|(yi, (xi, di))| *yi = xi + t * di);
        let v = f(&y);
        if v.is_finite() && v <= f0 + ARMIJO * t * slope {
            return Some(Accepted { step: t, value: v });
        }
        t *= 0.5;
    }
    None
}
