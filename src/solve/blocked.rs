//! Block-Jacobi PCG on an assembled matrix, reordered by aggregates and stored by row
//! templates: the CPU solver of the fit's normal equations; and the symmetric block
//! Gauss–Seidel PCG on the same aggregates in Eisenstat's form
//! ([`BlockedSystem::symmetric_gauss_seidel`]), which keeps only the couplings between
//! aggregates.
//!
//! Input: a symmetric positive definite CSR matrix A (`indptr`, `indices`, `data`), an
//! aggregate size m, right-hand sides b (three components) and a start x. Output: x with
//! ‖b − A x‖ ≤ `rel_tol`·‖b‖ per component, as [`super::pcg`] with
//! [`super::CgPreconditioner::BlockJacobi`] (same recurrences, same stopping rule, same
//! preconditioner M = the block diagonal of A over the same aggregates), only faster:
//!
//! * **Aggregate order.** The unknowns are renumbered so that every aggregate of
//!   `Aggregates` is a contiguous range; the block solves then work in place, with no
//!   gather/scatter, and the whole solve runs in that order (b and x are permuted once).
//! * **Row templates.** The fit's K depends on the topology and the weights only, not on the
//!   geometry, so most rows repeat the value sequence (in column order) of some other row:
//!   on a 52,728-hex cylinder the 61,180 rows have 898 distinct sequences, 94 k values for
//!   7.05 M entries. Each row stores its template id and its columns; the values come from the
//!   template table, which stays in cache, so the product streams 4 B per entry instead of 12.
//!   The values are A's own f64 values bit for bit (templates are found by exact comparison):
//!   the operator is A exactly, and a matrix without repeats just has one template per row.
//! * **Packed columns** ([`BlockedKind::Jacobi`] and the pair). A row's columns are stored
//!   as 16-bit offsets from its smallest column where they span less than 2¹⁶ (in aggregate
//!   order a row's neighbours are near: all but a few rows on the fit's systems), in 32 bits
//!   otherwise; the product then streams 2 B per entry, with the same sums in the same order
//!   (the same bits). The 32-bit array is never made; Gauss–Seidel keeps it.
//! * **Fused passes.** One iteration is three parallel passes: the product A p with the
//!   partial sums of pᵀAp; per aggregate the updates of x and r, the block solve z = M⁻¹ r and
//!   the partial sums of rᵀz and rᵀr; then p = z + β p.
//! * **Pair preconditioner** ([`BlockedKind::JacobiPair`]): z = ½ (M₁⁻¹ r + M₂⁻¹ r) with M₂
//!   block Jacobi on a second, staggered partition (factors stored as M₁'s). Its block solves
//!   need the updated r of neighbouring aggregates, so they take one more pass (gathering r
//!   into a work vector allocated once per solve, with the partial sums of rᵀM₂⁻¹r); the
//!   average is formed inside the pass p = z + β p, so z is never stored whole.
//! * **4-lane entries.** Vectors hold [f64; 4] (lane 3 zero), one 256-bit operation per entry;
//!   the two kernels are compiled a second time for AVX2 and chosen at run time (no FMA, so
//!   both give the same bits).
//!
//! Invariants: every dot product is a sum of per-chunk partial sums (fixed chunks of rows, or
//! aggregates) added in order, so the result does not depend on the thread count.

use super::block_jacobi::{Aggregates, FactorValue, factor_blocks, split_at_offsets};
use super::lines::{LineBlocks, Lines};
use super::{CgError, CgInfo, CgParams, CgSteps, Pair, Stopping, iterate};
use rayon::prelude::*;
use std::borrow::Cow;
use std::collections::HashMap;

/// Rows per chunk of the product (and per partial sum of pᵀAp).
const ROW_CHUNK: usize = 512;

/// A vector entry: the three components and a zero lane, so that one entry is one 256-bit
/// (or two 128-bit) vector operation.
pub type V4 = [f64; 4];

/// True when `POLYSPLINE_KERNELS=portable`: the solver then runs the portable kernels even on
/// an AVX2 CPU (read once per matrix; for checking that both give the same bits).
fn portable_from_env() -> bool {
    std::env::var("POLYSPLINE_KERNELS").is_ok_and(|v| v == "portable")
}

/// Runs `f` compiled for AVX2 where the CPU has it and `$portable` is false (no FMA: each lane
/// does the same IEEE multiplications and additions in the same order as the portable code, so
/// results are identical on every x86-64 CPU; a test forces both and compares the bits).
macro_rules! dispatch {
    ($portable:expr, $avx:ident, $generic:ident ( $($arg:expr),* )) => {{
        #[cfg(target_arch = "x86_64")]
        {
            if !$portable && std::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2 (checked just above).
                unsafe { $avx($($arg),*) }
            } else {
                $generic($($arg),*)
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = $portable;
            $generic($($arg),*)
        }
    }};
}

/// A in aggregate order with rows stored by template (see the module docs).
pub struct TemplateMatrix {
    /// Row i's columns (new numbering) are `cols[indptr[i]..indptr[i + 1]]` until
    /// [`Self::pack`] moves them into `packed`.
    indptr: Vec<usize>,
    cols: Vec<u32>,
    packed: Option<PackedColumns>,
    /// Template of each row; template t's values are `values[template_start[t]..]`, in the
    /// order of the row's columns.
    template: Vec<u32>,
    template_start: Vec<usize>,
    values: Vec<f64>,
    /// Run the portable kernels even where AVX2 is available.
    portable: bool,
}

/// [`PackedColumns::base`] of a row stored with 32-bit columns.
const WIDE: u32 = u32::MAX;

/// A's columns in 16 bits where a row's columns span less than 2¹⁶: row i (of `n` entries,
/// [`TemplateMatrix`]'s `indptr`) has columns `base[i] + offsets[start[i]..start[i] + n]`,
/// or, where `base[i]` is [`WIDE`], `wide[start[i]..start[i] + n]`. The product reads
/// 2 B per entry instead of 4 (the columns are its largest stream).
/// The distributed CG's share of K keeps its columns so too (`distributed::cg::LocalMatrix`).
pub(crate) struct PackedColumns {
    base: Vec<u32>,
    start: Vec<usize>,
    offsets: Vec<u16>,
    wide: Vec<u32>,
}

/// One row's stored columns ([`PackedColumns::row`]).
pub(crate) enum RowColumns<'a> {
    /// Column `base + offsets[k]`.
    Narrow(usize, &'a [u16]),
    Wide(&'a [u32]),
}

impl PackedColumns {
    /// The columns of A (CSR `indptr`, `indices`) renumbered as [`TemplateMatrix::renumbered`]
    /// renumbers them, packed.
    fn new(indptr: &[usize], indices: &[u32], rows: &[u32], slot: &[u32]) -> Self {
        let old = |i: usize| {
            let r = rows[i] as usize;
            &indices[indptr[r]..indptr[r + 1]]
        };
        Self::build(rows.len(), old, |c| slot[c as usize])
    }

    /// The columns of a CSR matrix (`indptr`, `indices`) as they are, packed.
    pub(crate) fn from_csr(indptr: &[usize], indices: &[u32]) -> Self {
        let row = |i: usize| &indices[indptr[i]..indptr[i + 1]];
        Self::build(indptr.len() - 1, row, |c| c)
    }

    /// Row i's stored columns, of `n` entries.
    #[inline(always)]
    pub(crate) fn row(&self, i: usize, n: usize) -> RowColumns<'_> {
        let at = self.start[i]..self.start[i] + n;
        match self.base[i] {
            WIDE => RowColumns::Wide(&self.wide[at]),
            base => RowColumns::Narrow(base as usize, &self.offsets[at]),
        }
    }

    /// `f(column, value)` for row i's entries (`vals`, in the order of its columns).
    #[inline]
    pub(crate) fn for_each_entry(&self, i: usize, vals: &[f64], mut f: impl FnMut(usize, f64)) {
        match self.row(i, vals.len()) {
            RowColumns::Wide(cols) => cols.iter().zip(vals).for_each(|(&c, &v)| f(c as usize, v)),
            RowColumns::Narrow(base, offsets) => offsets
                .iter()
                .zip(vals)
                .for_each(|(&o, &v)| f(base + usize::from(o), v)),
        }
    }

    /// Packed columns of `n` rows: row i's columns are `new(c)` for c in `old(i)`.
    fn build<'a>(
        n: usize,
        old: impl Fn(usize) -> &'a [u32] + Sync,
        new: impl Fn(u32) -> u32 + Sync,
    ) -> Self {
        let rows = 0..n;
        // Per row: its smallest new column, and whether its span fits 16 bits.
        let span: Vec<(u32, bool)> = rows
            .clone()
            .into_par_iter()
            .with_min_len(ROW_CHUNK)
            .map(|i| {
                let (lo, hi) = old(i).iter().fold((u32::MAX, 0), |(lo, hi), &c| {
                    let c = new(c);
                    (lo.min(c), hi.max(c))
                });
                (lo, hi.saturating_sub(lo) <= u32::from(u16::MAX))
            })
            .collect();
        // Row i's entries in `offsets` (narrow rows) and in `wide` (the others).
        let (mut narrow, mut wide_at) = (vec![0usize], vec![0usize]);
        let (mut base, mut start) = (Vec::with_capacity(n), Vec::new());
        start.reserve(n);
        for (i, &(lo, fits)) in span.iter().enumerate() {
            let len = old(i).len();
            let (n, w) = (*narrow.last().unwrap(), *wide_at.last().unwrap());
            base.push(if fits { lo } else { WIDE });
            start.push(if fits { n } else { w });
            narrow.push(n + if fits { len } else { 0 });
            wide_at.push(w + if fits { 0 } else { len });
        }
        drop(span);
        let mut offsets = vec![0u16; *narrow.last().unwrap()];
        let mut wide = vec![0u32; *wide_at.last().unwrap()];
        split_at_offsets(&mut offsets, &narrow)
            .into_par_iter()
            .zip(split_at_offsets(&mut wide, &wide_at))
            .enumerate()
            .with_min_len(256)
            .for_each(|(i, (o, w))| {
                let cols = old(i).iter().map(|&c| new(c));
                match base[i] {
                    WIDE => w.iter_mut().zip(cols).for_each(|(w, c)| *w = c),
                    lo => o
                        .iter_mut()
                        .zip(cols)
                        .for_each(|(o, c)| *o = (c - lo) as u16),
                }
            });
        PackedColumns {
            base,
            start,
            offsets,
            wide,
        }
    }
}

/// A hash of a row's value sequence (four independent lanes, so it is not latency-bound).
pub(crate) fn hash_row(v: &[f64]) -> u64 {
    let mut h = [v.len() as u64, 1, 2, 3];
    let mut it = v.chunks_exact(4);
    for c in &mut it {
        for l in 0..4 {
            h[l] = (h[l] ^ c[l].to_bits()).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        }
    }
    for (l, x) in it.remainder().iter().enumerate() {
        h[l] = (h[l] ^ x.to_bits()).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }
    h.iter().fold(0u64, |a, &x| {
        (a ^ x ^ (x >> 29)).wrapping_mul(0x100_0000_01b3)
    })
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// A table of distinct row value sequences (templates), filled batch by batch: template t's
/// values are `values[start[t]..start[t + 1]]`. Rows are matched by exact bits, so a row's
/// template holds its own values.
#[derive(Clone)]
pub(crate) struct RowTemplates {
    by_hash: HashMap<u64, u32>,
    /// Templates made for rows whose hash matched a template with other values.
    collided: Vec<u32>,
    pub(crate) start: Vec<usize>,
    pub(crate) values: Vec<f64>,
}

impl Default for RowTemplates {
    fn default() -> Self {
        RowTemplates {
            by_hash: HashMap::new(),
            collided: Vec::new(),
            start: vec![0],
            values: Vec::new(),
        }
    }
}

impl RowTemplates {
    /// Number of templates.
    pub(crate) fn len(&self) -> usize {
        self.start.len() - 1
    }

    /// Template t's values.
    pub(crate) fn get(&self, t: u32) -> &[f64] {
        &self.values[self.start[t as usize]..self.start[t as usize + 1]]
    }

    fn push(start: &mut Vec<usize>, values: &mut Vec<f64>, v: &[f64]) -> u32 {
        values.extend_from_slice(v);
        start.push(values.len());
        start.len() as u32 - 2
    }

    /// The template of each of the rows `row(0..count)`, adding the new ones in order of
    /// first appearance (by hash, sequentially: a deterministic numbering), then every row
    /// compared with its template in parallel; the rows of a hash collision (if any) get
    /// templates of their own.
    pub(crate) fn add_rows<'a>(
        &mut self,
        count: usize,
        row: impl Fn(usize) -> &'a [f64] + Sync,
        hash: impl Fn(&[f64]) -> u64 + Sync,
    ) -> Vec<u32> {
        let hashes: Vec<u64> = (0..count)
            .into_par_iter()
            .with_min_len(256)
            .map(|i| hash(row(i)))
            .collect();
        let RowTemplates {
            by_hash,
            collided,
            start,
            values,
        } = self;
        let mut template: Vec<u32> = hashes
            .iter()
            .enumerate()
            .map(|(i, &h)| {
                *by_hash
                    .entry(h)
                    .or_insert_with(|| Self::push(start, values, row(i)))
            })
            .collect();
        let get = |t: u32| &values[start[t as usize]..start[t as usize + 1]];
        let mismatched: Vec<usize> = (0..count)
            .into_par_iter()
            .with_min_len(256)
            .filter(|&i| !same_bits(row(i), get(template[i])))
            .collect();
        for i in mismatched {
            let v = row(i);
            let known = collided.iter().copied().find(|&t| {
                let t = t as usize;
                same_bits(&values[start[t]..start[t + 1]], v)
            });
            template[i] = known.unwrap_or_else(|| {
                let t = Self::push(start, values, v);
                collided.push(t);
                t
            });
        }
        template
    }
}

impl TemplateMatrix {
    /// A (CSR) renumbered so that new row i is old row `rows[i]` (`slot` is the inverse).
    #[cfg(test)]
    pub(crate) fn new(
        indptr: &[usize],
        indices: &[u32],
        data: &[f64],
        rows: &[u32],
        slot: &[u32],
    ) -> Self {
        Self::with_hash(
            indptr,
            Cow::Borrowed(indices),
            Cow::Borrowed(data),
            rows,
            slot,
            hash_row,
            false,
        )
    }

    /// [`Self::new`] with a given row hash (tests force collisions with it). Owned `data` is
    /// released once the template table holds the values, and owned `indices` once the
    /// columns are renumbered: A is never held twice over.
    fn with_hash(
        indptr: &[usize],
        indices: Cow<[u32]>,
        data: Cow<[f64]>,
        rows: &[u32],
        slot: &[u32],
        hash: impl Fn(&[f64]) -> u64 + Sync,
        pack: bool,
    ) -> Self {
        let row_values = |i: usize| {
            let r = rows[i] as usize;
            &data[indptr[r]..indptr[r + 1]]
        };
        let mut table = RowTemplates::default();
        let template = table.add_rows(rows.len(), row_values, hash);
        drop(data);
        Self::renumbered(indptr, indices, template, table, rows, slot, pack)
    }

    /// A whose rows are already stored by template (row r of the old numbering takes the
    /// values of template `row_template[r]` of `table`), renumbered like [`Self::new`]: the
    /// values are never expanded.
    fn from_templates(
        indptr: &[usize],
        indices: Cow<[u32]>,
        row_template: &[u32],
        table: RowTemplates,
        rows: &[u32],
        slot: &[u32],
        pack: bool,
    ) -> Self {
        let template = rows.iter().map(|&r| row_template[r as usize]).collect();
        Self::renumbered(indptr, indices, template, table, rows, slot, pack)
    }

    /// The columns of A renumbered (new row i is old row `rows[i]`, old column c is new
    /// column `slot[c]`), in 16 bits where they fit when `pack` ([`PackedColumns`]); owned
    /// `indices` are released once copied.
    fn renumbered(
        indptr: &[usize],
        indices: Cow<[u32]>,
        template: Vec<u32>,
        table: RowTemplates,
        rows: &[u32],
        slot: &[u32],
        pack: bool,
    ) -> Self {
        let mut new_indptr = Vec::with_capacity(rows.len() + 1);
        new_indptr.push(0usize);
        for &r in rows {
            let r = r as usize;
            new_indptr.push(new_indptr.last().unwrap() + indptr[r + 1] - indptr[r]);
        }
        let (cols, packed) = if pack {
            (
                Vec::new(),
                Some(PackedColumns::new(indptr, &indices, rows, slot)),
            )
        } else {
            (
                Self::renumbered_columns(indptr, &indices, rows, slot, &new_indptr),
                None,
            )
        };
        drop(indices);
        TemplateMatrix {
            indptr: new_indptr,
            cols,
            packed,
            template,
            template_start: table.start,
            values: table.values,
            portable: portable_from_env(),
        }
    }

    /// The renumbered columns in 32 bits, row by row (`new_indptr`).
    fn renumbered_columns(
        indptr: &[usize],
        indices: &[u32],
        rows: &[u32],
        slot: &[u32],
        new_indptr: &[usize],
    ) -> Vec<u32> {
        let mut cols = vec![0u32; indices.len()];
        split_at_offsets(&mut cols, new_indptr)
            .into_par_iter()
            .zip(rows.par_iter())
            .with_min_len(256)
            .for_each(|(c, &r)| {
                let (lo, hi) = (indptr[r as usize], indptr[r as usize + 1]);
                for (c, &old) in c.iter_mut().zip(&indices[lo..hi]) {
                    *c = slot[old as usize];
                }
            });
        cols
    }

    pub fn nrows(&self) -> usize {
        self.template.len()
    }

    /// Number of distinct row templates.
    pub fn n_templates(&self) -> usize {
        self.template_start.len() - 1
    }

    /// Row i as (columns, values) where the columns are not packed.
    #[inline(always)]
    fn row(&self, i: usize) -> (&[u32], &[f64]) {
        debug_assert!(self.packed.is_none(), "the columns are packed");
        (
            &self.cols[self.indptr[i]..self.indptr[i + 1]],
            self.values_of(i),
        )
    }

    /// `f(column, value)` for row i's entries in their stored order, packed or not.
    #[inline]
    fn for_each_entry(&self, i: usize, mut f: impl FnMut(usize, f64)) {
        let vals = self.values_of(i);
        match &self.packed {
            None => {
                let cols = &self.cols[self.indptr[i]..self.indptr[i + 1]];
                cols.iter().zip(vals).for_each(|(&c, &v)| f(c as usize, v));
            }
            Some(p) => p.for_each_entry(i, vals, f),
        }
    }

    /// Row i's values.
    #[inline(always)]
    fn values_of(&self, i: usize) -> &[f64] {
        let t = self.template[i] as usize;
        &self.values[self.template_start[t]..self.template_start[t + 1]]
    }

    /// Row i of A times x, from the packed columns where they are.
    #[inline(always)]
    fn row_times(&self, i: usize, x: &[V4]) -> V4 {
        let Some(p) = &self.packed else {
            let (cols, vals) = self.row(i);
            return super::row_dot(cols, vals, x);
        };
        let vals = self.values_of(i);
        match p.row(i, vals.len()) {
            RowColumns::Wide(cols) => super::row_dot(cols, vals, x),
            RowColumns::Narrow(base, offsets) => super::row_dot(offsets, vals, &x[base..]),
        }
    }

    /// y = A x, returning xᵀ A x per lane (a fixed-chunk sum).
    pub fn apply_dot(&self, x: &[V4], y: &mut [V4]) -> V4 {
        let partials: Vec<V4> = y
            .par_chunks_mut(ROW_CHUNK)
            .enumerate()
            .map(|(k, y)| {
                dispatch!(
                    self.portable,
                    spmv_chunk_avx2,
                    spmv_chunk(self, k * ROW_CHUNK, x, y)
                )
            })
            .collect();
        sum(&partials)
    }
}

/// Rows `base..base + y.len()` of A x into y; returns Σ x_i y_i over those rows.
#[inline(always)]
fn spmv_chunk(a: &TemplateMatrix, base: usize, x: &[V4], y: &mut [V4]) -> V4 {
    let mut dot = [0.0; 4];
    for (j, y) in y.iter_mut().enumerate() {
        *y = a.row_times(base + j, x);
        let xi = x[base + j];
        for d in 0..4 {
            dot[d] += xi[d] * y[d];
        }
    }
    dot
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn spmv_chunk_avx2(a: &TemplateMatrix, base: usize, x: &[V4], y: &mut [V4]) -> V4 {
    spmv_chunk(a, base, x, y)
}

/// `n` zero entries, written rather than allocated zeroed. A zeroed allocation is mapped on
/// first touch, and when that touch is a read (the first step reads `r`, `p` and `ap` before
/// anything writes them) the page is the shared zero page, whose copy-on-write at the first
/// write then interrupts every core to flush its TLB (the turbine's main remaining such
/// faults after `block_jacobi::factor_blocks` and the assembly were fixed).
fn written_zeros(n: usize) -> Vec<V4> {
    (0..n)
        .into_par_iter()
        .with_min_len(ROW_CHUNK)
        .map(|_| [0.0; 4])
        .collect()
}

fn sum(partials: &[V4]) -> V4 {
    partials
        .iter()
        .fold([0.0; 4], |a, b| std::array::from_fn(|d| a[d] + b[d]))
}

/// A's values as given to [`BlockedSystem::build`]: CSR values, or a template per row.
enum Values<'a> {
    Csr(Cow<'a, [f64]>),
    Templates(Vec<u32>, RowTemplates),
}

/// The reordered system and its block factors.
pub struct BlockedSystem {
    agg: Aggregates,
    op: Operator,
    /// Packed lower Cholesky factor of aggregate a's diagonal block, from `factor_start[a]`.
    factors: Factors,
    factor_start: Vec<usize>,
    /// Per row (new numbering), the even-rounded start of its factor row's envelope, counted
    /// from the aggregate's first row: the entries before it are exact zeros (see
    /// [`envelope_starts`]).
    first: Vec<u32>,
    /// The second partition of the pair preconditioner ([`BlockedKind::JacobiPair`]).
    second: Option<SecondPartition>,
    /// Line blocks added to the preconditioner ([`Self::with_lines`]).
    lines: Option<LineSystem>,
}

/// Line blocks in the system's numbering ([`super::lines`]), and per row the positions of its
/// shares in the lines' order (row i's at `share_at[share_start[i]..share_start[i + 1]]`).
struct LineSystem {
    blocks: LineBlocks,
    share_start: Vec<u32>,
    share_at: Vec<u32>,
}

/// The diagonal blocks' factors as stored: f32 for block Jacobi and the pair (widened per block
/// by [`widened`]; see `block_jacobi`'s module docs), f64 for Gauss–Seidel, whose Eisenstat
/// form uses D inside the operator (A = (D + L) + (D + U) − D), so D must be A's blocks exactly.
enum Factors {
    Single(Vec<f32>),
    Double(Vec<f64>),
}

/// Which preconditioner a [`BlockedSystem`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlockedKind {
    /// Block Jacobi on the aggregates.
    Jacobi,
    /// Additive block Jacobi on the aggregates and a staggered second partition,
    /// z = ½ (M₁⁻¹ r + M₂⁻¹ r), as [`super::block_jacobi::BlockJacobiPair`].
    JacobiPair,
    /// Symmetric block Gauss–Seidel in Eisenstat's form.
    GaussSeidel,
}

/// The second partition of the pair preconditioner, in the system's (first partition's)
/// numbering: aggregate a holds rows `rows[start[a]..start[a + 1]]`, which are not contiguous,
/// so its block solve gathers r into a work vector in this partition's order (`slot` maps a row
/// to its place there). Factors and envelopes are stored as the first partition's.
struct SecondPartition {
    rows: Vec<u32>,
    start: Vec<usize>,
    slot: Vec<u32>,
    factors: Vec<f32>,
    factor_start: Vec<usize>,
    first: Vec<u32>,
}

/// What the solve keeps of A besides the diagonal blocks' factors.
enum Operator {
    /// Block Jacobi: the whole of A, for the product A p.
    Whole(TemplateMatrix),
    /// Symmetric block Gauss–Seidel: only the couplings between aggregates (Eisenstat's form
    /// of the solve never multiplies by A itself) and the colour boundaries, colour k being
    /// aggregates `colours[k]..colours[k + 1]`.
    Split { off: OffBlock, order: SweepOrder },
}

/// The Gauss–Seidel order of the aggregates ([`colour_order`]): group g is aggregates
/// `groups[g]..groups[g + 1]`, colour k is groups `colours[k]..colours[k + 1]`.
struct SweepOrder {
    groups: Vec<usize>,
    colours: Vec<usize>,
}

/// A vector read in two pieces: entry c is `lo[c − lo_off]` below `split`, `hi[c − hi_off]`
/// from it on (a sweep reads its own group's rows and the other colours' rows from different
/// slices, since it writes the group's rows as it goes).
struct Pieces<'a> {
    lo: &'a [V4],
    lo_off: usize,
    split: usize,
    hi: &'a [V4],
    hi_off: usize,
}

impl Pieces<'_> {
    #[inline(always)]
    fn at(&self, c: usize) -> V4 {
        if c < self.split {
            self.lo[c - self.lo_off]
        } else {
            self.hi[c - self.hi_off]
        }
    }
}

/// A's entries between aggregates, by row (new numbering): row i's lower part (columns in
/// earlier aggregates) is entries `start[i]..mid[i]`, its upper part (later aggregates)
/// `mid[i]..start[i + 1]`. Each entry keeps the position of its value in the row's template
/// ([`TemplateMatrix`]), so the values still come from the small template table while each
/// sweep streams only its own part (6 B per entry).
struct OffBlock {
    start: Vec<usize>,
    mid: Vec<usize>,
    cols: Vec<u32>,
    pos: Vec<u16>,
    template: Vec<u32>,
    template_start: Vec<usize>,
    values: Vec<f64>,
    portable: bool,
}

impl OffBlock {
    /// The entries of `a` outside each row's aggregate (`agg_start` in `a`'s numbering), or
    /// `a` back when a row is too long for 16-bit positions.
    #[allow(clippy::result_large_err)]
    fn new(a: TemplateMatrix, agg_start: &[usize]) -> Result<Self, TemplateMatrix> {
        let n = a.nrows();
        if (0..n).any(|i| a.indptr[i + 1] - a.indptr[i] > usize::from(u16::MAX) + 1) {
            return Err(a);
        }
        // Per row its aggregate's range, then the sizes of its two parts.
        let mut range = vec![(0u32, 0u32); n];
        for w in agg_start.windows(2) {
            range[w[0]..w[1]].fill((w[0] as u32, w[1] as u32));
        }
        let counts: Vec<(usize, usize)> = (0..n)
            .into_par_iter()
            .with_min_len(ROW_CHUNK)
            .map(|i| {
                let (s, e) = range[i];
                let cols = &a.cols[a.indptr[i]..a.indptr[i + 1]];
                let lower = cols.iter().filter(|&&c| c < s).count();
                let upper = cols.iter().filter(|&&c| c >= e).count();
                (lower, upper)
            })
            .collect();
        let mut start = Vec::with_capacity(n + 1);
        let mut mid = Vec::with_capacity(n);
        start.push(0usize);
        for &(lower, upper) in &counts {
            let s = *start.last().unwrap();
            mid.push(s + lower);
            start.push(s + lower + upper);
        }
        drop(counts);
        let nnz = start[n];
        let mut cols = vec![0u32; nnz];
        let mut pos = vec![0u16; nnz];
        split_at_offsets(&mut cols, &start)
            .into_par_iter()
            .zip(split_at_offsets(&mut pos, &start))
            .enumerate()
            .with_min_len(256)
            .for_each(|(i, (cols, pos))| {
                let (s, e) = range[i];
                let row = &a.cols[a.indptr[i]..a.indptr[i + 1]];
                let mut k = 0;
                for pass in [true, false] {
                    for (j, &c) in row.iter().enumerate() {
                        if (pass && c < s) || (!pass && c >= e) {
                            cols[k] = c;
                            pos[k] = j as u16;
                            k += 1;
                        }
                    }
                }
            });
        Ok(OffBlock {
            start,
            mid,
            cols,
            pos,
            template: a.template,
            template_start: a.template_start,
            values: a.values,
            portable: a.portable,
        })
    }

    /// Row i's template values.
    #[inline(always)]
    fn values(&self, i: usize) -> &[f64] {
        let t = self.template[i] as usize;
        &self.values[self.template_start[t]..self.template_start[t + 1]]
    }

    /// Row i's lower part: (columns, value positions, template values).
    #[inline(always)]
    fn lower(&self, i: usize) -> (&[u32], &[u16], &[f64]) {
        let r = self.start[i]..self.mid[i];
        (&self.cols[r.clone()], &self.pos[r], self.values(i))
    }

    /// Row i's upper part.
    #[inline(always)]
    fn upper(&self, i: usize) -> (&[u32], &[u16], &[f64]) {
        let r = self.mid[i]..self.start[i + 1];
        (&self.cols[r.clone()], &self.pos[r], self.values(i))
    }
}

/// Per row of every aggregate's packed factor, its first non-zero column rounded down to even.
///
/// Cholesky keeps a matrix's envelope: a zero of the block before a row's first coupling stays
/// an exact (signed) zero in L, since each such entry is a zero minus products with zeros. The
/// triangular solves skip those entries, which changes no bit: their products with finite
/// values are signed zeros, and adding one to the forward solve's partial sums (which start at
/// +0, so are never −0) or subtracting one in the backward solve leaves a non-zero value as it
/// is and keeps a +0 at +0 (a −0 there would need r to be exactly −0 in that component). The
/// start is rounded to even so that each kept product still goes to the same one of the forward
/// solve's two partial sums.
fn envelope_starts<T: FactorValue>(
    start: &[usize],
    factors: &[T],
    factor_start: &[usize],
) -> Vec<u32> {
    let mut first = vec![0u32; *start.last().unwrap_or(&0)];
    for b in 0..start.len() - 1 {
        let l = &factors[factor_start[b]..factor_start[b + 1]];
        for i in 0..start[b + 1] - start[b] {
            let ri = i * (i + 1) / 2;
            let f = l[ri..ri + i]
                .iter()
                .position(|&v| v.widen() != 0.0)
                .unwrap_or(i);
            first[start[b] + i] = (f & !1) as u32;
        }
    }
    first
}

/// Runs `f` on the packed factor `l` widened to f64 (exactly) in a buffer of the calling
/// thread's: the kernels then read each factor entry from memory once per solve, at half the
/// bytes, and work in f64 from L1 (a 64-row block is 16.6 kB in f64).
#[inline]
fn widened<R>(l: &[f32], f: impl FnOnce(&[f64]) -> R) -> R {
    thread_local! {
        static BUFFER: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    BUFFER.with(|b| {
        let mut b = b.borrow_mut();
        b.clear();
        b.extend(l.iter().map(|&v| f64::from(v)));
        f(&b)
    })
}

/// One aggregate's step: x += α p, r −= α ap, z = (L Lᵀ)⁻¹ r; returns (rᵀz, rᵀr). Row i of
/// L is read from column `first[i]` on (the envelope, [`envelope_starts`]).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn block_step(
    l: &[f64],
    first: &[u32],
    alpha: V4,
    x: &mut [V4],
    r: &mut [V4],
    z: &mut [V4],
    p: &[V4],
    ap: &[V4],
) -> (V4, V4) {
    let m = x.len();
    let mut rr = [0.0; 4];
    for i in 0..m {
        for c in 0..4 {
            x[i][c] += alpha[c] * p[i][c];
            r[i][c] -= alpha[c] * ap[i][c];
            rr[c] += r[i][c] * r[i][c];
        }
    }
    // L y = r, row by row (two partial sums per row).
    for i in 0..m {
        let ri = i * (i + 1) / 2;
        let f = first[i] as usize;
        let (mut s0, mut s1) = ([0.0; 4], [0.0; 4]);
        let mut lk = l[ri + f..ri + i].chunks_exact(2);
        let mut zk = z[f..i].chunks_exact(2);
        for (lk, zk) in (&mut lk).zip(&mut zk) {
            for c in 0..4 {
                s0[c] += lk[0] * zk[0][c];
                s1[c] += lk[1] * zk[1][c];
            }
        }
        for (lk, zk) in lk.remainder().iter().zip(zk.remainder()) {
            for c in 0..4 {
                s0[c] += lk * zk[c];
            }
        }
        let d = l[ri + i];
        z[i] = std::array::from_fn(|c| (r[i][c] - (s0[c] + s1[c])) / d);
    }
    // Lᵀ z = y in place, column by column (independent updates).
    for i in (0..m).rev() {
        let ri = i * (i + 1) / 2;
        let d = l[ri + i];
        for c in 0..4 {
            z[i][c] /= d;
        }
        let zi = z[i];
        let f = first[i] as usize;
        for (zk, &lk) in z[f..i].iter_mut().zip(&l[ri + f..ri + i]) {
            for c in 0..4 {
                zk[c] -= lk * zi[c];
            }
        }
    }
    let mut rz = [0.0; 4];
    for (r, z) in r.iter().zip(z.iter()) {
        for c in 0..4 {
            rz[c] += r[c] * z[c];
        }
    }
    (rz, rr)
}

/// [`block_step`] in AVX2 registers ([`avx2`]): the same operations in the same order on
/// each lane, so the same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn block_step_avx2(
    l: &[f64],
    first: &[u32],
    alpha: V4,
    x: &mut [V4],
    r: &mut [V4],
    z: &mut [V4],
    p: &[V4],
    ap: &[V4],
) -> (V4, V4) {
    let rr = avx2::update(alpha, x, r, p, ap);
    z.copy_from_slice(r);
    avx2::forward::<true>(l, first, z);
    avx2::backward(l, first, z);
    (avx2::dot(r, z), rr)
}

/// One aggregate of the second partition: y = (L Lᵀ)⁻¹ r gathered at `rows`; returns rᵀy.
#[inline(always)]
fn pair_block(l: &[f64], first: &[u32], rows: &[u32], r: &[V4], y: &mut [V4]) -> V4 {
    gather(rows, r, y);
    block_solve(l, first, y);
    gathered_dot(rows, r, y)
}

/// `y` = `r` at `rows` (a second-partition aggregate's right-hand side).
#[inline(always)]
fn gather(rows: &[u32], r: &[V4], y: &mut [V4]) {
    for (y, &i) in y.iter_mut().zip(rows) {
        *y = r[i as usize];
    }
}

/// Σ r[rows[k]] · y[k] per component (rᵀy of a second-partition aggregate).
#[inline(always)]
fn gathered_dot(rows: &[u32], r: &[V4], y: &[V4]) -> V4 {
    let mut rz = [0.0; 4];
    for (y, &i) in y.iter().zip(rows) {
        let r = r[i as usize];
        for c in 0..4 {
            rz[c] += r[c] * y[c];
        }
    }
    rz
}

/// [`pair_block`] in AVX2 registers ([`avx2`]; the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn pair_block_avx2(l: &[f64], first: &[u32], rows: &[u32], r: &[V4], y: &mut [V4]) -> V4 {
    gather(rows, r, y);
    avx2::forward::<false>(l, first, y);
    avx2::backward(l, first, y);
    gathered_dot(rows, r, y)
}

/// The block kernels' loops written in AVX2 registers, one 256-bit operation per vector entry
/// (compiled from the portable loops, the triangular solves' updates were vectorised across
/// entries with shuffles), and the forward substitution four rows at a time.
///
/// Every lane sees the IEEE multiplications, additions and divisions of the portable kernels
/// in the same order (no FMA), so the results are the same bits:
/// * the forward substitution of rows i0..i0 + 4 runs their dot products' common part (the
///   columns before i0) as four independent chains, then finishes the rows in order, each
///   taking its remaining columns in increasing order: every row's sum is still accumulated
///   column by column in increasing order, into the same partial sum (`TWO`: even columns
///   into one, odd into the other, as [`block_step`]'s pairs from its even envelope start).
///   The common part starts at the group's smallest envelope start: a row whose own start is
///   later adds products with the exact zeros before it, which leave a +0 partial sum +0 (as
///   `envelope_starts` argues);
/// * the backward substitution applies columns i and i − 1 in one pass over the entries below
///   them, column i's update first, each over its own envelope (no zero products: those could
///   turn a −0 entry into +0).
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::V4;
    use std::arch::x86_64::*;

    #[inline]
    #[target_feature(enable = "avx2")]
    fn ld(v: &V4) -> __m256d {
        // SAFETY: a V4 is four contiguous f64 (unaligned load).
        unsafe { _mm256_loadu_pd(v.as_ptr()) }
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    fn st(v: &mut V4, x: __m256d) {
        // SAFETY: a V4 is four contiguous f64 (unaligned store).
        unsafe { _mm256_storeu_pd(v.as_mut_ptr(), x) }
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    fn lanes(x: __m256d) -> V4 {
        let mut v = [0.0; 4];
        st(&mut v, x);
        v
    }

    /// x += α p, r −= α ap entry by entry; returns rᵀr (per lane, in entry order).
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn update(alpha: V4, x: &mut [V4], r: &mut [V4], p: &[V4], ap: &[V4]) -> V4 {
        let a = ld(&alpha);
        let mut rr = _mm256_setzero_pd();
        for (((x, r), p), ap) in x.iter_mut().zip(r.iter_mut()).zip(p).zip(ap) {
            st(x, _mm256_add_pd(ld(x), _mm256_mul_pd(a, ld(p))));
            let rn = _mm256_sub_pd(ld(r), _mm256_mul_pd(a, ld(ap)));
            st(r, rn);
            rr = _mm256_add_pd(rr, _mm256_mul_pd(rn, rn));
        }
        lanes(rr)
    }

    /// Σ_i a_i b_i per lane, in entry order.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn dot(a: &[V4], b: &[V4]) -> V4 {
        let mut s = _mm256_setzero_pd();
        for (a, b) in a.iter().zip(b) {
            s = _mm256_add_pd(s, _mm256_mul_pd(ld(a), ld(b)));
        }
        lanes(s)
    }

    /// y = L⁻¹ y in place for one aggregate's packed factor (row i from column `first[i]`):
    /// one partial sum per row ([`super::block_solve`]) or, `TWO`, one for the even and one
    /// for the odd columns ([`super::block_step`]).
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn forward<const TWO: bool>(l: &[f64], first: &[u32], y: &mut [V4]) {
        let m = y.len();
        let tri = |i: usize| i * (i + 1) / 2;
        let mut i0 = 0;
        while i0 < m {
            let g = (m - i0).min(4);
            let mut s0 = [_mm256_setzero_pd(); 4];
            let mut s1 = [_mm256_setzero_pd(); 4];
            let ri: [usize; 4] = std::array::from_fn(|j| tri(i0 + j.min(g - 1)));
            // The columns before i0, common to the group's rows.
            let mut k = (0..g).map(|j| first[i0 + j]).min().unwrap_or(0) as usize;
            if g == 4 {
                if TWO {
                    while k + 1 < i0 {
                        let (y0, y1) = (ld(&y[k]), ld(&y[k + 1]));
                        for j in 0..4 {
                            let l0 = _mm256_set1_pd(l[ri[j] + k]);
                            let l1 = _mm256_set1_pd(l[ri[j] + k + 1]);
                            s0[j] = _mm256_add_pd(s0[j], _mm256_mul_pd(l0, y0));
                            s1[j] = _mm256_add_pd(s1[j], _mm256_mul_pd(l1, y1));
                        }
                        k += 2;
                    }
                } else {
                    while k < i0 {
                        let yk = ld(&y[k]);
                        for j in 0..4 {
                            let lk = _mm256_set1_pd(l[ri[j] + k]);
                            s0[j] = _mm256_add_pd(s0[j], _mm256_mul_pd(lk, yk));
                        }
                        k += 1;
                    }
                }
            }
            // The rest of each row, row by row (a short group starts at its own rows'
            // envelopes).
            for j in 0..g {
                let i = i0 + j;
                let from = if g == 4 { k } else { first[i] as usize };
                for c in from..i {
                    let t = _mm256_mul_pd(_mm256_set1_pd(l[ri[j] + c]), ld(&y[c]));
                    if TWO && c & 1 == 1 {
                        s1[j] = _mm256_add_pd(s1[j], t);
                    } else {
                        s0[j] = _mm256_add_pd(s0[j], t);
                    }
                }
                let acc = if TWO {
                    _mm256_add_pd(s0[j], s1[j])
                } else {
                    s0[j]
                };
                let d = _mm256_set1_pd(l[ri[j] + i]);
                let v = _mm256_div_pd(_mm256_sub_pd(ld(&y[i]), acc), d);
                st(&mut y[i], v);
            }
            i0 += g;
        }
    }

    /// y = L⁻ᵀ y in place, columns from the last ([`super::block_solve`]'s second half).
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn backward(l: &[f64], first: &[u32], y: &mut [V4]) {
        let tri = |i: usize| i * (i + 1) / 2;
        let mut i = y.len();
        while i >= 2 {
            // Columns i1 = i − 1 and i2 = i − 2.
            let (i1, i2) = (i - 1, i - 2);
            let (r1, r2) = (tri(i1), tri(i2));
            let (f1, f2) = (first[i1] as usize, first[i2] as usize);
            let z1 = _mm256_div_pd(ld(&y[i1]), _mm256_set1_pd(l[r1 + i1]));
            st(&mut y[i1], z1);
            if f1 <= i2 {
                let t = _mm256_mul_pd(_mm256_set1_pd(l[r1 + i2]), z1);
                let v = _mm256_sub_pd(ld(&y[i2]), t);
                st(&mut y[i2], v);
            }
            let z2 = _mm256_div_pd(ld(&y[i2]), _mm256_set1_pd(l[r2 + i2]));
            st(&mut y[i2], z2);
            let both = f1.max(f2).min(i2);
            for k in f1.min(both)..both {
                let v = _mm256_sub_pd(ld(&y[k]), _mm256_mul_pd(_mm256_set1_pd(l[r1 + k]), z1));
                st(&mut y[k], v);
            }
            for k in f2.min(both)..both {
                let v = _mm256_sub_pd(ld(&y[k]), _mm256_mul_pd(_mm256_set1_pd(l[r2 + k]), z2));
                st(&mut y[k], v);
            }
            for k in both..i2 {
                let t1 = _mm256_mul_pd(_mm256_set1_pd(l[r1 + k]), z1);
                let v = _mm256_sub_pd(ld(&y[k]), t1);
                let t2 = _mm256_mul_pd(_mm256_set1_pd(l[r2 + k]), z2);
                st(&mut y[k], _mm256_sub_pd(v, t2));
            }
            i -= 2;
        }
        if i == 1 {
            let v = _mm256_div_pd(ld(&y[0]), _mm256_set1_pd(l[0]));
            st(&mut y[0], v);
        }
    }
}

/// Σ_k vals[pos[k]] x[cols[k]] over one part of a row (two partial sums), x read by `at`.
#[inline(always)]
fn part_dot(cols: &[u32], pos: &[u16], vals: &[f64], at: impl Fn(usize) -> V4) -> V4 {
    let mut s = [[0.0; 4]; 2];
    let mut ci = cols.chunks_exact(2);
    let mut pi = pos.chunks_exact(2);
    for (c, p) in (&mut ci).zip(&mut pi) {
        for l in 0..2 {
            let v = vals[p[l] as usize];
            let xc = at(c[l] as usize);
            for d in 0..4 {
                s[l][d] += v * xc[d];
            }
        }
    }
    for (&c, &p) in ci.remainder().iter().zip(pi.remainder()) {
        let v = vals[p as usize];
        let xc = at(c as usize);
        for d in 0..4 {
            s[0][d] += v * xc[d];
        }
    }
    std::array::from_fn(|d| s[0][d] + s[1][d])
}

/// [`part_dot`] of one part of a row with two vectors at once (one pass over the entries).
#[inline(always)]
fn part_dot2(cols: &[u32], pos: &[u16], vals: &[f64], x: &Pieces, y: &[V4]) -> (V4, V4) {
    let (mut sx, mut sy) = ([0.0; 4], [0.0; 4]);
    for (&c, &p) in cols.iter().zip(pos) {
        let v = vals[p as usize];
        let (xc, yc) = (x.at(c as usize), y[c as usize]);
        for d in 0..4 {
            sx[d] += v * xc[d];
            sy[d] += v * yc[d];
        }
    }
    (sx, sy)
}

/// y = (L Lᵀ)⁻¹ y in place for one aggregate's packed factor L (row i read from column
/// `first[i]` on).
#[inline(always)]
fn block_solve(l: &[f64], first: &[u32], y: &mut [V4]) {
    let m = y.len();
    for i in 0..m {
        let ri = i * (i + 1) / 2;
        let f = first[i] as usize;
        let mut acc = [0.0; 4];
        for (lk, yk) in l[ri + f..ri + i].iter().zip(&y[f..i]) {
            for c in 0..4 {
                acc[c] += lk * yk[c];
            }
        }
        let d = l[ri + i];
        y[i] = std::array::from_fn(|c| (y[i][c] - acc[c]) / d);
    }
    for i in (0..m).rev() {
        let ri = i * (i + 1) / 2;
        let d = l[ri + i];
        for c in 0..4 {
            y[i][c] /= d;
        }
        let yi = y[i];
        let f = first[i] as usize;
        for k in f..i {
            let lk = l[ri + k];
            for c in 0..4 {
                y[k][c] -= lk * yi[c];
            }
        }
    }
}

/// z = L Lᵀ r for one aggregate's packed factor; returns rᵀz = ‖Lᵀ r‖² (a sum of squares,
/// so never negative).
#[inline(always)]
fn block_multiply(l: &[f64], first: &[u32], r: &[V4], z: &mut [V4]) -> V4 {
    let m = r.len();
    // s = Lᵀ r, row by row of L (s_k gathers L_ik r_i over i ≥ k).
    z.fill([0.0; 4]);
    for i in 0..m {
        let ri = i * (i + 1) / 2;
        let f = first[i] as usize;
        let r_i = r[i];
        for (zk, &lk) in z[f..=i].iter_mut().zip(&l[ri + f..=ri + i]) {
            for c in 0..4 {
                zk[c] += lk * r_i[c];
            }
        }
    }
    let mut rz = [0.0; 4];
    for s in z.iter() {
        for c in 0..4 {
            rz[c] += s[c] * s[c];
        }
    }
    // z = L s in place, last row first (row i reads s_k for k ≤ i only).
    for i in (0..m).rev() {
        let ri = i * (i + 1) / 2;
        let f = first[i] as usize;
        let mut acc = [0.0; 4];
        for (lk, sk) in l[ri + f..=ri + i].iter().zip(&z[f..=i]) {
            for c in 0..4 {
                acc[c] += lk * sk[c];
            }
        }
        z[i] = acc;
    }
    rz
}

/// One aggregate (rows from `s`) of the backward sweep t = (D + U)⁻¹ p: u_a = Σ_{b>a} A_ab t_b
/// from the later aggregates' t (`later`), then t_a = D_a⁻¹ (p_a − u_a).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn backward_block(
    a: &OffBlock,
    l: &[f64],
    first: &[u32],
    s: usize,
    p: &[V4],
    later: &Pieces,
    t: &mut [V4],
    u: &mut [V4],
) {
    for i in 0..t.len() {
        let (cols, pos, vals) = a.upper(s + i);
        let ui = part_dot(cols, pos, vals, |c| later.at(c));
        u[i] = ui;
        t[i] = std::array::from_fn(|c| p[i][c] - ui[c]);
    }
    block_solve(l, first, t);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn backward_block_avx2(
    a: &OffBlock,
    l: &[f64],
    first: &[u32],
    s: usize,
    p: &[V4],
    later: &Pieces,
    t: &mut [V4],
    u: &mut [V4],
) {
    backward_block(a, l, first, s, p, later, t, u)
}

/// One aggregate of the forward sweep v = (D + L)⁻¹ u in place (`v` holds u_a on entry;
/// `earlier` is v before the aggregate), with w_a = Σ_{b<a} A_ab t_b from the same pass over
/// the entries.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn forward_block(
    a: &OffBlock,
    l: &[f64],
    first: &[u32],
    s: usize,
    earlier: &Pieces,
    t: &[V4],
    v: &mut [V4],
    w: &mut [V4],
) {
    for i in 0..v.len() {
        let (cols, pos, vals) = a.lower(s + i);
        let (lv, lt) = part_dot2(cols, pos, vals, earlier, t);
        v[i] = std::array::from_fn(|c| v[i][c] - lv[c]);
        w[i] = lt;
    }
    block_solve(l, first, v);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn forward_block_avx2(
    a: &OffBlock,
    l: &[f64],
    first: &[u32],
    s: usize,
    earlier: &Pieces,
    t: &[V4],
    v: &mut [V4],
    w: &mut [V4],
) {
    forward_block(a, l, first, s, earlier, t, v, w)
}

/// The vectors of the Eisenstat-form CG (see [`BlockedSystem::symmetric_gauss_seidel`]), all
/// in the system's numbering: x and the true residual r = b − A x; r̃ = (D + L)⁻¹ r and
/// z̃ = D r̃; the search direction p̃ (p = t = (D + U)⁻¹ p̃ in A's variables); u/v the sweeps'
/// work vector, ending as v = (D + L)⁻¹ U t; w = L t.
struct Eisenstat {
    x: Vec<V4>,
    r: Vec<V4>,
    rt: Vec<V4>,
    zt: Vec<V4>,
    p: Vec<V4>,
    t: Vec<V4>,
    v: Vec<V4>,
    w: Vec<V4>,
}

/// One aggregate's update: x += α t, r −= α A t (A t = p̃ + L t), r̃ −= α (t + v) (that is
/// α Ã p̃), then z̃ = D r̃; returns (r̃ᵀz̃, rᵀr).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn eisenstat_update(
    l: &[f64],
    first: &[u32],
    alpha: V4,
    x: &mut [V4],
    r: &mut [V4],
    rt: &mut [V4],
    zt: &mut [V4],
    p: &[V4],
    t: &[V4],
    v: &[V4],
    w: &[V4],
) -> (V4, V4) {
    let mut rr = [0.0; 4];
    for i in 0..x.len() {
        for c in 0..4 {
            x[i][c] += alpha[c] * t[i][c];
            r[i][c] -= alpha[c] * (p[i][c] + w[i][c]);
            rr[c] += r[i][c] * r[i][c];
            rt[i][c] -= alpha[c] * (t[i][c] + v[i][c]);
        }
    }
    (block_multiply(l, first, rt, zt), rr)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn eisenstat_update_avx2(
    l: &[f64],
    first: &[u32],
    alpha: V4,
    x: &mut [V4],
    r: &mut [V4],
    rt: &mut [V4],
    zt: &mut [V4],
    p: &[V4],
    t: &[V4],
    v: &[V4],
    w: &[V4],
) -> (V4, V4) {
    eisenstat_update(l, first, alpha, x, r, rt, zt, p, t, v, w)
}

/// Domains of the Gauss–Seidel ordering (the aggregates' colour order): a fixed number, so that the
/// order (and every bit of the solve) does not depend on the thread count.
pub const SWEEP_DOMAINS: usize = 16;

/// The aggregates renumbered for the Gauss–Seidel sweeps, with the group and colour boundaries.
///
/// The aggregates, in the order of the breadth-first aggregation (neighbours in it are near in
/// space and in memory), are cut into `domains` consecutive ranges. An aggregate coupled in A
/// only to aggregates of its own range is interior; the others are separators. Colour 0 holds
/// one group per domain, its interior aggregates in order: the domains do not couple, so a
/// sweep runs them in parallel, each in order, reading neighbours that are near in memory and
/// mostly already updated. The separators follow, one group each, coloured greedily (each the
/// smallest colour from 1 not taken by an already coloured coupled separator), so that one
/// colour's separators do not couple. (Colouring every aggregate instead scatters each
/// aggregate's neighbours over the other colours, and the sweeps wait on memory.) Returns
/// (aggregates, groups, colours): group g is aggregates `groups[g]..groups[g + 1]`, colour k
/// is groups `colours[k]..colours[k + 1]`. Sequential, so independent of the thread count.
pub(crate) fn colour_order(
    agg: Aggregates,
    indptr: &[usize],
    indices: &[u32],
    domains: usize,
) -> (Aggregates, Vec<usize>, Vec<usize>) {
    let na = agg.start.len() - 1;
    let domains = domains.clamp(1, na.max(1));
    let n = agg.rows.len();
    let mut agg_of = vec![0u32; n];
    for a in 0..na {
        for &r in &agg.rows[agg.start[a]..agg.start[a + 1]] {
            agg_of[r as usize] = a as u32;
        }
    }
    let domain = |a: usize| a * domains / na.max(1);
    let neighbours = |a: usize| {
        agg.rows[agg.start[a]..agg.start[a + 1]]
            .iter()
            .flat_map(|&r| &indices[indptr[r as usize]..indptr[r as usize + 1]])
            .map(|&c| agg_of[c as usize] as usize)
    };
    let separator: Vec<bool> = (0..na)
        .map(|a| neighbours(a).any(|b| domain(b) != domain(a)))
        .collect();
    const NONE: u32 = u32::MAX;
    let mut colour = vec![NONE; na];
    // used[k] == a: colour k is taken by a separator coupled to separator a.
    let mut used: Vec<usize> = Vec::new();
    for a in (0..na).filter(|&a| separator[a]) {
        for b in neighbours(a) {
            let k = colour[b];
            if k != NONE {
                let k = k as usize;
                if used.len() <= k {
                    used.resize(k + 1, usize::MAX);
                }
                used[k] = a;
            }
        }
        let k = (1..).find(|&k| k >= used.len() || used[k] != a).unwrap();
        colour[a] = k as u32;
    }
    let nc = colour
        .iter()
        .filter(|&&k| k != NONE)
        .map(|&k| k as usize + 1)
        .max()
        .unwrap_or(0)
        .max(1);
    // The order: the domains' interiors, then the separators by colour.
    let mut order: Vec<usize> = (0..na).filter(|&a| !separator[a]).collect();
    let mut groups = vec![0usize];
    let mut d_end = 0;
    for d in 0..domains {
        while d_end < order.len() && domain(order[d_end]) == d {
            d_end += 1;
        }
        groups.push(d_end);
    }
    let mut colours = vec![0usize, domains];
    for k in 1..nc {
        for a in (0..na).filter(|&a| colour[a] == k as u32) {
            order.push(a);
            groups.push(order.len());
        }
        colours.push(groups.len() - 1);
    }
    let mut rows = Vec::with_capacity(n);
    let mut start = Vec::with_capacity(na + 1);
    start.push(0usize);
    for &a in &order {
        rows.extend_from_slice(&agg.rows[agg.start[a]..agg.start[a + 1]]);
        start.push(rows.len());
    }
    let mut slot = vec![0u32; n];
    for (k, &r) in rows.iter().enumerate() {
        slot[r as usize] = k as u32;
    }
    (Aggregates { rows, start, slot }, groups, colours)
}

impl SecondPartition {
    /// The aggregates `agg2` (old numbering) of the reordered A (`a`, numbered by `agg`),
    /// factored as `BlockJacobi::on` factors them: each block entry is one value of A added
    /// to zero, so the factors are the same bits.
    fn new(a: &TemplateMatrix, agg: &Aggregates, agg2: Aggregates) -> Result<Self, CgError> {
        let Aggregates { rows, start, .. } = agg2;
        let rows: Vec<u32> = rows.iter().map(|&r| agg.slot[r as usize]).collect();
        let mut slot = vec![0u32; rows.len()];
        for (k, &i) in rows.iter().enumerate() {
            slot[i as usize] = k as u32;
        }
        let old_rows: Vec<u32> = rows.iter().map(|&i| agg.rows[i as usize]).collect();
        let (factors, factor_start) = factor_blocks(&start, &old_rows, |b, l| {
            let s = start[b];
            for (ii, &i) in rows[s..start[b + 1]].iter().enumerate() {
                let ri = ii * (ii + 1) / 2;
                a.for_each_entry(i as usize, |c, v| {
                    let j = slot[c] as usize;
                    if (s..=s + ii).contains(&j) {
                        l[ri + j - s] += v;
                    }
                });
            }
        })?;
        let first = envelope_starts(&start, &factors, &factor_start);
        Ok(SecondPartition {
            rows,
            start,
            slot,
            factors,
            factor_start,
            first,
        })
    }

    /// y = M₂⁻¹ r in this partition's order (`y[k]` for row `rows[k]`); returns rᵀy summed in
    /// aggregate order.
    fn solve(&self, portable: bool, r: &[V4], y: &mut [V4]) -> V4 {
        let partials: Vec<V4> = split_at_offsets(y, &self.start)
            .into_par_iter()
            .enumerate()
            .map(|(b, y)| {
                let e = s_end(&self.start, b);
                let l = &self.factors[self.factor_start[b]..self.factor_start[b + 1]];
                let (first, rows) = (&self.first[e.clone()], &self.rows[e]);
                widened(l, |l| {
                    dispatch!(portable, pair_block_avx2, pair_block(l, first, rows, r, y))
                })
            })
            .collect();
        sum(&partials)
    }
}

impl BlockedSystem {
    /// Aggregate A (CSR) into blocks of at most `size` rows, reorder and factor.
    pub fn new(
        indptr: &[usize],
        indices: &[u32],
        data: &[f64],
        size: usize,
    ) -> Result<Self, CgError> {
        Self::with_kind(indptr, indices, data, size, BlockedKind::Jacobi)
    }

    /// [`Self::new`], the pair ([`BlockedKind::JacobiPair`]: the second partition is
    /// `Aggregates::reversed`'s, factored from the same values, so M is
    /// [`super::block_jacobi::BlockJacobiPair`]'s, its factors bit for bit) or
    /// [`Self::symmetric_gauss_seidel`], by `kind`.
    pub fn with_kind(
        indptr: &[usize],
        indices: &[u32],
        data: &[f64],
        size: usize,
        kind: BlockedKind,
    ) -> Result<Self, CgError> {
        Self::build(
            indptr,
            Cow::Borrowed(indices),
            Values::Csr(Cow::Borrowed(data)),
            size,
            kind,
        )
    }

    /// [`Self::with_kind`] consuming A's CSR
    /// arrays: the values are released once the row templates hold them and the columns once
    /// renumbered, so the solve does not keep A twice (at 1M hexes the CSR arrays are 1.5 GB,
    /// the reordered matrix 0.5 GB). Same system, same bits.
    pub fn from_parts(
        indptr: Vec<usize>,
        indices: Vec<u32>,
        data: Vec<f64>,
        size: usize,
        kind: BlockedKind,
    ) -> Result<Self, CgError> {
        Self::build(
            &indptr,
            Cow::Owned(indices),
            Values::Csr(Cow::Owned(data)),
            size,
            kind,
        )
    }

    /// [`Self::from_parts`] for a matrix whose rows are stored by template (row r's values
    /// are template `row_template[r]` of `table`, as the fit's assembly makes them): the
    /// values are never expanded into a CSR value array. Same system, same bits.
    pub(crate) fn from_templates(
        indptr: Vec<usize>,
        indices: Vec<u32>,
        row_template: Vec<u32>,
        table: RowTemplates,
        size: usize,
        kind: BlockedKind,
    ) -> Result<Self, CgError> {
        Self::build(
            &indptr,
            Cow::Owned(indices),
            Values::Templates(row_template, table),
            size,
            kind,
        )
    }

    /// [`Self::new`] with the aggregates ordered by colour, for the symmetric block
    /// Gauss–Seidel preconditioner M = (D + L) D⁻¹ (D + U) (D the aggregates' diagonal blocks,
    /// L and U the couplings to earlier and later aggregates). Aggregates of one colour do not
    /// couple, so each colour's block solves run in parallel and the result does not depend on
    /// the thread count.
    ///
    /// Unlike block Jacobi, every sweep uses the latest values of the aggregates' neighbours,
    /// which carries corrections across aggregate boundaries: on the fit's normal matrices,
    /// whose smallest eigenvalues belong to element-scale oscillations seen only by the lightly
    /// weighted midpoint samples, it needs about 40 % of block Jacobi's iterations.
    ///
    /// The solve runs CG in Eisenstat's form: on Ã = (D + L)⁻¹ A (D + U)⁻¹ (symmetric, since
    /// (D + L)ᵀ = D + U) with the preconditioner z̃ = D r̃, which gives the iterates of CG on A
    /// with M (same α, β and x in exact arithmetic) while Ã p̃ = t + (D + L)⁻¹ U t with
    /// t = (D + U)⁻¹ p̃ takes one backward and one forward sweep and no product with A: each
    /// coupling between aggregates is read once per iteration (the product A p and two
    /// Gauss–Seidel sweeps would read it three times). The true residual r = b − A x is
    /// carried along (A t = p̃ + L t, L t taken in the forward sweep's pass), so the stopping
    /// rule is [`super::pcg`]'s. A row longer than 65,536 entries (never seen in a fit) makes
    /// this a block-Jacobi system.
    pub fn symmetric_gauss_seidel(
        indptr: &[usize],
        indices: &[u32],
        data: &[f64],
        size: usize,
    ) -> Result<Self, CgError> {
        Self::with_kind(indptr, indices, data, size, BlockedKind::GaussSeidel)
    }

    fn build(
        indptr: &[usize],
        indices: Cow<[u32]>,
        values: Values,
        size: usize,
        kind: BlockedKind,
    ) -> Result<Self, CgError> {
        let agg = Aggregates::new(indptr, &indices, size);
        // The second partition is grown on A's graph before the columns are renumbered.
        let agg2 =
            (kind == BlockedKind::JacobiPair).then(|| Aggregates::reversed(indptr, &indices, size));
        let (agg, order) = if kind == BlockedKind::GaussSeidel {
            let (agg, groups, colours) = colour_order(agg, indptr, &indices, SWEEP_DOMAINS);
            (agg, Some(SweepOrder { groups, colours }))
        } else {
            (agg, None)
        };
        // Gauss–Seidel's operator keeps only the couplings between aggregates, from 32-bit
        // columns; block Jacobi and the pair multiply by the whole of A, from packed ones.
        let pack = order.is_none();
        let a = match values {
            Values::Csr(data) => TemplateMatrix::with_hash(
                indptr, indices, data, &agg.rows, &agg.slot, hash_row, pack,
            ),
            Values::Templates(row_template, table) => TemplateMatrix::from_templates(
                indptr,
                indices,
                &row_template,
                table,
                &agg.rows,
                &agg.slot,
                pack,
            ),
        };
        let start = &agg.start;
        let fill = |b: usize, l: &mut [f64]| {
            let s = start[b];
            for i in s..start[b + 1] {
                let ri = (i - s) * (i - s + 1) / 2;
                a.for_each_entry(i, |c, v| {
                    if (s..=i).contains(&c) {
                        l[ri + c - s] += v;
                    }
                });
            }
        };
        let (factors, factor_start, first) = if order.is_some() {
            let (f, fs) = factor_blocks::<f64>(start, &agg.rows, fill)?;
            let first = envelope_starts(start, &f, &fs);
            (Factors::Double(f), fs, first)
        } else {
            let (f, fs) = factor_blocks::<f32>(start, &agg.rows, fill)?;
            let first = envelope_starts(start, &f, &fs);
            (Factors::Single(f), fs, first)
        };
        let second = match agg2 {
            Some(agg2) => Some(SecondPartition::new(&a, &agg, agg2)?),
            None => None,
        };
        let op = match order {
            Some(order) => match OffBlock::new(a, start) {
                Ok(off) => Operator::Split { off, order },
                Err(a) => Operator::Whole(a),
            },
            None => Operator::Whole(a),
        };
        Ok(BlockedSystem {
            agg,
            op,
            factors,
            factor_start,
            first,
            second,
            lines: None,
        })
    }

    /// This block-Jacobi system (or pair) with the line blocks of `lines` (unknowns in A's
    /// numbering) added to its preconditioner: z = M⁻¹ r + Σ_l R_lᵀ K_l⁻¹ R_l r
    /// ([`super::lines`]). A Gauss–Seidel system is returned as it is.
    pub fn with_lines(mut self, lines: &Lines) -> Result<Self, CgError> {
        let Operator::Whole(a) = &self.op else {
            return Ok(self);
        };
        let slot = &self.agg.slot;
        let renamed = Lines {
            points: lines.points.iter().map(|&p| slot[p as usize]).collect(),
            start: lines.start.clone(),
            ring: lines.ring.clone(),
        };
        let n = self.agg.rows.len();
        let blocks = LineBlocks::new(n, &renamed, |i, f| a.for_each_entry(i, f))?;
        let (share_start, share_at) = blocks.shares(n);
        self.lines = Some(LineSystem {
            blocks,
            share_start,
            share_at,
        });
        Ok(self)
    }

    /// Number of line segments in the preconditioner ([`Self::with_lines`]; 0 without).
    pub fn n_line_blocks(&self) -> usize {
        self.lines.as_ref().map_or(0, |l| l.blocks.len())
    }

    /// The group and colour boundaries of the symmetric block Gauss–Seidel preconditioner
    /// (group g is aggregates `groups[g]..groups[g + 1]`, colour k is groups
    /// `colours[k]..colours[k + 1]`; see the colour order of the aggregates), `None` for block Jacobi.
    pub fn sweep_order(&self) -> Option<(&[usize], &[usize])> {
        match &self.op {
            Operator::Split { order, .. } => Some((&order.groups, &order.colours)),
            Operator::Whole(_) => None,
        }
    }

    /// The aggregate boundaries (new numbering: aggregate a is rows `start[a]..start[a + 1]`).
    pub fn aggregate_starts(&self) -> &[usize] {
        &self.agg.start
    }

    /// New row i is old row `rows()[i]`.
    pub fn rows(&self) -> &[u32] {
        &self.agg.rows
    }

    /// `f` on aggregate b's packed factor (in f64) and envelope starts.
    #[inline]
    fn with_factor<R>(&self, b: usize, f: impl FnOnce(&[f64], &[u32]) -> R) -> R {
        let (start, e) = (
            &self.agg.start,
            self.factor_start[b]..self.factor_start[b + 1],
        );
        let first = &self.first[start[b]..start[b + 1]];
        match &self.factors {
            Factors::Single(l) => widened(&l[e], |l| f(l, first)),
            Factors::Double(l) => f(&l[e], first),
        }
    }

    /// Colour k's rows `s0..s1` and the offsets of its groups from s0: (offsets, s0, s1).
    fn colour_rows(&self, order: &SweepOrder, k: usize) -> (Vec<usize>, usize, usize) {
        let start = &self.agg.start;
        let row = |g: usize| start[order.groups[g]];
        let (g0, g1) = (order.colours[k], order.colours[k + 1]);
        let s0 = row(g0);
        let offsets = (g0..=g1).map(|g| row(g) - s0).collect();
        (offsets, s0, row(g1))
    }

    /// t = (D + U)⁻¹ p̃, colour by colour from the last, each group's aggregates from the
    /// last; `u` gets U t. With `update` (β, z̃), p̃ = z̃ + β p̃ is formed first, aggregate by
    /// aggregate (fused into the sweep).
    fn backward(
        &self,
        off: &OffBlock,
        order: &SweepOrder,
        update: Option<(V4, &[V4])>,
        p: &mut [V4],
        t: &mut [V4],
        u: &mut [V4],
    ) {
        let start = &self.agg.start;
        for k in (0..order.colours.len() - 1).rev() {
            let (offsets, s0, s1) = self.colour_rows(order, k);
            let (t_head, tail) = t.split_at_mut(s1);
            let tail: &[V4] = tail;
            split_at_offsets(&mut t_head[s0..], &offsets)
                .into_par_iter()
                .zip(split_at_offsets(&mut u[s0..s1], &offsets))
                .zip(split_at_offsets(&mut p[s0..s1], &offsets))
                .enumerate()
                .for_each(|(j, ((tg, ug), pg))| {
                    let g = order.colours[k] + j;
                    let sg = start[order.groups[g]];
                    for b in (order.groups[g]..order.groups[g + 1]).rev() {
                        let (s, e) = (start[b], start[b + 1]);
                        let p = &mut pg[s - sg..e - sg];
                        if let Some((beta, zt)) = update {
                            for (p, z) in p.iter_mut().zip(&zt[s..e]) {
                                for c in 0..4 {
                                    p[c] = z[c] + beta[c] * p[c];
                                }
                            }
                        }
                        let (tb, after) = tg.split_at_mut(e - sg);
                        let later = Pieces {
                            lo: after,
                            lo_off: e,
                            split: e + after.len(),
                            hi: tail,
                            hi_off: s1,
                        };
                        let (t, u) = (&mut tb[s - sg..], &mut ug[s - sg..e - sg]);
                        self.with_factor(b, |l, first| {
                            dispatch!(
                                off.portable,
                                backward_block_avx2,
                                backward_block(off, l, first, s, p, &later, t, u)
                            )
                        })
                    }
                });
        }
    }

    /// v = (D + L)⁻¹ v in place, colour by colour from the first, each group's aggregates in
    /// order, and w = L t; returns Σ p̃ᵀ(t + v) (that is p̃ᵀÃp̃ after [`Self::backward`]) as a
    /// sum of per-group sums in order.
    fn forward(
        &self,
        off: &OffBlock,
        order: &SweepOrder,
        t: &[V4],
        p: &[V4],
        v: &mut [V4],
        w: &mut [V4],
    ) -> V4 {
        let start = &self.agg.start;
        let mut partials: Vec<V4> = Vec::with_capacity(order.groups.len());
        for k in 0..order.colours.len() - 1 {
            let (offsets, s0, s1) = self.colour_rows(order, k);
            let (head, rest) = v.split_at_mut(s0);
            let head: &[V4] = head;
            let part: Vec<V4> = split_at_offsets(&mut rest[..s1 - s0], &offsets)
                .into_par_iter()
                .zip(split_at_offsets(&mut w[s0..s1], &offsets))
                .enumerate()
                .map(|(j, (vg, wg))| {
                    let g = order.colours[k] + j;
                    let sg = start[order.groups[g]];
                    let mut pq = [0.0; 4];
                    for b in order.groups[g]..order.groups[g + 1] {
                        let (s, e) = (start[b], start[b + 1]);
                        let (before, vb) = vg.split_at_mut(s - sg);
                        let earlier = Pieces {
                            lo: head,
                            lo_off: 0,
                            split: sg,
                            hi: before,
                            hi_off: sg,
                        };
                        let (v, w) = (&mut vb[..e - s], &mut wg[s - sg..e - sg]);
                        self.with_factor(b, |l, first| {
                            dispatch!(
                                off.portable,
                                forward_block_avx2,
                                forward_block(off, l, first, s, &earlier, t, v, w)
                            )
                        });
                        for ((p, t), v) in p[s..e].iter().zip(&t[s..e]).zip(v.iter()) {
                            for c in 0..4 {
                                pq[c] += p[c] * (t[c] + v[c]);
                            }
                        }
                    }
                    pq
                })
                .collect();
            partials.extend(part);
        }
        sum(&partials)
    }

    /// z = M⁻¹ r (new numbering) for the symmetric block Gauss–Seidel M = (D + L) D⁻¹ (D + U):
    /// z = (D + U)⁻¹ D (D + L)⁻¹ r, by the sweeps the solve uses. Panics on a block-Jacobi
    /// system.
    pub fn apply_preconditioner(&self, r: &[V4], z: &mut [V4]) {
        let Operator::Split { off, order } = &self.op else {
            panic!("a Gauss–Seidel system");
        };
        let n = r.len();
        let zero = vec![[0.0; 4]; n];
        let mut v = r.to_vec();
        let mut w = vec![[0.0; 4]; n];
        self.forward(off, order, &zero, &zero, &mut v, &mut w);
        let start = &self.agg.start;
        let mut dv = vec![[0.0; 4]; n];
        for b in 0..start.len() - 1 {
            let r = start[b]..start[b + 1];
            self.with_factor(b, |l, first| {
                block_multiply(l, first, &v[r.clone()], &mut dv[r])
            });
        }
        self.backward(off, order, None, &mut dv, z, &mut w);
    }

    /// y = A x for the split system: the couplings between aggregates plus D x.
    fn apply_split(&self, off: &OffBlock, x: &[V4], y: &mut [V4]) {
        let start = &self.agg.start;
        split_at_offsets(y, start)
            .into_par_iter()
            .enumerate()
            .for_each(|(b, y)| {
                let s = start[b];
                self.with_factor(b, |l, first| {
                    block_multiply(l, first, &x[s..start[b + 1]], y)
                });
                for (i, y) in y.iter_mut().enumerate() {
                    let (cl, pl, vl) = off.lower(s + i);
                    let (cu, pu, vu) = off.upper(s + i);
                    let lo = part_dot(cl, pl, vl, |c| x[c]);
                    let up = part_dot(cu, pu, vu, |c| x[c]);
                    for c in 0..4 {
                        y[c] += lo[c] + up[c];
                    }
                }
            });
    }

    /// Per aggregate [`eisenstat_update`]; returns (r̃ᵀz̃, rᵀr) summed in aggregate order.
    fn eisenstat_step(&self, portable: bool, alpha: V4, v: &mut Eisenstat) -> (V4, V4) {
        let start = &self.agg.start;
        let (p, t, vv, w) = (&v.p, &v.t, &v.v, &v.w);
        let partials: Vec<(V4, V4)> = split_at_offsets(&mut v.x, start)
            .into_par_iter()
            .zip(split_at_offsets(&mut v.r, start))
            .zip(split_at_offsets(&mut v.rt, start))
            .zip(split_at_offsets(&mut v.zt, start))
            .enumerate()
            .map(|(b, (((x, r), rt), zt))| {
                let e = s_end(start, b);
                let (p, t, vv, w) = (&p[e.clone()], &t[e.clone()], &vv[e.clone()], &w[e]);
                self.with_factor(b, |l, first| {
                    dispatch!(
                        portable,
                        eisenstat_update_avx2,
                        eisenstat_update(l, first, alpha, x, r, rt, zt, p, t, vv, w)
                    )
                })
            })
            .collect();
        let rz: Vec<V4> = partials.iter().map(|p| p.0).collect();
        let rr: Vec<V4> = partials.iter().map(|p| p.1).collect();
        (sum(&rz), sum(&rr))
    }

    /// Run the portable kernels (`true`) or the fastest the CPU has (`false`, the default
    /// unless `POLYSPLINE_KERNELS=portable`). Both give the same bits.
    pub fn set_portable_kernels(&mut self, portable: bool) {
        match &mut self.op {
            Operator::Whole(a) => a.portable = portable,
            Operator::Split { off, .. } => off.portable = portable,
        }
    }

    /// The reordered matrix of a block-Jacobi system (`None` for Gauss–Seidel, which keeps
    /// only the couplings between aggregates).
    pub fn matrix(&self) -> Option<&TemplateMatrix> {
        match &self.op {
            Operator::Whole(a) => Some(a),
            Operator::Split { .. } => None,
        }
    }

    /// Per aggregate: x += α p, r −= α ap, z = M⁻¹ r; returns (rᵀz, rᵀr).
    #[allow(clippy::too_many_arguments)]
    fn update_and_precondition(
        &self,
        portable: bool,
        alpha: V4,
        x: &mut [V4],
        r: &mut [V4],
        z: &mut [V4],
        p: &[V4],
        ap: &[V4],
    ) -> (V4, V4) {
        let start = &self.agg.start;
        let partials: Vec<(V4, V4)> = split_at_offsets(x, start)
            .into_par_iter()
            .zip(split_at_offsets(r, start))
            .zip(split_at_offsets(z, start))
            .enumerate()
            .map(|(b, ((x, r), z))| {
                let e = s_end(start, b);
                let (p, ap) = (&p[e.clone()], &ap[e]);
                self.with_factor(b, |l, first| {
                    dispatch!(
                        portable,
                        block_step_avx2,
                        block_step(l, first, alpha, x, r, z, p, ap)
                    )
                })
            })
            .collect();
        let rz: Vec<V4> = partials.iter().map(|p| p.0).collect();
        let rr: Vec<V4> = partials.iter().map(|p| p.1).collect();
        (sum(&rz), sum(&rr))
    }

    /// Solve A x = b (original numbering) from the start `x`; see the module docs.
    pub fn solve(
        &self,
        b: &[[f64; 3]],
        x: &mut [[f64; 3]],
        params: &CgParams,
        progress: impl super::CgMonitor,
    ) -> Result<CgInfo, CgError> {
        let n = self.agg.rows.len();
        assert_eq!(b.len(), n);
        assert_eq!(x.len(), n);
        let rows = &self.agg.rows;
        let widen = |v: &[f64; 3]| [v[0], v[1], v[2], 0.0];
        let mut xp: Vec<V4> = rows.par_iter().map(|&i| widen(&x[i as usize])).collect();
        // r = b − A x (no product for the usual start x = 0).
        let mut r = written_zeros(n);
        if xp.par_iter().any(|v| v.iter().any(|&c| c != 0.0)) {
            match &self.op {
                Operator::Whole(a) => {
                    a.apply_dot(&xp, &mut r);
                }
                Operator::Split { off, .. } => self.apply_split(off, &xp, &mut r),
            }
        }
        r.par_iter_mut().zip(rows.par_iter()).for_each(|(r, &i)| {
            let b = widen(&b[i as usize]);
            for k in 0..4 {
                r[k] = b[k] - r[k];
            }
        });
        let bb: Vec<V4> = rows
            .par_chunks(ROW_CHUNK)
            .map(|c| {
                c.iter().fold([0.0; 4], |s, &i| {
                    let v = b[i as usize];
                    std::array::from_fn(|d| if d < 3 { s[d] + v[d] * v[d] } else { 0.0 })
                })
            })
            .collect();
        let bnorm = sum(&bb).map(f64::sqrt);
        let stop = Stopping::new([bnorm[0], bnorm[1], bnorm[2]], params);
        let (it, rr) = match &self.op {
            Operator::Whole(a) => {
                let mut steps = JacobiSteps::new(self, a, &mut xp, r);
                iterate(&stop, params.max_iters, &mut steps, progress)?
            }
            Operator::Split { off, order } => {
                let mut steps = EisenstatSteps::new(self, off, order, std::mem::take(&mut xp), r);
                let done = iterate(&stop, params.max_iters, &mut steps, progress)?;
                xp = steps.v.x;
                done
            }
        };
        for (&i, xp) in rows.iter().zip(&xp) {
            x[i as usize] = [xp[0], xp[1], xp[2]];
        }
        Ok(CgInfo {
            iterations: it,
            rel_residual: stop.rel(rr),
        })
    }

    /// The pair preconditioner's second half: z2 = M₂⁻¹ r (second partition's order); returns
    /// rᵀz for z = ½ (z₁ + M₂⁻¹ r) given rz₁ = rᵀz₁.
    fn add_second(
        &self,
        second: &SecondPartition,
        portable: bool,
        rz1: V4,
        r: &[V4],
        z2: &mut [V4],
    ) -> V4 {
        let rz2 = second.solve(portable, r, z2);
        std::array::from_fn(|c| 0.5 * (rz1[c] + rz2[c]))
    }

    /// p = z + β p, where z is the first partition's z₁ alone or, for the pair, ½ (z₁ + z₂)
    /// with z₂ gathered from the second partition's order (never stored: p is its only user),
    /// plus, with lines, each row's shares of the line solves `zl` (in line order).
    fn next_direction(&self, beta: V4, z: &[V4], z2: &[V4], zl: &[V4], p: &mut [V4]) {
        let lines = |i: usize, v: &mut V4| {
            if let Some(l) = &self.lines {
                let (s, e) = (l.share_start[i] as usize, l.share_start[i + 1] as usize);
                for &k in &l.share_at[s..e] {
                    let w = zl[k as usize];
                    for c in 0..4 {
                        v[c] += w[c];
                    }
                }
            }
        };
        match &self.second {
            None if self.lines.is_none() => p
                .par_iter_mut()
                .zip(z.par_iter())
                .with_min_len(ROW_CHUNK)
                .for_each(|(p, z)| {
                    for k in 0..4 {
                        p[k] = z[k] + beta[k] * p[k];
                    }
                }),
            None => p
                .par_iter_mut()
                .zip(z.par_iter())
                .enumerate()
                .with_min_len(ROW_CHUNK)
                .for_each(|(i, (p, z))| {
                    let mut v = *z;
                    lines(i, &mut v);
                    for c in 0..4 {
                        p[c] = v[c] + beta[c] * p[c];
                    }
                }),
            Some(second) => p
                .par_iter_mut()
                .zip(z.par_iter().zip(second.slot.par_iter()))
                .enumerate()
                .with_min_len(ROW_CHUNK)
                .for_each(|(i, (p, (z, &k)))| {
                    let w = z2[k as usize];
                    let mut v: V4 = std::array::from_fn(|c| 0.5 * (z[c] + w[c]));
                    lines(i, &mut v);
                    for c in 0..4 {
                        p[c] = v[c] + beta[c] * p[c];
                    }
                }),
        }
    }

    /// The line solves' part of z ([`Self::with_lines`]), in line order: zl = K_l⁻¹ r per line;
    /// returns rᵀz for z = z_blocks + Σ lines given rz = rᵀz_blocks.
    fn add_lines(&self, rz: V4, r: &[V4], zl: &mut [V4]) -> V4 {
        match &self.lines {
            Some(l) => {
                let rzl = l.blocks.solve(r, zl);
                std::array::from_fn(|c| rz[c] + rzl[c])
            }
            None => rz,
        }
    }
}

/// The block-Jacobi steps of [`iterate`] (and the pair's): the product with pᵀAp in one pass
/// ([`TemplateMatrix::apply_dot`]); the updates of x and r, the block solves z = M⁻¹ r and
/// rᵀz, rᵀr in another ([`BlockedSystem::update_and_precondition`], the pair's second
/// partition in one more); p = z + β p in the last.
struct JacobiSteps<'a> {
    sys: &'a BlockedSystem,
    a: &'a TemplateMatrix,
    x: &'a mut [V4],
    r: Vec<V4>,
    z: Vec<V4>,
    p: Vec<V4>,
    ap: Vec<V4>,
    /// The second partition's M₂⁻¹ r, in its own order (allocated once per solve).
    z2: Vec<V4>,
    /// The line solves, in line order (allocated once per solve).
    zl: Vec<V4>,
}

impl<'a> JacobiSteps<'a> {
    /// The steps from x (aggregate order) with residual r.
    fn new(sys: &'a BlockedSystem, a: &'a TemplateMatrix, x: &'a mut [V4], r: Vec<V4>) -> Self {
        let n = x.len();
        JacobiSteps {
            sys,
            a,
            x,
            r,
            z: written_zeros(n),
            p: written_zeros(n),
            ap: written_zeros(n),
            z2: match sys.second {
                Some(_) => written_zeros(n),
                None => Vec::new(),
            },
            zl: match &sys.lines {
                Some(l) => written_zeros(l.blocks.points.len()),
                None => Vec::new(),
            },
        }
    }

    /// x += α p, r −= α A p, z = M⁻¹ r (the pair's z₂ too); returns (rᵀz, rᵀr).
    fn update(&mut self, alpha: V4) -> Pair {
        let JacobiSteps { sys, a, .. } = *self;
        let (mut rz, rr) = sys.update_and_precondition(
            a.portable,
            alpha,
            self.x,
            &mut self.r,
            &mut self.z,
            &self.p,
            &self.ap,
        );
        if let Some(second) = &sys.second {
            rz = sys.add_second(second, a.portable, rz, &self.r, &mut self.z2);
        }
        rz = sys.add_lines(rz, &self.r, &mut self.zl);
        (head(rz), head(rr))
    }
}

impl CgSteps for JacobiSteps<'_> {
    fn start(&mut self) -> Pair {
        // z = M⁻¹ r (a zero step leaves x and r as they are).
        let sums = self.update([0.0; 4]);
        if self.sys.second.is_some() || self.sys.lines.is_some() {
            self.sys
                .next_direction([0.0; 4], &self.z, &self.z2, &self.zl, &mut self.p);
        } else {
            self.p.copy_from_slice(&self.z);
        }
        sums
    }

    fn curvature(&mut self) -> [f64; 3] {
        head(self.a.apply_dot(&self.p, &mut self.ap))
    }

    fn step(&mut self, alpha: [f64; 3]) -> Pair {
        self.update(lanes(alpha))
    }

    fn direction(&mut self, beta: [f64; 3]) {
        self.sys
            .next_direction(lanes(beta), &self.z, &self.z2, &self.zl, &mut self.p);
    }
}

/// The steps of [`iterate`] for symmetric block Gauss–Seidel in Eisenstat's form (see
/// [`BlockedSystem::symmetric_gauss_seidel`]): the curvature is the backward sweep, which
/// forms the direction p̃ = z̃ + β p̃ as it goes (so [`CgSteps::direction`] only keeps β),
/// and the forward sweep; the step is [`BlockedSystem::eisenstat_step`].
struct EisenstatSteps<'a> {
    sys: &'a BlockedSystem,
    off: &'a OffBlock,
    order: &'a SweepOrder,
    v: Eisenstat,
    beta: V4,
}

impl<'a> EisenstatSteps<'a> {
    /// The steps from x (aggregate order) with residual r.
    fn new(
        sys: &'a BlockedSystem,
        off: &'a OffBlock,
        order: &'a SweepOrder,
        x: Vec<V4>,
        r: Vec<V4>,
    ) -> Self {
        let n = x.len();
        let v = Eisenstat {
            x,
            rt: r.clone(),
            r,
            zt: written_zeros(n),
            p: written_zeros(n),
            t: written_zeros(n),
            v: written_zeros(n),
            w: written_zeros(n),
        };
        EisenstatSteps {
            sys,
            off,
            order,
            v,
            beta: [0.0; 4],
        }
    }
}

impl CgSteps for EisenstatSteps<'_> {
    fn start(&mut self) -> Pair {
        // r̃ = (D + L)⁻¹ r (t = 0, so w stays 0), then z̃ = D r̃ by a zero step.
        let (sys, off, v) = (self.sys, self.off, &mut self.v);
        sys.forward(off, self.order, &v.t, &v.p, &mut v.rt, &mut v.w);
        let (rz, rr) = sys.eisenstat_step(off.portable, [0.0; 4], v);
        (head(rz), head(rr))
    }

    fn curvature(&mut self) -> [f64; 3] {
        // p̃ = z̃ + β p̃ (fused), t = (D + U)⁻¹ p̃ and u = U t; v = (D + L)⁻¹ u and w = L t.
        let (sys, off, order, v) = (self.sys, self.off, self.order, &mut self.v);
        sys.backward(
            off,
            order,
            Some((self.beta, &v.zt)),
            &mut v.p,
            &mut v.t,
            &mut v.v,
        );
        head(sys.forward(off, order, &v.t, &v.p, &mut v.v, &mut v.w))
    }

    fn step(&mut self, alpha: [f64; 3]) -> Pair {
        let (rz, rr) = self
            .sys
            .eisenstat_step(self.off.portable, lanes(alpha), &mut self.v);
        (head(rz), head(rr))
    }

    fn direction(&mut self, beta: [f64; 3]) {
        self.beta = lanes(beta);
    }
}

#[cfg(test)]
impl BlockedSystem {
    /// z = M⁻¹ r in the original numbering, by the solve's own passes (a zero step, the
    /// second partition's pass and the direction update with β = 0).
    pub(crate) fn precondition(&self, r: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let Operator::Whole(a) = &self.op else {
            panic!("a block-Jacobi system");
        };
        let rows = &self.agg.rows;
        let n = rows.len();
        let mut rp: Vec<V4> = rows
            .iter()
            .map(|&i| {
                let v = r[i as usize];
                [v[0], v[1], v[2], 0.0]
            })
            .collect();
        let (mut x, mut z, mut p, ap) = (
            vec![[0.0; 4]; n],
            vec![[0.0; 4]; n],
            vec![[0.0; 4]; n],
            vec![[0.0; 4]; n],
        );
        let mut z2 = vec![[0.0; 4]; n];
        let mut zl = vec![[0.0; 4]; self.lines.as_ref().map_or(0, |l| l.blocks.points.len())];
        let _ =
            self.update_and_precondition(a.portable, [0.0; 4], &mut x, &mut rp, &mut z, &p, &ap);
        if let Some(second) = &self.second {
            self.add_second(second, a.portable, [0.0; 4], &rp, &mut z2);
        }
        self.add_lines([0.0; 4], &rp, &mut zl);
        self.next_direction([0.0; 4], &z, &z2, &zl, &mut p);
        let mut out = vec![[0.0; 3]; n];
        for (&i, v) in rows.iter().zip(&p) {
            out[i as usize] = [v[0], v[1], v[2]];
        }
        out
    }
}

/// Aggregate b's rows.
fn s_end(start: &[usize], b: usize) -> std::ops::Range<usize> {
    start[b]..start[b + 1]
}

/// The three components of a 4-lane entry.
fn head(v: V4) -> [f64; 3] {
    [v[0], v[1], v[2]]
}

/// Three components as a 4-lane entry (lane 3 zero).
fn lanes(v: [f64; 3]) -> V4 {
    [v[0], v[1], v[2], 0.0]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::block_jacobi::tests::{Csr, laplacian, matvec};
    use crate::solve::{BlockJacobi, CgPreconditioner, LinOp, Preconditioner, pcg_with};

    struct Op<'a>(&'a Csr);
    impl LinOp for Op<'_> {
        fn nrows(&self) -> usize {
            self.0.0.len() - 1
        }
        fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
            y.copy_from_slice(&matvec(self.0, x));
        }
        fn diagonal(&self) -> Vec<f64> {
            unimplemented!()
        }
    }

    fn test_vector(n: usize) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                [
                    (i as f64 * 0.7).sin(),
                    1.0 + (i % 5) as f64,
                    -(i as f64).sqrt(),
                ]
            })
            .collect()
    }

    /// The reordered template product, brought back to the original numbering.
    fn template_product(a: &Csr, m: &TemplateMatrix, agg: &Aggregates, x: &[[f64; 3]]) -> Vec<V4> {
        let xp: Vec<V4> = agg
            .rows
            .iter()
            .map(|&i| {
                let v = x[i as usize];
                [v[0], v[1], v[2], 0.0]
            })
            .collect();
        let mut yp = vec![[0.0; 4]; xp.len()];
        m.apply_dot(&xp, &mut yp);
        let mut y = vec![[0.0; 4]; a.0.len() - 1];
        for (&i, v) in agg.rows.iter().zip(&yp) {
            y[i as usize] = *v;
        }
        y
    }

    fn assert_close(got: &[V4], want: &[[f64; 3]], tol: f64) {
        for (g, w) in got.iter().zip(want) {
            for c in 0..3 {
                assert!(
                    (g[c] - w[c]).abs() <= tol * (1.0 + w[c].abs()),
                    "{g:?} vs {w:?}"
                );
            }
            assert_eq!(g[3], 0.0);
        }
    }

    #[test]
    fn repeated_rows_share_a_template_and_the_product_is_exact() {
        let a = laplacian(30, |_, _| 0.5);
        let agg = Aggregates::new(&a.0, &a.1, 16);
        let m = TemplateMatrix::new(&a.0, &a.1, &a.2, &agg.rows, &agg.slot);
        // Value sequences in column order: interior [-1, -1, d, -1, -1]; edges with the
        // diagonal second ([-1, d, -1, -1]: top and left) or third (right and bottom);
        // corners [d, -1, -1], [-1, d, -1] (two corners) and [-1, -1, d]: six in all.
        assert_eq!(m.n_templates(), 6);
        let x = test_vector(900);
        assert_close(&template_product(&a, &m, &agg, &x), &matvec(&a, &x), 1e-14);
    }

    /// The product from 16-bit columns gives the bits of the product from 32-bit ones, on a
    /// matrix of more than 2¹⁶ rows whose rows near its two ends couple across the whole
    /// range (kept in 32 bits) and whose other rows span a few columns (packed).
    #[test]
    fn packed_columns_give_the_bits_of_the_full_columns() {
        let g = 280; // 78,400 rows
        let n = g * g;
        let mut a = laplacian(g, |x, y| 0.01 * ((x * 7 + y * 3) % 11) as f64);
        // Couple rows k and n − 1 − k (k < 3) symmetrically: CSR rows rebuilt with the extra
        // column in order.
        let far = |r: usize| match r {
            0..3 => Some(n - 1 - r),
            r if r >= n - 3 => Some(n - 1 - r),
            _ => None,
        };
        let (mut indptr, mut indices, mut data) = (vec![0], Vec::new(), Vec::new());
        for r in 0..n {
            let mut row: Vec<(u32, f64)> = (a.0[r]..a.0[r + 1]).map(|k| (a.1[k], a.2[k])).collect();
            if let Some(c) = far(r) {
                row.push((c as u32, -0.25));
            }
            row.sort_by_key(|e| e.0);
            indices.extend(row.iter().map(|e| e.0));
            data.extend(row.iter().map(|e| e.1));
            indptr.push(indices.len());
        }
        a = (indptr, indices, data);
        let agg = Aggregates::new(&a.0, &a.1, 64);
        let full = TemplateMatrix::new(&a.0, &a.1, &a.2, &agg.rows, &agg.slot);
        let with = |pack| {
            let (i, d) = (Cow::Borrowed(&a.1[..]), Cow::Borrowed(&a.2[..]));
            TemplateMatrix::with_hash(&a.0, i, d, &agg.rows, &agg.slot, hash_row, pack)
        };
        let packed = with(true);
        assert!(full.packed.is_none() && with(false).packed.is_none());
        // The block factors read the packed entries as the unpacked ones.
        for i in (0..n).step_by(97).chain([0, 1, 2, n - 1]) {
            let k = agg.slot[i] as usize;
            let (mut e0, mut e1) = (Vec::new(), Vec::new());
            full.for_each_entry(k, |c, v| e0.push((c, v.to_bits())));
            packed.for_each_entry(k, |c, v| e1.push((c, v.to_bits())));
            assert_eq!(e0, e1, "row {i}");
        }
        // A row is kept in 32 bits exactly when its columns span 2¹⁶ or more: the six rows
        // coupled across the whole range and the few that the aggregation's renumbering puts
        // next to them.
        let p = packed.packed.as_ref().unwrap();
        let mut wide = 0;
        for k in 0..n {
            let (cols, _) = full.row(k);
            let span = cols.iter().max().unwrap() - cols.iter().min().unwrap();
            assert_eq!(p.base[k] == WIDE, span > 65_535, "row {k}: span {span}");
            wide += usize::from(span > 65_535);
        }
        assert!((6..n / 100).contains(&wide), "{wide} wide rows");
        let x = test_vector(n);
        let (mut full, mut packed) = (full, packed);
        for portable in [false, true] {
            full.portable = portable;
            packed.portable = portable;
            let y0 = template_product(&a, &full, &agg, &x);
            let y1 = template_product(&a, &packed, &agg, &x);
            for (i, (u, v)) in y0.iter().zip(&y1).enumerate() {
                assert_eq!(u.map(f64::to_bits), v.map(f64::to_bits), "row {i}");
            }
            // And the product is A's (the oracle: the plain CSR product).
            assert_close(&y1, &matvec(&a, &x), 1e-12);
        }
    }

    #[test]
    fn distinct_rows_and_hash_collisions_keep_their_own_values() {
        // Every diagonal differs, so every row is its own template; a constant hash sends every
        // row through the collision path, which must find the same templates.
        let a = laplacian(12, |x, y| 0.01 * (x * 12 + y) as f64);
        let agg = Aggregates::new(&a.0, &a.1, 8);
        let x = test_vector(144);
        let want = matvec(&a, &x);
        for m in [
            TemplateMatrix::new(&a.0, &a.1, &a.2, &agg.rows, &agg.slot),
            TemplateMatrix::with_hash(
                &a.0,
                Cow::Borrowed(&a.1),
                Cow::Borrowed(&a.2),
                &agg.rows,
                &agg.slot,
                |_| 7,
                true,
            ),
        ] {
            assert_eq!(m.n_templates(), 144);
            assert_close(&template_product(&a, &m, &agg, &x), &want, 1e-14);
        }
        // Two distinct sequences under one hash, each repeated: two templates, not more.
        let b = laplacian(12, |x, _| if x % 2 == 0 { 0.25 } else { 0.5 });
        let agg = Aggregates::new(&b.0, &b.1, 8);
        let plain = TemplateMatrix::new(&b.0, &b.1, &b.2, &agg.rows, &agg.slot);
        let collided = TemplateMatrix::with_hash(
            &b.0,
            Cow::Borrowed(&b.1),
            Cow::Borrowed(&b.2),
            &agg.rows,
            &agg.slot,
            |_| 7,
            false,
        );
        assert_eq!(plain.n_templates(), collided.n_templates());
        assert_close(
            &template_product(&b, &collided, &agg, &x),
            &matvec(&b, &x),
            1e-14,
        );
    }

    #[test]
    fn solves_a_known_system_like_the_generic_block_jacobi_cg() {
        let a = laplacian(40, |x, y| 0.05 + 0.01 * ((x + 2 * y) % 7) as f64);
        let n = 1600;
        let want = test_vector(n);
        let b = matvec(&a, &want);
        let params = CgParams {
            rel_tol: 1e-10,
            preconditioner: CgPreconditioner::BlockJacobi { size: 16 },
            ..Default::default()
        };
        let sys = BlockedSystem::new(&a.0, &a.1, &a.2, 16).unwrap();
        let mut x = vec![[0.0; 3]; n];
        let info = sys.solve(&b, &mut x, &params, |_, _| {}).unwrap();
        // The true residual of the returned x, computed independently, meets the tolerance.
        let ax = matvec(&a, &x);
        for c in 0..3 {
            let r: f64 = ax.iter().zip(&b).map(|(p, q)| (p[c] - q[c]).powi(2)).sum();
            let bb: f64 = b.iter().map(|q| q[c] * q[c]).sum();
            assert!(r.sqrt() <= 1.01e-10 * bb.sqrt(), "component {c}");
        }
        for (g, w) in x.iter().zip(&want) {
            for c in 0..3 {
                assert!((g[c] - w[c]).abs() < 1e-8);
            }
        }
        // The same method as the generic PCG with the block-Jacobi preconditioner.
        let pre = BlockJacobi::new(&a.0, &a.1, &a.2, 16).unwrap();
        let mut y = vec![[0.0; 3]; n];
        let generic = pcg_with(
            &Op(&a),
            &pre as &dyn Preconditioner,
            &b,
            &mut y,
            &params,
            |_, _| {},
        )
        .unwrap();
        assert!(info.iterations.abs_diff(generic.iterations) <= 1);
        // A start near the solution converges in fewer iterations.
        let mut z: Vec<[f64; 3]> = want.iter().map(|w| w.map(|v| v * (1.0 + 1e-6))).collect();
        let warm = sys.solve(&b, &mut z, &params, |_, _| {}).unwrap();
        assert!(warm.iterations < info.iterations);
    }

    /// The solver built from owned CSR arrays (released while it is built) is the one built
    /// from borrowed arrays, bit for bit, for both preconditioners and with templates shared.
    #[test]
    fn consuming_the_csr_arrays_gives_the_bits_of_borrowing_them() {
        let a = laplacian(30, |x, y| 0.05 + 0.01 * ((3 * x + y) % 5) as f64);
        let b = test_vector(900);
        for kind in [
            BlockedKind::Jacobi,
            BlockedKind::JacobiPair,
            BlockedKind::GaussSeidel,
        ] {
            let sweeps = kind == BlockedKind::GaussSeidel;
            let params = CgParams {
                rel_tol: 1e-9,
                ..Default::default()
            };
            let borrowed = BlockedSystem::build(
                &a.0,
                Cow::Borrowed(&a.1),
                Values::Csr(Cow::Borrowed(&a.2)),
                16,
                kind,
            )
            .unwrap();
            let owned =
                BlockedSystem::from_parts(a.0.clone(), a.1.clone(), a.2.clone(), 16, kind).unwrap();
            assert_eq!(owned.sweep_order().is_some(), sweeps);
            let mut x = vec![[0.0; 3]; 900];
            let mut y = vec![[0.0; 3]; 900];
            let i = borrowed.solve(&b, &mut x, &params, |_, _| {}).unwrap();
            let j = owned.solve(&b, &mut y, &params, |_, _| {}).unwrap();
            assert_eq!(i.iterations, j.iterations);
            assert!(i.iterations > 5);
            let bits =
                |v: &[[f64; 3]]| -> Vec<u64> { v.iter().flatten().map(|x| x.to_bits()).collect() };
            assert_eq!(bits(&x), bits(&y), "{kind:?}");
        }
    }

    /// Skipping the factor rows' leading zeros changes no bit of the solve: the same system
    /// with the whole rows read (envelope starts at 0) gives the same iterates.
    #[test]
    fn the_envelope_skip_gives_the_bits_of_the_full_triangular_solves() {
        let a = laplacian(30, |x, y| 0.05 + 0.01 * ((3 * x + y) % 5) as f64);
        let b = test_vector(900);
        let skip = BlockedSystem::new(&a.0, &a.1, &a.2, 64).unwrap();
        let full = BlockedSystem {
            first: vec![0; skip.first.len()],
            ..BlockedSystem::new(&a.0, &a.1, &a.2, 64).unwrap()
        };
        // The 5-point aggregates' factors do have leading zeros to skip.
        let skipped: usize = skip.first.iter().map(|&f| f as usize).sum();
        assert!(skipped > 1000, "{skipped}");
        let params = CgParams {
            rel_tol: 1e-12,
            ..Default::default()
        };
        let run = |sys: &BlockedSystem| {
            let mut x = vec![[0.0; 3]; 900];
            let info = sys.solve(&b, &mut x, &params, |_, _| {}).unwrap();
            (x, info.iterations, info.rel_residual.to_bits())
        };
        let (xs, is, rs) = run(&skip);
        let (xf, it, rf) = run(&full);
        assert_eq!((is, rs), (it, rf));
        assert!(
            xs.iter()
                .zip(&xf)
                .all(|(p, q)| p.map(f64::to_bits) == q.map(f64::to_bits))
        );
    }

    /// The portable and the AVX2 kernels give the same bits (on an AVX2 CPU; elsewhere both
    /// runs are portable and the comparison is trivially true, which the message says).
    #[test]
    fn portable_kernels_give_the_bits_of_the_avx2_kernels() {
        #[cfg(target_arch = "x86_64")]
        if !std::is_x86_feature_detected!("avx2") {
            println!("no AVX2 on this CPU: both runs use the portable kernels");
        }
        let a = laplacian(50, |x, y| 0.07 + 0.013 * ((2 * x + y) % 5) as f64);
        let b = test_vector(2500);
        let mut sys = BlockedSystem::new(&a.0, &a.1, &a.2, 32).unwrap();
        let mut run = |portable: bool| {
            sys.set_portable_kernels(portable);
            let mut x = vec![[0.0; 3]; 2500];
            let info = sys
                .solve(&b, &mut x, &CgParams::default(), |_, _| {})
                .unwrap();
            let mut y = vec![[0.0; 4]; 2500];
            let x4: Vec<V4> = x.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect();
            let dot = sys.matrix().unwrap().apply_dot(&x4, &mut y);
            (x, y, dot, info.iterations, info.rel_residual)
        };
        let (xa, ya, da, ia, ra) = run(false);
        let (xp, yp, dp, ip, rp) = run(true);
        // The Gauss–Seidel kernels too.
        let mut sgs = BlockedSystem::symmetric_gauss_seidel(&a.0, &a.1, &a.2, 32).unwrap();
        let mut run_sgs = |portable: bool| {
            sgs.set_portable_kernels(portable);
            let mut x = vec![[0.0; 3]; 2500];
            let info = sgs
                .solve(&b, &mut x, &CgParams::default(), |_, _| {})
                .unwrap();
            (
                x.iter().map(|p| p.map(f64::to_bits)).collect::<Vec<_>>(),
                info.iterations,
            )
        };
        assert_eq!(run_sgs(false), run_sgs(true));
        // And the pair's (its second partition's block solves).
        let mut pair =
            BlockedSystem::with_kind(&a.0, &a.1, &a.2, 32, BlockedKind::JacobiPair).unwrap();
        let mut run_pair = |portable: bool| {
            pair.set_portable_kernels(portable);
            let mut x = vec![[0.0; 3]; 2500];
            let info = pair
                .solve(&b, &mut x, &CgParams::default(), |_, _| {})
                .unwrap();
            (
                x.iter().map(|p| p.map(f64::to_bits)).collect::<Vec<_>>(),
                info.iterations,
                info.rel_residual.to_bits(),
            )
        };
        let (pair_avx2, pair_portable) = (run_pair(false), run_pair(true));
        assert!(pair_avx2.1 > 10, "{} iterations", pair_avx2.1);
        assert_eq!(pair_avx2, pair_portable);
        assert!(ia > 10, "{ia} iterations");
        assert_eq!((ia, ra.to_bits()), (ip, rp.to_bits()));
        assert_eq!(da.map(f64::to_bits), dp.map(f64::to_bits));
        let bits = |v: &[[f64; 3]]| v.iter().map(|p| p.map(f64::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(&xa), bits(&xp));
        assert!(
            ya.iter()
                .zip(&yp)
                .all(|(p, q)| p.map(f64::to_bits) == q.map(f64::to_bits))
        );
    }

    #[test]
    fn result_does_not_depend_on_the_thread_count() {
        let a = laplacian(70, |x, _| 0.1 + 0.001 * (x % 3) as f64);
        let b = test_vector(4900);
        let solve = |threads: usize, sgs: bool| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let sys = if sgs {
                    BlockedSystem::symmetric_gauss_seidel(&a.0, &a.1, &a.2, 64)
                } else {
                    BlockedSystem::new(&a.0, &a.1, &a.2, 64)
                }
                .unwrap();
                let mut x = vec![[0.0; 3]; 4900];
                let info = sys
                    .solve(&b, &mut x, &CgParams::default(), |_, _| {})
                    .unwrap();
                (x, info.iterations, info.rel_residual)
            })
        };
        for sgs in [false, true] {
            let one = solve(1, sgs);
            let three = solve(3, sgs);
            assert_eq!(one.1, three.1);
            assert_eq!(one.2.to_bits(), three.2.to_bits());
            assert!(
                one.0
                    .iter()
                    .zip(&three.0)
                    .all(|(p, q)| p.map(f64::to_bits) == q.map(f64::to_bits))
            );
        }
    }

    #[test]
    fn an_indefinite_block_names_its_original_row() {
        let mut a = laplacian(6, |_, _| 0.0);
        let k = (a.0[14]..a.0[15]).find(|&k| a.1[k] == 14).unwrap();
        a.2[k] = -1.0;
        match BlockedSystem::new(&a.0, &a.1, &a.2, 8) {
            Err(CgError::BadDiagonal { row, .. }) => assert_eq!(row, 14),
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("accepted an indefinite block"),
        }
    }

    /// Dense solve of the square system `a` (row-major n × n) by Gaussian elimination with
    /// partial pivoting (the test's own oracle, independent of the packed Cholesky).
    fn dense_solve(mut a: Vec<f64>, mut b: Vec<f64>, n: usize) -> Vec<f64> {
        for k in 0..n {
            let p = (k..n)
                .max_by(|&i, &j| a[i * n + k].abs().total_cmp(&a[j * n + k].abs()))
                .unwrap();
            for j in 0..n {
                a.swap(k * n + j, p * n + j);
            }
            b.swap(k, p);
            for i in k + 1..n {
                let f = a[i * n + k] / a[k * n + k];
                for j in k..n {
                    a[i * n + j] -= f * a[k * n + j];
                }
                b[i] -= f * b[k];
            }
        }
        for k in (0..n).rev() {
            let s: f64 = (k + 1..n).map(|j| a[k * n + j] * b[j]).sum();
            b[k] = (b[k] - s) / a[k * n + k];
        }
        b
    }

    #[test]
    fn colours_separate_coupled_groups() {
        let a = laplacian(40, |x, y| 0.1 + 0.01 * (x * y) as f64);
        let sys = BlockedSystem::symmetric_gauss_seidel(&a.0, &a.1, &a.2, 8).unwrap();
        let (groups, colours) = sys.sweep_order().unwrap();
        let (start, rows) = (sys.aggregate_starts(), sys.rows());
        assert!(colours.len() > 2, "{colours:?}");
        let mut colour_of_row = vec![usize::MAX; rows.len()];
        let mut group_of_row = vec![usize::MAX; rows.len()];
        for k in 0..colours.len() - 1 {
            for g in colours[k]..colours[k + 1] {
                for &r in &rows[start[groups[g]]..start[groups[g + 1]]] {
                    colour_of_row[r as usize] = k;
                    group_of_row[r as usize] = g;
                }
            }
        }
        assert!(colour_of_row.iter().all(|&k| k != usize::MAX));
        // Colour 0 is the domains' interiors, one group each; then one group per separator.
        assert_eq!(colours[1], SWEEP_DOMAINS);
        assert!(groups[SWEEP_DOMAINS] > 0, "no interior aggregates");
        assert!((colours[1]..groups.len() - 1).all(|g| groups[g + 1] == groups[g] + 1));
        for r in 0..rows.len() {
            for &c in &a.1[a.0[r]..a.0[r + 1]] {
                let c = c as usize;
                assert!(
                    group_of_row[c] == group_of_row[r] || colour_of_row[c] != colour_of_row[r],
                    "rows {r} and {c} couple across two groups of one colour"
                );
            }
        }
    }

    /// The sweeps apply M⁻¹ for M = (D + L) D⁻¹ (D + U) over the colour-ordered aggregates:
    /// checked against the dense M built from A, in the system's numbering.
    #[test]
    fn sweeps_invert_the_symmetric_gauss_seidel_matrix() {
        let g = 9;
        let a = laplacian(g, |x, y| 0.2 + 0.05 * ((x + 2 * y) % 3) as f64);
        let n = g * g;
        let sys = BlockedSystem::symmetric_gauss_seidel(&a.0, &a.1, &a.2, 7).unwrap();
        let (start, rows) = (sys.aggregate_starts(), sys.rows());
        let mut slot = vec![0usize; n];
        for (i, &r) in rows.iter().enumerate() {
            slot[r as usize] = i;
        }
        let mut agg = vec![0usize; n];
        for b in 0..start.len() - 1 {
            agg[start[b]..start[b + 1]].fill(b);
        }
        // Dense A (new numbering) split into D, L (earlier aggregates) and U (later ones).
        let (mut dl, mut du, mut d) = (vec![0.0; n * n], vec![0.0; n * n], vec![0.0; n * n]);
        for r in 0..n {
            for k in a.0[r]..a.0[r + 1] {
                let (i, j) = (slot[r], slot[a.1[k] as usize]);
                let v = a.2[k];
                if agg[j] <= agg[i] {
                    dl[i * n + j] += v;
                }
                if agg[j] >= agg[i] {
                    du[i * n + j] += v;
                }
                if agg[j] == agg[i] {
                    d[i * n + j] += v;
                }
            }
        }
        let r: Vec<V4> = (0..n)
            .map(|i| [(i as f64 * 0.37).sin(), 1.0 + (i % 4) as f64, -0.5, 0.0])
            .collect();
        let mut z = vec![[0.0; 4]; n];
        sys.apply_preconditioner(&r, &mut z);
        for c in 0..3 {
            // M z = (D + L) D⁻¹ (D + U) z must give r.
            let zc: Vec<f64> = z.iter().map(|v| v[c]).collect();
            let u: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|j| du[i * n + j] * zc[j]).sum())
                .collect();
            let q = dense_solve(d.clone(), u, n);
            for i in 0..n {
                let mz: f64 = (0..n).map(|j| dl[i * n + j] * q[j]).sum();
                assert!((mz - r[i][c]).abs() < 1e-11, "row {i}: {mz} vs {}", r[i][c]);
            }
        }
    }

    /// M⁻¹ of a Gauss–Seidel system in the original numbering, for the generic PCG.
    struct Sweeps<'a>(&'a BlockedSystem);
    impl Preconditioner for Sweeps<'_> {
        fn apply(&self, r: &[[f64; 3]], z: &mut [[f64; 3]]) {
            let rows = self.0.rows();
            let rp: Vec<V4> = rows
                .iter()
                .map(|&i| {
                    let v = r[i as usize];
                    [v[0], v[1], v[2], 0.0]
                })
                .collect();
            let mut zp = vec![[0.0; 4]; rp.len()];
            self.0.apply_preconditioner(&rp, &mut zp);
            for (&i, v) in rows.iter().zip(&zp) {
                z[i as usize] = [v[0], v[1], v[2]];
            }
        }
    }

    /// CG in Eisenstat's form makes the iterates of the plain PCG with M⁻¹ (whose sweeps the
    /// test above checks against the dense M): same iteration count, same solution, and the
    /// true residual, computed independently, meets the tolerance, from zero and from a warm
    /// start (which takes the split product A x).
    #[test]
    fn eisenstat_form_follows_the_plain_gauss_seidel_pcg() {
        let a = laplacian(36, |x, y| 0.03 + 0.02 * ((x * 5 + y * 3) % 7) as f64);
        let n = 36 * 36;
        let want = test_vector(n);
        let b = matvec(&a, &want);
        let params = CgParams {
            rel_tol: 1e-10,
            ..Default::default()
        };
        let sys = BlockedSystem::symmetric_gauss_seidel(&a.0, &a.1, &a.2, 16).unwrap();
        assert!(sys.matrix().is_none());
        let check = |x: &[[f64; 3]]| {
            let ax = matvec(&a, x);
            for c in 0..3 {
                let r: f64 = ax.iter().zip(&b).map(|(p, q)| (p[c] - q[c]).powi(2)).sum();
                let bb: f64 = b.iter().map(|q| q[c] * q[c]).sum();
                assert!(r.sqrt() <= 1.0e-10 * bb.sqrt(), "component {c}");
            }
        };
        let mut x = vec![[0.0; 3]; n];
        let info = sys.solve(&b, &mut x, &params, |_, _| {}).unwrap();
        check(&x);
        let mut y = vec![[0.0; 3]; n];
        let plain = pcg_with(&Op(&a), &Sweeps(&sys), &b, &mut y, &params, |_, _| {}).unwrap();
        assert!(info.iterations > 5, "{}", info.iterations);
        assert!(
            info.iterations.abs_diff(plain.iterations) <= 1,
            "{} vs {}",
            info.iterations,
            plain.iterations
        );
        for (p, q) in x.iter().zip(&y) {
            for c in 0..3 {
                assert!((p[c] - q[c]).abs() < 1e-8, "{p:?} vs {q:?}");
            }
        }
        let mut z: Vec<[f64; 3]> = want.iter().map(|w| w.map(|v| v * (1.0 + 1e-6))).collect();
        let warm = sys.solve(&b, &mut z, &params, |_, _| {}).unwrap();
        check(&z);
        assert!(warm.iterations < info.iterations);
    }

    #[test]
    fn gauss_seidel_solves_with_fewer_iterations_than_block_jacobi() {
        let a = laplacian(30, |x, y| 0.05 + 0.02 * ((x * 7 + y * 3) % 5) as f64);
        let n = 900;
        let want = test_vector(n);
        let b: Vec<[f64; 3]> = matvec(&a, &want)
            .iter()
            .map(|v| [v[0], v[1], v[2]])
            .collect();
        let params = CgParams {
            rel_tol: 1e-12,
            ..Default::default()
        };
        let mut its = Vec::new();
        for sgs in [false, true] {
            let sys = if sgs {
                BlockedSystem::symmetric_gauss_seidel(&a.0, &a.1, &a.2, 16)
            } else {
                BlockedSystem::new(&a.0, &a.1, &a.2, 16)
            }
            .unwrap();
            let mut x = vec![[0.0; 3]; n];
            let info = sys.solve(&b, &mut x, &params, |_, _| {}).unwrap();
            for (got, w) in x.iter().zip(&want) {
                for c in 0..3 {
                    assert!((got[c] - w[c]).abs() < 1e-8, "sgs {sgs}: {got:?} vs {w:?}");
                }
            }
            its.push(info.iterations);
        }
        assert!(
            3 * its[1] <= 2 * its[0],
            "Gauss–Seidel {} vs block Jacobi {}",
            its[1],
            its[0]
        );
    }

    /// The fused pair preconditioner applies BlockJacobiPair's M⁻¹ (an independent
    /// implementation: gathers, its own triangular solves, an explicit average) to rounding,
    /// on a weighted system with aggregates that do not divide the rows; with the AVX2 and the
    /// portable kernels alike.
    #[test]
    fn the_fused_pair_applies_the_generic_pair() {
        use crate::solve::block_jacobi::BlockJacobiPair;
        use crate::solve::block_jacobi::tests::{random_vectors, weighted};
        let a = weighted(23);
        let generic = BlockJacobiPair::new(&a.0, &a.1, &a.2, 16).unwrap();
        let mut fused =
            BlockedSystem::with_kind(&a.0, &a.1, &a.2, 16, BlockedKind::JacobiPair).unwrap();
        let jacobi = BlockJacobi::new(&a.0, &a.1, &a.2, 16).unwrap();
        for portable in [false, true] {
            fused.set_portable_kernels(portable);
            for seed in 0..3 {
                let r = random_vectors(529, seed);
                let mut want = vec![[0.0; 3]; 529];
                generic.apply(&r, &mut want);
                let got = fused.precondition(&r);
                let scale = want.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
                for (g, w) in got.iter().zip(&want) {
                    for c in 0..3 {
                        assert!((g[c] - w[c]).abs() <= 1e-12 * scale, "{g:?} vs {w:?}");
                    }
                }
                // Not block Jacobi alone: the second partition contributes.
                let mut one = vec![[0.0; 3]; 529];
                jacobi.apply(&r, &mut one);
                let diff = one
                    .iter()
                    .zip(&want)
                    .map(|(o, w)| (o[0] - w[0]).abs())
                    .fold(0.0, f64::max);
                assert!(diff > 1e-3 * scale, "{diff}");
            }
        }
    }

    /// The fused pair's M⁻¹ is symmetric and positive definite: uᵀM⁻¹v = vᵀM⁻¹u and
    /// uᵀM⁻¹u > 0 for random u, v.
    #[test]
    fn the_fused_pair_is_symmetric_positive_definite() {
        use crate::solve::block_jacobi::tests::{random_vectors, weighted};
        let a = weighted(19);
        let n = 361;
        let sys = BlockedSystem::with_kind(&a.0, &a.1, &a.2, 12, BlockedKind::JacobiPair).unwrap();
        let dot = |a: &[[f64; 3]], b: &[[f64; 3]]| -> [f64; 3] {
            std::array::from_fn(|c| a.iter().zip(b).map(|(a, b)| a[c] * b[c]).sum())
        };
        for seed in 0..4 {
            let (u, v) = (random_vectors(n, 2 * seed), random_vectors(n, 2 * seed + 1));
            let (mu, mv) = (sys.precondition(&u), sys.precondition(&v));
            let (uv, vu, uu) = (dot(&u, &mv), dot(&v, &mu), dot(&u, &mu));
            for c in 0..3 {
                assert!(
                    (uv[c] - vu[c]).abs() <= 1e-12 * uu[c].abs(),
                    "{uv:?} {vu:?}"
                );
                assert!(uu[c] > 0.0);
            }
        }
    }

    /// CG with the fused pair takes the generic loop's iterations with BlockJacobiPair (same
    /// method), fewer than block Jacobi, and reaches the same solution.
    #[test]
    fn the_fused_pair_solve_is_the_generic_pair_solve() {
        use crate::solve::block_jacobi::BlockJacobiPair;
        use crate::solve::block_jacobi::tests::weighted;
        let a = weighted(40);
        let n = 1600;
        let b = test_vector(n);
        let params = CgParams {
            rel_tol: 1e-10,
            ..Default::default()
        };
        let mut x = vec![[0.0; 3]; n];
        let fused = BlockedSystem::with_kind(&a.0, &a.1, &a.2, 16, BlockedKind::JacobiPair)
            .unwrap()
            .solve(&b, &mut x, &params, |_, _| {})
            .unwrap();
        let mut y = vec![[0.0; 3]; n];
        let pre = BlockJacobiPair::new(&a.0, &a.1, &a.2, 16).unwrap();
        let generic = pcg_with(&Op(&a), &pre, &b, &mut y, &params, |_, _| {}).unwrap();
        let mut w = vec![[0.0; 3]; n];
        let jacobi = BlockedSystem::new(&a.0, &a.1, &a.2, 16)
            .unwrap()
            .solve(&b, &mut w, &params, |_, _| {})
            .unwrap();
        assert!(fused.iterations.abs_diff(generic.iterations) <= 1);
        assert!(fused.iterations < jacobi.iterations, "{fused:?} {jacobi:?}");
        let residual = matvec(&a, &x);
        let bn = b.iter().flatten().map(|v| v * v).sum::<f64>().sqrt();
        let rn = residual
            .iter()
            .zip(&b)
            .flat_map(|(r, b)| (0..3).map(move |c| (b[c] - r[c]).powi(2)))
            .sum::<f64>()
            .sqrt();
        assert!(rn <= 2e-10 * bn, "{rn} {bn}");
        for (x, y) in x.iter().zip(&y) {
            for c in 0..3 {
                assert!((x[c] - y[c]).abs() <= 1e-7 * (1.0 + y[c].abs()));
            }
        }
    }
}
