//! VTK cell types → [`CellKind`], and the flat cell list both VTK readers fill.
//!
//! Input: a [`CellList`] (types, offsets, connectivity, locations) and optional tags. Output:
//! blocks pushed to a [`RawMesh`] in file order. Invariants: a cell of a linear type with the
//! wrong node count is an error at that cell; pixels and voxels are renumbered into quad/hex
//! order; Lagrange hexahedra of files older than VTK 9 are renumbered into VTK 9 order; every
//! other type is kept as a named [`CellKind::Other`].

use crate::mesh::raw::{CellKind, Location, NodeConvention, ParseError, RawBlock, RawMesh};
use std::borrow::Cow;

pub(super) const PIXEL_TO_QUAD: [usize; 4] = [0, 1, 3, 2];
pub(super) const VOXEL_TO_HEX: [usize; 8] = [0, 1, 3, 2, 4, 5, 7, 6];

/// Human-readable names of the VTK cell types polyspline does not read as linear cells.
pub(super) fn vtk_type_name(t: i64) -> &'static str {
    match t {
        0 => "empty cell",
        2 => "poly-vertex",
        4 => "poly-line",
        6 => "triangle strip",
        7 => "polygon",
        15 => "pentagonal prism",
        16 => "hexagonal prism",
        21 => "quadratic edge",
        22 => "quadratic triangle",
        23 => "quadratic quadrilateral",
        24 => "quadratic tetrahedron",
        25 => "quadratic hexahedron",
        26 => "quadratic wedge",
        27 => "quadratic pyramid",
        28 => "biquadratic quadrilateral",
        29 => "triquadratic hexahedron",
        30 => "quadratic-linear quadrilateral",
        31 => "quadratic-linear wedge",
        32 => "biquadratic-quadratic wedge",
        33 => "biquadratic-quadratic hexahedron",
        34 => "biquadratic triangle",
        35 => "cubic line",
        36 => "quadratic polygon",
        37 => "triquadratic pyramid",
        41 => "convex point set",
        42 => "polyhedron",
        51..=67 => "parametric or higher-order cell",
        68 => "Lagrange curve",
        69 => "Lagrange triangle",
        70 => "Lagrange quadrilateral",
        71 => "Lagrange tetrahedron",
        72 => "Lagrange hexahedron",
        73 => "Lagrange wedge",
        74 => "Lagrange pyramid",
        75 => "Bezier curve",
        76 => "Bezier triangle",
        77 => "Bezier quadrilateral",
        78 => "Bezier tetrahedron",
        79 => "Bezier hexahedron",
        80 => "Bezier wedge",
        81 => "Bezier pyramid",
        _ => "unknown cell",
    }
}

/// The order `p` of a Lagrange cell of dimension `dim` with `n = (p + 1)^dim` nodes.
pub(super) fn lattice_order(n: usize, dim: u32) -> Option<usize> {
    let mut k = 2usize;
    loop {
        match k.checked_pow(dim) {
            Some(v) if v == n => return Some(k - 1),
            Some(v) if v < n => k += 1,
            _ => return None,
        }
    }
}

/// A complete Lagrange cell in VTK node order; order 1 is the linear cell.
pub(super) fn lagrange(dim: usize, order: usize) -> CellKind {
    match (dim, order) {
        (1, 1) => CellKind::Line,
        (2, 1) => CellKind::Quad,
        (3, 1) => CellKind::Hexahedron,
        _ => CellKind::Lagrange {
            dim,
            order,
            convention: NodeConvention::Vtk,
        },
    }
}

/// Kind of a VTK cell type with `n` nodes, and the renumbering into VTK/Gmsh linear order
/// where the type needs one.
pub(super) fn vtk_cell(t: i64, n: usize) -> (CellKind, Option<&'static [usize]>) {
    let other = || CellKind::Other(format!("{n}-node {} (VTK type {t})", vtk_type_name(t)));
    let kind = match t {
        1 => CellKind::Vertex,
        3 => CellKind::Line,
        5 => CellKind::Triangle,
        8 => return (CellKind::Quad, Some(&PIXEL_TO_QUAD)),
        9 => CellKind::Quad,
        10 => CellKind::Tetra,
        11 => return (CellKind::Hexahedron, Some(&VOXEL_TO_HEX)),
        12 => CellKind::Hexahedron,
        13 => CellKind::Wedge,
        14 => CellKind::Pyramid,
        // Quadratic edge, biquadratic quad and triquadratic hex number their nodes exactly as
        // the order-2 Lagrange cells do.
        21 => lagrange(1, 2),
        28 => lagrange(2, 2),
        29 => lagrange(3, 2),
        // Lagrange curve, quadrilateral and hexahedron of uniform order, read from the node
        // count (anisotropic orders stay unsupported cells).
        68 | 70 | 72 => {
            let dim = (t as usize - 66) / 2;
            match lattice_order(n, dim as u32) {
                Some(p) => lagrange(dim, p),
                None => other(),
            }
        }
        _ => other(),
    };
    (kind, None)
}

/// Node renumbering of a VTK Lagrange hexahedron of order `p` written before VTK 9 (legacy
/// files before 5.1, XML files before 2.1): VTK 9 swapped the node runs of the vertical edges
/// above corners 2 and 3. Entry `j` is the file node that becomes node `j`.
pub(super) fn vtk8_hex_to_vtk9(p: usize) -> Vec<usize> {
    let m = p.saturating_sub(1);
    let start = 8 + 10 * m;
    (0..(p + 1).pow(3))
        .map(|j| {
            if (start..start + m).contains(&j) {
                j + m
            } else if (start + m..start + 2 * m).contains(&j) {
                j - m
            } else {
                j
            }
        })
        .collect()
}

pub(super) fn singular(kind: &CellKind) -> String {
    match kind {
        CellKind::Vertex => "vertex".into(),
        CellKind::Line => "line".into(),
        CellKind::Triangle => "triangle".into(),
        CellKind::Quad => "quadrilateral".into(),
        CellKind::Tetra => "tetrahedron".into(),
        CellKind::Hexahedron => "hexahedron".into(),
        CellKind::Wedge => "wedge".into(),
        CellKind::Pyramid => "pyramid".into(),
        CellKind::Lagrange { dim, order, .. } => {
            let what = ["point", "line", "quadrilateral", "hexahedron"][(*dim).min(3)];
            format!("order-{order} Lagrange {what}")
        }
        CellKind::Other(name) => name.clone(),
    }
}

/// Cells as VTK stores them: a type per cell and a flat connectivity cut by offsets.
#[derive(Default, Debug)]
pub(crate) struct CellList {
    pub types: Vec<i64>,
    /// `types.len() + 1` nondecreasing offsets into `conn`, starting at 0.
    pub offsets: Vec<usize>,
    pub conn: Vec<i64>,
    /// Where each cell was read.
    pub locations: Vec<Location>,
    /// The file predates VTK 9's Lagrange hexahedron numbering (see [`vtk8_hex_to_vtk9`]).
    pub vtk8_hexes: bool,
}

impl CellList {
    pub fn len(&self) -> usize {
        self.types.len()
    }

    /// Number of cells the offsets describe (known before the types are read).
    pub(super) fn len_declared(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Append the cells to `mesh` as blocks in file order, with `tags` (one per cell, or
    /// empty). Fails when a cell of a linear type has the wrong number of nodes.
    pub fn push_to(&self, mesh: &mut RawMesh, tags: &[i32]) -> Result<(), ParseError> {
        let mut block: Option<RawBlock> = None;
        let mut current: Option<(i64, usize)> = None;
        let mut perm: Option<Cow<'static, [usize]>> = None;
        for (c, &t) in self.types.iter().enumerate() {
            let (Some(&lo), Some(&hi)) = (self.offsets.get(c), self.offsets.get(c + 1)) else {
                break;
            };
            let nodes = self.conn.get(lo..hi).unwrap_or(&[]);
            let loc = self.locations.get(c).copied().unwrap_or_default();
            if current != Some((t, nodes.len())) {
                let (kind, p) = vtk_cell(t, nodes.len());
                if let Some(want) = kind.nodes()
                    && want != nodes.len()
                {
                    return Err(ParseError::new(
                        loc,
                        format!(
                            "cell {c} has VTK type {t} ({}) and {} nodes, expected {want}",
                            singular(&kind),
                            nodes.len()
                        ),
                    ));
                }
                if let Some(b) = block.take() {
                    mesh.push_block(b);
                }
                perm = match kind {
                    CellKind::Lagrange { dim: 3, order, .. } if t == 72 && self.vtk8_hexes => {
                        Some(Cow::Owned(vtk8_hex_to_vtk9(order)))
                    }
                    _ => p.map(Cow::Borrowed),
                };
                block = Some(RawBlock::new(kind, nodes.len()));
                current = Some((t, nodes.len()));
            }
            let Some(b) = block.as_mut() else { break };
            match &perm {
                Some(p) => b.nodes.extend(p.iter().map(|&i| nodes[i])),
                None => b.nodes.extend_from_slice(nodes),
            }
            if !tags.is_empty() {
                b.tags.push(tags.get(c).copied().unwrap_or(0));
            }
            b.locations.push(loc);
        }
        if let Some(b) = block {
            mesh.push_block(b);
        }
        Ok(())
    }
}

/// Convert tag values to `i32`, reporting the first that does not fit.
pub(crate) fn tags_to_i32(
    values: &[i64],
    name: &str,
    loc: impl Fn(usize) -> Location,
) -> Result<Vec<i32>, ParseError> {
    values
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            i32::try_from(v).map_err(|_| {
                ParseError::new(
                    loc(i),
                    format!(
                        "value {v} of cell {i} in tag array {name} does not fit a 32-bit integer"
                    ),
                )
            })
        })
        .collect()
}
