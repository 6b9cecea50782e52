//! One-dimensional quadratic bases of an element direction and their Bernstein forms.
//!
//! Every element direction carries one of five 1D bases on `[0, 1]` ([`Op1d`]): the four knot
//! cases of a spline element (`polyspline.md` §2.3, written as the closed-form polynomials, not
//! Cox–de Boor) or the quadratic Lagrange basis of a constrained Q2 element (nodes 0, ½, 1).
//! Each is a 3×3 change of basis to the quadratic Bernstein polynomials
//! `(1−t)², 2t(1−t), t²`: [`Op1d::bernstein_matrix`] maps the three coefficients of the basis
//! (stencil slots 0, 1, 2, or Lagrange values at 0, ½, 1) to the three Bernstein coefficients.
//! The element extraction operator is the tensor product of three of these (x fastest).

use crate::math::bernstein::{
    bernstein2 as bernstein, bernstein2_derivative as bernstein_derivative,
};

/// The 1D basis of one element direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Op1d {
    /// Spline, neighbours on both sides: knots `[-2,-1,0,1]`, `[-1,0,1,2]`, `[0,1,2,3]`.
    Interior = 0,
    /// Spline, no neighbour at t = 0 (boundary there): `[0,0,0,1]`, `[0,0,1,2]`, `[0,1,2,3]`.
    LeftEnd = 1,
    /// Spline, no neighbour at t = 1: `[-2,-1,0,1]`, `[-1,0,1,1]`, `[0,1,1,1]`.
    RightEnd = 2,
    /// Spline, no neighbour on either side: the Bernstein basis itself.
    BothEnds = 3,
    /// Quadratic Lagrange basis with nodes 0, ½, 1 (constrained Q2 elements).
    Lagrange = 4,
}

impl Op1d {
    /// Knot case of a spline direction from whether the neighbour at t = 0 / t = 1 is absent.
    pub fn spline(left_absent: bool, right_absent: bool) -> Op1d {
        match (left_absent, right_absent) {
            (false, false) => Op1d::Interior,
            (true, false) => Op1d::LeftEnd,
            (false, true) => Op1d::RightEnd,
            (true, true) => Op1d::BothEnds,
        }
    }

    /// The three basis functions at `t` (closed-form polynomials of §2.3).
    pub fn basis(self, t: f64) -> [f64; 3] {
        let s = 1.0 - t;
        match self {
            Op1d::Interior => [
                0.5 * s * s,
                0.5 * (1.0 + 2.0 * t - 2.0 * t * t),
                0.5 * t * t,
            ],
            Op1d::LeftEnd => [s * s, 2.0 * t - 1.5 * t * t, 0.5 * t * t],
            Op1d::RightEnd => [0.5 * s * s, 0.5 * (1.0 + 2.0 * t - 3.0 * t * t), t * t],
            Op1d::BothEnds => bernstein(t),
            Op1d::Lagrange => [s * (1.0 - 2.0 * t), 4.0 * t * s, t * (2.0 * t - 1.0)],
        }
    }

    /// Derivatives of [`Op1d::basis`] with respect to `t`.
    pub fn basis_derivative(self, t: f64) -> [f64; 3] {
        let s = 1.0 - t;
        match self {
            Op1d::Interior => [-s, 1.0 - 2.0 * t, t],
            Op1d::LeftEnd => [-2.0 * s, 2.0 - 3.0 * t, t],
            Op1d::RightEnd => [-s, 1.0 - 3.0 * t, 2.0 * t],
            Op1d::BothEnds => bernstein_derivative(t),
            Op1d::Lagrange => [4.0 * t - 3.0, 4.0 - 8.0 * t, 4.0 * t - 1.0],
        }
    }

    /// `M[i][j]`: Bernstein coefficient i of basis function j, so that the Bernstein
    /// coefficients of `Σ_j c_j N_j` are `M · c`.
    pub const fn bernstein_matrix(self) -> [[f64; 3]; 3] {
        match self {
            Op1d::Interior => [[0.5, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.5, 0.5]],
            Op1d::LeftEnd => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.5, 0.5]],
            Op1d::RightEnd => [[0.5, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            Op1d::BothEnds => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            Op1d::Lagrange => [[1.0, 0.0, 0.0], [-0.5, 2.0, -0.5], [0.0, 0.0, 1.0]],
        }
    }

    /// [`Op1d::bernstein_matrix`] with non-uniform knot intervals (`knot-intervals.md` §1):
    /// `w = [α, β]` with `α = h₀/(h₋₁+h₀)` the weight of the left neighbour's control point
    /// in the Bézier point at t = 0 and `β = h₁/(h₀+h₁)` the element's own weight in the one at
    /// t = 1. `[½, ½]` gives [`Op1d::bernstein_matrix`]; the Q2 basis ignores `w`.
    pub fn bernstein_matrix_graded(self, w: [f64; 2]) -> [[f64; 3]; 3] {
        let [a, b] = w;
        let left = [a, 1.0 - a, 0.0];
        let right = [0.0, b, 1.0 - b];
        match self {
            Op1d::Interior => [left, [0.0, 1.0, 0.0], right],
            Op1d::LeftEnd => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], right],
            Op1d::RightEnd => [left, [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            Op1d::BothEnds | Op1d::Lagrange => self.bernstein_matrix(),
        }
    }

    /// The three basis functions at `t` with knot weights `w` (see
    /// [`Op1d::bernstein_matrix_graded`]): Bernstein values times the matrix.
    pub fn basis_graded(self, t: f64, w: [f64; 2]) -> [f64; 3] {
        let m = self.bernstein_matrix_graded(w);
        let b = bernstein(t);
        std::array::from_fn(|j| (0..3).map(|i| b[i] * m[i][j]).sum())
    }

    /// True for the four spline knot cases.
    pub fn is_spline(self) -> bool {
        self != Op1d::Lagrange
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [Op1d; 5] = [
        Op1d::Interior,
        Op1d::LeftEnd,
        Op1d::RightEnd,
        Op1d::BothEnds,
        Op1d::Lagrange,
    ];

    #[test]
    fn bernstein_matrix_matches_basis() {
        for op in ALL {
            let m = op.bernstein_matrix();
            for i in 0..=20 {
                let t = i as f64 / 20.0;
                let (b, db) = (bernstein(t), bernstein_derivative(t));
                let (n, dn) = (op.basis(t), op.basis_derivative(t));
                for j in 0..3 {
                    let v: f64 = (0..3).map(|k| b[k] * m[k][j]).sum();
                    let dv: f64 = (0..3).map(|k| db[k] * m[k][j]).sum();
                    assert!((v - n[j]).abs() < 1e-14, "{op:?} {j} {t}");
                    assert!((dv - dn[j]).abs() < 1e-13, "{op:?} d{j} {t}");
                }
            }
        }
    }

    #[test]
    fn derivative_matches_finite_difference() {
        let h = 1e-6;
        for op in ALL {
            for i in 1..10 {
                let t = i as f64 / 10.0;
                let (a, b, d) = (op.basis(t + h), op.basis(t - h), op.basis_derivative(t));
                for j in 0..3 {
                    assert!(((a[j] - b[j]) / (2.0 * h) - d[j]).abs() < 1e-8);
                }
            }
        }
    }

    #[test]
    fn graded_rows_reproduce_linear_functions_on_any_knots() {
        // Knot intervals (h₋₁, h₀, h₁); Greville abscissae of the three B-splines in the
        // span's coordinate t = x / h₀ are (-h₋₁/2, h₀/2, h₀ + h₁/2) / h₀, the cell centres.
        for (hl, h0, hr) in [(1.0, 1.3, 1.69), (0.2, 1.0, 7.0), (1.0, 1.0, 1.0)] {
            let w = [h0 / (hl + h0), hr / (h0 + hr)];
            let g = [-0.5 * hl / h0, 0.5, 1.0 + 0.5 * hr / h0];
            for op in [Op1d::Interior, Op1d::LeftEnd, Op1d::RightEnd] {
                let mut c = g;
                if op == Op1d::LeftEnd {
                    c[0] = 0.0;
                }
                if op == Op1d::RightEnd {
                    c[2] = 1.0;
                }
                for i in 0..=10 {
                    let t = i as f64 / 10.0;
                    let n = op.basis_graded(t, w);
                    let x: f64 = (0..3).map(|j| n[j] * c[j]).sum();
                    assert!((x - t).abs() < 1e-14, "{op:?} {hl} {h0} {hr} {t}: {x}");
                    assert!((n.iter().sum::<f64>() - 1.0).abs() < 1e-14);
                }
            }
        }
        for op in ALL {
            assert_eq!(
                op.bernstein_matrix_graded([0.5, 0.5]),
                op.bernstein_matrix()
            );
        }
    }

    #[test]
    fn mirror_symmetry() {
        for (a, b) in [
            (Op1d::LeftEnd, Op1d::RightEnd),
            (Op1d::Interior, Op1d::Interior),
        ] {
            for i in 0..=10 {
                let t = i as f64 / 10.0;
                let (x, y) = (a.basis(t), b.basis(1.0 - t));
                for j in 0..3 {
                    assert!((x[j] - y[2 - j]).abs() < 1e-15);
                }
            }
        }
    }
}
