//! The scaled Jacobian's rule of the blend: each straight element's smallest scaled Jacobian
//! s_S over the lattice {0, ¼, ½, ¾, 1}^d, the straight mesh's 1st percentile P_s of it, and
//! the verdict on a blended element, sampled only where certified bounds do not decide.
//!
//! Bounds used (both hold on every lattice point): the coarse lattice {0, ½, 1}^d is a subset
//! of the fine one, so its smallest scaled Jacobian is an upper bound of the fine lattice's;
//! a certified lower bound L of det J over the element over the product of the columns'
//! largest Bernstein coefficient norms (the Hadamard bound, [`hadamard_upper`]) is a lower
//! bound of the scaled Jacobian everywhere in the element (each column is a convex
//! combination of its coefficients).

use super::shape::{fine_lattice_scaled_jacobian, hadamard_upper, lattice_scaled_jacobian};
use super::{BlendShare, Net};
use crate::math::BezierElements;
use rayon::prelude::*;
use std::sync::OnceLock;

/// Relative slack on the bounds' comparisons, above the rounding of the two lattices'
/// different sums (the fine lattice's coarse points are evaluated by other operators).
const ROUNDING: f64 = 1e-12;

/// The straight elements' scaled Jacobians and the targets of the rule.
pub(super) struct StraightScaledJacobians<'a> {
    dim: usize,
    straight: &'a (dyn BezierElements + 'a),
    /// Smallest scaled Jacobian of each straight element over the coarse lattice (an upper
    /// bound of s_S; NaN on other processes' elements).
    coarse: Vec<f64>,
    /// s_S, evaluated when a verdict or the percentile needs it.
    fine: Vec<OnceLock<f64>>,
    /// P_s, the whole mesh's 1st percentile of s_S.
    p1: f64,
    /// q_min and q_p.
    own_fraction: f64,
    floor_fraction: f64,
}

impl<'a> StraightScaledJacobians<'a> {
    /// The scaled Jacobians of the straight elements `mine` of `straight`, whose certified
    /// lower bounds of det J are `lower`; the percentile is the whole mesh's over `share`.
    ///
    /// P_s exactly, without s_S of every element: with T the coarse values' element at the
    /// percentile's rank k, at least k + 1 elements have s_S ≤ T, so the element at rank k
    /// has s_S ≤ T and is among those whose certified lower bound is at most T; only those
    /// are sampled on the fine lattice (every element, should rounding leave fewer than
    /// k + 1 of them).
    pub(super) fn new(
        straight: &'a (dyn BezierElements + 'a),
        mine: &[usize],
        lower: &[f64],
        (own_fraction, floor_fraction): (f64, f64),
        share: &dyn BlendShare,
    ) -> Self {
        let (dim, n) = (straight.dim(), straight.n_elements());
        let shapes: Vec<(f64, f64)> = mine
            .par_iter()
            .map(|&e| {
                let net = straight.bezier_net(e);
                (
                    lattice_scaled_jacobian(dim, &net),
                    lower[e] / hadamard_upper(dim, &net),
                )
            })
            .collect();
        let mut coarse = vec![f64::NAN; n];
        for (&e, s) in mine.iter().zip(&shapes) {
            coarse[e] = s.0;
        }
        let mut sorted = share.concat(shapes.iter().map(|s| s.0).collect());
        sorted.sort_by(f64::total_cmp);
        let k = sorted.len() / 100;
        let t = sorted.get(k).copied().unwrap_or(1.0);
        let mut sj = StraightScaledJacobians {
            dim,
            straight,
            coarse,
            fine: (0..n).map(|_| OnceLock::new()).collect(),
            p1: 1.0,
            own_fraction,
            floor_fraction,
        };
        let low = |bound: f64| bound <= t + ROUNDING * t.abs().max(1.0);
        let candidates = |all: bool| -> Vec<f64> {
            let mine: Vec<usize> = mine
                .iter()
                .zip(&shapes)
                .filter(|(_, s)| all || low(s.1))
                .map(|(&e, _)| e)
                .collect();
            let values: Vec<f64> = mine.par_iter().map(|&e| sj.fine(e)).collect();
            let mut values = share.concat(values);
            values.sort_by(f64::total_cmp);
            values
        };
        let mut values = candidates(false);
        if values.len() <= k && !sorted.is_empty() {
            values = candidates(true);
        }
        sj.p1 = values.get(k).copied().unwrap_or(1.0);
        sj
    }

    /// s_S of element `e`.
    fn fine(&self, e: usize) -> f64 {
        *self.fine[e]
            .get_or_init(|| fine_lattice_scaled_jacobian(self.dim, &self.straight.bezier_net(e)))
    }

    /// The targets (own, floor) of an element whose s_S is `s`: q_min · s and
    /// max(q_min · s, q_p · min(s, P_s)), both nondecreasing in `s`.
    fn targets(&self, s: f64) -> (f64, f64) {
        let own = self.own_fraction * s;
        (own, own.max(self.floor_fraction * s.min(self.p1)))
    }

    /// Whether the blended net `net` of element `e` meets its scaled Jacobian's targets
    /// (own, max(floor, `kept`)) on the fine lattice, `bound` a certified lower bound of its
    /// scaled Jacobian over the element. Decided without sampling where the bound reaches the
    /// second target at the straight element's coarse value (an upper bound of the floor);
    /// else the coarse lattice rejects below a target, and only the elements it passes and
    /// the bound does not are sampled on the fine lattice.
    pub(super) fn verdict(&self, e: usize, net: &Net, bound: f64, kept: f64) -> (bool, bool) {
        let upper = self.coarse[e] + ROUNDING * self.coarse[e].abs().max(1.0);
        if bound >= self.targets(upper).1.max(kept) {
            return (true, true);
        }
        let (own, floor) = self.targets(self.fine(e));
        let floor = floor.max(kept);
        if bound >= floor {
            return (true, true);
        }
        let coarse = lattice_scaled_jacobian(self.dim, net);
        if coarse < own {
            return (false, false);
        }
        let own_known = bound >= own;
        if own_known && coarse < floor {
            return (true, false);
        }
        let fine = fine_lattice_scaled_jacobian(self.dim, net);
        (own_known || fine >= own, fine >= floor)
    }
}
