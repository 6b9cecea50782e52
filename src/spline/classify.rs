//! Element classification: spline-compatible or constrained Q2 (`polyspline.md` §1).
//!
//! Input: a [`LinearMesh`] and its [`Topology`]. Output: one [`ElementClass`] per element from
//! the strict vertex/edge rules below; [`crate::spline::stencil`] later demotes elements whose
//! stencil is ambiguous. No PolyFEM quirk is reproduced.
//!
//! * **2D.** A boundary vertex is regular iff it has at most 2 quads, an interior vertex iff it
//!   has exactly 4. A quad is spline-compatible iff its 4 vertices are regular.
//! * **3D.** A hex is spline-compatible iff every interior vertex of it has 8 hexes and 6
//!   edges, all of valence 4; every boundary vertex has at most 4 hexes; every interior edge
//!   has valence 4; every boundary edge has valence at most 2; and if it has a boundary
//!   vertex it also has a boundary edge.
//! * In both: an element touching a non-manifold vertex, edge or facet (see
//!   [`crate::mesh::topology::NonManifold`]) is Q2.

use crate::mesh::LinearMesh;
use crate::mesh::topology::Topology;
use rayon::prelude::*;

/// Why an element is not a spline element. The first failing rule is reported, in the
/// order of the variants.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Q2Reason {
    /// The element touches a non-manifold vertex, edge or facet.
    NonManifold,
    /// 2D: an interior vertex with valence ≠ 4. 3D: an interior vertex without exactly 8
    /// hexes and 6 edges of valence 4.
    IrregularInteriorVertex,
    /// A boundary vertex with more than 2 quads (2D) or more than 4 hexes (3D).
    IrregularBoundaryVertex,
    /// 3D: an interior edge of valence ≠ 4.
    IrregularInteriorEdge,
    /// 3D: a boundary edge of valence > 2.
    IrregularBoundaryEdge,
    /// 3D: the hex has a boundary vertex but no boundary edge.
    BoundaryVertexWithoutBoundaryEdge,
    /// Tied orderings of a stencil slot resolve to different entities, a slot's remaining
    /// sides are not all boundary, or a crossing could not be transported.
    AmbiguousStencil,
    /// Two stencil slots resolve to the same entity (e.g. a ring of fewer than 3 elements).
    RepeatedStencilEntry,
    /// Demoted by the caller: a sharp feature (crease) runs between this element and a
    /// neighbour ([`crate::mesh::features::Features::crease_elements`]), where the map must be
    /// only C⁰, or (3D) along a curved crease on one of its boundary faces
    /// ([`crate::mesh::features::Features::curved_feature_elements`]).
    FeatureCrease,
    /// Demoted by the caller: the spline map of the element was not certified valid on the
    /// initial control points, so it takes its own Lagrange nodes (the input's shape).
    InvalidSplineMap,
    /// Made Q2 by the caller: the element touches a vertex where a boundary grid line kinks
    /// ([`crate::spline::kinks`]), which a C¹ spline cannot follow.
    BoundaryKink,
    /// Made Q2 by the caller: the element touches a regular interior vertex where an interior
    /// grid line turns sharply ([`crate::spline::kinks::interior_kink_elements`]).
    InteriorKink,
    /// Made Q2 by the caller after the fit: a boundary side of the element stayed far from its
    /// smooth targets, much further than a neighbouring side and than a Q2 element would
    /// leave (`pipeline::misfit`).
    BoundaryMisfit,
    /// Made Q2 by graded knot intervals: a knot surface through the element is split there,
    /// because the cells' measured interval ratios along it vary more than one ratio can fit
    /// ([`crate::spline::intervals`]); the map is C⁰ across the split.
    KnotSplit,
}

/// The kind of an element in the poly-spline space.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ElementClass {
    /// Tensor-product quadratic B-spline element with a 3^d stencil.
    Spline,
    /// Constrained triquadratic (biquadratic) Lagrange element, with the reason.
    Q2(Q2Reason),
}

impl ElementClass {
    pub fn is_spline(self) -> bool {
        self == ElementClass::Spline
    }
}

/// Local corner of `element` (its vertex list) holding vertex `v`.
#[inline]
pub(crate) fn corner_of(element: &[u32], v: u32) -> Option<usize> {
    element.iter().position(|&x| x == v)
}

/// Classify every element by the strict rules of the module docs.
pub fn classify(mesh: &LinearMesh, topo: &Topology) -> Vec<ElementClass> {
    assert_eq!(
        mesh.dim, topo.dim,
        "mesh and topology disagree on dimension"
    );
    assert_eq!(
        mesh.n_elements(),
        topo.n_elements,
        "mesh and topology disagree"
    );
    let nv = topo.n_vertices;
    let dim = topo.dim;

    // Non-manifold markers.
    let mut nm_vertex = vec![false; nv];
    for &v in &topo.non_manifold.vertices {
        nm_vertex[v as usize] = true;
    }
    let mut nm_edge = vec![false; topo.edges.len()];
    for &e in &topo.non_manifold.edges {
        nm_edge[e as usize] = true;
    }
    let mut nm_facet = vec![false; topo.n_facets()];
    for &f in &topo.non_manifold.facets {
        nm_facet[f as usize] = true;
    }

    // Per-vertex verdicts (None = regular).
    let vertex_state: Vec<Option<Q2Reason>> = if dim == 2 {
        (0..nv)
            .into_par_iter()
            .map(|v| {
                let n = topo.vertex_valence(v);
                if nm_vertex[v] {
                    Some(Q2Reason::NonManifold)
                } else if topo.vertex_on_boundary[v] {
                    (n > 2).then_some(Q2Reason::IrregularBoundaryVertex)
                } else {
                    (n != 4).then_some(Q2Reason::IrregularInteriorVertex)
                }
            })
            .collect()
    } else {
        let mut n_edges = vec![0u32; nv];
        let mut n_bad = vec![0u32; nv];
        for (e, &[a, b]) in topo.edges.iter().enumerate() {
            for v in [a, b] {
                n_edges[v as usize] += 1;
                if topo.edge_valence[e] != 4 {
                    n_bad[v as usize] += 1;
                }
            }
        }
        (0..nv)
            .into_par_iter()
            .map(|v| {
                let n = topo.vertex_valence(v);
                if nm_vertex[v] {
                    Some(Q2Reason::NonManifold)
                } else if topo.vertex_on_boundary[v] {
                    (n > 4).then_some(Q2Reason::IrregularBoundaryVertex)
                } else {
                    (n != 8 || n_edges[v] != 6 || n_bad[v] != 0)
                        .then_some(Q2Reason::IrregularInteriorVertex)
                }
            })
            .collect()
    };

    (0..topo.n_elements)
        .into_par_iter()
        .map(|e| {
            let mut worst: Option<Q2Reason> = None;
            let mut note = |r: Q2Reason| {
                if worst.is_none_or(|w| r < w) {
                    worst = Some(r);
                }
            };
            for s in 0..topo.sides() {
                if nm_facet[topo.element_facet(e, s) as usize] {
                    note(Q2Reason::NonManifold);
                }
            }
            let mut any_boundary_vertex = false;
            for &v in mesh.element(e) {
                any_boundary_vertex |= topo.vertex_on_boundary[v as usize];
                if let Some(r) = vertex_state[v as usize] {
                    note(r);
                }
            }
            if dim == 3 {
                let mut any_boundary_edge = false;
                for &ed in &topo.element_edges[e * 12..e * 12 + 12] {
                    let ed = ed as usize;
                    let val = topo.edge_valence[ed];
                    if nm_edge[ed] {
                        note(Q2Reason::NonManifold);
                    }
                    if topo.edge_on_boundary[ed] {
                        any_boundary_edge = true;
                        if val > 2 {
                            note(Q2Reason::IrregularBoundaryEdge);
                        }
                    } else if val != 4 {
                        note(Q2Reason::IrregularInteriorEdge);
                    }
                }
                if any_boundary_vertex && !any_boundary_edge {
                    note(Q2Reason::BoundaryVertexWithoutBoundaryEdge);
                }
            }
            match worst {
                None => ElementClass::Spline,
                Some(r) => ElementClass::Q2(r),
            }
        })
        .collect()
}
