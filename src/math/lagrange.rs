//! Lagrange basis on the equispaced nodes 0, 1/p, …, 1 of \[0, 1\]: the node family of every
//! order-p output element (quality, elastic analogy, plots, comparison, deviation).
//!
//! Invariants: L_i(j/p) = δ_ij, Σ_i L_i = 1, Σ_i L_i' = 0. The products are formed in node
//! order j = 0..=p, so [`lagrange_1d`] and [`lagrange_values`] give the same f64 values.

/// Values and derivatives of the p+1 basis functions at `t` (`values`, `derivs`: p+1 slots).
pub fn lagrange_1d(p: usize, t: f64, values: &mut [f64], derivs: &mut [f64]) {
    let nodes: Vec<f64> = (0..=p).map(|i| i as f64 / p as f64).collect();
    for i in 0..=p {
        let mut v = 1.0;
        let mut d = 0.0;
        for j in 0..=p {
            if j == i {
                continue;
            }
            let denom = nodes[i] - nodes[j];
            // Product rule: d/dt Π (t - x_j)/(x_i - x_j).
            d = d * (t - nodes[j]) / denom + v / denom;
            v *= (t - nodes[j]) / denom;
        }
        values[i] = v;
        derivs[i] = d;
    }
}

/// Values of the p+1 basis functions at `t` (the values of [`lagrange_1d`], without derivatives).
pub fn lagrange_values(p: usize, t: f64) -> Vec<f64> {
    (0..=p)
        .map(|i| {
            let ti = i as f64 / p as f64;
            (0..=p)
                .filter(|&j| j != i)
                .map(|j| {
                    let tj = j as f64 / p as f64;
                    (t - tj) / (ti - tj)
                })
                .product()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_sums_to_one_and_agrees_bitwise() {
        for p in 1..=10 {
            let (mut v, mut d) = (vec![0.0; p + 1], vec![0.0; p + 1]);
            for i in 0..=p {
                lagrange_1d(p, i as f64 / p as f64, &mut v, &mut d);
                for j in 0..=p {
                    let want = if i == j { 1.0 } else { 0.0 };
                    assert!((v[j] - want).abs() < 1e-12, "p {p} L{j}({i}/p) = {}", v[j]);
                }
            }
            for s in 0..=13 {
                let t = s as f64 / 13.0;
                lagrange_1d(p, t, &mut v, &mut d);
                assert!((v.iter().sum::<f64>() - 1.0).abs() < 1e-10);
                assert!(d.iter().sum::<f64>().abs() < 1e-8 * (p * p) as f64);
                assert_eq!(lagrange_values(p, t), v, "p {p} t {t}");
                // Derivative against a central difference of the values.
                let h = 1e-6;
                let (a, b) = (lagrange_values(p, t + h), lagrange_values(p, t - h));
                for j in 0..=p {
                    let fd = (a[j] - b[j]) / (2.0 * h);
                    assert!((d[j] - fd).abs() < 1e-5 * (1.0 + fd.abs()) * (p * p) as f64);
                }
            }
        }
    }
}
