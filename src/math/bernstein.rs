//! Quadratic Bernstein polynomials and tensor-product Bézier nets.
//!
//! A [`BezierNet`] is the 3^d Bernstein control points of one element map of \[0,1\]^d, x
//! fastest (index 9z + 3y + x; a quad uses the first 9 entries, the rest are ignored).
//! Parameters are (u, v, w) ∈ \[0,1\]^d; the w entry of a quad is ignored. Every element map of
//! the pipeline (spline space, straight input, targets, blends) is such a net, which is what
//! [`BezierElements`] hands out.
//!
//! Invariants: the basis is a partition of unity, so [`eval_net`] reproduces the net's corner
//! points at the corners and affine maps exactly (up to rounding). The evaluation order of the
//! sums is part of the output: sampling, certification and the energy all depend on these
//! exact f64 results, so the loops below are not to be reordered.

use super::reference::HEX_VERTEX_PARAMS;

/// The Bernstein control points of a quadratic element (see the module docs).
pub type BezierNet = [[f64; 3]; 27];

/// One 3-vector per point of the sample lattice {0, ½, 1}^d of an element, in [`BezierNet`]
/// order (index 9z + 3y + x): the fit's samples, targets and weighted residuals before they
/// are pulled back to Bernstein points.
pub type Lattice = [[f64; 3]; 27];

/// Entries of a [`BezierNet`] (and of a [`Lattice`]) that a `dim`-dimensional element uses: 3^d.
#[inline]
pub const fn net_len(dim: usize) -> usize {
    if dim == 2 { 9 } else { 27 }
}

/// Elements that are tensor-product quadratic Bézier maps of \[0,1\]^d.
pub trait BezierElements: Sync {
    fn dim(&self) -> usize;
    fn n_elements(&self) -> usize;
    /// Bernstein control points of element `e`, index 9z + 3y + x (the first 9 in 2D).
    fn bezier_net(&self, e: usize) -> BezierNet;
}

/// Quadratic Bernstein polynomials `(1−t)², 2t(1−t), t²` at `t`.
#[inline]
pub fn bernstein2(t: f64) -> [f64; 3] {
    let s = 1.0 - t;
    // 2·s·t: the factor 2 is exact, so (2s)t and (2t)s round alike.
    [s * s, 2.0 * s * t, t * t]
}

/// Derivatives of [`bernstein2`].
#[inline]
pub fn bernstein2_derivative(t: f64) -> [f64; 3] {
    [-2.0 * (1.0 - t), 2.0 - 4.0 * t, 2.0 * t]
}

/// Tensor Bernstein values at `u` (3^d entries used, net order).
pub fn bernstein_values(dim: usize, u: [f64; 3]) -> [f64; 27] {
    let b = [bernstein2(u[0]), bernstein2(u[1]), bernstein2(u[2])];
    let mut out = [0.0; 27];
    let n = net_len(dim);
    for (i, o) in out.iter_mut().enumerate().take(n) {
        let z = if dim == 2 { 1.0 } else { b[2][i / 9] };
        *o = b[0][i % 3] * b[1][(i / 3) % 3] * z;
    }
    out
}

/// Point of a Bézier net at `u`.
pub fn eval_net(dim: usize, net: &BezierNet, u: [f64; 3]) -> [f64; 3] {
    let bu = bernstein2(u[0]);
    let bv = bernstein2(u[1]);
    let bw = if dim == 2 {
        [1.0, 0.0, 0.0]
    } else {
        bernstein2(u[2])
    };
    let nz = if dim == 2 { 1 } else { 3 };
    let mut out = [0.0; 3];
    for c in 0..nz {
        for b in 0..3 {
            for a in 0..3 {
                let w = bu[a] * bv[b] * bw[c];
                let p = net[9 * c + 3 * b + a];
                for k in 0..3 {
                    out[k] += w * p[k];
                }
            }
        }
    }
    out
}

/// Point and parametric derivatives of a Bézier net at `u`: `d[k]` is ∂x/∂u_k
/// (`d[2]` is zero for a quad).
pub fn eval_net_with_derivatives(
    dim: usize,
    net: &BezierNet,
    u: [f64; 3],
) -> ([f64; 3], [[f64; 3]; 3]) {
    let b = [bernstein2(u[0]), bernstein2(u[1]), bernstein2(u[2])];
    let db = [
        bernstein2_derivative(u[0]),
        bernstein2_derivative(u[1]),
        bernstein2_derivative(u[2]),
    ];
    let n = net_len(dim);
    let mut x = [0.0; 3];
    let mut d = [[0.0; 3]; 3];
    for (i, p) in net.iter().enumerate().take(n) {
        let a = [i % 3, (i / 3) % 3, i / 9];
        let (bz, dbz) = if dim == 2 {
            (1.0, 0.0)
        } else {
            (b[2][a[2]], db[2][a[2]])
        };
        let v = b[0][a[0]] * b[1][a[1]] * bz;
        let g = [
            db[0][a[0]] * b[1][a[1]] * bz,
            b[0][a[0]] * db[1][a[1]] * bz,
            b[0][a[0]] * b[1][a[1]] * dbz,
        ];
        for c in 0..3 {
            x[c] += v * p[c];
            for k in 0..3 {
                d[k][c] += g[k] * p[c];
            }
        }
    }
    (x, d)
}

/// Bilinear (2D) or trilinear (3D) interpolation of element corners at `t` (corners in the
/// mesh's vertex order, [`HEX_VERTEX_PARAMS`]).
pub fn multilinear(dim: usize, x: &[[f64; 3]; 8], t: [f64; 3]) -> [f64; 3] {
    let mut out = [0.0; 3];
    let n = if dim == 2 { 4 } else { 8 };
    for (c, p) in HEX_VERTEX_PARAMS.iter().enumerate().take(n) {
        let mut w = 1.0;
        for k in 0..dim {
            w *= if p[k] == 1 { t[k] } else { 1.0 - t[k] };
        }
        for k in 0..3 {
            out[k] += w * x[c][k];
        }
    }
    out
}

/// The multilinear map of corners `x` degree-elevated to quadratic: its Bernstein points are
/// its values on the half lattice {0, ½, 1}^d.
pub fn elevated_net(dim: usize, x: &[[f64; 3]; 8]) -> BezierNet {
    let mut net = [[0.0; 3]; 27];
    let nz = if dim == 2 { 1 } else { 3 };
    for c in 0..nz {
        for b in 0..3 {
            for a in 0..3 {
                let t = [a as f64 / 2.0, b as f64 / 2.0, c as f64 / 2.0];
                net[9 * c + 3 * b + a] = multilinear(dim, x, t);
            }
        }
    }
    net
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent oracle: the quadratic Bézier of an arbitrary polynomial map by de Casteljau
    /// (repeated linear interpolation), against the closed-form Bernstein sums.
    fn casteljau(p: [f64; 3], t: f64) -> f64 {
        let (a, b) = (p[0] + t * (p[1] - p[0]), p[1] + t * (p[2] - p[1]));
        a + t * (b - a)
    }

    #[test]
    fn partition_of_unity_and_derivative_sum() {
        for i in 0..=20 {
            let t = i as f64 / 20.0;
            let b = bernstein2(t);
            let d = bernstein2_derivative(t);
            assert!((b.iter().sum::<f64>() - 1.0).abs() < 1e-15);
            assert!(d.iter().sum::<f64>().abs() < 1e-15);
            let p = [0.3, -1.7, 2.5];
            let want = casteljau(p, t);
            let got: f64 = (0..3).map(|k| b[k] * p[k]).sum();
            assert!((got - want).abs() < 1e-14, "t = {t}: {got} vs {want}");
        }
    }

    #[test]
    fn nets_reproduce_affine_maps_and_derivatives() {
        let map = |u: [f64; 3]| {
            [
                1.0 + 2.0 * u[0] - 0.5 * u[1] + 0.25 * u[2],
                -3.0 + 0.5 * u[0] + 1.5 * u[1] - u[2],
                0.7 * u[0] + 0.1 * u[1] + 3.0 * u[2],
            ]
        };
        for dim in [2, 3] {
            let mut x = [[0.0; 3]; 8];
            for (c, p) in HEX_VERTEX_PARAMS.iter().enumerate() {
                let mut u = p.map(|v| v as f64);
                if dim == 2 {
                    u[2] = 0.0;
                }
                x[c] = map(u);
            }
            let net = elevated_net(dim, &x);
            let u = [0.3, 0.8, if dim == 2 { 0.0 } else { 0.45 }];
            let got = eval_net(dim, &net, u);
            let (same, d) = eval_net_with_derivatives(dim, &net, u);
            let want = map(u);
            for k in 0..3 {
                assert!((got[k] - want[k]).abs() < 1e-14);
                assert!((same[k] - want[k]).abs() < 1e-14);
                // ∂x_k/∂u_j of the affine map: finite differences of `map` are exact.
                for j in 0..dim {
                    let mut e = [0.0; 3];
                    e[j] = 1.0;
                    let slope = map(e)[k] - map([0.0; 3])[k];
                    assert!((d[j][k] - slope).abs() < 1e-13, "dim {dim} ∂{j}x{k}");
                }
            }
            let b = bernstein_values(dim, u);
            let n = net_len(dim);
            assert!((b[..n].iter().sum::<f64>() - 1.0).abs() < 1e-15);
        }
    }
}
