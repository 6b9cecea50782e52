//! Rank-local sampling with a globally consistent node numbering: each rank samples its own
//! elements; no rank holds the whole output mesh.
//!
//! Input: the rank's [`LocalMesh`] (own elements, then ghosts), its topology, the element maps
//! of the local elements ([`BezierElements`], the certified blend's nets) and the order p.
//! Output: a [`RankOutput`]: the nodes this rank owns (written once over all ranks) with their
//! global tags, its elements' and boundary facets' node tags, and its figures for the report.
//!
//! **Ownership.** A node belongs to one mesh entity (vertex, edge, face or element interior).
//! Its owner element is the lowest global element index among the elements containing the
//! entity; every element containing an entity of an own element is in the sub-mesh (the
//! ghost layer holds the own elements' vertex one-ring at least), so every rank that has the
//! node computes the same owner element without communication, and the rank holding it
//! ([`LocalMesh::owner`], the partition's part of every local element) evaluates the node.
//!
//! **Global tags.** A vertex node keeps the input's node tag; the other nodes a rank owns are
//! numbered after the largest input tag, in the rank's order of (own element, lattice point),
//! offset by the exclusive scan of the ranks' counts. A rank asks the owner of each node it
//! uses but does not own for its tag and position by the key (owner element's global index,
//! lattice point in it); the owner answers with the value it evaluated, so shared nodes have
//! bit-identical coordinates on every rank. Invariant: the positions are those of the serial
//! [`crate::sample::sample`] (the same owner element and lattice point evaluate each node).
//!
//! **Periodic seams.** With periodic pairs, the seam nodes of the own elements are moved
//! before any check or box ([`super::periodic::make_images`], collective): every rank takes
//! them from one gathered copy, so shared seam nodes stay bit-identical across ranks.

use super::comm::Comm;
use super::read::LocalMesh;
use crate::math::BezierElements;
use crate::mesh::HighOrderMesh;
use crate::mesh::Topology;
use crate::mesh::features::Features;
use crate::mesh::high_order::{Lattice, lattice_point};
use crate::sample::{Numbering, eval_net};

/// One rank's share of the output mesh, in global node tags.
pub struct RankOutput {
    pub dim: usize,
    pub order: usize,
    /// Nodes this rank owns (written by it alone): tags and positions.
    pub node_tags: Vec<u64>,
    pub node_coords: Vec<[f64; 3]>,
    /// (p+1)^d node tags per own element, lattice order; region tag per element (or empty).
    pub elements: Vec<u64>,
    pub element_tags: Vec<i32>,
    /// (p+1)^(d−1) node tags per own boundary facet in its outward lattice frame, its tag
    /// (0 = untagged), and its sort key (the sorted input node tags of its vertices, which
    /// gives the serial order of boundary facets).
    pub boundary: Vec<u64>,
    pub boundary_tags: Vec<i32>,
    pub boundary_keys: Vec<[u64; 4]>,
    /// Global index of the own element each boundary facet bounds (a partitioned write
    /// puts the facet in that element's part).
    pub boundary_elements: Vec<u64>,
    /// Bounding box `[min x, y, z, max x, y, z]` of each own element's and boundary facet's
    /// nodes (for the entities' boxes of the MSH file).
    pub element_boxes: Vec<[f64; 6]>,
    pub boundary_boxes: Vec<[f64; 6]>,
    /// Smallest sampled scaled Jacobian of the own elements, and the global indices of
    /// those with a sampled det J ≤ 0.
    pub min_scaled_jacobian: f64,
    pub invalid_elements: Vec<u64>,
    /// Largest and summed squared distance of the owned boundary vertex nodes from their
    /// input vertices, and their count.
    pub vertex_deviation: (f64, f64, usize),
    /// Largest distance of the own boundary facets' nodes and sampled points from the input's
    /// linear boundary (absolute; [`crate::deviation::facet_distances`]).
    pub boundary_distance: (f64, f64),
    /// Largest distance of an owned feature vertex node from its input vertex, and of an own
    /// boundary facet's node from its planar patch's plane (absolute; 0 without features).
    pub feature_deviation: (f64, f64),
    /// The periodic pairs' node pairs in global tags (the same on every rank; empty without
    /// pairs) and what making the image sides exact images did ([`super::periodic`]).
    pub periodic: Vec<super::periodic::TagLink>,
    pub images: Option<crate::mesh::periodic::ImageInfo>,
}

/// Owner element of every local node id: its global index, its local index and the node's
/// lattice point in it.
fn owners(local: &LocalMesh, num: &Numbering, p: usize) -> (Vec<u64>, Vec<u32>, Vec<u16>) {
    let d = local.mesh.dim;
    let npe = (p + 1).pow(d as u32);
    let mut elem = vec![u64::MAX; num.n_nodes()];
    let mut at = vec![0u32; num.n_nodes()];
    let mut lat = vec![0u16; num.n_nodes()];
    for e in 0..local.mesh.n_elements() {
        let g = local.global_element[e];
        for n in 0..npe {
            let id = num.node_id(e, lattice_point(p, d, n)) as usize;
            if g < elem[id] {
                elem[id] = g;
                at[id] = e as u32;
                lat[id] = n as u16;
            }
        }
    }
    (elem, at, lat)
}

pub(super) fn lattice_param(p: usize, l: Lattice) -> [f64; 3] {
    let pf = p as f64;
    [l[0] as f64 / pf, l[1] as f64 / pf, l[2] as f64 / pf]
}

/// Sample this rank's elements (see the module docs), with `seams` the periodic pairs whose
/// image sides are made the transform of their masters ([`super::periodic::make_images`]).
/// Collective; an error (a seam) is the same on every rank.
pub fn sample_share(
    comm: &dyn Comm,
    local: &LocalMesh,
    topo: &Topology,
    source: &dyn BezierElements,
    p: usize,
    features: Option<&Features>,
    seams: Option<&super::periodic::Seams>,
) -> Result<RankOutput, crate::pipeline::CurveError> {
    let (rank, size) = (comm.rank(), comm.size());
    let mesh = &local.mesh;
    let d = mesh.dim;
    let npe = (p + 1).pow(d as u32);
    let num = Numbering::new(mesh, topo, p);
    let (owner_elem, owner_at, owner_lat) = owners(local, &num, p);
    // Own elements by global index, to answer the other ranks' keys.
    let mut own_index: Vec<(u64, u32)> = (0..local.n_owned)
        .map(|e| (local.global_element[e], e as u32))
        .collect();
    own_index.sort_unstable();
    let nv = mesh.n_vertices();

    // Local ids the own elements use, owned ones evaluated here.
    const UNSET: u64 = u64::MAX;
    let mut tag = vec![UNSET; num.n_nodes()];
    let mut xyz = vec![[0.0f64; 3]; num.n_nodes()];
    let mut ids = vec![0u32; local.n_owned * npe];
    let mut owned: Vec<u32> = Vec::new();
    let mut requests: Vec<Vec<u32>> = vec![Vec::new(); size];
    let mut seen = vec![false; num.n_nodes()];
    for e in 0..local.n_owned {
        for n in 0..npe {
            let id = num.node_id(e, lattice_point(p, d, n));
            ids[e * npe + n] = id;
            let i = id as usize;
            if std::mem::replace(&mut seen[i], true) {
                continue;
            }
            let q = local.owner[owner_at[i] as usize] as usize;
            if q == rank {
                owned.push(id);
            } else {
                requests[q].push(id);
            }
        }
    }
    drop(seen);
    // Evaluate the owned nodes, one net per owner element.
    owned.sort_unstable_by_key(|&id| (owner_elem[id as usize], owner_lat[id as usize]));
    let mut net_of = (usize::MAX, [[0.0; 3]; 27]);
    for &id in &owned {
        let i = id as usize;
        let e = owner_at[i] as usize;
        if net_of.0 != e {
            net_of = (e, source.bezier_net(e));
        }
        let l = lattice_point(p, d, owner_lat[i] as usize);
        xyz[i] = eval_net(d, &net_of.1, lattice_param(p, l));
    }
    // Global tags: vertices keep theirs; the rest after the largest input tag.
    let mut max_tag = [local.global_vertex.iter().copied().max().unwrap_or(0) as f64];
    comm.max_f64(&mut max_tag);
    let n_new = owned.iter().filter(|&&id| (id as usize) >= nv).count();
    let counts = comm.all_gather_f64(&[n_new as f64]);
    let offset: u64 = counts[..rank].iter().map(|c| c[0] as u64).sum();
    let mut next = max_tag[0] as u64 + 1 + offset;
    for &id in &owned {
        let i = id as usize;
        tag[i] = if i < nv {
            local.global_vertex[i]
        } else {
            next += 1;
            next - 1
        };
    }
    answer_requests(comm, &requests, &owner_elem, &owner_lat, |g, n| {
        // A key names an owner element of this rank (the asker computed the same owner).
        let k = own_index.partition_point(|&(x, _)| x < g);
        let e = own_index[k].1 as usize;
        let id = num.node_id(e, lattice_point(p, d, n)) as usize;
        (tag[id], xyz[id])
    })
    .into_iter()
    .for_each(|(id, t, x)| {
        tag[id as usize] = t;
        xyz[id as usize] = x;
    });

    let (boundary, boundary_tags, boundary_keys, boundary_ids) =
        own_boundary(local, topo, &num, &tag);
    let (periodic, images) = match seams.filter(|s| !s.pairs.is_empty()) {
        Some(seams) => {
            let share = super::periodic::SampledShare {
                local,
                p,
                ids: &ids,
                facet_ids: &boundary_ids,
                facet_tags: &boundary_tags,
                tag: &tag,
            };
            let (links, info) = super::periodic::make_images(comm, seams, &share, &mut xyz)?;
            (links, Some(info))
        }
        None => (Vec::new(), None),
    };
    let quality = local_quality(d, p, &xyz, &ids);
    let vertex_deviation = vertex_deviation(local, topo, &owned, &xyz);
    let (xyz, boundary_distance) = boundary_distance(local, topo, p, xyz, &boundary_ids);
    let feature_deviation = features.map_or((0.0, 0.0), |f| {
        let rows = seams.and_then(|s| s.boundary_rows);
        feature_deviation(local, topo, f, rows, &owned, &xyz, &boundary_ids)
    });
    let boundary_elements = topo
        .boundary_facets
        .iter()
        .map(|&f| topo.facet_elements[f as usize][0] as usize)
        .filter(|&e| e < local.n_owned)
        .map(|e| local.global_element[e])
        .collect();
    let boxes = |ids: &[u32], n: usize| -> Vec<[f64; 6]> {
        ids.chunks_exact(n)
            .map(|c| {
                let mut b = [
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                ];
                for &id in c {
                    let x = xyz[id as usize];
                    for k in 0..3 {
                        b[k] = b[k].min(x[k]);
                        b[3 + k] = b[3 + k].max(x[k]);
                    }
                }
                b
            })
            .collect()
    };
    let element_boxes = boxes(&ids, npe);
    let boundary_boxes = boxes(&boundary_ids, (p + 1).pow(d as u32 - 1));
    Ok(RankOutput {
        dim: d,
        order: p,
        node_tags: owned.iter().map(|&id| tag[id as usize]).collect(),
        node_coords: owned.iter().map(|&id| xyz[id as usize]).collect(),
        elements: ids.iter().map(|&id| tag[id as usize]).collect(),
        element_tags: mesh
            .element_tags
            .get(..local.n_owned)
            .map_or_else(Vec::new, <[i32]>::to_vec),
        boundary,
        boundary_tags,
        boundary_keys,
        boundary_elements,
        element_boxes,
        boundary_boxes,
        min_scaled_jacobian: quality.0,
        invalid_elements: quality.1.iter().map(|&e| local.global_element[e]).collect(),
        vertex_deviation,
        boundary_distance,
        feature_deviation,
        periodic,
        images,
    })
}

/// [`Features::deviations`] of this rank's share, absolute: the largest distance of an owned
/// feature vertex node from its input vertex, and of an own boundary facet's node (local ids
/// `ids`, in the order of `topo.boundary_facets`) from its patch's plane.
fn feature_deviation(
    local: &LocalMesh,
    topo: &Topology,
    f: &Features,
    rows: Option<&[u32]>,
    owned: &[u32],
    xyz: &[[f64; 3]],
    ids: &[u32],
) -> (f64, f64) {
    let mesh = &local.mesh;
    let nv = mesh.n_vertices();
    let dist = |a: [f64; 3], b: [f64; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
    let vertex = owned
        .iter()
        .map(|&id| id as usize)
        .filter(|&v| v < nv && f.vertex_mask[v])
        .map(|v| dist(xyz[v], mesh.coords[v]))
        .fold(0.0, f64::max);
    let own: Vec<usize> = topo
        .boundary_facets
        .iter()
        .enumerate()
        .filter(|&(_, &fc)| (topo.facet_elements[fc as usize][0] as usize) < local.n_owned)
        .map(|(i, _)| i)
        .collect();
    let npf = if own.is_empty() {
        1
    } else {
        ids.len() / own.len()
    };
    // With glued seams the features' facets are the input's but the seam facets (`rows`).
    let row_of: Option<std::collections::HashMap<u32, usize>> =
        rows.map(|r| r.iter().enumerate().map(|(k, &i)| (i, k)).collect());
    let mut planarity = 0.0f64;
    for (k, &i) in own.iter().enumerate() {
        let i = match &row_of {
            Some(m) => match m.get(&(i as u32)) {
                Some(&r) => r,
                None => continue,
            },
            None => i,
        };
        if let Some(Some((n, d))) = f.planes.get(f.facet_patch[i] as usize) {
            for &id in &ids[k * npf..(k + 1) * npf] {
                let x = xyz[id as usize];
                let s: f64 = (0..3).map(|c| n[c] * x[c]).sum();
                planarity = planarity.max((s - d).abs());
            }
        }
    }
    (vertex, planarity)
}

/// [`crate::deviation::facet_distances`] of the own boundary facets (local node ids `ids`,
/// positions `xyz`, handed back) against the sub-mesh's facets that are boundary facets of
/// the whole mesh near them: those of the elements touching an own element's vertex, whose
/// every neighbour is in the sub-mesh (2 vertex rings), so none of them is a cut face of the
/// ghost fringe. A curved node lies within a fraction of its element's size of its own
/// facet, so its nearest linear facet is among these.
fn boundary_distance(
    local: &LocalMesh,
    topo: &Topology,
    p: usize,
    xyz: Vec<[f64; 3]>,
    ids: &[u32],
) -> (Vec<[f64; 3]>, (f64, f64)) {
    let mesh = &local.mesh;
    let mut near = vec![false; mesh.n_vertices()];
    for e in 0..local.n_owned {
        for &v in mesh.element(e) {
            near[v as usize] = true;
        }
    }
    let mut facets = Vec::new();
    let mut over = Vec::new();
    for &f in &topo.boundary_facets {
        let e = topo.facet_elements[f as usize][0] as usize;
        if mesh.element(e).iter().any(|&v| near[v as usize]) {
            if e < local.n_owned {
                over.push(facets.len());
            }
            facets.push(f);
        }
    }
    let ho = HighOrderMesh {
        dim: mesh.dim,
        order: p,
        nodes: xyz,
        boundary: ids.to_vec(),
        ..Default::default()
    };
    let d = crate::deviation::facet_distances(mesh, topo, &facets, &ho, &over);
    (ho.nodes, d)
}

/// The sampled check over all ranks (an error on every rank when an element is invalid): the
/// smallest sampled scaled Jacobian, and the boundary distances relative to the input's
/// bounding-box diagonal (the serial quality stage's figures).
pub(super) fn global_quality(
    comm: &dyn Comm,
    input: &std::path::Path,
    local: &LocalMesh,
    out: &RankOutput,
) -> Result<(f64, crate::deviation::BoundaryDeviation), crate::pipeline::CurveError> {
    let invalid = comm.all_gather_f64(
        &out.invalid_elements
            .iter()
            .map(|&e| e as f64)
            .collect::<Vec<_>>(),
    );
    let invalid: Vec<usize> = invalid.concat().iter().map(|&e| e as usize).collect();
    if !invalid.is_empty() {
        return Err(crate::pipeline::CurveError::Invalid {
            input: input.to_owned(),
            what: "sampled output".into(),
            count: invalid.len(),
            first: invalid
                .iter()
                .take(8)
                .map(|e| e.to_string())
                .collect::<Vec<_>>()
                .join(", "),
        });
    }
    let mesh = &local.mesh;
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for e in 0..local.n_owned {
        for &v in mesh.element(e) {
            let x = mesh.coords[v as usize];
            for k in 0..3 {
                lo[k] = lo[k].min(x[k]);
                hi[k] = hi[k].max(x[k]);
            }
        }
    }
    let (vmax, vsum, vn) = out.vertex_deviation;
    let mut mins = [lo[0], lo[1], lo[2], out.min_scaled_jacobian];
    let (node, sample) = out.boundary_distance;
    let mut maxs = [hi[0], hi[1], hi[2], vmax, node, sample];
    let mut sums = [vsum, vn as f64];
    comm.min_f64(&mut mins);
    comm.max_f64(&mut maxs);
    comm.sum_f64(&mut sums);
    let diagonal = (0..3)
        .map(|k| (maxs[k] - mins[k]).powi(2))
        .sum::<f64>()
        .sqrt()
        .max(f64::MIN_POSITIVE);
    let deviation = crate::deviation::BoundaryDeviation {
        diagonal,
        vertex_max: maxs[3] / diagonal,
        node_max: maxs[4] / diagonal,
        sample_max: maxs[5] / diagonal,
        vertex_rms: if sums[1] > 0.0 {
            (sums[0] / sums[1]).sqrt() / diagonal
        } else {
            0.0
        },
    };
    Ok((mins[3], deviation))
}

/// Move the sampled elements to the rank whose run of the file holds them
/// ([`LocalMesh::starts`]), in increasing global index, so that the collective write lays
/// the elements out in the file's order and with the serial run's element tags whatever the
/// partition. Only the elements' node tags, region tags and boxes move; nodes stay with their
/// owners. Collective; indices and tags travel as f64 (exact below 2⁵³).
pub fn to_file_order(comm: &dyn Comm, local: &LocalMesh, out: &mut RankOutput) {
    let size = comm.size();
    let npe = (out.order + 1).pow(out.dim as u32);
    let starts = LocalMesh::starts(local.n_global, size);
    let tagged = !out.element_tags.is_empty();
    let mut send = vec![Vec::new(); size];
    for e in 0..local.n_owned {
        let g = local.global_element[e];
        let s = &mut send[LocalMesh::run_of(&starts, g)];
        s.push(g as f64);
        s.push(out.element_tags.get(e).map_or(0.0, |&t| t as f64));
        s.extend_from_slice(&out.element_boxes[e]);
        s.extend(
            out.elements[e * npe..(e + 1) * npe]
                .iter()
                .map(|&t| t as f64),
        );
    }
    out.elements = Vec::new();
    out.element_boxes = Vec::new();
    out.element_tags = Vec::new();
    let recv = comm.exchange_f64(&send);
    drop(send);
    let mut records: Vec<&[f64]> = recv.iter().flat_map(|r| r.chunks_exact(npe + 8)).collect();
    records.sort_unstable_by_key(|r| r[0] as u64);
    for r in records {
        if tagged {
            out.element_tags.push(r[1] as i32);
        }
        out.element_boxes.push(std::array::from_fn(|k| r[2 + k]));
        out.elements.extend(r[8..].iter().map(|&t| t as u64));
    }
}

/// Send the keys (owner element, lattice point) of the nodes in `requests[q]` to rank q,
/// answer the keys the other ranks sent with `lookup(owner element, lattice point)` = (tag,
/// position), and return the answers to this rank's requests as (local id, tag, position).
fn answer_requests(
    comm: &dyn Comm,
    requests: &[Vec<u32>],
    owner_elem: &[u64],
    owner_lat: &[u16],
    lookup: impl Fn(u64, usize) -> (u64, [f64; 3]),
) -> Vec<(u32, u64, [f64; 3])> {
    // Element indices and tags travel as f64 (exact below 2^53).
    let send: Vec<Vec<f64>> = requests
        .iter()
        .map(|ids| {
            ids.iter()
                .flat_map(|&id| {
                    let i = id as usize;
                    [owner_elem[i] as f64, owner_lat[i] as f64]
                })
                .collect()
        })
        .collect();
    let asked = comm.exchange_f64(&send);
    drop(send);
    let replies: Vec<Vec<f64>> = asked
        .iter()
        .map(|keys| {
            keys.chunks_exact(2)
                .flat_map(|k| {
                    let (t, x) = lookup(k[0] as u64, k[1] as usize);
                    [t as f64, x[0], x[1], x[2]]
                })
                .collect()
        })
        .collect();
    drop(asked);
    let answers = comm.exchange_f64(&replies);
    let mut out = Vec::new();
    for (ids, a) in requests.iter().zip(&answers) {
        for (&id, r) in ids.iter().zip(a.chunks_exact(4)) {
            out.push((id, r[0] as u64, [r[1], r[2], r[3]]));
        }
    }
    out
}

/// Smallest sampled scaled Jacobian of the own elements and how many are invalid (sampled
/// det J ≤ 0, local indices), from a high-order mesh of the own elements in local node ids.
fn local_quality(d: usize, p: usize, xyz: &[[f64; 3]], ids: &[u32]) -> (f64, Vec<usize>) {
    let ho = HighOrderMesh {
        dim: d,
        order: p,
        nodes: xyz.to_vec(),
        elements: ids.to_vec(),
        ..Default::default()
    };
    let q = crate::quality::sample_det_jacobian(&ho);
    let min = q
        .iter()
        .map(|q| q.min_scaled_jacobian)
        .fold(f64::INFINITY, f64::min);
    let invalid = (0..q.len())
        .filter(|&e| !(q[e].min_det_jacobian > 0.0))
        .collect();
    (min, invalid)
}

/// Largest and summed squared distance of the owned boundary vertex nodes from their input
/// vertices, and their count.
fn vertex_deviation(
    local: &LocalMesh,
    topo: &Topology,
    owned: &[u32],
    xyz: &[[f64; 3]],
) -> (f64, f64, usize) {
    let nv = local.mesh.n_vertices();
    let mut out = (0.0f64, 0.0, 0);
    for &id in owned {
        let v = id as usize;
        if v < nv && topo.vertex_on_boundary[v] {
            let a = local.mesh.coords[v];
            let b = xyz[v];
            let s: f64 = (0..3).map(|k| (a[k] - b[k]).powi(2)).sum();
            out.0 = out.0.max(s.sqrt());
            out.1 += s;
            out.2 += 1;
        }
    }
    out
}

/// The own elements' boundary facets (a facet of an own element with one element around it
/// in the sub-mesh is on the boundary, since the sub-mesh holds every neighbour of an own
/// element): node tags in the serial frame, tags, and sort keys.
fn own_boundary(
    local: &LocalMesh,
    topo: &Topology,
    num: &Numbering,
    tag: &[u64],
) -> (Vec<u64>, Vec<i32>, Vec<[u64; 4]>, Vec<u32>) {
    let ids = crate::sample::boundary_facets(&local.mesh, topo, num);
    let npf = if topo.boundary_facets.is_empty() {
        1
    } else {
        ids.len() / topo.boundary_facets.len()
    };
    let mut nodes = Vec::new();
    let mut local_ids = Vec::new();
    let mut tags = Vec::new();
    let mut keys = Vec::new();
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        let f = f as usize;
        if topo.facet_elements[f][0] as usize >= local.n_owned {
            continue;
        }
        nodes.extend(
            ids[i * npf..(i + 1) * npf]
                .iter()
                .map(|&id| tag[id as usize]),
        );
        local_ids.extend_from_slice(&ids[i * npf..(i + 1) * npf]);
        tags.push(topo.boundary_facet_tags.get(i).copied().unwrap_or(0));
        let vs: Vec<u32> = if local.mesh.dim == 2 {
            topo.edges[f].to_vec()
        } else {
            topo.faces[f].to_vec()
        };
        let mut k = [0u64; 4];
        for (j, &v) in vs.iter().enumerate() {
            k[j] = local.global_vertex[v as usize];
        }
        k[..vs.len()].sort_unstable();
        keys.push(k);
    }
    (nodes, tags, keys, local_ids)
}
