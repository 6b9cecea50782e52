//! Block-Jacobi preconditioner on aggregates of neighbouring unknowns of a CSR matrix.
//!
//! Input: a symmetric positive definite matrix in CSR form (sorted or unsorted columns) and an
//! aggregate size m. Output: z = M⁻¹ r with M the block diagonal of A over the aggregates,
//! applied to the three components of each entry alike.
//!
//! Aggregates are grown greedily in row order: the first row not yet taken seeds one, which
//! takes its matrix neighbours breadth-first (in column order) until it holds m rows. On a mesh
//! matrix an aggregate is a compact patch of control points (about 4×4×4 for m = 64), so the
//! preconditioner inverts the strong couplings inside each patch exactly, which point Jacobi
//! ignores. Every principal submatrix of an SPD matrix is SPD, so each block has a Cholesky
//! factor (stored packed, lower triangle); a block whose factorisation fails (A not SPD) is
//! reported as [`CgError::BadDiagonal`] at its first row.
//!
//! The factors are computed in f64 and stored in f32 (`factor_blocks`); the solves widen
//! them back (exactly) and run in f64. M is then L̃ L̃ᵀ with L̃ the rounded factor: still SPD
//! (L̃ is triangular with a positive diagonal) and within a relative 2⁻²⁴ per entry of the
//! exact block factor, which changes the preconditioner, not the operator, so CG converges to
//! the same solution. The factors are the largest stream of the fit's CG after the matrix's
//! columns (two partitions of 64-point blocks: 520 B per row in f64), so halving them pays at
//! scale. (Block Gauss–Seidel in Eisenstat's form keeps f64 factors: there D enters the
//! operator itself.)
//!
//! Invariants: the aggregates partition the rows; the construction is sequential where it
//! decides structure and parallel (per aggregate, independent) elsewhere, so the result does
//! not depend on the thread count.

use super::{CgError, Preconditioner};
use rayon::prelude::*;
use std::collections::VecDeque;

/// Default aggregate size of the fit's block-Jacobi preconditioner.
pub const DEFAULT_BLOCK: usize = 64;

/// Block-Jacobi preconditioner (see the module docs).
pub struct BlockJacobi {
    /// Rows of every aggregate, concatenated; aggregate a is `rows[start[a]..start[a + 1]]`.
    rows: Vec<u32>,
    start: Vec<usize>,
    /// Position of row i in `rows`.
    slot: Vec<u32>,
    /// Packed lower Cholesky factors (f32, see the module docs), aggregate a from
    /// `factor_start[a]`.
    factors: Vec<f32>,
    factor_start: Vec<usize>,
}

/// Greedy breadth-first aggregates of a CSR graph (see the module docs).
pub(crate) struct Aggregates {
    /// Rows of every aggregate, concatenated; aggregate a is `rows[start[a]..start[a + 1]]`.
    pub rows: Vec<u32>,
    pub start: Vec<usize>,
    /// Position of row i in `rows`.
    pub slot: Vec<u32>,
}

impl Aggregates {
    /// Aggregates of at most `size` rows of the graph (`indptr`, `indices`).
    pub fn new(indptr: &[usize], indices: &[u32], size: usize) -> Self {
        Self::grow(indptr, indices, size, false)
    }

    /// [`Self::new`] with the rows and each row's neighbours taken in descending order: on a
    /// mesh graph numbered along the mesh, its patches straddle the boundaries of
    /// [`Self::new`]'s.
    pub fn reversed(indptr: &[usize], indices: &[u32], size: usize) -> Self {
        Self::grow(indptr, indices, size, true)
    }

    fn grow(indptr: &[usize], indices: &[u32], size: usize, reverse: bool) -> Self {
        Self::grow_on(&mut Csr { indptr, indices }, size, reverse)
    }

    /// [`Self::new`] (or, when `reverse`, [`Self::reversed`]) on the graph `graph`, whose rows'
    /// neighbours come in increasing order as a CSR matrix stores them.
    pub(crate) fn grow_on(graph: &mut impl Neighbours, size: usize, reverse: bool) -> Self {
        let n = graph.len();
        let size = size.max(1);
        const FREE: u32 = u32::MAX;
        let mut agg = vec![FREE; n];
        let mut rows = Vec::with_capacity(n);
        let mut start = vec![0usize];
        let mut queue = VecDeque::new();
        for seed in 0..n {
            let seed = if reverse { n - 1 - seed } else { seed };
            if agg[seed] != FREE {
                continue;
            }
            let a = (start.len() - 1) as u32;
            let first = rows.len();
            agg[seed] = a;
            rows.push(seed as u32);
            queue.clear();
            queue.push_back(seed);
            'grow: while let Some(r) = queue.pop_front() {
                let neighbours = graph.of(r);
                for k in 0..neighbours.len() {
                    let c = neighbours[if reverse { neighbours.len() - 1 - k } else { k }];
                    if rows.len() - first >= size {
                        break 'grow;
                    }
                    let c = c as usize;
                    if agg[c] == FREE {
                        agg[c] = a;
                        rows.push(c as u32);
                        queue.push_back(c);
                    }
                }
            }
            start.push(rows.len());
        }
        let mut slot = vec![0u32; n];
        for (k, &r) in rows.iter().enumerate() {
            slot[r as usize] = k as u32;
        }
        Aggregates { rows, start, slot }
    }
}

/// A graph whose aggregates [`Aggregates::grow_on`] grows: its rows and each row's neighbours.
pub(crate) trait Neighbours {
    /// Number of rows.
    fn len(&self) -> usize;
    /// Row r's neighbours, increasing.
    fn of(&mut self, r: usize) -> &[u32];
}

/// A CSR matrix's graph.
struct Csr<'a> {
    indptr: &'a [usize],
    indices: &'a [u32],
}

impl Neighbours for Csr<'_> {
    fn len(&self) -> usize {
        self.indptr.len() - 1
    }
    fn of(&mut self, r: usize) -> &[u32] {
        &self.indices[self.indptr[r]..self.indptr[r + 1]]
    }
}

impl BlockJacobi {
    /// Aggregate the rows of the CSR matrix (`indptr`, `indices`, `data`) into blocks of at
    /// most `size` rows and factor each diagonal block.
    pub fn new(
        indptr: &[usize],
        indices: &[u32],
        data: &[f64],
        size: usize,
    ) -> Result<Self, CgError> {
        Self::on(
            indptr,
            indices,
            data,
            Aggregates::new(indptr, indices, size),
        )
    }

    /// Block Jacobi on the given aggregates of the CSR matrix's rows.
    pub(crate) fn on(
        indptr: &[usize],
        indices: &[u32],
        data: &[f64],
        aggregates: Aggregates,
    ) -> Result<Self, CgError> {
        let Aggregates { rows, start, slot } = aggregates;
        let (factors, factor_start) = factor_blocks(&start, &rows, |a, l| {
            let s = start[a];
            // Dense lower triangle of the block, packed row by row: (i, j ≤ i) at i(i+1)/2 + j.
            for (i, &r) in rows[s..start[a + 1]].iter().enumerate() {
                let r = r as usize;
                for k in indptr[r]..indptr[r + 1] {
                    let j = slot[indices[k] as usize] as usize;
                    if (s..start[a + 1]).contains(&j) && j - s <= i {
                        l[i * (i + 1) / 2 + (j - s)] += data[k];
                    }
                }
            }
        })?;
        Ok(BlockJacobi {
            rows,
            start,
            slot,
            factors,
            factor_start,
        })
    }

    /// Number of aggregates.
    pub fn n_blocks(&self) -> usize {
        self.start.len() - 1
    }
}

/// Packed lower Cholesky factors of the diagonal blocks of the aggregates `start` (rows of
/// aggregate a at `start[a]..start[a + 1]`; `rows` maps them to the caller's row numbers for
/// errors): `fill(a, l)` adds block a's lower triangle into the zeroed packed `l`. Returns the
/// factors, factored in f64 and stored as `T` (f32 for block Jacobi: the module docs), and the
/// start of each block's factor. A pivot that is not positive, or not positive and finite as a
/// `T`, is an error.
pub(crate) fn factor_blocks<T: FactorValue>(
    start: &[usize],
    rows: &[u32],
    fill: impl Fn(usize, &mut [f64]) + Sync,
) -> Result<(Vec<T>, Vec<usize>), CgError> {
    let na = start.len() - 1;
    let mut factor_start = Vec::with_capacity(na + 1);
    factor_start.push(0usize);
    for a in 0..na {
        let m = start[a + 1] - start[a];
        factor_start.push(factor_start[a] + m * (m + 1) / 2);
    }
    let mut factors = vec![T::default(); factor_start[na]];
    split_at_offsets(&mut factors, &factor_start)
        .into_par_iter()
        .enumerate()
        .try_for_each_init(Vec::new, |l: &mut Vec<f64>, (a, out)| {
            // Each thread factors in its own f64 buffer, written (zeros) before `fill` reads
            // it. `out` is only written: a fresh zeroed allocation is mapped on first touch,
            // and a read first maps the shared zero page, whose copy-on-write at the first
            // write then interrupts every core to flush its TLB. This site and the assembly's
            // row sums took 15 % of hole8170's `curve` samples that way.
            l.clear();
            l.resize(out.len(), 0.0);
            fill(a, l);
            let m = start[a + 1] - start[a];
            let bad = |i: usize, value: f64| CgError::BadDiagonal {
                row: rows[start[a] + i] as usize,
                value,
            };
            cholesky_packed(l, m).map_err(|i| bad(i, l[i * (i + 1) / 2 + i]))?;
            for (o, &v) in out.iter_mut().zip(l.iter()) {
                *o = T::narrow(v);
            }
            // A pivot outside f32's range would leave M singular or infinite.
            let diag = |i: usize| out[i * (i + 1) / 2 + i].widen();
            match (0..m).find(|&i| !(diag(i) > 0.0 && diag(i).is_finite())) {
                Some(i) => Err(bad(i, l[i * (i + 1) / 2 + i])),
                None => Ok(()),
            }
        })?;
    Ok((factors, factor_start))
}

/// How a block factor's entries are stored: narrowed from f64 once, widened exactly.
pub(crate) trait FactorValue: Copy + Default + Send + Sync {
    fn narrow(v: f64) -> Self;
    fn widen(self) -> f64;
}

impl FactorValue for f32 {
    #[inline(always)]
    fn narrow(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    fn widen(self) -> f64 {
        f64::from(self)
    }
}

impl FactorValue for f64 {
    #[inline(always)]
    fn narrow(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn widen(self) -> f64 {
        self
    }
}

/// Disjoint mutable pieces `v[offsets[i]..offsets[i + 1]]` (offsets ascending from 0), for
/// filling variable-length blocks in parallel.
pub(crate) fn split_at_offsets<'a, T>(mut v: &'a mut [T], offsets: &[usize]) -> Vec<&'a mut [T]> {
    let mut pieces = Vec::with_capacity(offsets.len().saturating_sub(1));
    for w in offsets.windows(2) {
        let (head, tail) = v.split_at_mut(w[1] - w[0]);
        pieces.push(head);
        v = tail;
    }
    pieces
}

/// In-place Cholesky factorisation of a packed lower triangle; `Err(i)` at a non-positive pivot.
///
/// Row i of L is zero before the first non-zero of row i of the block (Cholesky keeps the
/// envelope, see `blocked::envelope_starts`), so the row starts there and each dot product
/// starts where both rows' envelopes have begun, rounded down to a multiple of four. That
/// changes no bit: the skipped entries stay +0, and the skipped products are zeros that would
/// have gone, chunk by chunk, to the same four partial sums, which start at +0.
fn cholesky_packed(l: &mut [f64], m: usize) -> Result<(), usize> {
    let mut first = Vec::with_capacity(m);
    for i in 0..m {
        let ri = i * (i + 1) / 2;
        let fi = l[ri..ri + i].iter().position(|&v| v != 0.0).unwrap_or(i);
        first.push(fi);
        for j in fi..=i {
            let rj = j * (j + 1) / 2;
            let k0 = fi.max(first[j]).min(j) & !3;
            // Four partial sums: the dot product is not one long dependency chain.
            let mut acc = [0.0; 4];
            let (a, b) = (
                l[ri + k0..ri + j].chunks_exact(4),
                l[rj + k0..rj + j].chunks_exact(4),
            );
            let (ar, br) = (a.remainder(), b.remainder());
            for (a, b) in a.zip(b) {
                for q in 0..4 {
                    acc[q] += a[q] * b[q];
                }
            }
            for (a, b) in ar.iter().zip(br) {
                acc[0] += a * b;
            }
            let s = l[ri + j] - ((acc[0] + acc[1]) + (acc[2] + acc[3]));
            if i == j {
                if !(s > 0.0) {
                    return Err(i);
                }
                l[ri + i] = s.sqrt();
            } else {
                l[ri + j] = s / l[rj + j];
            }
        }
    }
    Ok(())
}

impl Preconditioner for BlockJacobi {
    fn apply(&self, r: &[[f64; 3]], z: &mut [[f64; 3]]) {
        let mut tmp = vec![[0.0; 3]; self.rows.len()];
        split_at_offsets(&mut tmp, &self.start)
            .into_par_iter()
            .enumerate()
            .for_each(|(a, y)| {
                let rows = &self.rows[self.start[a]..self.start[a + 1]];
                let l = &self.factors[self.factor_start[a]..self.factor_start[a + 1]];
                let m = rows.len();
                // L y = r.
                for i in 0..m {
                    let ri = i * (i + 1) / 2;
                    let mut s = r[rows[i] as usize];
                    for k in 0..i {
                        for c in 0..3 {
                            s[c] -= l[ri + k] as f64 * y[k][c];
                        }
                    }
                    y[i] = s.map(|v| v / l[ri + i] as f64);
                }
                // Lᵀ x = y, in place.
                for i in (0..m).rev() {
                    let d = l[i * (i + 1) / 2 + i] as f64;
                    for c in 0..3 {
                        y[i][c] /= d;
                    }
                    let yi = y[i];
                    let ri = i * (i + 1) / 2;
                    for k in 0..i {
                        for c in 0..3 {
                            y[k][c] -= l[ri + k] as f64 * yi[c];
                        }
                    }
                }
            });
        z.par_iter_mut()
            .zip(self.slot.par_iter())
            .with_min_len(1024)
            .for_each(|(z, &s)| *z = tmp[s as usize]);
    }
}

/// Additive block Jacobi on two staggered partitions: z = ½ (M₁⁻¹ r + M₂⁻¹ r), M₁ the
/// block diagonal on `Aggregates::new`'s patches and M₂ on `Aggregates::reversed`'s,
/// which straddle M₁'s boundaries (an overlapping additive Schwarz method whose overlap
/// costs no larger blocks). SPD as a sum of two SPD operators.
///
/// Why: the fit's slowest error modes under block Jacobi are not smooth ones that a coarse
/// space would catch but element-scale oscillations spread over the couplings that the
/// aggregates cut (a coarse space of piecewise constants, smoothed aggregates or even the
/// restrictions of the 40 lowest eigenvectors leaves 60–110 of 111 iterations on a 13.7k
/// control-point cylinder); the second partition inverts those couplings exactly.
///
/// What bounds the pair in turn (smooth preset, 9.7k-hex cylinder unless stated): the spread of
/// the weights, not the size. A quadratic spline's value at a vertex averages the control
/// points around it, so control points alternating along a row of elements are seen only by the
/// midpoint samples (weight 0.05 against 1 at corners): a large family of low-energy modes
/// rather than a few outliers. The Lanczos estimates of the pair-preconditioned spectrum rise
/// steadily from 0.014 (κ ≈ 270); with every weight 1, κ ≈ 64 and CG needs 38 iterations
/// instead of 75, while boundary corners weighted 1 instead of 20 need 73. Iterations barely
/// grow with size (`curve` on generated cylinders of 10k, 100k and 1M hexes: 73, 77, 80). So a
/// coarse space over the aggregates does not help: piecewise constants or smoothed aggregates
/// leave 73 of 75 iterations, and 16 local eigenvectors per aggregate (a quarter of the
/// unknowns) leave 57. Larger blocks do (pairs of 128 and 256 rows: 62 and 48 iterations), and
/// so do the aggregates' shape and stagger: on a 20³-hex box, cubes of 4³ control points
/// staggered by half a cube need 41 iterations where these breadth-first patches need 72 (a
/// seed takes its first neighbours in index order, which makes a patch a slab). Block
/// Gauss–Seidel's sweeps carry the correction along those rows: 42–51 iterations on every mesh
/// measured (the acoustics mesh: 45 against the pair's 102; 1M hexes: 51 against 80), but at 1M
/// hexes the whole job then took 71 s of CPU time against the pair's 58, and 5 % more memory.
///
/// The spectrum on the 52,728-hex cylinder (Lanczos estimates from `curve`'s CG coefficients,
/// smooth preset): point Jacobi λ ∈ [0.0011, 7.76] (κ ≈ 7,100, 310 iterations), block Jacobi
/// [0.0081, 5.38] (κ ≈ 660, 120), the pair [0.0147, 3.94] (κ ≈ 270, 77), block Gauss–Seidel
/// [0.0123, 1] (κ ≈ 81, 46). The pair's low end is a tail (0.015, 0.022, 0.035, 0.046, 0.063, …),
/// not a few outliers that deflation would remove. A diagonal rescaling of the weighted system
/// cannot help any of the block preconditioners: block Jacobi is invariant under scalings that
/// are block diagonal on its aggregates, which every diagonal scaling is. Aggregates grown
/// compact on the graph (each step adding the candidate with the most neighbours inside: about
/// 4³ points) are worse than these slabs (89 iterations, κ ≈ 365; acoustics 109), and so is a
/// second partition seeded where the most first-partition patches meet (compact: 90–94;
/// breadth-first: 74 on the cylinder but 108 on the acoustics mesh). Pairs of 96 and 128 rows
/// save iterations (67, 65) but not time: the CG stage took 1.3 and 1.7 times as long (median
/// of five alternating runs), the block solves growing with the block size.
pub struct BlockJacobiPair {
    first: BlockJacobi,
    second: BlockJacobi,
}

impl BlockJacobiPair {
    /// Both partitions into aggregates of at most `size` rows of the CSR matrix, factored.
    pub fn new(
        indptr: &[usize],
        indices: &[u32],
        data: &[f64],
        size: usize,
    ) -> Result<Self, CgError> {
        let (first, second) = rayon::join(
            || BlockJacobi::new(indptr, indices, data, size),
            || {
                let agg = Aggregates::reversed(indptr, indices, size);
                BlockJacobi::on(indptr, indices, data, agg)
            },
        );
        Ok(BlockJacobiPair {
            first: first?,
            second: second?,
        })
    }
}

impl Preconditioner for BlockJacobiPair {
    fn apply(&self, r: &[[f64; 3]], z: &mut [[f64; 3]]) {
        let mut z2 = vec![[0.0; 3]; r.len()];
        self.first.apply(r, z);
        self.second.apply(r, &mut z2);
        z.par_iter_mut()
            .zip(z2.par_iter())
            .with_min_len(1024)
            .for_each(|(z, w)| {
                for c in 0..3 {
                    z[c] = 0.5 * (z[c] + w[c]);
                }
            });
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) type Csr = (Vec<usize>, Vec<u32>, Vec<f64>);

    /// 2D 5-point Laplacian plus `shift(x, y)` on the diagonal, g × g grid, CSR: with a
    /// constant shift the interior rows repeat one value sequence.
    pub(crate) fn laplacian(g: usize, shift: impl Fn(usize, usize) -> f64) -> Csr {
        let (mut indptr, mut indices, mut data) = (vec![0], Vec::new(), Vec::new());
        for y in 0..g {
            for x in 0..g {
                let mut push = |xx: usize, yy: usize, v: f64| {
                    indices.push((yy * g + xx) as u32);
                    data.push(v);
                };
                if y > 0 {
                    push(x, y - 1, -1.0);
                }
                if x > 0 {
                    push(x - 1, y, -1.0);
                }
                push(x, y, 4.0 + shift(x, y));
                if x + 1 < g {
                    push(x + 1, y, -1.0);
                }
                if y + 1 < g {
                    push(x, y + 1, -1.0);
                }
                indptr.push(indices.len());
            }
        }
        (indptr, indices, data)
    }

    /// The plain CSR product (the oracle).
    pub(crate) fn matvec(a: &Csr, x: &[[f64; 3]]) -> Vec<[f64; 3]> {
        (0..a.0.len() - 1)
            .map(|r| {
                let mut s = [0.0; 3];
                for k in a.0[r]..a.0[r + 1] {
                    for c in 0..3 {
                        s[c] += a.2[k] * x[a.1[k] as usize][c];
                    }
                }
                s
            })
            .collect()
    }

    #[test]
    fn aggregates_partition_the_rows_and_are_connected_patches() {
        let a = laplacian(20, |_, _| 0.1);
        let bj = BlockJacobi::new(&a.0, &a.1, &a.2, 16).unwrap();
        let mut seen = vec![false; 400];
        for &r in &bj.rows {
            assert!(!seen[r as usize]);
            seen[r as usize] = true;
        }
        assert!(seen.iter().all(|&s| s));
        for b in 0..bj.n_blocks() {
            let rows = &bj.rows[bj.start[b]..bj.start[b + 1]];
            assert!(rows.len() <= 16);
            // Compact: a breadth-first patch of 16 grid points spans at most 7 columns/rows.
            let xs: Vec<usize> = rows.iter().map(|&r| r as usize % 20).collect();
            let ys: Vec<usize> = rows.iter().map(|&r| r as usize / 20).collect();
            let span = |v: &[usize]| v.iter().max().unwrap() - v.iter().min().unwrap();
            assert!(span(&xs) <= 7 && span(&ys) <= 7, "{rows:?}");
        }
    }

    /// |A z − r| ≤ `rel` · max |r| entry by entry.
    fn assert_inverts(a: &Csr, z: &[[f64; 3]], r: &[[f64; 3]], rel: f64) {
        let scale = r.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        for (got, want) in matvec(a, z).iter().zip(r) {
            for c in 0..3 {
                let e = (got[c] - want[c]).abs();
                assert!(e <= rel * scale, "{e:e} > {rel:e} · {scale}");
            }
        }
    }

    #[test]
    fn one_block_is_the_exact_inverse() {
        // With every row in one aggregate, M⁻¹ = A⁻¹ up to the factor's rounding to f32: A M⁻¹ r
        // = r within κ(A)·2⁻²⁴ (κ ≈ 16 here: 9.3e-7; 2.1e-7 measured).
        let a = laplacian(6, |_, _| 0.1);
        let bj = BlockJacobi::new(&a.0, &a.1, &a.2, 36).unwrap();
        assert_eq!(bj.n_blocks(), 1);
        let r: Vec<[f64; 3]> = (0..36).map(|i| [(i as f64).sin(), 1.0, i as f64]).collect();
        let mut z = vec![[0.0; 3]; 36];
        bj.apply(&r, &mut z);
        assert_inverts(&a, &z, &r, 1e-6);
    }

    #[test]
    fn blocks_of_one_are_point_jacobi() {
        let a = laplacian(5, |_, _| 0.1);
        let bj = BlockJacobi::new(&a.0, &a.1, &a.2, 1).unwrap();
        let r = vec![[1.0, 2.0, -3.0]; 25];
        let mut z = vec![[0.0; 3]; 25];
        bj.apply(&r, &mut z);
        // The pivot √4.1 is stored in f32: z = r / 4.1 within two roundings to f32.
        let tol = f64::from(f32::EPSILON) / 4.1;
        for z in z {
            assert!((z[0] - 1.0 / 4.1).abs() < tol && (z[2] + 3.0 / 4.1).abs() < 3.0 * tol);
        }
    }

    /// A weighted, graded system: the 2D Laplacian with a light shift inside (0.05) and a
    /// heavy one (20) on the boundary rows, like the fit's midpoint and boundary weights.
    pub(crate) fn weighted(g: usize) -> Csr {
        laplacian(g, |x, y| {
            if x == 0 || y == 0 || x + 1 == g || y + 1 == g {
                20.0
            } else {
                0.05 * (1.0 + (x * y) as f64 / (g * g) as f64)
            }
        })
    }

    pub(crate) fn random_vectors(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        (0..n).map(|_| [next(), next(), next()]).collect()
    }

    fn dot(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(a, b)| a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
            .sum()
    }

    #[test]
    fn the_pair_is_symmetric_positive_definite() {
        let a = weighted(30);
        let m = BlockJacobiPair::new(&a.0, &a.1, &a.2, 16).unwrap();
        let n = 900;
        for seed in 1..20 {
            let (x, y) = (random_vectors(n, seed), random_vectors(n, seed + 100));
            let (mut mx, mut my) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
            m.apply(&x, &mut mx);
            m.apply(&y, &mut my);
            assert!(dot(&x, &mx) > 0.0);
            let (xy, yx) = (dot(&y, &mx), dot(&x, &my));
            assert!((xy - yx).abs() <= 1e-12 * xy.abs().max(1.0), "{xy} {yx}");
        }
    }

    #[test]
    fn the_second_partition_straddles_the_first() {
        let a = weighted(30);
        let (p, q) = (
            Aggregates::new(&a.0, &a.1, 16),
            Aggregates::reversed(&a.0, &a.1, 16),
        );
        let label = |g: &Aggregates| {
            let mut l = vec![0usize; 900];
            for b in 0..g.start.len() - 1 {
                for &r in &g.rows[g.start[b]..g.start[b + 1]] {
                    l[r as usize] = b;
                }
            }
            l
        };
        let (lp, lq) = (label(&p), label(&q));
        // Grid edges cut by the first partition that the second keeps inside a patch.
        let (mut cut, mut covered) = (0, 0);
        for r in 0..900 {
            for &c in &a.1[a.0[r]..a.0[r + 1]] {
                let c = c as usize;
                if lp[r] != lp[c] {
                    cut += 1;
                    covered += usize::from(lq[r] == lq[c]);
                }
            }
        }
        assert!(
            covered * 3 > cut,
            "{covered} of {cut} cut couplings inside a second patch"
        );
    }

    #[test]
    fn the_pair_needs_fewer_iterations_than_block_jacobi_on_a_weighted_system() {
        use crate::solve::{CgParams, LinOp, pcg_with};
        struct Op(Csr);
        impl LinOp for Op {
            fn nrows(&self) -> usize {
                self.0.0.len() - 1
            }
            fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
                y.copy_from_slice(&matvec(&self.0, x));
            }
            fn diagonal(&self) -> Vec<f64> {
                unreachable!()
            }
        }
        let op = Op(weighted(60));
        let n = 3600;
        let b = random_vectors(n, 7);
        let params = CgParams {
            rel_tol: 1e-8,
            ..Default::default()
        };
        let a = &op.0;
        let solve = |m: &dyn Preconditioner| {
            let mut x = vec![[0.0; 3]; n];
            let info = pcg_with(&op, m, &b, &mut x, &params, |_, _| {}).unwrap();
            // The answer, checked against the matrix itself.
            let r = matvec(a, &x);
            let res: f64 = r.iter().zip(&b).map(|(r, b)| (r[0] - b[0]).powi(2)).sum();
            assert!(res.sqrt() <= 1e-7 * dot(&b, &b).sqrt());
            info.iterations
        };
        let jacobi = solve(&BlockJacobi::new(&a.0, &a.1, &a.2, 16).unwrap());
        let pair = solve(&BlockJacobiPair::new(&a.0, &a.1, &a.2, 16).unwrap());
        assert!(pair * 10 < jacobi * 9, "pair {pair}, block Jacobi {jacobi}");
    }

    /// The fit's normal matrix on a box of `n` hexes with uniform knots, as `fit::assembly`
    /// builds it for the smooth preset: per element, the 27 samples of {0, ½, 1}³ with weight
    /// 1 at corners and 0.05 elsewhere (20 and 1 on the box's boundary), times the size weight
    /// (h_max/h_e)² of element sizes graded geometrically by `ratio` along x; the quadratic
    /// B-spline values at ξ = 0, ½, 1 are (½, ½, 0), (⅛, ¾, ⅛), (0, ½, ½). Control points
    /// (n + 2 per axis) numbered x fastest; CSR with sorted columns.
    pub(crate) fn spline_fit_matrix(n: [usize; 3], ratio: f64) -> Csr {
        const VALUES: [[f64; 3]; 3] = [[0.5, 0.5, 0.0], [0.125, 0.75, 0.125], [0.0, 0.5, 0.5]];
        let m = n.map(|k| k + 2);
        let row = |p: [usize; 3]| p[0] + m[0] * (p[1] + m[1] * p[2]);
        let h = |ex: usize| ratio.powi(ex as i32);
        let h_max = h(0).max(h(n[0] - 1));
        // Per row, the 5³ couplings at offsets −2..=2.
        let mut dense = vec![[0.0f64; 125]; m[0] * m[1] * m[2]];
        for ez in 0..n[2] {
            for ey in 0..n[1] {
                for ex in 0..n[0] {
                    let e = [ex, ey, ez];
                    let size = (h_max / h(ex)).powi(2);
                    for s in 0..27 {
                        let t = [s % 3, s / 3 % 3, s / 9];
                        let corner = t.iter().all(|&t| t != 1);
                        let boundary = (0..3)
                            .any(|d| (t[d] == 0 && e[d] == 0) || (t[d] == 2 && e[d] + 1 == n[d]));
                        let w = size
                            * match (corner, boundary) {
                                (true, true) => 20.0,
                                (true, false) | (false, true) => 1.0,
                                (false, false) => 0.05,
                            };
                        let local: Vec<([usize; 3], f64)> = (0..27)
                            .map(|c| {
                                let o = [c % 3, c / 3 % 3, c / 9];
                                let v = (0..3).map(|d| VALUES[t[d]][o[d]]).product::<f64>();
                                (std::array::from_fn(|d| e[d] + o[d]), v)
                            })
                            .filter(|&(_, v)| v != 0.0)
                            .collect();
                        for &(p, vp) in &local {
                            for &(q, vq) in &local {
                                let off: [usize; 3] = std::array::from_fn(|d| q[d] + 2 - p[d]);
                                dense[row(p)][off[0] + 5 * (off[1] + 5 * off[2])] += w * vp * vq;
                            }
                        }
                    }
                }
            }
        }
        let (mut indptr, mut indices, mut data) = (vec![0], Vec::new(), Vec::new());
        for z in 0..m[2] {
            for y in 0..m[1] {
                for x in 0..m[0] {
                    let couplings = &dense[row([x, y, z])];
                    for o in 0..125 {
                        let q = [x + o % 5, y + o / 5 % 5, z + o / 25];
                        if couplings[o] != 0.0 && (0..3).all(|d| (2..m[d] + 2).contains(&q[d])) {
                            indices.push(row(q.map(|c| c - 2)) as u32);
                            data.push(couplings[o]);
                        }
                    }
                    indptr.push(indices.len());
                }
            }
        }
        (indptr, indices, data)
    }

    /// The extreme eigenvalues of M⁻¹A estimated by Lanczos from the coefficients of a
    /// preconditioned CG (one right-hand side, `b`'s first component): the tridiagonal matrix
    /// with diagonal 1/α_k + β_{k−1}/α_{k−1} and off-diagonal √β_k/α_k, whose extreme
    /// eigenvalues (found by Sturm bisection) converge to M⁻¹A's from inside.
    pub(crate) fn lanczos_extremes(a: &Csr, m: &dyn Preconditioner, b: &[[f64; 3]]) -> (f64, f64) {
        let n = b.len();
        let first =
            |v: &[[f64; 3]]| -> Vec<[f64; 3]> { v.iter().map(|e| [e[0], 0.0, 0.0]).collect() };
        let mut r = first(b);
        let mut z = vec![[0.0; 3]; n];
        m.apply(&r, &mut z);
        let mut p = z.clone();
        let mut rz = dot(&r, &z);
        let (mut alphas, mut betas) = (Vec::new(), Vec::new());
        let b0 = dot(&r, &r).sqrt();
        while alphas.len() < 400 && dot(&r, &r).sqrt() > 1e-10 * b0 {
            let ap = matvec(a, &p);
            let alpha = rz / dot(&p, &ap);
            for i in 0..n {
                r[i][0] -= alpha * ap[i][0];
            }
            m.apply(&r, &mut z);
            let rz_new = dot(&r, &z);
            let beta = rz_new / rz;
            for i in 0..n {
                p[i][0] = z[i][0] + beta * p[i][0];
            }
            rz = rz_new;
            alphas.push(alpha);
            betas.push(beta);
        }
        let k = alphas.len();
        let diag: Vec<f64> = (0..k)
            .map(|i| {
                1.0 / alphas[i]
                    + if i > 0 {
                        betas[i - 1] / alphas[i - 1]
                    } else {
                        0.0
                    }
            })
            .collect();
        let off: Vec<f64> = (0..k.saturating_sub(1))
            .map(|i| betas[i].sqrt() / alphas[i])
            .collect();
        // Number of eigenvalues below x (Sturm sequence of the LDLᵀ pivots).
        let below = |x: f64| {
            let (mut count, mut d) = (0, 1.0);
            for i in 0..k {
                let o = if i > 0 { off[i - 1] * off[i - 1] } else { 0.0 };
                d = diag[i] - x - if i > 0 { o / d } else { 0.0 };
                if d == 0.0 {
                    d = -1e-300;
                }
                count += usize::from(d < 0.0);
            }
            count
        };
        let hi = (0..k)
            .map(|i| {
                diag[i] + if i > 0 { off[i - 1] } else { 0.0 } + off.get(i).copied().unwrap_or(0.0)
            })
            .fold(0.0, f64::max);
        let bisect = |j: usize| {
            // The (j + 1)-th smallest eigenvalue.
            let (mut lo, mut up) = (0.0, hi);
            for _ in 0..200 {
                let mid = 0.5 * (lo + up);
                if below(mid) > j {
                    up = mid;
                } else {
                    lo = mid;
                }
            }
            0.5 * (lo + up)
        };
        (bisect(0), bisect(k - 1))
    }

    /// The pair's condition on the fit's weighted, graded normal matrix (a 14 × 12 × 10-hex
    /// box graded 1.25 per element along x: size weights up to 150): the condition number of
    /// M⁻¹A estimated by Lanczos from CG's coefficients, for point Jacobi, block Jacobi and
    /// the pair on blocks of [`DEFAULT_BLOCK`]. On the 52,728-hex cylinder these are 7093,
    /// 663 and 268 (Lanczos from `curve`'s solve), here 56,600, 5,010 and 1,290: block Jacobi
    /// removes most of point Jacobi's spread (0.09 of its κ on both) and the staggered second
    /// partition most of what is left (0.40 of block Jacobi's on the cylinder, 0.26 here),
    /// which CG turns into iterations as √κ. The bounds keep a margin of about two over the
    /// ratios measured here: block Jacobi below 0.2 of point Jacobi's κ, the pair below 0.45
    /// of block Jacobi's (a pair whose second partition is its first has a ratio of 1).
    #[test]
    fn the_pair_conditions_the_weighted_graded_fit_matrix() {
        let a = spline_fit_matrix([14, 12, 10], 1.25);
        let n = a.0.len() - 1;
        let b = random_vectors(n, 11);
        let kappa = |m: &dyn Preconditioner| {
            let (lo, hi) = lanczos_extremes(&a, m, &b);
            hi / lo
        };
        let point = kappa(&BlockJacobi::new(&a.0, &a.1, &a.2, 1).unwrap());
        let block = kappa(&BlockJacobi::new(&a.0, &a.1, &a.2, DEFAULT_BLOCK).unwrap());
        let pair = kappa(&BlockJacobiPair::new(&a.0, &a.1, &a.2, DEFAULT_BLOCK).unwrap());
        eprintln!("κ: point Jacobi {point:.1}, block Jacobi {block:.1}, pair {pair:.1}");
        assert!(
            block < 0.2 * point,
            "block Jacobi κ {block} against point Jacobi {point}"
        );
        assert!(
            pair < 0.45 * block,
            "pair κ {pair} against block Jacobi {block}"
        );
    }

    /// The Lanczos estimate is the spectrum's: on a diagonal matrix with point Jacobi on a
    /// scaled copy, M⁻¹A has the known eigenvalues d_i / s_i.
    #[test]
    fn the_lanczos_estimate_finds_known_extreme_eigenvalues() {
        let n = 200;
        let d: Vec<f64> = (0..n).map(|i| 1.0 + i as f64).collect();
        let a: Csr = ((0..=n).collect(), (0..n as u32).collect(), d.clone());
        let m = BlockJacobi::new(&a.0, &a.1, &a.2, 1).unwrap();
        // M = A: one eigenvalue 1 (within the f32 factor's rounding).
        let (lo, hi) = lanczos_extremes(&a, &m, &random_vectors(n, 5));
        assert!(
            (lo - 1.0).abs() < 1e-6 && (hi - 1.0).abs() < 1e-6,
            "{lo} {hi}"
        );
        // M = I: the eigenvalues are the diagonal, 1 to 200.
        let id: Csr = ((0..=n).collect(), (0..n as u32).collect(), vec![1.0; n]);
        let m = BlockJacobi::new(&id.0, &id.1, &id.2, 1).unwrap();
        let (lo, hi) = lanczos_extremes(&a, &m, &random_vectors(n, 5));
        assert!(
            (lo - 1.0).abs() < 1e-6 && (hi - 200.0).abs() < 1e-6,
            "{lo} {hi}"
        );
    }

    #[test]
    fn the_pair_of_whole_blocks_is_the_exact_inverse() {
        let a = weighted(6);
        let m = BlockJacobiPair::new(&a.0, &a.1, &a.2, 36).unwrap();
        let r = random_vectors(36, 3);
        let mut z = vec![[0.0; 3]; 36];
        m.apply(&r, &mut z);
        // Within κ(A)·2⁻²⁴ of the exact inverse (f32 factors; κ ≈ 33 here: 2.0e-6).
        assert_inverts(&a, &z, &r, 1e-5);
    }

    #[test]
    fn a_pivot_beyond_f32_is_an_error() {
        // Row 6's pivot √1e80 factors in f64 but is no f32: stored, it would make M singular
        // (an infinite pivot), so it is refused like a non-positive one.
        let mut a = laplacian(4, |_, _| 0.1);
        let k = (a.0[6]..a.0[7]).find(|&k| a.1[k] == 6).unwrap();
        a.2[k] = 1e80;
        match BlockJacobi::new(&a.0, &a.1, &a.2, 8) {
            Err(CgError::BadDiagonal { row, .. }) => assert_eq!(row, 6),
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("accepted a pivot beyond f32"),
        }
    }

    #[test]
    fn an_indefinite_block_is_an_error() {
        let mut a = laplacian(4, |_, _| 0.1);
        // Row 5's diagonal made negative.
        let k = (a.0[5]..a.0[6]).find(|&k| a.1[k] == 5).unwrap();
        a.2[k] = -1.0;
        match BlockJacobi::new(&a.0, &a.1, &a.2, 8) {
            Err(CgError::BadDiagonal { row, .. }) => assert_eq!(row, 5),
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("accepted an indefinite block"),
        }
    }
}
