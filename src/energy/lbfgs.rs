//! The global minimiser: L-BFGS on the free control points with a certified Armijo line
//! search ([`super::EnergySolver::Lbfgs`]).
//!
//! Input: the [`Energy`], a certified start, the [`Validity`] test. Output: the last accepted
//! iterate and an [`EnergyInfo`]. Invariant: every accepted iterate lowers Q and keeps every
//! element certified; the frozen (boundary) control points never move (their gradient is 0).

use super::{Energy, EnergyInfo, EnergyParams, EnergySolver, EnergyStop, Validity};
use rayon::prelude::*;

fn dot(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.par_chunks(4096)
        .zip(b.par_chunks(4096))
        .map(|(a, b)| {
            a.iter()
                .zip(b)
                .map(|(x, y)| x[0] * y[0] + x[1] * y[1] + x[2] * y[2])
                .sum::<f64>()
        })
        .collect::<Vec<f64>>()
        .iter()
        .sum()
}

fn max_abs(a: &[[f64; 3]]) -> f64 {
    a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()))
}

fn axpy(x: &[[f64; 3]], a: f64, d: &[[f64; 3]]) -> Vec<[f64; 3]> {
    x.iter()
        .zip(d)
        .map(|(x, d)| [x[0] + a * d[0], x[1] + a * d[1], x[2] + a * d[2]])
        .collect()
}

/// An L-BFGS pair (s, y, 1 / sᵀy).
type Pair = (Vec<[f64; 3]>, Vec<[f64; 3]>, f64);

/// L-BFGS with Armijo backtracking; a step is accepted only when every element stays
/// certified (see the module docs of [`super`]).
pub(super) fn lbfgs(
    energy: &Energy,
    validity: &Validity,
    start: &[[f64; 3]],
    params: &EnergyParams,
    observe: &mut dyn FnMut(&[[f64; 3]]),
) -> (Vec<[f64; 3]>, EnergyInfo) {
    let n = start.len();
    let mut x = start.to_vec();
    let mut g = vec![[0.0; 3]; n];
    let mut f = energy.value_and_free_gradient(&x, &mut g);
    let mut info = EnergyInfo::start(EnergySolver::Lbfgs, energy.weight, f);
    info.evaluations = 1;
    let g0 = max_abs(&g);
    // First step: move the furthest control point by a tenth of the smallest element size.
    let h_min = energy.h_min;
    // (s, y, 1 / sᵀy) pairs, oldest first.
    let mut hist: std::collections::VecDeque<Pair> = Default::default();
    while info.iterations < params.max_iterations {
        if max_abs(&g) <= params.grad_tol * g0 {
            info.stop = EnergyStop::Gradient;
            break;
        }
        // Two-loop recursion.
        let mut d: Vec<[f64; 3]> = g.iter().map(|v| v.map(|x| -x)).collect();
        let mut alphas = Vec::with_capacity(hist.len());
        for (s, y, rho) in hist.iter().rev() {
            let a = rho * dot(s, &d);
            d = axpy(&d, -a, y);
            alphas.push(a);
        }
        if let Some((s, y, _)) = hist.back() {
            let gamma = dot(s, y) / dot(y, y);
            for v in d.iter_mut() {
                for c in v.iter_mut() {
                    *c *= gamma;
                }
            }
        } else {
            let scale = 0.1 * h_min / max_abs(&d).max(f64::MIN_POSITIVE);
            for v in d.iter_mut() {
                for c in v.iter_mut() {
                    *c *= scale;
                }
            }
        }
        for ((s, y, rho), a) in hist.iter().zip(alphas.iter().rev()) {
            let b = rho * dot(y, &d);
            d = axpy(&d, a - b, s);
        }
        let mut slope = dot(&g, &d);
        if !(slope < 0.0) {
            hist.clear();
            let scale = 0.1 * h_min / max_abs(&g).max(f64::MIN_POSITIVE);
            d = g.iter().map(|v| v.map(|x| -scale * x)).collect();
            slope = dot(&g, &d);
        }
        // Armijo backtracking; a trial counts only when every element stays certified.
        let mut alpha = 1.0;
        let mut accepted = None;
        for _ in 0..=params.max_backtracks {
            let xn = axpy(&x, alpha, &d);
            let mut gn = vec![[0.0; 3]; n];
            let fnew = energy.value_and_free_gradient(&xn, &mut gn);
            info.evaluations += 1;
            if fnew.is_finite() && fnew <= f + 1e-4 * alpha * slope {
                if validity.accepts(energy, &xn) {
                    accepted = Some((xn, gn, fnew));
                    break;
                }
                info.uncertified_trials += 1;
            }
            alpha *= 0.5;
        }
        let Some((xn, gn, fnew)) = accepted else {
            info.stop = EnergyStop::LineSearch;
            break;
        };
        info.iterations += 1;
        observe(&xn);
        let s: Vec<[f64; 3]> = xn
            .iter()
            .zip(&x)
            .map(|(a, b)| [a[0] - b[0], a[1] - b[1], a[2] - b[2]])
            .collect();
        let y: Vec<[f64; 3]> = gn
            .iter()
            .zip(&g)
            .map(|(a, b)| [a[0] - b[0], a[1] - b[1], a[2] - b[2]])
            .collect();
        let sy = dot(&s, &y);
        if sy > 1e-12 * dot(&y, &y).sqrt() * dot(&s, &s).sqrt() {
            if hist.len() == params.history.max(1) {
                hist.pop_front();
            }
            hist.push_back((s, y, 1.0 / sy));
        }
        let decrease = f - fnew;
        x = xn;
        g = gn;
        f = fnew;
        if decrease <= params.rel_tol * f.abs().max(f64::MIN_POSITIVE) {
            info.stop = EnergyStop::Stalled;
            break;
        }
    }
    info.final_energy = f;
    (x, info)
}
