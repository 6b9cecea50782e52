//! Gmsh element type numbers → [`CellKind`] and node count, and the per-type output blocks.
//!
//! Input: a type number from an element record or block header. Output: the kind and its node
//! count (complete Lagrange lines/quads/hexes become [`CellKind::Lagrange`]; every other type Gmsh
//! defines becomes a named [`CellKind::Other`]), or the message saying why the type cannot be
//! read. Invariant: [`Blocks`] holds one [`RawBlock`] per type, in order of first appearance.

use crate::io::ordering::gmsh_type_info;
use crate::mesh::raw::{CellKind, Location, NodeConvention, ParseError, RawBlock};

// Element families, used to name the cell kinds polyspline does not handle itself.
pub(super) const POINT: &str = "point";
pub(super) const LINE: &str = "line";
pub(super) const TRIANGLE: &str = "triangle";
pub(super) const QUADRILATERAL: &str = "quadrilateral";
pub(super) const TETRAHEDRON: &str = "tetrahedron";
pub(super) const HEXAHEDRON: &str = "hexahedron";
pub(super) const PRISM: &str = "prism";
pub(super) const PYRAMID: &str = "pyramid";

/// Every element type Gmsh defines with a fixed node count: (type number, family, nodes).
/// Node counts as reported by the Gmsh API (`getElementProperties`); the high-order prisms Gmsh
/// defines but that API does not describe take their counts from their names in GmshDefines.h.
#[rustfmt::skip]
pub(super) const ELEMENT_TYPES: &[(u16, &str, u16)] = &[
    (1, LINE, 2), (2, TRIANGLE, 3), (3, QUADRILATERAL, 4), (4, TETRAHEDRON, 4),
    (5, HEXAHEDRON, 8), (6, PRISM, 6), (7, PYRAMID, 5), (8, LINE, 3), (9, TRIANGLE, 6),
    (10, QUADRILATERAL, 9), (11, TETRAHEDRON, 10), (12, HEXAHEDRON, 27), (13, PRISM, 18),
    (14, PYRAMID, 14), (15, POINT, 1), (16, QUADRILATERAL, 8), (17, HEXAHEDRON, 20),
    (18, PRISM, 15), (19, PYRAMID, 13), (20, TRIANGLE, 9), (21, TRIANGLE, 10), (22, TRIANGLE, 12),
    (23, TRIANGLE, 15), (24, TRIANGLE, 15), (25, TRIANGLE, 21), (26, LINE, 4), (27, LINE, 5),
    (28, LINE, 6), (29, TETRAHEDRON, 20), (30, TETRAHEDRON, 35), (31, TETRAHEDRON, 56),
    (32, TETRAHEDRON, 22), (33, TETRAHEDRON, 28), (36, QUADRILATERAL, 16),
    (37, QUADRILATERAL, 25), (38, QUADRILATERAL, 36), (39, QUADRILATERAL, 12),
    (40, QUADRILATERAL, 16), (41, QUADRILATERAL, 20), (42, TRIANGLE, 28), (43, TRIANGLE, 36),
    (44, TRIANGLE, 45), (45, TRIANGLE, 55), (46, TRIANGLE, 66), (47, QUADRILATERAL, 49),
    (48, QUADRILATERAL, 64), (49, QUADRILATERAL, 81), (50, QUADRILATERAL, 100),
    (51, QUADRILATERAL, 121), (52, TRIANGLE, 18), (53, TRIANGLE, 21), (54, TRIANGLE, 24),
    (55, TRIANGLE, 27), (56, TRIANGLE, 30), (57, QUADRILATERAL, 24), (58, QUADRILATERAL, 28),
    (59, QUADRILATERAL, 32), (60, QUADRILATERAL, 36), (61, QUADRILATERAL, 40), (62, LINE, 7),
    (63, LINE, 8), (64, LINE, 9), (65, LINE, 10), (66, LINE, 11), (71, TETRAHEDRON, 84),
    (72, TETRAHEDRON, 120), (73, TETRAHEDRON, 165), (74, TETRAHEDRON, 220),
    (75, TETRAHEDRON, 286), (79, TETRAHEDRON, 34), (80, TETRAHEDRON, 40), (81, TETRAHEDRON, 46),
    (82, TETRAHEDRON, 52), (83, TETRAHEDRON, 58), (84, LINE, 1), (85, TRIANGLE, 1),
    (86, QUADRILATERAL, 1), (87, TETRAHEDRON, 1), (88, HEXAHEDRON, 1), (89, PRISM, 1),
    (90, PRISM, 40), (91, PRISM, 75), (92, HEXAHEDRON, 64), (93, HEXAHEDRON, 125),
    (94, HEXAHEDRON, 216), (95, HEXAHEDRON, 343), (96, HEXAHEDRON, 512), (97, HEXAHEDRON, 729),
    (98, HEXAHEDRON, 1000), (99, HEXAHEDRON, 32), (100, HEXAHEDRON, 44), (101, HEXAHEDRON, 56),
    (102, HEXAHEDRON, 68), (103, HEXAHEDRON, 80), (104, HEXAHEDRON, 92), (105, HEXAHEDRON, 104),
    (106, PRISM, 126), (107, PRISM, 196), (108, PRISM, 288), (109, PRISM, 405), (110, PRISM, 550),
    (111, PRISM, 24), (112, PRISM, 33), (113, PRISM, 42), (114, PRISM, 51), (115, PRISM, 60),
    (116, PRISM, 69), (117, PRISM, 78), (118, PYRAMID, 30), (119, PYRAMID, 55),
    (120, PYRAMID, 91), (121, PYRAMID, 140), (122, PYRAMID, 204), (123, PYRAMID, 285),
    (124, PYRAMID, 385), (125, PYRAMID, 21), (126, PYRAMID, 29), (127, PYRAMID, 37),
    (128, PYRAMID, 45), (129, PYRAMID, 53), (130, PYRAMID, 61), (131, PYRAMID, 69),
    (132, PYRAMID, 1), (137, TETRAHEDRON, 16),
];

/// The cell kind and node count of Gmsh element type `t`, or a message saying why it cannot
/// be read.
pub(super) fn element_type(t: i64) -> Result<(CellKind, usize), String> {
    let linear = match t {
        15 => Some(CellKind::Vertex),
        1 => Some(CellKind::Line),
        2 => Some(CellKind::Triangle),
        3 => Some(CellKind::Quad),
        4 => Some(CellKind::Tetra),
        5 => Some(CellKind::Hexahedron),
        6 => Some(CellKind::Wedge),
        7 => Some(CellKind::Pyramid),
        _ => None,
    };
    if let Some(kind) = linear {
        let n = kind.nodes().unwrap_or(1);
        return Ok((kind, n));
    }
    // Complete Lagrange lines, quads and hexes of order >= 2 (polyspline's own output).
    if let Some((dim, order)) = u32::try_from(t).ok().and_then(gmsh_type_info) {
        let kind = CellKind::Lagrange {
            dim,
            order,
            convention: NodeConvention::Gmsh,
        };
        let n = kind.nodes().unwrap_or(1);
        return Ok((kind, n));
    }
    match ELEMENT_TYPES.binary_search_by_key(&t, |&(ty, _, _)| i64::from(ty)) {
        Ok(i) => {
            let (_, family, n) = ELEMENT_TYPES[i];
            Ok((
                CellKind::Other(format!("{n}-node {family} (Gmsh type {t})")),
                usize::from(n),
            ))
        }
        Err(_) => Err(match t {
            34 | 35 => format!(
                "Gmsh element type {t} ({}) has no fixed node count and is not supported",
                if t == 34 { "polygon" } else { "polyhedron" }
            ),
            _ => format!("unknown Gmsh element type {t}"),
        }),
    }
}

/// One output block per Gmsh element type, in order of first appearance.
#[derive(Default)]
pub(super) struct Blocks {
    pub(super) list: Vec<(i64, RawBlock)>,
}

impl Blocks {
    /// Index of the block for Gmsh type `t`, created on first use.
    pub(super) fn index(&mut self, t: i64, location: Location) -> Result<usize, ParseError> {
        if let Some(i) = self.list.iter().position(|(ty, _)| *ty == t) {
            return Ok(i);
        }
        let (kind, n) = element_type(t).map_err(|m| ParseError::new(location, m))?;
        self.list.push((t, RawBlock::new(kind, n)));
        Ok(self.list.len() - 1)
    }
}
