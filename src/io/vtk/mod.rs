//! VTK legacy files (`.vtk`), `DATASET UNSTRUCTURED_GRID` only.
//!
//! Variants read:
//! * file versions 2.0, 3.0 and 4.x (`CELLS n size`, then per cell a node count and its nodes)
//!   and 5.x (`CELLS n_offsets n_connectivity`, then `OFFSETS type` and `CONNECTIVITY type`
//!   arrays); the layout is taken from what follows `CELLS`, not from the version number;
//! * `ASCII` and `BINARY`; binary data is big-endian, as the format specifies, and starts on
//!   the line after its header line (`POINTS 8 float`);
//! * points of any numeric type (`float`, `double`, integers, `vtktypeint64`, ...).
//!
//! Cell types 1 (vertex), 3 (line), 5 (triangle), 9 (quad), 10 (tetra), 12 (hexahedron),
//! 13 (wedge) and 14 (pyramid) keep their kind. Pixels (8) and voxels (11) are axis-aligned
//! quads and hexes numbered lexicographically; they are renumbered into quad/hex order. Every
//! other type (polygons, quadratic and Lagrange cells, ...) becomes [`CellKind::Other`] named by
//! its node count and VTK type.
//!
//! Tags: a `CELL_DATA` integer array with one component, given as `SCALARS` or as a `FIELD`
//! array, named (most preferred first) `gmsh:physical`, `CellEntityIds`, `medit:ref`,
//! `mat_id`, `MaterialIds` or `attribute`. All other `POINT_DATA`, `CELL_DATA`, `FIELD` and
//! `METADATA` content is skipped. The format has no tag names.
//!
//! Traps: meshio writes 5.1 files with `FIELD` arrays (not `SCALARS`); `SCALARS` takes an
//! optional component count before its `LOOKUP_TABLE` line; binary blocks may contain newline
//! bytes. Errors inside binary blocks name byte offsets; errors in the text between them name
//! lines as a text editor counts them (every newline byte, including those in binary data).
//!
//! Parts: this module runs the keyword loop (`Legacy::parse`); `values` reads the header
//! and the ASCII or binary values of a section; `sections` reads each section; `cells`
//! (cell types, the cell list) and `scalar` (data types) are shared with the XML reader.
//!
//! [`CellKind`]: crate::mesh::raw::CellKind
//! [`CellKind::Other`]: crate::mesh::raw::CellKind::Other

mod cells;
mod scalar;
mod sections;
mod values;

pub(crate) use cells::{CellList, tags_to_i32};
pub(crate) use scalar::Scalar;

use super::text::TextCursor;
use crate::mesh::raw::{Location, ParseError, RawMesh};

/// Names of cell data arrays that hold cell tags, most preferred first.
pub(crate) const TAG_ARRAYS: [&str; 7] = [
    "gmsh:physical",
    "CellEntityIds",
    "medit:ref",
    "mat_id",
    "MaterialIds",
    "attribute",
    // polyspline's own VTU output.
    "tag",
];

/// Preference of a cell data array as the tag array (lower is better), if it is one.
pub(crate) fn tag_priority(name: &str) -> Option<usize> {
    TAG_ARRAYS.iter().position(|&n| n == name)
}

/// Parse a VTK legacy file.
pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    Legacy {
        cur: TextCursor::new(data),
        binary: false,
        version: (0, 0),
    }
    .parse()
}

/// Which attribute section (`POINT_DATA n` / `CELL_DATA n`) the parser is in.
#[derive(Clone, Copy, PartialEq)]
enum Section {
    None,
    Point(usize),
    Cell(usize),
}

struct Legacy<'a> {
    cur: TextCursor<'a>,
    binary: bool,
    /// File version from the first line (major, minor); (0, 0) if unreadable.
    version: (u32, u32),
}

/// The best tag array found so far: its preference and values.
type TagCandidate = Option<(usize, Vec<i32>)>;

impl<'a> Legacy<'a> {
    fn parse(&mut self) -> Result<RawMesh, ParseError> {
        self.header()?;
        let mut mesh = RawMesh::default();
        let mut dataset = false;
        let mut have_points = false;
        let mut cells: Option<CellList> = None;
        let mut have_types = false;
        let mut section = Section::None;
        let mut tags: TagCandidate = None;

        while let Some(kw) = self.cur.next_token() {
            let is = |k: &str| kw.eq_ignore_ascii_case(k);
            if is("DATASET") {
                let t = self.cur.expect_token("dataset type")?;
                if !t.eq_ignore_ascii_case("UNSTRUCTURED_GRID") {
                    return Err(self.cur.error(format!(
                        "DATASET {t} is not supported: only DATASET UNSTRUCTURED_GRID holds a general mesh"
                    )));
                }
                dataset = true;
                continue;
            }
            if is("FIELD") {
                self.field(section, &mut tags)?;
                continue;
            }
            if is("METADATA") {
                self.metadata();
                continue;
            }
            if !dataset {
                return Err(self.cur.expected("DATASET UNSTRUCTURED_GRID", kw));
            }
            if is("POINTS") {
                if have_points {
                    return Err(self.cur.error("second POINTS section"));
                }
                self.points(&mut mesh)?;
                have_points = true;
            } else if is("CELLS") {
                if cells.is_some() {
                    return Err(self.cur.error("second CELLS section"));
                }
                cells = Some(self.cells()?);
            } else if is("CELL_TYPES") {
                let Some(list) = cells.as_mut() else {
                    return Err(self.cur.error("CELL_TYPES before CELLS"));
                };
                if have_types {
                    return Err(self.cur.error("second CELL_TYPES section"));
                }
                self.cell_types(list)?;
                have_types = true;
            } else if is("POINT_DATA") {
                section = Section::Point(self.cur.usize("number of POINT_DATA values")?);
            } else if is("CELL_DATA") {
                let n = self.cur.usize("number of CELL_DATA values")?;
                let have = cells.as_ref().map_or(0, CellList::len_declared);
                if n != have {
                    return Err(self.cur.error(format!(
                        "CELL_DATA declares {n} values but the grid has {have} cells"
                    )));
                }
                section = Section::Cell(n);
            } else if let Section::Point(n) | Section::Cell(n) = section {
                self.attribute(kw, n, matches!(section, Section::Cell(_)), &mut tags)?;
            } else {
                return Err(self.cur.expected(
                    "POINTS, CELLS, CELL_TYPES, POINT_DATA, CELL_DATA or FIELD",
                    kw,
                ));
            }
        }

        if !dataset {
            return Err(ParseError::at_line(
                self.cur.line(),
                "no DATASET UNSTRUCTURED_GRID in the file",
            ));
        }
        if !have_points {
            return Err(ParseError::new(
                Location::File,
                "the file has no POINTS section",
            ));
        }
        if let Some(list) = cells {
            if !have_types {
                return Err(ParseError::new(
                    Location::File,
                    "the file has CELLS but no CELL_TYPES section",
                ));
            }
            let tags = tags.map(|(_, t)| t).unwrap_or_default();
            // VTK reads Lagrange hexahedra of files before 5.1 in the VTK 8 numbering.
            let mut list = list;
            list.vtk8_hexes = self.version < (5, 1);
            list.push_to(&mut mesh, &tags)?;
        }
        Ok(mesh)
    }
}

#[cfg(test)]
mod tests;
