//! Preconditioned conjugate gradients for symmetric positive definite operators with three
//! right-hand sides (x, y, z coordinates) solved together.
//!
//! Input: a [`LinOp`] (assembled matrix, matrix-free operator, or a GPU operator), a
//! preconditioner ([`CgPreconditioner`]: point Jacobi from the diagonal, block Jacobi on
//! aggregates of an assembled matrix, [`block_jacobi`], or symmetric block Gauss–Seidel on
//! colour-ordered aggregates, [`blocked`]), right-hand sides `b` and a start `x`. Output: `x` with ‖b − A x‖ ≤ `rel_tol`·‖b‖ per
//! component (or ≤ `abs_tol`), and a [`CgInfo`]; or [`CgError::NoConvergence`] with the
//! residuals reached. Each coordinate runs its own CG recurrence (its own α, β); they share the
//! operator application, so the matrix is read once per iteration for all three.
//! [`pcg_coupled`] is the variant for operators that couple the components of a node
//! (elasticity, the fit across rotation seams): one recurrence over all unknowns, with a
//! caller-supplied preconditioner; its loop, [`coupled_loop`], takes [`Reductions`] too.
//!
//! Every CPU solver here runs one loop, [`iterate`] ([`steps`]), over the
//! [`CgSteps`] that hold its vectors: [`pcg`] on an assembled matrix with block Jacobi, its
//! pair (the fit's default) or block Gauss–Seidel runs the steps of [`blocked`] (unknowns
//! renumbered by aggregates, rows stored by value template, vector updates, block solves and
//! dot products fused into three passes per iteration); [`pcg_with`] the generic steps
//! [`Vectors`] (any operator, any preconditioner) through [`cg_loop`], which the distributed
//! solver runs too, with its own [`Reductions`] (sums over the processes).
//!
//! Every loop reports each iteration to a [`CgMonitor`] (a closure `|iteration, rel_residual|`
//! is one), which may stop the solve: [`Cancellable`] stops it when the caller asks
//! (Ctrl-C in the Python package), with [`CgError::Cancelled`], within one iteration.
//!
//! [`direct`] solves the same assembled systems by sparse Cholesky instead (the fit's small
//! systems, chosen by the fit's `FitSolver`), reporting through [`CgInfo`] with 0 iterations.

pub mod block_jacobi;
pub mod blocked;
pub mod direct;
pub mod lines;
pub mod steps;

use crate::params::{ParamError, above, in_range};
pub use block_jacobi::BlockJacobi;
pub use blocked::{BlockedKind, BlockedSystem};
use rayon::prelude::*;
use std::ops::ControlFlow;
pub use steps::{CgSteps, Coupled, Vectors, iterate};

/// A symmetric positive definite operator on vectors of 3-component entries.
pub trait LinOp: Sync {
    fn nrows(&self) -> usize;
    /// y = A x.
    fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]);
    /// The diagonal of A (for the Jacobi preconditioner).
    fn diagonal(&self) -> Vec<f64>;
    /// The matrix in CSR form (`indptr`, `indices`, `data`) when it is assembled; block
    /// Jacobi needs it (operators without one fall back to point Jacobi).
    fn csr(&self) -> Option<(&[usize], &[u32], &[f64])> {
        None
    }
}

/// Preconditioner of [`pcg`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CgPreconditioner {
    /// Point Jacobi: the inverse diagonal.
    Jacobi,
    /// Block Jacobi on aggregates of at most `size` neighbouring unknowns
    /// ([`BlockJacobi`]); point Jacobi for operators that are not assembled.
    BlockJacobi { size: usize },
    /// Symmetric block Gauss–Seidel on the same aggregates, ordered by colour
    /// ([`BlockedSystem::symmetric_gauss_seidel`]); point Jacobi for operators that are not
    /// assembled.
    BlockSgs { size: usize },
    /// Additive block Jacobi on two staggered partitions into aggregates of at most `size`
    /// unknowns ([`block_jacobi::BlockJacobiPair`]); point Jacobi for operators that are not
    /// assembled.
    BlockJacobiPair { size: usize },
    /// Block Jacobi on aggregates of at most `size` unknowns plus the line blocks of the
    /// fit's control points ([`lines`]): z = M⁻¹ r + Σ_l R_lᵀ K_l⁻¹ R_l r. Lines exist only
    /// where the matrix comes with them (the fit's normal matrix); elsewhere
    /// (other operators, the distributed solve, the coupled fit) this is the pair.
    BlockJacobiLines { size: usize },
}

impl CgPreconditioner {
    /// For the preconditioners that [`BlockedSystem`] runs on an assembled matrix, the
    /// aggregate size and which one it is; `None` for point Jacobi.
    pub fn blocked(self) -> Option<(usize, BlockedKind)> {
        match self {
            CgPreconditioner::BlockJacobi { size } => Some((size, BlockedKind::Jacobi)),
            CgPreconditioner::BlockSgs { size } => Some((size, BlockedKind::GaussSeidel)),
            CgPreconditioner::BlockJacobiPair { size } => Some((size, BlockedKind::JacobiPair)),
            // Without lines (see [`Self::with_lines`]): the pair.
            CgPreconditioner::BlockJacobiLines { size } => Some((size, BlockedKind::JacobiPair)),
            CgPreconditioner::Jacobi => None,
        }
    }
}

impl CgPreconditioner {
    /// Whether this preconditioner takes line blocks; with them, [`BlockedSystem`] runs
    /// [`BlockedKind::Jacobi`] plus the lines (without them, [`Self::blocked`]'s kind).
    pub fn with_lines(self) -> bool {
        matches!(self, CgPreconditioner::BlockJacobiLines { .. })
    }
}

impl Default for CgPreconditioner {
    fn default() -> Self {
        // The pair needs about 65 % of block Jacobi's iterations on the fit's systems (cylinder
        // 50k: 77 against 120, 300k: 80 against 124) and, fused into the blocked solver, an
        // iteration costs one more pass over the block factors and two vectors, while the
        // product's column indices (the larger stream) are read as often as before: the CG
        // stage takes 0.86–0.92 of block Jacobi's time. Block Gauss–Seidel needs 40 % of the
        // iterations, but an iteration costs about 2.4 block-Jacobi ones (its sweeps' gathers
        // wait on memory). Distributed runs keep block Jacobi (the second partition's patches
        // would cross the ranks' shares).
        CgPreconditioner::BlockJacobiPair {
            size: block_jacobi::DEFAULT_BLOCK,
        }
    }
}

/// CG parameters.
#[derive(Clone, Copy, Debug)]
pub struct CgParams {
    /// Stop when ‖r‖ ≤ rel_tol · ‖b‖ (per component).
    pub rel_tol: f64,
    /// … or when ‖r‖ ≤ abs_tol.
    pub abs_tol: f64,
    pub max_iters: usize,
    /// Preconditioner of [`pcg`] (the coupled solver takes its own).
    pub preconditioner: CgPreconditioner,
}

impl Default for CgParams {
    fn default() -> Self {
        CgParams {
            rel_tol: 1e-6,
            abs_tol: 0.0,
            max_iters: 10_000,
            preconditioner: CgPreconditioner::default(),
        }
    }
}

impl CgParams {
    /// Tolerances and iteration limit.
    pub fn check(&self) -> Result<(), ParamError> {
        above("--cg-tol", self.rel_tol, 0.0, 1.0)?;
        in_range("CG absolute tolerance", self.abs_tol, 0.0, f64::MAX)?;
        if self.max_iters == 0 {
            return Err(ParamError::new("CG iterations", 0, "must be at least 1"));
        }
        Ok(())
    }
}

/// What CG achieved.
#[deny(missing_docs)]
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct CgInfo {
    /// Iterations run (0 when a factorisation solved the system instead).
    pub iterations: usize,
    /// Largest ‖r‖/‖b‖ over the three components at the end.
    pub rel_residual: f64,
}

/// CG failures.
#[derive(Clone, Debug, thiserror::Error)]
pub enum CgError {
    #[error(
        "conjugate gradients did not converge in {iterations} iterations (relative residual {rel_residual:.3e}, tolerance {rel_tol:.1e})"
    )]
    NoConvergence {
        iterations: usize,
        rel_residual: f64,
        rel_tol: f64,
    },
    #[error(
        "conjugate gradients broke down at iteration {iteration}: the operator is not positive definite (pᵀAp = {curvature:.3e})"
    )]
    NotPositiveDefinite { iteration: usize, curvature: f64 },
    #[error("the Jacobi preconditioner has a non-positive diagonal entry {value:.3e} at row {row}")]
    BadDiagonal { row: usize, value: f64 },
    /// The sparse Cholesky solve ([`direct`]) met a non-positive pivot.
    #[error(
        "the sparse Cholesky factorisation met a non-positive pivot at unknown {pivot} (of the reordered matrix): the operator is not positive definite"
    )]
    NotPositiveDefinitePivot { pivot: usize },
    /// The sparse Cholesky solve could not allocate or index its factor.
    #[error("the sparse Cholesky factorisation failed: {0}")]
    Factorisation(String),
    /// The GPU solver's device failed.
    #[error("the GPU solver failed: {0}")]
    Device(String),
    /// The solver cannot apply this preconditioner (the distributed CG and block
    /// Gauss–Seidel).
    #[error("the {what} preconditioner is not available here: {why}")]
    Unavailable {
        what: &'static str,
        why: &'static str,
    },
    /// The [`CgMonitor`] stopped the solve (the caller cancelled the job).
    #[error("conjugate gradients cancelled after {iterations} iterations")]
    Cancelled { iterations: usize },
}

/// What a CG solve tells after every iteration (`iteration`, largest relative residual), and
/// whether it goes on: [`ControlFlow::Break`] ends the solve with [`CgError::Cancelled`].
/// Every closure `FnMut(usize, f64)` is a monitor that never stops the solve.
pub trait CgMonitor {
    fn iteration(&mut self, iteration: usize, rel_residual: f64) -> ControlFlow<()>;
}

impl<F: FnMut(usize, f64)> CgMonitor for F {
    fn iteration(&mut self, iteration: usize, rel_residual: f64) -> ControlFlow<()> {
        self(iteration, rel_residual);
        ControlFlow::Continue(())
    }
}

impl CgMonitor for &mut dyn CgMonitor {
    fn iteration(&mut self, iteration: usize, rel_residual: f64) -> ControlFlow<()> {
        (**self).iteration(iteration, rel_residual)
    }
}

/// A monitor that reports to `progress` and stops the solve as soon as `cancelled()` is
/// true (asked once per iteration, so it must be cheap).
pub struct Cancellable<F, C> {
    pub progress: F,
    pub cancelled: C,
}

impl<F: FnMut(usize, f64), C: Fn() -> bool> CgMonitor for Cancellable<F, C> {
    fn iteration(&mut self, iteration: usize, rel_residual: f64) -> ControlFlow<()> {
        (self.progress)(iteration, rel_residual);
        if (self.cancelled)() {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }
}

/// Rows per partial sum of [`dot3`]: the summation order is fixed by the data, not by the
/// thread count, so results are the same on any number of threads.
const DOT_BLOCK: usize = 4096;

fn dot3(a: &[[f64; 3]], b: &[[f64; 3]]) -> [f64; 3] {
    let partials: Vec<[f64; 3]> = a
        .par_chunks(DOT_BLOCK)
        .zip(b.par_chunks(DOT_BLOCK))
        .map(|(a, b)| {
            let mut s = [0.0; 3];
            for (x, y) in a.iter().zip(b) {
                for k in 0..3 {
                    s[k] += x[k] * y[k];
                }
            }
            s
        })
        .collect();
    partials
        .iter()
        .fold([0.0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]])
}

/// r = b − A x, with A applied by `apply`: the start of every CG loop here and of the GPU
/// solver's host loop (and its f64 check of the final residual).
pub(crate) fn residual(
    apply: &mut impl FnMut(&[[f64; 3]], &mut [[f64; 3]]),
    b: &[[f64; 3]],
    x: &[[f64; 3]],
    r: &mut [[f64; 3]],
) {
    apply(x, r);
    r.par_iter_mut().zip(b.par_iter()).for_each(|(r, b)| {
        for k in 0..3 {
            r[k] = b[k] - r[k];
        }
    });
}

/// The stopping rule, step lengths and iteration record of the three per-component
/// recurrences: one rule for the loop [`iterate`] (serial, distributed and [`blocked`]; the
/// coupled recurrence as the first component) and the GPU solver's host loop.
pub struct Stopping {
    bnorm: [f64; 3],
    /// ‖r‖ at which a component has converged: max(rel_tol·‖b‖, abs_tol).
    pub target: [f64; 3],
    rel_tol: f64,
}

impl Stopping {
    /// The rule for right-hand sides of norms `bnorm` (per component).
    pub fn new(bnorm: [f64; 3], params: &CgParams) -> Self {
        Stopping {
            bnorm,
            target: std::array::from_fn(|k| (params.rel_tol * bnorm[k]).max(params.abs_tol)),
            rel_tol: params.rel_tol,
        }
    }

    /// Largest ‖r‖/‖b‖ (‖r‖ where b = 0) from the squared norms rᵀr.
    pub fn rel(&self, rr: [f64; 3]) -> f64 {
        (0..3)
            .map(|k| {
                if self.bnorm[k] > 0.0 {
                    rr[k].sqrt() / self.bnorm[k]
                } else {
                    rr[k].sqrt()
                }
            })
            .fold(0.0, f64::max)
    }

    /// Whether component `k` of squared residual norms `rr` has not converged yet.
    pub fn running(&self, rr: [f64; 3], k: usize) -> bool {
        // A NaN residual keeps running (and fails), never converges.
        !(rr[k].sqrt() <= self.target[k])
    }

    /// Whether every component has converged.
    pub fn converged(&self, rr: [f64; 3]) -> bool {
        (0..3).all(|k| !self.running(rr, k))
    }

    /// The error of a solve stopped after `iterations` at squared residual norms `rr`.
    pub fn no_convergence(&self, iterations: usize, rr: [f64; 3]) -> CgError {
        CgError::NoConvergence {
            iterations,
            rel_residual: self.rel(rr),
            rel_tol: self.rel_tol,
        }
    }

    /// α = rᵀz / pᵀAp per component; components already converged keep their iterate
    /// (α = 0), so 0/0 never occurs.
    fn alpha(
        &self,
        iteration: usize,
        rr: [f64; 3],
        rz: [f64; 3],
        pap: [f64; 3],
    ) -> Result<[f64; 3], CgError> {
        let running = std::array::from_fn(|k| self.running(rr, k));
        step_lengths(running, rz, pap).map_err(|k| CgError::NotPositiveDefinite {
            iteration,
            curvature: pap[k],
        })
    }

    fn beta(rz: [f64; 3], rz_new: [f64; 3]) -> [f64; 3] {
        direction_weights(rz, rz_new)
    }

    /// The iteration record: `progress` told of `iteration` at squared residual norms `rr`;
    /// [`CgError::Cancelled`] when it stops the solve.
    pub fn record(
        &self,
        progress: &mut impl CgMonitor,
        iteration: usize,
        rr: [f64; 3],
    ) -> Result<(), CgError> {
        match progress.iteration(iteration, self.rel(rr)) {
            ControlFlow::Break(()) => Err(CgError::Cancelled {
                iterations: iteration,
            }),
            ControlFlow::Continue(()) => Ok(()),
        }
    }
}

/// α = rᵀz / pᵀAp for the `running` components (0 for the others), at any precision: the
/// arithmetic of [`Stopping`]'s steps and of the GPU kernel's CPU twin
/// (`exec::cpu::cg::finalize_alpha`, whose `running` compares squared norms as the shader
/// does). `Err(k)`: the first running component k whose pᵀAp is not positive.
pub fn step_lengths<T>(running: [bool; 3], rz: [T; 3], pap: [T; 3]) -> Result<[T; 3], usize>
where
    T: Copy + Default + PartialOrd + std::ops::Div<Output = T>,
{
    let mut alpha = [T::default(); 3];
    for k in 0..3 {
        if running[k] {
            if !(pap[k] > T::default()) {
                return Err(k);
            }
            alpha[k] = rz[k] / pap[k];
        }
    }
    Ok(alpha)
}

/// β = rᵀz_new / rᵀz per component (0 where rᵀz is not positive), at any precision: the
/// arithmetic of [`Stopping`]'s steps and of `exec::cpu::cg::finalize_beta`.
pub fn direction_weights<T>(rz: [T; 3], rz_new: [T; 3]) -> [T; 3]
where
    T: Copy + Default + PartialOrd + std::ops::Div<Output = T>,
{
    std::array::from_fn(|k| {
        if rz[k] > T::default() {
            rz_new[k] / rz[k]
        } else {
            T::default()
        }
    })
}

/// Point Jacobi: z = D⁻¹ r.
pub struct Jacobi(Vec<f64>);

impl Jacobi {
    /// From the operator's diagonal; a non-positive entry is [`CgError::BadDiagonal`].
    pub fn new(op: &dyn LinOp) -> Result<Self, CgError> {
        let diag = op.diagonal();
        if let Some((row, &value)) = diag.iter().enumerate().find(|(_, d)| !(**d > 0.0)) {
            return Err(CgError::BadDiagonal { row, value });
        }
        Ok(Jacobi(diag.iter().map(|d| 1.0 / d).collect()))
    }
}

impl Preconditioner for Jacobi {
    fn apply(&self, r: &[[f64; 3]], z: &mut [[f64; 3]]) {
        z.par_iter_mut()
            .zip(r.par_iter().zip(self.0.par_iter()))
            .for_each(|(z, (r, d))| *z = r.map(|v| v * d));
    }
}

/// The preconditioner `params` asks for, built for `op`.
pub fn preconditioner(
    op: &dyn LinOp,
    params: &CgParams,
) -> Result<Box<dyn Preconditioner>, CgError> {
    match (params.preconditioner, op.csr()) {
        // The generic loop has no sweeps: block Gauss–Seidel runs in [`pcg`] through
        // [`BlockedSystem`], and is block Jacobi here.
        (
            CgPreconditioner::BlockJacobi { size } | CgPreconditioner::BlockSgs { size },
            Some((indptr, indices, data)),
        ) => Ok(Box::new(BlockJacobi::new(indptr, indices, data, size)?)),
        (
            CgPreconditioner::BlockJacobiPair { size }
            | CgPreconditioner::BlockJacobiLines { size },
            Some((indptr, indices, data)),
        ) => Ok(Box::new(block_jacobi::BlockJacobiPair::new(
            indptr, indices, data, size,
        )?)),
        _ => Ok(Box::new(Jacobi::new(op)?)),
    }
}

/// A stored column index: 32-bit, or a 16-bit offset into a slice of x that starts at the row's
/// smallest column (`blocked`'s packed columns).
pub(crate) trait Column: Copy {
    fn index(self) -> usize;
}

impl Column for u32 {
    #[inline(always)]
    fn index(self) -> usize {
        self as usize
    }
}

impl Column for u16 {
    #[inline(always)]
    fn index(self) -> usize {
        usize::from(self)
    }
}

/// Σ_k vals[k] x[cols[k]] for one CSR row, on N-component entries. Four partial sums break
/// the dependency chain of the accumulation; their order is fixed, so every caller gets the
/// same bits for the same row.
#[inline(always)]
pub(crate) fn row_dot<const N: usize, C: Column>(
    cols: &[C],
    vals: &[f64],
    x: &[[f64; N]],
) -> [f64; N] {
    let mut s = [[0.0; N]; 4];
    let mut ci = cols.chunks_exact(4);
    let mut vi = vals.chunks_exact(4);
    for (c, v) in (&mut ci).zip(&mut vi) {
        for l in 0..4 {
            let xc = x[c[l].index()];
            for d in 0..N {
                s[l][d] += v[l] * xc[d];
            }
        }
    }
    for (&c, &v) in ci.remainder().iter().zip(vi.remainder()) {
        let xc = x[c.index()];
        for d in 0..N {
            s[0][d] += v * xc[d];
        }
    }
    std::array::from_fn(|d| (s[0][d] + s[1][d]) + (s[2][d] + s[3][d]))
}

/// Solve A x = b by preconditioned CG (the preconditioner of `params`), starting from `x`.
/// `progress` ([`CgMonitor`]) sees every iteration and may stop the solve. An assembled operator
/// ([`LinOp::csr`]) with block Jacobi, its pair or block Gauss–Seidel is solved by [`BlockedSystem`],
/// anything else by [`pcg_with`].
pub fn pcg(
    op: &dyn LinOp,
    b: &[[f64; 3]],
    x: &mut [[f64; 3]],
    params: &CgParams,
    progress: impl CgMonitor,
) -> Result<CgInfo, CgError> {
    // An assembled matrix with a block preconditioner takes the reordered, fused solver (same
    // method).
    if let (Some((size, kind)), Some((indptr, indices, data))) =
        (params.preconditioner.blocked(), op.csr())
    {
        return BlockedSystem::with_kind(indptr, indices, data, size, kind)?
            .solve(b, x, params, progress);
    }
    let pre = preconditioner(op, params)?;
    pcg_with(op, pre.as_ref(), b, x, params, progress)
}

/// [`pcg`] with a given preconditioner.
pub fn pcg_with(
    op: &dyn LinOp,
    pre: &dyn Preconditioner,
    b: &[[f64; 3]],
    x: &mut [[f64; 3]],
    params: &CgParams,
    progress: impl CgMonitor,
) -> Result<CgInfo, CgError> {
    let n = op.nrows();
    assert_eq!(b.len(), n);
    assert_eq!(x.len(), n);
    let apply = |v: &[[f64; 3]], y: &mut [[f64; 3]]| op.apply(v, y);
    let precondition = |r: &[[f64; 3]], z: &mut [[f64; 3]]| pre.apply(r, z);
    cg_loop(&Rows, apply, precondition, b, x, params, progress)
}

/// The dot products of a CG solve over the whole system, per component: the parameter that
/// makes [`cg_loop`] the serial solver ([`Rows`]) or the solver of many processes (sums of
/// each process's owned rows, reduced over the processes).
pub trait Reductions {
    /// aᵀb per component.
    fn dot(&self, a: &[[f64; 3]], b: &[[f64; 3]]) -> [f64; 3];
    /// (aᵀb, cᵀd): one reduction where the sums travel; each value is the one
    /// [`Reductions::dot`] gives.
    fn dot2(&self, ab: (&[[f64; 3]], &[[f64; 3]]), cd: (&[[f64; 3]], &[[f64; 3]])) -> Pair {
        (self.dot(ab.0, ab.1), self.dot(cd.0, cd.1))
    }
}

/// Two per-component dot products.
pub type Pair = ([f64; 3], [f64; 3]);

/// The dot products of one process: sums over all rows, in an order fixed by the data.
pub struct Rows;

impl Reductions for Rows {
    fn dot(&self, a: &[[f64; 3]], b: &[[f64; 3]]) -> [f64; 3] {
        dot3(a, b)
    }
}

/// Preconditioned CG of the three per-component recurrences from `x`, on vectors in the
/// caller's numbering: the loop [`iterate`] over [`Vectors`] with the caller's operator,
/// preconditioner and [`Reductions`] (the serial [`pcg_with`] and the distributed solver).
/// The stopping rule is [`Stopping`]'s: ‖r‖ ≤ max(rel_tol·‖b‖, abs_tol) per component, ‖·‖
/// from `reduce`. `progress` sees every iteration; when it breaks, the solve ends with
/// [`CgError::Cancelled`] (x is the last iterate).
pub fn cg_loop(
    reduce: &dyn Reductions,
    mut apply: impl FnMut(&[[f64; 3]], &mut [[f64; 3]]),
    precondition: impl FnMut(&[[f64; 3]], &mut [[f64; 3]]),
    b: &[[f64; 3]],
    x: &mut [[f64; 3]],
    params: &CgParams,
    progress: impl CgMonitor,
) -> Result<CgInfo, CgError> {
    let mut r = vec![[0.0; 3]; b.len()];
    residual(&mut apply, b, x, &mut r);
    let stop = Stopping::new(reduce.dot(b, b).map(f64::sqrt), params);
    let mut steps = Vectors::new(reduce, apply, precondition, x, r);
    let (iterations, rr) = iterate(&stop, params.max_iters, &mut steps, progress)?;
    Ok(CgInfo {
        iterations,
        rel_residual: stop.rel(rr),
    })
}

/// A preconditioner M⁻¹ for [`pcg_coupled`]: z = M⁻¹ r, symmetric positive definite.
pub trait Preconditioner: Sync {
    fn apply(&self, r: &[[f64; 3]], z: &mut [[f64; 3]]);
}

/// Solve A x = b by preconditioned CG for an operator that couples the three components of a
/// node (linear elasticity): one recurrence over all 3n unknowns, unlike [`pcg`]'s three.
/// Stops when ‖r‖ ≤ rel_tol·‖b‖ (Euclidean norm over all components) or ≤ abs_tol
/// ([`Stopping`]'s rule). `progress` sees every iteration; when it breaks, the solve ends with
/// [`CgError::Cancelled`].
pub fn pcg_coupled(
    op: &dyn LinOp,
    pre: &dyn Preconditioner,
    b: &[[f64; 3]],
    x: &mut [[f64; 3]],
    params: &CgParams,
    progress: impl CgMonitor,
) -> Result<CgInfo, CgError> {
    let n = op.nrows();
    assert_eq!(b.len(), n);
    assert_eq!(x.len(), n);
    coupled_loop(
        &Rows,
        |v, y| op.apply(v, y),
        |r, z| pre.apply(r, z),
        b,
        x,
        params,
        progress,
    )
}

/// The loop of [`pcg_coupled`] from `x`, with the dot products of `reduce` summed over the
/// three components ([`iterate`] over [`Coupled`] [`Vectors`]): the serial solver runs it on
/// all rows ([`Rows`]), the distributed one with its sums over the processes. `progress` as
/// [`cg_loop`]'s.
pub fn coupled_loop(
    reduce: &dyn Reductions,
    mut apply: impl FnMut(&[[f64; 3]], &mut [[f64; 3]]),
    precondition: impl FnMut(&[[f64; 3]], &mut [[f64; 3]]),
    b: &[[f64; 3]],
    x: &mut [[f64; 3]],
    params: &CgParams,
    progress: impl CgMonitor,
) -> Result<CgInfo, CgError> {
    let mut r = vec![[0.0; 3]; b.len()];
    residual(&mut apply, b, x, &mut r);
    let stop = Stopping::new(steps::one(reduce.dot(b, b)).map(f64::sqrt), params);
    let mut steps = Coupled(Vectors::new(reduce, apply, precondition, x, r));
    let (iterations, rr) = iterate(&stop, params.max_iters, &mut steps, progress)?;
    Ok(CgInfo {
        iterations,
        rel_residual: stop.rel(rr),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 1D Laplacian plus a shift: SPD, with a known solution.
    struct Lap(usize);
    impl LinOp for Lap {
        fn nrows(&self) -> usize {
            self.0
        }
        fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
            let n = self.0;
            for i in 0..n {
                for k in 0..3 {
                    let l = if i > 0 { x[i - 1][k] } else { 0.0 };
                    let r = if i + 1 < n { x[i + 1][k] } else { 0.0 };
                    y[i][k] = (2.0 + 0.01 * i as f64) * x[i][k] - l - r;
                }
            }
        }
        fn diagonal(&self) -> Vec<f64> {
            (0..self.0).map(|i| 2.0 + 0.01 * i as f64).collect()
        }
    }

    #[test]
    fn solves_three_right_hand_sides() {
        let op = Lap(200);
        let want: Vec<[f64; 3]> = (0..200).map(|i| [(i as f64).sin(), 1.0, 0.0]).collect();
        let mut b = vec![[0.0; 3]; 200];
        op.apply(&want, &mut b);
        let mut x = vec![[0.0; 3]; 200];
        let info = pcg(
            &op,
            &b,
            &mut x,
            &CgParams {
                rel_tol: 1e-12,
                ..Default::default()
            },
            |_, _| {},
        )
        .unwrap();
        assert!(info.rel_residual <= 1e-12);
        for (a, w) in x.iter().zip(&want) {
            for k in 0..3 {
                assert!((a[k] - w[k]).abs() < 1e-8);
            }
        }
        // The third right-hand side is zero: its solution is exactly zero (a column that
        // converged at once is not updated, nor made NaN by a 0/0 step length).
        assert!(x.iter().all(|a| a[2] == 0.0), "{:?}", &x[..3]);
    }

    /// The Laplacian as an assembled CSR matrix, so block Jacobi applies.
    struct LapCsr(Vec<usize>, Vec<u32>, Vec<f64>);
    impl LapCsr {
        fn new(n: usize) -> Self {
            let (mut p, mut i, mut d) = (vec![0], Vec::new(), Vec::new());
            for r in 0..n {
                if r > 0 {
                    i.push(r as u32 - 1);
                    d.push(-1.0);
                }
                i.push(r as u32);
                d.push(2.0 + 0.01 * r as f64);
                if r + 1 < n {
                    i.push(r as u32 + 1);
                    d.push(-1.0);
                }
                p.push(i.len());
            }
            LapCsr(p, i, d)
        }
    }
    impl LinOp for LapCsr {
        fn nrows(&self) -> usize {
            self.0.len() - 1
        }
        fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
            Lap(self.nrows()).apply(x, y)
        }
        fn diagonal(&self) -> Vec<f64> {
            Lap(self.nrows()).diagonal()
        }
        fn csr(&self) -> Option<(&[usize], &[u32], &[f64])> {
            Some((&self.0, &self.1, &self.2))
        }
    }

    #[test]
    fn both_preconditioners_solve_and_blocks_need_fewer_iterations() {
        let op = LapCsr::new(400);
        let want: Vec<[f64; 3]> = (0..400).map(|i| [(i as f64).cos(), 2.0, -1.0]).collect();
        let mut b = vec![[0.0; 3]; 400];
        op.apply(&want, &mut b);
        let mut its = Vec::new();
        for pre in [
            CgPreconditioner::Jacobi,
            CgPreconditioner::BlockJacobi { size: 16 },
        ] {
            let mut x = vec![[0.0; 3]; 400];
            let params = CgParams {
                rel_tol: 1e-12,
                preconditioner: pre,
                ..Default::default()
            };
            let info = pcg(&op, &b, &mut x, &params, |_, _| {}).unwrap();
            for (a, w) in x.iter().zip(&want) {
                for k in 0..3 {
                    assert!((a[k] - w[k]).abs() < 1e-8, "{pre:?}");
                }
            }
            its.push(info.iterations);
        }
        assert!(
            its[1] < its[0],
            "block Jacobi {} vs Jacobi {}",
            its[1],
            its[0]
        );
    }

    /// A cancelled solve stops at the iteration where the monitor first says so, in both the
    /// generic loop (point Jacobi) and the fused block Jacobi solver, where it would otherwise
    /// run on to convergence.
    #[test]
    fn a_cancelled_solve_stops_at_once() {
        let op = LapCsr::new(400);
        let b = vec![[1.0, -2.0, 0.5]; 400];
        for pre in [
            CgPreconditioner::Jacobi,
            CgPreconditioner::BlockJacobi { size: 16 },
        ] {
            let params = CgParams {
                rel_tol: 1e-12,
                preconditioner: pre,
                ..Default::default()
            };
            let full = pcg(&op, &b, &mut vec![[0.0; 3]; 400], &params, |_, _| {}).unwrap();
            assert!(full.iterations > 10, "{pre:?}: {}", full.iterations);
            let seen = std::cell::Cell::new(0usize);
            let monitor = Cancellable {
                progress: |i: usize, _: f64| seen.set(i),
                cancelled: || seen.get() >= 7,
            };
            let e = pcg(&op, &b, &mut vec![[0.0; 3]; 400], &params, monitor).unwrap_err();
            assert!(
                matches!(e, CgError::Cancelled { iterations: 7 }),
                "{pre:?}: {e}"
            );
            assert_eq!(seen.get(), 7);
        }
        // The coupled loop (the fit across rotation seams, the elastic analogy) alike.
        let params = CgParams {
            rel_tol: 1e-12,
            ..Default::default()
        };
        let pre = Jacobi::new(&op).unwrap();
        let full = pcg_coupled(&op, &pre, &b, &mut vec![[0.0; 3]; 400], &params, |_, _| {});
        assert!(full.unwrap().iterations > 10);
        let seen = std::cell::Cell::new(0usize);
        let monitor = Cancellable {
            progress: |i: usize, _: f64| seen.set(i),
            cancelled: || seen.get() >= 7,
        };
        let e = pcg_coupled(&op, &pre, &b, &mut vec![[0.0; 3]; 400], &params, monitor);
        assert!(
            matches!(e, Err(CgError::Cancelled { iterations: 7 })),
            "coupled: {e:?}"
        );
    }

    /// The coupled loop stops by the same rule as the per-component one: a NaN residual
    /// never converges (it used to end the coupled loop at once, "converged").
    #[test]
    fn a_nan_residual_fails_in_both_loops() {
        let op = Lap(50);
        let mut b = vec![[1.0; 3]; 50];
        b[7][1] = f64::NAN;
        let params = CgParams::default();
        let mut x = vec![[0.0; 3]; 50];
        let three = pcg(&op, &b, &mut x, &params, |_, _| {});
        assert!(three.is_err(), "{three:?}");
        let mut x = vec![[0.0; 3]; 50];
        let coupled = pcg_coupled(
            &op,
            &Jacobi::new(&op).unwrap(),
            &b,
            &mut x,
            &params,
            |_, _| {},
        );
        assert!(
            matches!(coupled, Err(CgError::NotPositiveDefinite { .. })),
            "{coupled:?}"
        );
        // Finite data: the coupled loop reaches the tolerance on ‖r‖ over all components.
        b[7][1] = 2.0;
        let mut x = vec![[0.0; 3]; 50];
        let info = pcg_coupled(
            &op,
            &Jacobi::new(&op).unwrap(),
            &b,
            &mut x,
            &params,
            |_, _| {},
        )
        .unwrap();
        let mut r = vec![[0.0; 3]; 50];
        op.apply(&x, &mut r);
        let norm = |v: &[[f64; 3]]| v.iter().flatten().map(|a| a * a).sum::<f64>().sqrt();
        let rr: Vec<[f64; 3]> = r
            .iter()
            .zip(&b)
            .map(|(r, b)| std::array::from_fn(|k| b[k] - r[k]))
            .collect();
        assert!(norm(&rr) <= 1.0001 * params.rel_tol * norm(&b), "{info:?}");
        assert!(
            info.rel_residual <= params.rel_tol && info.iterations > 0,
            "{info:?}"
        );
    }

    #[test]
    fn non_convergence_is_an_error_with_the_residual() {
        let op = Lap(500);
        let b = vec![[1.0; 3]; 500];
        let mut x = vec![[0.0; 3]; 500];
        let e = pcg(
            &op,
            &b,
            &mut x,
            &CgParams {
                rel_tol: 1e-14,
                abs_tol: 0.0,
                max_iters: 5,
                ..Default::default()
            },
            |_, _| {},
        )
        .unwrap_err();
        match e {
            CgError::NoConvergence {
                iterations,
                rel_residual,
                ..
            } => {
                assert_eq!(iterations, 5);
                assert!(rel_residual > 1e-14);
            }
            other => panic!("{other}"),
        }
    }
}
