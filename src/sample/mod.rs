//! Sampling element maps on equispaced lattices into a conforming high-order mesh.
//!
//! Input: element maps as tensor-product quadratic Bézier nets ([`BezierElements`]: the spline
//! space, or a linear mesh degree-elevated), the mesh [`Topology`], and an order p (1…10).
//! Output: a [`HighOrderMesh`] whose element e has the (p+1)^d nodes x_e(i/p, j/p[, k/p]) in
//! lattice order (i fastest). Because every element map is a quadratic polynomial, an output
//! element of order p ≥ 2 represents the map exactly: its Lagrange interpolant reproduces every
//! polynomial of degree ≤ p per direction.
//!
//! **Conforming numbering.** A node is created once per mesh entity and position on it, never by
//! matching coordinates: vertices take the vertex ids 0..V; edge interiors follow (p−1 per edge,
//! counted from the edge's lower vertex id); then face interiors ((p−1)² per face, in the face's
//! stored frame: origin at its first vertex, first axis toward its second); then element
//! interiors. Each node's position is evaluated once, from one element that contains it, so
//! neighbours share ids and positions exactly.
//!
//! **Cost.** [`sample`] runs element by element: an element computes its Bézier net once and
//! evaluates the nodes it owns (about p^d of its (p+1)^d), so the spline's extraction is
//! applied once per element rather than once per node.

// The Bézier basis lives in the foundation layer; these re-exports keep the paths that the
// integration tests use (`polyspline::sample::{eval_net, multilinear, BezierElements}`).
use crate::math::bernstein::elevated_net;
pub use crate::math::bernstein::{BezierElements, BezierNet, bernstein2, eval_net, multilinear};
use crate::math::reference::{HEX_EDGES, HEX_VERTEX_PARAMS, QUAD_SIDES};
use crate::mesh::HighOrderMesh;
use crate::mesh::high_order::{Lattice, lattice_point};
use crate::mesh::{LinearMesh, Topology};
use rayon::prelude::*;

/// Largest output order.
pub const MAX_ORDER: usize = 10;

impl BezierElements for LinearMesh {
    fn dim(&self) -> usize {
        self.dim
    }
    fn n_elements(&self) -> usize {
        LinearMesh::n_elements(self)
    }
    /// The multilinear map degree-elevated to quadratic: its Bernstein points are its values on
    /// the half lattice {0, ½, 1}^d.
    fn bezier_net(&self, e: usize) -> BezierNet {
        elevated_net(self.dim, &self.element_coords(e))
    }
}

/// Conforming node numbering of an order-p mesh over a topology.
pub struct Numbering<'a> {
    mesh: &'a LinearMesh,
    topo: &'a Topology,
    p: usize,
    edge_base: usize,
    face_base: usize,
    cell_base: usize,
    total: usize,
}

/// Corner number of a lattice point whose coordinates are all 0 or p.
fn corner_of(p: usize, l: Lattice) -> usize {
    let b = [l[0] / p, l[1] / p, l[2] / p];
    const TABLE: [usize; 8] = [0, 1, 3, 2, 4, 5, 7, 6];
    TABLE[b[0] + 2 * b[1] + 4 * b[2]]
}

impl<'a> Numbering<'a> {
    pub fn new(mesh: &'a LinearMesh, topo: &'a Topology, p: usize) -> Self {
        let d = mesh.dim;
        let m = p - 1;
        let edge_base = mesh.n_vertices();
        let face_base = edge_base + topo.edges.len() * m;
        let cell_base = face_base + if d == 3 { topo.faces.len() * m * m } else { 0 };
        let total = cell_base + mesh.n_elements() * m.pow(d as u32);
        Numbering {
            mesh,
            topo,
            p,
            edge_base,
            face_base,
            cell_base,
            total,
        }
    }

    pub fn n_nodes(&self) -> usize {
        self.total
    }

    /// Face frame of side `side` of hex `e` against the stored face: for the two free
    /// directions (u < v) of the side, the lattice origin (ou, ov) of the face's first vertex
    /// and whether the face's first axis runs along v instead of u.
    fn face_frame(&self, e: usize, side: usize) -> ([usize; 2], [usize; 2], bool) {
        let p = self.p;
        let f = self.topo.element_faces[e * 6 + side] as usize;
        let fv = self.topo.faces[f];
        let m = side / 2;
        let dirs = match m {
            0 => [1, 2],
            1 => [0, 2],
            _ => [0, 1],
        };
        let nodes = self.mesh.element(e);
        let vertex_at = |a: usize, b: usize| {
            let mut l = [0; 3];
            l[m] = (side % 2) * p;
            l[dirs[0]] = a;
            l[dirs[1]] = b;
            nodes[corner_of(p, l)]
        };
        let corners = [(0, 0), (p, 0), (0, p), (p, p)];
        let (ou, ov) = *corners
            .iter()
            .find(|&&(a, b)| vertex_at(a, b) == fv[0])
            .expect("stored face vertex belongs to the element side");
        let swapped = vertex_at(p - ou, ov) != fv[1];
        (dirs, [ou, ov], swapped)
    }

    /// Node id of lattice point `l` of element `e`.
    pub fn node_id(&self, e: usize, l: Lattice) -> u32 {
        let p = self.p;
        let d = self.mesh.dim;
        let at_end = |x: usize| x == 0 || x == p;
        let mut interior = [0usize; 3];
        let mut n_interior = 0;
        for k in 0..d {
            if !at_end(l[k]) {
                interior[n_interior] = k;
                n_interior += 1;
            }
        }
        let interior = &interior[..n_interior];
        let nodes = self.mesh.element(e);
        let m = p - 1;
        match interior.len() {
            0 => nodes[corner_of(p, l)],
            1 if d == 2 || d == 3 => {
                let dir = interior[0];
                let local = if d == 2 {
                    let other = 1 - dir;
                    2 * other + l[other] / p
                } else {
                    let others = [[1, 2], [0, 2], [0, 1]][dir];
                    4 * dir + l[others[0]] / p + 2 * (l[others[1]] / p)
                };
                let edge =
                    self.topo.element_edges[e * if d == 2 { 4 } else { 12 } + local] as usize;
                let mut start = l;
                start[dir] = 0;
                let start_vertex = nodes[corner_of(p, start)];
                let t = l[dir];
                let pos = if start_vertex == self.topo.edges[edge][0] {
                    t
                } else {
                    p - t
                };
                (self.edge_base + edge * m + pos - 1) as u32
            }
            2 if d == 3 => {
                let fixed = (0..3).find(|k| !interior.contains(k)).unwrap();
                let side = 2 * fixed + l[fixed] / p;
                let f = self.topo.element_faces[e * 6 + side] as usize;
                let (dirs, [ou, ov], swapped) = self.face_frame(e, side);
                let du = l[dirs[0]].abs_diff(ou);
                let dv = l[dirs[1]].abs_diff(ov);
                let (a, b) = if swapped { (dv, du) } else { (du, dv) };
                (self.face_base + f * m * m + (a - 1) + (b - 1) * m) as u32
            }
            _ => {
                let local = (l[0] - 1) + m * ((l[1] - 1) + if d == 3 { m * (l[2] - 1) } else { 0 });
                (self.cell_base + e * m.pow(d as u32) + local) as u32
            }
        }
    }
}

/// Element lattice point of canonical position `pos` (1..p−1) on edge `edge` = local edge
/// `local` of element `e`.
fn edge_lattice(
    mesh: &LinearMesh,
    topo: &Topology,
    p: usize,
    e: usize,
    local: usize,
    pos: usize,
) -> Lattice {
    let nodes = mesh.element(e);
    let edge = topo.element_edges[e * if mesh.dim == 2 { 4 } else { 12 } + local] as usize;
    let (a, b, dir, mut l) = if mesh.dim == 2 {
        let [a, b] = QUAD_SIDES[local];
        let dir = 1 - local / 2;
        let mut l = [0; 3];
        l[local / 2] = (local % 2) * p;
        (a, b, dir, l)
    } else {
        let [a, b] = HEX_EDGES[local];
        let dir = local / 4;
        let q = HEX_VERTEX_PARAMS[a];
        (
            a,
            b,
            dir,
            [q[0] as usize * p, q[1] as usize * p, q[2] as usize * p],
        )
    };
    // The lattice runs along `dir` from the corner with the lower parameter.
    let lower = if HEX_VERTEX_PARAMS[a][dir] < HEX_VERTEX_PARAMS[b][dir] {
        a
    } else {
        b
    };
    let t = if nodes[lower] == topo.edges[edge][0] {
        pos
    } else {
        p - pos
    };
    l[dir] = t;
    l
}

/// Sample `source` at order `p` over `mesh`'s topology.
///
/// Element by element: each element computes its Bézier net once and evaluates the nodes it
/// owns (the same owner and lattice point as [`sample_with`], so the nodes are those of
/// `sample_with` with [`eval_net`], bit for bit), instead of one net per node.
pub fn sample(
    source: &dyn BezierElements,
    mesh: &LinearMesh,
    topo: &Topology,
    p: usize,
) -> HighOrderMesh {
    assert_eq!(source.n_elements(), mesh.n_elements());
    assert!((1..=MAX_ORDER).contains(&p), "order {p} out of range");
    let d = mesh.dim;
    let pf = p as f64;
    let num = Numbering::new(mesh, topo, p);
    let owner = Owners::new(mesh, topo, &num);
    let npe = (p + 1).pow(d as u32);
    let ne = mesh.n_elements();
    let lattice: Vec<Lattice> = (0..npe).map(|n| lattice_point(p, d, n)).collect();
    let mut elements = vec![0u32; ne * npe];
    let mut nodes = vec![[0.0f64; 3]; num.n_nodes()];
    let writer = DisjointWriter::new(&mut nodes);
    elements
        .par_chunks_mut(npe)
        .enumerate()
        .for_each(|(e, ids)| {
            for (id, &l) in ids.iter_mut().zip(&lattice) {
                *id = num.node_id(e, l);
            }
            let mut net = None;
            for (&id, l) in ids.iter().zip(&lattice) {
                if owner.of(id) != e {
                    continue;
                }
                let net = net.get_or_insert_with(|| source.bezier_net(e));
                let x = eval_net(
                    d,
                    net,
                    [l[0] as f64 / pf, l[1] as f64 / pf, l[2] as f64 / pf],
                );
                // SAFETY: every node id has exactly one owner element ([`Owners::of`]), and
                // only that element's task writes it.
                unsafe { writer.write(id as usize, x) };
            }
        });
    let mut ho = HighOrderMesh {
        dim: d,
        order: p,
        nodes,
        elements,
        element_tags: mesh.element_tags.clone(),
        boundary: boundary_facets(mesh, topo, &num),
        boundary_tags: topo.boundary_facet_tags.clone(),
        tag_names: mesh.tag_names.clone(),
        periodic: Vec::new(),
    };
    ho.nodes.shrink_to_fit();
    ho
}

/// Write access to distinct entries of a slice from parallel tasks.
struct DisjointWriter<'a, T> {
    ptr: *mut T,
    len: usize,
    _slice: std::marker::PhantomData<&'a mut [T]>,
}

// SAFETY: the writer only hands out writes to entries; callers of `write` guarantee that no
// entry is written by two tasks, so tasks never touch the same memory.
unsafe impl<T: Send> Sync for DisjointWriter<'_, T> {}

impl<'a, T> DisjointWriter<'a, T> {
    fn new(slice: &'a mut [T]) -> Self {
        DisjointWriter {
            ptr: slice.as_mut_ptr(),
            len: slice.len(),
            _slice: std::marker::PhantomData,
        }
    }

    /// # Safety
    /// No other task may write or read entry `i` while the writer lives.
    unsafe fn write(&self, i: usize, value: T) {
        assert!(i < self.len, "entry {i} out of {}", self.len);
        // SAFETY: in bounds (checked above); exclusive per the caller's guarantee.
        unsafe { self.ptr.add(i).write(value) }
    }
}

/// The element that evaluates each node (as in [`sample_with`]): a vertex's first element, an
/// edge's first element (in `element_edges` order), a face's first element, the element of
/// an interior node.
struct Owners<'a> {
    topo: &'a Topology,
    edge_owner: Vec<u32>,
    /// Nodes per edge, face and element interior.
    per: [usize; 3],
    bases: [usize; 3],
}

impl<'a> Owners<'a> {
    fn new(mesh: &LinearMesh, topo: &'a Topology, num: &Numbering) -> Self {
        let nle = if mesh.dim == 2 { 4 } else { 12 };
        let mut edge_owner = vec![u32::MAX; topo.edges.len()];
        for (slot, &edge) in topo.element_edges.iter().enumerate().rev() {
            edge_owner[edge as usize] = (slot / nle) as u32;
        }
        let m = num.p - 1;
        Owners {
            topo,
            edge_owner,
            per: [m, m * m, m.pow(mesh.dim as u32)],
            bases: [num.edge_base, num.face_base, num.cell_base],
        }
    }

    /// Owner of node `id` (an id of an edge, face or interior node implies p ≥ 2, so the
    /// divisions are by non-zero counts).
    fn of(&self, id: u32) -> usize {
        let id = id as usize;
        let [edge_base, face_base, cell_base] = self.bases;
        if id < edge_base {
            self.topo.elements_at_vertex(id)[0] as usize
        } else if id < face_base {
            self.edge_owner[(id - edge_base) / self.per[0]] as usize
        } else if id < cell_base {
            self.topo.facet_elements[(id - face_base) / self.per[1]][0] as usize
        } else {
            (id - cell_base) / self.per[2]
        }
    }
}

/// Boundary facets in their outward frames: (p+1)^(d−1) node ids each.
pub(crate) fn boundary_facets(mesh: &LinearMesh, topo: &Topology, num: &Numbering) -> Vec<u32> {
    let (d, p) = (mesh.dim, num.p);
    let npf = (p + 1).pow(d as u32 - 1);
    let mut boundary = vec![0u32; topo.boundary_facets.len() * npf];
    boundary
        .par_chunks_mut(npf)
        .zip(&topo.boundary_facets)
        .for_each(|(out, &f)| {
            let f = f as usize;
            let e = topo.facet_elements[f][0] as usize;
            let side = topo.facet_sides[f][0] as usize;
            if d == 2 {
                let [a, b] = QUAD_SIDES[side];
                let (qa, qb) = (HEX_VERTEX_PARAMS[a], HEX_VERTEX_PARAMS[b]);
                for (t, id) in out.iter_mut().enumerate() {
                    let l: Lattice = std::array::from_fn(|k| {
                        if k == 2 {
                            0
                        } else {
                            qa[k] as usize * (p - t) + qb[k] as usize * t
                        }
                    });
                    *id = num.node_id(e, l);
                }
            } else {
                // The stored face cycle is outward for its first element; walk its frame.
                let (dirs, [ou, ov], swapped) = num.face_frame(e, side);
                for b in 0..=p {
                    for a in 0..=p {
                        let (du, dv) = if swapped { (b, a) } else { (a, b) };
                        let mut l = [0; 3];
                        l[side / 2] = (side % 2) * p;
                        l[dirs[0]] = if ou == 0 { du } else { p - du };
                        l[dirs[1]] = if ov == 0 { dv } else { p - dv };
                        out[a + b * (p + 1)] = num.node_id(e, l);
                    }
                }
            }
        });
    boundary
}

/// The order-`p` mesh over `mesh`'s topology with node values from `eval(e, lattice, out)`,
/// which fills `out[i]` for lattice point `lattice[i]` of element `e` (each node is produced
/// once, from one element that contains it). Returns the mesh with `nodes` empty, and the node
/// values. [`sample`] evaluates positions directly; the GPU path first collects
/// (element, lattice point) queries this way and evaluates them in a kernel.
pub fn sample_with<T: Copy + Default + Send + Sync>(
    mesh: &LinearMesh,
    topo: &Topology,
    p: usize,
    eval: impl Fn(usize, &[Lattice], &mut [T]) + Sync,
) -> (HighOrderMesh, Vec<T>) {
    assert!((1..=MAX_ORDER).contains(&p), "order {p} out of range");
    let d = mesh.dim;
    let num = Numbering::new(mesh, topo, p);
    let npe = (p + 1).pow(d as u32);
    let ne = mesh.n_elements();

    // Element connectivity.
    let mut elements = vec![0u32; ne * npe];
    elements
        .par_chunks_mut(npe)
        .enumerate()
        .for_each(|(e, out)| {
            for (n, id) in out.iter_mut().enumerate() {
                *id = num.node_id(e, lattice_point(p, d, n));
            }
        });

    // Node values, entity by entity, each from one owning element.
    let mut nodes = vec![T::default(); num.n_nodes()];
    let (vertex_part, rest) = nodes.split_at_mut(num.edge_base);
    let (edge_part, rest) = rest.split_at_mut(num.face_base - num.edge_base);
    let (face_part, cell_part) = rest.split_at_mut(num.cell_base - num.face_base);
    vertex_part.par_iter_mut().enumerate().for_each(|(v, x)| {
        let e = topo.elements_at_vertex(v)[0] as usize;
        let c = mesh
            .element(e)
            .iter()
            .position(|&u| u as usize == v)
            .unwrap();
        let q = HEX_VERTEX_PARAMS[c];
        let l = [q[0] as usize * p, q[1] as usize * p, q[2] as usize * p];
        eval(e, &[l], std::slice::from_mut(x));
    });
    if p > 1 {
        // First element and local edge of every edge.
        let nle = if d == 2 { 4 } else { 12 };
        let mut edge_owner = vec![u32::MAX; topo.edges.len()];
        for (slot, &edge) in topo.element_edges.iter().enumerate() {
            if edge_owner[edge as usize] == u32::MAX {
                edge_owner[edge as usize] = slot as u32;
            }
        }
        edge_part
            .par_chunks_mut(p - 1)
            .enumerate()
            .for_each(|(edge, out)| {
                let slot = edge_owner[edge] as usize;
                let (e, local) = (slot / nle, slot % nle);
                let lattice: Vec<Lattice> = (0..out.len())
                    .map(|i| edge_lattice(mesh, topo, p, e, local, i + 1))
                    .collect();
                eval(e, &lattice, out);
            });
        if d == 3 {
            let m = p - 1;
            face_part
                .par_chunks_mut(m * m)
                .enumerate()
                .for_each(|(f, out)| {
                    let e = topo.facet_elements[f][0] as usize;
                    let side = topo.facet_sides[f][0] as usize;
                    let (dirs, [ou, ov], swapped) = num.face_frame(e, side);
                    let mut lattice = vec![[0; 3]; m * m];
                    for b in 1..p {
                        for a in 1..p {
                            let (du, dv) = if swapped { (b, a) } else { (a, b) };
                            let mut l = [0; 3];
                            l[side / 2] = (side % 2) * p;
                            l[dirs[0]] = if ou == 0 { du } else { p - du };
                            l[dirs[1]] = if ov == 0 { dv } else { p - dv };
                            lattice[(a - 1) + (b - 1) * m] = l;
                        }
                    }
                    eval(e, &lattice, out);
                });
        }
        let m = p - 1;
        cell_part
            .par_chunks_mut(m.pow(d as u32))
            .enumerate()
            .for_each(|(e, out)| {
                let lattice: Vec<Lattice> = (0..out.len())
                    .map(|n| {
                        let l = lattice_point(m - 1, d, n).map(|c| c + 1);
                        if d == 2 { [l[0], l[1], 0] } else { l }
                    })
                    .collect();
                eval(e, &lattice, out);
            });
    }

    let ho = HighOrderMesh {
        dim: d,
        order: p,
        nodes: Vec::new(),
        elements,
        element_tags: mesh.element_tags.clone(),
        boundary: boundary_facets(mesh, topo, &num),
        boundary_tags: topo.boundary_facet_tags.clone(),
        tag_names: mesh.tag_names.clone(),
        periodic: Vec::new(),
    };
    (ho, nodes)
}
