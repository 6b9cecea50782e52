//! 3-vectors and 3×3 matrices on glam.
//!
//! Geometry stores points as `[f64; 3]` (files, meshes, GPU buffers); [`DVec3`] is the same
//! three f64 (`From`/`Into` both ways, no copy beyond the value), so code converts at its API
//! and computes on glam. Matrices are glam's column-major [`DMat3`]; [`Mat3`] (row-major
//! `[[f64; 3]; 3]`, `m[row][col]`) is the storage form of the GPU's local problems (their
//! buffers hold the rows), with [`to_dmat3`]/[`from_dmat3`] between the two.
//!
//! **Rounding.** glam's `dot`, `cross`, `length` and the matrix product compute exactly the
//! textbook formulas in the textbook order (checked against glam 0.34's `dvec3.rs`/`dmat3.rs`:
//! `dot` = (x·x′ + y·y′) + z·z′, `cross` component-wise a_j b_k − a_k b_j, `length` =
//! √dot, `A·B` column j = (A₀ b₀ⱼ + A₁ b₁ⱼ) + A₂ b₂ⱼ), so they are used as they are. Its
//! `determinant` expands along the first column (x·(y×z)) and its `inverse` scales by a
//! reciprocal, `normalize` multiplies by a reciprocal length: those differ in the last bit
//! from the row expansion and divisions the outputs were defined with, so [`det3`], [`inv3`]
//! (and [`inverse`], its form on a `DMat3`) and [`unit()`] keep the explicit formulas.

pub use glam::{DMat3, DVec3};

/// A 3×3 matrix stored by rows: `m[row][col]`.
pub type Mat3 = [[f64; 3]; 3];

/// The glam matrix of row-major `m`.
#[inline]
pub fn to_dmat3(m: &Mat3) -> DMat3 {
    DMat3::from_cols_array_2d(m).transpose()
}

/// Row-major storage of `m`.
#[inline]
pub fn from_dmat3(m: &DMat3) -> Mat3 {
    m.transpose().to_cols_array_2d()
}

/// det of a row-major matrix, expanded along the first row.
#[inline]
pub fn det3(m: &Mat3) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// Inverse (cofactors times 1/det) and determinant.
pub fn inv3(m: &Mat3) -> (Mat3, f64) {
    let det = det3(m);
    let s = 1.0 / det;
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let (a, b) = ((j + 1) % 3, (j + 2) % 3);
            let (c, d) = ((i + 1) % 3, (i + 2) % 3);
            r[i][j] = s * (m[a][c] * m[b][d] - m[a][d] * m[b][c]);
        }
    }
    (r, det)
}

/// The product a·b (glam's product: the same sums in the same order as the row formula).
#[inline]
pub fn mul3(a: &Mat3, b: &Mat3) -> Mat3 {
    from_dmat3(&(to_dmat3(a) * to_dmat3(b)))
}

/// The transpose.
#[inline]
pub fn transpose(a: &Mat3) -> Mat3 {
    // The columns of A are the rows of Aᵀ.
    to_dmat3(a).to_cols_array_2d()
}

/// Squared Frobenius norm, summed by rows.
#[inline]
pub fn norm2(a: &Mat3) -> f64 {
    a.iter().flatten().map(|x| x * x).sum()
}

/// [`inv3`] of a glam matrix: the same cofactor formula, not glam's `inverse`.
#[inline]
pub fn inverse(m: &DMat3) -> (DMat3, f64) {
    let (r, det) = inv3(&from_dmat3(m));
    (to_dmat3(&r), det)
}

/// [`norm2`] of a glam matrix: summed by rows, as for the row-major form.
#[inline]
pub fn norm2_rows(m: &DMat3) -> f64 {
    norm2(&from_dmat3(m))
}

/// The diagonal of the box `[lo, hi]`, at least the smallest positive `f64` (what lengths
/// are measured against, relative).
#[inline]
pub fn box_diagonal(lo: [f64; 3], hi: [f64; 3]) -> f64 {
    (DVec3::from(hi) - DVec3::from(lo))
        .length()
        .max(f64::MIN_POSITIVE)
}

/// `a` scaled to unit length by division (the zero vector stays zero).
#[inline]
pub fn unit(a: DVec3) -> DVec3 {
    let l = a.length();
    if l > 0.0 { a / l } else { a }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_matrices() -> Vec<Mat3> {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
        };
        (0..200)
            .map(|_| std::array::from_fn(|_| std::array::from_fn(|_| next())))
            .collect()
    }

    /// The glam product and transpose against the row formulas written out here, bit for
    /// bit; det·inverse against the identity; the row layout against glam's column layout.
    #[test]
    fn glam_products_match_the_row_formulas_bitwise() {
        let ms = sample_matrices();
        for w in ms.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            let mut want = [[0.0; 3]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    want[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
                }
            }
            assert_eq!(mul3(a, b), want);
            let t = transpose(a);
            for i in 0..3 {
                for j in 0..3 {
                    assert_eq!(t[i][j].to_bits(), a[j][i].to_bits());
                    assert_eq!(to_dmat3(a).col(j)[i].to_bits(), a[i][j].to_bits());
                }
            }
            let (inv, det) = inv3(a);
            assert!((det - to_dmat3(a).determinant()).abs() < 1e-12 * (1.0 + det.abs()));
            let id = mul3(a, &inv);
            for i in 0..3 {
                for j in 0..3 {
                    let e = if i == j { 1.0 } else { 0.0 };
                    assert!((id[i][j] - e).abs() < 1e-9 / det.abs().min(1.0), "{det}");
                }
            }
        }
    }

    #[test]
    fn vector_operations_match_the_formulas_bitwise() {
        let ms = sample_matrices();
        for m in &ms {
            let (a, b) = (m[0], m[1]);
            let (ga, gb) = (DVec3::from(a), DVec3::from(b));
            let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            assert_eq!(ga.dot(gb).to_bits(), dot.to_bits());
            assert_eq!(ga.length().to_bits(), dot_self(a).sqrt().to_bits());
            let cross = [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ];
            assert_eq!(<[f64; 3]>::from(ga.cross(gb)), cross);
            let l = dot_self(a).sqrt();
            assert_eq!(<[f64; 3]>::from(unit(ga)), a.map(|c| c / l));
        }
        assert_eq!(unit(DVec3::ZERO), DVec3::ZERO);
    }

    fn dot_self(a: [f64; 3]) -> f64 {
        a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
    }
}
