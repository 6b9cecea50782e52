//! Constrained Q2 elements (`polyspline.md` §3).
//!
//! Input: the element classes, the spline elements' resolved stencils (control point ids) and
//! knot cases. Output: the 3^d local Lagrange nodes (positions {0, ½, 1}^d, x fastest) of every
//! Q2 element, as control point ids (own nodes) or constraint rows (constrained nodes).
//!
//! * A node at a vertex, edge midpoint or face centre is **constrained** when some spline
//!   element contains that entity; its weights are the spline basis of one such element S
//!   evaluated at the entity's parameter point in S's frame (found by vertex correspondence),
//!   summed per control point (§3.3, "simpler equivalent"). In debug builds every other spline
//!   element containing the entity is checked to give the same row.
//! * Otherwise the node is an **own** control point, shared by entity between the Q2 elements
//!   that contain it, starting at the vertex, edge midpoint or face vertex average.
//! * The centre node is always a fresh own control point at the element's vertex average.
//!
//! Own control points are numbered after the spline ones: vertices, edges, faces (3D) in id
//! order, then centres in element order. Constraint rows are numbered vertices, edges, faces.

use super::ControlPoint;
use super::classify::{ElementClass, corner_of};
use super::knots::Op1d;
use crate::math::bernstein::net_len;
use crate::math::reference::{HEX_EDGES, HEX_VERTEX_PARAMS};
use crate::mesh::LinearMesh;
use crate::mesh::topology::{NONE, Topology};
use rayon::prelude::*;

/// Where a local Lagrange node of an element sits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LocalEntity {
    Corner(u8),
    /// 3D: local hex edge (index into `HEX_EDGES`).
    Edge(u8),
    /// Local side: an edge of a quad, a face of a hex.
    Side(u8),
    Centre,
}

/// The local entity of each tensor position a ∈ {0,1,2}^d (index 9z + 3y + x).
pub(crate) fn local_entities(dim: usize) -> Vec<LocalEntity> {
    let n = net_len(dim);
    (0..n)
        .map(|i| {
            let a = [i % 3, (i / 3) % 3, i / 9];
            let fixed: Vec<usize> = (0..dim).filter(|&k| a[k] != 1).collect();
            let on = |c: usize| {
                fixed
                    .iter()
                    .all(|&k| 2 * HEX_VERTEX_PARAMS[c][k] as usize == a[k])
            };
            match (dim, fixed.len()) {
                (_, 0) => LocalEntity::Centre,
                (2, 2) | (3, 3) => {
                    LocalEntity::Corner((0..1 << dim).find(|&c| on(c)).expect("corner") as u8)
                }
                (3, 2) => LocalEntity::Edge(
                    HEX_EDGES
                        .iter()
                        .position(|&[p, q]| on(p) && on(q))
                        .expect("edge") as u8,
                ),
                _ => LocalEntity::Side((2 * fixed[0] + a[fixed[0]] / 2) as u8),
            }
        })
        .collect()
}

/// Global entity of a Q2 node other than the centre.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Node {
    Vertex(u32),
    Edge(u32),
    Face(u32),
}

pub(crate) struct Q2Output {
    /// New own control points in numbering order.
    pub keys: Vec<ControlPoint>,
    pub constraint_offsets: Vec<u32>,
    pub constraint_entries: Vec<(u32, f64)>,
}

/// Weights in the zero-drop test: only exact zeros (basis factors at 0, ½, 1 are exact).
const ZERO_WEIGHT: f64 = 0.0;

/// Agreement required between the rows of different spline elements at one entity.
const WITNESS_TOL: f64 = 1e-12;

pub(crate) struct Q2Builder<'a> {
    pub mesh: &'a LinearMesh,
    pub topo: &'a Topology,
    pub classes: &'a [ElementClass],
    pub ops: &'a [[Op1d; 3]],
    /// Knot weights of each element (`None`: uniform knots).
    pub knot_weights: Option<&'a [[[f64; 2]; 3]]>,
    /// 3^d local nodes per element; for spline elements the stencil's control point ids.
    pub local_nodes: &'a mut [u32],
    /// Number of spline control points already numbered.
    pub n_spline_cp: usize,
}

impl Q2Builder<'_> {
    fn is_spline(&self, e: u32) -> bool {
        e != NONE && self.classes[e as usize].is_spline()
    }

    fn vertices(&self, n: Node) -> ([u32; 4], usize) {
        let topo = self.topo;
        match n {
            Node::Vertex(v) => ([v, 0, 0, 0], 1),
            Node::Edge(e) => {
                let [a, b] = topo.edges[e as usize];
                ([a, b, 0, 0], 2)
            }
            Node::Face(f) => (topo.faces[f as usize], 4),
        }
    }

    /// Elements containing the entity (all of them, spline or not), passed to `f` until it
    /// returns true.
    fn find_element(&self, n: Node, mut f: impl FnMut(u32) -> bool) -> Option<u32> {
        let topo = self.topo;
        match n {
            Node::Vertex(v) => topo
                .elements_at_vertex(v as usize)
                .iter()
                .copied()
                .find(|&x| f(x)),
            Node::Edge(ed) if topo.dim == 3 => {
                let a = topo.edges[ed as usize][0] as usize;
                topo.elements_at_vertex(a).iter().copied().find(|&x| {
                    topo.element_edges[x as usize * 12..x as usize * 12 + 12].contains(&ed) && f(x)
                })
            }
            Node::Edge(f2) | Node::Face(f2) => topo.facet_elements[f2 as usize]
                .iter()
                .copied()
                .find(|&x| x != NONE && f(x)),
        }
    }

    fn witness(&self, n: Node) -> u32 {
        self.find_element(n, |x| self.is_spline(x)).unwrap_or(NONE)
    }

    /// Constraint row of entity `n` from spline element `s`, sorted by column.
    fn row(&self, n: Node, s: u32, out: &mut Vec<(u32, f64)>) {
        out.clear();
        let dim = self.topo.dim;
        let (vs, nvs) = self.vertices(n);
        let sv = self.mesh.element(s as usize);
        let mut xi = [0.0f64; 3];
        for &v in &vs[..nvs] {
            let c = corner_of(sv, v).expect("entity vertex belongs to the witness element");
            for k in 0..dim {
                xi[k] += HEX_VERTEX_PARAMS[c][k] as f64 / nvs as f64;
            }
        }
        let ops = self.ops[s as usize];
        let w = self.knot_weights.map(|w| w[s as usize]);
        let b: [[f64; 3]; 3] = std::array::from_fn(|k| {
            if k < dim {
                match w {
                    Some(w) => ops[k].basis_graded(xi[k], w[k]),
                    None => ops[k].basis(xi[k]),
                }
            } else {
                [1.0, 0.0, 0.0]
            }
        });
        let nl = net_len(dim);
        let nodes = &self.local_nodes[s as usize * nl..(s as usize + 1) * nl];
        for (slot, &g) in nodes.iter().enumerate() {
            let w = b[0][slot % 3] * b[1][(slot / 3) % 3] * b[2][slot / 9];
            if w.abs() > ZERO_WEIGHT {
                out.push((g, w));
            }
        }
        out.sort_unstable_by_key(|p| p.0);
        let mut merged: Vec<(u32, f64)> = Vec::with_capacity(out.len());
        for &(g, w) in out.iter() {
            match merged.last_mut() {
                Some(last) if last.0 == g => last.1 += w,
                _ => merged.push((g, w)),
            }
        }
        *out = merged;
    }

    /// Debug check: every spline element containing `n` gives the same row.
    fn check_witnesses(&self, n: Node, row: &[(u32, f64)]) {
        let mut other = Vec::new();
        self.find_element(n, |x| {
            if self.is_spline(x) {
                self.row(n, x, &mut other);
                let same = other.len() == row.len()
                    && other
                        .iter()
                        .zip(row)
                        .all(|(a, b)| a.0 == b.0 && (a.1 - b.1).abs() < WITNESS_TOL);
                assert!(
                    same,
                    "spline elements disagree at {n:?}: {row:?} vs {other:?} (element {x})"
                );
            }
            false
        });
    }

    pub fn build(self) -> Q2Output {
        let topo = self.topo;
        let dim = topo.dim;
        let ne = topo.n_elements;
        let nl = net_len(dim);
        let local = local_entities(dim);

        // Entities used by Q2 elements.
        let mut need_v = vec![false; topo.n_vertices];
        let mut need_e = vec![false; topo.edges.len()];
        let mut need_f = vec![false; topo.faces.len()];
        let q2: Vec<usize> = (0..ne).filter(|&e| !self.classes[e].is_spline()).collect();
        for &e in &q2 {
            for &v in self.mesh.element(e) {
                need_v[v as usize] = true;
            }
            let ne_loc = if dim == 2 { 4 } else { 12 };
            for &ed in &topo.element_edges[e * ne_loc..(e + 1) * ne_loc] {
                need_e[ed as usize] = true;
            }
            if dim == 3 {
                for &f in &topo.element_faces[e * 6..e * 6 + 6] {
                    need_f[f as usize] = true;
                }
            }
        }

        // Witness spline element of each needed entity (NONE: own node).
        let witnesses = |need: &[bool], make: fn(u32) -> Node| -> Vec<u32> {
            need.par_iter()
                .enumerate()
                .map(|(i, &n)| {
                    if n {
                        self.witness(make(i as u32))
                    } else {
                        NONE
                    }
                })
                .collect()
        };
        let wv = witnesses(&need_v, Node::Vertex);
        let we = witnesses(&need_e, Node::Edge);
        let wf = witnesses(&need_f, Node::Face);

        // Own nodes first (control point ids), then constraint rows.
        let mut keys = Vec::new();
        let mut next = self.n_spline_cp as u32;
        let mut own = |need: &[bool], w: &[u32], key: fn(u32) -> ControlPoint| -> Vec<u32> {
            let mut ids = vec![NONE; need.len()];
            for i in 0..need.len() {
                if need[i] && w[i] == NONE {
                    ids[i] = next;
                    keys.push(key(i as u32));
                    next += 1;
                }
            }
            ids
        };
        let mut id_v = own(&need_v, &wv, ControlPoint::Q2Vertex);
        let mut id_e = own(&need_e, &we, ControlPoint::Q2Edge);
        let mut id_f = own(&need_f, &wf, ControlPoint::Q2Face);
        let mut centre = vec![NONE; ne];
        for &e in &q2 {
            centre[e] = next;
            keys.push(ControlPoint::Q2Centre(e as u32));
            next += 1;
        }
        let n_control = next as usize;

        let mut constraint_offsets = vec![0u32];
        let mut constraint_entries = Vec::new();
        let mut row = Vec::new();
        let mut n_con = 0u32;
        let mut constrain = |ids: &mut [u32], w: &[u32], make: fn(u32) -> Node| {
            for i in 0..ids.len() {
                if w[i] != NONE {
                    let n = make(i as u32);
                    self.row(n, w[i], &mut row);
                    if cfg!(debug_assertions) {
                        self.check_witnesses(n, &row);
                    }
                    constraint_entries.extend_from_slice(&row);
                    constraint_offsets.push(constraint_entries.len() as u32);
                    ids[i] = n_control as u32 + n_con;
                    n_con += 1;
                }
            }
        };
        constrain(&mut id_v, &wv, Node::Vertex);
        constrain(&mut id_e, &we, Node::Edge);
        constrain(&mut id_f, &wf, Node::Face);

        // Local nodes of the Q2 elements.
        for &e in &q2 {
            let verts = self.mesh.element(e);
            let out = &mut self.local_nodes[e * nl..(e + 1) * nl];
            for (slot, le) in local.iter().enumerate() {
                out[slot] = match *le {
                    LocalEntity::Corner(c) => id_v[verts[c as usize] as usize],
                    LocalEntity::Edge(l) => id_e[topo.element_edges[e * 12 + l as usize] as usize],
                    LocalEntity::Side(s) => {
                        let f = topo.element_facet(e, s as usize) as usize;
                        if dim == 2 { id_e[f] } else { id_f[f] }
                    }
                    LocalEntity::Centre => centre[e],
                };
                debug_assert_ne!(out[slot], NONE);
            }
        }
        Q2Output {
            keys,
            constraint_offsets,
            constraint_entries,
        }
    }
}
