//! The linear input mesh: quads in the plane (2D) or hexes (3D), checked and oriented.
//!
//! Input: a [`RawMesh`] from any reader. Output: a [`LinearMesh`] whose invariants every later
//! stage relies on:
//! * all elements are of one kind: quads (`dim == 2`, 4 nodes, counter-clockwise) or hexes
//!   (`dim == 3`, 8 nodes in VTK/Gmsh order, positive Jacobian at all corners), unless the user
//!   passed `allow_invalid`, in which case tangled or degenerate elements are kept and listed
//!   in [`LinearMesh::invalid_elements`];
//! * node indices are in range and every vertex is used by an element (unused vertices are
//!   dropped and counted);
//! * coordinates are finite; in 2D the z coordinate is 0;
//! * lower-dimensional cells of the file are kept only as tagged facets (lines in 2D, quads in
//!   3D) for boundary conditions; the boundary itself comes from [`crate::mesh::Topology`].

use crate::math::linalg::DVec3;
use crate::mesh::raw::{CellKind, Location, ParseError, RawBlock, RawMesh};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Options for building a [`LinearMesh`].
#[derive(Clone, Debug, Default)]
pub struct MeshOptions {
    /// Keep tangled or degenerate elements (listed in `invalid_elements`) instead of failing.
    pub allow_invalid: bool,
}

/// Why an element was judged invalid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum InvalidKind {
    /// Corner Jacobians of both signs.
    Tangled,
    /// A repeated vertex or a (numerically) zero corner Jacobian.
    Degenerate,
}

/// An element kept with `allow_invalid`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct InvalidElement {
    pub element: u32,
    pub kind: InvalidKind,
}

/// A linear quad or hex mesh.
#[derive(Clone, Debug, Default)]
pub struct LinearMesh {
    /// 2 (quads) or 3 (hexes).
    pub dim: usize,
    /// Vertex coordinates; z = 0 in 2D.
    pub coords: Vec<[f64; 3]>,
    /// Element vertices, [`LinearMesh::nodes_per_element`] per element.
    pub elements: Vec<u32>,
    /// Region tag of each element (Gmsh physical volume, MFEM attribute, ...), or empty.
    pub element_tags: Vec<i32>,
    /// Vertices of the lower-dimensional cells the file tagged ([`LinearMesh::nodes_per_facet`]
    /// each): lines in 2D, quads in 3D.
    pub tagged_facets: Vec<u32>,
    /// Tag of each tagged facet.
    pub facet_tags: Vec<i32>,
    /// Names of tags where the file gives them.
    pub tag_names: BTreeMap<i32, String>,
    /// How many elements were re-ordered to positive orientation.
    pub reoriented: usize,
    /// Tangled or degenerate elements kept because of `allow_invalid`.
    pub invalid_elements: Vec<InvalidElement>,
    /// Vertices of the file that no element uses (dropped).
    pub unused_vertices: usize,
    /// Cells of the file that are neither elements nor tagged facets (points, edges in 3D).
    pub ignored_cells: BTreeMap<String, usize>,
    /// Periodic pairs of facet tags the file declares (Gmsh's `$Periodic`); used by
    /// [`crate::mesh::periodic::resolve`] after verification.
    pub declared_periodic: Vec<crate::mesh::raw::DeclaredPeriodic>,
}

/// Corner neighbours of each hex corner, ordered so that the corner Jacobian
/// det(v_a - v_c, v_b - v_c, v_d - v_c) is positive for a right-handed hex.
pub const HEX_CORNER_NEIGHBOURS: [[usize; 3]; 8] = [
    [1, 3, 4],
    [2, 0, 5],
    [3, 1, 6],
    [0, 2, 7],
    [7, 5, 0],
    [4, 6, 1],
    [5, 7, 2],
    [6, 4, 3],
];

/// Re-orderings that mirror an element (reverse its orientation) keeping vertex 0 first.
const QUAD_FLIP: [usize; 4] = [0, 3, 2, 1];
const HEX_FLIP: [usize; 8] = [0, 3, 2, 1, 4, 7, 6, 5];

/// Largest coordinate magnitude: the cube of a coordinate difference (a 3D det J) stays
/// finite, with room for the fit's weights.
pub const MAX_COORDINATE: f64 = 1e100;
/// Smallest extent of a mesh: its det J stays a normal float.
pub const MIN_EXTENT: f64 = 1e-100;

/// Relative size below which a corner Jacobian counts as zero (degenerate corner).
const DEGENERATE_REL_TOL: f64 = 1e-12;

/// How many offending elements an error message lists.
const MAX_LISTED: usize = 8;

// Not `a.dot(b.cross(c))`: that adds a₁(b₂c₀ − b₀c₂) where this subtracts a₁(b₀c₂ − b₂c₀),
// equal except for the sign of an exact zero, which would change the verdict's input bits.
fn det3(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    a.x * (b.y * c.z - b.z * c.y) - a.y * (b.x * c.z - b.z * c.x) + a.z * (b.x * c.y - b.y * c.x)
}

/// Corner Jacobians of an element and the scaled ones (divided by the lengths of the corner's
/// edges), written into `out` (4 or 8 entries). `dim` picks quad or hex.
pub fn corner_jacobians(dim: usize, x: &[[f64; 3]], jac: &mut [f64], scaled: &mut [f64]) {
    if dim == 2 {
        for i in 0..4 {
            let p = DVec3::from_array(x[i]);
            let a = DVec3::from_array(x[(i + 1) % 4]) - p;
            let b = DVec3::from_array(x[(i + 3) % 4]) - p;
            let j = a.x * b.y - a.y * b.x;
            jac[i] = j;
            let s = a.length() * b.length();
            scaled[i] = if s > 0.0 { j / s } else { 0.0 };
        }
    } else {
        for (i, nb) in HEX_CORNER_NEIGHBOURS.iter().enumerate() {
            let p = DVec3::from_array(x[i]);
            let a = DVec3::from_array(x[nb[0]]) - p;
            let b = DVec3::from_array(x[nb[1]]) - p;
            let c = DVec3::from_array(x[nb[2]]) - p;
            let j = det3(a, b, c);
            jac[i] = j;
            let s = a.length() * b.length() * c.length();
            scaled[i] = if s > 0.0 { j / s } else { 0.0 };
        }
    }
}

/// Orientation verdict of one element from its corner Jacobians.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Orientation {
    Positive,
    Negative,
    Invalid(InvalidKind),
}

fn classify(dim: usize, x: &[[f64; 3]], nodes: &[u32]) -> Orientation {
    let n = nodes.len();
    for i in 0..n {
        if nodes[i + 1..].contains(&nodes[i]) {
            return Orientation::Invalid(InvalidKind::Degenerate);
        }
    }
    let mut jac = [0.0; 8];
    let mut scaled = [0.0; 8];
    corner_jacobians(dim, x, &mut jac[..n], &mut scaled[..n]);
    let (mut pos, mut neg) = (0, 0);
    for &s in &scaled[..n] {
        if s > DEGENERATE_REL_TOL {
            pos += 1;
        } else if s < -DEGENERATE_REL_TOL {
            neg += 1;
        }
    }
    if pos == n {
        Orientation::Positive
    } else if neg == n {
        Orientation::Negative
    } else if pos > 0 && neg > 0 {
        Orientation::Invalid(InvalidKind::Tangled)
    } else {
        Orientation::Invalid(InvalidKind::Degenerate)
    }
}

impl LinearMesh {
    pub fn nodes_per_element(&self) -> usize {
        if self.dim == 2 { 4 } else { 8 }
    }

    pub fn nodes_per_facet(&self) -> usize {
        if self.dim == 2 { 2 } else { 4 }
    }

    pub fn n_elements(&self) -> usize {
        self.elements.len() / self.nodes_per_element().max(1)
    }

    pub fn n_vertices(&self) -> usize {
        self.coords.len()
    }

    /// Vertex indices of element `e`.
    pub fn element(&self, e: usize) -> &[u32] {
        let n = self.nodes_per_element();
        &self.elements[e * n..(e + 1) * n]
    }

    /// Corner coordinates of element `e` (4 or 8 of the returned entries are used).
    pub fn element_coords(&self, e: usize) -> [[f64; 3]; 8] {
        let mut x = [[0.0; 3]; 8];
        for (k, &v) in self.element(e).iter().enumerate() {
            x[k] = self.coords[v as usize];
        }
        x
    }

    /// Axis-aligned bounding box (min, max).
    pub fn bounding_box(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.coords {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    /// Minimum over elements and corners of the scaled corner Jacobian (1 for a square or
    /// cube, ≤ 0 for an inverted corner), and the element where it occurs.
    pub fn min_scaled_jacobian(&self) -> Option<(f64, usize)> {
        let n = self.nodes_per_element();
        (0..self.n_elements())
            .into_par_iter()
            .map(|e| {
                let x = self.element_coords(e);
                let mut jac = [0.0; 8];
                let mut scaled = [0.0; 8];
                corner_jacobians(self.dim, &x[..n], &mut jac[..n], &mut scaled[..n]);
                let m = scaled[..n].iter().copied().fold(f64::INFINITY, f64::min);
                (m, e)
            })
            .reduce_with(|a, b| if b.0 < a.0 { b } else { a })
    }

    /// Build a checked, oriented mesh from what a reader found. Errors name the place in the
    /// file (from the raw block's locations) and the problem. The checks run in this order:
    /// cell kinds, node indices (in file order), coordinates of the used nodes, the extent,
    /// planarity of 2D meshes, then orientation.
    pub fn from_raw(raw: RawMesh, options: &MeshOptions) -> Result<LinearMesh, ParseError> {
        // Pick the element kind: hexes if any, else quads.
        let n_hex = raw.count(&CellKind::Hexahedron);
        let n_quad = raw.count(&CellKind::Quad);
        let RawMesh {
            points,
            point_locations,
            declared_dim: _,
            blocks,
            tag_names,
            periodic,
        } = raw;
        let dim = if n_hex > 0 {
            3
        } else if n_quad > 0 {
            2
        } else {
            0
        };
        check_cell_kinds(&blocks, dim, n_hex, n_quad, points.len())?;
        let n_elements = if dim == 3 { n_hex } else { n_quad };
        let Cells {
            mut elements,
            element_locations,
            element_tags,
            tagged_facets,
            facet_tags,
            ignored_cells,
        } = Cells::collect(&blocks, dim, points.len(), n_elements)?;
        let n_points = points.len();
        let (mut coords, new_index) = used_coordinates(&points, &point_locations, &elements)?;
        check_extent(&coords)?;
        let unused_vertices = n_points - coords.len();
        for v in elements.iter_mut() {
            *v = new_index[*v as usize];
        }
        // Facets touching unused vertices cannot be boundary facets of the elements: drop them.
        let npf = if dim == 2 { 2 } else { 4 };
        let mut kept_facets = Vec::with_capacity(tagged_facets.len());
        let mut kept_tags = Vec::with_capacity(facet_tags.len());
        for (f, &tag) in tagged_facets.chunks(npf).zip(&facet_tags) {
            if f.iter().all(|&v| new_index[v as usize] != u32::MAX) {
                kept_facets.extend(f.iter().map(|&v| new_index[v as usize]));
                kept_tags.push(tag);
            }
        }
        if dim == 2 {
            let z0 = coords[0][2];
            if let Some((i, p)) = coords.iter().enumerate().find(|(_, p)| p[2] != z0) {
                return Err(ParseError::new(
                    Location::File,
                    format!(
                        "the quadrilaterals do not lie in a plane z = const (node {} has z = {}, another z = {}); polyspline curves planar quad meshes, not surface meshes",
                        i + 1,
                        p[2],
                        z0
                    ),
                ));
            }
            for p in coords.iter_mut() {
                p[2] = 0.0;
            }
        }

        let mut mesh = LinearMesh {
            dim,
            coords,
            elements,
            element_tags,
            tagged_facets: kept_facets,
            facet_tags: kept_tags,
            tag_names,
            reoriented: 0,
            invalid_elements: Vec::new(),
            unused_vertices,
            ignored_cells,
            // Only pairs of boundary facets concern the volume mesh.
            declared_periodic: periodic.into_iter().filter(|p| p.dim + 1 == dim).collect(),
        };
        mesh.normalise_orientation(options, &element_locations)?;
        Ok(mesh)
    }

    /// Re-order negatively oriented elements; report tangled or degenerate ones (an error
    /// unless `allow_invalid`). `locations` names each element's place in the file.
    pub fn normalise_orientation(
        &mut self,
        options: &MeshOptions,
        locations: &[Location],
    ) -> Result<(), ParseError> {
        let npe = self.nodes_per_element();
        let dim = self.dim;
        let coords = &self.coords;
        let verdicts: Vec<Orientation> = self
            .elements
            .par_chunks(npe)
            .map(|nodes| {
                let mut x = [[0.0; 3]; 8];
                for (k, &v) in nodes.iter().enumerate() {
                    x[k] = coords[v as usize];
                }
                classify(dim, &x[..npe], nodes)
            })
            .collect();
        let flip: &[usize] = if dim == 2 { &QUAD_FLIP } else { &HEX_FLIP };
        let mut invalid = Vec::new();
        let mut reoriented = 0;
        for (e, v) in verdicts.iter().enumerate() {
            match v {
                Orientation::Positive => {}
                Orientation::Negative => {
                    let nodes = &mut self.elements[e * npe..(e + 1) * npe];
                    let old: [u32; 8] = std::array::from_fn(|k| if k < npe { nodes[k] } else { 0 });
                    for (k, &f) in flip.iter().enumerate() {
                        nodes[k] = old[f];
                    }
                    reoriented += 1;
                }
                Orientation::Invalid(kind) => invalid.push(InvalidElement {
                    element: e as u32,
                    kind: *kind,
                }),
            }
        }
        self.reoriented += reoriented;
        if !invalid.is_empty() && !options.allow_invalid {
            let first = invalid[0];
            let loc = locations
                .get(first.element as usize)
                .copied()
                .unwrap_or_default();
            let listed: Vec<String> = invalid
                .iter()
                .take(MAX_LISTED)
                .map(|i| {
                    let what = match i.kind {
                        InvalidKind::Tangled => "tangled",
                        InvalidKind::Degenerate => "degenerate",
                    };
                    match locations.get(i.element as usize) {
                        Some(l) if *l != Location::File => format!("{} ({what}, {l})", i.element),
                        _ => format!("{} ({what})", i.element),
                    }
                })
                .collect();
            let more = if invalid.len() > MAX_LISTED {
                format!(" and {} more", invalid.len() - MAX_LISTED)
            } else {
                String::new()
            };
            return Err(ParseError::new(
                loc,
                format!(
                    "{} invalid element{} (corner Jacobians of mixed sign = tangled, zero or repeated vertex = degenerate): element {}{more}; pass --allow-invalid to keep them",
                    invalid.len(),
                    if invalid.len() == 1 { "" } else { "s" },
                    listed.join(", ")
                ),
            ));
        }
        self.invalid_elements.extend(invalid);
        Ok(())
    }
}

fn element_kind(dim: usize) -> CellKind {
    if dim == 3 {
        CellKind::Hexahedron
    } else {
        CellKind::Quad
    }
}

/// Refuse cells of the volume dimension (or higher) that are not the element kind of `dim`
/// (0: neither quads nor hexes were found, which is refused too).
fn check_cell_kinds(
    blocks: &[RawBlock],
    dim: usize,
    n_hex: usize,
    n_quad: usize,
    n_points: usize,
) -> Result<(), ParseError> {
    // Cells of the volume dimension (or higher) that are not our element kind.
    let mut unsupported: BTreeMap<CellKind, usize> = BTreeMap::new();
    for b in blocks {
        let k = b.kind();
        let bad = match k.dim() {
            Some(d) => {
                (dim == 0 && d >= 2) || (dim > 0 && d >= dim && d <= 3 && *k != element_kind(dim))
            }
            None => true,
        };
        if bad && !b.is_empty() {
            *unsupported.entry(k.clone()).or_default() += b.len();
        }
    }
    if !unsupported.is_empty() {
        let found: Vec<String> = unsupported
            .iter()
            .map(|(k, n)| format!("{n} {}", k.plural()))
            .collect();
        let have = match dim {
            3 => format!(" (besides {n_hex} hexahedra)"),
            2 => format!(" (besides {n_quad} quadrilaterals)"),
            _ => String::new(),
        };
        return Err(ParseError::new(
            Location::File,
            format!(
                "found {}{have}; polyspline curves linear quad (2D) and hex (3D) meshes",
                found.join(", ")
            ),
        ));
    }
    if dim == 0 {
        return Err(ParseError::new(
            Location::File,
            if n_points == 0 {
                "the mesh is empty: no nodes and no quadrilateral or hexahedral elements".into()
            } else {
                format!(
                    "the mesh has {} nodes but no quadrilateral or hexahedral elements",
                    n_points
                )
            },
        ));
    }
    Ok(())
}

/// The cells polyspline keeps from a raw mesh, node indices checked but not yet renumbered.
struct Cells {
    elements: Vec<u32>,
    element_locations: Vec<Location>,
    /// One per element, or empty when no element block has tags.
    element_tags: Vec<i32>,
    /// Facets of dimension `dim - 1` with a nonzero tag.
    tagged_facets: Vec<u32>,
    facet_tags: Vec<i32>,
    /// Plural kind name → count of the cells that are neither.
    ignored_cells: BTreeMap<String, usize>,
}

impl Cells {
    /// Elements of the kind of `dim` and tagged facets of dimension `dim - 1`; a node index
    /// outside `0..n_points` is an error at its cell.
    fn collect(
        blocks: &[RawBlock],
        dim: usize,
        n_points: usize,
        n_elements: usize,
    ) -> Result<Cells, ParseError> {
        let npe = if dim == 2 { 4 } else { 8 };
        let npf = if dim == 2 { 2 } else { 4 };
        let facet_kind = if dim == 2 {
            CellKind::Line
        } else {
            CellKind::Quad
        };
        let check_index = |v: i64, loc: Location, what: &str| -> Result<u32, ParseError> {
            if v < 0 || v as usize >= n_points {
                Err(ParseError::new(
                    loc,
                    format!(
                        "{what} refers to node {} (0-based index {v}), but the file defines {n_points} nodes",
                        v + 1
                    ),
                ))
            } else {
                Ok(v as u32)
            }
        };
        let mut elements: Vec<u32> = Vec::with_capacity(npe * n_elements);
        let mut element_locations: Vec<Location> = Vec::new();
        let mut element_tags: Vec<i32> = Vec::new();
        let mut any_element_tags = false;
        let mut tagged_facets: Vec<u32> = Vec::new();
        let mut facet_tags: Vec<i32> = Vec::new();
        let mut ignored_cells: BTreeMap<String, usize> = BTreeMap::new();
        let ek = element_kind(dim);
        for b in blocks {
            let k = b.kind();
            if *k == ek {
                if !b.tags.is_empty() {
                    any_element_tags = true;
                }
                for c in 0..b.len() {
                    let loc = b.location(c);
                    for &v in &b.nodes[c * npe..(c + 1) * npe] {
                        elements.push(check_index(v, loc, "element")?);
                    }
                    element_locations.push(loc);
                    element_tags.push(b.tags.get(c).copied().unwrap_or(0));
                }
            } else if *k == facet_kind && !b.tags.is_empty() {
                for c in 0..b.len() {
                    if b.tags[c] == 0 {
                        continue;
                    }
                    let loc = b.location(c);
                    for &v in &b.nodes[c * npf..(c + 1) * npf] {
                        tagged_facets.push(check_index(v, loc, "boundary cell")?);
                    }
                    facet_tags.push(b.tags[c]);
                }
            } else if !b.is_empty() {
                *ignored_cells.entry(k.plural()).or_default() += b.len();
            }
        }
        if !any_element_tags {
            element_tags.clear();
        }

        Ok(Cells {
            elements,
            element_locations,
            element_tags,
            tagged_facets,
            facet_tags,
            ignored_cells,
        })
    }
}

/// The coordinates of the nodes `elements` use, in file order, and the map from file index
/// to new index (`u32::MAX` for unused nodes). Non-finite or huge coordinates are errors.
fn used_coordinates(
    points: &[[f64; 3]],
    point_locations: &[Location],
    elements: &[u32],
) -> Result<(Vec<[f64; 3]>, Vec<u32>), ParseError> {
    let n_points = points.len();
    let mut new_index = vec![u32::MAX; n_points];
    for &v in elements.iter() {
        new_index[v as usize] = 0;
    }
    let mut coords = Vec::with_capacity(n_points);
    for (i, p) in points.iter().enumerate() {
        if new_index[i] == u32::MAX {
            continue;
        }
        if let Some(k) = p.iter().position(|c| !c.is_finite()) {
            let loc = point_locations.get(i).copied().unwrap_or_default();
            return Err(ParseError::new(
                loc,
                format!(
                    "node {} has a non-finite {} coordinate ({})",
                    i + 1,
                    ["x", "y", "z"][k],
                    p[k]
                ),
            ));
        }
        if let Some(k) = p.iter().position(|c| c.abs() > MAX_COORDINATE) {
            let loc = point_locations.get(i).copied().unwrap_or_default();
            return Err(ParseError::new(
                loc,
                format!(
                    "node {} has its {} coordinate {:e} out of range (|x| ≤ {MAX_COORDINATE:e}, so that Jacobians cannot overflow); rescale the mesh",
                    i + 1,
                    ["x", "y", "z"][k],
                    p[k]
                ),
            ));
        }
        new_index[i] = coords.len() as u32;
        coords.push(*p);
    }
    Ok((coords, new_index))
}

/// A mesh this small has Jacobians that underflow to zero.
fn check_extent(coords: &[[f64; 3]]) -> Result<(), ParseError> {
    if let Some(first) = coords.first() {
        let (mut lo, mut hi) = (*first, *first);
        for p in coords {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        if extent > 0.0 && extent < MIN_EXTENT {
            return Err(ParseError::new(
                Location::File,
                format!(
                    "the mesh's extent {extent:e} is out of range (at least {MIN_EXTENT:e}, so that Jacobians cannot underflow); rescale the mesh"
                ),
            ));
        }
    }
    Ok(())
}
