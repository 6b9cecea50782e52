//! What a rank's ghosted sub-mesh needs to agree with the other ranks: global keys of its
//! control points, the halo built from them, the size levels under the whole mesh's largest
//! element, and the certified blend's sharing in global element ids.
//!
//! Input: a [`LocalMesh`] (own elements, then ghosts), its topology and spline space.
//! Output: the [`Halo`] of the control points the own elements touch (local ids of the space,
//! increasing; per neighbour the shared ones in key order, the same order on both sides), the
//! size levels, and a [`BlendShare`]. Invariant: a control point's key names the mesh entity it
//! belongs to by global ids (element index in the file, node tags), so two ranks that build
//! the same control point from their own ghosted sub-meshes give it the same key.

use super::cg::Halo;
use super::comm::Comm;
use super::read::LocalMesh;
use crate::fit::{InheritShare, RECORD_LEN};
use crate::mesh::Topology;
use crate::spline::{ControlPoint, ElementRows, SplineSpace};
use crate::validity::blend::BlendShare;
use std::collections::{BTreeSet, HashMap};

/// Vertex rings of ghosts around a rank's elements. The spline stencil of an element reaches
/// its vertex one-ring; its class and the constrained Q2 elements' weights, the next ring;
/// the smooth targets and features of its boundary vertices read their facet two-ring, whose
/// facets belong to the same two element rings (a facet of the cut fringe of the ghost layer
/// touches no vertex of a one-ring element). The size scaling D of a control point, the
/// largest level of the elements using it, is agreed over the halo instead
/// ([`min_over_halo`]), so no ghost's own stencil is needed. What reads farther is taken
/// from the ranks that compute it instead of deeper rings ([`VertexHalo`]): the interior
/// inheritance's paths, and on coarse surfaces the arc normals, whose flag and grid normal
/// read the two-ring models of vertices two rings out (`fit::smooth`).
pub const GHOST_DEPTH: usize = 2;

/// `v[i]` ← min over the ranks sharing control point `halo.global[i]` of their values (one
/// exchange with the neighbours).
pub fn min_over_halo(comm: &dyn Comm, halo: &Halo, v: &mut [f64]) {
    let mut send = vec![Vec::new(); comm.size()];
    for (q, list) in &halo.neighbours {
        send[*q] = list.iter().map(|&i| v[i as usize]).collect();
    }
    let recv = comm.exchange_f64(&send);
    for (q, list) in &halo.neighbours {
        for (&i, &x) in list.iter().zip(&recv[*q]) {
            v[i as usize] = v[i as usize].min(x);
        }
    }
}

/// A control point's entity kind and the sorted global ids of the entity.
pub type Key = [u64; 5];

/// The global key of control point `cp` of the space built on `local`; with `seams` (node
/// tag → representative tag, [`super::periodic::Resolved::seam_map`]) that of the glued
/// entity, whose vertices are the representatives: a space glued along periodic seams
/// numbers its control points by the glued mesh's entities (`spline::seam::unwrap` renames
/// the keys to one side's entity, not the numbering).
pub fn key_of(
    cp: ControlPoint,
    local: &LocalMesh,
    topo: &Topology,
    seams: Option<&HashMap<u64, u64>>,
) -> Key {
    let gv = |v: u32| {
        let t = local.global_vertex[v as usize];
        seams.and_then(|m| m.get(&t)).copied().unwrap_or(t)
    };
    let ge = |e: u32| local.global_element[e as usize];
    let (kind, ids): (u64, Vec<u64>) = match cp {
        ControlPoint::Cell(e) => (0, vec![ge(e)]),
        ControlPoint::BFace(f) => (1, topo.faces[f as usize].iter().map(|&v| gv(v)).collect()),
        ControlPoint::BEdge(d) => (2, topo.edges[d as usize].iter().map(|&v| gv(v)).collect()),
        ControlPoint::BVertex(v) => (3, vec![gv(v)]),
        ControlPoint::Q2Vertex(v) => (4, vec![gv(v)]),
        ControlPoint::Q2Edge(d) => (5, topo.edges[d as usize].iter().map(|&v| gv(v)).collect()),
        ControlPoint::Q2Face(f) => (6, topo.faces[f as usize].iter().map(|&v| gv(v)).collect()),
        ControlPoint::Q2Centre(e) => (7, vec![ge(e)]),
    };
    let mut k = [0u64; 5];
    k[0] = kind;
    let mut ids = ids;
    ids.sort_unstable();
    k[1..1 + ids.len()].copy_from_slice(&ids);
    k
}

/// The control points the own elements touch, increasing.
pub fn touched(space: &SplineSpace, n_owned: usize) -> Vec<u32> {
    let mut rows = ElementRows::default();
    let mut t = Vec::new();
    for e in 0..n_owned {
        space.extraction.rows(e, &mut rows);
        t.extend_from_slice(&rows.cols);
    }
    t.sort_unstable();
    t.dedup();
    t
}

/// The halo of the own elements' control points (see the module docs): each rank sends the
/// keys of its control points to the owners of its ghosts and keeps the keys it has in common
/// with each.
pub fn halo(
    comm: &dyn Comm,
    local: &LocalMesh,
    topo: &Topology,
    space: &SplineSpace,
    seams: Option<&HashMap<u64, u64>>,
) -> Halo {
    let (rank, size) = (comm.rank(), comm.size());
    let global = touched(space, local.n_owned);
    let keys: Vec<Key> = global
        .iter()
        .map(|&c| key_of(space.control_point_keys[c as usize], local, topo, seams))
        .collect();
    let mut by_key: Vec<(Key, u32)> = keys
        .iter()
        .enumerate()
        .map(|(i, &k)| (k, i as u32))
        .collect();
    by_key.sort_unstable();
    let candidates: BTreeSet<usize> = local.owner[local.n_owned..]
        .iter()
        .map(|&q| q as usize)
        .filter(|&q| q != rank)
        .collect();
    // Keys travel as f64 (node tags and element ids are below 2^53).
    let flat: Vec<f64> = by_key
        .iter()
        .flat_map(|(k, _)| k.map(|x| x as f64))
        .collect();
    let mut send = vec![Vec::new(); size];
    for &q in &candidates {
        send[q] = flat.clone();
    }
    drop(flat);
    let recv = comm.exchange_f64(&send);
    drop(send);
    let mut neighbours = Vec::new();
    for (q, theirs) in recv.iter().enumerate() {
        if q == rank || theirs.is_empty() || !candidates.contains(&q) {
            continue;
        }
        let mut list = Vec::new();
        let mut j = 0;
        for k in theirs.chunks_exact(5) {
            let k: Key = std::array::from_fn(|i| k[i] as u64);
            while j < by_key.len() && by_key[j].0 < k {
                j += 1;
            }
            if j < by_key.len() && by_key[j].0 == k {
                list.push(by_key[j].1);
                j += 1;
            }
        }
        if !list.is_empty() {
            neighbours.push((q, list));
        }
    }
    let mut owned = vec![true; global.len()];
    for (q, list) in &neighbours {
        if *q < rank {
            for &i in list {
                owned[i as usize] = false;
            }
        }
    }
    Halo {
        global,
        owned,
        neighbours,
        keys,
    }
}

/// [`BlendShare`] of a ghosted sub-mesh: element lists travel in global ids (as f64, exact
/// below 2⁵³) and come back as the local ids of the elements this rank has (own or ghost).
pub struct LocalShare<'a> {
    pub comm: &'a dyn Comm,
    pub mine: &'a [usize],
    pub global: &'a [u64],
    pub local_of: HashMap<u64, usize>,
}

impl BlendShare for LocalShare<'_> {
    fn mine(&self) -> Option<&[usize]> {
        Some(self.mine)
    }
    fn union(&self, elements: Vec<usize>) -> (Vec<usize>, bool) {
        let v: Vec<f64> = elements.iter().map(|&e| self.global[e] as f64).collect();
        let gathered = self.comm.all_gather_f64(&v).concat();
        let any = !gathered.is_empty();
        let mut all: Vec<usize> = gathered
            .into_iter()
            .filter_map(|x| self.local_of.get(&(x as u64)).copied())
            .collect();
        // In the whole mesh's order: the blend lowers the factors of the rejected elements
        // one after the other, each looking at the factors the ones before it left.
        all.sort_unstable_by_key(|&e| self.global[e]);
        all.dedup();
        (all, any)
    }
    fn concat(&self, values: Vec<f64>) -> Vec<f64> {
        self.comm.all_gather_f64(&values).concat()
    }
    fn sum(&self, v: usize) -> usize {
        let mut x = [v as u64];
        self.comm.sum_u64(&mut x);
        x[0] as usize
    }
    fn min(&self, v: f64) -> f64 {
        let mut x = [v];
        self.comm.min_f64(&mut x);
        x[0]
    }
    fn global(&self, e: usize) -> usize {
        self.global[e] as usize
    }
}

/// [`InheritShare`] of a ghosted sub-mesh: a rank computes the vertices of its own elements;
/// the other vertices of the elements around them take the records of the rank owning the
/// lowest global element among the ghosts at that vertex (a vertex of one of its own
/// elements); with [`InheritShare::exchange_all`], every other vertex of its ghost rings does.
/// The whole mesh's vertex order is the node tags' (the file's order, as the serial reader
/// numbers the vertices, wherever the tags increase through the file).
pub struct VertexHalo<'a> {
    comm: &'a dyn Comm,
    local: &'a LocalMesh,
    computed: Vec<bool>,
    /// The vertices around the computed ones: per rank, the local vertices whose records it
    /// asked for, in its order, and the local vertices whose records come from it.
    around: Lists,
    /// The same for every vertex of the ghost rings, made at the first
    /// [`InheritShare::exchange_all`].
    all: std::cell::OnceCell<Lists>,
}

/// Per rank: the local vertices whose records it asked for (`give`), and the local vertices
/// whose records come from it (`take`), both in the order asked.
struct Lists {
    give: Vec<(usize, Vec<u32>)>,
    take: Vec<(usize, Vec<u32>)>,
}

impl<'a> VertexHalo<'a> {
    /// The halo of `local`'s vertices (collective: one exchange of the requests).
    pub fn new(comm: &'a dyn Comm, local: &'a LocalMesh) -> Self {
        let mesh = &local.mesh;
        let mut computed = vec![false; mesh.n_vertices()];
        for e in 0..local.n_owned {
            for &v in mesh.element(e) {
                computed[v as usize] = true;
            }
        }
        let around = Self::lists(comm, local, &computed, false);
        VertexHalo {
            comm,
            local,
            computed,
            around,
            all: std::cell::OnceCell::new(),
        }
    }

    /// The request lists of the vertices not computed here: those of the ghosts touching a
    /// computed vertex (across periodic seams too: a ghost glued to a computed vertex, where
    /// the inheritance steps over to the other side), or (`all`) those of every ghost
    /// (collective: one exchange).
    fn lists(comm: &dyn Comm, local: &LocalMesh, computed: &[bool], all: bool) -> Lists {
        let (mesh, size) = (&local.mesh, comm.size());
        // The glued vertices of the computed ones (none without glued seams).
        let glued = local.glued.as_deref().map(|g| &g.mesh);
        let mut glued_computed = vec![false; glued.map_or(0, |g| g.n_vertices())];
        if let Some(g) = glued {
            for e in 0..mesh.n_elements() {
                for (&v, &w) in mesh.element(e).iter().zip(g.element(e)) {
                    glued_computed[w as usize] |= computed[v as usize];
                }
            }
        }
        let touches = |e: usize| {
            mesh.element(e).iter().any(|&v| computed[v as usize])
                || glued.is_some_and(|g| g.element(e).iter().any(|&w| glued_computed[w as usize]))
        };
        // Per vertex needed: the lowest global ghost element at it.
        let mut from: HashMap<u32, (u64, usize)> = HashMap::new();
        for e in local.n_owned..mesh.n_elements() {
            let vs = mesh.element(e);
            if !all && !touches(e) {
                continue;
            }
            let g = local.global_element[e];
            for &v in vs.iter().filter(|&&v| !computed[v as usize]) {
                let at = from.entry(v).or_insert((g, e));
                if g < at.0 {
                    *at = (g, e);
                }
            }
        }
        let mut take = vec![Vec::new(); size];
        for (&v, &(_, e)) in &from {
            take[local.owner[e] as usize].push(v);
        }
        for t in &mut take {
            t.sort_unstable_by_key(|&v| local.global_vertex[v as usize]);
        }
        let send: Vec<Vec<f64>> = take
            .iter()
            .map(|t| {
                t.iter()
                    .map(|&v| local.global_vertex[v as usize] as f64)
                    .collect()
            })
            .collect();
        let asked = comm.exchange_f64(&send);
        let of_tag: HashMap<u64, u32> = (0..mesh.n_vertices() as u32)
            .filter(|&v| computed[v as usize])
            .map(|v| (local.global_vertex[v as usize], v))
            .collect();
        let give = asked
            .into_iter()
            .enumerate()
            .filter(|(_, a)| !a.is_empty())
            .map(|(q, a)| {
                // A vertex asked for is one of this rank's own elements' (the asker holds
                // that element as a ghost).
                let list = a.iter().map(|&t| of_tag[&(t as u64)]).collect();
                (q, list)
            })
            .collect();
        let take = take
            .into_iter()
            .enumerate()
            .filter(|(_, t)| !t.is_empty())
            .collect();
        Lists { give, take }
    }

    /// Replaces the records of `lists`' taken vertices by the ranks' that give them.
    fn swap(&self, lists: &Lists, records: &mut [f64]) {
        let n = RECORD_LEN;
        let mut send = vec![Vec::new(); self.comm.size()];
        for (q, list) in &lists.give {
            send[*q] = list
                .iter()
                .flat_map(|&v| &records[v as usize * n..(v as usize + 1) * n])
                .copied()
                .collect();
        }
        let recv = self.comm.exchange_f64(&send);
        for (q, list) in &lists.take {
            for (&v, r) in list.iter().zip(recv[*q].chunks_exact(n)) {
                records[v as usize * n..(v as usize + 1) * n].copy_from_slice(r);
            }
        }
    }
}

impl InheritShare for VertexHalo<'_> {
    fn computes(&self, v: usize) -> bool {
        self.computed[v]
    }
    fn order(&self, v: usize) -> u64 {
        self.local.global_vertex[v]
    }
    fn exchange(&self, records: &mut [f64]) {
        self.swap(&self.around, records);
    }
    fn exchange_all(&self, records: &mut [f64]) {
        let all = self
            .all
            .get_or_init(|| Self::lists(self.comm, self.local, &self.computed, true));
        self.swap(all, records);
    }
    fn any(&self, local: bool) -> bool {
        let mut x = [u64::from(local)];
        self.comm.sum_u64(&mut x);
        x[0] > 0
    }
}
