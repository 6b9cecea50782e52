//! Mesh entities of the Bernstein points of quadratic elements: the blend's factors are per
//! entity, so that every element on an entity blends its shared points alike (conformity).

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

/// See [`EntityIds::of`].
pub fn entity_ids(mesh: &LinearMesh, topo: &Topology, e: usize) -> [u32; 27] {
    use crate::mesh::topology::HEX_VERTEX_PARAMS;
    let dim = mesh.dim;
    let n = if dim == 2 { 9 } else { 27 };
    let verts = mesh.element(e);
    let nv = topo.n_vertices as u32;
    let ne = topo.edges.len() as u32;
    let nf = topo.faces.len() as u32;
    let edges_per = if dim == 2 { 4 } else { 12 };
    let mut out = [u32::MAX; 27];
    for (i, slot) in out.iter_mut().enumerate().take(n) {
        let l = [i % 3, (i / 3) % 3, i / 9];
        // The coordinates at ½ (no allocation: this runs for every point of every judged
        // element).
        let (mut ones, mut n_ones) = ([0usize; 3], 0);
        for k in 0..dim {
            if l[k] == 1 {
                ones[n_ones] = k;
                n_ones += 1;
            }
        }
        *slot = match (dim, n_ones) {
            (_, 0) => {
                let c = HEX_VERTEX_PARAMS
                    .iter()
                    .take(1 << dim)
                    .position(|p| (0..dim).all(|k| 2 * p[k] as usize == l[k]))
                    .expect("corner of the lattice");
                verts[c]
            }
            (2, 1) => {
                // Quad edges are its sides: side 2j + s where coordinate j (≠ the edge's
                // direction) equals s.
                let j = 1 - ones[0];
                nv + topo.element_edges[edges_per * e + 2 * j + l[j] / 2]
            }
            (3, 1) => {
                // Hex edge 4k + a + 2b, (a, b) the other two coordinates in axis order.
                let k = ones[0];
                let others = [(k + 1) % 3, (k + 2) % 3];
                let (a, b) = (others[0].min(others[1]), others[0].max(others[1]));
                let local = 4 * k + l[a] / 2 + 2 * (l[b] / 2);
                nv + topo.element_edges[edges_per * e + local]
            }
            (3, 2) => {
                let j = (0..3).find(|&j| l[j] != 1).expect("one coordinate off 1");
                nv + ne + topo.element_faces[6 * e + 2 * j + l[j] / 2]
            }
            _ => nv + ne + nf + e as u32,
        };
    }
    out
}
