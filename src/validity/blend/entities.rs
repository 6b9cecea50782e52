//! Mesh entities of the Bernstein points of quadratic elements: the blend's factors are per
//! entity, so that every element on an entity blends its shared points alike (conformity).

use crate::math::bernstein::net_len;
use crate::mesh::{LinearMesh, Topology};

/// Global ids of the mesh entities of an element's 3^d Bernstein points: vertices first
/// (ids 0..nv), then edges, faces (3D) and cells.
pub struct EntityIds<'a> {
    pub(super) mesh: &'a LinearMesh,
    pub(super) topo: &'a Topology,
}

impl<'a> EntityIds<'a> {
    pub fn new(mesh: &'a LinearMesh, topo: &'a Topology) -> Self {
        EntityIds { mesh, topo }
    }

    /// Number of entities (the length of a λ vector).
    pub fn len(&self) -> usize {
        self.topo.n_vertices
            + self.topo.edges.len()
            + self.topo.faces.len()
            + self.mesh.n_elements()
    }

    /// Whether the mesh has no entity.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Entity ids of the Bernstein points of element `e` (the first 3^d entries).
    pub fn of(&self, e: usize) -> [u32; 27] {
        entity_ids(self.mesh, self.topo, e)
    }
}

/// Where a lattice point of a quadratic element sits: which local entity of the element.
#[derive(Clone, Copy)]
enum Slot {
    /// Local vertex.
    Corner(u8),
    /// Local edge (the element's `element_edges` entry).
    Edge(u8),
    /// Local face of a hex (its `element_faces` entry).
    Face(u8),
    /// The cell itself.
    Cell,
}

/// The [`Slot`] of every lattice point {0, ½, 1}^d (index 9z + 3y + x) of a quad (`dim` 2)
/// or hex (3); unused entries are [`Slot::Cell`]. Depends on nothing but the element type, so
/// it is computed once, not for every point of every judged element.
const fn slots(dim: usize) -> [Slot; 27] {
    use crate::math::reference::HEX_VERTEX_PARAMS;
    let n = net_len(dim);
    let mut out = [Slot::Cell; 27];
    let mut i = 0;
    while i < n {
        let l = [i % 3, (i / 3) % 3, i / 9];
        // The coordinates at ½.
        let (mut ones, mut n_ones) = ([0usize; 3], 0);
        let mut k = 0;
        while k < dim {
            if l[k] == 1 {
                ones[n_ones] = k;
                n_ones += 1;
            }
            k += 1;
        }
        out[i] = match (dim, n_ones) {
            (_, 0) => {
                let mut c = 0;
                loop {
                    let p = HEX_VERTEX_PARAMS[c];
                    let mut all = true;
                    let mut k = 0;
                    while k < dim {
                        all &= 2 * p[k] as usize == l[k];
                        k += 1;
                    }
                    if all {
                        break;
                    }
                    c += 1;
                }
                Slot::Corner(c as u8)
            }
            (2, 1) => {
                // Quad edges are its sides: side 2j + s where coordinate j (≠ the edge's
                // direction) equals s.
                let j = 1 - ones[0];
                Slot::Edge((2 * j + l[j] / 2) as u8)
            }
            (3, 1) => {
                // Hex edge 4k + a + 2b, (a, b) the other two coordinates in axis order.
                let k = ones[0];
                let (o1, o2) = ((k + 1) % 3, (k + 2) % 3);
                let (a, b) = if o1 < o2 { (o1, o2) } else { (o2, o1) };
                Slot::Edge((4 * k + l[a] / 2 + 2 * (l[b] / 2)) as u8)
            }
            (3, 2) => {
                let j = if l[0] != 1 {
                    0
                } else if l[1] != 1 {
                    1
                } else {
                    2
                };
                Slot::Face((2 * j + l[j] / 2) as u8)
            }
            _ => Slot::Cell,
        };
        i += 1;
    }
    out
}

const SLOTS_2D: [Slot; 27] = slots(2);
const SLOTS_3D: [Slot; 27] = slots(3);

/// See [`EntityIds::of`].
pub fn entity_ids(mesh: &LinearMesh, topo: &Topology, e: usize) -> [u32; 27] {
    let dim = mesh.dim;
    let (n, table, edges_per) = if dim == 2 {
        (9, &SLOTS_2D, 4)
    } else {
        (27, &SLOTS_3D, 12)
    };
    let verts = mesh.element(e);
    let nv = topo.n_vertices as u32;
    let ne = topo.edges.len() as u32;
    let nf = topo.faces.len() as u32;
    let mut out = [u32::MAX; 27];
    for (slot, kind) in out.iter_mut().zip(table).take(n) {
        *slot = match *kind {
            Slot::Corner(c) => verts[c as usize],
            Slot::Edge(k) => nv + topo.element_edges[edges_per * e + k as usize],
            Slot::Face(k) => nv + ne + topo.element_faces[6 * e + k as usize],
            Slot::Cell => nv + ne + nf + e as u32,
        };
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::reference::HEX_VERTEX_PARAMS;
    use crate::mesh::generate::{extrude, star_2d};
    use std::collections::HashMap;

    /// The multilinear point of lattice point `i` ({0, ½, 1}^d) of element `e`.
    fn position(mesh: &LinearMesh, e: usize, i: usize) -> [i64; 3] {
        let x = mesh.element_coords(e);
        let l = [i % 3, (i / 3) % 3, i / 9].map(|c| c as f64 / 2.0);
        let mut p = [0.0; 3];
        for (c, pc) in HEX_VERTEX_PARAMS.iter().enumerate().take(1 << mesh.dim) {
            let w: f64 = (0..mesh.dim)
                .map(|k| if pc[k] == 1 { l[k] } else { 1.0 - l[k] })
                .product();
            for k in 0..3 {
                p[k] += w * x[c][k];
            }
        }
        // Rounded, so that the same point reached from two elements compares equal.
        p.map(|c| (c * 1e9).round() as i64)
    }

    /// On meshes whose elements meet in every orientation (a valence-5 star and its
    /// extrusion), the ids are a bijection with the lattice points' positions: every element
    /// on an entity names it at the same point, and no two entities share a point.
    #[test]
    fn ids_name_each_shared_lattice_point_once() {
        let star = star_2d(5);
        for mesh in [star.clone(), extrude(&star, &[0.0, 0.3, 0.7])] {
            let topo = Topology::build(&mesh);
            let ids = EntityIds::new(&mesh, &topo);
            let np = net_len(mesh.dim);
            let (mut at, mut named) = (HashMap::new(), HashMap::new());
            for e in 0..mesh.n_elements() {
                let of = ids.of(e);
                for (i, &id) in of[..np].iter().enumerate() {
                    assert!((id as usize) < ids.len(), "element {e} point {i}");
                    let p = position(&mesh, e, i);
                    assert_eq!(*at.entry(id).or_insert(p), p, "id {id} at two points");
                    assert_eq!(*named.entry(p).or_insert(id), id, "point {p:?} has two ids");
                }
            }
            assert_eq!(at.len(), ids.len(), "every entity is some element's point");
        }
    }
}
