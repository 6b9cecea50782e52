//! Each rank's share of a single binary MSH 4.1 file: read by runs, repartitioned along the
//! Morton curve, then ghosted.
//!
//! Input: the file's path, the communicator, the ghost depth g. Output: a [`LocalMesh`]
//! whose own elements are the rank's part of the Morton partition
//! ([`super::partition`]: the elements sorted by the Morton key of their centroid in the
//! mesh's bounding box, ties by file index, cut into equal runs), in increasing global index,
//! then the ghosts within g vertex rings, with the rank owning each.
//!
//! Steps: (1) each rank reads the contiguous run ⌊rN/P⌋ … ⌊(r+1)N/P⌋ − 1 of the file's
//! elements at their offsets and the coordinates of their nodes; (2) the bounding box by a
//! min- and max-reduce, the Morton keys of the run's centroids, the cut values by bisection
//! (128 sum-reduces of P − 1 counts); (3) every element of the run travels to the rank of
//! its part (index, physical tag, node tags: (2 + nodes per element) × 8 B); (4) the ghost
//! rings by streamed passes over the file ([`MshFile::ghosts`]); (5) each ghost's owner from
//! the rank whose run holds it (one request and one answer of 8 B per ghost); (6) the tagged
//! facets and the coordinates ([`MshFile::local_mesh`]).
//!
//! Gmsh's partitioned files (`$PartitionedEntities`) go to [`super::read_parts`] instead,
//! which reads each rank's parts and joins the same steps from the Morton partition on.
//!
//! `POLYSPLINE_PARTITION=file-order` skips steps 2 and 3 (each rank owns its run), for
//! comparison.
//!
//! Why: the file's order cut into runs gives slabs for meshes numbered along layers, and a
//! slab's ghost rings are as large as its cross-section; Morton parts are compact, so their
//! ghosts and halos grow like their surface. Invariant: every element is owned by exactly one
//! rank; the partition depends only on the file (not on how the runs were read).

use super::comm::Comm;
use super::partition::{Grid, sort_value, thresholds};
use super::read::{Elements, LocalMesh, MshFile};
use crate::mesh::MeshOptions;
use crate::mesh::raw::{Location, ParseError};
use std::collections::{HashMap, HashSet};
use std::path::Path;

/// Read this rank's share with `depth` vertex rings of ghosts (see the module docs); with
/// `seams` (node tag → representative tag of glued periodic seams) the rings run on across
/// the seams ([`MshFile::ghosts`], and for Gmsh's parts `read_parts`' rings).
pub fn read_share(
    comm: &dyn Comm,
    path: &Path,
    depth: usize,
    options: &MeshOptions,
    seams: Option<&HashMap<u64, u64>>,
) -> Result<LocalMesh, crate::io::ReadError> {
    let wrap = |source| crate::io::ReadError::Parse {
        path: path.to_owned(),
        source,
    };
    // Gmsh's partitioned files: each rank reads its parts (`super::read_parts`, whose errors
    // are agreed like the ones below).
    if super::read_parts::is_partitioned(path) {
        return super::read_parts::read_parts_share(comm, path, depth, options, seams)
            .map_err(wrap);
    }
    // Each step that can fail on one rank alone (a truncated or corrupt run of the file, a
    // node missing or not finite among its share's) is agreed before the next collective, so
    // every rank stops together with the failing rank's error.
    let elsewhere = |q: usize| wrap(ParseError::new(Location::File, format!("rank {q} failed")));
    let mut file = agree_with(comm, MshFile::open(path).map_err(wrap), elsewhere)?;
    let (rank, size) = (comm.rank(), comm.size());
    let starts = LocalMesh::starts(file.n_global, size);
    let (lo, hi) = (starts[rank], starts[rank + 1]);
    let run = agree_with(comm, file.run(lo, hi).map_err(wrap), elsewhere)?;
    let part = if file_order() {
        vec![rank as u32; run.global.len()]
    } else {
        let have: HashSet<u64> = run.nodes.iter().copied().collect();
        let coords = agree_with(comm, file.coordinates(&have).map_err(wrap), elsewhere)?;
        drop(have);
        morton_parts(comm, &file, &run, coords)
    };
    let own = route(comm, &run, &part, file.npe);
    drop(run);
    let ghosts = agree_with(
        comm,
        file.ghosts(&own, depth, seams).map_err(wrap),
        elsewhere,
    )?;
    let owner = ghost_owners(comm, &starts, lo, &part, &ghosts.global);
    drop(part);
    agree_with(
        comm,
        file.local_mesh(own, ghosts, owner, rank, options)
            .map_err(wrap),
        elsewhere,
    )
}

/// [`super::comm::agree`] for a read step.
fn agree_with<T>(
    comm: &dyn Comm,
    r: Result<T, crate::io::ReadError>,
    elsewhere: impl FnOnce(usize) -> crate::io::ReadError,
) -> Result<T, crate::io::ReadError> {
    super::comm::agree(comm, r, elsewhere)
}

/// `POLYSPLINE_PARTITION=file-order`: keep the runs of the file as the partition (no
/// repartition), to measure what the Morton partition saves.
fn file_order() -> bool {
    std::env::var("POLYSPLINE_PARTITION").is_ok_and(|v| v == "file-order")
}

/// The Morton part of every element of `run` (see the module docs, step 2).
/// `coords`: the tags and coordinates of the run's nodes.
fn morton_parts(
    comm: &dyn Comm,
    file: &MshFile,
    run: &Elements,
    coords: (Vec<u64>, Vec<[f64; 3]>),
) -> Vec<u32> {
    let (tags, points) = coords;
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    comm.min_f64(&mut lo);
    comm.max_f64(&mut hi);
    let grid = Grid::new(lo, hi);
    let at: HashMap<u64, usize> = tags.iter().enumerate().map(|(i, &t)| (t, i)).collect();
    let npe = file.npe;
    let values: Vec<u128> = run
        .global
        .iter()
        .zip(run.nodes.chunks_exact(npe))
        .map(|(&g, v)| {
            let corners: Vec<[f64; 3]> = v.iter().map(|t| points[at[t]]).collect();
            sort_value(grid.key(&corners), g)
        })
        .collect();
    let mut sorted = values.clone();
    sorted.sort_unstable();
    let cut = thresholds(file.n_global, comm.size(), |mid| {
        let mut c: Vec<u64> = mid
            .iter()
            .map(|&m| sorted.partition_point(|&x| x <= m) as u64)
            .collect();
        comm.sum_u64(&mut c);
        c
    });
    values
        .iter()
        .map(|v| cut.partition_point(|&t| t <= *v) as u32)
        .collect()
}

/// Send every element of `run` to the rank of its part; the elements received, in increasing
/// global index (step 3). Indices and node tags travel as f64 (exact below 2⁵³).
pub(super) fn route(comm: &dyn Comm, run: &Elements, part: &[u32], npe: usize) -> Elements {
    let mut send = vec![Vec::new(); comm.size()];
    for (i, &q) in part.iter().enumerate() {
        let s = &mut send[q as usize];
        s.push(run.global[i] as f64);
        s.push(run.tags[i] as f64);
        s.extend(run.nodes[i * npe..(i + 1) * npe].iter().map(|&t| t as f64));
    }
    let recv = comm.exchange_f64(&send);
    drop(send);
    let mut records: Vec<&[f64]> = recv.iter().flat_map(|r| r.chunks_exact(npe + 2)).collect();
    records.sort_unstable_by_key(|r| r[0] as u64);
    let mut own = Elements::default();
    for r in records {
        let nodes: Vec<u64> = r[2..].iter().map(|&t| t as u64).collect();
        own.global.push(r[0] as u64);
        own.tags.push(r[1] as i32);
        own.nodes.extend(nodes);
    }
    own
}

/// The rank owning each of `ghosts`, asked of the rank whose run holds it (step 5).
fn ghost_owners(
    comm: &dyn Comm,
    starts: &[u64],
    lo: u64,
    part: &[u32],
    ghosts: &[u64],
) -> Vec<u32> {
    let size = comm.size();
    let mut ask = vec![Vec::new(); size];
    for &g in ghosts {
        ask[LocalMesh::run_of(starts, g)].push(g as f64);
    }
    let asked = comm.exchange_f64(&ask);
    let answer: Vec<Vec<f64>> = asked
        .iter()
        .map(|list| {
            list.iter()
                .map(|&g| part[(g as u64 - lo) as usize] as f64)
                .collect()
        })
        .collect();
    let answered = comm.exchange_f64(&answer);
    // The answers come back per run in the order asked.
    let mut next = vec![0usize; size];
    ghosts
        .iter()
        .map(|&g| {
            let q = LocalMesh::run_of(starts, g);
            next[q] += 1;
            answered[q][next[q] - 1] as u32
        })
        .collect()
}
