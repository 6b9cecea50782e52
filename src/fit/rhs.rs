//! Right-hand side of the displacement system, F − K C0.
//!
//! Input: a [`FitSpace`] (E_e, C0), the linear mesh, the weights and per-element weight masks
//! ([`super::ElementBlocks::masks`]) and the optional smooth targets. Output: one 3-vector per
//! control point.
//!
//! With B the Bernstein values at the 3^d lattice samples (rows b_iᵀ), W the position weights
//! and P_e the targets at the samples, F_e = Bᵀ W P_e + G^r_e B⁰_e and G_e = Bᵀ W B + G^r_e,
//! so the frame term cancels in the displacement form:
//!
//!   F_e − G_e B⁰_e = Bᵀ W (P_e − B B⁰_e),
//!
//! the weighted residual of the initial map at the samples, pulled back to the Bernstein
//! points. B = B₁ ⊗ B₁ (⊗ B₁) with B₁ the 1D Bernstein values at {0, ½, 1}, so P_e (the
//! multilinear map at the lattice: repeated midpoints), B B⁰_e and Bᵀ r are all applied line
//! by line, direction by direction (sum factorisation), and E_eᵀ by
//! [`FitSpace::add_transposed`]. Elements are processed in parallel, a bounded batch at a
//! time, and their contributions added in element order, so the result does not depend on
//! the thread count.

use super::{FitSpace, FitWeights, SmoothTargets, sample_weight};
use crate::math::Lattice;
use crate::math::bernstein::net_len;
use crate::math::linalg::DVec3;
use crate::math::reference::HEX_VERTEX_PARAMS;
use crate::mesh::{LinearMesh, Topology};
use rayon::prelude::*;

/// Elements per batch (bounds the temporary (control point, value) pairs).
const RHS_BATCH: usize = 1 << 16;

/// Apply `f` to every line of the 3^`dim` lattice `v`, direction by direction (x, y, z).
pub(super) fn map_lines(dim: usize, v: &mut Lattice, f: impl Fn([DVec3; 3]) -> [DVec3; 3]) {
    let n = 3usize.pow(dim as u32);
    for s in [1, 3, 9].into_iter().take(dim) {
        for b in (0..n).filter(|i| (i / s) % 3 == 0) {
            let out = f([v[b], v[b + s], v[b + 2 * s]].map(DVec3::from));
            (v[b], v[b + s], v[b + 2 * s]) = (out[0].into(), out[1].into(), out[2].into());
        }
    }
}

/// The multilinear map of the corners `x` at the lattice: midpoints of the lines.
pub(super) fn multilinear_lattice(dim: usize, x: &[[f64; 3]; 8]) -> Lattice {
    let mut p = [[0.0; 3]; 27];
    for (c, pc) in HEX_VERTEX_PARAMS.iter().enumerate().take(1 << dim) {
        p[2 * (pc[0] as usize + 3 * pc[1] as usize + 9 * pc[2] as usize)] = x[c];
    }
    map_lines(dim, &mut p, |[a, _, c]| [a, a * 0.5 + c * 0.5, c]);
    p
}

/// F − K C0 for the fit with weights `w`, weight masks `masks` and optional smooth targets.
pub(super) fn displacement_rhs(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
    masks: &[u64],
    smooth: Option<&SmoothTargets>,
) -> Vec<[f64; 3]> {
    displacement_rhs_of(space, mesh, topo, w, masks, smooth, None)
}

/// [`displacement_rhs`] summed over the elements `subset` only (all when `None`); element
/// indices, like `masks`, are the mesh's.
pub(super) fn displacement_rhs_of(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
    masks: &[u64],
    smooth: Option<&SmoothTargets>,
    subset: Option<&[usize]>,
) -> Vec<[f64; 3]> {
    let dim = space.dim();
    let nb = net_len(dim);
    let c0 = space.control_points();
    let ne = subset.map_or(space.n_elements(), |s| s.len());
    let at = |i: usize| subset.map_or(i, |s| s[i]);
    let mut rhs = vec![[0.0; 3]; c0.len()];
    let element = |e: usize, acc: &mut Vec<(u32, [f64; 3])>| {
        let mut r = multilinear_lattice(dim, &mesh.element_coords(e));
        if let Some(t) = smooth {
            let shift = t.corrections_at(mesh, topo, e, &r);
            for (p, s) in r.iter_mut().zip(shift) {
                *p = (DVec3::from(*p) + DVec3::from(s)).into();
            }
        }
        // The initial map at the samples: B B⁰.
        let mut x0 = space.bezier_net_with(e, c0);
        map_lines(dim, &mut x0, |[a, b, c]| {
            [a, (a * 0.25 + c * 0.25) + b * 0.5, c]
        });
        for (i, (r, x0)) in r.iter_mut().zip(&x0).enumerate().take(nb) {
            let l = [i % 3, (i / 3) % 3, i / 9];
            let corner = l[..dim].iter().all(|&c| c != 1);
            let wd = sample_weight(w, masks[e], i, l, corner);
            *r = if wd == 0.0 {
                [0.0; 3]
            } else {
                ((DVec3::from(*r) - DVec3::from(*x0)) * wd).into()
            };
        }
        // Bᵀ: B₁ᵀ on every line.
        map_lines(dim, &mut r, |[a, b, c]| {
            [a + b * 0.25, b * 0.5, b * 0.25 + c]
        });
        space.add_transposed(e, &r, acc);
    };
    for batch in (0..ne).step_by(RHS_BATCH) {
        let chunks: Vec<Vec<(u32, [f64; 3])>> = (batch..(batch + RHS_BATCH).min(ne))
            .into_par_iter()
            .fold(Vec::new, |mut acc, i| {
                element(at(i), &mut acc);
                acc
            })
            .collect();
        for f in chunks {
            for (i, f) in f {
                let r = &mut rhs[i as usize];
                *r = (DVec3::from(*r) + DVec3::from(f)).into();
            }
        }
    }
    rhs
}
