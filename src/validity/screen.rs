//! A cheap certified lower bound of det J, run before the exact Bernstein certificate.
//!
//! **Bound.** The columns of J of a quadratic Bézier element are polynomials whose Bernstein
//! coefficients are a_i = 2ΔP (differences of the net along u), b_j (along v), c_k (along w).
//! det J is trilinear in its columns, so every Bernstein coefficient of det J (degree (5,5,5))
//! is a convex combination of det(a_i, b_j, c_k). For any constant vectors a₀, b₀, c₀,
//!
//!   det(a, b, c) = det(a₀, b₀, c₀) + det(a₀, b₀, c − c₀) + det(a₀, b − b₀, c) + det(a − a₀, b, c),
//!
//! and Hadamard's inequality |det(x, y, z)| ≤ |x||y||z| gives, for every coefficient triple,
//!
//!   det(a_i, b_j, c_k) ≥ det(a₀, b₀, c₀) − |a₀||b₀|·D_c − |a₀|·D_b·M_c − D_a·M_b·M_c
//!
//! with D_a = max_i |a_i − a₀| and M_a = max_i |a_i| (likewise for b, c; in 2D the same with
//! two columns). [`screen_bounds`] takes a₀, b₀, c₀ at the centres of the coefficients'
//! bounding boxes and subtracts a forward rounding-error margin. The result is a lower bound of
//! det J on the element that is also ≤ every Bernstein coefficient of det J, hence ≤ the
//! exact certificate's lower bound ([`super::det_jacobian_bounds`], whose subdivision only
//! takes convex combinations of coefficients). Its upper value is the smallest det J at a
//! corner (a value attained in the element), as in the exact certificate.
//!
//! **Use.** It costs a small fraction of the exact certificate's arithmetic and decides
//! nearly all elements of a fitted mesh. [`certify_screened`] certifies every element whose
//! screen bound already exceeds its target (the acceptance threshold, or 0) and runs the exact
//! certificate, on the given [`Certifier`] (CPU or GPU), only for the rest. Because screen ≤ exact, every decision
//! "lower bound > t" with t ≤ the target is the one the exact certificate takes.
//! [`Screened::refine_smallest`] then computes the exact certificate for as many screened
//! elements as needed so that the k smallest lower bounds of the mesh are the exact ones: the
//! reported minimum and the worst elements are those of the exact certificate.

use super::{Certifier, DetBounds};
use crate::math::BezierNet;
use rayon::prelude::*;

/// Elements certified exactly per refinement batch in [`Screened::refine_smallest`].
const REFINE_BATCH: usize = 64;

/// Roundings counted per term of the screen bound, generously: each term is a product of three
/// quantities computed with a few roundings each, and det(a₀, b₀, c₀) sums six such products.
const SCREEN_ROUNDINGS: f64 = 128.0;

/// Screen bound of one element (see the module docs): `lower` ≤ every Bernstein coefficient of
/// det J (so ≤ min det J), `upper` = the smallest corner value of det J.
pub fn screen_bounds(dim: usize, net: &BezierNet) -> DetBounds {
    let at = |i: usize, j: usize, k: usize| net[i + 3 * j + 9 * k];
    let nz = if dim == 2 { 1 } else { 3 };
    let nc = if dim == 2 { 2 } else { 3 };
    // Columns' Bernstein coefficients: cols[d][n], n = lattice index of the lower point.
    let mut cols = [[[0.0f64; 3]; 18]; 3];
    let mut count = [0usize; 3];
    for k in 0..nz {
        for j in 0..3 {
            for i in 0..3 {
                let p = at(i, j, k);
                let mut push = |d: usize, q: [f64; 3]| {
                    // A quad's z column is the unit vector; its nets' z differences are unused.
                    let z = if dim == 2 { 0.0 } else { 2.0 * (q[2] - p[2]) };
                    cols[d][count[d]] = [2.0 * (q[0] - p[0]), 2.0 * (q[1] - p[1]), z];
                    count[d] += 1;
                };
                if i < 2 {
                    push(0, at(i + 1, j, k));
                }
                if j < 2 {
                    push(1, at(i, j + 1, k));
                }
                if dim == 3 && k < 2 {
                    push(2, at(i, j, k + 1));
                }
            }
        }
    }
    let norm = |x: [f64; 3]| (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
    // Per column: centre a₀ (bounding-box midpoint), |a₀|, D = max |a − a₀|, M = max |a|.
    let mut centre = [[0.0f64; 3]; 3];
    let mut n0 = [1.0f64; 3];
    let mut dev = [0.0f64; 3];
    let mut max = [1.0f64; 3];
    for d in 0..nc {
        let c = &cols[d][..count[d]];
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for x in c {
            for r in 0..nc {
                lo[r] = lo[r].min(x[r]);
                hi[r] = hi[r].max(x[r]);
            }
        }
        for r in 0..nc {
            centre[d][r] = 0.5 * (lo[r] + hi[r]);
        }
        n0[d] = norm(centre[d]);
        // Largest squared norms, one square root each (sqrt is monotone and correctly
        // rounded, so this equals the largest of the norms).
        let sq = |x: [f64; 3]| x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
        let (mut dv, mut mx) = (0.0f64, 0.0f64);
        for x in c {
            dv = dv.max(sq([
                x[0] - centre[d][0],
                x[1] - centre[d][1],
                x[2] - centre[d][2],
            ]));
            mx = mx.max(sq(*x));
        }
        dev[d] = dv.sqrt();
        max[d] = mx.sqrt();
    }
    let det3 = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
        a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0])
    };
    let det = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
        if dim == 2 {
            a[0] * b[1] - a[1] * b[0]
        } else {
            det3(a, b, c)
        }
    };
    // In 2D the third column is the unit z vector: centre (0,0,1), no deviation, norm 1.
    if dim == 2 {
        centre[2] = [0.0, 0.0, 1.0];
    }
    let det0 = det(centre[0], centre[1], centre[2]);
    let spread = n0[0] * n0[1] * dev[2] + n0[0] * dev[1] * max[2] + dev[0] * max[1] * max[2];
    let scale = (n0[0] + dev[0]) * (n0[1] + dev[1]) * (n0[2] + dev[2]);
    let lower = det0 - spread - SCREEN_ROUNDINGS * f64::EPSILON * scale;
    // Corner values: the coefficient of each column at the corner's end of each direction.
    let mut upper = f64::INFINITY;
    let col = |d: usize, l: [usize; 3]| {
        // Index of lattice point l among the lower points of direction d (i fastest).
        let n = [if d == 0 { 2 } else { 3 }, if d == 1 { 2 } else { 3 }];
        cols[d][l[0] + n[0] * (l[1] + n[1] * l[2])]
    };
    for ck in 0..nz.min(2) {
        for cj in 0..2 {
            for ci in 0..2 {
                let a = col(0, [ci, 2 * cj, 2 * ck]);
                let b = col(1, [2 * ci, cj, 2 * ck]);
                let c = if dim == 2 {
                    [0.0, 0.0, 1.0]
                } else {
                    col(2, [2 * ci, 2 * cj, ck])
                };
                upper = upper.min(det(a, b, c));
            }
        }
    }
    DetBounds {
        lower: lower.min(upper),
        upper,
    }
}

/// Certified bounds of a batch of elements, with which of them come from the exact
/// certificate (the others from the screen).
#[derive(Clone, Debug, Default)]
pub struct Screened {
    /// Bounds of `elements[i]`, as [`Certifier::certify`] returns them.
    pub bounds: Vec<DetBounds>,
    /// Whether `bounds[i]` is the exact certificate's.
    pub exact: Vec<bool>,
}

/// Certified bounds of `elements`: the screen bound where it exceeds `target(e)`, else the
/// exact certificate from `certifier`. Every decision "lower > t" with t ≤ `target(e)` is the
/// exact certificate's.
pub fn certify_screened(
    certifier: &dyn Certifier,
    dim: usize,
    elements: &[usize],
    net: &(dyn Fn(usize) -> BezierNet + Sync),
    max_depth: usize,
    target: &(dyn Fn(usize) -> f64 + Sync),
) -> Screened {
    let mut bounds: Vec<DetBounds> = elements
        .par_iter()
        .map(|&e| screen_bounds(dim, &net(e)))
        .collect();
    let mut exact: Vec<bool> = elements
        .par_iter()
        .zip(&bounds)
        .map(|(&e, b)| !(b.lower > target(e)))
        .collect();
    let rest: Vec<usize> = (0..elements.len()).filter(|&i| exact[i]).collect();
    if !rest.is_empty() {
        let ids: Vec<usize> = rest.iter().map(|&i| elements[i]).collect();
        for (i, b) in rest
            .into_iter()
            .zip(certifier.certify(dim, &ids, net, max_depth))
        {
            bounds[i] = b;
        }
    }
    exact.shrink_to_fit();
    Screened { bounds, exact }
}

impl Screened {
    /// Replace screened bounds by exact ones until the `k` smallest lower bounds are exact,
    /// so that the minimum and the `k` least certified elements are the exact certificate's.
    /// A screened bound never exceeds the exact one, so an element whose screened bound is at
    /// least the k-th smallest exact bound cannot enter the k smallest.
    pub fn refine_smallest(
        &mut self,
        certifier: &dyn Certifier,
        dim: usize,
        elements: &[usize],
        net: &(dyn Fn(usize) -> BezierNet + Sync),
        max_depth: usize,
        k: usize,
    ) {
        if k == 0 {
            return;
        }
        loop {
            let mut exact: Vec<f64> = (0..self.bounds.len())
                .filter(|&i| self.exact[i])
                .map(|i| self.bounds[i].lower)
                .collect();
            let kth = if exact.len() >= k {
                *exact.select_nth_unstable_by(k - 1, |a, b| a.total_cmp(b)).1
            } else {
                f64::INFINITY
            };
            let mut candidates: Vec<usize> = (0..self.bounds.len())
                .filter(|&i| !self.exact[i] && self.bounds[i].lower < kth)
                .collect();
            if candidates.is_empty() {
                return;
            }
            if candidates.len() > REFINE_BATCH {
                let key = |&i: &usize| (self.bounds[i].lower, i);
                candidates.select_nth_unstable_by(REFINE_BATCH - 1, |a, b| {
                    let (x, y) = (key(a), key(b));
                    x.0.total_cmp(&y.0).then(x.1.cmp(&y.1))
                });
                candidates.truncate(REFINE_BATCH);
            }
            let ids: Vec<usize> = candidates.iter().map(|&i| elements[i]).collect();
            for (i, b) in candidates
                .into_iter()
                .zip(certifier.certify(dim, &ids, net, max_depth))
            {
                self.bounds[i] = b;
                self.exact[i] = true;
            }
        }
    }

    /// Smallest lower bound (exact after [`Self::refine_smallest`] with k ≥ 1).
    pub fn min_lower(&self) -> f64 {
        self.bounds
            .iter()
            .map(|b| b.lower)
            .fold(f64::INFINITY, f64::min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validity::{CpuCertifier, det_jacobian_bernstein, det_jacobian_bounds};

    /// Deterministic pseudo-random numbers in [−1, 1] (xorshift).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        }
    }

    /// A unit cube (square), affinely sheared and scaled, with every Bézier point moved by up
    /// to `amp`.
    fn random_net(rng: &mut Rng, dim: usize, amp: f64) -> BezierNet {
        let mut a = [[0.0; 3]; 3];
        for (r, row) in a.iter_mut().enumerate() {
            for (c, x) in row.iter_mut().enumerate() {
                *x = if r == c { 1.0 } else { 0.3 * rng.next() };
            }
        }
        let s = 0.01 + 2.0 * (rng.next() + 1.0);
        let mut net = [[0.0; 3]; 27];
        let nz = if dim == 2 { 1 } else { 3 };
        for k in 0..nz {
            for j in 0..3 {
                for i in 0..3 {
                    let t = [i as f64 / 2.0, j as f64 / 2.0, k as f64 / 2.0];
                    let mut x = [0.0; 3];
                    for r in 0..dim {
                        for c in 0..dim {
                            x[r] += s * a[r][c] * t[c];
                        }
                        x[r] += s * amp * rng.next();
                    }
                    net[i + 3 * j + 9 * k] = x;
                }
            }
        }
        net
    }

    #[test]
    fn screen_is_below_the_bernstein_coefficients_and_the_sampled_det() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let mut decided = 0;
        for dim in [2, 3] {
            for trial in 0..400 {
                let amp = [0.0, 0.02, 0.1, 0.3][trial % 4];
                let net = random_net(&mut rng, dim, amp);
                let s = screen_bounds(dim, &net);
                let b = det_jacobian_bernstein(dim, &net);
                let min_coef = b.coef.iter().copied().fold(f64::INFINITY, f64::min);
                assert!(s.lower <= min_coef, "dim {dim}: {} > {min_coef}", s.lower);
                let exact = det_jacobian_bounds(dim, &net, 6);
                assert!(s.lower <= exact.lower, "{s:?} vs {exact:?}");
                // Independent oracle: det J from finite differences of the map on a dense grid.
                let n = if dim == 2 { 24 } else { 10 };
                let nz = if dim == 2 { 0 } else { n };
                let mut sampled = f64::INFINITY;
                for k in 0..=nz {
                    for j in 0..=n {
                        for i in 0..=n {
                            let t = [i, j, k].map(|x| x as f64 / n as f64);
                            sampled = sampled.min(det_fd(dim, &net, t));
                        }
                    }
                }
                assert!(
                    s.lower <= sampled + 1e-7 * s.upper.abs().max(1.0),
                    "{s:?} vs {sampled}"
                );
                assert!(
                    s.upper >= sampled - 1e-7 * s.upper.abs().max(1.0),
                    "{s:?} vs {sampled}"
                );
                // The corner value is a value of det J: it matches the exact certificate's.
                let corner =
                    b.eval([0.0; 3])
                        .min(b.eval([1.0, 1.0, if dim == 2 { 0.0 } else { 1.0 }]));
                assert!(s.upper <= corner + 1e-9 * corner.abs().max(1.0));
                if amp == 0.02 && s.lower > 0.0 {
                    decided += 1;
                }
            }
        }
        // Mildly curved elements are decided by the screen alone.
        assert!(
            decided >= 190,
            "{decided} of 200 mildly curved elements screened"
        );
    }

    /// det J of the Bézier map at `t` by central differences of the map (independent of the
    /// Bernstein algebra).
    fn det_fd(dim: usize, net: &BezierNet, t: [f64; 3]) -> f64 {
        crate::validity::tests::det_fd(dim, &|u| crate::math::bernstein::eval_net(dim, net, u), t)
    }

    #[test]
    fn screened_decisions_and_smallest_bounds_match_the_exact_certificate() {
        let mut rng = Rng(12345);
        for dim in [2, 3] {
            // Mixed batch: straight, mildly and strongly curved, and folded elements.
            let nets: Vec<BezierNet> = (0..300)
                .map(|i| random_net(&mut rng, dim, [0.0, 0.01, 0.1, 0.5, 0.9][i % 5]))
                .collect();
            let all: Vec<usize> = (0..nets.len()).collect();
            let net = |e: usize| nets[e];
            let exact = CpuCertifier.certify(dim, &all, &net, 6);
            assert!(
                exact.iter().any(|b| !b.certified_positive()),
                "some invalid"
            );
            let targets: Vec<f64> = all
                .iter()
                .map(|&e| 0.3 * exact[e].upper.abs() * (e % 3) as f64 / 2.0)
                .collect();
            let mut s = certify_screened(&CpuCertifier, dim, &all, &net, 6, &|e| targets[e]);
            assert!(
                s.exact.iter().any(|&x| !x),
                "the screen decides some elements"
            );
            for e in 0..nets.len() {
                assert!(s.bounds[e].lower <= exact[e].lower);
                for t in [0.0, targets[e]] {
                    assert_eq!(s.bounds[e].lower > t, exact[e].lower > t, "element {e}");
                }
            }
            s.refine_smallest(&CpuCertifier, dim, &all, &net, 6, 10);
            let mut want: Vec<f64> = exact.iter().map(|b| b.lower).collect();
            let mut got: Vec<f64> = s.bounds.iter().map(|b| b.lower).collect();
            want.sort_by(f64::total_cmp);
            got.sort_by(f64::total_cmp);
            assert_eq!(want[..10], got[..10]);
            assert_eq!(s.min_lower(), want[0]);
        }
    }
}
