//! Exodus element types → element families, cell kinds and side tables.
//!
//! Input: a block's `elem_type` attribute, its nodes per element and the file's dimension; a
//! side number of a side set. Output: the [`CellKind`] of the block's cells and the facet kind
//! and local nodes of each side (Exodus side numbering, 1-based in the file).

use crate::mesh::raw::CellKind;

/// Element families with their side tables.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Family {
    Hex,
    Tet,
    Wedge,
    Pyramid,
    /// A quad in a 2D file (sides are edges).
    Quad,
    /// A quad in a 3D file (sides 1, 2 are faces; 3.. are edges).
    Shell,
    Tri,
    TriShell,
    Line,
    Point,
    Unknown,
}

impl Family {
    pub(super) fn of(elem_type: &str, dim: usize) -> Family {
        let t = elem_type.trim().to_ascii_uppercase();
        let fam = t.trim_end_matches(|c: char| c.is_ascii_digit());
        let digits = &t[fam.len()..];
        match fam {
            "HEX" | "HEXAHEDRON" => Family::Hex,
            "TET" | "TETRA" | "TETRAHEDRON" => Family::Tet,
            "WEDGE" => Family::Wedge,
            "PYRAMID" | "PYRA" => Family::Pyramid,
            "SHELL" if digits == "3" => Family::TriShell,
            "SHELL" => Family::Shell,
            "QUAD" | "QUADRILATERAL" if dim == 3 => Family::Shell,
            "QUAD" | "QUADRILATERAL" => Family::Quad,
            "TRISHELL" => Family::TriShell,
            "TRI" | "TRIANGLE" if dim == 3 => Family::TriShell,
            "TRI" | "TRIANGLE" => Family::Tri,
            "BAR" | "BEAM" | "TRUSS" | "EDGE" | "ROD" => Family::Line,
            "SPHERE" | "CIRCLE" | "POINT" => Family::Point,
            _ => Family::Unknown,
        }
    }

    /// The linear cell kind when the node count is that of the linear cell.
    pub(super) fn kind(self, npe: usize, elem_type: &str) -> CellKind {
        let linear = match self {
            Family::Hex => Some((CellKind::Hexahedron, 8)),
            Family::Tet => Some((CellKind::Tetra, 4)),
            Family::Wedge => Some((CellKind::Wedge, 6)),
            Family::Pyramid => Some((CellKind::Pyramid, 5)),
            Family::Quad | Family::Shell => Some((CellKind::Quad, 4)),
            Family::Tri | Family::TriShell => Some((CellKind::Triangle, 3)),
            Family::Line => Some((CellKind::Line, 2)),
            Family::Point => Some((CellKind::Vertex, 1)),
            Family::Unknown => None,
        };
        match linear {
            Some((k, n)) if n == npe => k,
            _ => CellKind::Other(format!("{npe}-node {} (Exodus)", elem_type.trim())),
        }
    }

    /// Corner positions (0-based) of side `side` (1-based) and the facet kind.
    pub(super) fn side(self, side: i64) -> Option<(CellKind, &'static [usize])> {
        const HEX: [[usize; 4]; 6] = [
            [0, 1, 5, 4],
            [1, 2, 6, 5],
            [2, 3, 7, 6],
            [0, 4, 7, 3],
            [0, 3, 2, 1],
            [4, 5, 6, 7],
        ];
        const TET: [[usize; 3]; 4] = [[0, 1, 3], [1, 2, 3], [0, 3, 2], [0, 2, 1]];
        const WEDGE_QUAD: [[usize; 4]; 3] = [[0, 1, 4, 3], [1, 2, 5, 4], [0, 3, 5, 2]];
        const WEDGE_TRI: [[usize; 3]; 2] = [[0, 2, 1], [3, 4, 5]];
        const PYR_TRI: [[usize; 3]; 4] = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [0, 4, 3]];
        const PYR_BASE: [usize; 4] = [0, 3, 2, 1];
        const QUAD_EDGES: [[usize; 2]; 4] = [[0, 1], [1, 2], [2, 3], [3, 0]];
        const SHELL_FACES: [[usize; 4]; 2] = [[0, 1, 2, 3], [0, 3, 2, 1]];
        const TRI_EDGES: [[usize; 2]; 3] = [[0, 1], [1, 2], [2, 0]];
        const TRI_FACES: [[usize; 3]; 2] = [[0, 1, 2], [0, 2, 1]];
        let i = usize::try_from(side).ok()?.checked_sub(1)?;
        let quad = |f: &'static [usize]| (CellKind::Quad, f);
        let tri = |f: &'static [usize]| (CellKind::Triangle, f);
        let line = |f: &'static [usize]| (CellKind::Line, f);
        match self {
            Family::Hex => HEX.get(i).map(|f| quad(f)),
            Family::Tet => TET.get(i).map(|f| tri(f)),
            Family::Wedge if i < 3 => Some(quad(&WEDGE_QUAD[i])),
            Family::Wedge => WEDGE_TRI.get(i - 3).map(|f| tri(f)),
            Family::Pyramid if i < 4 => Some(tri(&PYR_TRI[i])),
            Family::Pyramid => (i == 4).then_some(quad(&PYR_BASE)),
            Family::Quad => QUAD_EDGES.get(i).map(|f| line(f)),
            Family::Shell if i < 2 => Some(quad(&SHELL_FACES[i])),
            Family::Shell => QUAD_EDGES.get(i - 2).map(|f| line(f)),
            Family::Tri => TRI_EDGES.get(i).map(|f| line(f)),
            Family::TriShell if i < 2 => Some(tri(&TRI_FACES[i])),
            Family::TriShell => TRI_EDGES.get(i - 2).map(|f| line(f)),
            Family::Line | Family::Point | Family::Unknown => None,
        }
    }
}
