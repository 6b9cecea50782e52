//! Sparse Cholesky solve of a symmetric positive definite system, for the fit's small
//! normal equations.
//!
//! Input: an assembled matrix A (CSR of the full symmetric matrix, sorted columns; read as
//! CSC, which is the same for a symmetric matrix), right-hand sides `b` with `ncomp` used
//! components (2 in 2D, 3 in 3D; the others are left as they are). Output: `x` = A⁻¹ b and a
//! [`CgInfo`] with 0 iterations and the relative residual ‖b − A x‖/‖b‖ actually reached,
//! measured after the solve; or [`CgError::NotPositiveDefinitePivot`].
//!
//! The factorisation is faer's: an approximate minimum degree ordering, then a simplicial
//! or supernodal L Lᵀ, whichever its flop estimate prefers. It runs on one thread: on the
//! systems it is chosen for (by the fit's `FitSolver`) the parallel
//! triangular solves were 5× slower than the serial ones on two cores, and a fit of a few
//! thousand control points is factored in a few milliseconds. The cost of the ordering and
//! the fill grow faster than CG's work (nested-dissection-like fill: about n^1.5 in 2D and
//! n² in 3D), which is why larger systems stay with CG.

use super::{CgError, CgInfo};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, Mat, Par, Side};

/// Solve A x = b by sparse Cholesky (module docs). `indptr`, `indices`, `data` hold the
/// whole symmetric matrix in CSR with sorted columns.
pub fn cholesky(
    indptr: &[usize],
    indices: &[u32],
    data: &[f64],
    b: &[[f64; 3]],
    x: &mut [[f64; 3]],
    ncomp: usize,
) -> Result<CgInfo, CgError> {
    let n = indptr.len() - 1;
    assert_eq!(b.len(), n);
    assert_eq!(x.len(), n);
    let factor = SparseCholesky::new(indptr, indices, data)?;
    let mut rhs = Mat::<f64>::from_fn(n, ncomp, |i, c| b[i][c]);
    factor.solve_in_place(&mut rhs)?;
    for (i, xi) in x.iter_mut().enumerate() {
        for c in 0..ncomp {
            xi[c] = rhs[(i, c)];
        }
    }
    Ok(CgInfo {
        iterations: 0,
        rel_residual: relative_residual(indptr, indices, data, b, x, ncomp),
    })
}

/// The symbolic analysis of a symmetric sparsity pattern: the fill-reducing ordering and the
/// size of the factor, known before any number is computed, so a caller can choose between
/// the factorisation and an iterative solve by the memory the factor would take.
pub struct CholeskyPattern {
    symbolic: SymbolicCholesky<u32>,
    col_ptr: Vec<u32>,
    indices: Vec<u32>,
}

impl CholeskyPattern {
    /// Analyse the pattern of a symmetric matrix given as CSR with sorted columns (the whole
    /// matrix, both triangles).
    pub fn new(indptr: &[usize], indices: &[u32]) -> Result<Self, CgError> {
        let n = indptr.len() - 1;
        let col_ptr: Vec<u32> = indptr
            .iter()
            .map(|&p| u32::try_from(p))
            .collect::<Result<_, _>>()
            .map_err(|_| {
                CgError::Factorisation(format!("{n} unknowns, {} entries", indices.len()))
            })?;
        let pattern = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, indices);
        let symbolic = factorize_symbolic_cholesky(
            pattern,
            Side::Lower,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams::default(),
        )
        .map_err(oom)?;
        Ok(CholeskyPattern {
            symbolic,
            col_ptr,
            indices: indices.to_vec(),
        })
    }

    /// Entries of the Cholesky factor L (each an f64).
    pub fn factor_entries(&self) -> usize {
        self.symbolic.len_val()
    }

    /// Factor the matrix with this pattern and the values `data` (CSR order).
    pub fn factor(self, data: &[f64]) -> Result<SparseCholesky, CgError> {
        let n = self.col_ptr.len() - 1;
        let pattern =
            SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.indices);
        let a = SparseColMatRef::new(pattern, data);
        let mut l = vec![0.0; self.symbolic.len_val()];
        let mut scratch = MemBuffer::try_new(
            self.symbolic
                .factorize_numeric_llt_scratch::<f64>(PAR, Default::default()),
        )
        .map_err(|_| oom(faer::sparse::FaerError::OutOfMemory))?;
        self.symbolic
            .factorize_numeric_llt(
                &mut l,
                a,
                Side::Lower,
                faer::linalg::cholesky::llt::factor::LltRegularization::default(),
                PAR,
                MemStack::new(&mut scratch),
                Default::default(),
            )
            .map_err(|e| match e {
                faer::linalg::solvers::LltError::NonPositivePivot { index } => {
                    CgError::NotPositiveDefinitePivot { pivot: index }
                }
            })?;
        Ok(SparseCholesky {
            symbolic: self.symbolic,
            l,
        })
    }
}

/// A sparse Cholesky factor L Lᵀ = A of a symmetric positive definite matrix.
pub struct SparseCholesky {
    symbolic: SymbolicCholesky<u32>,
    l: Vec<f64>,
}

impl SparseCholesky {
    /// Analyse and factor A (CSR of the whole symmetric matrix, sorted columns).
    pub fn new(indptr: &[usize], indices: &[u32], data: &[f64]) -> Result<Self, CgError> {
        CholeskyPattern::new(indptr, indices)?.factor(data)
    }

    /// Overwrite each column of `rhs` (n rows) with A⁻¹ times it.
    pub fn solve_in_place(&self, rhs: &mut Mat<f64>) -> Result<(), CgError> {
        let mut scratch = MemBuffer::try_new(
            self.symbolic
                .solve_in_place_scratch::<f64>(rhs.ncols(), PAR),
        )
        .map_err(|_| oom(faer::sparse::FaerError::OutOfMemory))?;
        let llt = LltRef::new(&self.symbolic, &self.l);
        llt.solve_in_place_with_conj(Conj::No, rhs.as_mut(), PAR, MemStack::new(&mut scratch));
        Ok(())
    }
}

/// One thread: the parallel triangular solves were slower on two cores (module docs).
const PAR: Par = Par::Seq;

fn oom(e: faer::sparse::FaerError) -> CgError {
    CgError::Factorisation(format!("{e:?}"))
}

/// max over the used components of ‖b − A x‖ / ‖b‖ (0 for a zero right-hand side).
fn relative_residual(
    indptr: &[usize],
    indices: &[u32],
    data: &[f64],
    b: &[[f64; 3]],
    x: &[[f64; 3]],
    ncomp: usize,
) -> f64 {
    let (mut rr, mut bb) = ([0.0f64; 3], [0.0f64; 3]);
    for (i, bi) in b.iter().enumerate() {
        let r = indptr[i]..indptr[i + 1];
        let ax = super::row_dot(&indices[r.clone()], &data[r], x);
        for c in 0..ncomp {
            rr[c] += (bi[c] - ax[c]).powi(2);
            bb[c] += bi[c] * bi[c];
        }
    }
    (0..ncomp)
        .map(|c| {
            if bb[c] > 0.0 {
                (rr[c] / bb[c]).sqrt()
            } else {
                rr[c].sqrt()
            }
        })
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::block_jacobi::tests::{laplacian, matvec};

    /// A known solution of a shifted 2D Laplacian comes back to rounding, in every used
    /// component, and the reported residual is the true one.
    #[test]
    fn solves_a_laplacian_to_rounding() {
        let a = laplacian(23, |x, y| 0.05 + 0.01 * (x * y) as f64);
        let n = a.0.len() - 1;
        let want: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let t = i as f64;
                [t.sin(), (0.3 * t).cos(), 0.0]
            })
            .collect();
        let b = matvec(&a, &want);
        let mut x = vec![[7.0; 3]; n];
        let info = cholesky(&a.0, &a.1, &a.2, &b, &mut x, 2).unwrap();
        assert_eq!(info.iterations, 0);
        assert!(info.rel_residual < 1e-13, "{}", info.rel_residual);
        for (g, w) in x.iter().zip(&want) {
            assert!((g[0] - w[0]).abs() < 1e-10 && (g[1] - w[1]).abs() < 1e-10);
            assert_eq!(g[2], 7.0, "an unused component is left as it was");
        }
    }

    /// An indefinite matrix is refused with the pivot, not solved.
    #[test]
    fn refuses_an_indefinite_matrix() {
        let mut a = laplacian(5, |_, _| 0.0);
        let d = (a.0[12]..a.0[13]).find(|&k| a.1[k] == 12).unwrap();
        a.2[d] = -1.0;
        let n = a.0.len() - 1;
        let err = cholesky(
            &a.0,
            &a.1,
            &a.2,
            &vec![[1.0; 3]; n],
            &mut vec![[0.0; 3]; n],
            3,
        )
        .unwrap_err();
        assert!(
            matches!(err, CgError::NotPositiveDefinitePivot { .. }),
            "{err}"
        );
    }
}
