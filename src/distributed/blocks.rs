//! The serial solver's block preconditioners applied across ranks: block Jacobi and the
//! block-Jacobi pair on the aggregates the serial run grows, whatever the shares.
//!
//! Input: a rank's share of K ([`LocalMatrix`], its rows of the control points its elements
//! touch, partial where a control point is shared) and its [`Halo`] with the global keys of
//! those control points. Output: z = M⁻¹ r on the rank's control points (consistent: every
//! copy of a shared control point gets the same value), with M the serial preconditioner:
//! [`crate::solve::block_jacobi::BlockJacobi`] on `Aggregates::new`, and for the pair also on
//! `Aggregates::reversed`, z = ½ (M₁⁻¹ r + M₂⁻¹ r).
//!
//! **Numbering.** A control point's global number is the rank of its key
//! ([`super::local::key_of`]: entity kind, then the entity's sorted global ids) among all keys;
//! for a file listing its nodes in tag order this is the serial space's numbering (spline
//! control points by kind, then element index, or face, edge and vertex by sorted vertex
//! numbers, as the topology sorts them), so the aggregates are the serial run's; in any case
//! they do not depend on the ranks.
//!
//! **Setup** (once per solve). The ranks gather their keys (40 B per control point, on every
//! rank) and K's graph in global numbers (rank 0 only, 4–8 B per stored entry); rank 0 grows
//! the aggregates as the serial solver does and sends every rank the blocks and each block's
//! home (the lowest rank touching its first row). Each block's home receives its partial
//! entries from the ranks touching it, sums them in rank order and factors the block.
//!
//! **Per application** two exchanges with the homes: each rank sends r of the control points
//! it owns to their blocks' homes; the homes solve their blocks and return z to every rank
//! touching one of the rows. A block inside one rank's share stays on that rank.
//!
//! Invariants: every row is in exactly one block per partition and one home solves it, so the
//! copies of z agree bit for bit; the result does not depend on the thread count.

use super::cg::{Halo, LocalMatrix};
use super::comm::Comm;
use super::local::Key;
use crate::solve::block_jacobi::{Aggregates, BlockJacobi};
use crate::solve::{CgError, Preconditioner};

/// One partition of the rows into blocks, as this rank sees it.
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

/// Rank 0: K's graph in global numbers (columns sorted, as the serial matrix stores them) and
/// the lowest rank touching each row, from every rank's records `[row, rank, count, cols…]`.
fn gathered_graph(records: &[f64], n: usize) -> (Vec<usize>, Vec<u32>, Vec<u32>) {
    let mut cols: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut owner = vec![u32::MAX; n];
    let mut at = 0;
    while at < records.len() {
        let (g, q, len) = (
            records[at] as usize,
            records[at + 1] as u32,
            records[at + 2] as usize,
        );
        owner[g] = owner[g].min(q);
        cols[g].extend(records[at + 3..at + 3 + len].iter().map(|&c| c as u32));
        at += 3 + len;
    }
    let mut indptr = Vec::with_capacity(n + 1);
    indptr.push(0);
    let mut indices = Vec::new();
    for mut c in cols {
        c.sort_unstable();
        c.dedup();
        indices.extend_from_slice(&c);
        indptr.push(indices.len());
    }
    (indptr, indices, owner)
}

/// One partition as rank 0 grew it: the rows of every block in the order of growth (block a is
/// `rows[start[a]..start[a + 1]]`) and each block's home rank.
struct Blocks {
    rows: Vec<u32>,
    start: Vec<usize>,
    home: Vec<u32>,
}

/// Rank 0 grows the serial aggregates on the gathered graph; every rank receives them.
fn serial_aggregates(
    comm: &dyn Comm,
    k: &LocalMatrix,
    numbers: &[u32],
    n: usize,
    size: usize,
    pair: bool,
) -> Vec<Blocks> {
    let mut records = Vec::new();
    for (i, &g) in numbers.iter().enumerate() {
        let (cols, _) = k.row(i);
        records.extend([g as f64, comm.rank() as f64, cols.len() as f64]);
        records.extend(cols.iter().map(|&c| numbers[c as usize] as f64));
    }
    let gathered = comm.gather_f64(0, &records);
    drop(records);
    // Per partition: the number of blocks, the rows, the starts, the homes.
    let message: Vec<f64> = match gathered {
        Some(records) => {
            let (indptr, indices, owner) = gathered_graph(&records, n);
            drop(records);
            let mut partitions = vec![Aggregates::new(&indptr, &indices, size)];
            if pair {
                partitions.push(Aggregates::reversed(&indptr, &indices, size));
            }
            let mut m = Vec::new();
            for agg in &partitions {
                let blocks = agg.start.len() - 1;
                m.push(blocks as f64);
                m.extend(agg.rows.iter().map(|&r| r as f64));
                m.extend(agg.start.iter().map(|&s| s as f64));
                m.extend((0..blocks).map(|a| owner[agg.rows[agg.start[a]] as usize] as f64));
            }
            m
        }
        None => Vec::new(),
    };
    let message = comm.all_gather_f64(&message).swap_remove(0);
    let mut out = Vec::new();
    let mut at = 0;
    while at < message.len() {
        let blocks = message[at] as usize;
        at += 1;
        let take = |at: &mut usize, len: usize| {
            let s = &message[*at..*at + len];
            *at += len;
            s
        };
        let rows = take(&mut at, n).iter().map(|&r| r as u32).collect();
        let start = take(&mut at, blocks + 1).iter().map(|&s| s as usize).collect();
        let home = take(&mut at, blocks).iter().map(|&q| q as u32).collect();
        out.push(Blocks { rows, start, home });
    }
    out
}

impl GlobalBlocks {
    /// The blocks of at most `size` rows (collective; see the module docs); both partitions of
    /// the pair when `pair`. A block that fails to factor fails on every rank alike.
    pub fn new(
        comm: &dyn Comm,
        halo: &Halo,
        k: &LocalMatrix,
        size: usize,
        pair: bool,
    ) -> Result<GlobalBlocks, CgError> {
        let (numbers, n) = global_numbers(comm, halo);
        let partitions = serial_aggregates(comm, k, &numbers, n, size.max(1), pair);
        let mut parts = Vec::new();
        let mut failure = None;
        for blocks in &partitions {
            let part = Partition::new(comm, halo, k, &numbers, blocks);
            match part {
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
        let home_of = |i: usize| home[of[numbers[i] as usize] as usize] as usize;
        let mut send_r = vec![Vec::new(); ranks];
        let mut recv_z = vec![Vec::new(); ranks];
        for i in 0..numbers.len() {
            let q = home_of(i);
            recv_z[q].push(i as u32);
            if halo.owned[i] {
                send_r[q].push(i as u32);
            }
        }
        // To each home: the rows this rank sends r of, the rows it wants z of, and its partial
        // entries of the blocks (row, column, value; the columns in the row's block).
        let mut send = vec![Vec::new(); ranks];
        for q in 0..ranks {
            let s = &mut send[q];
            s.push(send_r[q].len() as f64);
            s.extend(send_r[q].iter().map(|&i| numbers[i as usize] as f64));
            s.push(recv_z[q].len() as f64);
            s.extend(recv_z[q].iter().map(|&i| numbers[i as usize] as f64));
            for &i in &recv_z[q] {
                let g = numbers[i as usize];
                let (cols, values) = k.row(i as usize);
                for (&c, &v) in cols.iter().zip(values) {
                    let h = numbers[c as usize];
                    if of[h as usize] == of[g as usize] {
                        s.extend([g as f64, h as f64, v]);
                    }
                }
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
        let mut recv_r = vec![Vec::new(); ranks];
        let mut send_z = vec![Vec::new(); ranks];
        let mut entries: Vec<Vec<(u32, f64)>> = vec![Vec::new(); m];
        for (q, buf) in received.iter().enumerate() {
            let nr = buf[0] as usize;
            recv_r[q] = buf[1..1 + nr]
                .iter()
                .map(|&g| position[g as usize])
                .collect();
            let nz = buf[1 + nr] as usize;
            let at = 2 + nr;
            send_z[q] = buf[at..at + nz]
                .iter()
                .map(|&g| position[g as usize])
                .collect();
            for t in buf[at + nz..].chunks_exact(3) {
                let (i, j) = (position[t[0] as usize], position[t[1] as usize]);
                entries[i as usize].push((j, t[2]));
            }
        }
        drop(received);
        let blocks = if m == 0 {
            None
        } else {
            let mut indptr = vec![0usize];
            let (mut indices, mut data) = (Vec::new(), Vec::new());
            for row in entries {
                for (j, v) in row {
                    indices.push(j);
                    data.push(v);
                }
                indptr.push(indices.len());
            }
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
            let blocks = GlobalBlocks::new(&comm, &halo, &local, 8, pair).unwrap();
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
        let k = NormalMatrix::new(n, fptr, fidx, fdat);
        let mut halo = Halo::new(0, &[(0..n as u32).collect()], n);
        halo.keys = (0..n).map(|i| [0, flip(i) as u64, 0, 0, 0]).collect();
        let local = LocalMatrix::new(&k, &halo);
        let r: Vec<[f64; 3]> = (0..n).map(|i| [i as f64, 1.0, (i * i) as f64]).collect();
        let r_flipped: Vec<[f64; 3]> = (0..n).map(|i| r[flip(i)]).collect();
        let comm = Single::default();
        let blocks = GlobalBlocks::new(&comm, &halo, &local, 8, true).unwrap();
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
