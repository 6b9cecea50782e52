//! Bézier elements of the spline space: an element's net from the control points (rotated
//! where it sees them across a rotation seam, [`Extraction::frames`], plus its periodic seam
//! offsets, [`Extraction::node_shift`]), and the rows of global basis functions (CPU, f64). Points and derivatives of a net are the
//! foundation's ([`crate::math::bernstein`]).

use super::extraction::Extraction;
use crate::math::bernstein::BezierNet;
use crate::math::bernstein::bernstein2 as bernstein;
pub use crate::math::bernstein::{eval_net, eval_net_with_derivatives};

/// The Bézier net of element `e` for control point positions `cps`.
pub fn bezier_net(ext: &Extraction, e: usize, cps: &[[f64; 3]]) -> BezierNet {
    let n = ext.n_local();
    // Positions of the local nodes.
    let mut p = [[0.0f64; 3]; 27];
    let frames = ext.frames(e);
    for (l, &node) in ext.element_nodes(e).iter().enumerate() {
        let mut x = [0.0; 3];
        for (g, w) in ext.node_entries(node) {
            let mut c = cps[g as usize];
            // Across a rotation seam the point is seen rotated (its offset is in the shift).
            if let Some((_, r)) = frames.and_then(|f| f.iter().find(|f| f.0 == g)) {
                c = std::array::from_fn(|i| r[i][0] * c[0] + r[i][1] * c[1] + r[i][2] * c[2]);
            }
            for i in 0..3 {
                x[i] += w * c[i];
            }
        }
        p[l] = x;
    }
    // Across a periodic seam the control points are those of the other side, moved by the
    // period (rows sum to 1, so the shift of a local node is the rows' mix of the shifts).
    if let Some(s) = ext.node_shift(e) {
        for (x, d) in p.iter_mut().zip(s).take(n) {
            for i in 0..3 {
                x[i] += d[i];
            }
        }
    }
    to_bernstein(ext, e, p)
}

/// The Bernstein net of element `e`'s periodic seam offsets alone (the net of `e` is that of
/// its control points plus this), `None` when it has none.
pub fn shift_net(ext: &Extraction, e: usize) -> Option<BezierNet> {
    ext.node_shift(e).map(|s| to_bernstein(ext, e, *s))
}

/// Local node positions `p` of element `e` to its Bernstein points.
fn to_bernstein(ext: &Extraction, e: usize, mut p: BezierNet) -> BezierNet {
    let n = ext.n_local();
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

/// The global basis functions that are non-zero on element `e` at `u`, as
/// (control point, value) pairs sorted by control point (duplicates summed). The scalar
/// functions only: an element with [`Extraction::frames`] also rotates some of the points.
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
