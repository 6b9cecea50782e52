//! The collective operations the distributed curve job needs, behind one trait: MPI through
//! rsmpi with the `mpi` feature (`Mpi`), or a single process ([`Single`], which the unit
//! tests and the one-rank case use).
//!
//! Every method is collective: all ranks call it in the same order. Each implementation
//! counts the bytes this rank sends ([`Comm::bytes_sent`]) so reports can state the
//! communication volume.

use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The lowest rank whose stage failed, as the first failed [`agree`] found it (`usize::MAX`:
/// none yet). The launcher lets that rank print the job's one error line.
static FAILING_RANK: AtomicUsize = AtomicUsize::new(usize::MAX);

/// Agree on a stage's outcome across the ranks: one min-reduce of the failing ranks. When no
/// rank failed, `r` is returned unchanged; when any did, every rank returns an error (its own,
/// or `elsewhere(q)` with q the lowest failing rank), so no rank goes on into a collective the
/// failed ones will never join. Every stage boundary where a rank can fail alone (a read, a
/// check of its share) ends in one call of this, on every rank.
pub fn agree<T, E>(
    comm: &dyn Comm,
    r: Result<T, E>,
    elsewhere: impl FnOnce(usize) -> E,
) -> Result<T, E> {
    match (lowest_failed(comm, r.is_err()), r) {
        (Some(q), Ok(_)) => Err(elsewhere(q)),
        (_, r) => r,
    }
}

/// Bytes (text, a file's header) as the collectives carry them: one f64 each.
pub fn bytes_as_f64(bytes: &[u8]) -> Vec<f64> {
    bytes.iter().map(|&b| f64::from(b)).collect()
}

/// The bytes of [`bytes_as_f64`] back.
pub fn f64_as_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().map(|&b| b as u8).collect()
}

/// The lowest rank whose stage failed (`failed`: this rank's did), when any did ([`agree`]'s
/// one min-reduce); the first such rank is the one [`failing_rank`] names.
pub fn lowest_failed(comm: &dyn Comm, failed: bool) -> Option<usize> {
    let mut lowest = [if failed {
        comm.rank() as f64
    } else {
        f64::INFINITY
    }];
    comm.min_f64(&mut lowest);
    if !lowest[0].is_finite() {
        return None;
    }
    let q = lowest[0] as usize;
    // Only the first failure counts: later stages do not run.
    let _ = FAILING_RANK.compare_exchange(usize::MAX, q, Ordering::Relaxed, Ordering::Relaxed);
    Some(q)
}

/// The ranks of a communicator as the job's processes ([`crate::pipeline::head`]).
impl crate::pipeline::head::Reduction for dyn Comm + '_ {
    fn reduce(&self, op: crate::pipeline::head::Reduce, v: &mut [f64]) {
        use crate::pipeline::head::Reduce;
        match op {
            Reduce::Sum => self.sum_f64(v),
            Reduce::Min => self.min_f64(v),
            Reduce::Max => self.max_f64(v),
        }
    }
    fn lowest_failed(&self, failed: bool) -> Option<usize> {
        lowest_failed(self, failed)
    }
}

/// The rank that found the job's first error, agreed over the ranks by [`agree`]; `None` when
/// no agreed stage failed (an error every rank finds alike is then printed by rank 0).
pub fn failing_rank() -> Option<usize> {
    let q = FAILING_RANK.load(Ordering::Relaxed);
    (q != usize::MAX).then_some(q)
}

/// Collective communication among the ranks of a job.
pub trait Comm {
    fn rank(&self) -> usize;
    fn size(&self) -> usize;
    /// Element-wise sum over the ranks, in place (every rank gets the result).
    fn sum_f64(&self, v: &mut [f64]);
    /// Element-wise minimum over the ranks, in place.
    fn min_f64(&self, v: &mut [f64]);
    /// Element-wise maximum over the ranks, in place.
    fn max_f64(&self, v: &mut [f64]);
    /// Element-wise sum of counters over the ranks, in place.
    fn sum_u64(&self, v: &mut [u64]);
    /// Every rank's `v`, indexed by rank, on every rank.
    fn all_gather_f64(&self, v: &[f64]) -> Vec<Vec<f64>>;
    /// Personalised exchange: `send[q]` goes to rank q; returns what each rank sent here.
    fn exchange_f64(&self, send: &[Vec<f64>]) -> Vec<Vec<f64>>;
    /// [`Comm::exchange_f64`] when every pair of ranks sends each other as many values (a
    /// halo's lists are the same on both sides): the counts need not be exchanged first.
    fn exchange_symmetric_f64(&self, send: &[Vec<f64>]) -> Vec<Vec<f64>> {
        self.exchange_f64(send)
    }
    /// Every rank's `v` on `root`, concatenated in rank order (one buffer, no copy per
    /// rank); `None` on the other ranks.
    fn gather_f64(&self, root: usize, v: &[f64]) -> Option<Vec<f64>>;
    /// Bytes this rank has sent so far.
    fn bytes_sent(&self) -> u64;
}

/// One process: every collective is the identity.
#[derive(Default)]
pub struct Single {
    sent: Cell<u64>,
}

impl Comm for Single {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn sum_f64(&self, _: &mut [f64]) {}
    fn min_f64(&self, _: &mut [f64]) {}
    fn max_f64(&self, _: &mut [f64]) {}
    fn sum_u64(&self, _: &mut [u64]) {}
    fn all_gather_f64(&self, v: &[f64]) -> Vec<Vec<f64>> {
        vec![v.to_vec()]
    }
    fn exchange_f64(&self, send: &[Vec<f64>]) -> Vec<Vec<f64>> {
        send.to_vec()
    }
    fn gather_f64(&self, _root: usize, v: &[f64]) -> Option<Vec<f64>> {
        Some(v.to_vec())
    }
    fn bytes_sent(&self) -> u64 {
        self.sent.get()
    }
}

/// Split a concatenated receive buffer by counts.
#[cfg_attr(not(feature = "mpi"), allow(dead_code))]
fn split(buf: Vec<f64>, counts: &[i32]) -> Vec<Vec<f64>> {
    let mut out = Vec::with_capacity(counts.len());
    let mut at = 0;
    for &c in counts {
        out.push(buf[at..at + c as usize].to_vec());
        at += c as usize;
    }
    out
}

#[cfg(feature = "mpi")]
pub use with_mpi::Mpi;

#[cfg(feature = "mpi")]
mod with_mpi {
    use super::{Cell, Comm, split};
    use mpi::collective::SystemOperation;
    use mpi::datatype::{Partition, PartitionMut};
    use mpi::topology::{Communicator, SimpleCommunicator};
    use mpi::traits::*;

    /// MPI's world communicator (rsmpi over the system MPI).
    pub struct Mpi {
        pub world: SimpleCommunicator,
        sent: Cell<u64>,
    }

    impl Mpi {
        pub fn new(world: SimpleCommunicator) -> Self {
            Mpi {
                world,
                sent: Cell::new(0),
            }
        }

        fn count(&self, bytes: usize) {
            self.sent.set(self.sent.get() + bytes as u64);
        }

        fn reduce<T: Equivalence + Copy>(&self, v: &mut [T], op: SystemOperation) {
            if self.size() == 1 || v.is_empty() {
                return;
            }
            self.count(std::mem::size_of_val(v));
            let send = v.to_vec();
            self.world.all_reduce_into(&send[..], v, op);
        }

        fn displacements(counts: &[i32]) -> Vec<i32> {
            counts
                .iter()
                .scan(0, |at, &c| {
                    let d = *at;
                    *at += c;
                    Some(d)
                })
                .collect()
        }

        fn counts_of(&self, n: usize) -> Vec<i32> {
            let mut counts = vec![0i32; self.size()];
            self.world.all_gather_into(&(n as i32), &mut counts[..]);
            counts
        }
    }

    impl Comm for Mpi {
        fn rank(&self) -> usize {
            self.world.rank() as usize
        }
        fn size(&self) -> usize {
            self.world.size() as usize
        }
        fn sum_f64(&self, v: &mut [f64]) {
            self.reduce(v, SystemOperation::sum())
        }
        fn min_f64(&self, v: &mut [f64]) {
            self.reduce(v, SystemOperation::min())
        }
        fn max_f64(&self, v: &mut [f64]) {
            self.reduce(v, SystemOperation::max())
        }
        fn sum_u64(&self, v: &mut [u64]) {
            self.reduce(v, SystemOperation::sum())
        }
        fn all_gather_f64(&self, v: &[f64]) -> Vec<Vec<f64>> {
            let counts = self.counts_of(v.len());
            let displs = Self::displacements(&counts);
            let total: i32 = counts.iter().sum();
            let mut buf = vec![0.0f64; total as usize];
            self.count(8 * v.len() * (self.size() - 1));
            {
                let mut part = PartitionMut::new(&mut buf[..], &counts[..], &displs[..]);
                self.world.all_gather_varcount_into(v, &mut part);
            }
            split(buf, &counts)
        }
        fn exchange_f64(&self, send: &[Vec<f64>]) -> Vec<Vec<f64>> {
            let n = self.size();
            assert_eq!(send.len(), n);
            let send_counts: Vec<i32> = send.iter().map(|s| s.len() as i32).collect();
            let mut recv_counts = vec![0i32; n];
            self.world
                .all_to_all_into(&send_counts[..], &mut recv_counts[..]);
            let flat: Vec<f64> = send.concat();
            let me = self.rank();
            self.count(8 * (flat.len() - send[me].len()));
            let send_displs = Self::displacements(&send_counts);
            let recv_displs = Self::displacements(&recv_counts);
            let total: i32 = recv_counts.iter().sum();
            let mut buf = vec![0.0f64; total as usize];
            {
                let sp = Partition::new(&flat[..], &send_counts[..], &send_displs[..]);
                let mut rp = PartitionMut::new(&mut buf[..], &recv_counts[..], &recv_displs[..]);
                self.world.all_to_all_varcount_into(&sp, &mut rp);
            }
            split(buf, &recv_counts)
        }
        fn exchange_symmetric_f64(&self, send: &[Vec<f64>]) -> Vec<Vec<f64>> {
            let n = self.size();
            assert_eq!(send.len(), n);
            let counts: Vec<i32> = send.iter().map(|s| s.len() as i32).collect();
            let flat: Vec<f64> = send.concat();
            self.count(8 * (flat.len() - send[self.rank()].len()));
            let displs = Self::displacements(&counts);
            let mut buf = vec![0.0f64; flat.len()];
            {
                let sp = Partition::new(&flat[..], &counts[..], &displs[..]);
                let mut rp = PartitionMut::new(&mut buf[..], &counts[..], &displs[..]);
                self.world.all_to_all_varcount_into(&sp, &mut rp);
            }
            split(buf, &counts)
        }
        fn gather_f64(&self, root: usize, v: &[f64]) -> Option<Vec<f64>> {
            let counts = self.counts_of(v.len());
            let proc = self.world.process_at_rank(root as i32);
            if self.rank() == root {
                let displs = Self::displacements(&counts);
                let total: i32 = counts.iter().sum();
                let mut buf = vec![0.0f64; total as usize];
                {
                    let mut part = PartitionMut::new(&mut buf[..], &counts[..], &displs[..]);
                    proc.gather_varcount_into_root(v, &mut part);
                }
                Some(buf)
            } else {
                self.count(8 * v.len());
                proc.gather_varcount_into(v);
                None
            }
        }
        fn bytes_sent(&self) -> u64 {
            self.sent.get()
        }
    }
}
