//! The certified line searches of a fitted step C(s) = C0 + s ⊙ (C* − C0) (paper §2.3): one
//! factor for the whole mesh ([`line_search_with`]) or one per control point
//! ([`local_line_search_with`]), [`certified_step`] choosing between them by
//! [`LineSearchMode`], and the per-element acceptance thresholds ([`acceptance_thresholds`]).
//!
//! Input: the certified initial control points C0, the fitted C*, each element's Bézier net as
//! a function of the control points. Output: control points on the segment whose every element
//! is certified above its threshold, or [`ValidityError::InitialInvalid`] when C0 itself is not.

use super::blend;
use super::certificate::{Certifier, CpuCertifier};
use super::{DetBounds, certify_screened};
use crate::math::BezierNet;
use crate::mesh::LinearMesh;
use crate::params::{ParamError, above, in_range};

/// How the fitted step is shortened where it would invalidate elements.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LineSearchMode {
    /// One α for all control points (paper §2.3).
    Global,
    /// A factor per control point, halved only around elements that are not certified
    /// ([`local_line_search`]).
    Local,
}

/// Line-search parameters (paper §2.3: bisection on α in C(α) = C0 + α(C* − C0)).
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct LineSearchParams {
    /// Bisection steps at most.
    pub max_bisections: usize,
    /// Stop when the bracket [valid α, invalid α] is narrower than this.
    pub tolerance: f64,
    /// Subdivision depth of the Bernstein certificate.
    pub certificate_depth: usize,
    /// Accept an element only when its certified det J lower bound exceeds this fraction of
    /// the smallest corner det J of its straight input element (capped at half the initial
    /// map's own bound), so a valid result is not also a nearly degenerate one. 0 accepts any
    /// certified-positive element, as in the paper.
    pub min_det_fraction: f64,
    /// Least-squares fits: accept an element only when its Jacobian ratio bound (min det J
    /// over max det J, certified) is at least this fraction of its straight elevation's
    /// ([`blend`]); 0 turns the test off.
    pub min_quality_fraction: f64,
    /// … and its ratio and scaled Jacobian at least this fraction of min(its straight
    /// elevation's, the straight mesh's 1st percentile) ([`blend`]).
    pub percentile_quality_fraction: f64,
    /// Hold elements back until their scaled Jacobian also meets the floor
    /// max(q_min · s_S, q_p · min(s_S, P_s)) ([`blend`]); without it only the element rules.
    pub scaled_jacobian_floor: bool,
}

impl Default for LineSearchParams {
    fn default() -> Self {
        LineSearchParams {
            max_bisections: 30,
            tolerance: 1e-3,
            certificate_depth: 6,
            min_det_fraction: 0.1,
            min_quality_fraction: 0.55,
            percentile_quality_fraction: 0.85,
            scaled_jacobian_floor: true,
        }
    }
}

impl LineSearchParams {
    /// The parameters of the certified blend ([`blend::blend_search`]); `global`: one factor
    /// for the whole mesh.
    pub fn blend(&self, global: bool) -> blend::BlendParams {
        blend::BlendParams {
            max_bisections: 6,
            certificate_depth: self.certificate_depth,
            min_det_fraction: self.min_det_fraction,
            min_quality_fraction: self.min_quality_fraction,
            percentile_quality_fraction: self.percentile_quality_fraction,
            global,
            scaled_jacobian_floor: self.scaled_jacobian_floor,
        }
    }
}

impl LineSearchParams {
    /// Fractions in [0, 1], a tolerance in (0, 1], at most 1000 bisections.
    pub fn check(&self) -> Result<(), ParamError> {
        in_range("--min-det-fraction", self.min_det_fraction, 0.0, 1.0)?;
        in_range(
            "--min-quality-fraction",
            self.min_quality_fraction,
            0.0,
            1.0,
        )?;
        in_range(
            "--percentile-quality-fraction",
            self.percentile_quality_fraction,
            0.0,
            1.0,
        )?;
        above("line-search tolerance", self.tolerance, 0.0, 1.0)?;
        if self.max_bisections > 1000 {
            return Err(ParamError::new(
                "--max-bisections",
                self.max_bisections,
                "must be at most 1000",
            ));
        }
        Ok(())
    }
}

/// One element and its certified lower bound of det J.
#[deny(missing_docs)]
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct WorstElement {
    /// Element index (0-based, input order).
    pub element: usize,
    /// Certified lower bound of det J.
    pub lower: f64,
    /// Upper bound of det J.
    pub upper: f64,
}

/// Outcome of the line search.
#[deny(missing_docs)]
#[derive(Clone, Debug, serde::Serialize)]
pub struct LineSearchInfo {
    /// Step taken: 1 when the full fit is certified valid.
    pub alpha: f64,
    /// Bisection steps made.
    pub bisections: usize,
    /// Elements not certified valid at α = 1.
    pub invalid_at_full_step: usize,
    /// The least certified elements at α = 1 (at most 10), worst first.
    pub worst_at_full_step: Vec<WorstElement>,
    /// Smallest certified lower bound of det J over the mesh at the chosen α.
    pub min_det_lower_bound: f64,
}

/// Why no valid mesh could be certified.
#[derive(Clone, Debug, thiserror::Error)]
pub enum ValidityError {
    #[error(
        "the initial spline map is not certified valid on {count} element(s) (first: {}); the input is too distorted for the spline space there",
        first.iter().map(|e| e.to_string()).collect::<Vec<_>>().join(", ")
    )]
    InitialInvalid { count: usize, first: Vec<usize> },
}

fn worst(bounds: &[DetBounds], n: usize) -> Vec<WorstElement> {
    let mut idx: Vec<usize> = (0..bounds.len()).collect();
    idx.sort_by(|&a, &b| bounds[a].lower.total_cmp(&bounds[b].lower));
    idx.into_iter()
        .take(n)
        .map(|e| WorstElement {
            element: e,
            lower: bounds[e].lower,
            upper: bounds[e].upper,
        })
        .collect()
}

/// Largest certified-valid α in [0, 1] for C(α) = C0 + α(C* − C0), by bisection. `net(e, cps)`
/// gives the Bernstein net of element e for control points cps. An element is accepted when
/// its certified lower bound of det J exceeds `thresholds[e]` (0 where the slice is short).
/// C0 must be accepted.
pub fn line_search(
    dim: usize,
    n_elements: usize,
    net: impl Fn(usize, &[[f64; 3]]) -> BezierNet + Sync,
    c0: &[[f64; 3]],
    c_star: &[[f64; 3]],
    thresholds: &[f64],
    params: &LineSearchParams,
) -> Result<(Vec<[f64; 3]>, LineSearchInfo), ValidityError> {
    line_search_with(
        &CpuCertifier,
        dim,
        n_elements,
        net,
        c0,
        c_star,
        thresholds,
        params,
    )
}

/// [`line_search`] with the certificates computed by `certifier`.
#[allow(clippy::too_many_arguments)]
pub fn line_search_with(
    certifier: &dyn Certifier,
    dim: usize,
    n_elements: usize,
    net: impl Fn(usize, &[[f64; 3]]) -> BezierNet + Sync,
    c0: &[[f64; 3]],
    c_star: &[[f64; 3]],
    thresholds: &[f64],
    params: &LineSearchParams,
) -> Result<(Vec<[f64; 3]>, LineSearchInfo), ValidityError> {
    let all: Vec<usize> = (0..n_elements).collect();
    let threshold = |e: usize| thresholds.get(e).copied().unwrap_or(0.0);
    let ok = |e: usize, b: &DetBounds| b.lower > threshold(e);
    let at = |alpha: f64| -> Vec<[f64; 3]> {
        c0.iter()
            .zip(c_star)
            .map(|(a, b)| std::array::from_fn(|k| a[k] + alpha * (b[k] - a[k])))
            .collect()
    };
    // Screen against max(threshold, 0): both decisions below (> 0, > threshold) are then the
    // exact certificate's.
    let target = |e: usize| threshold(e).max(0.0);
    let depth = params.certificate_depth;
    let check =
        |cps: &[[f64; 3]]| certify_screened(certifier, dim, &all, &|e| net(e, cps), depth, &target);
    let mut full = check(c_star);
    full.refine_smallest(certifier, dim, &all, &|e| net(e, c_star), depth, 10);
    let bad: Vec<usize> = (0..n_elements)
        .filter(|&e| !full.bounds[e].certified_positive())
        .collect();
    let mut info = LineSearchInfo {
        alpha: 1.0,
        bisections: 0,
        invalid_at_full_step: bad.len(),
        worst_at_full_step: worst(&full.bounds, 10),
        min_det_lower_bound: full.min_lower(),
    };
    if bad.is_empty() {
        return Ok((c_star.to_vec(), info));
    }
    let start = check(c0);
    let bad0: Vec<usize> = (0..n_elements)
        .filter(|&e| !start.bounds[e].certified_positive())
        .collect();
    if !bad0.is_empty() {
        return Err(ValidityError::InitialInvalid {
            count: bad0.len(),
            first: bad0.into_iter().take(8).collect(),
        });
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    let mut lo_bounds = start;
    while info.bisections < params.max_bisections && hi - lo > params.tolerance {
        let mid = 0.5 * (lo + hi);
        let b = check(&at(mid));
        if b.bounds.iter().enumerate().all(|(e, x)| ok(e, x)) {
            lo = mid;
            lo_bounds = b;
        } else {
            hi = mid;
        }
        info.bisections += 1;
    }
    let c = at(lo);
    lo_bounds.refine_smallest(certifier, dim, &all, &|e| net(e, &c), depth, 1);
    info.alpha = lo;
    info.min_det_lower_bound = lo_bounds.min_lower();
    Ok((c, info))
}

/// Outcome of the local line search.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LocalSearchInfo {
    /// Rounds of halving.
    pub rounds: usize,
    /// Control points whose step was shortened, and the smallest step factor among them.
    pub damped_control_points: usize,
    pub min_step: f64,
    /// Elements not certified valid at the full step.
    pub invalid_at_full_step: usize,
    pub min_det_lower_bound: f64,
}

/// A local variant of the line search: every control point moves by its own factor
/// s_c ∈ [0, 1] of the fitted displacement, C = C0 + s ⊙ (C* − C0). Starting from s = 1,
/// the factors of all control points of elements that are not certified valid are halved
/// until every element is certified (after `max_bisections` halvings they are set to 0,
/// which restores the certified initial map locally). Elements away from trouble keep the
/// full least-squares step, where a single global α would shorten it everywhere.
/// `support(e)` lists the control points that element e depends on.
#[allow(clippy::too_many_arguments)]
pub fn local_line_search(
    dim: usize,
    n_elements: usize,
    net: impl Fn(usize, &[[f64; 3]]) -> BezierNet + Sync,
    support: impl Fn(usize) -> Vec<u32> + Sync,
    c0: &[[f64; 3]],
    c_star: &[[f64; 3]],
    thresholds: &[f64],
    params: &LineSearchParams,
) -> Result<(Vec<[f64; 3]>, LocalSearchInfo), ValidityError> {
    local_line_search_with(
        &CpuCertifier,
        dim,
        n_elements,
        net,
        support,
        c0,
        c_star,
        thresholds,
        params,
    )
}

/// [`local_line_search`] with the certificates computed by `certifier`.
#[allow(clippy::too_many_arguments)]
pub fn local_line_search_with(
    certifier: &dyn Certifier,
    dim: usize,
    n_elements: usize,
    net: impl Fn(usize, &[[f64; 3]]) -> BezierNet + Sync,
    support: impl Fn(usize) -> Vec<u32> + Sync,
    c0: &[[f64; 3]],
    c_star: &[[f64; 3]],
    thresholds: &[f64],
    params: &LineSearchParams,
) -> Result<(Vec<[f64; 3]>, LocalSearchInfo), ValidityError> {
    use rayon::prelude::*;
    let threshold = |e: usize| thresholds.get(e).copied().unwrap_or(0.0);
    let ok = |e: usize, b: &DetBounds| b.lower > threshold(e);
    // Screen against max(threshold, 0), so that the decisions are the exact certificate's.
    let target = |e: usize| threshold(e).max(0.0);
    let depth = params.certificate_depth;
    let n = c0.len();
    let mut step = vec![1.0f64; n];
    let place = |step: &[f64]| -> Vec<[f64; 3]> {
        c0.iter()
            .zip(c_star)
            .zip(step)
            .map(|((a, b), s)| std::array::from_fn(|k| a[k] + s * (b[k] - a[k])))
            .collect()
    };
    let mut cps = c_star.to_vec();
    let all: Vec<usize> = (0..n_elements).collect();
    let mut cert = certify_screened(certifier, dim, &all, &|e| net(e, &cps), depth, &target);
    let invalid_at_full_step = (0..n_elements).filter(|&e| !ok(e, &cert.bounds[e])).count();
    // Supports are needed only once some element fails.
    let mut supports: Vec<Vec<u32>> = Vec::new();
    let mut rounds = 0;
    loop {
        let bad: Vec<usize> = (0..n_elements)
            .filter(|&e| !ok(e, &cert.bounds[e]))
            .collect();
        if bad.is_empty() {
            break;
        }
        if supports.is_empty() {
            supports = (0..n_elements).into_par_iter().map(&support).collect();
        }
        let last = rounds >= params.max_bisections;
        if last {
            // Past the bisections whole supports are reset, which can leave a neighbour with a
            // mix of steps that is invalid although its initial map is valid; such elements
            // are reset in turn (each round zeroes more steps, so this ends). Only an element
            // whose whole support is back at the initial map has an invalid initial map.
            let initial: Vec<usize> = bad
                .iter()
                .copied()
                .filter(|&e| supports[e].iter().all(|&c| step[c as usize] == 0.0))
                .collect();
            if !initial.is_empty() {
                return Err(ValidityError::InitialInvalid {
                    count: initial.len(),
                    first: initial.into_iter().take(8).collect(),
                });
            }
        }
        let mut touched = vec![false; n];
        for &e in &bad {
            for &c in &supports[e] {
                let c = c as usize;
                if !touched[c] {
                    touched[c] = true;
                    step[c] = if last { 0.0 } else { 0.5 * step[c] };
                }
            }
        }
        cps = place(&step);
        // Re-certify the elements that depend on a changed control point.
        let recheck: Vec<usize> = (0..n_elements)
            .into_par_iter()
            .filter(|&e| supports[e].iter().any(|&c| touched[c as usize]))
            .collect();
        let fresh = certify_screened(certifier, dim, &recheck, &|e| net(e, &cps), depth, &target);
        for ((&e, b), x) in recheck.iter().zip(fresh.bounds).zip(fresh.exact) {
            cert.bounds[e] = b;
            cert.exact[e] = x;
        }
        rounds += 1;
    }
    cert.refine_smallest(certifier, dim, &all, &|e| net(e, &cps), depth, 1);
    let damped: Vec<f64> = step.iter().copied().filter(|&s| s < 1.0).collect();
    Ok((
        cps,
        LocalSearchInfo {
            rounds,
            damped_control_points: damped.len(),
            min_step: damped.iter().copied().fold(1.0, f64::min),
            invalid_at_full_step,
            min_det_lower_bound: cert.min_lower(),
        },
    ))
}

/// The step [`certified_step`] took.
#[derive(Clone, Debug)]
pub struct CertifiedStep {
    pub control_points: Vec<[f64; 3]>,
    /// The global α, or the smallest control point factor of the local search.
    pub alpha: f64,
    pub min_det_lower_bound: f64,
    pub invalid_at_full_step: usize,
    /// Control points held back from the full step (local search; 0 with the global one).
    pub damped_control_points: usize,
    /// The global search's details.
    pub global: Option<LineSearchInfo>,
}

/// The line search of `mode` from `c0` towards `c_star`; `support(e)` (the control points
/// element e depends on) is used by the local search only.
#[allow(clippy::too_many_arguments)]
pub fn certified_step(
    certifier: &dyn Certifier,
    mode: LineSearchMode,
    dim: usize,
    n_elements: usize,
    net: impl Fn(usize, &[[f64; 3]]) -> BezierNet + Sync,
    support: impl Fn(usize) -> Vec<u32> + Sync,
    c0: &[[f64; 3]],
    c_star: &[[f64; 3]],
    thresholds: &[f64],
    params: &LineSearchParams,
) -> Result<CertifiedStep, ValidityError> {
    match mode {
        LineSearchMode::Global => line_search_with(
            certifier, dim, n_elements, net, c0, c_star, thresholds, params,
        )
        .map(|(c, ls)| CertifiedStep {
            control_points: c,
            alpha: ls.alpha,
            min_det_lower_bound: ls.min_det_lower_bound,
            invalid_at_full_step: ls.invalid_at_full_step,
            damped_control_points: 0,
            global: Some(ls),
        }),
        LineSearchMode::Local => local_line_search_with(
            certifier, dim, n_elements, net, support, c0, c_star, thresholds, params,
        )
        .map(|(c, ls)| CertifiedStep {
            control_points: c,
            alpha: ls.min_step,
            min_det_lower_bound: ls.min_det_lower_bound,
            invalid_at_full_step: ls.invalid_at_full_step,
            damped_control_points: ls.damped_control_points,
            global: None,
        }),
    }
}

/// Per-element acceptance threshold of the line search: `fraction` × the smallest corner det J
/// of the straight input element, but never more than half of what the initial map is
/// certified to achieve (0 where the initial map is not certified). `certify(target)` certifies
/// the initial map; its bounds need to be exact only where they are at most `target(e)` =
/// 2 × `fraction` × reference, since above that the threshold is `fraction` × reference.
pub fn acceptance_thresholds(
    mesh: &LinearMesh,
    fraction: f64,
    certify: impl FnOnce(&(dyn Fn(usize) -> f64 + Sync)) -> Vec<DetBounds>,
) -> Vec<f64> {
    use rayon::prelude::*;
    if fraction <= 0.0 {
        return Vec::new();
    }
    let npe = mesh.nodes_per_element();
    let reference: Vec<f64> = (0..mesh.n_elements())
        .into_par_iter()
        .map(|e| {
            let x = mesh.element_coords(e);
            let mut jac = [0.0; 8];
            let mut scaled = [0.0; 8];
            crate::mesh::linear::corner_jacobians(
                mesh.dim,
                &x[..npe],
                &mut jac[..npe],
                &mut scaled[..npe],
            );
            jac[..npe]
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min)
                .max(0.0)
        })
        .collect();
    let initial = certify(&|e| 2.0 * (fraction * reference[e]));
    reference
        .par_iter()
        .zip(&initial)
        .map(|(&reference, initial)| {
            let initial = initial.lower;
            if initial > 0.0 {
                (fraction * reference).min(0.5 * initial)
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod local_search_tests {
    use super::*;

    /// A row of quads of width 1 + x(c_{e+1}) − x(c_e), height 1: element e depends on
    /// control points e and e + 1 and is valid iff its width is positive.
    fn row_net(e: usize, cps: &[[f64; 3]]) -> BezierNet {
        let w = 1.0 + cps[e + 1][0] - cps[e][0];
        let mut net = [[0.0; 3]; 27];
        for j in 0..3 {
            for i in 0..3 {
                net[3 * j + i] = [0.5 * i as f64 * w, 0.5 * j as f64, 0.0];
            }
        }
        net
    }

    #[test]
    fn resets_cascade_to_neighbours_instead_of_blaming_the_initial_map() {
        // Full step: element 0 has width −4; the others are valid (3, 3, 1). Resetting
        // element 0's support leaves element 1 at width −2, resetting that leaves element 2 at
        // width 0, and so on: every element ends valid, as its initial map is.
        let c0 = vec![[0.0; 3]; 5];
        let c_star: Vec<[f64; 3]> = [0.0, -5.0, -3.0, -1.0, -1.0]
            .iter()
            .map(|&x| [x, 0.0, 0.0])
            .collect();
        let params = LineSearchParams {
            max_bisections: 0,
            ..Default::default()
        };
        let support = |e: usize| vec![e as u32, e as u32 + 1];
        let (c, info) = local_line_search(2, 4, row_net, support, &c0, &c_star, &[], &params)
            .expect("the initial map is valid everywhere");
        assert!(info.min_det_lower_bound > 0.0);
        assert_eq!(info.invalid_at_full_step, 1);
        for e in 0..4 {
            assert!(1.0 + c[e + 1][0] - c[e][0] > 0.0, "element {e}");
        }
        // A really invalid initial map (element 2 of width −1 at c0) is still reported.
        let mut bad0 = c0.clone();
        bad0[3][0] = -2.0;
        match local_line_search(2, 4, row_net, support, &bad0, &c_star, &[], &params) {
            Err(ValidityError::InitialInvalid { first, .. }) => assert_eq!(first, vec![2]),
            other => panic!("{:?}", other.map(|(_, i)| i)),
        }
    }
}
