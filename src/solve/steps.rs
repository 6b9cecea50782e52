//! The one preconditioned CG loop: [`iterate`] runs the three per-component recurrences over
//! any [`CgSteps`], which holds the vectors and computes the product, the preconditioner and
//! the dot products as it likes (fused passes, a reordered layout, sums over processes).
//!
//! Input: a [`CgSteps`] whose residual r = b − A x is already formed, the [`Stopping`] rule
//! of b's norms and the iteration limit. Output: the iterations run and rᵀr at the end, x
//! (inside the steps) the last iterate; or the rule's error ([`CgError::NoConvergence`],
//! [`CgError::NotPositiveDefinite`]) or [`CgError::Cancelled`] when the monitor says so.
//!
//! Implementations: [`Vectors`] (the vectors as slices of 3-component entries, with an
//! operator, a preconditioner and [`Reductions`] given as parameters: the serial
//! [`super::pcg_with`] and the distributed solver, through [`super::cg_loop`]), [`Coupled`]
//! (one recurrence over all components, [`super::coupled_loop`]) and the fused block solvers of
//! [`super::blocked`] (block Jacobi and its pair: the product with pᵀAp in one pass, the
//! update, block solve and dot products in another; Gauss–Seidel in Eisenstat's form: the
//! direction p = z + β p deferred into the next sweep). The GPU solver
//! (`exec::gpu::cg::pcg`) does not run this loop: see its module docs.
//!
//! Invariant: the loop only does scalar arithmetic on what the steps return ([`Stopping`]'s α
//! and β); every vector operation and its summation order is the steps', so moving a solver
//! onto the loop does not change its bits.

use super::{CgError, CgMonitor, Pair, Reductions, Stopping};
use rayon::prelude::*;

/// One CG iteration's vector work, in the order [`iterate`] asks for it. Each method returns
/// the sums the loop needs (per component, over the whole system: each implementation reduces
/// them its own way).
pub trait CgSteps {
    /// z = M⁻¹ r for the start's residual r, and the first direction p = z; returns
    /// (rᵀz, rᵀr).
    fn start(&mut self) -> Pair;
    /// A p for the current direction; returns pᵀAp.
    fn curvature(&mut self) -> [f64; 3];
    /// x += α p, r −= α A p, z = M⁻¹ r; returns the new (rᵀz, rᵀr).
    fn step(&mut self, alpha: [f64; 3]) -> Pair;
    /// The next direction p = z + β p (an implementation may defer it into the next
    /// [`CgSteps::curvature`]; it is asked after every step, also the last).
    fn direction(&mut self, beta: [f64; 3]);
}

/// The CG loop over `steps`: until every component meets `stop` (or fails it), α = rᵀz / pᵀAp
/// and β = rᵀz_new / rᵀz per component ([`Stopping`]); `progress` sees every iteration and may
/// end the solve with [`CgError::Cancelled`]. Returns (iterations, rᵀr).
pub fn iterate(
    stop: &Stopping,
    max_iters: usize,
    steps: &mut impl CgSteps,
    mut progress: impl CgMonitor,
) -> Result<(usize, [f64; 3]), CgError> {
    let (mut rz, mut rr) = steps.start();
    let mut it = 0;
    while !stop.converged(rr) {
        if it >= max_iters {
            return Err(stop.no_convergence(it, rr));
        }
        let pap = steps.curvature();
        let alpha = stop.alpha(it, rr, rz, pap)?;
        let (rz_new, rr_new) = steps.step(alpha);
        steps.direction(Stopping::beta(rz, rz_new));
        (rz, rr) = (rz_new, rr_new);
        it += 1;
        stop.record(&mut progress, it, rr)?;
    }
    Ok((it, rr))
}

/// The steps on vectors of 3-component entries in the caller's numbering: A applied by
/// `apply`, M⁻¹ by `precondition`, the dot products by `reduce` (each a separate pass).
pub struct Vectors<'a, A, M> {
    reduce: &'a dyn Reductions,
    apply: A,
    precondition: M,
    x: &'a mut [[f64; 3]],
    r: Vec<[f64; 3]>,
    z: Vec<[f64; 3]>,
    p: Vec<[f64; 3]>,
    ap: Vec<[f64; 3]>,
}

impl<'a, A, M> Vectors<'a, A, M>
where
    A: FnMut(&[[f64; 3]], &mut [[f64; 3]]),
    M: FnMut(&[[f64; 3]], &mut [[f64; 3]]),
{
    /// The steps from `x` with residual `r` (= b − A x).
    pub fn new(
        reduce: &'a dyn Reductions,
        apply: A,
        precondition: M,
        x: &'a mut [[f64; 3]],
        r: Vec<[f64; 3]>,
    ) -> Self {
        let n = r.len();
        Vectors {
            reduce,
            apply,
            precondition,
            x,
            r,
            z: vec![[0.0; 3]; n],
            p: Vec::new(),
            ap: vec![[0.0; 3]; n],
        }
    }
}

impl<A, M> CgSteps for Vectors<'_, A, M>
where
    A: FnMut(&[[f64; 3]], &mut [[f64; 3]]),
    M: FnMut(&[[f64; 3]], &mut [[f64; 3]]),
{
    fn start(&mut self) -> Pair {
        (self.precondition)(&self.r, &mut self.z);
        self.p = self.z.clone();
        self.reduce.dot2((&self.r, &self.z), (&self.r, &self.r))
    }

    fn curvature(&mut self) -> [f64; 3] {
        (self.apply)(&self.p, &mut self.ap);
        self.reduce.dot(&self.p, &self.ap)
    }

    fn step(&mut self, alpha: [f64; 3]) -> Pair {
        advance(self.x, &mut self.r, &self.p, &self.ap, alpha);
        (self.precondition)(&self.r, &mut self.z);
        self.reduce.dot2((&self.r, &self.z), (&self.r, &self.r))
    }

    fn direction(&mut self, beta: [f64; 3]) {
        new_direction(&mut self.p, &self.z, beta);
    }
}

/// One recurrence over all components (operators that couple the components of a node): the
/// sums of `S` added over the three components are [`Stopping`]'s first component, the other
/// two are zero (converged from the start, never stepped), and the first component's α and β
/// step all three.
pub struct Coupled<S>(pub S);

/// A per-component sum as the coupled recurrence's (its [`Stopping`] is of `one(bᵀb)`).
pub(super) fn one(d: [f64; 3]) -> [f64; 3] {
    [d[0] + d[1] + d[2], 0.0, 0.0]
}

impl<S: CgSteps> CgSteps for Coupled<S> {
    fn start(&mut self) -> Pair {
        let (rz, rr) = self.0.start();
        (one(rz), one(rr))
    }

    fn curvature(&mut self) -> [f64; 3] {
        one(self.0.curvature())
    }

    fn step(&mut self, alpha: [f64; 3]) -> Pair {
        let (rz, rr) = self.0.step([alpha[0]; 3]);
        (one(rz), one(rr))
    }

    fn direction(&mut self, beta: [f64; 3]) {
        self.0.direction([beta[0]; 3]);
    }
}

/// x += α p, r −= α A p (per component α).
fn advance(
    x: &mut [[f64; 3]],
    r: &mut [[f64; 3]],
    p: &[[f64; 3]],
    ap: &[[f64; 3]],
    alpha: [f64; 3],
) {
    x.par_iter_mut()
        .zip(r.par_iter_mut())
        .zip(p.par_iter().zip(ap.par_iter()))
        .for_each(|((x, r), (p, ap))| {
            for k in 0..3 {
                x[k] += alpha[k] * p[k];
                r[k] -= alpha[k] * ap[k];
            }
        });
}

/// p = z + β p (per component β).
fn new_direction(p: &mut [[f64; 3]], z: &[[f64; 3]], beta: [f64; 3]) {
    p.par_iter_mut().zip(z.par_iter()).for_each(|(p, z)| {
        for k in 0..3 {
            p[k] = z[k] + beta[k] * p[k];
        }
    });
}
