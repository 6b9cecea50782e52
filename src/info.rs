//! The `info` report: what a linear mesh is made of, in numbers.
//!
//! Input: a [`LinearMesh`] and its [`Topology`]. Output: a [`MeshInfo`] that serialises to the
//! JSON of `polyspline info --json` and prints as an aligned table.

use crate::mesh::{LinearMesh, Topology};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt;

/// Summary of a linear mesh.
#[derive(Clone, Debug, Serialize)]
pub struct MeshInfo {
    pub dimension: usize,
    /// "quadrilateral" or "hexahedron".
    pub element_kind: &'static str,
    pub elements: usize,
    pub vertices: usize,
    pub edges: usize,
    /// 3D only (0 in 2D).
    pub faces: usize,
    pub boundary_facets: usize,
    pub boundary_vertices: usize,
    /// Boundary facets per tag (key 0 = untagged), with names where the file gives them.
    pub boundary_tags: BTreeMap<i32, usize>,
    pub tag_names: BTreeMap<i32, String>,
    /// Elements per region tag, when the file tags elements.
    pub element_tags: BTreeMap<i32, usize>,
    pub components: usize,
    /// Elements re-ordered to positive orientation on input.
    pub reoriented: usize,
    /// Tangled or degenerate elements kept with `--allow-invalid`.
    pub invalid_elements: usize,
    /// 2D: interior vertices with valence ≠ 4. 3D: edges not both of whose end points are on
    /// the boundary, with valence ≠ 4.
    pub irregular: usize,
    /// What `irregular` counts, in words.
    pub irregular_kind: &'static str,
    /// Largest number of elements around a vertex.
    pub max_vertex_valence: usize,
    /// 3D: largest number of hexes around an edge.
    pub max_edge_valence: usize,
    pub bounding_box: [[f64; 3]; 2],
    /// Minimum scaled corner Jacobian of the linear mesh (1 = square/cube corners).
    pub min_scaled_jacobian: f64,
    pub min_scaled_jacobian_element: usize,
    pub non_manifold_facets: usize,
    pub non_manifold_edges: usize,
    pub non_manifold_vertices: usize,
    /// Elements on the same vertex set as an earlier element (`curve` refuses them).
    pub duplicate_elements: usize,
    pub unused_vertices: usize,
    pub interior_tagged_facets: usize,
    pub unmatched_tagged_facets: usize,
    /// Cells of the file that are neither elements nor boundary tags.
    pub ignored_cells: BTreeMap<String, usize>,
    /// Poly-spline space: elements with a spline stencil, constrained Q2 elements, control
    /// points (spline control points and own Q2 nodes); with translation pairs, of the space on
    /// the glued mesh ([`MeshInfo::set_spline_space`]).
    pub spline_elements: usize,
    pub q2_elements: usize,
    pub control_points: usize,
    /// Q2 elements by reason.
    pub q2_reasons: BTreeMap<String, usize>,
    /// Sharp features, when detected (`docs/features.md`); `crease_elements` become
    /// `feature_crease` Q2 elements in `curve` (not counted in `q2_reasons`).
    pub features: Option<crate::mesh::features::FeatureSummary>,
    /// Periodic pairs (`--periodic` and the file's `$Periodic`) with their transforms.
    pub periodic: Vec<crate::mesh::periodic::PeriodicSummary>,
    /// With graded knot intervals (`--knot-intervals graded`): the knot surfaces; the spline
    /// space's counts above then include the elements made Q2 where surfaces are split.
    pub knot_surfaces: Option<crate::spline::KnotSurfaceInfo>,
}

/// Q2 elements of `space` by reason.
fn q2_reasons(space: &crate::spline::SplineSpace) -> BTreeMap<String, usize> {
    let mut q2_reasons = BTreeMap::new();
    for c in &space.classes {
        if let crate::spline::ElementClass::Q2(r) = c {
            let name = serde_json::to_value(r)
                .ok()
                .and_then(|v| v.as_str().map(str::to_owned))
                .unwrap_or_default();
            *q2_reasons.entry(name).or_insert(0) += 1;
        }
    }
    q2_reasons
}

impl MeshInfo {
    pub fn new(mesh: &LinearMesh, topo: &Topology) -> MeshInfo {
        let space = crate::spline::SplineSpace::build(mesh, topo);
        let q2_reasons = q2_reasons(&space);
        let mut boundary_tags = BTreeMap::new();
        for &t in &topo.boundary_facet_tags {
            *boundary_tags.entry(t).or_insert(0) += 1;
        }
        let mut element_tags = BTreeMap::new();
        for &t in &mesh.element_tags {
            *element_tags.entry(t).or_insert(0) += 1;
        }
        let (lo, hi) = mesh.bounding_box();
        let (msj, msj_e) = mesh.min_scaled_jacobian().unwrap_or((f64::NAN, 0));
        MeshInfo {
            dimension: mesh.dim,
            element_kind: if mesh.dim == 2 {
                "quadrilateral"
            } else {
                "hexahedron"
            },
            elements: mesh.n_elements(),
            vertices: mesh.n_vertices(),
            edges: topo.edges.len(),
            faces: topo.faces.len(),
            boundary_facets: topo.boundary_facets.len(),
            boundary_vertices: topo.vertex_on_boundary.iter().filter(|&&b| b).count(),
            boundary_tags,
            tag_names: mesh.tag_names.clone(),
            element_tags,
            components: topo.n_components,
            reoriented: mesh.reoriented,
            invalid_elements: mesh.invalid_elements.len(),
            irregular: topo.irregular_count(),
            irregular_kind: if mesh.dim == 2 {
                "interior vertices with valence != 4"
            } else {
                "interior edges with valence != 4"
            },
            max_vertex_valence: (0..topo.n_vertices)
                .map(|v| topo.vertex_valence(v))
                .max()
                .unwrap_or(0),
            max_edge_valence: if mesh.dim == 3 {
                topo.edge_valence.iter().copied().max().unwrap_or(0) as usize
            } else {
                0
            },
            bounding_box: [lo, hi],
            min_scaled_jacobian: msj,
            min_scaled_jacobian_element: msj_e,
            non_manifold_facets: topo.non_manifold.facets.len(),
            non_manifold_edges: topo.non_manifold.edges.len(),
            non_manifold_vertices: topo.non_manifold.vertices.len(),
            duplicate_elements: crate::mesh::manifold::duplicate_elements(mesh).len(),
            unused_vertices: mesh.unused_vertices,
            interior_tagged_facets: topo.interior_tagged_facets,
            unmatched_tagged_facets: topo.unmatched_tagged_facets,
            ignored_cells: mesh.ignored_cells.clone(),
            spline_elements: space.n_spline_elements(),
            q2_elements: space.n_q2_elements(),
            control_points: space.n_control_points(),
            q2_reasons,
            features: None,
            periodic: Vec::new(),
            knot_surfaces: None,
        }
    }

    /// The spline space's figures as `curve` builds it: with the knot intervals of `params`,
    /// on the mesh with its translation seams glued where `glued` is given (`mesh` and `topo`
    /// as given to [`MeshInfo::new`], `glued` from [`crate::spline::seam::glue`] of `mesh`).
    /// Graded knots are measured across the glued seams ([`crate::spline::seam::knot_weights`]).
    /// Nothing changes with uniform knots and no seams.
    pub fn set_spline_space(
        &mut self,
        mesh: &LinearMesh,
        topo: &Topology,
        glued: Option<&crate::spline::seam::Glued>,
        params: &crate::spline::KnotParams,
    ) -> Result<(), crate::params::ParamError> {
        use crate::spline::{KnotIntervals, Q2Reason, SplineSpace, seam};
        params.check()?;
        let graded = params.intervals == KnotIntervals::Graded;
        if !graded && glued.is_none() {
            return Ok(());
        }
        let on = |m: &LinearMesh, t: &Topology, knots: &crate::spline::Knots| {
            let split = [(&knots.split[..], Q2Reason::KnotSplit)];
            SplineSpace::build_with_knots(m, t, &split, knots.weights.as_deref())
        };
        // As `curve`: where the glued space cannot be put back on the input, the sides stay
        // apart.
        let glued_space = glued.and_then(|g| {
            let knots = seam::knot_weights(mesh, g, params);
            let mut space = on(&g.mesh, &g.topo, &knots);
            seam::unwrap(&mut space, mesh, topo, g).ok()?;
            Some((knots, space))
        });
        let (knots, space) = glued_space.unwrap_or_else(|| {
            let knots = SplineSpace::knot_weights(mesh, topo, params);
            let space = on(mesh, topo, &knots);
            (knots, space)
        });
        self.spline_elements = space.n_spline_elements();
        self.q2_elements = space.n_q2_elements();
        self.control_points = space.n_control_points();
        self.q2_reasons = q2_reasons(&space);
        self.knot_surfaces = graded.then_some(knots.info);
        Ok(())
    }
}

impl fmt::Display for MeshInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.fmt_sizes_and_tags(f)?;
        self.fmt_structure(f)?;
        self.fmt_problems(f)?;
        self.fmt_features(f)?;
        for p in &self.periodic {
            row(f, "periodic", p.to_string())?;
        }
        Ok(())
    }
}

/// One `key value` row of the table.
fn row(f: &mut fmt::Formatter<'_>, k: &str, v: String) -> fmt::Result {
    writeln!(f, "{k:<22}{v}")
}

impl MeshInfo {
    /// Dimension, counts of elements, vertices, edges, faces and boundary facets, and tags.
    fn fmt_sizes_and_tags(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        row(f, "dimension", self.dimension.to_string())?;
        row(
            f,
            "elements",
            format!("{} ({})", self.elements, self.element_kind),
        )?;
        row(f, "vertices", self.vertices.to_string())?;
        if self.dimension == 3 {
            row(
                f,
                "edges / faces",
                format!("{} / {}", self.edges, self.faces),
            )?;
        } else {
            row(f, "edges", self.edges.to_string())?;
        }
        row(
            f,
            "boundary facets",
            format!(
                "{} ({} boundary vertices)",
                self.boundary_facets, self.boundary_vertices
            ),
        )?;
        let tags: Vec<String> = self
            .boundary_tags
            .iter()
            .map(|(t, n)| match (t, self.tag_names.get(t)) {
                (0, _) => format!("untagged: {n}"),
                (t, Some(name)) => format!("{t} \"{name}\": {n}"),
                (t, None) => format!("{t}: {n}"),
            })
            .collect();
        row(f, "boundary tags", tags.join(", "))?;
        if !self.element_tags.is_empty() {
            let tags: Vec<String> = self
                .element_tags
                .iter()
                .map(|(t, n)| match self.tag_names.get(t) {
                    Some(name) => format!("{t} \"{name}\": {n}"),
                    None => format!("{t}: {n}"),
                })
                .collect();
            row(f, "element tags", tags.join(", "))?;
        }
        Ok(())
    }

    /// Components, orientation, irregularity, the spline space, valences, the bounding box
    /// and the element quality.
    fn fmt_structure(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        row(f, "components", self.components.to_string())?;
        row(f, "reoriented", self.reoriented.to_string())?;
        if self.invalid_elements > 0 {
            row(f, "invalid (kept)", self.invalid_elements.to_string())?;
        }
        row(
            f,
            "irregular",
            format!("{} {}", self.irregular, self.irregular_kind),
        )?;
        row(
            f,
            "spline space",
            format!(
                "{} spline + {} Q2 elements, {} control points",
                self.spline_elements, self.q2_elements, self.control_points
            ),
        )?;
        if !self.q2_reasons.is_empty() {
            let reasons: Vec<String> = self
                .q2_reasons
                .iter()
                .map(|(k, n)| format!("{n} {}", k.replace('_', " ")))
                .collect();
            row(f, "Q2 because", reasons.join(", "))?;
        }
        if let Some(k) = &self.knot_surfaces {
            row(
                f,
                "knot surfaces",
                format!(
                    "{} ({} graded, {} clamped, {} non-orientable), max |ln ratio| {:.3}, \
                     max spread {:.3}, {} split elements",
                    k.surfaces,
                    k.graded,
                    k.clamped,
                    k.non_orientable,
                    k.max_abs_log_ratio,
                    k.max_spread,
                    k.split_elements
                ),
            )?;
        }
        let mut valence = format!("vertex {}", self.max_vertex_valence);
        if self.dimension == 3 {
            valence += &format!(", edge {}", self.max_edge_valence);
        }
        row(f, "max valence", valence)?;
        let [lo, hi] = self.bounding_box;
        let axes = &["x", "y", "z"][..self.dimension];
        let bbox: Vec<String> = axes
            .iter()
            .enumerate()
            .map(|(k, a)| format!("{a} [{:.6}, {:.6}]", lo[k], hi[k]))
            .collect();
        row(f, "bounding box", bbox.join("  "))?;
        row(
            f,
            "min scaled Jacobian",
            format!(
                "{:.6} (element {})",
                self.min_scaled_jacobian, self.min_scaled_jacobian_element
            ),
        )?;
        Ok(())
    }

    /// Non-manifold parts, duplicates and what the reader dropped or ignored.
    fn fmt_problems(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let nm = self.non_manifold_facets + self.non_manifold_edges + self.non_manifold_vertices;
        row(
            f,
            "non-manifold",
            if nm == 0 {
                "none".into()
            } else {
                format!(
                    "{} facets, {} edges, {} vertices",
                    self.non_manifold_facets, self.non_manifold_edges, self.non_manifold_vertices
                )
            },
        )?;
        if self.duplicate_elements > 0 {
            row(f, "duplicate elements", self.duplicate_elements.to_string())?;
        }
        if self.unused_vertices > 0 {
            row(
                f,
                "unused vertices",
                format!("{} (dropped)", self.unused_vertices),
            )?;
        }
        if self.interior_tagged_facets + self.unmatched_tagged_facets > 0 {
            row(
                f,
                "tagged facets ignored",
                format!(
                    "{} interior, {} not a facet of any element",
                    self.interior_tagged_facets, self.unmatched_tagged_facets
                ),
            )?;
        }
        if !self.ignored_cells.is_empty() {
            let c: Vec<String> = self
                .ignored_cells
                .iter()
                .map(|(k, n)| format!("{n} {k}"))
                .collect();
            row(f, "ignored cells", c.join(", "))?;
        }
        Ok(())
    }

    /// The sharp features, when they were detected.
    fn fmt_features(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(s) = &self.features {
            let what = if self.dimension == 2 {
                format!("{} corners", s.feature_corners)
            } else {
                format!(
                    "{} edges, {} corners, {} vertices",
                    s.feature_edges, s.feature_corners, s.feature_vertices
                )
            };
            row(
                f,
                "sharp features",
                format!(
                    "{what}; {} patches ({} {}); {} crease elements (angle {}°{})",
                    s.patches,
                    s.planar_patches,
                    if self.dimension == 2 {
                        "straight"
                    } else {
                        "planar"
                    },
                    s.crease_elements,
                    s.feature_angle_deg,
                    if s.tags { ", tags" } else { "" }
                ),
            )?;
        }
        Ok(())
    }
}
