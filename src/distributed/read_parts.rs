//! Reading Gmsh's partitioned MSH 4.1 files (`IN_1.msh … IN_K.msh`, as Gmsh writes them with
//! `Mesh.PartitionSplitMeshFiles=1`) across the ranks: each rank reads only its parts.
//!
//! Input: the path of one part (`NAME_<k>.msh`, ASCII or binary MSH 4.1 with
//! `$PartitionedEntities`, linear hexes or quads), the communicator, the ghost depth g.
//! Output: the same [`LocalMesh`] as [`super::share::read_share`] makes of a single file: the
//! rank's Morton part of the elements (in increasing global index), then the ghosts within g
//! vertex rings with the rank owning each, the tagged boundary facets among their nodes, and
//! the coordinates of those nodes.
//!
//! Every part repeats the whole mesh's `$Periodic` links (Gmsh writes them so); each rank
//! reads those of its parts and every rank gets all of them (`gather_periodic`), so the
//! periodic pairs are resolved as from the single file.
//!
//! Steps: (1) the part names come from the given part's name and its number of partitions K;
//! every rank checks that all K exist (a missing part is one error on every rank); (2) rank r
//! reads parts ⌊rK/P⌋ … ⌊(r+1)K/P⌋ − 1 whole (K may differ from P), keeping the cells of the
//! partition entities (the cells of Gmsh's ghost entities are dropped: another part owns
//! them), the tagged facets and the nodes; (3) global element ids: a cell's Gmsh tag minus the
//! smallest cell tag, which needs the cell tags to be contiguous (Gmsh keeps the tags of the
//! unpartitioned mesh, which numbers them so); a cell in two parts is one error; (4) the
//! Morton partition of [`super::partition`] on the cells read, each moved to the rank of its
//! part ([`super::share`]); (5) ghost rings, tagged facets and coordinates through directories
//! by node tag (rank t mod P): every rank files its cells under the homes of their nodes, its
//! facets under the home of their smallest node tag, its nodes under their home, then asks
//! the homes of the nodes it has: per ring, the cells around them (not its own), then the
//! facets and the coordinates. With glued periodic seams (the share read a second time, the
//! pairs known) a node stands for its seam representative in the rings' directories, so the
//! rings run on across the seams as a single file's do.
//!
//! Every error is agreed on by all ranks before the next collective step (the first failing
//! rank's message on every rank), so a bad part set never leaves a rank waiting.
//! Invariant: the local mesh is what [`super::share::read_share`] makes of the unpartitioned
//! file when the cells' tags follow the file's order (as Gmsh numbers them).

use super::comm::{Comm, bytes_as_f64, f64_as_bytes};
pub use super::part_file::is_partitioned;
use super::part_file::{part_names, read_part};
use super::partition::{Grid, sort_value, thresholds};
use super::read::{Elements, LocalMesh};
use crate::mesh::raw::{CellKind, DeclaredPeriodic, Location, ParseError, RawBlock, RawMesh};
use crate::mesh::{LinearMesh, MeshOptions};
use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};

fn err(what: impl Into<String>) -> ParseError {
    ParseError::new(Location::File, what)
}

/// Every rank's `r`, or on every rank the error of the lowest failing rank (collective).
fn agree<T>(comm: &dyn Comm, r: Result<T, ParseError>) -> Result<T, ParseError> {
    let msg: Vec<f64> = match &r {
        Ok(_) => Vec::new(),
        Err(e) => bytes_as_f64(e.message.as_bytes()),
    };
    let all = comm.all_gather_f64(&msg);
    match all.iter().position(|m| !m.is_empty()) {
        None => r,
        Some(q) if q == comm.rank() => r,
        Some(q) => Err(err(String::from_utf8_lossy(&f64_as_bytes(&all[q])))),
    }
}

/// What the rank's parts hold, merged: cells, tagged facets and nodes.
struct Read {
    npe: usize,
    cells: Elements,
    /// Gmsh tag and physical tag of each facet, and its node tags.
    facets: Vec<(u64, i32)>,
    facet_nodes: Vec<u64>,
    nodes: HashMap<u64, [f64; 3]>,
    tag_names: BTreeMap<i32, String>,
    /// Every part's `$Periodic` links, the same on every rank ([`gather_periodic`]).
    periodic: Vec<DeclaredPeriodic>,
}

/// Every rank's links of `mine` (its parts' `$Periodic`), in rank order, on every rank: a
/// rank reading no part still needs them, and the pairs must be the same everywhere. A link
/// travels as `[dim, master, slave (NaN: not named), affine flag, 16 entries, precision,
/// source length, source bytes…]` (its place in its part is in the source text).
fn gather_periodic(comm: &dyn Comm, mine: &[DeclaredPeriodic]) -> Vec<DeclaredPeriodic> {
    let mut send = Vec::new();
    for d in mine {
        let [a, b] = d.sides.map_or([f64::NAN; 2], |s| s.map(f64::from));
        send.extend([d.dim as f64, a, b, d.affine.is_some() as u8 as f64]);
        send.extend(d.affine.unwrap_or([0.0; 16]));
        send.push(d.precision);
        send.push(d.source.len() as f64);
        send.extend(bytes_as_f64(d.source.as_bytes()));
    }
    let mut out = Vec::new();
    for v in comm.all_gather_f64(&send) {
        let mut at = 0;
        while at < v.len() {
            let sides = (!v[at + 1].is_nan()).then(|| [v[at + 1] as i32, v[at + 2] as i32]);
            let affine = (v[at + 3] != 0.0).then(|| std::array::from_fn(|i| v[at + 4 + i]));
            let len = v[at + 21] as usize;
            out.push(DeclaredPeriodic {
                dim: v[at] as usize,
                sides,
                source: String::from_utf8_lossy(&f64_as_bytes(&v[at + 22..at + 22 + len]))
                    .into_owned(),
                affine,
                precision: v[at + 20],
                location: Location::File,
            });
            at += 22 + len;
        }
    }
    out
}

/// Read the rank's parts (step 2 of the module docs); `three_d` from every rank's parts.
fn read_mine(comm: &dyn Comm, parts: &[PathBuf]) -> Result<Read, ParseError> {
    let (rank, size) = (comm.rank(), comm.size());
    let k = parts.len();
    let (lo, hi) = (rank * k / size, (rank + 1) * k / size);
    let mut data = Vec::new();
    let read = (lo..hi).try_for_each(|i| {
        // The part's name and the place in it (line or byte) where the parser stopped.
        let mut d = read_part(&parts[i]).map_err(|e| match e.location {
            Location::File => err(format!("{}: {}", parts[i].display(), e.message)),
            _ => err(format!("{}: {e}", parts[i].display())),
        })?;
        // The place in the part goes into the text: the links travel to every rank.
        for link in &mut d.periodic {
            let part = parts[i].display();
            link.source = match std::mem::take(&mut link.location) {
                Location::File => format!("{} in {part}", link.source),
                at => format!("{} at {at} of {part}", link.source),
            };
        }
        if d.partitions != k as u64 {
            return Err(err(format!(
                "{} declares {} partitions, {} declares {k}: the parts are not of one partitioned mesh",
                parts[i].display(),
                d.partitions,
                parts[0].display()
            )));
        }
        data.push(d);
        Ok(())
    });
    agree(comm, read)?;
    let periodic = gather_periodic(
        comm,
        &data
            .iter_mut()
            .flat_map(|d| std::mem::take(&mut d.periodic))
            .collect::<Vec<_>>(),
    );
    let mut hex = [data.iter().any(|d| !d.hexes.items.is_empty()) as u64];
    comm.sum_u64(&mut hex);
    let three_d = hex[0] > 0;
    let npe = if three_d { 8 } else { 4 };
    let mut r = Read {
        npe,
        cells: Elements::default(),
        facets: Vec::new(),
        facet_nodes: Vec::new(),
        nodes: HashMap::new(),
        tag_names: BTreeMap::new(),
        periodic,
    };
    for d in data {
        let (cells, facets) = if three_d {
            (d.hexes, d.quads)
        } else {
            (d.quads, d.lines)
        };
        // Ghost cells are another part's: dropped.
        for (i, &(t, p, ghost)) in cells.items.iter().enumerate() {
            if !ghost {
                r.cells.global.push(t);
                r.cells.tags.push(p);
                r.cells
                    .nodes
                    .extend_from_slice(&cells.nodes[i * npe..(i + 1) * npe]);
            }
        }
        for (i, &(t, p, _)) in facets.items.iter().enumerate() {
            if p != 0 {
                r.facets.push((t, p));
                r.facet_nodes
                    .extend_from_slice(&facets.nodes[i * npe / 2..(i + 1) * npe / 2]);
            }
        }
        r.nodes.extend(d.node_tags.into_iter().zip(d.node_coords));
    }
    Ok(r)
}

/// Global element ids: the cells' Gmsh tags less the smallest, checked contiguous (step 3);
/// returns the number of cells in the mesh.
fn global_ids(comm: &dyn Comm, cells: &mut Elements) -> Result<u64, ParseError> {
    let mut lo = [cells.global.iter().copied().min().unwrap_or(u64::MAX) as f64];
    let mut hi = [cells.global.iter().copied().max().unwrap_or(0) as f64];
    let mut n = [cells.global.len() as u64];
    comm.min_f64(&mut lo);
    comm.max_f64(&mut hi);
    comm.sum_u64(&mut n);
    let (lo, hi, n) = (lo[0] as u64, hi[0] as u64, n[0]);
    if n == 0 {
        return Err(err("no hexahedra or quadrilaterals in the parts"));
    }
    if hi - lo + 1 != n {
        return Err(err(format!(
            "the parts' {n} cells have tags {lo} … {hi}: partitioned input needs the cells numbered contiguously, each in one part (as Gmsh numbers an unpartitioned mesh)"
        )));
    }
    for g in &mut cells.global {
        *g -= lo;
    }
    Ok(n)
}

/// The Morton part of every cell read (step 4), from the coordinates of its nodes.
fn morton_parts(comm: &dyn Comm, r: &Read, n_global: u64) -> Result<Vec<u32>, ParseError> {
    let corners = |i: usize| -> Option<Vec<[f64; 3]>> {
        r.cells.nodes[i * r.npe..(i + 1) * r.npe]
            .iter()
            .map(|t| r.nodes.get(t).copied())
            .collect()
    };
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    let mut missing = false;
    for i in 0..r.cells.global.len() {
        match corners(i) {
            Some(c) => {
                for p in c {
                    for k in 0..3 {
                        lo[k] = lo[k].min(p[k]);
                        hi[k] = hi[k].max(p[k]);
                    }
                }
            }
            None => missing = true,
        }
    }
    agree(
        comm,
        if missing {
            Err(err("a cell uses a node its part does not define"))
        } else {
            Ok(())
        },
    )?;
    comm.min_f64(&mut lo);
    comm.max_f64(&mut hi);
    let grid = Grid::new(lo, hi);
    let values: Vec<u128> = (0..r.cells.global.len())
        .map(|i| sort_value(grid.key(&corners(i).unwrap()), r.cells.global[i]))
        .collect();
    let mut sorted = values.clone();
    sorted.sort_unstable();
    let cut = thresholds(n_global, comm.size(), |mid| {
        let mut c: Vec<u64> = mid
            .iter()
            .map(|&m| sorted.partition_point(|&x| x <= m) as u64)
            .collect();
        comm.sum_u64(&mut c);
        c
    });
    Ok(values
        .iter()
        .map(|v| cut.partition_point(|&t| t <= *v) as u32)
        .collect())
}

fn home(t: u64, size: usize) -> usize {
    (t % size as u64) as usize
}

/// The cells within `depth` vertex rings of `own` and not in it, with their owners (step 5):
/// every rank files its cells under the homes of their nodes, then per ring asks the homes of
/// its newest nodes for the cells around them. With `seams` (node tag → its representative,
/// for the image nodes of glued periodic seams) a node stands for its representative: cells
/// are filed and asked for under the representatives, so the rings run on across the seams as
/// [`super::read::MshFile::ghosts`]' do, whatever ranks hold the two sides. Collective (the
/// same number of exchanges on every rank). Ids and tags travel as f64 (exact below 2⁵³).
fn ghost_rings(
    comm: &dyn Comm,
    own: &Elements,
    npe: usize,
    depth: usize,
    seams: Option<&HashMap<u64, u64>>,
) -> (Elements, Vec<u32>) {
    let glued = |t: u64| seams.and_then(|m| m.get(&t)).copied().unwrap_or(t);
    let (rank, size) = (comm.rank(), comm.size());
    let rec = 3 + npe;
    let mut send = vec![Vec::new(); size];
    let mut homes = Vec::with_capacity(npe);
    for i in 0..own.global.len() {
        let nodes = &own.nodes[i * npe..(i + 1) * npe];
        homes.clear();
        homes.extend(nodes.iter().map(|&t| home(glued(t), size)));
        homes.sort_unstable();
        homes.dedup();
        for &q in &homes {
            let s = &mut send[q];
            s.push(own.global[i] as f64);
            s.push(own.tags[i] as f64);
            s.push(rank as f64);
            s.extend(nodes.iter().map(|&t| t as f64));
        }
    }
    let filed: Vec<f64> = comm.exchange_f64(&send).concat();
    drop(send);
    // The cells around each node filed here.
    let mut around: HashMap<u64, Vec<u32>> = HashMap::new();
    for (k, c) in filed.chunks_exact(rec).enumerate() {
        for &t in &c[3..] {
            let g = glued(t as u64);
            if home(g, size) == rank {
                let cells = around.entry(g).or_default();
                // A cell holding both sides of a seam node is filed once under it.
                if cells.last() != Some(&(k as u32)) {
                    cells.push(k as u32);
                }
            }
        }
    }
    // Representatives of the nodes reached.
    let mut have: HashSet<u64> = own.nodes.iter().map(|&t| glued(t)).collect();
    let mut seen: HashSet<u64> = own.global.iter().copied().collect();
    let mut frontier: Vec<u64> = have.iter().copied().collect();
    let (mut ghosts, mut owner) = (Elements::default(), Vec::new());
    for _ in 0..depth {
        let mut ask = vec![Vec::new(); size];
        for &t in &frontier {
            ask[home(t, size)].push(t as f64);
        }
        let asked = comm.exchange_f64(&ask);
        let replies: Vec<Vec<f64>> = asked
            .iter()
            .enumerate()
            .map(|(q, nodes)| {
                let mut ks: Vec<u32> = nodes
                    .iter()
                    .flat_map(|&t| around.get(&(t as u64)).into_iter().flatten().copied())
                    .filter(|&k| filed[k as usize * rec + 2] as usize != q)
                    .collect();
                ks.sort_unstable();
                ks.dedup();
                ks.iter()
                    .flat_map(|&k| &filed[k as usize * rec..(k as usize + 1) * rec])
                    .copied()
                    .collect()
            })
            .collect();
        drop(asked);
        let got = comm.exchange_f64(&replies);
        drop(replies);
        frontier.clear();
        for c in got.iter().flat_map(|g| g.chunks_exact(rec)) {
            let g = c[0] as u64;
            if seen.insert(g) {
                ghosts.global.push(g);
                ghosts.tags.push(c[1] as i32);
                owner.push(c[2] as u32);
                for &t in &c[3..] {
                    let t = t as u64;
                    ghosts.nodes.push(t);
                    if have.insert(glued(t)) {
                        frontier.push(glued(t));
                    }
                }
            }
        }
    }
    (ghosts, owner)
}

/// Ask the homes of `nodes` for what they filed under them: `filed[q]` is what rank q sent
/// to this rank's directory, `lookup` the records filed under a node (collective).
fn ask_homes(comm: &dyn Comm, nodes: &[u64], lookup: impl Fn(u64) -> Vec<f64>) -> Vec<Vec<f64>> {
    let size = comm.size();
    let mut ask = vec![Vec::new(); size];
    for &t in nodes {
        ask[home(t, size)].push(t as f64);
    }
    let asked = comm.exchange_f64(&ask);
    drop(ask);
    let replies: Vec<Vec<f64>> = asked
        .iter()
        .map(|list| list.iter().flat_map(|&t| lookup(t as u64)).collect())
        .collect();
    comm.exchange_f64(&replies)
}

/// The tagged facets whose nodes are all in `have`, sorted by Gmsh tag, and the coordinates
/// of the nodes of `have` (sorted by tag), through the directories (step 5).
#[allow(clippy::type_complexity)]
fn facets_and_coordinates(
    comm: &dyn Comm,
    r: &Read,
    have: &HashSet<u64>,
) -> Result<(Vec<i32>, Vec<u64>, Vec<u64>, Vec<[f64; 3]>), ParseError> {
    let size = comm.size();
    let npf = r.npe / 2;
    // Facets filed under their smallest node, once per Gmsh tag.
    let mut send = vec![Vec::new(); size];
    for (i, &(t, p)) in r.facets.iter().enumerate() {
        let nodes = &r.facet_nodes[i * npf..(i + 1) * npf];
        let s = &mut send[home(*nodes.iter().min().unwrap(), size)];
        s.push(t as f64);
        s.push(p as f64);
        s.extend(nodes.iter().map(|&x| x as f64));
    }
    let filed = comm.exchange_f64(&send).concat();
    let mut by_tag: BTreeMap<u64, &[f64]> = BTreeMap::new();
    for c in filed.chunks_exact(2 + npf) {
        by_tag.entry(c[0] as u64).or_insert(c);
    }
    let mut under: HashMap<u64, Vec<&[f64]>> = HashMap::new();
    for c in by_tag.values() {
        let m = c[2..].iter().map(|&x| x as u64).min().unwrap();
        under.entry(m).or_default().push(c);
    }
    let mut nodes: Vec<u64> = have.iter().copied().collect();
    nodes.sort_unstable();
    let got = ask_homes(comm, &nodes, |t| {
        under
            .get(&t)
            .into_iter()
            .flatten()
            .flat_map(|c| c.iter().copied())
            .collect()
    });
    let mut list: Vec<&[f64]> = got
        .iter()
        .flat_map(|g| g.chunks_exact(2 + npf))
        .filter(|c| c[2..].iter().all(|&x| have.contains(&(x as u64))))
        .collect();
    list.sort_unstable_by_key(|c| c[0] as u64);
    let facet_tags = list.iter().map(|c| c[1] as i32).collect();
    let facet_nodes = list
        .iter()
        .flat_map(|c| c[2..].iter().map(|&x| x as u64))
        .collect();
    // Coordinates filed under their node, answered in the order asked.
    let mut send = vec![Vec::new(); size];
    for (&t, x) in &r.nodes {
        let s = &mut send[home(t, size)];
        s.push(t as f64);
        s.extend_from_slice(x);
    }
    let filed = comm.exchange_f64(&send).concat();
    let directory: HashMap<u64, [f64; 3]> = filed
        .chunks_exact(4)
        .map(|c| (c[0] as u64, [c[1], c[2], c[3]]))
        .collect();
    drop(filed);
    let got = ask_homes(comm, &nodes, |t| {
        directory.get(&t).map_or(vec![f64::NAN; 3], |x| x.to_vec())
    });
    let mut next = vec![0usize; size];
    let mut points = Vec::with_capacity(nodes.len());
    let mut missing = 0usize;
    for &t in &nodes {
        let q = home(t, size);
        let x = &got[q][3 * next[q]..3 * next[q] + 3];
        next[q] += 1;
        missing += x[0].is_nan() as usize;
        points.push([x[0], x[1], x[2]]);
    }
    let ok = if missing > 0 {
        Err(err(format!(
            "{missing} node(s) used by the cells are defined in no part"
        )))
    } else {
        Ok(())
    };
    agree(comm, ok)?;
    Ok((facet_tags, facet_nodes, nodes, points))
}

/// Read this rank's share of the partitioned mesh `path` is a part of, with `depth` vertex
/// rings of ghosts (see the module docs); with `seams` (node tag → representative tag of glued
/// periodic seams) the rings run on across the seams (step 5 of the module docs). Collective.
pub fn read_parts_share(
    comm: &dyn Comm,
    path: &Path,
    depth: usize,
    options: &MeshOptions,
    seams: Option<&HashMap<u64, u64>>,
) -> Result<LocalMesh, ParseError> {
    let (parts, tag_names) = agree(comm, part_names(path))?;
    let mut r = read_mine(comm, &parts)?;
    r.tag_names = tag_names;
    let n_global = agree(comm, global_ids(comm, &mut r.cells))?;
    let part = morton_parts(comm, &r, n_global)?;
    let own = super::share::route(comm, &r.cells, &part, r.npe);
    r.cells = Elements::default();
    let twice = own.global.windows(2).find(|w| w[0] == w[1]);
    agree(
        comm,
        twice.map_or(Ok(()), |w| {
            Err(err(format!(
                "the cell with tag offset {} is in two parts: the parts are not one partition",
                w[0]
            )))
        }),
    )?;
    let (ghosts, owner) = ghost_rings(comm, &own, r.npe, depth, seams);
    let n_owned = own.global.len();
    let (mut global_element, mut tags, mut nodes) = (own.global, own.tags, own.nodes);
    global_element.extend_from_slice(&ghosts.global);
    tags.extend_from_slice(&ghosts.tags);
    nodes.extend_from_slice(&ghosts.nodes);
    drop(ghosts);
    let mut owners = vec![comm.rank() as u32; n_owned];
    owners.extend_from_slice(&owner);
    let have: HashSet<u64> = nodes.iter().copied().collect();
    let (facet_tags, facet_nodes, global_vertex, points) = facets_and_coordinates(comm, &r, &have)?;
    drop(have);
    let local: HashMap<u64, i64> = global_vertex
        .iter()
        .enumerate()
        .map(|(i, &t)| (t, i as i64))
        .collect();
    let (cell, facet) = if r.npe == 8 {
        (CellKind::Hexahedron, CellKind::Quad)
    } else {
        (CellKind::Quad, CellKind::Line)
    };
    let mut block = RawBlock::new(cell, r.npe);
    block.nodes = nodes.iter().map(|t| local[t]).collect();
    block.tags = tags;
    let mut fblock = RawBlock::new(facet, r.npe / 2);
    fblock.nodes = facet_nodes.iter().map(|t| local[t]).collect();
    fblock.tags = facet_tags;
    let raw = RawMesh {
        points,
        point_locations: Vec::new(),
        declared_dim: Some(3),
        blocks: vec![block, fblock],
        periodic: r.periodic,
        tag_names: r.tag_names,
    };
    let mesh = agree(comm, LinearMesh::from_raw(raw, options))?;
    Ok(LocalMesh {
        mesh,
        n_owned,
        global_element,
        owner: owners,
        global_vertex,
        n_global,
        glued: None,
    })
}
