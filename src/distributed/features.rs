//! The report's feature summary over the ranks: each rank detects the features of its
//! ghosted sub-mesh (`pipeline::spline::SplineSetup`); this module counts every feature entity
//! once over the ranks and joins the patches that cross ranks.
//!
//! Input: this rank's [`LocalMesh`], its topology and [`Features`], the sampled figures of its
//! own boundary ([`super::sample::RankOutput::feature_deviation`]). Output: the serial
//! report's [`FeatureReport`], the same on every rank.
//!
//! **Counts.** A vertex is counted by the rank holding the lowest global element around it
//! (every element around a vertex of an own element is in the sub-mesh, so the rank that owns
//! that element sees it); a feature edge by the rank counting its end point of lower input
//! tag; a crease element by its owner. Each rank's features are detected from the facet
//! two-ring of its own vertices, as the serial detection reads them, so the counts are the
//! serial ones.
//!
//! **Patches.** A patch may cross ranks. Each rank's patches get global labels (an exclusive
//! scan of the counts); each boundary facet this rank holds as a ghost near its own elements
//! (of an element touching an own element's vertex, so not a cut face of the ghost fringe)
//! is sent, by its sorted input node tags, to the rank owning it, which links the sender's
//! label to its own patch of that facet. The links are gathered and joined (union–find); a
//! joined patch counts when one of its parts holds an own facet, and is planar when every such
//! part found its facets on one plane (the plane is fitted per rank over the part it holds;
//! docs/distributed.md).

use super::comm::Comm;
use super::read::LocalMesh;
use crate::mesh::Topology;
use crate::mesh::features::{FeatureParams, FeatureReport, FeatureSummary, Features};
use std::collections::HashMap;

/// The sorted input node tags of boundary facet `f` (unused slots 0).
fn facet_key(local: &LocalMesh, topo: &Topology, f: usize) -> [u64; 4] {
    let mut k = [0u64; 4];
    let vs = topo.facet_vertices(f);
    for (j, &v) in vs.iter().enumerate() {
        k[j] = local.global_vertex[v as usize];
    }
    k[..vs.len()].sort_unstable();
    k
}

/// Per vertex of the sub-mesh: whether this rank counts it (see the module docs).
fn counted_vertices(local: &LocalMesh) -> Vec<bool> {
    let mesh = &local.mesh;
    let mut lowest = vec![(u64::MAX, usize::MAX); mesh.n_vertices()];
    for e in 0..mesh.n_elements() {
        let g = local.global_element[e];
        for &v in mesh.element(e) {
            let l = &mut lowest[v as usize];
            if g < l.0 {
                *l = (g, e);
            }
        }
    }
    lowest.iter().map(|&(_, e)| e < local.n_owned).collect()
}

/// The feature report of the whole mesh (collective; see the module docs). `deviation`: this
/// rank's largest feature vertex deviation and planarity (absolute), `diagonal` the input's.
pub fn feature_report(
    comm: &dyn Comm,
    local: &LocalMesh,
    topo: &Topology,
    f: Option<&Features>,
    params: &FeatureParams,
    deviation: (f64, f64),
    diagonal: f64,
) -> FeatureReport {
    let (sums, patches, planar) = match f {
        Some(f) => counts(comm, local, topo, f),
        // No feature near this rank's elements: it still takes part in the collectives.
        None => {
            let mut sums = [0u64; 4];
            comm.sum_u64(&mut sums);
            let (patches, planar) = joined(comm, &[], vec![Vec::new(); comm.size()], |_| None);
            (sums, patches, planar)
        }
    };
    let mut maxs = [deviation.0, deviation.1];
    comm.max_f64(&mut maxs);
    FeatureReport {
        found: FeatureSummary {
            feature_angle_deg: params.angle_deg,
            tags: params.tags,
            feature_edges: sums[0] as usize,
            feature_corners: sums[1] as usize,
            feature_vertices: sums[2] as usize,
            patches,
            planar_patches: planar,
            crease_elements: sums[3] as usize,
        },
        feature_vertex_deviation_max: maxs[0] / diagonal,
        planarity_max: maxs[1] / diagonal,
    }
}

/// Feature edges, corners, vertices and crease elements summed over the ranks, and the
/// joined patches (collective).
fn counts(
    comm: &dyn Comm,
    local: &LocalMesh,
    topo: &Topology,
    f: &Features,
) -> ([u64; 4], usize, usize) {
    let counted = counted_vertices(local);
    let tag = |v: u32| local.global_vertex[v as usize];
    let edges = f
        .edges
        .iter()
        .filter(|&&e| {
            let [a, b] = topo.edges[e as usize];
            counted[if tag(a) < tag(b) { a } else { b } as usize]
        })
        .count();
    let corners = f.corners.iter().filter(|&&v| counted[v as usize]).count();
    let vertices = (0..f.vertex_mask.len())
        .filter(|&v| f.vertex_mask[v] && counted[v])
        .count();
    let crease = f.crease_elements(topo)[..local.n_owned]
        .iter()
        .filter(|&&c| c)
        .count();
    let mut sums = [edges as u64, corners as u64, vertices as u64, crease as u64];
    comm.sum_u64(&mut sums);
    let (patches, planar) = joined_patches(comm, local, topo, f);
    (sums, patches, planar)
}

/// The patches of the whole mesh and how many are planar (see the module docs).
fn joined_patches(
    comm: &dyn Comm,
    local: &LocalMesh,
    topo: &Topology,
    f: &Features,
) -> (usize, usize) {
    let mesh = &local.mesh;
    let n = f.n_patches;
    // Per local patch: holds an own facet, planar.
    let mut info = vec![0.0f64; 2 * n];
    for p in 0..n {
        info[2 * p + 1] = f64::from(u8::from(f.planes[p].is_some()));
    }
    let mut near = vec![false; mesh.n_vertices()];
    for e in 0..local.n_owned {
        for &v in mesh.element(e) {
            near[v as usize] = true;
        }
    }
    let mut own_patch: HashMap<[u64; 4], u32> = HashMap::new();
    let mut send = vec![Vec::new(); comm.size()];
    for (i, &fc) in topo.boundary_facets.iter().enumerate() {
        let fc = fc as usize;
        let e = topo.facet_elements[fc][0] as usize;
        let p = f.facet_patch[i];
        if e < local.n_owned {
            info[2 * p as usize] = 1.0;
            own_patch.insert(facet_key(local, topo, fc), p);
        } else if mesh.element(e).iter().any(|&v| near[v as usize]) {
            let s = &mut send[local.owner[e] as usize];
            s.extend(facet_key(local, topo, fc).iter().map(|&t| t as f64));
            s.push(f64::from(p));
        }
    }
    joined(comm, &info, send, |key| own_patch.get(key).copied())
}

/// Join the ranks' patches: `info` per local patch (holds an own facet, planar), `send[q]`
/// the (facet key, local patch) records of the facets rank q owns, `own` the local patch of
/// an own facet by key. (patches, planar patches) of the whole mesh.
fn joined(
    comm: &dyn Comm,
    info: &[f64],
    send: Vec<Vec<f64>>,
    own: impl Fn(&[u64; 4]) -> Option<u32>,
) -> (usize, usize) {
    let rank = comm.rank();
    let infos = comm.all_gather_f64(info);
    let offsets: Vec<usize> = infos
        .iter()
        .scan(0, |at, v| {
            let o = *at;
            *at += v.len() / 2;
            Some(o)
        })
        .collect();
    let recv = comm.exchange_f64(&send);
    drop(send);
    let mut links = Vec::new();
    for (q, r) in recv.iter().enumerate() {
        for rec in r.chunks_exact(5) {
            let key: [u64; 4] = std::array::from_fn(|j| rec[j] as u64);
            if let Some(p) = own(&key) {
                links.push((offsets[q] + rec[4] as usize) as f64);
                links.push((offsets[rank] + p as usize) as f64);
            }
        }
    }
    let links = comm.all_gather_f64(&links).concat();
    let total: usize = infos.iter().map(|v| v.len() / 2).sum();
    let mut parent: Vec<usize> = (0..total).collect();
    fn root(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for l in links.chunks_exact(2) {
        let (a, b) = (
            root(&mut parent, l[0] as usize),
            root(&mut parent, l[1] as usize),
        );
        parent[a.max(b)] = a.min(b);
    }
    let flat: Vec<f64> = infos.concat();
    // Per joined patch: planar.
    let mut planar: HashMap<usize, bool> = HashMap::new();
    for label in 0..total {
        if flat[2 * label] > 0.0 {
            let r = root(&mut parent, label);
            *planar.entry(r).or_insert(true) &= flat[2 * label + 1] > 0.0;
        }
    }
    (planar.len(), planar.values().filter(|&&p| p).count())
}
