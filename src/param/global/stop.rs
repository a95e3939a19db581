//! The global solver's stop test, apart from the solver so it can be checked on scripted
//! histories: converged when the energy has stopped decreasing (a window of relative
//! decreases under tolerance) or, sufficient but not necessary, when the scale-free gradient
//! norm is under its tolerance. Both judge only the true problem: while progressive references
//! cap some faces the objective is a surrogate, and its decrease says nothing about the energy.

use super::GlobalOptions;

/// State of the stop test over one solve.
#[derive(Clone, Debug)]
pub struct StopTest {
    grad_tol: f64,
    energy_tol: f64,
    window: usize,
    /// True energies of the iterations since the references became the rest triangles.
    energies: Vec<f64>,
    /// `(E_{k−W} − E_k) / (W · E_k)` after the last step (∞ before there were W + 1 energies).
    decrease: f64,
}

impl StopTest {
    pub fn new(opts: &GlobalOptions) -> StopTest {
        StopTest {
            grad_tol: opts.grad_tol,
            energy_tol: opts.energy_tol,
            window: opts.energy_window.max(1),
            energies: Vec::new(),
            decrease: f64::INFINITY,
        }
    }

    /// Before a step: the gradient test at the current iterate (`capped` faces on progressive
    /// references: 0 is the true problem).
    pub fn gradient_met(&self, grad_norm: f64, capped: usize) -> bool {
        capped == 0 && grad_norm <= self.grad_tol
    }

    /// After a step to true energy `energy` taken with `capped` faces on progressive
    /// references: whether the energy has stopped decreasing.
    pub fn energy_met(&mut self, energy: f64, capped: usize) -> bool {
        if capped > 0 {
            self.energies.clear();
            self.decrease = f64::INFINITY;
            return false;
        }
        self.energies.push(energy);
        let n = self.energies.len();
        if n <= self.window {
            return false;
        }
        let old = self.energies[n - 1 - self.window];
        self.decrease = (old - energy) / (self.window as f64 * energy.abs());
        self.decrease <= self.energy_tol
    }

    /// The relative decrease per iteration over the last window (∞ until there was one).
    pub fn decrease(&self) -> f64 {
        self.decrease
    }

    pub fn window(&self) -> usize {
        self.window
    }
}
