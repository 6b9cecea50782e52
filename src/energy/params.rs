//! Parameters, outcome and errors of the energy minimisation.

use crate::params::{ParamError, in_range};
/// Which minimiser runs (`--energy-solver`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EnergySolver {
    /// Global L-BFGS with a certified Armijo line search.
    #[default]
    Lbfgs,
    /// Coloured local Newton (one control point at a time, a colour in parallel).
    Colored,
}

/// The length² that makes S_e comparable with D.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EnergyScale {
    /// h_e² of each element: every element weighs by its size, like D.
    Element,
    /// h̄² = (mean element volume)^{2/d} for every element: every element weighs the same,
    /// so thin boundary-layer cells count as much as large ones.
    #[default]
    Mean,
}

/// Parameters of the energy minimisation.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct EnergyParams {
    /// w_e, the weight of the degeneration energy against D + R.
    pub weight: f64,
    pub scale: EnergyScale,
    pub solver: EnergySolver,
    /// L-BFGS iterations, or coloured sweeps, at most.
    pub max_iterations: usize,
    /// Stop L-BFGS when an iteration lowers Q by less than this fraction of Q.
    pub rel_tol: f64,
    /// Stop the coloured solver when a sweep lowers Q by less than this fraction of Q.
    pub sweep_tol: f64,
    /// Stop when ‖∇Q‖∞ falls below this fraction of its initial value (L-BFGS).
    pub grad_tol: f64,
    /// L-BFGS memory (pairs kept).
    pub history: usize,
    /// Halvings of a step before giving up on it.
    pub max_backtracks: usize,
    /// Newton steps per control point and sweep (coloured solver).
    pub local_iterations: usize,
}

impl Default for EnergyParams {
    fn default() -> Self {
        EnergyParams {
            weight: 1.0,
            scale: EnergyScale::default(),
            solver: EnergySolver::Lbfgs,
            max_iterations: 200,
            rel_tol: 1e-6,
            sweep_tol: 1e-3,
            grad_tol: 1e-6,
            history: 8,
            max_backtracks: 30,
            local_iterations: 2,
        }
    }
}

impl EnergyParams {
    /// Weight and tolerances in their ranges.
    pub fn check(&self) -> Result<(), ParamError> {
        in_range("--energy-weight", self.weight, 0.0, 1e12)?;
        in_range("--energy-tol", self.rel_tol, 0.0, 1.0)?;
        in_range("--energy-sweep-tol", self.sweep_tol, 0.0, 1.0)?;
        in_range("energy gradient tolerance", self.grad_tol, 0.0, 1.0)
    }
}

/// Why the minimisation stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EnergyStop {
    /// The decrease per iteration fell below `rel_tol`.
    Stalled,
    /// The gradient fell below `grad_tol`.
    Gradient,
    /// `max_iterations` reached.
    MaxIterations,
    /// No certified step lowering Q was found along the search direction.
    LineSearch,
}

/// What the minimisation did.
#[deny(missing_docs)]
#[derive(Clone, Debug, serde::Serialize)]
pub struct EnergyInfo {
    /// L-BFGS or the coloured local Newton.
    pub solver: EnergySolver,
    /// Weight of the degeneration term (`--energy-weight`).
    pub weight: f64,
    /// L-BFGS iterations or coloured sweeps.
    pub iterations: usize,
    /// Why it stopped.
    pub stop: EnergyStop,
    /// Q at the start (the least-squares result).
    pub initial_energy: f64,
    /// Q at the end.
    pub final_energy: f64,
    /// Σ_e S_e (without the weight) at the start.
    pub initial_degeneration: f64,
    /// Σ_e S_e (without the weight) at the end.
    pub final_degeneration: f64,
    /// Energy evaluations (L-BFGS) or local Newton steps tried (coloured).
    pub evaluations: usize,
    /// Steps shortened because an element lost its certificate.
    pub uncertified_trials: usize,
    /// Number of colours (coloured solver).
    pub colors: Option<usize>,
    /// Seconds spent minimising.
    pub seconds: f64,
}

impl EnergyInfo {
    /// Nothing done yet, at energy `q`.
    pub(crate) fn start(solver: EnergySolver, weight: f64, q: f64) -> Self {
        EnergyInfo {
            solver,
            weight,
            iterations: 0,
            stop: EnergyStop::MaxIterations,
            initial_energy: q,
            final_energy: q,
            initial_degeneration: 0.0,
            final_degeneration: 0.0,
            evaluations: 0,
            uncertified_trials: 0,
            colors: None,
            seconds: 0.0,
        }
    }
}

/// Why the energy cannot be minimised from the given start.
#[derive(Clone, Debug, thiserror::Error)]
pub enum EnergyError {
    #[error(
        "the degeneration energy is infinite at the start: element {element} has det J ≤ 0 at a quadrature point"
    )]
    InfiniteStart { element: usize },
    #[error("the start is not certified valid on element {element}")]
    UncertifiedStart { element: usize },
    #[error("energy weight must be finite and non-negative, got {0}")]
    Weight(f64),
    #[error("GPU: {0}")]
    Gpu(String),
}
