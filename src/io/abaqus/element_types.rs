//! Abaqus element type names → [`CellKind`], and the faces of each kind in Abaqus numbering.
//!
//! Input: a `TYPE=` value, or a kind and a face number `Sn`. Output: the kind and, where the type
//! fixes it, its node count; the facet kind and its local node indices. The 9-node
//! quadrilaterals and 27-node hexahedra are quadratic Lagrange cells; every type not listed
//! here is kept as a named [`CellKind::Other`].

use crate::mesh::raw::CellKind;

/// What an Abaqus element type is: its kind and, where the type fixes it, its node count.
pub(super) fn element_kind(ty: &str) -> (CellKind, Option<usize>) {
    let t = ty.to_ascii_uppercase();
    // Leading decimal digits after `prefix`, if `t` starts with it.
    let count_after = |prefix: &str| -> Option<usize> {
        let rest = t.strip_prefix(prefix)?;
        let digits: String = rest.chars().take_while(|c| c.is_ascii_digit()).collect();
        digits.parse().ok()
    };
    let other = |n: Option<usize>, shape: &str| -> (CellKind, Option<usize>) {
        let name = match n {
            Some(n) if !shape.is_empty() => format!("{n}-node {shape} (Abaqus {ty})"),
            _ => format!("Abaqus {ty}"),
        };
        (CellKind::Other(name), n)
    };
    pub(super) const SOLID: [&str; 5] = ["DCC3D", "DC3D", "AC3D", "C3D", "SC"];
    pub(super) const PLANAR: [&str; 16] = [
        "CPEG", "CPE", "CPS", "CGAX", "CAX", "DCC2D", "DCCAX", "DC2D", "DCAX", "AC2D", "ACAX",
        "SFM3D", "M3D", "R3D", "STRI", "DS",
    ];
    pub(super) const LINE: [&str; 7] = ["DCC1D", "DC1D", "T2D", "T3D", "RB2D", "RB3D", "R2D"];
    for p in SOLID {
        if let Some(n) = count_after(p) {
            return match n {
                4 => (CellKind::Tetra, Some(4)),
                5 => (CellKind::Pyramid, Some(5)),
                6 => (CellKind::Wedge, Some(6)),
                8 => (CellKind::Hexahedron, Some(8)),
                10 => other(Some(10), "tetrahedron"),
                15 => other(Some(15), "wedge"),
                20 => other(Some(n), "hexahedron"),
                27 => (abaqus_lagrange(3), Some(27)),
                _ => other(None, ""),
            };
        }
    }
    // Shells S3, S4, S4R, S8R, ... (checked after "SC" and "SFM3D" above and below).
    let planar = PLANAR
        .iter()
        .find_map(|p| count_after(p))
        .or_else(|| count_after("S"));
    if let Some(n) = planar {
        return match n {
            3 => (CellKind::Triangle, Some(3)),
            4 => (CellKind::Quad, Some(4)),
            6 => other(Some(6), "triangle"),
            8 => other(Some(n), "quadrilateral"),
            9 => (abaqus_lagrange(2), Some(9)),
            _ => other(None, ""),
        };
    }
    if let Some(n) = LINE.iter().find_map(|p| count_after(p)) {
        return match n {
            2 => (CellKind::Line, Some(2)),
            3 => other(Some(3), "line"),
            _ => other(None, ""),
        };
    }
    // Beams and pipes: B21, B31, B23 (cubic, 2 nodes), B22/B32 (3 nodes), PIPE21, ...
    for p in ["B2", "B3", "PIPE2", "PIPE3"] {
        if let Some(n) = count_after(p) {
            return match n {
                1 | 3 => (CellKind::Line, Some(2)),
                2 => other(Some(3), "line"),
                _ => other(None, ""),
            };
        }
    }
    other(None, "")
}

/// The quadratic Lagrange cell of dimension `dim` in Abaqus node order (M3D9, S9R5: corners,
/// mid-edge nodes, centre; C3D27: see [`crate::io::abaqus_write::c3d27`]).
fn abaqus_lagrange(dim: usize) -> CellKind {
    CellKind::Lagrange {
        dim,
        order: 2,
        convention: crate::mesh::raw::NodeConvention::Abaqus,
    }
}

/// Face (or edge) `face` (1-based) of an element as 0-based local node positions, with the
/// facet kind; `None` when the element has no such face.
pub(super) fn element_face(kind: &CellKind, face: usize) -> Option<(CellKind, &'static [usize])> {
    pub(super) const HEX: [[usize; 4]; 6] = [
        [0, 1, 2, 3],
        [4, 7, 6, 5],
        [0, 4, 5, 1],
        [1, 5, 6, 2],
        [2, 6, 7, 3],
        [3, 7, 4, 0],
    ];
    pub(super) const TET: [[usize; 3]; 4] = [[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]];
    pub(super) const WEDGE_TRI: [[usize; 3]; 2] = [[0, 1, 2], [3, 5, 4]];
    pub(super) const WEDGE_QUAD: [[usize; 4]; 3] = [[0, 3, 4, 1], [1, 4, 5, 2], [2, 5, 3, 0]];
    pub(super) const PYR_TRI: [[usize; 3]; 4] = [[0, 4, 1], [1, 4, 2], [2, 4, 3], [3, 4, 0]];
    pub(super) const QUAD: [[usize; 2]; 4] = [[0, 1], [1, 2], [2, 3], [3, 0]];
    pub(super) const TRI: [[usize; 2]; 3] = [[0, 1], [1, 2], [2, 0]];
    let i = face.checked_sub(1)?;
    match kind {
        CellKind::Hexahedron => HEX.get(i).map(|f| (CellKind::Quad, &f[..])),
        CellKind::Tetra => TET.get(i).map(|f| (CellKind::Triangle, &f[..])),
        CellKind::Wedge => match i {
            0 | 1 => Some((CellKind::Triangle, &WEDGE_TRI[i][..])),
            _ => WEDGE_QUAD.get(i - 2).map(|f| (CellKind::Quad, &f[..])),
        },
        CellKind::Pyramid => match i {
            0 => Some((CellKind::Quad, &HEX[0][..])),
            _ => PYR_TRI.get(i - 1).map(|f| (CellKind::Triangle, &f[..])),
        },
        CellKind::Quad => QUAD.get(i).map(|f| (CellKind::Line, &f[..])),
        CellKind::Triangle => TRI.get(i).map(|f| (CellKind::Line, &f[..])),
        _ => None,
    }
}
