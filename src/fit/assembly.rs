//! Assembly of the normal-equation matrix K = Σ_e E_eᵀ G_e E_e into CSR.
//!
//! Input: a [`FitSpace`] and the element blocks G_e ([`ElementBlocks`]). Output: K as a
//! [`NormalMatrix`] with sorted column indices per row, its values stored by row template
//! where rows repeat (step 4).
//!
//! 1. **Element columns and local matrices.** Every element gets its list of distinct control
//!    points (its columns, flat CSR over the elements) and a dense local matrix
//!    Rᵀ G_e R over them. Most elements share it: when E_e is a fixed matrix times a selection
//!    of distinct control points ([`FitSpace::element_pattern`]: spline elements, and Q2
//!    elements made only of own nodes), the local matrix depends only on the pattern key and
//!    the element's weight mask, so one table entry per (key, mask) is computed up front, in
//!    parallel, and the element keeps an index into it. Elements with graded knots are the
//!    same product of 1D matrices, but their own: their matrices are formed from the 1D
//!    factors into one flat array ([`FitSpace::element_factors`]). The other elements (Q2
//!    elements with constrained nodes) keep their own matrix, from E_e's explicit rows.
//! 2. **Incidence.** Control point → (element, local index) in CSR form, filled in element
//!    order.
//! 3. **Rows, in parallel and without atomics.** Row c is built by its own task: the union of
//!    the columns of its incident elements (a per-thread marker dedups them; only the ~100
//!    distinct ones are sorted, through a per-thread bitmap when they span a narrow range of
//!    indices), then a per-thread column → position map scatters row i of
//!    each incident element's local matrix into the row. A first pass counts the row lengths,
//!    the second writes columns and values in place. The values of an entry are summed over
//!    the incident elements in element order, so K is the same on any thread count.
//! 4. **Row templates.** The values are computed a chunk of rows at a time (1/16 of them)
//!    and reduced to row templates (distinct value sequences, matched by exact bits; K depends
//!    on the topology and the weights, not the geometry: on a 52,728-hex cylinder 898
//!    templates cover the 61,180 rows): the 8 bytes per entry of a CSR value array are
//!    never held, only the columns (4 bytes per entry), one chunk's values and the templates.
//!    Where the templates come to hold more than half of the values seen (little repetition),
//!    the plain value array is written from then on instead.
//!
//! Memory besides K itself: per element ~27 column indices, 27 incidence entries (6 bytes
//! each), a table index and a 16-byte tag; the shared table (one 27 × 27 matrix per (key,
//! mask): a handful on regular meshes) and the own matrices of the constrained elements. No
//! triplet list, no value array for repeating rows, no per-element allocation for pattern
//! elements.

use super::{ElementBlocks, FitSpace, NormalMatrix};
use crate::math::bernstein::net_len;
use crate::solve::block_jacobi::split_at_offsets;
use crate::solve::blocked::{RowTemplates, hash_row};
use rayon::prelude::*;
use std::collections::HashMap;

/// Dense element matrix on the element's sorted distinct columns.
struct Local {
    ids: Vec<u32>,
    /// m × m, row-major, over `ids`.
    k: Vec<f64>,
}

/// The buffers of [`local_matrix`], one set per thread: the element's rows, its block G,
/// the rows' local column indices and G R (a graded mesh computes one matrix per element).
#[derive(Default)]
struct Scratch {
    offsets: Vec<usize>,
    cols: Vec<u32>,
    weights: Vec<f64>,
    local: Vec<usize>,
    g: Vec<f64>,
    gr: Vec<f64>,
}

/// Rᵀ G R for the explicit rows of element `e` (R: nb × m over the sorted distinct columns;
/// G the block of its weight mask), through R's non-zeros: G R column by column, then
/// Rᵀ (G R) row by row.
fn local_matrix(
    space: &dyn FitSpace,
    e: usize,
    blocks: &ElementBlocks,
    nb: usize,
    s: &mut Scratch,
) -> Local {
    let Scratch {
        offsets,
        cols,
        weights,
        local,
        g,
        gr,
    } = s;
    space.element_rows(e, offsets, cols, weights);
    let (gd, gs) = &blocks.cache[&blocks.masks[e]];
    g.clear();
    g.extend(gd.iter().zip(gs).map(|(a, b)| a + b));
    let mut ids = cols.clone();
    ids.sort_unstable();
    ids.dedup();
    let m = ids.len();
    local.clear();
    local.extend(
        cols.iter()
            .map(|c| ids.binary_search(c).expect("column of the element")),
    );
    gr.clear();
    gr.resize(nb * m, 0.0);
    for b in 0..nb {
        for k in offsets[b]..offsets[b + 1] {
            let (j, w) = (local[k], weights[k]);
            for a in 0..nb {
                gr[a * m + j] += g[a * nb + b] * w;
            }
        }
    }
    let mut k = vec![0.0; m * m];
    for a in 0..nb {
        let gra = &gr[a * m..(a + 1) * m];
        for t in offsets[a]..offsets[a + 1] {
            let (i, w) = (local[t], weights[t]);
            for (kij, g) in k[i * m..(i + 1) * m].iter_mut().zip(gra) {
                *kij += w * g;
            }
        }
    }
    Local { ids, k }
}

pub(crate) fn atomic_add(slot: &std::sync::atomic::AtomicU64, v: f64) {
    use std::sync::atomic::Ordering;
    let mut cur = slot.load(Ordering::Relaxed);
    loop {
        let new = (f64::from_bits(cur) + v).to_bits();
        match slot.compare_exchange_weak(cur, new, Ordering::Relaxed, Ordering::Relaxed) {
            Ok(_) => return,
            Err(x) => cur = x,
        }
    }
}

/// Sort the distinct columns `cols` of a row. When they span few 64-bit words, as they do
/// on meshes numbered with some locality, they are set in the all-zero bitmap `bits` and read
/// back in order (clearing it again), which is far cheaper than a comparison sort.
fn sort_columns(cols: &mut [u32], bits: &mut [u64]) {
    let (Some(&lo), Some(&hi)) = (cols.iter().min(), cols.iter().max()) else {
        return;
    };
    let (lo, hi) = (lo as usize / 64, hi as usize / 64);
    if hi - lo > 4 * cols.len() {
        cols.sort_unstable();
        return;
    }
    for &j in cols.iter() {
        bits[j as usize / 64] |= 1 << (j % 64);
    }
    let mut out = 0;
    for (w, word) in bits[lo..=hi].iter_mut().enumerate() {
        let mut x = std::mem::take(word);
        while x != 0 {
            cols[out] = ((lo + w) * 64) as u32 + x.trailing_zeros();
            out += 1;
            x &= x - 1;
        }
    }
}

/// Rᵀ G R for an element whose E_e is (M_z ⊗ M_y ⊗ M_x) times a selection of distinct
/// control points ([`FitSpace::element_factors`]), over its local nodes in order: R's entries
/// are the products of the 1D matrices' entries, so neither R's rows nor a column order are
/// built. `k` (nb × nb) receives it; the sums run in the order of [`local_matrix`]'s (over
/// R's rows, then G's), so both give the same bits.
fn factored_matrix(m: &[[[f64; 3]; 3]; 3], (gd, gs): &(Vec<f64>, Vec<f64>), k: &mut [f64]) {
    let nb = k.len().isqrt();
    let mut g = [0.0; 27 * 27];
    for ((g, a), b) in g.iter_mut().zip(gd).zip(gs) {
        *g = a + b;
    }
    let mut r = [0.0; 27 * 27];
    for b in 0..nb {
        let (bx, by, bz) = (b % 3, (b / 3) % 3, b / 9);
        for l in 0..nb {
            r[b * nb + l] = m[0][bx][l % 3] * m[1][by][(l / 3) % 3] * m[2][bz][l / 9];
        }
    }
    let mut gr = [0.0; 27 * 27];
    for b in 0..nb {
        for l in 0..nb {
            let w = r[b * nb + l];
            if w != 0.0 {
                for a in 0..nb {
                    gr[a * nb + l] += g[a * nb + b] * w;
                }
            }
        }
    }
    k.fill(0.0);
    for a in 0..nb {
        let gra = &gr[a * nb..(a + 1) * nb];
        for i in 0..nb {
            let w = r[a * nb + i];
            if w != 0.0 {
                for (kij, g) in k[i * nb..(i + 1) * nb].iter_mut().zip(gra) {
                    *kij += w * g;
                }
            }
        }
    }
}

/// Where an element's local matrix lives.
enum Matrix {
    /// A pattern element, by its pattern key (its shared-table entry follows from the key and
    /// its weight mask).
    Shared(u64),
    /// A factored element of its own (graded knots), by its index among them: its nb × nb
    /// matrix over its local nodes is a slice of `ElementMatrices::factored`.
    Factored(u32),
    /// The element's own matrix (its columns are `Local::ids`), boxed so that the tag stays
    /// 16 bytes per element.
    Own(Box<Local>),
}

/// The element matrices of K: each element's columns (`elem_cols[elem_ptr[e]..]`, in the
/// pattern's node order for pattern elements) and its matrix, shared by the elements of one
/// (pattern, weight mask) through `table`.
struct ElementMatrices {
    kinds: Vec<Matrix>,
    elem_ptr: Vec<usize>,
    elem_cols: Vec<u32>,
    table_index: Vec<u32>,
    table: Vec<Vec<f64>>,
    /// The matrices of the [`Matrix::Factored`] elements, nb × nb each, flat.
    factored: Vec<f64>,
    nb: usize,
}

impl ElementMatrices {
    fn matrix(&self, e: usize) -> &[f64] {
        match &self.kinds[e] {
            Matrix::Shared(_) => &self.table[self.table_index[e] as usize],
            Matrix::Factored(i) => {
                let len = self.nb * self.nb;
                &self.factored[*i as usize * len..(*i as usize + 1) * len]
            }
            Matrix::Own(l) => &l.k,
        }
    }
}

/// Step 1 of the assembly: pattern keys (or own matrices), the element columns, flat, and the
/// shared table.
fn element_matrices(space: &dyn FitSpace, blocks: &ElementBlocks) -> ElementMatrices {
    let ne = space.n_elements();
    let nb = net_len(space.dim());

    let mut kinds: Vec<Matrix> = (0..ne)
        .into_par_iter()
        .map_init(
            || (Vec::new(), Scratch::default()),
            |(ids, scratch), e| match space.element_pattern(e, ids) {
                Some(key) => Matrix::Shared(key),
                None if space.element_factors(e, ids).is_some() => Matrix::Factored(u32::MAX),
                None => Matrix::Own(Box::new(local_matrix(space, e, blocks, nb, scratch))),
            },
        )
        .collect();
    // The factored elements' matrices, flat and in element order: no allocation per element.
    let mut factored_elements = Vec::new();
    for (e, k) in kinds.iter_mut().enumerate() {
        if let Matrix::Factored(i) = k {
            *i = factored_elements.len() as u32;
            factored_elements.push(e);
        }
    }
    let mut factored = vec![0.0; factored_elements.len() * nb * nb];
    factored
        .par_chunks_mut(nb * nb)
        .zip(&factored_elements)
        .for_each_init(Vec::new, |ids, (k, &e)| {
            let m = space.element_factors(e, ids).expect("a factored element");
            factored_matrix(&m, &blocks.cache[&blocks.masks[e]], k);
        });
    let mut elem_ptr = Vec::with_capacity(ne + 1);
    elem_ptr.push(0usize);
    for k in &kinds {
        let m = match k {
            Matrix::Shared(_) | Matrix::Factored(_) => nb,
            Matrix::Own(l) => l.ids.len(),
        };
        elem_ptr.push(elem_ptr[elem_ptr.len() - 1] + m);
    }
    let mut elem_cols = vec![0u32; elem_ptr[ne]];
    split_at_offsets(&mut elem_cols, &elem_ptr)
        .into_par_iter()
        .enumerate()
        .for_each_init(Vec::new, |ids, (e, out)| match &kinds[e] {
            Matrix::Shared(_) => {
                space.element_pattern(e, ids);
                out.copy_from_slice(ids);
            }
            Matrix::Factored(_) => {
                space.element_factors(e, ids);
                out.copy_from_slice(ids);
            }
            Matrix::Own(l) => out.copy_from_slice(&l.ids),
        });

    // The shared table: one representative element per (key, mask), in element order, and
    // each pattern element's entry.
    let mut slot_of: HashMap<(u64, u64), u32> = HashMap::new();
    let mut representatives = Vec::new();
    let table_index: Vec<u32> = kinds
        .iter()
        .enumerate()
        .map(|(e, k)| match k {
            Matrix::Shared(key) => *slot_of.entry((*key, blocks.masks[e])).or_insert_with(|| {
                representatives.push(e);
                representatives.len() as u32 - 1
            }),
            Matrix::Factored(_) | Matrix::Own(_) => u32::MAX,
        })
        .collect();
    drop(slot_of);
    // Local-node order: permute the sorted-column matrix back to the pattern's node order.
    let table: Vec<Vec<f64>> = representatives
        .par_iter()
        .map_init(Scratch::default, |scratch, &e| {
            let l = local_matrix(space, e, blocks, nb, scratch);
            let local_ids = &elem_cols[elem_ptr[e]..elem_ptr[e + 1]];
            let pos: Vec<usize> = local_ids
                .iter()
                .map(|c| l.ids.binary_search(c).expect("column of the element"))
                .collect();
            let m = local_ids.len();
            let mut k = vec![0.0; m * m];
            for i in 0..m {
                for j in 0..m {
                    k[i * m + j] = l.k[pos[i] * l.ids.len() + pos[j]];
                }
            }
            k
        })
        .collect();
    ElementMatrices {
        kinds,
        elem_ptr,
        elem_cols,
        table_index,
        table,
        factored,
        nb,
    }
}

/// Step 2 of the assembly, the incidence: control point c's (element, local index) pairs are
/// `start[c]..start[c + 1]` of `inc_elem` and `inc_local`, in element order.
struct Incidence {
    start: Vec<usize>,
    inc_elem: Vec<u32>,
    inc_local: Vec<u16>,
}

fn incidence(elem_cols: &[u32], elem_ptr: &[usize], n: usize) -> Incidence {
    let ne = elem_ptr.len() - 1;
    let mut start = vec![0usize; n + 1];
    for &c in elem_cols {
        start[c as usize + 1] += 1;
    }
    for c in 0..n {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut inc_elem = vec![0u32; start[n]];
    let mut inc_local = vec![0u16; start[n]];
    for e in 0..ne {
        let cols = &elem_cols[elem_ptr[e]..elem_ptr[e + 1]];
        assert!(
            cols.len() <= u16::MAX as usize,
            "element {e} has too many columns"
        );
        for (i, &c) in cols.iter().enumerate() {
            let f = &mut fill[c as usize];
            inc_elem[*f] = e as u32;
            inc_local[*f] = i as u16;
            *f += 1;
        }
    }
    Incidence {
        start,
        inc_elem,
        inc_local,
    }
}

impl Incidence {
    /// Control point c's (element, local index) pairs, in element order.
    fn of(&self, c: usize) -> impl Iterator<Item = (&u32, &u16)> {
        let r = self.start[c]..self.start[c + 1];
        self.inc_elem[r.clone()].iter().zip(&self.inc_local[r])
    }
}

/// Row c's distinct columns, unsorted, into `cols`: the union of its incident elements'
/// columns. `mark[j] == c` once column j is in the row (a marker per thread, not per row).
fn row_columns(
    em: &ElementMatrices,
    inc: &Incidence,
    mark: &mut [u32],
    c: usize,
    cols: &mut Vec<u32>,
) {
    cols.clear();
    for (&e, _) in inc.of(c) {
        let e = e as usize;
        for &j in &em.elem_cols[em.elem_ptr[e]..em.elem_ptr[e + 1]] {
            if mark[j as usize] != c as u32 {
                mark[j as usize] = c as u32;
                cols.push(j);
            }
        }
    }
}

/// The n + 1 row offsets of K: the rows' lengths counted in parallel (splits of at least
/// `split` rows, one marker each), then summed.
fn row_offsets(em: &ElementMatrices, inc: &Incidence, n: usize, split: usize) -> Vec<usize> {
    let lengths: Vec<usize> = (0..n)
        .into_par_iter()
        .with_min_len(split)
        .map_init(
            || (vec![u32::MAX; n], Vec::new()),
            |(mark, cols), c| {
                row_columns(em, inc, mark, c, cols);
                cols.len()
            },
        )
        .collect();
    let mut indptr = Vec::with_capacity(n + 1);
    indptr.push(0usize);
    for l in lengths {
        indptr.push(indptr[indptr.len() - 1] + l);
    }
    indptr
}

/// Row c's values over its columns `cols` into `row_vals`: row i of each incident element's
/// matrix scattered through `pos` (column → position, set here), summed in element order.
fn sum_row(
    em: &ElementMatrices,
    inc: &Incidence,
    c: usize,
    cols: &[u32],
    pos: &mut [u32],
    row_vals: &mut [f64],
) {
    // Written before the sums read it: see `block_jacobi::factor_blocks`.
    row_vals.fill(0.0);
    for (p, &j) in cols.iter().enumerate() {
        pos[j as usize] = p as u32;
    }
    for (&e, &i) in inc.of(c) {
        let e = e as usize;
        let ids = &em.elem_cols[em.elem_ptr[e]..em.elem_ptr[e + 1]];
        let m = ids.len();
        let k = &em.matrix(e)[i as usize * m..(i as usize + 1) * m];
        for (&j, &v) in ids.iter().zip(k) {
            row_vals[pos[j as usize] as usize] += v;
        }
    }
}

/// Assemble K.
pub fn assemble_matrix(space: &dyn FitSpace, blocks: &ElementBlocks) -> NormalMatrix {
    let n = space.control_points().len();
    assemble_rows(space, blocks, (n / CHUNKS).max(MIN_CHUNK_ROWS), Some(2))
}

/// Row chunks of the value pass (each chunk's values are held at once, then reduced to
/// templates), and their least size.
const CHUNKS: usize = 16;
const MIN_CHUNK_ROWS: usize = 1 << 14;

/// [`assemble_matrix`] with the values computed `chunk_rows` rows at a time and, given
/// `Some(share)`, stored by row template while the templates hold at most 1/share of the
/// values seen (K's rows repeat on meshes with regular topology; otherwise the plain value
/// array is written from then on, as it is throughout for `None`).
fn assemble_rows(
    space: &dyn FitSpace,
    blocks: &ElementBlocks,
    chunk_rows: usize,
    template_share: Option<usize>,
) -> NormalMatrix {
    let n = space.control_points().len();
    let em = element_matrices(space, blocks);
    // Where most elements have a matrix of their own (graded knots), K's rows hardly repeat:
    // the first chunk's templates would only be expanded again.
    let own = em
        .kinds
        .iter()
        .filter(|k| !matches!(k, Matrix::Shared(_)))
        .count();
    let template_share = template_share.filter(|_| 2 * own <= em.kinds.len());
    let inc = incidence(&em.elem_cols, &em.elem_ptr, n);

    // 3. Rows.
    let row_columns =
        |mark: &mut Vec<u32>, c: usize, cols: &mut Vec<u32>| row_columns(&em, &inc, mark, c, cols);
    let split = (n / 32).max(1024);
    let indptr = row_offsets(&em, &inc, n, split);
    let mut indices = vec![0u32; indptr[n]];
    // The values: row templates, or the whole value array once they stop paying.
    let mut table = template_share.map(|_| RowTemplates::default());
    let mut row_template: Vec<u32> = Vec::new();
    let mut data: Vec<f64> = Vec::new();
    let mut chunk_values: Vec<f64> = Vec::new();
    let chunk_rows = chunk_rows.max(1);
    let mut r0 = 0;
    while r0 < n {
        let r1 = (r0 + chunk_rows).min(n);
        let (lo, hi) = (indptr[r0], indptr[r1]);
        let offsets: Vec<usize> = indptr[r0..=r1].iter().map(|&o| o - lo).collect();
        let values: &mut [f64] = if table.is_some() {
            chunk_values.resize(hi - lo, 0.0);
            &mut chunk_values
        } else {
            if data.is_empty() {
                data = vec![0.0; indptr[n]];
            }
            &mut data[lo..hi]
        };
        split_at_offsets(&mut indices[lo..hi], &offsets)
            .into_par_iter()
            .zip(split_at_offsets(values, &offsets))
            .enumerate()
            .with_min_len((split / 4).max(256))
            .for_each_init(
                || {
                    let bits = vec![0u64; n.div_ceil(64)];
                    (vec![u32::MAX; n], vec![0u32; n], bits, Vec::new())
                },
                |(mark, pos, bits, cols), (i, (row_cols, row_vals))| {
                    let c = r0 + i;
                    row_columns(mark, c, cols);
                    sort_columns(cols, bits);
                    row_cols.copy_from_slice(cols);
                    sum_row(&em, &inc, c, cols, pos, row_vals);
                },
            );
        if let Some(t) = &mut table {
            let rows = &offsets;
            let chunk = &chunk_values;
            row_template.extend(t.add_rows(r1 - r0, |i| &chunk[rows[i]..rows[i + 1]], hash_row));
            if template_share.unwrap_or(0).saturating_mul(t.values.len()) > hi {
                // Few repeats: the templates would cost as much as the values.
                data = super::normal_matrix::expand(&indptr, &row_template, t);
                table = None;
                row_template = Vec::new();
                chunk_values = Vec::new();
            }
        }
        r0 = r1;
    }
    match table {
        Some(t) => NormalMatrix::from_templates(indptr, indices, row_template, t),
        None => NormalMatrix::new(n, indptr, indices, data),
    }
}

/// K's values left unsummed: the element matrices and the incidence the rows are summed from
/// ([`assemble_deferred`]). The host sums a row when asked ([`RowSums::row`], the arithmetic of
/// [`assemble_matrix`], so the same bits); a device sums all of them from [`RowSums::tables`]
/// and [`RowSums::incidence`] (the GPU's `assemble` kernel).
pub struct RowSums {
    em: ElementMatrices,
    inc: Incidence,
}

/// The element matrices flat, as a device reads them: per element (and one past the last)
/// its first column in `elem_cols` and the offset of its m × m matrix (row-major over its
/// columns, m the element's column count) in `mats`.
pub struct ElementTables<'a> {
    pub elements: Vec<[u32; 2]>,
    pub elem_cols: &'a [u32],
    pub mats: Vec<f64>,
    /// Bits of the local index in a packed incidence entry (`element << bits | local`).
    pub local_bits: u32,
}

impl RowSums {
    /// The number of rows.
    pub fn n(&self) -> usize {
        self.inc.start.len() - 1
    }

    /// Row c's values over its sorted columns `cols` (f64, the bits of [`assemble_matrix`]'s),
    /// with `pos` a column → position scratch of n entries.
    pub fn row(&self, c: usize, cols: &[u32], pos: &mut [u32], out: &mut [f64]) {
        sum_row(&self.em, &self.inc, c, cols, pos, out);
    }

    /// The diagonal: per row, its incident elements' diagonal entries summed in element order
    /// (each element holds the row's own column once), the bits of the assembled diagonal.
    pub fn diagonal(&self) -> Vec<f64> {
        (0..self.n())
            .into_par_iter()
            .with_min_len(1024)
            .map(|c| {
                let mut s = 0.0;
                for (&e, &i) in self.inc.of(c) {
                    let e = e as usize;
                    let m = self.em.elem_ptr[e + 1] - self.em.elem_ptr[e];
                    s += self.em.matrix(e)[i as usize * (m + 1)];
                }
                s
            })
            .collect()
    }

    /// What a device reads the sums from, in entries: the element matrices' values, the
    /// elements' columns, the elements (and one past the last) and the incidence.
    pub fn device_entries(&self) -> [usize; 4] {
        let em = &self.em;
        let own: usize = em
            .kinds
            .iter()
            .map(|k| match k {
                Matrix::Own(l) => l.k.len(),
                _ => 0,
            })
            .sum();
        let mats = em.table.iter().map(Vec::len).sum::<usize>() + em.factored.len() + own;
        [
            mats,
            em.elem_cols.len(),
            em.kinds.len() + 1,
            self.inc.inc_elem.len(),
        ]
    }

    /// The element matrices as one flat table (the shared (pattern, mask) entries once, then
    /// the own matrices), or why a 32-bit device index cannot address them.
    pub fn tables(&self) -> Result<ElementTables<'_>, String> {
        let em = &self.em;
        let ne = em.kinds.len();
        let mut mats: Vec<f64> = Vec::new();
        let mut table_at = Vec::with_capacity(em.table.len());
        for t in &em.table {
            table_at.push(mats.len());
            mats.extend_from_slice(t);
        }
        let factored_at = mats.len();
        mats.extend_from_slice(&em.factored);
        let mut elements = Vec::with_capacity(ne + 1);
        let mut max_m = 1;
        for e in 0..ne {
            let m = em.elem_ptr[e + 1] - em.elem_ptr[e];
            max_m = max_m.max(m);
            let at = match &em.kinds[e] {
                Matrix::Shared(_) => table_at[em.table_index[e] as usize],
                Matrix::Factored(i) => factored_at + *i as usize * em.nb * em.nb,
                Matrix::Own(l) => {
                    mats.extend_from_slice(&l.k);
                    mats.len() - l.k.len()
                }
            };
            elements.push([em.elem_ptr[e], at]);
        }
        elements.push([em.elem_ptr[ne], 0]);
        let local_bits = usize::BITS - (max_m - 1).leading_zeros();
        let fits = |x: usize| u32::try_from(x).is_ok();
        if !fits(mats.len()) || !fits(em.elem_cols.len()) || !fits(ne << local_bits) {
            return Err(format!(
                "{ne} elements with {} matrix entries exceed 32-bit indices",
                mats.len()
            ));
        }
        Ok(ElementTables {
            elements: elements
                .iter()
                .map(|&[c, m]| [c as u32, m as u32])
                .collect(),
            elem_cols: &em.elem_cols,
            mats,
            local_bits,
        })
    }

    /// The incidence of rows `rows` as a device reads it: offsets relative to the first row's
    /// (one per row and one past the last) and entries `element << local_bits | local index`,
    /// in element order.
    pub fn incidence(&self, rows: std::ops::Range<usize>, local_bits: u32) -> (Vec<u32>, Vec<u32>) {
        let inc = &self.inc;
        let (k0, k1) = (inc.start[rows.start], inc.start[rows.end]);
        let start = inc.start[rows.start..=rows.end]
            .iter()
            .map(|&k| (k - k0) as u32)
            .collect();
        let packed = inc.inc_elem[k0..k1]
            .iter()
            .zip(&inc.inc_local[k0..k1])
            .map(|(&e, &i)| (e << local_bits) | i as u32)
            .collect();
        (start, packed)
    }

    /// Every row's values over the columns `indices` (rows `indptr`), times d_r d_c when
    /// `scale` is given: the value array of [`assemble_matrix`] (and its scaling) to the bit.
    pub fn values(&self, indptr: &[usize], indices: &[u32], scale: Option<&[f64]>) -> Vec<f64> {
        let n = self.n();
        let mut data = vec![0.0; indptr[n]];
        split_at_offsets(&mut data, indptr)
            .into_par_iter()
            .enumerate()
            .with_min_len(256)
            .for_each_init(
                || vec![0u32; n],
                |pos, (c, row)| {
                    let cols = &indices[indptr[c]..indptr[c + 1]];
                    self.row(c, cols, pos, row);
                    if let Some(d) = scale {
                        super::normal_matrix::scale_row(cols, d, c, row);
                    }
                },
            );
        data
    }
}

/// K with its structure (row offsets and sorted columns) and its values left to whoever
/// solves with it ([`RowSums`]): a device that sums the rows itself never receives them, and
/// the host sums them with [`assemble_matrix`]'s bits when it needs them.
pub fn assemble_deferred(space: &dyn FitSpace, blocks: &ElementBlocks) -> NormalMatrix {
    let n = space.control_points().len();
    let em = element_matrices(space, blocks);
    let inc = incidence(&em.elem_cols, &em.elem_ptr, n);
    let split = (n / 32).max(1024);
    let indptr = row_offsets(&em, &inc, n, split);
    let mut indices = vec![0u32; indptr[n]];
    split_at_offsets(&mut indices, &indptr)
        .into_par_iter()
        .enumerate()
        .with_min_len((split / 4).max(256))
        .for_each_init(
            || (vec![u32::MAX; n], vec![0u64; n.div_ceil(64)], Vec::new()),
            |(mark, bits, cols), (c, out)| {
                row_columns(&em, &inc, mark, c, cols);
                sort_columns(cols, bits);
                out.copy_from_slice(cols);
            },
        );
    NormalMatrix::deferred(indptr, indices, std::sync::Arc::new(RowSums { em, inc }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{FitWeights, assemble};
    use crate::mesh::Topology;
    use crate::mesh::generate::{Kind, generate};
    use crate::solve::CgParams;
    use crate::spline::SplineSpace;

    /// The assembly stores K's values by row template without ever holding the value array
    /// (a small fraction of the values on a cylinder, whose rows repeat), with the bits of the
    /// plain assembly; falling back to the plain array part-way gives them too; and the
    /// default blocked CG on the templated matrix gives the bits of the CG on the plain one.
    #[test]
    fn templated_rows_are_the_plain_assembly_and_solve_alike() {
        let m = generate(Kind::Cylinder, 3000);
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        let w = FitWeights::position();
        let blocks = ElementBlocks::new(&s, &m, &t, &w);
        let n = s.control_points().len();
        let plain = assemble_rows(&s, &blocks, n, None);
        let nnz = plain.indices().len();
        let bits = |k: &NormalMatrix| k.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(plain.n_templates(), None);
        let templated = assemble_rows(&s, &blocks, 97, Some(2));
        let n_templates = templated.n_templates().expect("rows stored by template");
        assert!(n_templates * 2 < n, "{n_templates} templates for {n} rows");
        let switched = assemble_rows(&s, &blocks, 97, Some(usize::MAX));
        assert_eq!(switched.n_templates(), None);
        for k in [&templated, &switched] {
            assert_eq!(k.indptr(), plain.indptr());
            assert_eq!(k.indices(), plain.indices());
            assert_eq!(bits(k), bits(&plain));
        }
        assert_eq!(
            assemble_matrix(&s, &blocks).n_templates(),
            Some(n_templates)
        );
        assert!(nnz > 50 * n);

        let (_, b) = assemble(&s, &m, &t, &w);
        let cg = CgParams::default();
        assert!(cg.preconditioner.blocked().is_some());
        let solve = |k: NormalMatrix| {
            let mut x = vec![[0.0; 3]; n];
            let info = k.pcg(&b, &mut x, &cg, |_: usize, _: f64| {}).unwrap();
            (
                info.iterations,
                x.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>(),
            )
        };
        let (it, x) = solve(templated);
        assert!(it > 5);
        assert_eq!((it, x), solve(plain));
    }

    /// The space's elements with their explicit rows only (no pattern, no factors).
    struct RowsOnly<'a>(&'a SplineSpace);

    impl FitSpace for RowsOnly<'_> {
        fn dim(&self) -> usize {
            self.0.dim
        }
        fn n_elements(&self) -> usize {
            self.0.n_elements()
        }
        fn control_points(&self) -> &[[f64; 3]] {
            &self.0.control_points
        }
        fn element_rows(
            &self,
            e: usize,
            offsets: &mut Vec<usize>,
            cols: &mut Vec<u32>,
            weights: &mut Vec<f64>,
        ) {
            self.0.element_rows(e, offsets, cols, weights)
        }
        fn bezier_net_with(&self, e: usize, cps: &[[f64; 3]]) -> crate::math::BezierNet {
            self.0.bezier_net_with(e, cps)
        }
    }

    /// With graded knots (every spline element its own 1D matrices) the matrices formed from
    /// the 1D factors give K with the bits of the matrices formed from E_e's explicit rows, in
    /// 2D and 3D, and K is stored as plain values (its rows do not repeat).
    #[test]
    fn factored_graded_matrices_are_the_explicit_rows_alike() {
        for (kind, n) in [(Kind::Disc, 400), (Kind::Cylinder, 1500)] {
            let m = generate(kind, n);
            let t = Topology::build(&m);
            // Knot weights of a graded grid, different per element and direction.
            let weights: Vec<_> = (0..m.n_elements())
                .map(|e| {
                    let f = |k: usize| 0.3 + 0.4 * (((e * 7 + k * 3) % 11) as f64 / 10.0);
                    [[f(0), f(1)], [f(2), f(3)], [f(4), f(5)]]
                })
                .collect();
            let s = SplineSpace::build_with_knots(&m, &t, &[], Some(&weights));
            let factored = (0..s.n_elements())
                .filter(|&e| s.element_factors(e, &mut Vec::new()).is_some())
                .filter(|&e| s.element_pattern(e, &mut Vec::new()).is_none())
                .count();
            assert!(
                2 * factored > s.n_elements(),
                "{factored} factored elements"
            );
            let w = FitWeights::position();
            let blocks = ElementBlocks::new(&s, &m, &t, &w);
            let n = s.control_points().len();
            let fast = assemble_matrix(&s, &blocks);
            assert_eq!(fast.n_templates(), None);
            let rows = assemble_rows(&RowsOnly(&s), &blocks, n, None);
            let bits = |k: &NormalMatrix| k.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(fast.indptr(), rows.indptr());
            assert_eq!(fast.indices(), rows.indices());
            assert!(bits(&fast) == bits(&rows), "{kind:?}: K differs");
        }
    }
}
