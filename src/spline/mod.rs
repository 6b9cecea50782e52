//! The quadratic poly-spline space of a quad or hex mesh: PolyFEM's construction, used by the
//! paper "Isogeometric High Order Mesh Generation" (each step below is documented in its
//! submodule).
//!
//! Input: a [`LinearMesh`] (quads or hexes) and its [`Topology`]. Output: a [`SplineSpace`]:
//! global control points `C` at their initial positions and, for every element, the Bézier
//! extraction `B_e = E_e · C` of its 3^d Bernstein control points (see [`extraction`]).
//!
//! Construction, linear in the mesh size:
//! 1. [`classify`]: each element is a spline element or a constrained Q2 element (§1, strict
//!    rule of the design's recommendation).
//! 2. [`stencil`]: every spline element's 3^d stencil is resolved topologically to entities
//!    (`Cell`, `BFace`, `BEdge`, `BVertex`); elements with an ambiguous or repeated stencil
//!    are demoted to Q2. Each direction's knot case follows from whether the element has a
//!    neighbour on that side ([`knots`]); its knot intervals are uniform or graded
//!    ([`intervals`]: one log-ratio per knot surface, passed in as weights).
//! 3. Control points are created once per referenced entity and numbered by kind then id:
//!    cells, boundary faces, boundary edges, boundary vertices; they start at vertex averages.
//! 4. [`q2`]: the Q2 elements' own nodes (numbered after the spline control points) and the
//!    constraint rows of their nodes on spline elements.
//!
//! Invariants of the result:
//! * the basis of a spline element is non-negative and sums to 1; the map is C¹ across
//!   spline/spline facets and C⁰ across every facet;
//! * the initial map reproduces affine images of uniform grids (of any tensor-product grid
//!   with graded knot intervals), and any single element's
//!   bilinear/trilinear map when it has no spline neighbours;
//! * the result depends only on the topology and coordinates, not on the elements' local
//!   vertex order (up to the matching reparametrisation of each element).

pub mod classify;
pub mod eval;
pub mod extraction;
pub mod intervals;
pub mod kinks;
pub mod knots;
pub mod q2;
pub mod seam;
pub mod stencil;

use crate::math::BezierNet;
pub use classify::{ElementClass, Q2Reason};
pub use extraction::{ElementRows, Extraction, ExtractionCsr};
pub use intervals::{
    AUTO_GRADED_SHARE, AUTO_MIN_LOG_RATIO, KnotIntervals, KnotParams, KnotSurfaceInfo, KnotSurvey,
    KnotWeights, Knots,
};
pub use knots::Op1d;
pub use stencil::Entity;

use crate::math::bernstein::net_len;
use crate::mesh::LinearMesh;
use crate::mesh::topology::{NONE, Topology};
use rayon::prelude::*;

/// The mesh entity a global control point belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
pub enum ControlPoint {
    /// Spline cell node of an element (also of Q2 elements next to spline elements).
    Cell(u32),
    /// Spline node of a boundary face (3D).
    BFace(u32),
    /// Spline node of a boundary edge.
    BEdge(u32),
    /// Spline node of a boundary vertex.
    BVertex(u32),
    /// Own Lagrange node of Q2 elements at a vertex.
    Q2Vertex(u32),
    /// Own Lagrange node of Q2 elements at an edge midpoint.
    Q2Edge(u32),
    /// Own Lagrange node of Q2 elements at a face centre (3D).
    Q2Face(u32),
    /// Own Lagrange centre node of one Q2 element.
    Q2Centre(u32),
}

impl ControlPoint {
    /// True for the spline control points (referenced by spline stencils).
    pub fn is_spline(self) -> bool {
        matches!(
            self,
            ControlPoint::Cell(_)
                | ControlPoint::BFace(_)
                | ControlPoint::BEdge(_)
                | ControlPoint::BVertex(_)
        )
    }
}

/// A quadratic poly-spline space in Bézier-extracted form.
#[derive(Clone, Debug, Default)]
pub struct SplineSpace {
    /// 2 or 3.
    pub dim: usize,
    /// Global control points (z = 0 in 2D). Fitting moves these.
    pub control_points: Vec<[f64; 3]>,
    /// The entity of each control point (parallel to `control_points`).
    pub control_point_keys: Vec<ControlPoint>,
    /// Per element: `B_e = E_e · C`.
    pub extraction: Extraction,
    /// Class of each element.
    pub classes: Vec<ElementClass>,
}

impl SplineSpace {
    /// Build the space of `mesh` with topology `topo` (built from the same mesh).
    ///
    /// Panics if the mesh has 2^30 or more vertices, edges, faces or elements (the packed
    /// stencil representation's limit), or if `topo` does not belong to `mesh`.
    pub fn build(mesh: &LinearMesh, topo: &Topology) -> SplineSpace {
        Self::build_with_demoted(mesh, topo, &[])
    }

    /// [`SplineSpace::build`], with the elements marked in `demote` (indexed by element; an
    /// empty slice demotes none) made constrained Q2 elements
    /// ([`Q2Reason::InvalidSplineMap`]). Their spline neighbours keep their stencils.
    pub fn build_with_demoted(mesh: &LinearMesh, topo: &Topology, demote: &[bool]) -> SplineSpace {
        Self::build_with_q2(mesh, topo, &[(demote, Q2Reason::InvalidSplineMap)])
    }

    /// [`SplineSpace::build`], with the spline elements marked in each `(marks, reason)` pair
    /// (indexed by element; empty slices mark none) made constrained Q2 elements for that
    /// reason, the first pair that marks an element deciding. Their spline neighbours keep
    /// their stencils.
    pub fn build_with_q2(
        mesh: &LinearMesh,
        topo: &Topology,
        demote: &[(&[bool], Q2Reason)],
    ) -> SplineSpace {
        Self::build_with_knots(mesh, topo, demote, None)
    }

    /// The knot intervals of `mesh` for `params` ([`intervals::knot_weights`]; no weights for
    /// uniform knots): the weights to pass to [`SplineSpace::build_with_knots`], with the
    /// elements to make Q2 ([`Q2Reason::KnotSplit`]) where knot surfaces are split.
    pub fn knot_weights(mesh: &LinearMesh, topo: &Topology, params: &KnotParams) -> Knots {
        if params.intervals != KnotIntervals::Graded {
            return Knots::default();
        }
        intervals::knot_weights_from(Self::knot_survey(mesh, topo), topo, params)
    }

    /// The measured ratios and ties of `mesh`'s knot surfaces ([`intervals::survey`]), for
    /// [`intervals::knot_weights_from`].
    pub fn knot_survey(mesh: &LinearMesh, topo: &Topology) -> intervals::KnotSurvey {
        let spline: Vec<bool> = classify::classify(mesh, topo)
            .iter()
            .map(|c| c.is_spline())
            .collect();
        intervals::survey(mesh, topo, &spline)
    }

    /// The space of `mesh` with the knot intervals of `params` (the split elements made Q2),
    /// and the figures of its knot surfaces; [`SplineSpace::build`] for uniform knots.
    pub fn build_for_knots(
        mesh: &LinearMesh,
        topo: &Topology,
        params: &KnotParams,
    ) -> Result<(SplineSpace, KnotSurfaceInfo), crate::params::ParamError> {
        params.check()?;
        let knots = Self::knot_weights(mesh, topo, params);
        let space = Self::build_with_knots(
            mesh,
            topo,
            &[(&knots.split, Q2Reason::KnotSplit)],
            knots.weights.as_deref(),
        );
        Ok((space, knots.info))
    }

    /// [`SplineSpace::build_with_q2`] with non-uniform knot intervals: `weights` (one entry
    /// per element, from [`SplineSpace::knot_weights`]) or uniform knots (`None`).
    pub fn build_with_knots(
        mesh: &LinearMesh,
        topo: &Topology,
        demote: &[(&[bool], Q2Reason)],
        weights: Option<&[KnotWeights]>,
    ) -> SplineSpace {
        if let Some(w) = weights {
            assert_eq!(
                w.len(),
                topo.n_elements,
                "one knot weight entry per element"
            );
        }
        let dim = topo.dim;
        assert!(dim == 2 || dim == 3, "quad or hex meshes only");
        let ne = topo.n_elements;
        let nl = net_len(dim);
        for count in [ne, topo.n_vertices, topo.edges.len(), topo.faces.len()] {
            assert!(
                count < stencil::MAX_ENTITIES,
                "mesh too large for the spline space"
            );
        }

        // 1–2. Classes and stencils.
        let mut classes = classify::classify(mesh, topo);
        for &(marks, reason) in demote {
            for (c, &d) in classes.iter_mut().zip(marks) {
                if d && c.is_spline() {
                    *c = ElementClass::Q2(reason);
                }
            }
        }
        let mut local_nodes = vec![NONE; ne * nl];
        {
            let transport = stencil::transport_table(mesh, topo);
            let resolver = stencil::StencilResolver {
                mesh,
                topo,
                transport: &transport,
            };
            local_nodes
                .par_chunks_mut(nl)
                .zip(classes.par_iter_mut())
                .enumerate()
                .for_each(|(e, (out, class))| {
                    if class.is_spline()
                        && let Err(r) = resolver.stencil(e, out)
                    {
                        *class = ElementClass::Q2(r);
                        out.fill(NONE);
                    }
                });
        }
        let ops: Vec<[Op1d; 3]> = (0..ne)
            .into_par_iter()
            .map(|e| {
                if classes[e].is_spline() {
                    std::array::from_fn(|k| {
                        if k < dim {
                            Op1d::spline(
                                topo.neighbor(e, 2 * k) == NONE,
                                topo.neighbor(e, 2 * k + 1) == NONE,
                            )
                        } else {
                            Op1d::BothEnds
                        }
                    })
                } else {
                    [Op1d::Lagrange; 3]
                }
            })
            .collect();

        // 3. Spline control points: mark referenced entities, number by kind then id.
        let mut used = [
            vec![false; ne],
            vec![false; topo.faces.len()],
            vec![false; topo.edges.len()],
            vec![false; topo.n_vertices],
        ];
        for &p in &local_nodes {
            if p != NONE {
                let (k, id) = kind_id(stencil::Entity::unpack(p));
                used[k][id as usize] = true;
            }
        }
        let mut keys = Vec::new();
        let mut ids: [Vec<u32>; 4] = Default::default();
        for (k, used_k) in used.iter().enumerate() {
            ids[k] = vec![NONE; used_k.len()];
            for (i, &u) in used_k.iter().enumerate() {
                if u {
                    ids[k][i] = keys.len() as u32;
                    keys.push(match k {
                        0 => ControlPoint::Cell(i as u32),
                        1 => ControlPoint::BFace(i as u32),
                        2 => ControlPoint::BEdge(i as u32),
                        _ => ControlPoint::BVertex(i as u32),
                    });
                }
            }
        }
        drop(used);
        local_nodes.par_iter_mut().for_each(|p| {
            if *p != NONE {
                let (k, id) = kind_id(stencil::Entity::unpack(*p));
                *p = ids[k][id as usize];
            }
        });
        drop(ids);
        let n_spline_cp = keys.len();

        // 4. Q2 elements.
        let q2 = q2::Q2Builder {
            mesh,
            topo,
            classes: &classes,
            ops: &ops,
            knot_weights: weights,
            local_nodes: &mut local_nodes,
            n_spline_cp,
        }
        .build();
        keys.extend(q2.keys);
        let n_control = keys.len();

        let control_points = keys
            .par_iter()
            .map(|&k| initial_position(mesh, topo, k))
            .collect();

        SplineSpace {
            dim,
            control_points,
            control_point_keys: keys,
            extraction: Extraction {
                dim,
                n_control,
                ops,
                knot_weights: weights.map_or_else(Vec::new, <[_]>::to_vec),
                local_nodes,
                constraint_offsets: q2.constraint_offsets,
                constraint_entries: q2.constraint_entries,
                shift_of: Vec::new(),
                node_shifts: Vec::new(),
                frame_of: Vec::new(),
                frames: Vec::new(),
            },
            classes,
        }
    }

    pub fn n_elements(&self) -> usize {
        self.classes.len()
    }

    pub fn is_spline(&self, e: usize) -> bool {
        self.classes[e].is_spline()
    }

    pub fn n_spline_elements(&self) -> usize {
        self.classes.iter().filter(|c| c.is_spline()).count()
    }

    pub fn n_q2_elements(&self) -> usize {
        self.n_elements() - self.n_spline_elements()
    }

    pub fn n_control_points(&self) -> usize {
        self.control_points.len()
    }

    /// Control points referenced by spline stencils (they come first in the numbering).
    pub fn n_spline_control_points(&self) -> usize {
        self.control_point_keys
            .iter()
            .take_while(|k| k.is_spline())
            .count()
    }

    /// The 3^d Bernstein control points of element `e` (x fastest; a quad uses 9).
    pub fn element_bezier(&self, e: usize) -> BezierNet {
        eval::bezier_net(&self.extraction, e, &self.control_points)
    }

    /// The Bernstein control points of element `e` for other control point positions.
    pub fn element_bezier_with(&self, e: usize, control_points: &[[f64; 3]]) -> BezierNet {
        eval::bezier_net(&self.extraction, e, control_points)
    }

    /// The map of element `e` at `u` ∈ `[0,1]`^d (`u[2]` ignored in 2D).
    pub fn eval(&self, e: usize, u: [f64; 3]) -> [f64; 3] {
        eval::eval_net(self.dim, &self.element_bezier(e), u)
    }

    /// The map of element `e` at `u` and its parametric derivatives `d[k] = ∂x/∂u_k`.
    pub fn eval_with_derivatives(&self, e: usize, u: [f64; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
        eval::eval_net_with_derivatives(self.dim, &self.element_bezier(e), u)
    }

    /// The non-zero global basis functions of element `e` at `u`, as (control point, value).
    pub fn basis_at(&self, e: usize, u: [f64; 3], out: &mut Vec<(u32, f64)>) {
        eval::basis_at(&self.extraction, e, u, out)
    }
}

impl crate::math::BezierElements for SplineSpace {
    fn dim(&self) -> usize {
        self.dim
    }
    fn n_elements(&self) -> usize {
        self.classes.len()
    }
    fn bezier_net(&self, e: usize) -> BezierNet {
        self.element_bezier(e)
    }
}

fn kind_id(e: stencil::Entity) -> (usize, u32) {
    match e {
        stencil::Entity::Cell(i) => (0, i),
        stencil::Entity::BFace(i) => (1, i),
        stencil::Entity::BEdge(i) => (2, i),
        stencil::Entity::BVertex(i) => (3, i),
    }
}

fn average(mesh: &LinearMesh, vs: &[u32]) -> [f64; 3] {
    let mut x = [0.0; 3];
    for &v in vs {
        let p = mesh.coords[v as usize];
        for i in 0..3 {
            x[i] += p[i];
        }
    }
    x.map(|c| c / vs.len() as f64)
}

/// Initial position of a control point: the vertex average of its entity (§2.1, §3.2).
fn initial_position(mesh: &LinearMesh, topo: &Topology, key: ControlPoint) -> [f64; 3] {
    use ControlPoint::*;
    match key {
        Cell(e) | Q2Centre(e) => average(mesh, mesh.element(e as usize)),
        BFace(f) | Q2Face(f) => average(mesh, &topo.faces[f as usize]),
        BEdge(e) | Q2Edge(e) => average(mesh, &topo.edges[e as usize]),
        BVertex(v) | Q2Vertex(v) => mesh.coords[v as usize],
    }
}
