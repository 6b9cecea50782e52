//! Gmsh's partitioned MSH 4.1 output: each rank writes its own file `OUT_<r+1>.msh`, and
//! Gmsh reads the files together as one mesh.
//!
//! Input: each rank's [`RankOutput`] after [`super::sample::to_file_order`] (its run of the
//! file's elements, the boundary facets of its Morton part with the global index of the
//! element each bounds, the nodes it owns), the output path and options. Output: on every
//! rank, its part written to an exclusive temporary beside `OUT_<r+1>.msh`
//! ([`PendingFile`]); [`commit_parts`] renames them all only when every rank has its part
//! (and rank 0 its report) complete and synced, so no part is ever left half-written and no
//! part is renamed while another rank failed.
//!
//! What a part holds (the format of Gmsh's own `Mesh.PartitionSplitMeshFiles=1` files, without
//! the partition-boundary topology and ghost cells): `$MeshFormat`, `$PhysicalNames` and
//! `$Entities` as the single-file writer (the same groups, ids and names, the same parent
//! entities, whose boxes are those of the whole mesh); `$PartitionedEntities` with the
//! number of parts P, no ghost entities, and one partition entity per (group, part) that has
//! elements (tag `max parent tag + g·P + r + 1`, parent the group's entity, partition r + 1,
//! its own box, the group's physical tag), listed alike in every part; `$Nodes`: one block of
//! every node the part's elements and facets use, with its global tag (nodes on a part
//! boundary are written in each part that uses them, with the same tag and bit-identical
//! coordinates: Gmsh merges the files by tag); `$Elements`: one block per (group, part), the
//! volume elements of the rank's run of the file (element tags as the single file's: the
//! serial ones) and the boundary facets bounding them, sorted by tag.
//!
//! Communication: the groups and boundary-facet places of the single-file writer
//! (`write::plan`, `write::facet_places`); each boundary facet travels to the
//! rank whose run holds its element ((8 + its nodes) × 8 B); the coordinates of the nodes a
//! part uses but its rank does not own come through a directory by node tag (rank t mod P):
//! 32 B per owned node in, 8 B per asked node and 24 B per answer; one all-gather of every
//! group's count and box per rank; two sums (the barriers before and after the renames).

use super::comm::Comm;
use super::read::LocalMesh;
use super::sample::RankOutput;
use super::write::{Plan, WriteOptions, elsewhere, facet_places, plan};
use crate::io::output::{PendingFile, WriteBin, WriteError};
use crate::pipeline::{CurveError, CurveReport};
use std::collections::HashMap;
use std::ffi::OsString;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// `DIR/NAME_<k>.EXT` for `DIR/NAME.EXT` (Gmsh's names of the files of a split mesh).
pub fn part_path(path: &Path, k: usize) -> PathBuf {
    let mut name: OsString = path.file_stem().unwrap_or_default().to_os_string();
    name.push(format!("_{k}"));
    if let Some(e) = path.extension() {
        name.push(".");
        name.push(e);
    }
    path.with_file_name(name)
}

/// The part paths `OUT_1 … OUT_P` of `path`.
pub fn part_paths(path: &Path, parts: usize) -> Vec<PathBuf> {
    (1..=parts).map(|k| part_path(path, k)).collect()
}

/// One part's records: its volume elements and boundary facets with their serial tags and
/// groups, and the nodes they use.
struct Part {
    /// (group, tag, index of the element in the rank's output).
    volume: Vec<(usize, u64, usize)>,
    /// (group, tag, node tags), sorted by tag.
    facets: Vec<(usize, u64, Vec<u64>)>,
    /// Node tags (increasing) and coordinates.
    node_tags: Vec<u64>,
    node_coords: Vec<[f64; 3]>,
    /// Members and box of every group in every part (`[rank][group]`).
    counts: Vec<Vec<u64>>,
    boxes: Vec<Vec<[f64; 6]>>,
}

fn empty_box() -> [f64; 6] {
    [
        f64::INFINITY,
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ]
}

fn grow(b: &mut [f64; 6], o: &[f64]) {
    for k in 0..3 {
        b[k] = b[k].min(o[k]);
        b[3 + k] = b[3 + k].max(o[3 + k]);
    }
}

/// The rank's part (collective: facet places, facet routing, node directory, boxes).
fn gather_part(comm: &dyn Comm, plan: &Plan, out: &RankOutput) -> Part {
    let (rank, size) = (comm.rank(), comm.size());
    let ng = plan.groups.len();
    let npe = (out.order + 1).pow(out.dim as u32);
    let npf = (out.order + 1).pow(out.dim as u32 - 1);
    let first_tag = plan.first_tags();
    let before = plan.before(rank);
    let mut counts = vec![0u64; ng];
    let mut boxes = vec![empty_box(); ng];
    let mut volume = Vec::with_capacity(out.elements.len() / npe);
    for e in 0..out.elements.len() / npe {
        let g = plan.vol_group(out, e);
        volume.push((g, first_tag[g] + before[g] + counts[g], e));
        counts[g] += 1;
        grow(&mut boxes[g], &out.element_boxes[e]);
    }
    // Boundary facets: their serial tags, then to the rank whose run holds their element.
    let (places, _) = facet_places(comm, plan, out, &first_tag);
    let n_global: u64 = (0..ng)
        .filter(|&g| plan.groups[g].dim == plan.d)
        .map(|g| plan.total(g))
        .sum();
    let starts = LocalMesh::starts(n_global, size);
    let mut send = vec![Vec::new(); size];
    for (i, &t) in out.boundary_tags.iter().enumerate() {
        let g = plan.group_of(true, t);
        let s = &mut send[LocalMesh::run_of(&starts, out.boundary_elements[i])];
        s.push((first_tag[g] + places[i].0) as f64);
        s.push(g as f64);
        s.extend_from_slice(&out.boundary_boxes[i]);
        s.extend(
            out.boundary[i * npf..(i + 1) * npf]
                .iter()
                .map(|&x| x as f64),
        );
    }
    let recv = comm.exchange_f64(&send);
    drop(send);
    let mut facets: Vec<(usize, u64, Vec<u64>)> = Vec::new();
    for r in recv.iter().flat_map(|r| r.chunks_exact(8 + npf)) {
        let g = r[1] as usize;
        counts[g] += 1;
        grow(&mut boxes[g], &r[2..8]);
        facets.push((g, r[0] as u64, r[8..].iter().map(|&x| x as u64).collect()));
    }
    drop(recv);
    facets.sort_unstable_by_key(|f| f.1);
    // Every node the part uses, from the directory of node tags.
    let mut node_tags: Vec<u64> = out.elements.clone();
    node_tags.extend(facets.iter().flat_map(|f| f.2.iter().copied()));
    node_tags.sort_unstable();
    node_tags.dedup();
    let node_coords = coordinates(comm, out, &node_tags);
    // Every part's counts and boxes.
    let mut v = Vec::with_capacity(7 * ng);
    for g in 0..ng {
        v.push(counts[g] as f64);
        v.extend_from_slice(&boxes[g]);
    }
    let all = comm.all_gather_f64(&v);
    let counts = all
        .iter()
        .map(|a| a.chunks_exact(7).map(|c| c[0] as u64).collect())
        .collect();
    let boxes = all
        .iter()
        .map(|a| {
            a.chunks_exact(7)
                .map(|c| std::array::from_fn(|k| c[1 + k]))
                .collect()
        })
        .collect();
    Part {
        volume,
        facets,
        node_tags,
        node_coords,
        counts,
        boxes,
    }
}

/// The coordinates of the nodes `tags` (sorted), asked of the directory rank `t mod P` to
/// which every rank sends the nodes it owns (collective). Tags travel as f64 (exact below
/// 2⁵³).
fn coordinates(comm: &dyn Comm, out: &RankOutput, tags: &[u64]) -> Vec<[f64; 3]> {
    let size = comm.size() as u64;
    let home = |t: u64| (t % size) as usize;
    let mut send = vec![Vec::new(); size as usize];
    for (t, x) in out.node_tags.iter().zip(&out.node_coords) {
        let s = &mut send[home(*t)];
        s.push(*t as f64);
        s.extend_from_slice(x);
    }
    let recv = comm.exchange_f64(&send);
    drop(send);
    let directory: HashMap<u64, [f64; 3]> = recv
        .iter()
        .flat_map(|r| r.chunks_exact(4))
        .map(|c| (c[0] as u64, [c[1], c[2], c[3]]))
        .collect();
    drop(recv);
    let mut ask = vec![Vec::new(); size as usize];
    for &t in tags {
        ask[home(t)].push(t as f64);
    }
    let asked = comm.exchange_f64(&ask);
    let answers: Vec<Vec<f64>> = asked
        .iter()
        .map(|list| {
            list.iter()
                .flat_map(|&t| directory.get(&(t as u64)).copied().unwrap_or([f64::NAN; 3]))
                .collect()
        })
        .collect();
    drop(directory);
    let answered = comm.exchange_f64(&answers);
    let mut next = vec![0usize; size as usize];
    tags.iter()
        .map(|&t| {
            let q = home(t);
            let a = &answered[q][3 * next[q]..3 * next[q] + 3];
            next[q] += 1;
            [a[0], a[1], a[2]]
        })
        .collect()
}

/// Tag of the partition entity of group `g` in part `r` (0-based) of `parts`: after every
/// parent entity's tag, so no two entities of a dimension share one.
fn partition_entity(plan: &Plan, parts: usize, g: usize, r: usize) -> i32 {
    let base = plan.groups.iter().map(|g| g.entity).max().unwrap_or(0);
    base + (g * parts + r) as i32 + 1
}

/// `$PartitionedEntities`: every part's entity of every group that has members there.
fn partitioned_entities(plan: &Plan, part: &Part, w: &mut impl Write) -> io::Result<()> {
    let binary = plan.blocks.binary;
    let parts = part.counts.len();
    writeln!(w, "$PartitionedEntities")?;
    let mut per_dim = [0u64; 4];
    for c in &part.counts {
        for (g, &n) in c.iter().enumerate() {
            if n > 0 {
                per_dim[plan.groups[g].dim] += 1;
            }
        }
    }
    if binary {
        w.u64(parts as u64)?;
        w.u64(0)?;
    } else {
        writeln!(w, "{parts}\n0")?;
    }
    plan.blocks.four(w, per_dim)?;
    for dim in 1..=3 {
        for (g, gr) in plan.groups.iter().enumerate().filter(|(_, g)| g.dim == dim) {
            for r in (0..parts).filter(|&r| part.counts[r][g] > 0) {
                let tag = partition_entity(plan, parts, g, r);
                let b = part.boxes[r][g];
                if binary {
                    w.i32(tag)?;
                    w.i32(dim as i32)?;
                    w.i32(gr.entity)?;
                    w.u64(1)?;
                    w.i32(r as i32 + 1)?;
                    b.iter().try_for_each(|&x| w.f64(x))?;
                    w.u64(1)?;
                    w.i32(gr.physical)?;
                    w.u64(0)?;
                } else {
                    writeln!(
                        w,
                        "{tag} {dim} {} 1 {} {} {} {} {} {} {} 1 {} 0",
                        gr.entity,
                        r + 1,
                        b[0],
                        b[1],
                        b[2],
                        b[3],
                        b[4],
                        b[5],
                        gr.physical
                    )?;
                }
            }
        }
    }
    plan.blocks.end(w, "PartitionedEntities")
}

/// `$Nodes`: one block holding every node of the part, in the part's first volume entity.
fn nodes(plan: &Plan, part: &Part, rank: usize, w: &mut impl Write) -> io::Result<()> {
    let parts = part.counts.len();
    let n = part.node_tags.len();
    writeln!(w, "$Nodes")?;
    let lo = part.node_tags.first().copied().unwrap_or(0);
    let hi = part.node_tags.last().copied().unwrap_or(0);
    plan.blocks.four(w, [(n > 0) as u64, n as u64, lo, hi])?;
    let entity = (0..plan.groups.len())
        .find(|&g| plan.groups[g].dim == plan.d && part.counts[rank][g] > 0)
        .map(|g| partition_entity(plan, parts, g, rank));
    if let (true, Some(e)) = (n > 0, entity) {
        let tags = &part.node_tags;
        plan.blocks
            .node_block(w, e, |i| tags[i], &part.node_coords)?;
    }
    plan.blocks.end(w, "Nodes")
}

/// `$Elements`: one block per group with members in the part, records sorted by tag.
fn elements(
    plan: &Plan,
    part: &Part,
    out: &RankOutput,
    rank: usize,
    w: &mut impl Write,
) -> io::Result<()> {
    let blocks = &plan.blocks;
    let parts = part.counts.len();
    let npe = (out.order + 1).pow(out.dim as u32);
    let ng = plan.groups.len();
    let tags = part
        .volume
        .iter()
        .map(|v| v.1)
        .chain(part.facets.iter().map(|f| f.1));
    let (lo, hi) = tags.fold((u64::MAX, 0), |(lo, hi), t| (lo.min(t), hi.max(t)));
    let n = (part.volume.len() + part.facets.len()) as u64;
    let count = (0..ng).filter(|&g| part.counts[rank][g] > 0).count() as u64;
    writeln!(w, "$Elements")?;
    blocks.four(w, [count, n, if n > 0 { lo } else { 0 }, hi])?;
    for g in (0..ng).filter(|&g| part.counts[rank][g] > 0) {
        let dim = plan.groups[g].dim;
        let e = partition_entity(plan, parts, g, rank);
        blocks.block_header(w, dim, e, blocks.kind(dim), part.counts[rank][g])?;
        for &(_, tag, i) in part.volume.iter().filter(|v| v.0 == g) {
            blocks.record(w, dim, tag, &out.elements[i * npe..(i + 1) * npe], 0)?;
        }
        for (_, tag, nodes) in part.facets.iter().filter(|f| f.0 == g) {
            blocks.record(w, dim, *tag, nodes, 0)?;
        }
    }
    blocks.end(w, "Elements")
}

/// Write this rank's part of a partitioned output of `path` to a temporary beside
/// `OUT_<rank+1>.msh` (see the module docs). Collective. The temporaries are complete and
/// synced on every rank when this returns `Ok`; an error when any rank failed (then no rank
/// keeps a temporary).
pub fn write_partitioned(
    comm: &dyn Comm,
    out: &RankOutput,
    path: &Path,
    inputs: &[&Path],
    options: &WriteOptions,
) -> Result<PendingFile, WriteError> {
    let rank = comm.rank();
    let target = part_path(path, rank + 1);
    let io_err = |source| WriteError::Io {
        path: target.clone(),
        source,
    };
    let result = plan(comm, out, options).map_err(io_err).and_then(|plan| {
        let part = gather_part(comm, &plan, out);
        crate::io::output::prepare(&target, inputs, |w| {
            plan.entities(w)?;
            partitioned_entities(&plan, &part, w)?;
            nodes(&plan, &part, rank, w)?;
            elements(&plan, &part, out, rank, w)
        })
    });
    // Every rank's outcome: the barrier before any part may be renamed. The lowest failing
    // rank prints its own error (the binary's launcher, `cli/launch.rs`).
    super::comm::agree(comm, result, |q| {
        elsewhere(
            &target,
            &format!("rank {q} failed to write its part; no part was written"),
        )
    })
}

/// Rename every rank's part over its target when every rank is ready (`ready`: this rank's
/// other outputs, such as rank 0's report, are complete). Collective: the parts are renamed
/// only when no rank failed; otherwise every temporary is removed and every rank returns an
/// error.
pub fn commit_parts(comm: &dyn Comm, part: PendingFile, ready: bool) -> Result<(), WriteError> {
    let mut failed = [!ready as u64];
    comm.sum_u64(&mut failed);
    if failed[0] > 0 {
        let path = part.path().to_owned();
        drop(part);
        return Err(elsewhere(
            &path,
            "another output failed; no part was written",
        ));
    }
    let path = part.path().to_owned();
    let result = part.commit();
    super::comm::agree(comm, result, |q| {
        elsewhere(&path, &format!("rank {q} failed to rename its part"))
    })
}

/// The partitioned output and rank 0's report, renamed together: [`write_partitioned`], the
/// report prepared on rank 0, then [`commit_parts`]. Collective. Returns the report on rank 0
/// and `None` elsewhere; an error is every rank's, and the lowest failing rank (or rank 0)
/// prints it (the binary's launcher, `cli/launch.rs`).
#[allow(clippy::too_many_arguments)]
pub fn write_all(
    comm: &dyn Comm,
    out: &RankOutput,
    mut report: CurveReport,
    output: &Path,
    report_path: Option<&Path>,
    inputs: &[&Path],
    options: &WriteOptions,
    started: std::time::Instant,
) -> Result<Option<CurveReport>, CurveError> {
    let rank = comm.rank();
    let write_started = std::time::Instant::now();
    let part = write_partitioned(comm, out, output, inputs, options)?;
    let mut pending_report = None;
    let mut report_error = None;
    if rank == 0 {
        report.written(output, write_started, started);
        if let Some(path) = report_path {
            let json = serde_json::to_string_pretty(&report).expect("the report serialises");
            match crate::io::output::prepare(path, inputs, |w| writeln!(w, "{json}")) {
                Ok(p) => pending_report = Some(p),
                Err(e) => report_error = Some(e),
            }
        }
    }
    let committed = commit_parts(comm, part, report_error.is_none());
    if let Some(e) = report_error {
        return Err(e.into());
    }
    committed?;
    if let Some(p) = pending_report {
        p.commit()?;
    }
    Ok((rank == 0).then_some(report))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn part_names_follow_gmsh() {
        assert_eq!(
            part_path(Path::new("dir/out.msh"), 3),
            PathBuf::from("dir/out_3.msh")
        );
        assert_eq!(part_path(Path::new("out"), 1), PathBuf::from("out_1"));
        assert_eq!(
            part_paths(Path::new("a.b.msh"), 2),
            vec![PathBuf::from("a.b_1.msh"), PathBuf::from("a.b_2.msh")]
        );
    }
}
