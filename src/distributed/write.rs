//! One MSH 4.1 file written collectively by the ranks, each writing its own part at its byte
//! offset: no rank holds the whole mesh.
//!
//! Input: each rank's [`RankOutput`] (its owned nodes, its elements and boundary facets in
//! global node tags), the output path and options. Output: on rank 0, a complete and synced
//! temporary beside the target ([`PendingFile`]), renamed over the target by the caller after
//! the report is ready; `None` on the others.
//!
//! Layout (the serial writer's sections and groups, [`crate::io::gmsh_write`], every entity,
//! node block and element block encoded by its `Blocks`):
//! `$MeshFormat`, `$PhysicalNames`, `$Entities` (one entity per physical group, its bounding
//! box reduced over the ranks) and the `$Nodes` header, written by rank 0; one node block per
//! rank holding its owned nodes; then `$Elements` with one block per physical group, as the
//! serial file: a volume group's records are the ranks' runs in rank order (the ranks hold
//! the file's elements in order), a boundary group's records are in the serial order of
//! boundary facets (their sorted vertex tags), so the element tags are the serial ones; then,
//! with periodic pairs, `$Periodic` (rank 0: the serial writer's section, node pairs in
//! global tags).
//!
//! Offsets: every part's size is computed first by formatting it into a byte counter (exact
//! for ASCII and binary alike), the sizes are all-gathered, and each rank writes its parts
//! with `pwrite` ([`FileExt::write_at`]) at the exclusive scan of the sizes before them. The
//! file is a temporary created exclusively by rank 0 ([`crate::io::output::prepare`]); every
//! rank syncs its writes and reports success in one reduction (the barrier) before rank 0 may
//! rename it, so the target is never half-written; a failed write on any rank removes the
//! temporary and leaves the target untouched.

use super::comm::Comm;
use super::sample::RankOutput;
use crate::io::gmsh_write::{
    Blocks, PeriodicRecord, PlannedGroup, group_plan, write_format_and_names,
    write_periodic_section,
};
use crate::io::output::{PendingFile, WriteError};
use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

/// Counts the bytes written to it.
#[derive(Default)]
pub(super) struct Counter(u64);

impl Write for Counter {
    fn write(&mut self, b: &[u8]) -> io::Result<usize> {
        self.0 += b.len() as u64;
        Ok(b.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// Writes at increasing offsets of a file with `pwrite` (no shared file position).
struct At<'f> {
    file: &'f File,
    at: u64,
}

impl Write for At<'_> {
    fn write(&mut self, b: &[u8]) -> io::Result<usize> {
        let n = self.file.write_at(b, self.at)?;
        self.at += n as u64;
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// Byte size of what `f` writes.
pub(super) fn size_of(f: impl FnOnce(&mut Counter) -> io::Result<()>) -> u64 {
    let mut c = Counter::default();
    f(&mut c).expect("counting never fails");
    c.0
}

/// Write what `f` writes at `at` of `file`, buffered.
fn write_at(
    file: &File,
    at: u64,
    f: impl FnOnce(&mut BufWriter<At<'_>>) -> io::Result<()>,
) -> io::Result<()> {
    let mut w = BufWriter::with_capacity(1 << 20, At { file, at });
    f(&mut w)?;
    w.flush()
}

/// Non-negative tag (a reader takes no other as an id): the serial writer's rule.
pub(super) fn clamp(t: i32) -> i32 {
    t.max(0)
}

/// What every rank agrees on before writing: the groups, their global member counts and
/// boxes, the node count and tag range, and the formats of the records.
pub(super) struct Plan {
    /// The encoding of the file's entities and blocks.
    pub(super) blocks: Blocks,
    pub(super) d: usize,
    pub(super) groups: Vec<PlannedGroup>,
    /// Members of each group on each rank (`[rank][group]`).
    pub(super) counts: Vec<Vec<u64>>,
    pub(super) bbox: Vec<[f64; 6]>,
    /// Owned nodes per rank, the smallest and largest node tag.
    nodes: Vec<u64>,
    tag_range: [u64; 2],
}

impl Plan {
    pub(super) fn group_of(&self, boundary: bool, tag: i32) -> usize {
        let dim = if boundary { self.d - 1 } else { self.d };
        self.groups
            .iter()
            .position(|g| g.dim == dim && g.tag == clamp(tag))
            .expect("every tag present has its group")
    }

    /// The group of own element `e`.
    pub(super) fn vol_group(&self, out: &RankOutput, e: usize) -> usize {
        self.group_of(false, out.element_tags.get(e).copied().unwrap_or(0))
    }

    pub(super) fn total(&self, g: usize) -> u64 {
        self.counts.iter().map(|c| c[g]).sum()
    }

    /// The element tag of each group's first record (groups in order, tags from 1).
    pub(super) fn first_tags(&self) -> Vec<u64> {
        (0..self.groups.len())
            .scan(1u64, |t, g| {
                let s = *t;
                *t += self.total(g);
                Some(s)
            })
            .collect()
    }

    /// Members of each group on the ranks before `rank`.
    pub(super) fn before(&self, rank: usize) -> Vec<u64> {
        (0..self.groups.len())
            .map(|g| self.counts[..rank].iter().map(|c| c[g]).sum())
            .collect()
    }

    /// `$MeshFormat`, `$PhysicalNames` and `$Entities` (one entity per group, with its box
    /// over all ranks).
    pub(super) fn entities(&self, w: &mut impl Write) -> io::Result<()> {
        let names = self
            .groups
            .iter()
            .map(|g| (g.dim, g.physical, g.name.as_str()));
        write_format_and_names(w, "4.1", self.blocks.binary, names)?;
        let groups: Vec<(usize, i32, i32)> = self
            .groups
            .iter()
            .map(|g| (g.dim, g.entity, g.physical))
            .collect();
        self.blocks.entities(w, &groups, |i| self.bbox[i])
    }

    /// `$MeshFormat`, `$PhysicalNames`, `$Entities` and the `$Nodes` header.
    fn header(&self, w: &mut impl Write) -> io::Result<()> {
        self.entities(w)?;
        writeln!(w, "$Nodes")?;
        let blocks = self.nodes.iter().filter(|&&n| n > 0).count() as u64;
        let nn: u64 = self.nodes.iter().sum();
        let [lo, hi] = self.tag_range;
        self.blocks.four(w, [blocks, nn, lo, hi])
    }

    pub(super) fn vol_entity(&self) -> i32 {
        self.groups
            .iter()
            .find(|g| g.dim == self.d)
            .map_or(1, |g| g.entity)
    }

    /// One node block of a rank (nothing when it owns no node).
    fn node_block(&self, out: &RankOutput, w: &mut impl Write) -> io::Result<()> {
        if out.node_tags.is_empty() {
            return Ok(());
        }
        let tags = &out.node_tags;
        self.blocks
            .node_block(w, self.vol_entity(), |i| tags[i], &out.node_coords)
    }

    /// `$EndNodes` and the `$Elements` header.
    fn middle(&self, w: &mut impl Write) -> io::Result<()> {
        self.blocks.end(w, "Nodes")?;
        writeln!(w, "$Elements")?;
        let ne: u64 = (0..self.groups.len()).map(|g| self.total(g)).sum();
        self.blocks
            .four(w, [self.groups.len() as u64, ne, 1.min(ne), ne])
    }

    fn block_header(&self, g: usize, w: &mut impl Write) -> io::Result<()> {
        let gr = &self.groups[g];
        self.blocks.block_header(
            w,
            gr.dim,
            gr.entity,
            self.blocks.kind(gr.dim),
            self.total(g),
        )
    }

    /// One boundary facet's record: its tag and node tags (lattice order); with no nodes, the
    /// tag alone.
    pub(super) fn facet_record(
        &self,
        tag: u64,
        nodes: &[u64],
        w: &mut impl Write,
    ) -> io::Result<()> {
        self.blocks.record(w, self.d - 1, tag, nodes, 0)
    }
}

/// The groups every rank agrees on, with counts, boxes and node figures (collective).
pub(super) fn plan(comm: &dyn Comm, out: &RankOutput, options: &WriteOptions) -> io::Result<Plan> {
    let (d, p) = (out.dim, out.order);
    let vol_tags: Vec<i32> = if out.element_tags.is_empty() {
        vec![0; out.elements.len() / (p + 1).pow(d as u32)]
    } else {
        out.element_tags.clone()
    };
    let mine_b: BTreeSet<i32> = out.boundary_tags.iter().map(|&t| clamp(t)).collect();
    let mine_v: BTreeSet<i32> = vol_tags.iter().map(|&t| clamp(t)).collect();
    let mut v: Vec<f64> = vec![mine_b.len() as f64];
    v.extend(mine_b.iter().map(|&t| t as f64));
    v.extend(mine_v.iter().map(|&t| t as f64));
    let (mut bnd, mut vol) = (BTreeSet::new(), BTreeSet::new());
    for r in comm.all_gather_f64(&v) {
        let nb = r[0] as usize;
        bnd.extend(r[1..1 + nb].iter().map(|&x| x as i32));
        vol.extend(r[1 + nb..].iter().map(|&x| x as i32));
    }
    let groups = group_plan(
        d,
        bnd.into_iter(),
        vol.into_iter(),
        options.tag_names,
        options.volume_name,
    );
    let mut plan = Plan {
        blocks: Blocks::new(d, p, options.binary)?,
        d,
        counts: Vec::new(),
        bbox: Vec::new(),
        nodes: Vec::new(),
        tag_range: [0, 0],
        groups,
    };
    // Member counts per rank, boxes reduced, node figures.
    let ng = plan.groups.len();
    let mut counts = vec![0f64; ng];
    let mut lo = vec![f64::INFINITY; 3 * ng];
    let mut hi = vec![f64::NEG_INFINITY; 3 * ng];
    let mut add = |g: usize, box6: &[f64; 6]| {
        counts[g] += 1.0;
        for k in 0..3 {
            lo[3 * g + k] = lo[3 * g + k].min(box6[k]);
            hi[3 * g + k] = hi[3 * g + k].max(box6[3 + k]);
        }
    };
    for (i, &t) in vol_tags.iter().enumerate() {
        add(plan.group_of(false, t), &out.element_boxes[i]);
    }
    for (i, &t) in out.boundary_tags.iter().enumerate() {
        add(plan.group_of(true, t), &out.boundary_boxes[i]);
    }
    comm.min_f64(&mut lo);
    comm.max_f64(&mut hi);
    plan.bbox = (0..ng)
        .map(|g| {
            std::array::from_fn(|k| {
                if k < 3 {
                    lo[3 * g + k]
                } else {
                    hi[3 * g + k - 3]
                }
            })
        })
        .collect();
    counts.push(out.node_tags.len() as f64);
    let all = comm.all_gather_f64(&counts);
    plan.counts = all
        .iter()
        .map(|c| c[..ng].iter().map(|&x| x as u64).collect())
        .collect();
    plan.nodes = all.iter().map(|c| c[ng] as u64).collect();
    let mut range = [
        out.node_tags.iter().copied().min().unwrap_or(u64::MAX) as f64,
        -(out.node_tags.iter().copied().max().unwrap_or(0) as f64),
    ];
    comm.min_f64(&mut range);
    plan.tag_range = [range[0] as u64, (-range[1]) as u64];
    Ok(plan)
}

/// Where each of this rank's boundary facets goes in its group's records: (position among
/// the group's facets, byte offset from the group's first record), and the byte size of
/// every group's boundary records, from every rank's sort keys and record sizes without the
/// tag (collective; the boundary only).
pub(super) fn facet_places(
    comm: &dyn Comm,
    plan: &Plan,
    out: &RankOutput,
    first_tag: &[u64],
) -> (Vec<(u64, u64)>, Vec<u64>) {
    let npf = (out.order + 1).pow(out.dim as u32 - 1);
    let no_tag = size_of(|w| plan.facet_record(0, &[], w));
    let mut v = Vec::with_capacity(6 * out.boundary_tags.len());
    for (i, &t) in out.boundary_tags.iter().enumerate() {
        let g = plan.group_of(true, t);
        // The record's size without its tag, so that every rank can add the tag's.
        let body =
            size_of(|w| plan.facet_record(0, &out.boundary[i * npf..(i + 1) * npf], w)) - no_tag;
        v.push(g as f64);
        v.extend(out.boundary_keys[i].iter().map(|&k| k as f64));
        v.push(body as f64);
    }
    let all = comm.all_gather_f64(&v);
    drop(v);
    // (group, key, rank, index on the rank, body size), in the serial order.
    let mut list: Vec<(usize, [u64; 4], usize, usize, u64)> = Vec::new();
    for (r, a) in all.iter().enumerate() {
        for (i, f) in a.chunks_exact(6).enumerate() {
            let key = [f[1], f[2], f[3], f[4]].map(|x| x as u64);
            list.push((f[0] as usize, key, r, i, f[5] as u64));
        }
    }
    drop(all);
    list.sort_unstable();
    let me = comm.rank();
    let mut places = vec![(0, 0); out.boundary_tags.len()];
    let mut bytes = vec![0u64; plan.groups.len()];
    let mut pos = vec![0u64; plan.groups.len()];
    for (g, _, r, i, body) in list {
        let tag = first_tag[g] + pos[g];
        if r == me {
            places[i] = (pos[g], bytes[g]);
        }
        bytes[g] += body + size_of(|w| plan.facet_record(tag, &[], w));
        pos[g] += 1;
    }
    (places, bytes)
}

/// Where this rank writes: the byte offsets of its parts and the tags of its records
/// (collective).
struct Layout {
    first_tag: Vec<u64>,
    /// This rank's records of each group come after `before[g]` records of the lower ranks.
    before: Vec<u64>,
    /// Offsets of rank 0's parts: `$Elements` header, each group's block header, the tail.
    middle_at: u64,
    block_at: Vec<u64>,
    tail_at: u64,
    /// Offsets of this rank's node block and of its volume records of each group.
    nodes_at: u64,
    volume_at: Vec<u64>,
    /// Boundary facets: position in their group and offset of the group's first record.
    places: Vec<(u64, u64)>,
}

fn layout(comm: &dyn Comm, plan: &Plan, out: &RankOutput) -> Layout {
    let rank = comm.rank();
    let npe = (out.order + 1).pow(out.dim as u32);
    let ng = plan.groups.len();
    let first_tag = plan.first_tags();
    let before = plan.before(rank);
    // This rank's volume record bytes per group (with their tags), and its node block's.
    let mut bytes = vec![0f64; ng + 1];
    let mut seen = vec![0u64; ng];
    for e in 0..out.elements.len() / npe {
        let g = plan.vol_group(out, e);
        let tag = first_tag[g] + before[g] + seen[g];
        seen[g] += 1;
        let nodes = &out.elements[e * npe..(e + 1) * npe];
        bytes[g] += size_of(|w| plan.blocks.record(w, plan.d, tag, nodes, 0)) as f64;
    }
    bytes[ng] = size_of(|w| plan.node_block(out, w)) as f64;
    let sizes = comm.all_gather_f64(&bytes);
    drop(bytes);
    let (places, boundary_bytes) = facet_places(comm, plan, out, &first_tag);
    let header = size_of(|w| plan.header(w));
    let nodes_at = header + sizes[..rank].iter().map(|s| s[ng] as u64).sum::<u64>();
    let middle_at = header + sizes.iter().map(|s| s[ng] as u64).sum::<u64>();
    let mut at = middle_at + size_of(|w| plan.middle(w));
    let mut block_at = Vec::with_capacity(ng);
    let mut volume_at = Vec::with_capacity(ng);
    for g in 0..ng {
        block_at.push(at);
        at += size_of(|w| plan.block_header(g, w));
        if plan.groups[g].dim == plan.d {
            volume_at.push(at + sizes[..rank].iter().map(|s| s[g] as u64).sum::<u64>());
            at += sizes.iter().map(|s| s[g] as u64).sum::<u64>();
        } else {
            // A boundary group's facets: offsets from here.
            volume_at.push(at);
            at += boundary_bytes[g];
        }
    }
    Layout {
        first_tag,
        before,
        middle_at,
        block_at,
        tail_at: at,
        nodes_at,
        volume_at,
        places,
    }
}

/// Write this rank's parts at their offsets (no communication, so a failing rank cannot
/// leave the others waiting).
fn write_parts(
    plan: &Plan,
    out: &RankOutput,
    l: &Layout,
    rank: usize,
    file: &File,
) -> io::Result<()> {
    let npe = (out.order + 1).pow(out.dim as u32);
    let npf = (out.order + 1).pow(out.dim as u32 - 1);
    if rank == 0 {
        write_at(file, 0, |w| plan.header(w))?;
        write_at(file, l.middle_at, |w| plan.middle(w))?;
        for g in 0..plan.groups.len() {
            write_at(file, l.block_at[g], |w| plan.block_header(g, w))?;
        }
        write_at(file, l.tail_at, |w| {
            plan.blocks.end(w, "Elements")?;
            periodic_section(plan, out, w)
        })?;
    }
    write_at(file, l.nodes_at, |w| plan.node_block(out, w))?;
    for g in (0..plan.groups.len()).filter(|&g| plan.groups[g].dim == plan.d) {
        let mine: Vec<usize> = (0..out.elements.len() / npe)
            .filter(|&e| plan.vol_group(out, e) == g)
            .collect();
        write_at(file, l.volume_at[g], |w| {
            let first = l.first_tag[g] + l.before[g];
            plan.blocks.records(w, plan.d, first, mine.len(), 0, |k| {
                &out.elements[mine[k] * npe..(mine[k] + 1) * npe]
            })
        })?;
    }
    // Boundary facets one record each, at their places in the serial order.
    let mut buf = Vec::new();
    for (i, &t) in out.boundary_tags.iter().enumerate() {
        let g = plan.group_of(true, t);
        let (pos, off) = l.places[i];
        buf.clear();
        let nodes = &out.boundary[i * npf..(i + 1) * npf];
        plan.facet_record(l.first_tag[g] + pos, nodes, &mut buf)?;
        file.write_all_at(&buf, l.volume_at[g] + off)?;
    }
    file.sync_all()
}

/// `$Periodic` after `$Elements` (rank 0; every rank holds the whole node pairs): the serial
/// writer's section, entities of the boundary groups and the node pairs in global tags.
fn periodic_section(plan: &Plan, out: &RankOutput, w: &mut impl Write) -> io::Result<()> {
    if out.periodic.is_empty() {
        return Ok(());
    }
    let entity = |tag: i32| plan.groups[plan.group_of(true, tag)].entity;
    let pairs: Vec<_> = out
        .periodic
        .iter()
        .map(|l| move |i: usize| l.node_pairs[i])
        .collect();
    let records: Vec<PeriodicRecord> = out
        .periodic
        .iter()
        .zip(&pairs)
        .map(|(l, pair)| PeriodicRecord {
            slave_entity: entity(l.slave_tag),
            master_entity: entity(l.master_tag),
            affine: l.transform.affine(),
            n: l.node_pairs.len(),
            pair,
        })
        .collect();
    write_periodic_section(
        w,
        crate::io::gmsh_write::MshVersion::V41,
        plan.blocks.binary,
        plan.d as i32 - 1,
        &records,
    )
}

/// Options of the collective write.
pub struct WriteOptions<'a> {
    pub binary: bool,
    pub volume_name: &'a str,
    pub tag_names: &'a BTreeMap<i32, String>,
}

/// Bytes as f64 (one each) from rank 0 to every rank.
pub(super) fn broadcast_bytes(comm: &dyn Comm, bytes: &[u8]) -> Vec<u8> {
    let v = super::comm::bytes_as_f64(bytes);
    super::comm::f64_as_bytes(&comm.all_gather_f64(if comm.rank() == 0 { &v } else { &[] })[0])
}

/// Write the ranks' outputs into one MSH 4.1 file at `path` (see the module docs). Collective.
/// Returns rank 0's pending file (complete and synced on every rank), `None` elsewhere; an
/// error when any rank failed (then no temporary is left).
pub fn write_collective(
    comm: &dyn Comm,
    out: &RankOutput,
    path: &Path,
    inputs: &[&Path],
    options: &WriteOptions,
) -> Result<Option<PendingFile>, WriteError> {
    let io_err = |source| WriteError::Io {
        path: path.to_owned(),
        source,
    };
    // Rank 0 creates the temporary exclusively and tells the others its name.
    let (pending, err0) = if comm.rank() == 0 {
        match crate::io::output::prepare(path, inputs, |_| Ok(())) {
            Ok(p) => (Some(p), None),
            Err(e) => (None, Some(e)),
        }
    } else {
        (None, None)
    };
    let name = pending
        .as_ref()
        .and_then(|p| p.temp_path())
        .map(|p| p.as_os_str().as_encoded_bytes().to_vec())
        .unwrap_or_default();
    let name = broadcast_bytes(comm, &name);
    if name.is_empty() {
        return Err(err0.unwrap_or_else(|| elsewhere(path, "rank 0 could not create the file")));
    }
    // SAFETY: the bytes are rank 0's `OsStr` encoding of a path on the same system.
    let temp = PathBuf::from(unsafe { std::ffi::OsString::from_encoded_bytes_unchecked(name) });
    let result = plan(comm, out, options).and_then(|plan| {
        let l = layout(comm, &plan, out);
        let file = std::fs::OpenOptions::new().write(true).open(&temp)?;
        write_parts(&plan, out, &l, comm.rank(), &file)
    });
    // Every rank's outcome: the barrier before rank 0 may rename the file.
    let mut failed = [result.is_err() as u64];
    comm.sum_u64(&mut failed);
    match result {
        Err(e) => Err(io_err(e)),
        Ok(()) if failed[0] > 0 => Err(elsewhere(path, "another rank failed to write its part")),
        Ok(()) => Ok(pending),
    }
}

pub(super) fn elsewhere(path: &Path, what: &str) -> WriteError {
    WriteError::Refused {
        path: path.to_owned(),
        what: what.into(),
    }
}
