//! Gauss–Legendre rules on \[0, 1\] (weights summing to 1): the energy's fixed 3-point rule
//! ([`GAUSS3`]) and the n-point rule of the elastic analogy ([`gauss_legendre`]).
//!
//! Invariant: the n-point rule integrates polynomials of degree ≤ 2n − 1 exactly (up to
//! rounding). [`GAUSS3`] is the closed form (1/2 ∓ √15/10, weights 5/18, 8/18, 5/18);
//! `gauss_legendre(3)` (Newton on P₃) agrees with it to about 1e-15 but not bit for bit (its
//! outer weights are 0.27777777777777635, not 5/18), so each caller keeps the rule it has
//! always used and outputs do not move by an ulp.

/// 3-point Gauss rule on \[0, 1\] as (point, weight) (exact to degree 5).
pub const GAUSS3: [(f64, f64); 3] = [
    (0.112_701_665_379_258_31, 5.0 / 18.0),
    (0.5, 8.0 / 18.0),
    (0.887_298_334_620_741_7, 5.0 / 18.0),
];

/// Gauss–Legendre points and weights on \[0, 1\] (n points, exact to degree 2n − 1).
pub fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let (mut xs, mut ws) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for i in 0..n {
        // Newton on P_n from the Chebyshev-like guess; converges in a few steps.
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            let pn = if n == 0 { 1.0 } else { p1 };
            let pm = if n == 1 { 1.0 } else { p0 };
            dp = n as f64 * (x * pn - pm) / (x * x - 1.0);
            let dx = pn / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        xs.push(0.5 * (1.0 - x));
        ws.push(1.0 / ((1.0 - x * x) * dp * dp));
    }
    (xs, ws)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫₀¹ t^k dt = 1/(k+1): exact up to degree 2n − 1, and not at degree 2n (the rule's
    /// error term is non-zero there, so a rule of lower order would be caught).
    #[test]
    fn rules_integrate_monomials_to_their_degree() {
        for n in 1..=8 {
            let (xs, ws) = gauss_legendre(n);
            let q = |k: i32| -> f64 { xs.iter().zip(&ws).map(|(x, w)| w * x.powi(k)).sum() };
            for k in 0..2 * n as i32 {
                assert!(
                    (q(k) - 1.0 / (k + 1) as f64).abs() < 1e-14,
                    "n {n} degree {k}"
                );
            }
            let k = 2 * n as i32;
            assert!(
                (q(k) - 1.0 / (k + 1) as f64).abs() > 1e-12,
                "n {n} degree {k}"
            );
        }
        let (xs, ws) = gauss_legendre(3);
        let mut sorted: Vec<(f64, f64)> = xs.into_iter().zip(ws).collect();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        for ((x, w), (gx, gw)) in sorted.iter().zip(GAUSS3) {
            assert!((x - gx).abs() < 1e-14, "{x} vs {gx}");
            assert!((w - gw).abs() < 1e-14, "{w} vs {gw}");
        }
        let r = (0.6f64).sqrt() / 2.0;
        assert!((GAUSS3[0].0 - (0.5 - r)).abs() < 2.0 * f64::EPSILON);
        assert!((GAUSS3[2].0 - (0.5 + r)).abs() < 2.0 * f64::EPSILON);
    }
}
