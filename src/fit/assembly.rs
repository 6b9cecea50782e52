//! Assembly of the normal-equation matrix K = Σ_e E_eᵀ G_e E_e into CSR.
//!
//! Input: a [`FitSpace`] and the element blocks G_e ([`ElementBlocks`]). Output: K as a
//! [`NormalMatrix`] with sorted column indices per row.
//!
//! 1. Each element's distinct control points (its columns) are collected once.
//! 2. The sparsity pattern follows from them: row c holds the union of the columns of the
//!    elements that use c (a control point → elements incidence in CSR form, then one sorted
//!    union per row, in parallel).
//! 3. Element matrices are added into the values with atomic adds, in parallel. Most elements
//!    share their local matrix: when E_e is a fixed matrix times a selection of distinct
//!    control points ([`FitSpace::element_pattern`]: spline elements, and Q2 elements made only
//!    of own nodes), the local matrix depends only on the pattern key and the element's weight
//!    pattern, and is computed once per (key, weight pattern).
//!
//! Memory is the CSR itself plus ~30 indices per element, never a triplet list.

use super::{ElementBlocks, FitSpace, NormalMatrix};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// Local matrices shared by elements of one (pattern key, weight mask), in local-node order.
type SharedLocals = HashMap<(u64, u64), Arc<Vec<f64>>>;

/// Dense element matrix on the element's sorted distinct columns.
struct Local {
    ids: Vec<u32>,
    /// m × m, row-major, over `ids`.
    k: Vec<f64>,
}

/// Rᵀ G R for the explicit rows of element `e` (R: nb × m over the sorted distinct columns).
fn local_matrix(space: &dyn FitSpace, e: usize, g: &[f64], nb: usize) -> Local {
    let (mut offsets, mut cols, mut weights) = (Vec::new(), Vec::new(), Vec::new());
    space.element_rows(e, &mut offsets, &mut cols, &mut weights);
    let mut ids = cols.clone();
    ids.sort_unstable();
    ids.dedup();
    let m = ids.len();
    let mut r = vec![0.0; nb * m];
    for i in 0..nb {
        for k in offsets[i]..offsets[i + 1] {
            let j = ids.binary_search(&cols[k]).expect("column of the element");
            r[i * m + j] += weights[k];
        }
    }
    let mut gr = vec![0.0; nb * m];
    for a in 0..nb {
        for b in 0..nb {
            let x = g[a * nb + b];
            if x != 0.0 {
                for j in 0..m {
                    gr[a * m + j] += x * r[b * m + j];
                }
            }
        }
    }
    let mut k = vec![0.0; m * m];
    for a in 0..nb {
        for i in 0..m {
            let ri = r[a * m + i];
            if ri != 0.0 {
                for j in 0..m {
                    k[i * m + j] += ri * gr[a * m + j];
                }
            }
        }
    }
    Local { ids, k }
}

pub(crate) fn atomic_add(slot: &AtomicU64, v: f64) {
    let mut cur = slot.load(Ordering::Relaxed);
    loop {
        let new = (f64::from_bits(cur) + v).to_bits();
        match slot.compare_exchange_weak(cur, new, Ordering::Relaxed, Ordering::Relaxed) {
            Ok(_) => return,
            Err(x) => cur = x,
        }
    }
}

/// Assemble K.
pub fn assemble_matrix(space: &dyn FitSpace, blocks: &ElementBlocks) -> NormalMatrix {
    let ne = space.n_elements();
    let n = space.control_points().len();
    let nb = if space.dim() == 2 { 9 } else { 27 };
    let g_of = |e: usize| -> Vec<f64> {
        let (gd, gr) = &blocks.cache[&blocks.masks[e]];
        gd.iter().zip(gr).map(|(a, b)| a + b).collect()
    };

    // 1. Columns of every element.
    let columns: Vec<Vec<u32>> = (0..ne)
        .into_par_iter()
        .map(|e| match space.element_pattern(e) {
            Some((_, ids)) => {
                let mut ids = ids;
                ids.sort_unstable();
                ids.dedup();
                ids
            }
            None => {
                let (mut o, mut cols, mut w) = (Vec::new(), Vec::new(), Vec::new());
                space.element_rows(e, &mut o, &mut cols, &mut w);
                cols.sort_unstable();
                cols.dedup();
                cols
            }
        })
        .collect();

    // 2. Pattern: control point → elements, then the union of columns per row.
    let mut start = vec![0u32; n + 1];
    for ids in &columns {
        for &c in ids {
            start[c as usize + 1] += 1;
        }
    }
    for c in 0..n {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut incident = vec![0u32; start[n] as usize];
    for (e, ids) in columns.iter().enumerate() {
        for &c in ids {
            incident[fill[c as usize] as usize] = e as u32;
            fill[c as usize] += 1;
        }
    }
    drop(fill);
    // A per-thread marker (last row that took each column) dedups before sorting, so only
    // the ~115 distinct columns are sorted instead of the ~27 × 27 incident ones. Two passes
    // (lengths, then the columns into their final place) avoid a vector per row; at most ~32
    // markers are made per pass (one per split), not one per row range rayon cuts.
    let row_columns = |mark: &mut Vec<u32>, c: usize, cols: &mut Vec<u32>| {
        cols.clear();
        for &e in &incident[start[c] as usize..start[c + 1] as usize] {
            for &j in &columns[e as usize] {
                if mark[j as usize] != c as u32 {
                    mark[j as usize] = c as u32;
                    cols.push(j);
                }
            }
        }
        cols.sort_unstable();
    };
    let split = (n / 32).max(1024);
    let marker = || (vec![u32::MAX; n], Vec::new());
    let lengths: Vec<usize> = (0..n)
        .into_par_iter()
        .with_min_len(split)
        .map_init(marker, |(mark, cols), c| {
            row_columns(mark, c, cols);
            cols.len()
        })
        .collect();
    let mut indptr = Vec::with_capacity(n + 1);
    indptr.push(0usize);
    for l in lengths {
        indptr.push(indptr.last().unwrap() + l);
    }
    let mut indices = vec![0u32; indptr[n]];
    crate::solve::block_jacobi::split_at_offsets(&mut indices, &indptr)
        .into_par_iter()
        .enumerate()
        .with_min_len(split)
        .for_each_init(marker, |(mark, cols), (c, row)| {
            row_columns(mark, c, cols);
            row.copy_from_slice(cols);
        });
    drop(incident);
    let values: Vec<AtomicU64> = (0..indices.len()).map(|_| AtomicU64::new(0)).collect();

    // 3. Values. Shared local matrices by (pattern key, weight mask), in local-node order.
    let shared: Mutex<SharedLocals> = Mutex::new(HashMap::new());
    (0..ne).into_par_iter().for_each(|e| {
        let (ids, k): (Vec<u32>, Arc<Vec<f64>>) = match space.element_pattern(e) {
            Some((key, local_ids)) => {
                let mask = blocks.masks[e];
                let cached = shared
                    .lock()
                    .expect("no panics while held")
                    .get(&(key, mask))
                    .cloned();
                let k = cached.unwrap_or_else(|| {
                    // Local-node order: permute the sorted-column matrix back to `local_ids`.
                    let l = local_matrix(space, e, &g_of(e), nb);
                    let pos: Vec<usize> = local_ids
                        .iter()
                        .map(|c| l.ids.binary_search(c).unwrap())
                        .collect();
                    let m = local_ids.len();
                    let mut k = vec![0.0; m * m];
                    for i in 0..m {
                        for j in 0..m {
                            k[i * m + j] = l.k[pos[i] * l.ids.len() + pos[j]];
                        }
                    }
                    let k = Arc::new(k);
                    shared
                        .lock()
                        .expect("no panics while held")
                        .insert((key, mask), k.clone());
                    k
                });
                (local_ids, k)
            }
            None => {
                let l = local_matrix(space, e, &g_of(e), nb);
                (l.ids, Arc::new(l.k))
            }
        };
        let m = ids.len();
        for i in 0..m {
            let row = ids[i] as usize;
            let cols = &indices[indptr[row]..indptr[row + 1]];
            for j in 0..m {
                let v = k[i * m + j];
                if v != 0.0 {
                    let at = cols
                        .binary_search(&ids[j])
                        .expect("pattern holds the element's columns");
                    atomic_add(&values[indptr[row] + at], v);
                }
            }
        }
    });
    let data = values
        .into_iter()
        .map(|a| f64::from_bits(a.into_inner()))
        .collect();
    NormalMatrix {
        n,
        indptr,
        indices,
        data,
    }
}
