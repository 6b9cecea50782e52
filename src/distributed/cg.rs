//! The fit's normal equations solved across ranks: each rank holds the rows of the control
//! points its elements touch, assembled from its own elements only, and the ranks run one
//! block-Jacobi-preconditioned CG together.
//!
//! Input: this rank's share K_s, F_s of the system ([`crate::fit::partial`]), the control
//! points each rank touches ([`Halo`]). Output: the displacement δ on this rank's control
//! points, the same (to the CG tolerance) as the serial solve of K δ = F.
//!
//! **Vectors.** Every vector is stored on the rank's local control points, fully summed
//! ("consistent"): a control point shared by several ranks has the same value on each.
//! K x is the sum of the shares' products: each rank multiplies by its K_s, then the ranks
//! sharing a control point exchange their partial values and add them **in rank order**, so
//! every copy is bit-identical (a different order per rank would let the copies drift apart
//! by rounding over the iterations). Dot products count each control point once, on its owner
//! (the lowest rank touching it), then sum over the ranks (one all-reduce of 3 values for p·Kp, one of
//! 6 for r·z and the stopping test's r·r together: two per iteration). The halo exchange
//! needs no counts (the lists are the same on both sides), so an iteration is 3 collectives,
//! and 2 more with a block preconditioner (r to the blocks' homes, z back): on oversubscribed
//! or loaded nodes each one waits for every rank to be scheduled.
//!
//! **Preconditioner.** The serial solver's own ([`super::blocks`]): block Jacobi and the
//! block-Jacobi pair (the default) on the aggregates the serial run grows, numbered by the
//! control points' global keys, not by the shares (grown before the assembly,
//! [`Aggregation`], and passed in); a block that straddles ranks is summed and solved on one
//! home rank. With `--cg-preconditioner jacobi` every row gets point Jacobi on
//! its summed diagonal. Either way the preconditioner is the serial one, so the iterates are
//! the serial ones up to the order of the sums (the ranks' partial products, dot products and
//! block entries), whatever the shares: the loop and its stopping rule (‖r‖ ≤ rel_tol ‖b‖ per
//! coordinate) are the serial solver's, [`crate::solve::cg_loop`], with the ranks' dot
//! products as its reductions. Block Gauss–Seidel, whose sweeps run in an order across the
//! whole matrix, is refused ([`CgError::Unavailable`]).
//!
//! **Rotation seams.** Across glued rotation-periodic seams the fit's system is
//! (K ⊗ I₃ + C) δ = b ([`crate::fit::rotated`]): [`pcg_coupled`] adds each rank's share C_s
//! (its own elements' couplings) to K_s's product before the halo exchange, and runs the
//! serial coupled recurrence ([`crate::solve::coupled_loop`], one α and β over the three
//! coordinates) under K's block-Jacobi pair, as the serial solve on its CG path.

use super::blocks::{Aggregation, GlobalBlocks};
use super::comm::Comm;
use super::local::Key;
use crate::fit::NormalMatrix;
use crate::fit::rotated::Coupling;
use crate::solve::blocked::{PackedColumns, RowTemplates};
use crate::solve::{CgError, CgInfo, CgParams, CgPreconditioner};
use rayon::prelude::*;
use std::collections::HashSet;

/// The control points of this rank and how they are shared.
pub struct Halo {
    /// Global ids of this rank's control points (those its elements touch), increasing.
    pub global: Vec<u32>,
    /// Whether this rank owns each (the lowest rank touching it): it counts in dot products.
    pub owned: Vec<bool>,
    /// Per other rank sharing control points with this one: the rank and the local indices
    /// of the shared control points, in increasing global id (the same order on both sides).
    pub neighbours: Vec<(usize, Vec<u32>)>,
    /// The global key of each control point ([`super::local::key_of`]): the same on every
    /// rank holding it, and ordered as the serial space numbers its control points.
    pub keys: Vec<Key>,
}

impl Halo {
    /// From every rank's control points (`touched[q]`: increasing global ids, known to every
    /// rank since the setup is replicated; see docs/distributed.md).
    pub fn new(rank: usize, touched: &[Vec<u32>], n_global: usize) -> Halo {
        // Per control point, the ranks touching it (increasing).
        let mut ranks: Vec<Vec<u16>> = vec![Vec::new(); n_global];
        for (q, list) in touched.iter().enumerate() {
            for &g in list {
                ranks[g as usize].push(q as u16);
            }
        }
        let global = touched[rank].clone();
        let owned = global
            .iter()
            .map(|&g| ranks[g as usize][0] as usize == rank)
            .collect();
        let mut per: Vec<Vec<u32>> = vec![Vec::new(); touched.len()];
        for (i, &g) in global.iter().enumerate() {
            for &q in &ranks[g as usize] {
                if q as usize != rank {
                    per[q as usize].push(i as u32);
                }
            }
        }
        let neighbours = per
            .into_iter()
            .enumerate()
            .filter(|(_, l)| !l.is_empty())
            .collect();
        // The ids are global here: their order is every rank's.
        let keys = global.iter().map(|&g| [0, u64::from(g), 0, 0, 0]).collect();
        Halo {
            global,
            owned,
            neighbours,
            keys,
        }
    }

    pub fn len(&self) -> usize {
        self.global.len()
    }

    pub fn is_empty(&self) -> bool {
        self.global.is_empty()
    }

    /// Control points shared with another rank.
    pub fn shared(&self) -> usize {
        let mut s = vec![false; self.len()];
        for (_, l) in &self.neighbours {
            for &i in l {
                s[i as usize] = true;
            }
        }
        s.iter().filter(|&&b| b).count()
    }

    /// Local index of global control point `g`.
    pub fn local(&self, g: u32) -> Option<usize> {
        self.global.binary_search(&g).ok()
    }

    /// Turn per-rank partial values into their sums over the ranks sharing each control
    /// point, added in rank order (see the module docs). `w` components per control point.
    pub fn sum_partials(&self, comm: &dyn Comm, v: &mut [f64], w: usize) {
        let me = comm.rank();
        let mut send = vec![Vec::new(); comm.size()];
        for (q, list) in &self.neighbours {
            send[*q] = list
                .iter()
                .flat_map(|&i| v[w * i as usize..w * (i as usize + 1)].to_vec())
                .collect();
        }
        // The lists are the same on both sides: no counts to exchange (one collective per
        // product, which matters when the ranks wait on each other).
        let recv = comm.exchange_symmetric_f64(&send);
        let mine = v.to_vec();
        v.fill(0.0);
        // Rank order: the neighbours below this rank, this rank, the neighbours above.
        let below = self.neighbours.partition_point(|(q, _)| *q < me);
        let add = |v: &mut [f64], q: usize, list: &[u32]| {
            for (k, &i) in list.iter().enumerate() {
                for c in 0..w {
                    v[w * i as usize + c] += recv[q][w * k + c];
                }
            }
        };
        for (q, list) in &self.neighbours[..below] {
            add(v, *q, list);
        }
        for (x, m) in v.iter_mut().zip(&mine) {
            *x += m;
        }
        for (q, list) in &self.neighbours[below..] {
            add(v, *q, list);
        }
    }

    /// Σ over owned control points of a·b per coordinate, on this rank.
    fn local_dot(&self, a: &[[f64; 3]], b: &[[f64; 3]]) -> [f64; 3] {
        let mut s = [0.0f64; 3];
        for ((x, y), &o) in a.iter().zip(b).zip(&self.owned) {
            if o {
                for k in 0..3 {
                    s[k] += x[k] * y[k];
                }
            }
        }
        s
    }

    /// Σ over owned control points of a·b per coordinate, summed over the ranks.
    fn dot(&self, comm: &dyn Comm, a: &[[f64; 3]], b: &[[f64; 3]]) -> [f64; 3] {
        let mut s = self.local_dot(a, b);
        comm.sum_f64(&mut s);
        s
    }

    /// The dot products a·b and c·d in one reduction (each component's sum is the one
    /// [`Halo::dot`] would give: the reduction is element-wise).
    fn dot2(
        &self,
        comm: &dyn Comm,
        (a, b): (&[[f64; 3]], &[[f64; 3]]),
        (c, d): (&[[f64; 3]], &[[f64; 3]]),
    ) -> ([f64; 3], [f64; 3]) {
        let (x, y) = (self.local_dot(a, b), self.local_dot(c, d));
        let mut s = [x[0], x[1], x[2], y[0], y[1], y[2]];
        comm.sum_f64(&mut s);
        ([s[0], s[1], s[2]], [s[3], s[4], s[5]])
    }
}

/// This rank's share of K in its local numbering (rows and columns of `halo.global`), its
/// columns stored as the serial blocked CG stores its product's (`solve::blocked`'s packed
/// columns: 16-bit offsets from each row's smallest column where they fit, 32-bit otherwise).
pub struct LocalMatrix {
    /// Row r's entries are `indptr[r]..indptr[r + 1]` (of the values where they are full).
    indptr: Vec<usize>,
    columns: PackedColumns,
    values: LocalValues,
}

/// The values of a [`LocalMatrix`]: a CSR value array, or a template per row as the
/// assembly stores them (the share's rows repeat like K's; see [`NormalMatrix`]).
enum LocalValues {
    Full(Vec<f64>),
    Templated(Vec<u32>, RowTemplates),
}

impl LocalMatrix {
    /// Restrict `k` (global numbering; its non-empty rows are this rank's control points) to
    /// the local numbering.
    pub fn new(k: &NormalMatrix, halo: &Halo) -> LocalMatrix {
        let mut indptr = vec![0usize];
        let mut indices = Vec::new();
        let mut data = Vec::new();
        for &g in &halo.global {
            let g = g as usize;
            for j in k.indptr()[g]..k.indptr()[g + 1] {
                let c = halo
                    .local(k.indices()[j])
                    .expect("a column of this rank's share is one of its control points");
                indices.push(c as u32);
                data.push(k.data()[j]);
            }
            indptr.push(indices.len());
        }
        LocalMatrix {
            columns: PackedColumns::from_csr(&indptr, &indices),
            indptr,
            values: LocalValues::Full(data),
        }
    }

    /// [`LocalMatrix::new`] taking `k` apart instead of copying it: its rows outside
    /// `halo.global` are empty and the local numbering keeps the global order, so the
    /// entries stay where they are and only the columns are renumbered (the assembled share
    /// is the largest array a rank holds; a copy would double it at the fit's peak). Rows
    /// stored by template stay so: the share's values are never expanded.
    pub fn from_matrix(k: NormalMatrix, halo: &Halo) -> LocalMatrix {
        let touched: usize = halo
            .global
            .iter()
            .map(|&g| k.indptr()[g as usize + 1] - k.indptr()[g as usize])
            .sum();
        if touched != k.indices().len() {
            return LocalMatrix::new(&k, halo);
        }
        let (global_ptr, mut indices, values) = match k.into_templates() {
            Ok((indptr, indices, row_template, table)) => {
                let local = halo.global.iter().map(|&g| row_template[g as usize]);
                (
                    indptr,
                    indices,
                    LocalValues::Templated(local.collect(), table),
                )
            }
            Err(k) => {
                let (indptr, indices, data) = (*k).into_parts();
                (indptr, indices, LocalValues::Full(data))
            }
        };
        let mut indptr = Vec::with_capacity(halo.len() + 1);
        indptr.push(0);
        indptr.extend(halo.global.iter().map(|&g| global_ptr[g as usize + 1]));
        drop(global_ptr);
        for c in &mut indices {
            *c = halo
                .local(*c)
                .expect("a column of this rank's share is one of its control points")
                as u32;
        }
        let columns = PackedColumns::from_csr(&indptr, &indices);
        drop(indices);
        LocalMatrix {
            indptr,
            columns,
            values,
        }
    }

    pub fn nonzeros(&self) -> usize {
        *self.indptr.last().unwrap()
    }

    /// The stored entries of the whole K, on every rank (collective): each entry (r, c) is
    /// counted by the lowest rank whose share holds it. A lower rank q holding an entry of
    /// this rank's share touches both r and c, which are then on the list this rank shares
    /// with q: each rank sends its higher neighbours, per row of their shared list, the
    /// columns of its share on the same list (as positions in it, the same on both sides),
    /// and counts its entries none of its lower neighbours sent. Summing the ranks'
    /// [`LocalMatrix::nonzeros`] counts an entry once per rank holding it (the generated
    /// 975-hex torus: 229,838 and 254,085 at 2 and 4 ranks against K's 206,295).
    pub fn global_nonzeros(&self, comm: &dyn Comm, halo: &Halo) -> usize {
        let me = comm.rank();
        let mut position = vec![u32::MAX; halo.len()];
        let mut send = vec![Vec::new(); comm.size()];
        for (p, list) in halo.neighbours.iter().filter(|(p, _)| *p > me) {
            for (k, &i) in list.iter().enumerate() {
                position[i as usize] = k as u32;
            }
            let out = &mut send[*p];
            for &i in list {
                let at = out.len();
                out.push(0.0);
                self.for_each_entry(i as usize, |c, _| {
                    if position[c] != u32::MAX {
                        out.push(f64::from(position[c]));
                    }
                });
                out[at] = (out.len() - at - 1) as f64;
            }
            for &i in list {
                position[i as usize] = u32::MAX;
            }
        }
        let recv = comm.exchange_f64(&send);
        drop(send);
        // The entries the lower neighbours hold, in this rank's local numbering.
        let mut below: HashSet<(u32, u32)> = HashSet::new();
        for (q, list) in halo.neighbours.iter().filter(|(q, _)| *q < me) {
            let mut at = 0;
            for &i in list {
                let n = recv[*q][at] as usize;
                let cols = recv[*q][at + 1..at + 1 + n].iter();
                below.extend(cols.map(|&k| (i, list[k as usize])));
                at += 1 + n;
            }
        }
        let mut count = [(0..halo.len())
            .map(|r| {
                let mut n = 0;
                self.for_each_entry(r, |c, _| {
                    n += u64::from(!below.contains(&(r as u32, c as u32)));
                });
                n
            })
            .sum::<u64>()];
        comm.sum_u64(&mut count);
        count[0] as usize
    }

    /// Row r's values, in the order of its columns.
    fn values(&self, r: usize) -> &[f64] {
        match &self.values {
            LocalValues::Full(data) => &data[self.indptr[r]..self.indptr[r + 1]],
            LocalValues::Templated(row_template, table) => table.get(row_template[r]),
        }
    }

    /// `f(column, value)` for row r's entries in their stored order.
    #[inline]
    pub(super) fn for_each_entry(&self, r: usize, f: impl FnMut(usize, f64)) {
        self.columns.for_each_entry(r, self.values(r), f);
    }

    fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        y.par_iter_mut().enumerate().for_each(|(r, y)| {
            let mut s = [0.0; 3];
            self.for_each_entry(r, |c, a| {
                let xv = x[c];
                for k in 0..3 {
                    s[k] += a * xv[k];
                }
            });
            *y = s;
        });
    }

    fn diagonal(&self) -> Vec<f64> {
        (0..self.indptr.len() - 1)
            .map(|r| {
                let mut d = None;
                self.for_each_entry(r, |c, v| {
                    if c == r {
                        d = d.or(Some(v));
                    }
                });
                d.unwrap_or(0.0)
            })
            .collect()
    }
}

/// The preconditioner of the distributed CG (see the module docs).
enum Local {
    /// Point Jacobi: the summed diagonal.
    Point(Vec<f64>),
    Blocks(GlobalBlocks),
}

fn flat(v: &mut [[f64; 3]]) -> &mut [f64] {
    v.as_flattened_mut()
}

/// The serial fit's check of a warm start (`fit::keep_closer_starts`) across the ranks: zero
/// every component of the start `x` (consistent) whose residual ‖b − K x‖ is not below the
/// cold start's ‖b‖, the norms summed over the control points' owners (`b_partial`: this
/// rank's partial right-hand side). Collective; every rank zeroes the same components.
pub fn keep_closer_starts(
    comm: &dyn Comm,
    halo: &Halo,
    k: &LocalMatrix,
    b_partial: &[[f64; 3]],
    x: &mut [[f64; 3]],
) {
    let mut b = b_partial.to_vec();
    halo.sum_partials(comm, flat(&mut b), 3);
    let mut kx = vec![[0.0; 3]; x.len()];
    k.apply(x, &mut kx);
    halo.sum_partials(comm, flat(&mut kx), 3);
    let owned = b.iter().zip(&kx).zip(&halo.owned).filter(|(_, o)| **o);
    let mut norms = crate::fit::start_norms(owned.map(|(row, _)| row));
    comm.sum_f64(&mut norms);
    crate::fit::zero_farther_components(&norms, x);
}

/// Solve the distributed system for δ (consistent, on `halo`'s control points) from `x` = 0:
/// `b` is this rank's partial right-hand side (summed here). A block preconditioner applies
/// `aggregation`, made for it ([`Aggregation::for_preconditioner`]; without one it is
/// [`CgError::Unavailable`]). Returns the CG figures; every rank returns the same ones.
pub fn pcg(
    comm: &dyn Comm,
    halo: &Halo,
    k: &LocalMatrix,
    b_partial: &[[f64; 3]],
    x: &mut [[f64; 3]],
    params: &CgParams,
    aggregation: Option<&Aggregation>,
) -> Result<CgInfo, CgError> {
    solve(comm, halo, k, None, b_partial, x, params, aggregation)
}

/// [`pcg`] of the system (K ⊗ I₃ + C) δ = b of a fit across rotation seams
/// ([`crate::fit::rotated`]): `c` is this rank's share C_s of C in its local numbering
/// (`None` when none of its elements sees a control point rotated; the rank still takes
/// part), added to K_s's product before the halo exchange, so the exchange sums both. The
/// loop is the serial coupled one ([`crate::solve::coupled_loop`]: one recurrence over the
/// three coordinates), preconditioned by the block-Jacobi pair of K per coordinate on
/// `aggregation` (which must be the pair's), as the serial `rotated::solve` is on the CG path.
#[allow(clippy::too_many_arguments)]
pub fn pcg_coupled(
    comm: &dyn Comm,
    halo: &Halo,
    k: &LocalMatrix,
    c: Option<&Coupling>,
    b_partial: &[[f64; 3]],
    x: &mut [[f64; 3]],
    params: &CgParams,
    aggregation: Option<&Aggregation>,
) -> Result<CgInfo, CgError> {
    solve(comm, halo, k, Some(c), b_partial, x, params, aggregation)
}

/// [`pcg`] (`coupled`: `None`) or [`pcg_coupled`] (`Some` of the rank's C_s).
#[allow(clippy::too_many_arguments)]
fn solve(
    comm: &dyn Comm,
    halo: &Halo,
    k: &LocalMatrix,
    coupled: Option<Option<&Coupling>>,
    b_partial: &[[f64; 3]],
    x: &mut [[f64; 3]],
    params: &CgParams,
    aggregation: Option<&Aggregation>,
) -> Result<CgInfo, CgError> {
    let mut b = b_partial.to_vec();
    halo.sum_partials(comm, flat(&mut b), 3);
    let mut diag = k.diagonal();
    halo.sum_partials(comm, &mut diag, 1);
    // The lowest diagonal over the ranks, to fail on every rank alike.
    let mut worst = [diag
        .iter()
        .enumerate()
        .filter(|(i, _)| halo.owned[*i])
        .map(|(_, &d)| d)
        .fold(f64::INFINITY, f64::min)];
    comm.min_f64(&mut worst);
    if !(worst[0] > 0.0) {
        return Err(CgError::BadDiagonal {
            row: 0,
            value: worst[0],
        });
    }
    let apply = |p: &[[f64; 3]], y: &mut [[f64; 3]]| {
        k.apply(p, y);
        if let Some(Some(c)) = coupled {
            c.apply_add(p, y);
        }
        halo.sum_partials(comm, flat(y), 3);
    };
    // The serial solver's preconditioner on every share (the module docs); the coupled
    // solve's is K's block-Jacobi pair whatever the option, as serially.
    let m = match (params.preconditioner, aggregation) {
        (_, Some(a)) if coupled.is_some() => Local::Blocks(GlobalBlocks::new(comm, halo, k, a)?),
        (CgPreconditioner::Jacobi, _) => Local::Point(diag),
        (CgPreconditioner::BlockSgs { .. }, _) => {
            return Err(CgError::Unavailable {
                what: "block Gauss–Seidel",
                why: "its sweeps run across the whole matrix in one order",
            });
        }
        (_, Some(a)) => Local::Blocks(GlobalBlocks::new(comm, halo, k, a)?),
        (_, None) => {
            return Err(CgError::Unavailable {
                what: "block",
                why: "the distributed CG was given no aggregates",
            });
        }
    };
    let precondition = |r: &[[f64; 3]], z: &mut [[f64; 3]]| match &m {
        Local::Point(d) => {
            for ((z, r), d) in z.iter_mut().zip(r).zip(d) {
                *z = r.map(|v| v / d);
            }
        }
        Local::Blocks(b) => b.apply(comm, r, z),
    };
    let ranks = OwnedRows { comm, halo };
    if coupled.is_some() {
        return crate::solve::coupled_loop(&ranks, apply, precondition, &b, x, params, |_, _| {});
    }
    crate::solve::cg_loop(&ranks, apply, precondition, &b, x, params, |_, _| {})
}

/// The dot products of the distributed CG: each control point counted on its owner, summed
/// over the ranks (the serial solver's loop with these reductions, [`crate::solve::cg_loop`]).
struct OwnedRows<'a> {
    comm: &'a dyn Comm,
    halo: &'a Halo,
}

impl crate::solve::Reductions for OwnedRows<'_> {
    fn dot(&self, a: &[[f64; 3]], b: &[[f64; 3]]) -> [f64; 3] {
        self.halo.dot(self.comm, a, b)
    }
    fn dot2(
        &self,
        ab: (&[[f64; 3]], &[[f64; 3]]),
        cd: (&[[f64; 3]], &[[f64; 3]]),
    ) -> crate::solve::Pair {
        self.halo.dot2(self.comm, ab, cd)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::distributed::comm::Single;

    #[test]
    fn one_rank_solves_a_small_spd_system() {
        // 1D Laplacian + identity on 5 unknowns, three right-hand sides.
        let n: usize = 5;
        let mut indptr = vec![0];
        let (mut indices, mut data) = (Vec::new(), Vec::new());
        for r in 0..n {
            for c in r.saturating_sub(1)..(r + 2).min(n) {
                indices.push(c as u32);
                data.push(if c == r { 3.0 } else { -1.0 });
            }
            indptr.push(indices.len());
        }
        let k = NormalMatrix::new(n, indptr, indices, data);
        let halo = Halo::new(0, &[(0..n as u32).collect()], n);
        let local = LocalMatrix::new(&k, &halo);
        let b: Vec<[f64; 3]> = (0..n).map(|i| [1.0, i as f64, -2.0]).collect();
        let mut x = vec![[0.0; 3]; n];
        let params = CgParams {
            rel_tol: 1e-12,
            ..Default::default()
        };
        // The graph's edges as the elements' stencils.
        let stencils: Vec<Vec<u32>> = (0..n as u32 - 1).map(|i| vec![i, i + 1]).collect();
        let comm = Single::default();
        let aggregation =
            Aggregation::for_preconditioner(&comm, &halo, &stencils, &params.preconditioner);
        pcg(
            &comm,
            &halo,
            &local,
            &b,
            &mut x,
            &params,
            aggregation.as_ref(),
        )
        .unwrap();
        let mut y = vec![[0.0; 3]; n];
        crate::solve::LinOp::apply(&k, &x, &mut y);
        for (y, b) in y.iter().zip(&b) {
            for c in 0..3 {
                assert!((y[c] - b[c]).abs() < 1e-10, "{y:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn a_share_taken_apart_is_the_copied_local_matrix() {
        // Rows 1 and 3 empty (control points of other ranks); this rank touches 0, 2 and 4.
        let (indptr, indices, data) = (
            vec![0, 2, 2, 5, 5, 7],
            vec![0u32, 2, 0, 2, 4, 2, 4],
            vec![4.0, -1.0, -1.0, 5.0, -2.0, -2.0, 6.0],
        );
        let halo = Halo::new(0, &[vec![0, 2, 4]], 5);
        let copy = LocalMatrix::new(
            &NormalMatrix::new(5, indptr.clone(), indices.clone(), data.clone()),
            &halo,
        );
        // The same share with its rows stored by template.
        let mut table = RowTemplates::default();
        let templates = table.add_rows(
            5,
            |r| &data[indptr[r]..indptr[r + 1]],
            crate::solve::blocked::hash_row,
        );
        let templated = LocalMatrix::from_matrix(
            NormalMatrix::from_templates(indptr.clone(), indices.clone(), templates, table),
            &halo,
        );
        assert!(matches!(templated.values, LocalValues::Templated(..)));
        let parts = LocalMatrix::from_matrix(NormalMatrix::new(5, indptr, indices, data), &halo);
        let entries = |k: &LocalMatrix| {
            let mut e = Vec::new();
            (0..3).for_each(|r| k.for_each_entry(r, |c, v| e.push((r, c, v))));
            e
        };
        assert_eq!(copy.indptr, vec![0, 2, 5, 7]);
        let columns: Vec<usize> = entries(&copy).iter().map(|e| e.1).collect();
        assert_eq!(columns, vec![0, 1, 0, 1, 2, 1, 2]);
        for k in [&parts, &templated] {
            assert_eq!((&k.indptr, entries(k)), (&copy.indptr, entries(&copy)));
        }
    }
}
