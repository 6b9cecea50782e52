//! Shape measures of quadratic Bézier elements used by the blend's quality test: bounds of
//! max det J, the lattice scaled Jacobian, and the straight element's Jacobian ratio.

use super::Net;
use crate::math::bernstein::{bernstein2, bernstein2_derivative, net_len};
use crate::math::linalg::DVec3;
use crate::mesh::LinearMesh;
use crate::validity::det_jacobian_bernstein;

/// Largest Bernstein coefficient of det J: an upper bound of max det J over the element.
pub fn max_det_bound(dim: usize, net: &Net) -> f64 {
    det_jacobian_bernstein(dim, net)
        .coef
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Smallest scaled Jacobian det J / (|J₁| |J₂| (|J₃|)) of a quadratic Bézier element over the
/// lattice {0, ½, 1}^d (sampled, not certified: a shape measure, not a validity test).
///
/// The columns ∂x/∂ξ_k at the lattice are tensor products of 1-D operators (values B and
/// derivatives D of the quadratic Bernstein basis at 0, ½, 1), applied one axis at a time.
pub fn lattice_scaled_jacobian(dim: usize, net: &Net) -> f64 {
    const B: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.25, 0.5, 0.25], [0.0, 0.0, 1.0]];
    const D: [[f64; 3]; 3] = [[-2.0, 2.0, 0.0], [-1.0, 0.0, 1.0], [0.0, -2.0, 2.0]];
    let n = net_len(dim);
    let z = |src: Net, m: &[[f64; 3]; 3]| {
        if dim == 2 {
            src
        } else {
            along::<9>(&src, n, m)
        }
    };
    let bx = along::<1>(net, n, &B);
    let cols = [
        z(along::<3>(&along::<1>(net, n, &D), n, &B), &B),
        z(along::<3>(&bx, n, &D), &B),
        if dim == 2 {
            [[0.0; 3]; 27]
        } else {
            along::<9>(&along::<3>(&bx, n, &B), n, &D)
        },
    ];
    (0..n)
        .map(|p| scaled_jacobian(dim, [cols[0][p], cols[1][p], cols[2][p]]))
        .fold(f64::INFINITY, f64::min)
}

/// det J / (|J₁| |J₂| (|J₃|)) of the columns `jac` (the third unused in 2D); −1 where it is
/// NaN (a zero column), so a degenerate point counts as the worst shape.
fn scaled_jacobian(dim: usize, jac: [[f64; 3]; 3]) -> f64 {
    let [j0, j1, j2] = jac.map(DVec3::from);
    let sj = if dim == 2 {
        (jac[0][0] * jac[1][1] - jac[0][1] * jac[1][0]) / (j0.length() * j1.length())
    } else {
        j0.cross(j1).dot(j2) / (j0.length() * j1.length() * j2.length())
    };
    if sj.is_nan() { -1.0 } else { sj }
}

/// Smallest scaled Jacobian over the finer lattice {0, ¼, ½, ¾, 1}^d, the lattice on which
/// the report and `scripts/` sample the output's scaled Jacobian (sampled, not certified).
///
/// The columns at the 5^d points, one axis at a time: the values B and derivatives D of the
/// quadratic Bernstein basis at the five parameters along x, then y, then z.
pub fn fine_lattice_scaled_jacobian(dim: usize, net: &Net) -> f64 {
    const T: [f64; 5] = [0.0, 0.25, 0.5, 0.75, 1.0];
    let (b, d) = (T.map(bernstein2), T.map(bernstein2_derivative));
    let nz = if dim == 2 { 1 } else { 3 };
    let dot = |m: &[f64; 3], p: [[f64; 3]; 3]| -> [f64; 3] {
        std::array::from_fn(|q| m[0] * p[0][q] + m[1] * p[1][q] + m[2] * p[2][q])
    };
    // Along x: [i][y][z] of the values and of the derivatives.
    let mut bx = [[[[0.0; 3]; 3]; 3]; 5];
    let mut dx = bx;
    for z in 0..nz {
        for y in 0..3 {
            let row = [0, 1, 2].map(|x| net[x + 3 * y + 9 * z]);
            for i in 0..5 {
                bx[i][y][z] = dot(&b[i], row);
                dx[i][y][z] = dot(&d[i], row);
            }
        }
    }
    // Along y: [i][j][z] of (∂x, ∂y, values) before z.
    let mut xy = [[[[[0.0; 3]; 3]; 3]; 5]; 5];
    for i in 0..5 {
        for j in 0..5 {
            for z in 0..nz {
                let (vb, vd) = (
                    [0, 1, 2].map(|y| bx[i][y][z]),
                    [0, 1, 2].map(|y| dx[i][y][z]),
                );
                xy[i][j][z] = [dot(&b[j], vd), dot(&d[j], vb), dot(&b[j], vb)];
            }
        }
    }
    let mut min = f64::INFINITY;
    for row in &xy {
        for c in row {
            // Along z (3D): the columns at the five points of this (x, y).
            let along =
                |k: usize, m: &[[f64; 3]; 5], l: usize| dot(&m[l], [0, 1, 2].map(|z| c[z][k]));
            let planes: [[[f64; 3]; 3]; 5] = if dim == 2 {
                [c[0]; 5]
            } else {
                std::array::from_fn(|l| [along(0, &b, l), along(1, &b, l), along(2, &d, l)])
            };
            for &jac in &planes[..if dim == 2 { 1 } else { 5 }] {
                min = min.min(scaled_jacobian(dim, jac));
            }
        }
    }
    min
}

/// `m` along the axis of stride `STRIDE` (1, 3 or 9) of the first `n` (9 or 27) slots of a
/// lattice net: out[.., i, ..] = Σ_a m[i][a] src[.., a, ..], the other slots 0.
///
/// Loops over (outer, i, inner) with the stride a constant: no integer division per slot (a
/// runtime stride's `o / stride % 3` per slot costs more than the slot's products). Each slot
/// is m[i][0] p₀ + m[i][1] p₁ + m[i][2] p₂, summed left to right.
#[inline(always)]
fn along<const STRIDE: usize>(src: &Net, n: usize, m: &[[f64; 3]; 3]) -> Net {
    let mut out = [[0.0f64; 3]; 27];
    for hi in 0..n / (3 * STRIDE) {
        for (i, mi) in m.iter().enumerate() {
            for lo in 0..STRIDE {
                let base = lo + 3 * STRIDE * hi;
                let (p0, p1, p2) = (src[base], src[base + STRIDE], src[base + 2 * STRIDE]);
                out[base + i * STRIDE] =
                    std::array::from_fn(|q| mi[0] * p0[q] + mi[1] * p1[q] + mi[2] * p2[q]);
            }
        }
    }
    out
}

/// An upper bound of max det J: the product over directions of the largest Bernstein
/// coefficient norm of the column ∂x/∂ξ_k (Hadamard's inequality; cheap, loose when sheared).
pub(super) fn hadamard_upper(dim: usize, net: &Net) -> f64 {
    let nz = if dim == 2 { 1 } else { 3 };
    let mut m = [0.0f64; 3];
    for k in 0..nz {
        for j in 0..3 {
            for i in 0..3 {
                let p = net[i + 3 * j + 9 * k];
                let mut d = |dir: usize, q: [f64; 3]| {
                    let v = DVec3::from(q) - DVec3::from(p);
                    m[dir] = m[dir].max(2.0 * v.length());
                };
                if i < 2 {
                    d(0, net[i + 1 + 3 * j + 9 * k]);
                }
                if j < 2 {
                    d(1, net[i + 3 * (j + 1) + 9 * k]);
                }
                if dim == 3 && k < 2 {
                    d(2, net[i + 3 * j + 9 * (k + 1)]);
                }
            }
        }
    }
    if dim == 2 {
        m[0] * m[1]
    } else {
        m[0] * m[1] * m[2]
    }
}

/// Jacobian ratio of a straight element from its corner values of det J (exact for quads,
/// whose det J is affine in each coordinate).
pub(super) fn corner_ratio(mesh: &LinearMesh, e: usize) -> f64 {
    let npe = mesh.nodes_per_element();
    let x = mesh.element_coords(e);
    let (mut jac, mut scaled) = ([0.0; 8], [0.0; 8]);
    crate::mesh::linear::corner_jacobians(mesh.dim, &x[..npe], &mut jac[..npe], &mut scaled[..npe]);
    let lo = jac[..npe].iter().copied().fold(f64::INFINITY, f64::min);
    let hi = jac[..npe].iter().copied().fold(f64::NEG_INFINITY, f64::max);
    lo / hi
}
