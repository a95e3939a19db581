//! Limited-memory BFGS (Nocedal 1980; two-loop recursion and initial scaling γ = sᵀy/yᵀy as in
//! Nocedal & Wright, *Numerical Optimization*, 2nd ed. 2006, Algorithm 7.4 and eq. 7.20) with
//! backtracking Armijo steps, and the ε schedule of the regularised barrier of Garanzha,
//! Kaporin, Kudryavtseva, Protais, Ray & Sokolov (2021, "Foldover-free maps in 50 lines of
//! code"). The tet untangler of `volmap` (`vol::untangle`) minimises that barrier round by
//! round with it; the energy ([`Objective`]) lives with the untangler, so another barrier
//! problem reuses the minimiser and the schedule as they are.
#![forbid(unsafe_code)]

/// A smooth energy over a flat vector of unknowns.
pub trait Objective {
    type Error;
    /// Energy at `x`, its gradient written to `g` (restricted to the directions the problem
    /// may move in: zero on fixed unknowns, tangent on constrained ones).
    fn value_grad(&mut self, x: &[f64], g: &mut [f64]) -> Result<f64, Self::Error>;
    /// Scale `s` of the steepest-descent step −s·g taken without curvature information (the
    /// first step, or a restart after a non-descent direction); `None`: no step (stop).
    fn steepest_scale(&self, g: &[f64]) -> Option<f64>;
    /// The inner product of the recursion (the plain slice dot product by default).
    fn dot(&self, a: &[f64], b: &[f64]) -> f64 {
        super::dot(a, b)
    }
    /// Maps a trial point back onto the feasible set after a step (none by default).
    fn retract(&self, _x: &mut [f64]) {}
}

/// Stopping rules and memory of [`minimise`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LbfgsOptions {
    /// Pairs (s, y) kept.
    pub memory: usize,
    /// Cap on iterations (line searches).
    pub max_iterations: usize,
    /// Stop before a step when ‖g‖ ≤ this·(1 + |E|) or E is not finite (`None`: no such test).
    pub gradient_tolerance: Option<f64>,
    /// Stop after an accepted step that lowered E by ≤ this·|E|.
    pub rel_decrease: f64,
    /// A pair is stored when sᵀy > max(`curvature_rel`·yᵀy, `curvature_abs`).
    pub curvature_rel: f64,
    pub curvature_abs: f64,
}

/// Armijo sufficient-decrease constant.
const ARMIJO: f64 = 1e-4;
/// Step halvings before a line search gives up.
const HALVINGS: usize = 40;

/// What [`minimise`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LbfgsResult {
    /// Energy at the start.
    pub initial_energy: f64,
    /// Energy at the returned `x`.
    pub energy: f64,
    /// Line searches run (accepted or not).
    pub iterations: usize,
    /// Energy evaluations in the line searches.
    pub evaluations: usize,
}

/// One memory entry: step s, gradient change y, 1/(sᵀy).
type Pair = (Vec<f64>, Vec<f64>, f64);

/// Minimises `f` from `x` (overwritten with the last accepted iterate). Stops at the iteration
/// cap, on a failed line search, or by the tests of `opts`.
pub fn minimise<O: Objective>(
    f: &mut O,
    x: &mut [f64],
    opts: &LbfgsOptions,
) -> Result<LbfgsResult, O::Error> {
    let n = x.len();
    let mut g = vec![0.0; n];
    let mut e = f.value_grad(x, &mut g)?;
    let mut hist: Vec<Pair> = Vec::new();
    let mut trial = vec![0.0; n];
    let mut g_new = vec![0.0; n];
    let mut dir = vec![0.0; n];
    let mut alpha = Vec::with_capacity(opts.memory);
    let mut out = LbfgsResult {
        initial_energy: e,
        energy: e,
        iterations: 0,
        evaluations: 0,
    };
    for _ in 0..opts.max_iterations {
        if let Some(tol) = opts.gradient_tolerance {
            if f.dot(&g, &g).sqrt() <= tol * (1.0 + e.abs()) || !e.is_finite() {
                break;
            }
        }
        // Two-loop recursion: dir = −H·g.
        dir.copy_from_slice(&g);
        alpha.clear();
        for (s, y, rho) in hist.iter().rev() {
            let a = rho * f.dot(s, &dir);
            dir.iter_mut().zip(y).for_each(|(q, yi)| *q -= a * yi);
            alpha.push(a);
        }
        let gamma = match hist.last() {
            Some((s, y, _)) => f.dot(s, y) / f.dot(y, y),
            None => f.steepest_scale(&g).unwrap_or(1.0),
        };
        dir.iter_mut().for_each(|q| *q *= gamma);
        for ((s, y, rho), a) in hist.iter().zip(alpha.iter().rev()) {
            let b = rho * f.dot(y, &dir);
            dir.iter_mut().zip(s).for_each(|(q, si)| *q += (a - b) * si);
        }
        dir.iter_mut().for_each(|q| *q = -*q);
        let mut slope = f.dot(&dir, &g);
        if !slope.is_finite() || slope >= 0.0 {
            // Lost curvature information: restart from steepest descent.
            hist.clear();
            let Some(sc) = f.steepest_scale(&g) else {
                break;
            };
            for (q, gv) in dir.iter_mut().zip(&g) {
                *q = -sc * gv;
            }
            slope = f.dot(&dir, &g);
        }
        let mut t = 1.0;
        let mut accepted = None;
        for _ in 0..HALVINGS {
            out.evaluations += 1;
            for ((p, xi), d) in trial.iter_mut().zip(x.iter()).zip(&dir) {
                *p = xi + t * d;
            }
            f.retract(&mut trial);
            let et = f.value_grad(&trial, &mut g_new)?;
            if et.is_finite() && et <= e + ARMIJO * t * slope {
                accepted = Some(et);
                break;
            }
            t *= 0.5;
        }
        out.iterations += 1;
        let Some(et) = accepted else {
            break;
        };
        // The step actually taken (a retraction may shorten it).
        let s: Vec<f64> = trial.iter().zip(x.iter()).map(|(a, b)| a - b).collect();
        let y: Vec<f64> = g_new.iter().zip(&g).map(|(a, b)| a - b).collect();
        x.copy_from_slice(&trial);
        std::mem::swap(&mut g, &mut g_new);
        let de = e - et;
        e = et;
        out.energy = e;
        let sy = f.dot(&s, &y);
        if sy > (opts.curvature_rel * f.dot(&y, &y)).max(opts.curvature_abs) {
            if hist.len() == opts.memory {
                hist.remove(0);
            }
            hist.push((s, y, 1.0 / sy));
        }
        if de <= opts.rel_decrease * e.abs() {
            break;
        }
    }
    Ok(out)
}

/// The next ε of Garanzha et al.: aim for χ(min det) to shrink by the relative energy decrease
/// σ = max(1 − E/E_prev, 0.1) of the round, `chi_min` = χ(min det, ε); once the smallest
/// determinant is above that aim, a negligible ε.
pub fn next_eps(e: f64, e_prev: f64, min_det: f64, chi_min: f64) -> f64 {
    let sigma = (1.0 - e / e_prev).max(0.1);
    let mu = (1.0 - sigma) * chi_min;
    if min_det < mu {
        2.0 * (mu * (mu - min_det)).sqrt()
    } else {
        1e-10
    }
}
