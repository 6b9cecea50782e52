//! The fit's normal equations across rotation-periodic seams.
//!
//! Input: a [`FitSpace`] some of whose elements see control points rotated
//! ([`FitSpace::frames`]: element e takes R_{e,c} P_c + t_{e,c} for control point c), the
//! scalar normal matrix K of its rows (as for any space: the glued space's, one matrix for
//! x, y and z) and the element blocks G_e of the weights. Output: the coupling C and the
//! solution of the fit's system (K ⊗ I₃ + C) δ = b.
//!
//! With x_e = Σ_c N_c (R_c P_c) + s, the least-squares matrix couples control points i and j
//! by Σ_e A^e_ij R_iᵀ R_j, A^e = E_eᵀ G_e E_e restricted to the pair (position and frame
//! samples alike); R_iᵀ R_j = I wherever element e sees both points in the same frame, so
//!
//!   K ⊗ I₃ + C,  C_ij = Σ_e A^e_ij (R_{e,i}ᵀ R_{e,j} − I),
//!
//! with C non-zero only on the pairs an element sees in different frames (a few rows along
//! the seams). The right-hand side needs R_{e,c}ᵀ on the rotated points' rows, which
//! [`FitSpace::add_transposed`] applies. The system is solved by [`crate::solve::pcg_coupled`]
//! (one recurrence over the three coordinates), preconditioned by K⁻¹ ⊗ I₃ (K factored where
//! the fit would factor it) or by K's pair of block-Jacobi partitions: C has low rank, so the
//! factored preconditioner leaves a handful of iterations.
//!
//! Invariant: without frames nothing here runs, and the fit is the ordinary one.

use super::{ElementBlocks, FitSpace, NormalMatrix};
use crate::math::linalg::DVec3;
use crate::solve::{CgError, CgInfo, CgParams, LinOp, Preconditioner};
use rayon::prelude::*;
use std::collections::HashMap;

type Mat3 = [[f64; 3]; 3];

const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The coupling C between control points seen in different frames, as 3 × 3 blocks by rows.
pub struct Coupling {
    indptr: Vec<usize>,
    cols: Vec<u32>,
    blocks: Vec<Mat3>,
}

impl Coupling {
    /// C of `space` with the element blocks `blocks`; `None` when no element sees a control
    /// point rotated.
    pub fn of(space: &dyn FitSpace, blocks: &ElementBlocks) -> Option<Coupling> {
        if !space.has_frames() {
            return None;
        }
        let nb = if space.dim() == 2 { 9 } else { 27 };
        let per_element: Vec<Vec<((u32, u32), Mat3)>> = (0..space.n_elements())
            .into_par_iter()
            .filter_map(|e| space.frames(e).map(|f| (e, f)))
            .map(|(e, frames)| {
                let (mut o, mut c, mut w) = (Vec::new(), Vec::new(), Vec::new());
                space.element_rows(e, &mut o, &mut c, &mut w);
                let mut ids = c.clone();
                ids.sort_unstable();
                ids.dedup();
                // n_i[b]: control point i's weight in Bernstein point b.
                let mut n = vec![0.0; ids.len() * nb];
                for b in 0..nb {
                    for k in o[b]..o[b + 1] {
                        let i = ids.binary_search(&c[k]).expect("a listed column");
                        n[i * nb + b] += w[k];
                    }
                }
                let (gd, gr) = &blocks.cache[&blocks.masks[e]];
                let frame = |id: u32| frames.iter().find(|f| f.0 == id).map_or(IDENTITY, |f| f.1);
                let mut out = Vec::new();
                for (i, &a) in ids.iter().enumerate() {
                    let ra = frame(a);
                    // G n_i.
                    let gn: Vec<f64> = (0..nb)
                        .map(|r| {
                            (0..nb)
                                .map(|s| (gd[r * nb + s] + gr[r * nb + s]) * n[i * nb + s])
                                .sum()
                        })
                        .collect();
                    for (j, &b) in ids.iter().enumerate() {
                        let rb = frame(b);
                        if ra == rb {
                            continue;
                        }
                        let aij: f64 = (0..nb).map(|r| gn[r] * n[j * nb + r]).sum();
                        if aij == 0.0 {
                            continue;
                        }
                        // A_ij (R_aᵀ R_b − I).
                        let m: Mat3 = std::array::from_fn(|p| {
                            std::array::from_fn(|q| {
                                let rtr: f64 = (0..3).map(|k| ra[k][p] * rb[k][q]).sum();
                                aij * (rtr - IDENTITY[p][q])
                            })
                        });
                        out.push(((a, b), m));
                    }
                }
                out
            })
            .collect();
        let mut sum: HashMap<(u32, u32), Mat3> = HashMap::new();
        for (ij, m) in per_element.into_iter().flatten() {
            let s = sum.entry(ij).or_insert([[0.0; 3]; 3]);
            for p in 0..3 {
                for q in 0..3 {
                    s[p][q] += m[p][q];
                }
            }
        }
        let mut entries: Vec<((u32, u32), Mat3)> = sum.into_iter().collect();
        entries.sort_unstable_by_key(|e| e.0);
        let n = space.control_points().len();
        let mut indptr = vec![0usize; n + 1];
        for ((i, _), _) in &entries {
            indptr[*i as usize + 1] += 1;
        }
        for i in 0..n {
            indptr[i + 1] += indptr[i];
        }
        Some(Coupling {
            indptr,
            cols: entries.iter().map(|e| e.0.1).collect(),
            blocks: entries.into_iter().map(|e| e.1).collect(),
        })
    }

    /// C ← D C D for the diagonal D = diag(`d`) (the fit's symmetric scaling of K).
    pub fn scale_symmetric(&mut self, d: &[f64]) {
        for r in 0..self.indptr.len() - 1 {
            for k in self.indptr[r]..self.indptr[r + 1] {
                let s = d[r] * d[self.cols[k] as usize];
                self.blocks[k] = self.blocks[k].map(|row| row.map(|x| x * s));
            }
        }
    }

    /// The number of 3 × 3 blocks stored.
    pub fn n_blocks(&self) -> usize {
        self.blocks.len()
    }

    /// y += C x.
    fn apply_add(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        for (r, y) in y.iter_mut().enumerate() {
            for k in self.indptr[r]..self.indptr[r + 1] {
                let (m, v) = (&self.blocks[k], x[self.cols[k] as usize]);
                for p in 0..3 {
                    y[p] += m[p][0] * v[0] + m[p][1] * v[1] + m[p][2] * v[2];
                }
            }
        }
    }
}

/// K ⊗ I₃ + C.
struct Rotated<'a> {
    k: &'a NormalMatrix,
    c: &'a Coupling,
}

impl LinOp for Rotated<'_> {
    fn nrows(&self) -> usize {
        self.k.n()
    }
    fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        self.k.apply(x, y);
        self.c.apply_add(x, y);
    }
    fn diagonal(&self) -> Vec<f64> {
        // C's diagonal blocks vanish (R_iᵀ R_i = I).
        self.k.diagonal()
    }
}

/// K⁻¹ ⊗ I₃, exact or by K's block-Jacobi pair.
enum OnK {
    Factor(crate::solve::direct::SparseCholesky),
    Blocks(crate::solve::block_jacobi::BlockJacobiPair),
}

impl Preconditioner for OnK {
    fn apply(&self, r: &[[f64; 3]], z: &mut [[f64; 3]]) {
        match self {
            OnK::Blocks(b) => b.apply(r, z),
            OnK::Factor(f) => {
                let mut m = faer::Mat::<f64>::from_fn(r.len(), 3, |i, c| r[i][c]);
                f.solve_in_place(&mut m)
                    .expect("the solve's scratch was allocated for the factor");
                for (i, z) in z.iter_mut().enumerate() {
                    *z = [m[(i, 0)], m[(i, 1)], m[(i, 2)]];
                }
            }
        }
    }
}

/// Solve (K ⊗ I₃ + C) δ = `b` from `delta` by [`crate::solve::pcg_coupled`], preconditioned by
/// K factored (`factor`) or by K's block-Jacobi pair (module docs).
pub fn solve(
    k: &NormalMatrix,
    c: &Coupling,
    b: &[[f64; 3]],
    delta: &mut [[f64; 3]],
    params: &CgParams,
    factor: bool,
) -> Result<CgInfo, CgError> {
    let (indptr, indices, data) = (k.indptr(), k.indices(), k.data());
    let pre = if factor {
        OnK::Factor(crate::solve::direct::SparseCholesky::new(
            indptr, indices, data,
        )?)
    } else {
        OnK::Blocks(crate::solve::block_jacobi::BlockJacobiPair::new(
            indptr,
            indices,
            data,
            crate::solve::block_jacobi::DEFAULT_BLOCK,
        )?)
    };
    crate::solve::pcg_coupled(&Rotated { k, c }, &pre, b, delta, params)
}

/// Rᵀ applied to `v`.
pub(crate) fn rotate_back(r: &Mat3, v: DVec3) -> DVec3 {
    DVec3::new(
        r[0][0] * v.x + r[1][0] * v.y + r[2][0] * v.z,
        r[0][1] * v.x + r[1][1] * v.y + r[2][1] * v.z,
        r[0][2] * v.x + r[1][2] * v.y + r[2][2] * v.z,
    )
}
