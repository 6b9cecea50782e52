//! Periodic pairs across MPI ranks (`--periodic A:B` under mpirun): the two sides of a pair
//! may fall on different ranks.
//!
//! Input: each rank's [`LocalMesh`] and topology (its own elements' boundary facets carry the
//! input's tags), the pairs as the user names them, and after sampling the rank's sampled
//! nodes (local ids with global tags and positions). Output: on every rank alike, the
//! verified pairs ([`resolve`]), and after [`make_images`] the node pairs in global node tags
//! ([`TagLink`], what the collective writer's `$Periodic` section writes), with every seam node
//! a rank holds moved so that the image side's nodes are the transform of the master side's.
//!
//! **Resolve.** Every rank contributes the boundary facets of its own elements tagged A or B
//! (vertex tags and positions, the element's centroid); the gathered facets are the two sides
//! whole, and every rank finds and verifies the transform on them with the serial code
//! ([`crate::mesh::periodic::pair_facets`]), so every rank has the same pairs and the same
//! error. The boundary groups of the sides are gathered whole (one all-gather of 21 doubles per
//! facet of A and B): this is replicated, like the 2D post-fit misfit sides.
//!
//! **Glue.** [`Resolved::seam_map`] gives every image node of a pair (translation or
//! rotation) its representative tag; the job reads its share again with the ghost rings run
//! on across the seams, and [`glue_share`] glues it as the serial job glues the whole mesh
//! (the ranks agree that all of them can). Across a rotation seam each rank's elements,
//! ghosts too, then see the control points across it rotated (`spline::seam::unwrap`, homes
//! by global element), and the fit couples the coordinates (`super::cg::pcg_coupled`).
//!
//! **Images.** After sampling, every rank
//! contributes the order-P nodes of its own A and B facets (global tag, straight-sided position
//! — the multilinear map of their element at the lattice point — and sampled position); the
//! gathered nodes pair by their straight positions as [`crate::mesh::periodic::node_pairs`]
//! pairs them serially, and [`crate::mesh::periodic::place_images`] moves them on the gathered
//! copy, which is the same on every rank: so a node held by several ranks gets bit-identical
//! coordinates on each, and an image node is the transform of its master to rounding whatever
//! ranks hold the two. Every rank certifies its own elements holding a moved node (Bernstein
//! bounds of their Lagrange map, as serially); the nodes of the elements that fail are
//! all-gathered and the pairs around them keep the master's, then the image's side, as the
//! serial [`crate::mesh::periodic::make_images`] does. Invariant: the result is the serial
//! seam pass's on the same sampled nodes.

use super::comm::Comm;
use super::read::LocalMesh;
use crate::math::BezierElements;
use crate::mesh::Topology;
use crate::mesh::high_order::lattice_point;
use crate::mesh::periodic::{
    Declared, IMAGE_WEIGHTS, ImageInfo, PERIODIC_REL_TOL, PeriodicError, PeriodicLink,
    PeriodicPair, PeriodicSpec, PointGrid, Rigid, SideFacet, declared_pairs, pair_facets,
    place_images, spec_tags,
};
use crate::pipeline::CurveError;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// A periodic pair's node pairs in global node tags: what `$Periodic` writes.
#[derive(Clone, Debug)]
pub struct TagLink {
    pub master_tag: i32,
    pub slave_tag: i32,
    /// Maps the master side onto the image side.
    pub transform: Rigid,
    /// (image node tag, master node tag), sorted.
    pub node_pairs: Vec<[u64; 2]>,
}

/// The facets of the own elements tagged `tag`, as (local facet index in
/// `topo.boundary_facets`, facet id).
fn own_facets<'a>(
    local: &'a LocalMesh,
    topo: &'a Topology,
    tag: i32,
) -> impl Iterator<Item = (usize, usize)> + 'a {
    topo.boundary_facets
        .iter()
        .enumerate()
        .filter(move |&(i, &f)| {
            topo.boundary_facet_tags.get(i) == Some(&tag)
                && (topo.facet_elements[f as usize][0] as usize) < local.n_owned
        })
        .map(|(i, &f)| (i, f as usize))
}

/// Width of a gathered facet record: side, vertex count, 4 vertex tags, 4 positions, the
/// element's centroid.
const FACET_WIDTH: usize = 21;

/// Resolve and verify every pair of `specs` over the whole mesh (collective; the same pairs,
/// or the same error, on every rank). The pairs' vertex maps index the gathered sides'
/// vertices, not the rank's.
pub fn resolve(
    comm: &dyn Comm,
    local: &LocalMesh,
    topo: &Topology,
    specs: &[PeriodicSpec],
) -> Result<Resolved, PeriodicError> {
    let mesh = &local.mesh;
    // The boundary groups of the whole mesh.
    let mine: Vec<f64> = topo
        .boundary_facets
        .iter()
        .zip(&topo.boundary_facet_tags)
        .filter(|&(&f, _)| (topo.facet_elements[f as usize][0] as usize) < local.n_owned)
        .map(|(_, &t)| t)
        .collect::<std::collections::BTreeSet<i32>>()
        .into_iter()
        .map(f64::from)
        .collect();
    let mut tags: Vec<i32> = comm
        .all_gather_f64(&mine)
        .concat()
        .iter()
        .map(|&t| t as i32)
        .collect();
    tags.sort_unstable();
    tags.dedup();
    // The command line's pairs, then the file's (`$Periodic`, read by every rank) whose groups
    // they do not name, as the serial `resolve` takes them.
    let mut resolved: Vec<Declared> = spec_tags(&mesh.tag_names, &tags, specs)?
        .into_iter()
        .map(|(spec, ta, tb)| (spec, ta, tb, Vec::new()))
        .collect();
    let mut seen: Vec<i32> = resolved.iter().flat_map(|r| [r.1, r.2]).collect();
    resolved.extend(declared_pairs(
        &mesh.tag_names,
        &mesh.declared_periodic,
        &tags,
        &mut seen,
    )?);
    let mut out = Resolved::default();
    for (spec, ta, tb, claims) in resolved {
        let mut send = Vec::new();
        for (side, tag) in [(0.0, ta), (1.0, tb)] {
            for (_, f) in own_facets(local, topo, tag) {
                let vs = topo.facet_vertices(f);
                let mut r = [0.0; FACET_WIDTH];
                r[0] = side;
                r[1] = vs.len() as f64;
                for (k, &v) in vs.iter().enumerate() {
                    r[2 + k] = local.global_vertex[v as usize] as f64;
                    r[6 + 3 * k..9 + 3 * k].copy_from_slice(&mesh.coords[v as usize]);
                }
                let ex = mesh.element(topo.facet_elements[f][0] as usize);
                for &v in ex {
                    for c in 0..3 {
                        r[18 + c] += mesh.coords[v as usize][c] / ex.len() as f64;
                    }
                }
                send.extend_from_slice(&r);
            }
        }
        let all = comm.all_gather_f64(&send).concat();
        drop(send);
        // The sides' vertices by tag (sorted, so every rank numbers them alike).
        let mut index: BTreeMap<u64, [f64; 3]> = BTreeMap::new();
        for r in all.chunks_exact(FACET_WIDTH) {
            for k in 0..r[1] as usize {
                index
                    .entry(r[2 + k] as u64)
                    .or_insert([r[6 + 3 * k], r[7 + 3 * k], r[8 + 3 * k]]);
            }
        }
        let coords: Vec<[f64; 3]> = index.values().copied().collect();
        let at: HashMap<u64, u32> = index
            .keys()
            .enumerate()
            .map(|(i, &t)| (t, i as u32))
            .collect();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for r in all.chunks_exact(FACET_WIDTH) {
            let facet = SideFacet {
                vertices: (0..r[1] as usize).map(|k| at[&(r[2 + k] as u64)]).collect(),
                inside: [r[18], r[19], r[20]],
            };
            if r[0] == 0.0 { &mut a } else { &mut b }.push(facet);
        }
        let found = pair_facets(&coords, mesh.dim, &spec, (ta, a), (tb, b), &claims)?;
        let tag: Vec<u64> = index.into_keys().collect();
        out.tag_maps.push(
            found
                .vertex_map
                .iter()
                .map(|&[b, a]| [tag[b as usize], tag[a as usize]])
                .collect(),
        );
        out.pairs.push(found);
    }
    Ok(out)
}

/// The verified pairs of [`resolve`], the same on every rank.
#[derive(Default)]
pub struct Resolved {
    /// Their vertex maps index the gathered sides' vertices.
    pub pairs: Vec<PeriodicPair>,
    /// Per pair, its vertex map in node tags: (image tag, master tag).
    pub tag_maps: Vec<Vec<[u64; 2]>>,
}

impl Resolved {
    /// Node tag → representative tag of the glued seams (the lowest tag of each chain of
    /// pairs, as `spline::seam::glue` represents a class by its lowest vertex); only the tags
    /// represented by another. Empty without pairs.
    pub fn seam_map(&self) -> HashMap<u64, u64> {
        let mut parent: HashMap<u64, u64> = HashMap::new();
        fn find(parent: &mut HashMap<u64, u64>, mut t: u64) -> u64 {
            while let Some(&p) = parent.get(&t) {
                t = p;
            }
            t
        }
        for map in &self.tag_maps {
            for &[b, a] in map {
                let (rb, ra) = (find(&mut parent, b), find(&mut parent, a));
                if ra != rb {
                    parent.insert(ra.max(rb), ra.min(rb));
                }
            }
        }
        let tags: Vec<u64> = parent.keys().copied().collect();
        tags.into_iter()
            .map(|t| (t, find(&mut parent, t)))
            .collect()
    }

    /// The pairs with their vertex maps in the local vertices of `local` (the vertex pairs
    /// whose two vertices it holds): what a rank's sub-mesh is glued by.
    pub fn local_pairs(&self, local: &LocalMesh) -> Vec<PeriodicPair> {
        let at: HashMap<u64, u32> = local
            .global_vertex
            .iter()
            .enumerate()
            .map(|(i, &t)| (t, i as u32))
            .collect();
        self.pairs
            .iter()
            .zip(&self.tag_maps)
            .map(|(p, map)| PeriodicPair {
                vertex_map: map
                    .iter()
                    .filter_map(|[b, a]| Some([*at.get(b)?, *at.get(a)?]))
                    .collect(),
                ..p.clone()
            })
            .collect()
    }
}

/// The seams of `pairs` (translations and rotations) glued on this rank's sub-mesh
/// (`spline::seam::glue_share`: classes represented by their lowest node tag, homes by the
/// lowest global element, only the own elements' entities checked manifold), and why a pair
/// stays apart: the serial job's rule (`pipeline::head::glue_seams`) with the ranks' reduction.
/// Collective: either every rank glues its seams or none does. The share must have been read
/// with its ghost rings run on across the seams ([`Resolved::seam_map`]), a single file's or
/// Gmsh's parts alike.
pub fn glue_share(
    comm: &dyn Comm,
    local: &LocalMesh,
    resolved: &Resolved,
) -> (Option<crate::spline::seam::Glued>, Option<String>) {
    let pairs = &resolved.pairs;
    if pairs.is_empty() {
        return (None, None);
    }
    let mesh = &local.mesh;
    let mut near = vec![false; mesh.n_vertices()];
    for e in 0..local.n_owned {
        for &v in mesh.element(e) {
            near[v as usize] = true;
        }
    }
    let order = crate::spline::seam::ShareOrder {
        vertex: &local.global_vertex,
        element: &local.global_element,
        near: &near,
    };
    let local_pairs = resolved.local_pairs(local);
    crate::pipeline::head::glue_seams(comm, pairs, |rotations| {
        crate::spline::seam::glue_share(mesh, &local_pairs, Some(&order), rotations)
    })
}

/// What the seam pass needs besides the sampled nodes.
pub struct Seams<'a> {
    pub pairs: &'a [PeriodicPair],
    pub input: &'a Path,
    /// Subdivision depth of the Bernstein certificate (`--certificate-depth`).
    pub depth: usize,
    /// With glued seams, the features' boundary facets: per boundary facet of the topology
    /// they were found on (the seam facets interior), its index among the input's
    /// (`SeamView::boundary_rows`); `None`: the input's.
    pub boundary_rows: Option<&'a [u32]>,
}

/// The rank's sampled share as the seam pass sees it: local node ids of the own elements
/// (`(p+1)^d` each) and of the own boundary facets (`(p+1)^(d−1)` each, with their tags), the
/// global tag of every local id the own elements use, and their positions.
pub struct SampledShare<'a> {
    pub local: &'a LocalMesh,
    pub p: usize,
    pub ids: &'a [u32],
    pub facet_ids: &'a [u32],
    pub facet_tags: &'a [i32],
    pub tag: &'a [u64],
}

/// Width of a gathered node record: pair, side, tag, straight position, sampled position.
const NODE_WIDTH: usize = 9;

/// Make the image sides' nodes the transform of their masters' over all ranks (see the module
/// docs), moving the seam nodes of `xyz`. Collective; the same links, figures and errors on
/// every rank.
pub fn make_images(
    comm: &dyn Comm,
    seams: &Seams,
    share: &SampledShare,
    xyz: &mut [[f64; 3]],
) -> Result<(Vec<TagLink>, ImageInfo), CurveError> {
    let (local, p) = (share.local, share.p);
    let mesh = &local.mesh;
    let d = mesh.dim;
    let npe = (p + 1).pow(d as u32);
    let npf = (p + 1).pow(d as u32 - 1);
    // Which (pair, side) each own facet's nodes are on.
    let mut side_of: HashMap<u32, Vec<(usize, usize)>> = HashMap::new();
    let mut spacing = vec![f64::INFINITY; seams.pairs.len()];
    let corners: Vec<usize> = if d == 2 {
        vec![0, p]
    } else {
        vec![0, p, (p + 1) * (p + 1) - 1, (p + 1) * p]
    };
    // Straight-sided positions of the seam nodes, from their own elements.
    let mut straight: HashMap<u32, [f64; 3]> = HashMap::new();
    for (k, &t) in share.facet_tags.iter().enumerate() {
        for (i, pair) in seams.pairs.iter().enumerate() {
            for (s, side_tag) in [pair.master_tag, pair.slave_tag].into_iter().enumerate() {
                if t == side_tag {
                    for &id in &share.facet_ids[k * npf..(k + 1) * npf] {
                        let e = side_of.entry(id).or_default();
                        if !e.contains(&(i, s)) {
                            e.push((i, s));
                        }
                    }
                }
            }
        }
    }
    for e in 0..local.n_owned {
        let cell = &share.ids[e * npe..(e + 1) * npe];
        if !cell.iter().any(|id| side_of.contains_key(id)) {
            continue;
        }
        let net = mesh.bezier_net(e);
        for (n, &id) in cell.iter().enumerate() {
            if side_of.contains_key(&id) && !straight.contains_key(&id) {
                let l = lattice_point(p, d, n);
                let t = super::sample::lattice_param(p, l);
                straight.insert(id, crate::sample::eval_net(d, &net, t));
            }
        }
    }
    // The image sides' node spacing (the serial `pair_spacing`).
    for (k, &t) in share.facet_tags.iter().enumerate() {
        for (i, pair) in seams.pairs.iter().enumerate() {
            if t != pair.slave_tag {
                continue;
            }
            let f = &share.facet_ids[k * npf..(k + 1) * npf];
            for c in 0..corners.len() {
                let a = straight[&f[corners[c]]];
                let b = straight[&f[corners[(c + 1) % corners.len()]]];
                let len = (0..3).map(|j| (a[j] - b[j]).powi(2)).sum::<f64>().sqrt();
                spacing[i] = spacing[i].min(len);
            }
        }
    }
    comm.min_f64(&mut spacing);
    let mut send = Vec::new();
    let mut ids: Vec<u32> = side_of.keys().copied().collect();
    ids.sort_unstable();
    for &id in &ids {
        for &(i, s) in &side_of[&id] {
            send.push(i as f64);
            send.push(s as f64);
            send.push(share.tag[id as usize] as f64);
            send.extend_from_slice(&straight[&id]);
            send.extend_from_slice(&xyz[id as usize]);
        }
    }
    let all = comm.all_gather_f64(&send).concat();
    drop(send);
    // Every seam node once, by tag (sorted: every rank numbers them alike).
    let mut nodes: BTreeMap<u64, ([f64; 3], [f64; 3])> = BTreeMap::new();
    let mut sides: Vec<[Vec<u64>; 2]> = vec![[Vec::new(), Vec::new()]; seams.pairs.len()];
    for r in all.chunks_exact(NODE_WIDTH) {
        let tag = r[2] as u64;
        nodes
            .entry(tag)
            .or_insert(([r[3], r[4], r[5]], [r[6], r[7], r[8]]));
        sides[r[0] as usize][r[1] as usize].push(tag);
    }
    drop(all);
    let at: HashMap<u64, u32> = nodes
        .keys()
        .enumerate()
        .map(|(i, &t)| (t, i as u32))
        .collect();
    let tags: Vec<u64> = nodes.keys().copied().collect();
    let straight_pos: Vec<[f64; 3]> = nodes.values().map(|v| v.0).collect();
    let original: Vec<[f64; 3]> = nodes.values().map(|v| v.1).collect();
    drop(nodes);
    let periodic_err = |pair: &PeriodicPair, what: String| CurveError::Periodic {
        input: seams.input.to_owned(),
        source: PeriodicError {
            spec: pair.spec.label(),
            what,
        },
    };
    let mut links = Vec::with_capacity(seams.pairs.len());
    for (i, pair) in seams.pairs.iter().enumerate() {
        let [a, b] = &mut sides[i];
        a.sort_unstable();
        a.dedup();
        b.sort_unstable();
        b.dedup();
        let shortest = spacing[i] / p.max(1) as f64;
        let b_ids: Vec<u32> = b.iter().map(|t| at[t]).collect();
        let grid = PointGrid::new(&straight_pos, &b_ids, shortest);
        let tol = (PERIODIC_REL_TOL * shortest).max(2.0 * pair.input_mismatch);
        let mut node_pairs = Vec::with_capacity(a.len());
        for t in a.iter() {
            let n = at[t];
            match grid.nearest(pair.transform.apply(straight_pos[n as usize])) {
                Some((m, dist)) if dist <= tol => node_pairs.push([m, n]),
                _ => {
                    return Err(periodic_err(
                        pair,
                        format!("node {t} of the order-{p} mesh has no image"),
                    ));
                }
            }
        }
        node_pairs.sort_unstable();
        if node_pairs.len() != b.len() || node_pairs.windows(2).any(|w| w[0][0] == w[1][0]) {
            return Err(periodic_err(
                pair,
                format!("the order-{p} nodes of the two sides do not pair one-to-one"),
            ));
        }
        links.push(PeriodicLink {
            master_tag: pair.master_tag,
            slave_tag: pair.slave_tag,
            transform: pair.transform,
            node_pairs,
        });
    }
    drop(sides);
    // The own elements holding a seam node, and where each seam node sits in `xyz`.
    let local_of: Vec<(u32, u32)> = {
        let mut v: Vec<(u32, u32)> = Vec::new();
        let mut seen = std::collections::HashSet::new();
        for &id in share.ids {
            let t = share.tag[id as usize];
            if let Some(&k) = at.get(&t)
                && seen.insert(id)
            {
                v.push((id, k));
            }
        }
        v
    };
    let touched: Vec<usize> = (0..local.n_owned)
        .filter(|&e| {
            share.ids[e * npe..(e + 1) * npe]
                .iter()
                .any(|id| at.contains_key(&share.tag[*id as usize]))
        })
        .collect();
    let mut weight: Vec<Vec<usize>> = links.iter().map(|l| vec![0; l.node_pairs.len()]).collect();
    let mut pos = original.clone();
    let mut min_det_bound = f64::INFINITY;
    let mut bad_global: Vec<u64> = Vec::new();
    for round in 0..IMAGE_WEIGHTS.len() {
        place_images(&mut pos, &original, &links, &weight);
        for &(id, k) in &local_of {
            xyz[id as usize] = pos[k as usize];
        }
        let ho = crate::mesh::HighOrderMesh {
            dim: d,
            order: p,
            nodes: xyz.to_vec(),
            elements: share.ids.to_vec(),
            ..Default::default()
        };
        use rayon::prelude::*;
        let bounds: Vec<(usize, f64)> = touched
            .par_iter()
            .map(|&e| {
                (
                    e,
                    crate::validity::lagrange_element_bounds(&ho, e, seams.depth).lower,
                )
            })
            .collect();
        drop(ho);
        let mut m = [bounds.iter().map(|b| b.1).fold(f64::INFINITY, f64::min)];
        comm.min_f64(&mut m);
        min_det_bound = m[0];
        // The failing elements' global ids, then their nodes' tags.
        let bad: Vec<usize> = bounds
            .iter()
            .filter(|b| !(b.1 > 0.0))
            .map(|b| b.0)
            .collect();
        let mut send: Vec<f64> = Vec::new();
        for &e in &bad {
            send.push(local.global_element[e] as f64);
            send.extend(
                share.ids[e * npe..(e + 1) * npe]
                    .iter()
                    .map(|&id| share.tag[id as usize] as f64),
            );
        }
        let all = comm.all_gather_f64(&send).concat();
        bad_global = all.chunks_exact(npe + 1).map(|r| r[0] as u64).collect();
        if bad_global.is_empty() || round + 1 == IMAGE_WEIGHTS.len() {
            break;
        }
        let mut in_bad = vec![false; tags.len()];
        for r in all.chunks_exact(npe + 1) {
            for &t in &r[1..] {
                if let Some(&k) = at.get(&(t as u64)) {
                    in_bad[k as usize] = true;
                }
            }
        }
        for (l, w) in links.iter().zip(weight.iter_mut()) {
            for (k, &[s, m]) in l.node_pairs.iter().enumerate() {
                if in_bad[s as usize] || in_bad[m as usize] {
                    w[k] = round + 1;
                }
            }
        }
    }
    if !bad_global.is_empty() {
        bad_global.sort_unstable();
        let bad: Vec<usize> = bad_global.iter().map(|&e| e as usize).collect();
        return Err(CurveError::invalid(seams.input, "periodic seam", &bad));
    }
    let mut recertified = [touched.len() as u64];
    comm.sum_u64(&mut recertified);
    let max_shift = pos
        .iter()
        .zip(&original)
        .map(|(a, b)| (0..3).map(|j| (a[j] - b[j]).powi(2)).sum::<f64>().sqrt())
        .fold(0.0, f64::max);
    let info = ImageInfo {
        max_shift,
        max_mismatch: crate::mesh::periodic::max_mismatch(&pos, &links),
        recertified: recertified[0] as usize,
        min_det_bound,
    };
    let links = links
        .into_iter()
        .map(|l| TagLink {
            master_tag: l.master_tag,
            slave_tag: l.slave_tag,
            transform: l.transform,
            node_pairs: l
                .node_pairs
                .iter()
                .map(|&[s, m]| [tags[s as usize], tags[m as usize]])
                .collect(),
        })
        .collect();
    Ok((links, info))
}
