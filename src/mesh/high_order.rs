//! A conforming high-order quad or hex mesh: nodes, elements and boundary facets of one order,
//! each element's nodes in *lattice order*.
//!
//! An order-p element's nodes sit on the equispaced lattice `(i, j[, k])`, `0 ≤ i, j, k ≤ p`,
//! of the reference element; polyspline keeps them in lattice order (i fastest, then j, then k,
//! [`lattice_index`]). Sampling makes such meshes, the writers emit their nodes in the order of
//! the file's format, and a reader turns a file's back into one.
//!
//! Invariants: `elements` holds `(order+1)^dim` node ids per element and `boundary`
//! `(order+1)^(dim−1)` per facet, in lattice order; `element_tags` is empty or has one tag per
//! element.

use std::collections::BTreeMap;

/// A lattice point of an order-p element (the third entry is 0 in 2D).
pub type Lattice = [usize; 3];

/// Lattice index in polyspline's order (i fastest).
pub fn lattice_index(p: usize, l: Lattice) -> usize {
    l[0] + (p + 1) * (l[1] + (p + 1) * l[2])
}

/// The lattice point of lattice index `n`.
pub fn lattice_point(p: usize, dim: usize, n: usize) -> Lattice {
    let m = p + 1;
    if dim == 2 {
        [n % m, n / m, 0]
    } else {
        [n % m, (n / m) % m, n / (m * m)]
    }
}

/// A conforming high-order quad or hex mesh.
#[derive(Clone, Debug, Default)]
pub struct HighOrderMesh {
    pub dim: usize,
    pub order: usize,
    pub nodes: Vec<[f64; 3]>,
    /// (order+1)^dim node ids per element, lattice order (i fastest).
    pub elements: Vec<u32>,
    /// Region tag per element, or empty.
    pub element_tags: Vec<i32>,
    /// (order+1)^(dim−1) node ids per boundary facet in lattice order of the facet's frame,
    /// oriented with the outward normal (2D: counter-clockwise around the domain).
    pub boundary: Vec<u32>,
    /// Tag per boundary facet (0 = untagged).
    pub boundary_tags: Vec<i32>,
    pub tag_names: BTreeMap<i32, String>,
    /// Periodic pairs of boundary tags with their node pairs (written to MSH `$Periodic`);
    /// node ids stay valid through [`HighOrderMesh::subdivided`].
    pub periodic: Vec<crate::mesh::periodic::PeriodicLink>,
}

impl HighOrderMesh {
    pub fn nodes_per_element(&self) -> usize {
        (self.order + 1).pow(self.dim as u32)
    }
    pub fn nodes_per_facet(&self) -> usize {
        (self.order + 1).pow(self.dim as u32 - 1)
    }
    pub fn n_elements(&self) -> usize {
        self.elements.len() / self.nodes_per_element()
    }
    pub fn n_boundary(&self) -> usize {
        self.boundary.len() / self.nodes_per_facet()
    }
    pub fn element(&self, e: usize) -> &[u32] {
        let n = self.nodes_per_element();
        &self.elements[e * n..(e + 1) * n]
    }

    /// Split every element of order k into k^d linear elements (and the boundary likewise):
    /// a refined linear mesh whose nodes lie on the curved geometry.
    pub fn subdivided(&self) -> HighOrderMesh {
        let p = self.order;
        // Each sub-cell keeps the lattice order of an order-1 element (i fastest), like every
        // element of a HighOrderMesh.
        let split = |cells: &[u32], dim: usize| -> Vec<u32> {
            let per = (p + 1).pow(dim as u32);
            let sub = p.pow(dim as u32);
            let mut out = Vec::with_capacity(cells.len() / per * sub * (1 << dim));
            for c in cells.chunks(per) {
                for s in 0..sub {
                    let base = lattice_point(p - 1, dim, s);
                    for corner in 0..1usize << dim {
                        let l: Lattice = std::array::from_fn(|k| {
                            if k < dim {
                                base[k] + (corner >> k & 1)
                            } else {
                                0
                            }
                        });
                        out.push(c[lattice_index(p, l)]);
                    }
                }
            }
            out
        };
        let rep = |tags: &[i32], n: usize| -> Vec<i32> {
            tags.iter()
                .flat_map(|&t| std::iter::repeat_n(t, n))
                .collect()
        };
        let per_e = p.pow(self.dim as u32);
        let per_f = p.pow(self.dim as u32 - 1);
        HighOrderMesh {
            dim: self.dim,
            order: 1,
            nodes: self.nodes.clone(),
            elements: split(&self.elements, self.dim),
            element_tags: rep(&self.element_tags, per_e),
            boundary: split(&self.boundary, self.dim - 1),
            boundary_tags: rep(&self.boundary_tags, per_f),
            tag_names: self.tag_names.clone(),
            periodic: self.periodic.clone(),
        }
    }
}
