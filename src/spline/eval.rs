//! Evaluation of Bézier elements: nets, points, parametric derivatives, basis rows (CPU, f64).
//!
//! A Bézier net is the 3^d Bernstein control points of one element, x fastest
//! (index 9z + 3y + x; a quad uses the first 9 entries). Parameters are (u, v, w) ∈ `[0,1]`^d;
//! the w entry of a quad is ignored.

use super::extraction::Extraction;
use super::knots::{bernstein, bernstein_derivative};

/// The Bézier net of element `e` for control point positions `cps`.
pub fn bezier_net(ext: &Extraction, e: usize, cps: &[[f64; 3]]) -> [[f64; 3]; 27] {
    let n = ext.n_local();
    // Positions of the local nodes.
    let mut p = [[0.0f64; 3]; 27];
    for (l, &node) in ext.element_nodes(e).iter().enumerate() {
        let mut x = [0.0; 3];
        for (g, w) in ext.node_entries(node) {
            let c = cps[g as usize];
            for i in 0..3 {
                x[i] += w * c[i];
            }
        }
        p[l] = x;
    }
    // Apply M_x, M_y, M_z in turn (sum factorisation).
    let m = ext.matrices(e);
    for (k, mk) in m.iter().enumerate().take(ext.dim) {
        let stride = [1, 3, 9][k];
        let mut q = [[0.0f64; 3]; 27];
        for (idx, qi) in q.iter_mut().enumerate().take(n) {
            let a = (idx / stride) % 3;
            let base = idx - a * stride;
            let mut x = [0.0; 3];
            for (j, &w) in mk[a].iter().enumerate() {
                if w != 0.0 {
                    let y = p[base + j * stride];
                    for i in 0..3 {
                        x[i] += w * y[i];
                    }
                }
            }
            *qi = x;
        }
        p = q;
    }
    p
}

/// Tensor Bernstein values at `u` (3^d entries used).
pub fn bernstein_values(dim: usize, u: [f64; 3]) -> [f64; 27] {
    let b = [bernstein(u[0]), bernstein(u[1]), bernstein(u[2])];
    let mut out = [0.0; 27];
    let n = if dim == 2 { 9 } else { 27 };
    for (i, o) in out.iter_mut().enumerate().take(n) {
        let z = if dim == 2 { 1.0 } else { b[2][i / 9] };
        *o = b[0][i % 3] * b[1][(i / 3) % 3] * z;
    }
    out
}

/// Point of a Bézier net at `u`.
pub fn eval_net(dim: usize, net: &[[f64; 3]; 27], u: [f64; 3]) -> [f64; 3] {
    let b = bernstein_values(dim, u);
    let n = if dim == 2 { 9 } else { 27 };
    let mut x = [0.0; 3];
    for i in 0..n {
        for c in 0..3 {
            x[c] += b[i] * net[i][c];
        }
    }
    x
}

/// Point and parametric derivatives of a Bézier net at `u`: `d[k]` is ∂x/∂u_k
/// (`d[2]` is zero for a quad).
pub fn eval_net_with_derivatives(
    dim: usize,
    net: &[[f64; 3]; 27],
    u: [f64; 3],
) -> ([f64; 3], [[f64; 3]; 3]) {
    let b = [bernstein(u[0]), bernstein(u[1]), bernstein(u[2])];
    let db = [
        bernstein_derivative(u[0]),
        bernstein_derivative(u[1]),
        bernstein_derivative(u[2]),
    ];
    let n = if dim == 2 { 9 } else { 27 };
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

/// The global basis functions that are non-zero on element `e` at `u`, as
/// (control point, value) pairs sorted by control point (duplicates summed).
pub fn basis_at(ext: &Extraction, e: usize, u: [f64; 3], out: &mut Vec<(u32, f64)>) {
    out.clear();
    let dim = ext.dim;
    let m = ext.matrices(e);
    // Value of local node basis l: Π_k (Bernstein(u_k) · M_k)[l_k].
    let mut phi = [[0.0f64; 3]; 3];
    for k in 0..3 {
        let b = if k < dim {
            bernstein(u[k])
        } else {
            [1.0, 0.0, 0.0]
        };
        for j in 0..3 {
            phi[k][j] = (0..3).map(|i| b[i] * m[k][i][j]).sum();
        }
    }
    for (l, &node) in ext.element_nodes(e).iter().enumerate() {
        let v = phi[0][l % 3] * phi[1][(l / 3) % 3] * phi[2][l / 9];
        out.extend(ext.node_entries(node).map(|(g, w)| (g, v * w)));
    }
    out.sort_unstable_by_key(|p| p.0);
    let mut merged: Vec<(u32, f64)> = Vec::with_capacity(out.len());
    for &(g, w) in out.iter() {
        match merged.last_mut() {
            Some(last) if last.0 == g => last.1 += w,
            _ => merged.push((g, w)),
        }
    }
    *out = merged;
}
