//! The serial solver's block preconditioners applied across ranks: block Jacobi and the
//! block-Jacobi pair on the aggregates the serial run grows, whatever the shares.
//!
//! Input: the control points each own element couples (its stencil, in the rank's local
//! numbering of its [`Halo`], with the global keys of those control points), then a rank's
//! share of K ([`LocalMatrix`]: the rows of the control points its elements touch, partial
//! where a control point is shared). Output: z = M⁻¹ r on the rank's control points
//! (consistent: every copy of a shared control point gets the same value), with M the
//! serial preconditioner: [`crate::solve::block_jacobi::BlockJacobi`] on `Aggregates::new`,
//! and for the pair also on `Aggregates::reversed`, z = ½ (M₁⁻¹ r + M₂⁻¹ r).
//!
//! **Numbering.** A control point's global number is the rank of its key
//! ([`super::local::key_of`]: entity kind, then the entity's sorted global ids) among all keys;
//! for a file listing its nodes in tag order this is the serial space's numbering (spline
//! control points by kind, then element index, or face, edge and vertex by sorted vertex
//! numbers, as the topology sorts them), so the aggregates are the serial run's; in any case
//! they do not depend on the ranks.
//!
//! **Aggregates** ([`Aggregation`], before the fit's assembly, when a rank holds least). The
//! ranks gather their keys (40 B per control point, on every rank) and send rank 0 their own
//! elements' stencils in global numbers (8 B per stencil entry; K's graph is the union of the
//! stencils' cliques, E_eᵀ G_e E_e being dense on the element's columns); rank 0 grows the
//! aggregates as the serial solver does, on that graph (each row's neighbours formed when the
//! growth reaches it, never the whole graph), and sends every rank the blocks and each block's
//! home (the lowest rank touching its first row).
//!
//! **Blocks** ([`GlobalBlocks`], in the CG). Each block's home sums its entries from the
//! ranks' shares (its own rows without a copy, the other ranks' in rank order) and factors it.
//! Per application, two exchanges with the homes: each rank sends r of the control points it
//! owns to their blocks' homes; the homes solve their blocks and return z to every rank
//! touching one of the rows. A block inside one rank's share stays on that rank.
//!
//! Invariants: every row is in exactly one block per partition and one home solves it, so the
//! copies of z agree bit for bit; the result does not depend on the thread count.

use super::cg::{Halo, LocalMatrix};
use super::comm::Comm;
use super::local::Key;
use crate::fit::FitSpace;
use crate::solve::block_jacobi::{Aggregates, BlockJacobi, Neighbours};
use crate::solve::{CgError, CgPreconditioner, Preconditioner};
use crate::spline::SplineSpace;

/// One partition as rank 0 grew it: the rows of every block in the order of growth (block a is
/// `rows[start[a]..start[a + 1]]`) and each block's home rank.
struct Blocks {
    rows: Vec<u32>,
    start: Vec<usize>,
    home: Vec<u32>,
}

/// The serial aggregates of the whole mesh's control points, known to every rank (see the
/// module docs): one partition for block Jacobi, two for the pair.
pub struct Aggregation {
    /// The global number of each of this rank's control points (local numbering of the halo).
    numbers: Vec<u32>,
    parts: Vec<Blocks>,
}

/// One partition of the rows into blocks, as this rank applies it.
struct Partition {
    /// Per rank q: the local rows this rank sends r of (its owned rows in q's blocks).
    send_r: Vec<Vec<u32>>,
    /// Per rank q: the local rows whose z comes from q.
    recv_z: Vec<Vec<u32>>,
    /// Per rank q: positions in `blocks` of the rows q sends r of.
    recv_r: Vec<Vec<u32>>,
    /// Per rank q: positions in `blocks` of the rows q touches (their z is returned to q).
    send_z: Vec<Vec<u32>>,
    /// The blocks homed on this rank, factored, over the positions 0..`m`.
    blocks: Option<BlockJacobi>,
    m: usize,
}

/// The serial block preconditioner across the ranks (see the module docs).
pub struct GlobalBlocks {
    parts: Vec<Partition>,
}

/// Keys travel as f64 (node tags and element ids are below 2⁵³).
fn key_from(c: &[f64]) -> Key {
    std::array::from_fn(|i| c[i] as u64)
}

/// The global number of each of this rank's control points (see the module docs) and the
/// number of control points of the whole mesh.
fn global_numbers(comm: &dyn Comm, halo: &Halo) -> (Vec<u32>, usize) {
    let owned: Vec<f64> = halo
        .keys
        .iter()
        .zip(&halo.owned)
        .filter(|(_, o)| **o)
        .flat_map(|(k, _)| k.map(|x| x as f64))
        .collect();
    let mut all: Vec<Key> = comm
        .all_gather_f64(&owned)
        .concat()
        .chunks_exact(5)
        .map(key_from)
        .collect();
    all.sort_unstable();
    let numbers = halo
        .keys
        .iter()
        .map(|k| {
            all.binary_search(k)
                .expect("every control point is owned by one rank") as u32
        })
        .collect();
    (numbers, all.len())
}

/// Rank 0's view of K's graph: the elements' stencils and, per control point, the elements
/// holding it; a row's neighbours are formed when asked for.
struct Stencils {
    element_start: Vec<usize>,
    element_points: Vec<u32>,
    point_start: Vec<usize>,
    point_elements: Vec<u32>,
    /// The lowest rank touching each control point.
    owner: Vec<u32>,
    row: Vec<u32>,
}

impl Stencils {
    /// From every rank's records `[rank, elements, (count, points…) per element]`, in rank
    /// order, over `n` control points.
    fn new(records: &[f64], n: usize) -> Stencils {
        let (mut element_start, mut element_points) = (vec![0usize], Vec::new());
        let mut owner = vec![u32::MAX; n];
        let mut at = 0;
        while at < records.len() {
            let (q, elements) = (records[at] as u32, records[at + 1] as usize);
            at += 2;
            for _ in 0..elements {
                let len = records[at] as usize;
                for &g in &records[at + 1..at + 1 + len] {
                    owner[g as usize] = owner[g as usize].min(q);
                    element_points.push(g as u32);
                }
                element_start.push(element_points.len());
                at += 1 + len;
            }
        }
        let mut point_start = vec![0usize; n + 1];
        for &g in &element_points {
            point_start[g as usize + 1] += 1;
        }
        for g in 0..n {
            point_start[g + 1] += point_start[g];
        }
        let mut fill = point_start.clone();
        let mut point_elements = vec![0u32; element_points.len()];
        for e in 0..element_start.len() - 1 {
            for &g in &element_points[element_start[e]..element_start[e + 1]] {
                point_elements[fill[g as usize]] = e as u32;
                fill[g as usize] += 1;
            }
        }
        Stencils {
            element_start,
            element_points,
            point_start,
            point_elements,
            owner,
            row: Vec::new(),
        }
    }
}

impl Neighbours for Stencils {
    fn len(&self) -> usize {
        self.point_start.len() - 1
    }
    fn of(&mut self, r: usize) -> &[u32] {
        self.row.clear();
        for &e in &self.point_elements[self.point_start[r]..self.point_start[r + 1]] {
            let e = e as usize;
            self.row.extend_from_slice(
                &self.element_points[self.element_start[e]..self.element_start[e + 1]],
            );
        }
        self.row.sort_unstable();
        self.row.dedup();
        &self.row
    }
}

impl Aggregation {
    /// The aggregates of at most `size` rows (collective; see the module docs), both
    /// partitions of the pair when `pair`, of the graph whose cliques are `stencils`: each own
    /// element's control points, in the halo's local numbering.
    pub fn new(
        comm: &dyn Comm,
        halo: &Halo,
        stencils: &[Vec<u32>],
        size: usize,
        pair: bool,
    ) -> Aggregation {
        let (numbers, n) = global_numbers(comm, halo);
        let mut records = vec![comm.rank() as f64, stencils.len() as f64];
        for s in stencils {
            records.push(s.len() as f64);
            records.extend(s.iter().map(|&i| numbers[i as usize] as f64));
        }
        let gathered = comm.gather_f64(0, &records);
        drop(records);
        // Per partition: the number of blocks, the rows, the starts, the homes.
        let message: Vec<f64> = match gathered {
            Some(records) => {
                let mut graph = Stencils::new(&records, n);
                drop(records);
                let size = size.max(1);
                let mut m = Vec::new();
                for reverse in [false, true].into_iter().take(1 + usize::from(pair)) {
                    let agg = Aggregates::grow_on(&mut graph, size, reverse);
                    let blocks = agg.start.len() - 1;
                    m.push(blocks as f64);
                    m.extend(agg.rows.iter().map(|&r| r as f64));
                    m.extend(agg.start.iter().map(|&s| s as f64));
                    m.extend(
                        (0..blocks).map(|a| graph.owner[agg.rows[agg.start[a]] as usize] as f64),
                    );
                }
                m
            }
            None => Vec::new(),
        };
        let message = comm.all_gather_f64(&message).swap_remove(0);
        let mut parts = Vec::new();
        let mut at = 0;
        let take = |at: &mut usize, len: usize| {
            *at += len;
            &message[*at - len..*at]
        };
        while at < message.len() {
            let blocks = take(&mut at, 1)[0] as usize;
            let rows = take(&mut at, n).iter().map(|&r| r as u32).collect();
            let start = take(&mut at, blocks + 1)
                .iter()
                .map(|&s| s as usize)
                .collect();
            let home = take(&mut at, blocks).iter().map(|&q| q as u32).collect();
            parts.push(Blocks { rows, start, home });
        }
        Aggregation { numbers, parts }
    }
}

/// The control points each element of `elements` couples in `space`, in the local numbering
/// of `halo`: the columns the fit's assembly gives the element's matrix
/// ([`FitSpace::element_pattern`]'s control points, or else the distinct columns of its
/// extraction rows), so the union of their cliques is K's graph.
pub fn own_stencils(space: &SplineSpace, halo: &Halo, elements: &[usize]) -> Vec<Vec<u32>> {
    let (mut ids, mut offsets, mut cols, mut weights) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    elements
        .iter()
        .map(|&e| {
            let used: &[u32] = if space.element_pattern(e, &mut ids).is_some() {
                &ids
            } else {
                space.element_rows(e, &mut offsets, &mut cols, &mut weights);
                &cols
            };
            let mut stencil: Vec<u32> = used
                .iter()
                .map(|&c| {
                    halo.local(c)
                        .expect("an own element's control point is in the halo")
                        as u32
                })
                .collect();
            stencil.sort_unstable();
            stencil.dedup();
            stencil
        })
        .collect()
}

impl Aggregation {
    /// The aggregates `preconditioner` applies ([`Aggregation::new`]), or `None` for one
    /// without blocks.
    pub fn for_preconditioner(
        comm: &dyn Comm,
        halo: &Halo,
        stencils: &[Vec<u32>],
        preconditioner: &CgPreconditioner,
    ) -> Option<Aggregation> {
        match *preconditioner {
            CgPreconditioner::BlockJacobi { size } => {
                Some(Aggregation::new(comm, halo, stencils, size, false))
            }
            // The lines are refused under mpirun (`job::check_supported`); the pair stands in
            // for them if a caller of this module passes them.
            CgPreconditioner::BlockJacobiPair { size }
            | CgPreconditioner::BlockJacobiLines { size } => {
                Some(Aggregation::new(comm, halo, stencils, size, true))
            }
            CgPreconditioner::Jacobi | CgPreconditioner::BlockSgs { .. } => None,
        }
    }
}

impl GlobalBlocks {
    /// The blocks of `aggregation` over this rank's share `k` of K (collective; see the module
    /// docs). A block that fails to factor fails on every rank alike.
    pub fn new(
        comm: &dyn Comm,
        halo: &Halo,
        k: &LocalMatrix,
        aggregation: &Aggregation,
    ) -> Result<GlobalBlocks, CgError> {
        let mut parts = Vec::new();
        let mut failure = None;
        for blocks in &aggregation.parts {
            match Partition::new(comm, halo, k, &aggregation.numbers, blocks) {
                Ok(p) => parts.push(p),
                Err(e) => {
                    failure.get_or_insert(e);
                }
            }
        }
        let mut ok = [if failure.is_none() { 1.0 } else { 0.0 }];
        comm.min_f64(&mut ok);
        match failure {
            Some(e) => Err(e),
            None if ok[0] < 1.0 => Err(CgError::BadDiagonal {
                row: 0,
                value: f64::NAN,
            }),
            None => Ok(GlobalBlocks { parts }),
        }
    }

    /// z = M⁻¹ r on this rank's control points (collective: two exchanges).
    pub fn apply(&self, comm: &dyn Comm, r: &[[f64; 3]], z: &mut [[f64; 3]]) {
        let ranks = comm.size();
        let mut send = vec![Vec::new(); ranks];
        for p in &self.parts {
            for (q, rows) in p.send_r.iter().enumerate() {
                send[q].extend(rows.iter().flat_map(|&i| r[i as usize]));
            }
        }
        let received = comm.exchange_f64(&send);
        let mut back = vec![Vec::new(); ranks];
        let mut from = vec![0usize; ranks];
        for p in &self.parts {
            let mut rh = vec![[0.0; 3]; p.m];
            for (q, at) in p.recv_r.iter().enumerate() {
                for &pos in at {
                    let o = from[q];
                    rh[pos as usize] = [received[q][o], received[q][o + 1], received[q][o + 2]];
                    from[q] += 3;
                }
            }
            let mut zh = vec![[0.0; 3]; p.m];
            if let Some(b) = &p.blocks {
                b.apply(&rh, &mut zh);
            }
            for (q, at) in p.send_z.iter().enumerate() {
                back[q].extend(at.iter().flat_map(|&pos| zh[pos as usize]));
            }
        }
        drop(received);
        let returned = comm.exchange_f64(&back);
        let mut from = vec![0usize; ranks];
        let mut second = vec![[0.0; 3]; if self.parts.len() > 1 { z.len() } else { 0 }];
        for (j, p) in self.parts.iter().enumerate() {
            let out: &mut [[f64; 3]] = if j == 0 { z } else { &mut second };
            for (q, rows) in p.recv_z.iter().enumerate() {
                for &i in rows {
                    let o = from[q];
                    out[i as usize] = [returned[q][o], returned[q][o + 1], returned[q][o + 2]];
                    from[q] += 3;
                }
            }
        }
        if !second.is_empty() {
            // The pair: ½ (M₁⁻¹ r + M₂⁻¹ r), as the serial preconditioner forms it.
            for (z, w) in z.iter_mut().zip(&second) {
                for c in 0..3 {
                    z[c] = 0.5 * (z[c] + w[c]);
                }
            }
        }
    }
}

impl Partition {
    /// This rank's traffic for the partition `blocks`, and its homed blocks summed from the
    /// ranks' shares and factored.
    fn new(
        comm: &dyn Comm,
        halo: &Halo,
        k: &LocalMatrix,
        numbers: &[u32],
        blocks: &Blocks,
    ) -> Result<Partition, CgError> {
        let (me, ranks) = (comm.rank(), comm.size());
        let Blocks { rows, start, home } = blocks;
        let mut of = vec![0u32; rows.len()];
        for a in 0..home.len() {
            for &r in &rows[start[a]..start[a + 1]] {
                of[r as usize] = a as u32;
            }
        }
        let mut send_r = vec![Vec::new(); ranks];
        let mut recv_z = vec![Vec::new(); ranks];
        for (i, &g) in numbers.iter().enumerate() {
            let q = home[of[g as usize] as usize] as usize;
            recv_z[q].push(i as u32);
            if halo.owned[i] {
                send_r[q].push(i as u32);
            }
        }
        // Local row i's entries in its block: (row, column, value) in global numbers.
        let entries = |i: u32, f: &mut dyn FnMut(u32, u32, f64)| {
            let g = numbers[i as usize];
            k.for_each_entry(i as usize, |c, v| {
                let h = numbers[c];
                if of[h as usize] == of[g as usize] {
                    f(g, h, v);
                }
            });
        };
        // To each other home: the rows this rank sends r of, the rows it wants z of, and its
        // partial entries of those rows.
        let mut send = vec![Vec::new(); ranks];
        for q in (0..ranks).filter(|&q| q != me) {
            let s = &mut send[q];
            s.push(send_r[q].len() as f64);
            s.extend(send_r[q].iter().map(|&i| numbers[i as usize] as f64));
            s.push(recv_z[q].len() as f64);
            s.extend(recv_z[q].iter().map(|&i| numbers[i as usize] as f64));
            for &i in &recv_z[q] {
                entries(i, &mut |g, h, v| s.extend([g as f64, h as f64, v]));
            }
        }
        let received = comm.exchange_f64(&send);
        drop(send);
        // The blocks homed here, numbered 0..m in block order, each block's rows in their
        // order of growth (the serial factor's order).
        let mut position = vec![u32::MAX; rows.len()];
        let mut local_start = vec![0usize];
        let mut global = Vec::new();
        for a in (0..home.len()).filter(|&a| home[a] as usize == me) {
            for &g in &rows[start[a]..start[a + 1]] {
                position[g as usize] = global.len() as u32;
                global.push(g);
            }
            local_start.push(global.len());
        }
        let m = global.len();
        let at = |list: &[u32]| -> Vec<u32> {
            list.iter()
                .map(|&i| position[numbers[i as usize] as usize])
                .collect()
        };
        let mut recv_r = vec![Vec::new(); ranks];
        let mut send_z = vec![Vec::new(); ranks];
        recv_r[me] = at(&send_r[me]);
        send_z[me] = at(&recv_z[me]);
        // The other ranks' parts: their lists, then their entries.
        let entries_from = |buf: &[f64]| {
            let nr = buf[0] as usize;
            2 + nr + buf[1 + nr] as usize
        };
        // Each homed row's entries from every rank, in rank order (this rank's from its share).
        let for_each_entry = |f: &mut dyn FnMut(u32, u32, f64)| {
            for (q, buf) in received.iter().enumerate() {
                if q == me {
                    for &i in &recv_z[me] {
                        entries(i, &mut |g, h, v| {
                            f(position[g as usize], position[h as usize], v)
                        });
                    }
                } else {
                    for t in buf[entries_from(buf)..].chunks_exact(3) {
                        f(position[t[0] as usize], position[t[1] as usize], t[2]);
                    }
                }
            }
        };
        let mut indptr = vec![0usize; m + 1];
        for_each_entry(&mut |i, _, _| indptr[i as usize + 1] += 1);
        for i in 0..m {
            indptr[i + 1] += indptr[i];
        }
        let mut fill = indptr.clone();
        let mut indices = vec![0u32; indptr[m]];
        let mut data = vec![0.0; indptr[m]];
        for_each_entry(&mut |i, j, v| {
            let f = &mut fill[i as usize];
            indices[*f] = j;
            data[*f] = v;
            *f += 1;
        });
        drop(fill);
        for (q, buf) in received.iter().enumerate().filter(|(q, _)| *q != me) {
            let nr = buf[0] as usize;
            let list =
                |ids: &[f64]| -> Vec<u32> { ids.iter().map(|&g| position[g as usize]).collect() };
            recv_r[q] = list(&buf[1..1 + nr]);
            send_z[q] = list(&buf[2 + nr..entries_from(buf)]);
        }
        drop(received);
        let blocks = if m == 0 {
            None
        } else {
            let aggregates = Aggregates {
                rows: (0..m as u32).collect(),
                start: local_start,
                slot: (0..m as u32).collect(),
            };
            Some(
                BlockJacobi::on(&indptr, &indices, &data, aggregates).map_err(|e| match e {
                    CgError::BadDiagonal { row, value } => CgError::BadDiagonal {
                        row: global[row] as usize,
                        value,
                    },
                    e => e,
                })?,
            )
        };
        Ok(Partition {
            send_r,
            recv_z,
            recv_r,
            send_z,
            blocks,
            m,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::distributed::comm::Single;
    use crate::fit::NormalMatrix;
    use crate::solve::block_jacobi::BlockJacobiPair;

    /// A 2D Laplacian plus identity on a 9 × 7 grid (CSR, sorted columns).
    fn grid() -> (Vec<usize>, Vec<u32>, Vec<f64>) {
        let (nx, ny) = (9usize, 7usize);
        let mut indptr = vec![0];
        let (mut indices, mut data) = (Vec::new(), Vec::new());
        for y in 0..ny {
            for x in 0..nx {
                let mut row = vec![(y * nx + x, 5.0)];
                if x > 0 {
                    row.push((y * nx + x - 1, -1.0));
                }
                if x + 1 < nx {
                    row.push((y * nx + x + 1, -1.0));
                }
                if y > 0 {
                    row.push(((y - 1) * nx + x, -1.0));
                }
                if y + 1 < ny {
                    row.push(((y + 1) * nx + x, -1.0 - 0.01 * x as f64));
                }
                row.sort_by_key(|e| e.0);
                for (c, v) in row {
                    indices.push(c as u32);
                    data.push(v);
                }
                indptr.push(indices.len());
            }
        }
        // Symmetrise the vertical couplings (the upper one set the value).
        for r in 0..nx * ny {
            for k in indptr[r]..indptr[r + 1] {
                let c = indices[k] as usize;
                if c + nx == r {
                    data[k] = -1.0 - 0.01 * (r % nx) as f64;
                }
            }
        }
        (indptr, indices, data)
    }

    /// The edges of a CSR graph as 2-cliques (their union is the graph).
    fn pairs(indptr: &[usize], indices: &[u32]) -> Vec<Vec<u32>> {
        let mut out = Vec::new();
        for r in 0..indptr.len() - 1 {
            for &c in &indices[indptr[r]..indptr[r + 1]] {
                if c as usize >= r {
                    out.push(vec![r as u32, c]);
                }
            }
        }
        out
    }

    /// On one rank the blocks are the serial solver's: the same z, bit for bit, as
    /// [`BlockJacobiPair`] (both partitions) and [`BlockJacobi`] (the first).
    #[test]
    fn one_rank_applies_the_serial_block_preconditioners_bit_for_bit() {
        let (indptr, indices, data) = grid();
        let n = indptr.len() - 1;
        let k = NormalMatrix::new(n, indptr.clone(), indices.clone(), data.clone());
        let halo = Halo::new(0, &[(0..n as u32).collect()], n);
        let local = LocalMatrix::new(&k, &halo);
        let r: Vec<[f64; 3]> = (0..n)
            .map(|i| [(i as f64).sin(), 1.0 + i as f64, -(i as f64).cos()])
            .collect();
        let comm = Single::default();
        for (pair, serial) in [
            (
                true,
                Box::new(BlockJacobiPair::new(&indptr, &indices, &data, 8).unwrap())
                    as Box<dyn Preconditioner>,
            ),
            (
                false,
                Box::new(BlockJacobi::new(&indptr, &indices, &data, 8).unwrap()),
            ),
        ] {
            let stencils = pairs(&indptr, &indices);
            let aggregation = Aggregation::new(&comm, &halo, &stencils, 8, pair);
            let blocks = GlobalBlocks::new(&comm, &halo, &local, &aggregation).unwrap();
            let (mut z, mut want) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
            blocks.apply(&comm, &r, &mut z);
            serial.apply(&r, &mut want);
            let bits = |v: &[[f64; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&z), bits(&want), "pair {pair}");
        }
    }

    /// Keys that are not the local order still give the serial numbering: a rank whose local
    /// control points come in reverse key order applies the same blocks.
    #[test]
    fn the_blocks_follow_the_keys_not_the_local_order() {
        let (indptr, indices, data) = grid();
        let n = indptr.len() - 1;
        // The matrix with its rows and columns reversed: local i is global n − 1 − i.
        let flip = |i: usize| n - 1 - i;
        let mut rows: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
        for r in 0..n {
            for k in indptr[r]..indptr[r + 1] {
                rows[flip(r)].push((flip(indices[k] as usize) as u32, data[k]));
            }
        }
        let mut fptr = vec![0];
        let (mut fidx, mut fdat) = (Vec::new(), Vec::new());
        for mut row in rows {
            row.sort_by_key(|e| e.0);
            for (c, v) in row {
                fidx.push(c);
                fdat.push(v);
            }
            fptr.push(fidx.len());
        }
        let stencils = pairs(&fptr, &fidx);
        let k = NormalMatrix::new(n, fptr, fidx, fdat);
        let mut halo = Halo::new(0, &[(0..n as u32).collect()], n);
        halo.keys = (0..n).map(|i| [0, flip(i) as u64, 0, 0, 0]).collect();
        let local = LocalMatrix::new(&k, &halo);
        let r: Vec<[f64; 3]> = (0..n).map(|i| [i as f64, 1.0, (i * i) as f64]).collect();
        let r_flipped: Vec<[f64; 3]> = (0..n).map(|i| r[flip(i)]).collect();
        let comm = Single::default();
        let aggregation = Aggregation::new(&comm, &halo, &stencils, 8, true);
        let blocks = GlobalBlocks::new(&comm, &halo, &local, &aggregation).unwrap();
        let mut z = vec![[0.0; 3]; n];
        blocks.apply(&comm, &r_flipped, &mut z);
        let mut want = vec![[0.0; 3]; n];
        BlockJacobiPair::new(&indptr, &indices, &data, 8)
            .unwrap()
            .apply(&r, &mut want);
        for i in 0..n {
            assert_eq!(z[i], want[flip(i)], "row {i}");
        }
    }
}
