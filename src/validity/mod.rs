//! Certified Jacobian bounds of quadratic Bézier elements.
//!
//! Input: the Bernstein net of a tensor-product quadratic element (9 points in 2D, 27 in 3D,
//! index 9z + 3y + x). The Jacobian determinant of such a map is itself a tensor-product
//! polynomial, of degree (3,3) in 2D and (5,5,5) in 3D; [`det_jacobian_bernstein`] computes its
//! Bernstein coefficients exactly (products of Bernstein polynomials are Bernstein polynomials).
//! Since the Bernstein basis is a non-negative partition of unity, the smallest coefficient is
//! a lower bound of det J on the whole element, and the corner coefficients are values of
//! det J. [`det_jacobian_bounds`] sharpens the lower bound by de Casteljau subdivision where the
//! coefficients are inconclusive. Output: a certified interval [lower, upper] ∋ min det J;
//! `lower > 0` certifies the element valid, `upper ≤ 0` proves it invalid.
//!
//! The line searches first try the cheap [`screen`] bound (a lower bound of every Bernstein
//! coefficient of det J) and run the exact certificate only where the screen does not already
//! exceed the element's acceptance threshold; decisions are those of the exact certificate,
//! and the reported smallest bound (and worst elements) are made exact by
//! [`Screened::refine_smallest`]. Other per-element bounds may be the screen's, which are
//! certified lower bounds too, only less sharp.

pub mod blend;
pub mod certificate;
pub mod line_search;
pub mod screen;
pub mod snap;

use crate::math::BezierNet;
pub use certificate::{Certifier, CpuCertifier, certify_elements};
pub use line_search::{
    LineSearchInfo, LineSearchMode, LineSearchParams, LocalSearchInfo, ValidityError, WorstElement,
    line_search, line_search_with, local_line_search, local_line_search_with,
};
pub use screen::{Screened, certify_screened, screen_bounds};

/// Largest polynomial degree handled (det J of an order-10 hex has degree 29 per direction).
const MAX_DEGREE: usize = 32;

/// Binomial coefficients up to [`MAX_DEGREE`].
const BINOM: [[f64; MAX_DEGREE + 1]; MAX_DEGREE + 1] = {
    let mut t = [[0.0; MAX_DEGREE + 1]; MAX_DEGREE + 1];
    let mut n = 0;
    while n <= MAX_DEGREE {
        let mut k = 0;
        while k <= n {
            t[n][k] = if k == 0 || k == n {
                1.0
            } else {
                t[n - 1][k - 1] + t[n - 1][k]
            };
            k += 1;
        }
        n += 1;
    }
    t
};

/// A tensor-product polynomial in Bernstein form of degrees `deg` (index i fastest).
#[derive(Clone, Debug)]
pub struct Bernstein {
    pub deg: [usize; 3],
    pub coef: Vec<f64>,
}

impl Bernstein {
    fn zeros(deg: [usize; 3]) -> Self {
        Bernstein {
            deg,
            coef: vec![0.0; (deg[0] + 1) * (deg[1] + 1) * (deg[2] + 1)],
        }
    }

    #[inline]
    fn idx(&self, i: usize, j: usize, k: usize) -> usize {
        i + (self.deg[0] + 1) * (j + (self.deg[1] + 1) * k)
    }

    /// Product, exact in Bernstein form: B^m_i B^n_j = C(m,i)C(n,j)/C(m+n,i+j) B^{m+n}_{i+j}.
    /// In scaled coefficients ĉ_i = C(n,i) c_i (per direction) the product is a plain
    /// convolution, so the inner loop is a contiguous multiply-add without weights.
    pub fn mul(&self, other: &Bernstein) -> Bernstein {
        let deg = [0, 1, 2].map(|d| self.deg[d] + other.deg[d]);
        let a = self.scaled(1.0);
        let b = other.scaled(1.0);
        let mut out = Bernstein::zeros(deg);
        let (na, nb) = (self.deg.map(|d| d + 1), other.deg.map(|d| d + 1));
        let no = deg.map(|d| d + 1);
        for k1 in 0..na[2] {
            for j1 in 0..na[1] {
                for i1 in 0..na[0] {
                    let x = a[i1 + na[0] * (j1 + na[1] * k1)];
                    if x == 0.0 {
                        continue;
                    }
                    for k2 in 0..nb[2] {
                        for j2 in 0..nb[1] {
                            let bo = nb[0] * (j2 + nb[1] * k2);
                            let oo = i1 + no[0] * (j1 + j2 + no[1] * (k1 + k2));
                            let row = &mut out.coef[oo..oo + nb[0]];
                            for (o, y) in row.iter_mut().zip(&b[bo..bo + nb[0]]) {
                                *o += x * y;
                            }
                        }
                    }
                }
            }
        }
        let inv = out.scaled(-1.0);
        out.coef = inv;
        out
    }

    /// Coefficients times (`sign` > 0) or divided by (`sign` < 0) C(n0,i)·C(n1,j)·C(n2,k).
    fn scaled(&self, sign: f64) -> Vec<f64> {
        let mut c = self.coef.clone();
        for k in 0..=self.deg[2] {
            for j in 0..=self.deg[1] {
                let bjk = BINOM[self.deg[1]][j] * BINOM[self.deg[2]][k];
                for i in 0..=self.deg[0] {
                    let f = BINOM[self.deg[0]][i] * bjk;
                    let o = self.idx(i, j, k);
                    if sign > 0.0 {
                        c[o] *= f;
                    } else {
                        c[o] /= f;
                    }
                }
            }
        }
        c
    }

    fn add_scaled(&mut self, other: &Bernstein, s: f64) {
        debug_assert_eq!(self.deg, other.deg);
        for (a, b) in self.coef.iter_mut().zip(&other.coef) {
            *a += s * b;
        }
    }

    /// Value at (u, v, w) by tensor de Casteljau (Bernstein sums).
    pub fn eval(&self, t: [f64; 3]) -> f64 {
        let basis = |n: usize, x: f64| -> Vec<f64> {
            (0..=n)
                .map(|i| BINOM[n][i] * x.powi(i as i32) * (1.0 - x).powi((n - i) as i32))
                .collect()
        };
        let (bu, bv, bw) = (
            basis(self.deg[0], t[0]),
            basis(self.deg[1], t[1]),
            basis(self.deg[2], t[2]),
        );
        let mut s = 0.0;
        for k in 0..=self.deg[2] {
            for j in 0..=self.deg[1] {
                for i in 0..=self.deg[0] {
                    s += self.coef[self.idx(i, j, k)] * bu[i] * bv[j] * bw[k];
                }
            }
        }
        s
    }

    /// Split at the middle of direction `d` by de Casteljau: (lower half, upper half), each
    /// reparametrised to [0,1].
    fn split(&self, d: usize) -> (Bernstein, Bernstein) {
        let n = self.deg[d];
        let mut lo = self.clone();
        let mut hi = self.clone();
        let dims = [self.deg[0] + 1, self.deg[1] + 1, self.deg[2] + 1];
        let stride = [1, dims[0], dims[0] * dims[1]];
        let lines: Vec<usize> = (0..self.coef.len())
            .filter(|&o| (o / stride[d]).is_multiple_of(dims[d]))
            .collect();
        let mut buf = vec![0.0; n + 1];
        for &o in &lines {
            for (i, b) in buf.iter_mut().enumerate() {
                *b = self.coef[o + i * stride[d]];
            }
            // De Casteljau at 1/2: left gets the first entry of each level, right the last.
            for level in 0..=n {
                lo.coef[o + level * stride[d]] = buf[0];
                hi.coef[o + (n - level) * stride[d]] = buf[n - level];
                for i in 0..n - level {
                    buf[i] = 0.5 * (buf[i] + buf[i + 1]);
                }
            }
        }
        (lo, hi)
    }

    fn min_coef(&self) -> f64 {
        self.coef.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// Smallest corner value (corner coefficients are values).
    fn min_corner(&self) -> f64 {
        self.corner_range().0
    }

    /// Smallest and largest corner values.
    fn corner_range(&self) -> (f64, f64) {
        let (mut m, mut x) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in [0, self.deg[2]] {
            for j in [0, self.deg[1]] {
                for i in [0, self.deg[0]] {
                    let v = self.coef[self.idx(i, j, k)];
                    m = m.min(v);
                    x = x.max(v);
                }
            }
        }
        (m, x)
    }
}

/// out += a ∗ b (tensor convolution) of scaled coefficient arrays with `na`, `nb`, `no`
/// coefficients per direction (no = na + nb − 1).
#[inline(always)]
fn convolve(a: &[f64], na: [usize; 3], b: &[f64], nb: [usize; 3], out: &mut [f64], no: [usize; 3]) {
    for k1 in 0..na[2] {
        for j1 in 0..na[1] {
            for i1 in 0..na[0] {
                let x = a[i1 + na[0] * (j1 + na[1] * k1)];
                for k2 in 0..nb[2] {
                    for j2 in 0..nb[1] {
                        let bo = nb[0] * (j2 + nb[1] * k2);
                        let oo = i1 + no[0] * (j1 + j2 + no[1] * (k1 + k2));
                        for i2 in 0..nb[0] {
                            out[oo + i2] += x * b[bo + i2];
                        }
                    }
                }
            }
        }
    }
}

/// Bernstein coefficients of det J of a quadratic Bézier element (`dim` 2 or 3).
///
/// Computed in scaled coefficients (c_ijk · C(n0,i)C(n1,j)C(n2,k), see [`Bernstein::mul`]):
/// the partial derivatives are scaled once, the products are plain convolutions on fixed-size
/// arrays, and det J is unscaled once at the end.
pub fn det_jacobian_bernstein(dim: usize, net: &BezierNet) -> Bernstein {
    // Scaled partial derivative d of coordinate c: degree 1 in direction d (coefficients
    // 2 ΔP), 2 elsewhere (binomials 1, 2, 1); 18 coefficients in 3D, 6 in 2D.
    let partial = |d: usize, c: usize| -> [f64; 18] {
        let mut n = if dim == 2 { [3, 3, 1] } else { [3, 3, 3] };
        n[d] = 2;
        let mut out = [0.0; 18];
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let l = [i, j, k];
                    let mut hi = l;
                    hi[d] += 1;
                    let at = |q: [usize; 3]| net[q[0] + 3 * q[1] + 9 * q[2]][c];
                    let mut scale = 2.0;
                    for e in 0..3 {
                        if e != d && n[e] == 3 && l[e] == 1 {
                            scale *= 2.0;
                        }
                    }
                    out[i + n[0] * (j + n[1] * k)] = scale * (at(hi) - at(l));
                }
            }
        }
        out
    };
    let mut det = if dim == 2 {
        let (ux, uy, vx, vy) = (partial(0, 0), partial(0, 1), partial(1, 0), partial(1, 1));
        let (nu, nv, no) = ([2, 3, 1], [3, 2, 1], [4, 4, 1]);
        let mut det = Bernstein::zeros([3, 3, 0]);
        let mut neg = [0.0; 16];
        convolve(&ux, nu, &vy, nv, &mut det.coef, no);
        convolve(&uy, nu, &vx, nv, &mut neg, no);
        for (d, n) in det.coef.iter_mut().zip(neg) {
            *d -= n;
        }
        det
    } else {
        let du: [[f64; 18]; 3] = std::array::from_fn(|c| partial(0, c));
        let dv: [[f64; 18]; 3] = std::array::from_fn(|c| partial(1, c));
        let dw: [[f64; 18]; 3] = std::array::from_fn(|c| partial(2, c));
        let (nu, nv, nw, nc) = ([2, 3, 3], [3, 2, 3], [3, 3, 2], [5, 4, 4]);
        let mut det = Bernstein::zeros([5, 5, 5]);
        for c in 0..3 {
            let (a, b) = ((c + 1) % 3, (c + 2) % 3);
            // (dv × dw)_c = dv_a dw_b − dv_b dw_a
            let mut cross = [0.0; 80];
            let mut neg = [0.0; 80];
            convolve(&dv[a], nv, &dw[b], nw, &mut cross, nc);
            convolve(&dv[b], nv, &dw[a], nw, &mut neg, nc);
            for (x, n) in cross.iter_mut().zip(neg) {
                *x -= n;
            }
            convolve(&du[c], nu, &cross, nc, &mut det.coef, [6, 6, 6]);
        }
        det
    };
    det.coef = det.scaled(-1.0);
    det
}

/// Bernstein coefficients of det J of an order-p Lagrange element whose nodes are given in
/// lattice order (i fastest; (p+1)^dim points): the nodes are converted to Bernstein points of
/// degree p per direction, then differentiated and multiplied exactly.
pub fn det_jacobian_bernstein_lagrange(dim: usize, p: usize, nodes: &[[f64; 3]]) -> Bernstein {
    let m = p + 1;
    // 1D Lagrange → Bernstein: solve A c = f with A[i][j] = B^p_j(i/p) (Gauss–Jordan, small).
    let mut a: Vec<Vec<f64>> = (0..m)
        .map(|i| {
            let t = i as f64 / p as f64;
            (0..m)
                .map(|j| BINOM[p][j] * t.powi(j as i32) * (1.0 - t).powi((p - j) as i32))
                .collect()
        })
        .collect();
    let mut inv: Vec<Vec<f64>> = (0..m)
        .map(|i| (0..m).map(|j| (i == j) as u8 as f64).collect())
        .collect();
    for c in 0..m {
        let piv = (c..m)
            .max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))
            .unwrap();
        a.swap(c, piv);
        inv.swap(c, piv);
        let d = a[c][c];
        for j in 0..m {
            a[c][j] /= d;
            inv[c][j] /= d;
        }
        for r in 0..m {
            if r != c && a[r][c] != 0.0 {
                let f = a[r][c];
                for j in 0..m {
                    a[r][j] -= f * a[c][j];
                    inv[r][j] -= f * inv[c][j];
                }
            }
        }
    }
    let mz = if dim == 2 { 1 } else { m };
    let mut net = nodes.to_vec();
    for d in 0..dim {
        let stride = [1, m, m * m][d];
        let mut out = net.clone();
        for o in 0..m * m * mz {
            if !(o / stride).is_multiple_of(m) {
                continue;
            }
            for i in 0..m {
                let mut acc = [0.0; 3];
                for j in 0..m {
                    let x = net[o + j * stride];
                    for k in 0..3 {
                        acc[k] += inv[i][j] * x[k];
                    }
                }
                out[o + i * stride] = acc;
            }
        }
        net = out;
    }
    let partial = |d: usize, c: usize| -> Bernstein {
        let mut deg = if dim == 2 { [p, p, 0] } else { [p, p, p] };
        deg[d] = p - 1;
        let mut b = Bernstein::zeros(deg);
        for k in 0..=deg[2] {
            for j in 0..=deg[1] {
                for i in 0..=deg[0] {
                    let mut hi = [i, j, k];
                    hi[d] += 1;
                    let at = |q: [usize; 3]| net[q[0] + m * (q[1] + m * q[2])][c];
                    let o = b.idx(i, j, k);
                    b.coef[o] = p as f64 * (at(hi) - at([i, j, k]));
                }
            }
        }
        b
    };
    if dim == 2 {
        let mut det = partial(0, 0).mul(&partial(1, 1));
        det.add_scaled(&partial(0, 1).mul(&partial(1, 0)), -1.0);
        det
    } else {
        let mut det: Option<Bernstein> = None;
        for c in 0..3 {
            let (a, b) = ((c + 1) % 3, (c + 2) % 3);
            let mut cross = partial(1, a).mul(&partial(2, b));
            cross.add_scaled(&partial(1, b).mul(&partial(2, a)), -1.0);
            let term = partial(0, c).mul(&cross);
            match &mut det {
                None => det = Some(term),
                Some(d) => d.add_scaled(&term, 1.0),
            }
        }
        det.expect("three terms")
    }
}

/// Certified bounds of min det J of a Bernstein polynomial, with subdivision as in
/// [`det_jacobian_bounds`].
pub fn bernstein_min_bounds(dim: usize, b: Bernstein, max_depth: usize) -> DetBounds {
    let mut upper = b.min_corner();
    let mut lower = f64::INFINITY;
    let mut stack = vec![(b, 0usize)];
    while let Some((p, depth)) = stack.pop() {
        let lo = p.min_coef();
        upper = upper.min(p.min_corner());
        if lo > 0.0 || depth >= max_depth || upper <= 0.0 {
            lower = lower.min(lo);
            continue;
        }
        let (a, c) = p.split(depth % dim);
        stack.push((a, depth + 1));
        stack.push((c, depth + 1));
    }
    DetBounds {
        lower: lower.min(upper),
        upper,
    }
}

/// Whether min det J ≥ `q` · max det J is certified for the Bernstein polynomial `b` of det J,
/// with the certified lower bound of min det J reached.
///
/// The coefficients bound a patch's values from both sides, but the smallest over the whole
/// element can sit far below the minimum (and the largest above the maximum) of a curved
/// element's det J, so the ratio of the two is pessimistic. Patches whose smallest coefficient
/// is below `q` × the current upper bound of max det J, or whose largest is above the current
/// lower bound of min det J / `q`, are split (at most `max_depth` rounds, cycling the
/// directions) until the test is decided: the result is still a certificate (each patch's
/// coefficients bound its values), only tighter.
pub fn certify_ratio(dim: usize, b: Bernstein, q: f64, max_depth: usize) -> (bool, f64) {
    let mut leaves = vec![b];
    for depth in 0..=max_depth {
        // Bounds of min and max det J: coefficients outside, corner values inside.
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut min_in, mut max_in) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in &leaves {
            let max = p.coef.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let (cmin, cmax) = p.corner_range();
            lo = lo.min(p.min_coef());
            hi = hi.max(max);
            min_in = min_in.min(cmin);
            max_in = max_in.max(cmax);
        }
        if lo >= q * hi {
            return (true, lo);
        }
        // Decided the other way by values: no refinement can pass it.
        if depth == max_depth || lo <= 0.0 || min_in < q * max_in {
            return (false, lo);
        }
        let mut next = Vec::with_capacity(2 * leaves.len());
        for p in leaves {
            let max = p.coef.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            if p.min_coef() < q * hi || max * q > lo {
                let (a, c) = p.split(depth % dim);
                next.push(a);
                next.push(c);
            } else {
                next.push(p);
            }
        }
        leaves = next;
    }
    unreachable!("the loop returns at max_depth")
}

/// Certified bounds of min det J of element `e` of a high-order Lagrange mesh.
pub fn lagrange_element_bounds(
    ho: &crate::mesh::HighOrderMesh,
    e: usize,
    max_depth: usize,
) -> DetBounds {
    let nodes: Vec<[f64; 3]> = ho
        .element(e)
        .iter()
        .map(|&n| ho.nodes[n as usize])
        .collect();
    let b = det_jacobian_bernstein_lagrange(ho.dim, ho.order, &nodes);
    bernstein_min_bounds(ho.dim, b, max_depth)
}

/// Certified bounds on min det J over an element.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct DetBounds {
    /// min det J ≥ lower (certified).
    pub lower: f64,
    /// min det J ≤ upper (a value of det J attained in the element).
    pub upper: f64,
}

impl DetBounds {
    /// det J > 0 everywhere on the element, certified.
    pub fn certified_positive(&self) -> bool {
        self.lower > 0.0
    }
}

/// Certified bounds of min det J, subdividing up to `max_depth` times (each time halving the
/// direction of the largest degree, cycling) where the coefficients do not decide the sign.
pub fn det_jacobian_bounds(dim: usize, net: &BezierNet, max_depth: usize) -> DetBounds {
    bernstein_min_bounds(dim, det_jacobian_bernstein(dim, net), max_depth)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn net_of(dim: usize, f: impl Fn([f64; 3]) -> [f64; 3]) -> BezierNet {
        // Bernstein points of a map that is quadratic per direction: interpolate at 0, ½, 1
        // and convert (middle coefficient = 2 f(½) − (f(0) + f(1))/2).
        let mut net = [[0.0; 3]; 27];
        let nz = if dim == 2 { 1 } else { 3 };
        let mut vals = [[0.0; 3]; 27];
        for k in 0..nz {
            for j in 0..3 {
                for i in 0..3 {
                    vals[i + 3 * j + 9 * k] = f([i as f64 / 2.0, j as f64 / 2.0, k as f64 / 2.0]);
                }
            }
        }
        net.copy_from_slice(&vals);
        for d in 0..dim {
            let stride = [1, 3, 9][d];
            for o in 0..27 {
                if (o / stride) % 3 == 1 {
                    for c in 0..3 {
                        net[o][c] =
                            2.0 * net[o][c] - 0.5 * (net[o - stride][c] + net[o + stride][c]);
                    }
                }
            }
        }
        net
    }

    /// det J of the map `f` at `t` by central differences.
    pub(super) fn det_fd(dim: usize, f: &impl Fn([f64; 3]) -> [f64; 3], t: [f64; 3]) -> f64 {
        let h = 1e-6;
        let col = |d: usize| {
            let mut a = t;
            let mut b = t;
            a[d] -= h;
            b[d] += h;
            let (fa, fb) = (f(a), f(b));
            [0, 1, 2].map(|c| (fb[c] - fa[c]) / (2.0 * h))
        };
        let (u, v) = (col(0), col(1));
        if dim == 2 {
            u[0] * v[1] - u[1] * v[0]
        } else {
            let w = col(2);
            u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
                + u[2] * (v[0] * w[1] - v[1] * w[0])
        }
    }

    /// A map whose det J = 1 + 2u(1 − u) has its maximum inside (1.5 at u = ½) and cubic
    /// coefficients [1, 5/3, 5/3, 1] in u: the coefficients' ratio 0.6 understates the true
    /// 2/3 (from finite differences of the map, the oracle). The refined certificate decides
    /// q = 0.63 true and q = 0.7 false, and never certifies a q above the sampled ratio.
    #[test]
    fn ratio_certificate_refines_the_coefficients_and_stays_sound() {
        let f = |t: [f64; 3]| [t[0], t[1] * (1.0 + 2.0 * t[0] * (1.0 - t[0])), 0.0];
        let net = net_of(2, f);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for i in 0..=40 {
            for j in 0..=40 {
                let d = det_fd(2, &f, [i as f64 / 40.0, j as f64 / 40.0, 0.0]);
                lo = lo.min(d);
                hi = hi.max(d);
            }
        }
        let sampled = lo / hi;
        assert!((sampled - 1.0 / 1.5).abs() < 1e-6, "{sampled}");
        let poly = det_jacobian_bernstein(2, &net);
        let max = poly.coef.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert!(poly.min_coef() / max < 0.63);
        assert!(certify_ratio(2, poly.clone(), 0.63, 6).0);
        assert!(!certify_ratio(2, poly.clone(), 0.7, 6).0);
        for q in [0.5, 0.6, 0.65, 0.666, 0.667, 0.7] {
            let (ok, lower) = certify_ratio(2, poly.clone(), q, 8);
            assert!(
                !ok || q <= sampled + 1e-9,
                "q {q} certified above {sampled}"
            );
            assert!(lower <= lo + 1e-6, "{lower} above the sampled {lo}");
        }
    }

    #[test]
    fn product_evaluates_to_the_product_of_values() {
        let poly = |deg: [usize; 3], seed: f64| {
            let mut b = Bernstein::zeros(deg);
            for (i, c) in b.coef.iter_mut().enumerate() {
                *c = (seed + 1.7 * i as f64).sin();
            }
            b
        };
        for (da, db) in [
            ([2, 1, 2], [2, 2, 1]),
            ([1, 2, 0], [3, 0, 0]),
            ([4, 3, 3], [1, 2, 2]),
        ] {
            let (a, b) = (poly(da, 0.3), poly(db, 1.1));
            let p = a.mul(&b);
            assert_eq!(p.deg, [0, 1, 2].map(|d| da[d] + db[d]));
            for t in [
                [0.1, 0.7, 0.4],
                [0.5, 0.5, 0.5],
                [1.0, 0.0, 0.9],
                [0.33, 0.01, 0.99],
            ] {
                let (want, got) = (a.eval(t) * b.eval(t), p.eval(t));
                assert!(
                    (want - got).abs() <= 1e-12 * (1.0 + want.abs()),
                    "{want} vs {got}"
                );
            }
        }
    }

    #[test]
    fn bernstein_det_matches_finite_differences() {
        for dim in [2, 3] {
            let f = |t: [f64; 3]| {
                [
                    t[0] + 0.3 * t[1] * t[1] - 0.1 * t[0] * t[2],
                    t[1] + 0.2 * t[0] * t[0] * t[1] + 0.05 * t[2],
                    t[2] + 0.15 * t[0] * t[1] * t[2] - 0.2 * t[1] * t[1],
                ]
            };
            let g = |t: [f64; 3]| {
                if dim == 2 {
                    [f(t)[0], f(t)[1], 0.0]
                } else {
                    f(t)
                }
            };
            let net = net_of(dim, g);
            let b = det_jacobian_bernstein(dim, &net);
            for t in [
                [0.1, 0.7, 0.3],
                [0.9, 0.2, 0.5],
                [0.5, 0.5, 0.5],
                [0.0, 1.0, 1.0],
            ] {
                let t = if dim == 2 { [t[0], t[1], 0.0] } else { t };
                let want = det_fd(dim, &g, t);
                assert!(
                    (b.eval(t) - want).abs() < 1e-7,
                    "dim {dim} at {t:?}: {} vs {want}",
                    b.eval(t)
                );
            }
        }
    }

    #[test]
    fn lagrange_det_matches_the_bezier_det_and_finite_differences() {
        let f = |t: [f64; 3]| {
            [
                t[0] + 0.3 * t[1] * t[1],
                t[1] + 0.2 * t[0] * t[0] * t[1] + 0.05 * t[2],
                t[2] + 0.1 * t[0] * t[1],
            ]
        };
        for p in [2, 3, 5] {
            let m = p + 1;
            let nodes: Vec<[f64; 3]> = (0..m * m * m)
                .map(|n| {
                    f([
                        (n % m) as f64 / p as f64,
                        ((n / m) % m) as f64 / p as f64,
                        (n / (m * m)) as f64 / p as f64,
                    ])
                })
                .collect();
            let b = det_jacobian_bernstein_lagrange(3, p, &nodes);
            for t in [[0.1, 0.7, 0.3], [0.9, 0.2, 0.5], [1.0, 0.0, 1.0]] {
                let want = det_fd(3, &f, t);
                assert!(
                    (b.eval(t) - want).abs() < 1e-6,
                    "p={p} at {t:?}: {} vs {want}",
                    b.eval(t)
                );
            }
        }
    }

    #[test]
    fn bounds_certify_valid_and_prove_invalid_elements() {
        // The unit cube: det J = 1 everywhere.
        let cube = net_of(3, |t| t);
        let b = det_jacobian_bounds(3, &cube, 6);
        assert!((b.lower - 1.0).abs() < 1e-12 && (b.upper - 1.0).abs() < 1e-12);
        // A folded square: det J = 1 − 5 t0 (1 − t0) is negative around t0 = ½.
        let folded = net_of(2, |t| [t[0], t[1] * (1.0 - 5.0 * t[0] * (1.0 - t[0])), 0.0]);
        // Its minimum, −¼ at t0 = ½, lies in [lower, upper], and upper (a value of det J that
        // the subdivision reached) proves the element invalid.
        let b = det_jacobian_bounds(2, &folded, 8);
        assert!(
            b.lower <= -0.25 + 1e-12 && -0.25 <= b.upper + 1e-12,
            "{b:?}"
        );
        assert!(b.upper <= 0.0, "{b:?}");
        assert!(!b.certified_positive());
        // Strongly curved but valid: the coefficient bound alone may be negative; subdivision
        // must certify it.
        let bent = net_of(2, |t| {
            [t[0] + 0.45 * t[1] * t[1], t[1] + 0.45 * t[0] * t[0], 0.0]
        });
        let b = det_jacobian_bounds(2, &bent, 10);
        let mut true_min = f64::INFINITY;
        for i in 0..=50 {
            for j in 0..=50 {
                let t = [i as f64 / 50.0, j as f64 / 50.0, 0.0];
                true_min = true_min.min(det_jacobian_bernstein(2, &bent).eval(t));
            }
        }
        assert!(true_min > 0.0);
        assert!(b.certified_positive(), "{b:?}");
        assert!(b.lower <= true_min + 1e-12 && true_min <= b.upper + 1e-12);
    }
}
