//! VTK XML unstructured grids (`.vtu`).
//!
//! Variants read:
//! * `DataArray` formats `ascii`, `binary` (base64 inside the element) and `appended` (an
//!   `<AppendedData>` block after the XML, `encoding="raw"` or `"base64"`, after its `_` marker);
//! * `header_type` `UInt32` (the default) or `UInt64`; data uncompressed or compressed with
//!   `compressor="vtkZLibDataCompressor"` (the block header: count, block size, last block size,
//!   compressed sizes);
//! * `byte_order` `LittleEndian` or `BigEndian`, for headers and data alike;
//! * one or more `<Piece>`s; later pieces' point indices are offset by the earlier pieces'
//!   point counts.
//!
//! From each piece: `Points`, the `Cells` arrays `connectivity`, `offsets` and `types`, and as
//! tags the `CellData` integer array with one component named (most preferred first)
//! `gmsh:physical`, `CellEntityIds`, `medit:ref`, `mat_id`, `MaterialIds` or `attribute`.
//! Cell types map as in the legacy reader ([`super::vtk`]): pixels and voxels are renumbered
//! into quad/hex order; other types become [`CellKind::Other`](crate::mesh::raw::CellKind::Other).
//!
//! Traps: raw appended data is not UTF-8 (or XML), so only the part before `<AppendedData` is
//! parsed as XML; base64 writers encode the header and the data either as one stream (meshio,
//! uncompressed) or as two separately padded streams (VTK; meshio when compressing): both are
//! accepted. In appended base64 data an array's `offset` counts base64 characters.
//!
//! Locations: values of `ascii` arrays are located by line; raw appended data by byte offset in
//! the file; inline base64 data by the line of its `DataArray`; appended base64 data by the byte
//! offset where its encoded block starts.
//!
//! Parts: `xml` parses the XML and locates every array; `decode` turns an array's text or
//! appended block into bytes; `piece` turns bytes into values and a piece into points, cells
//! and tags; [`read`] joins the pieces.

mod decode;
mod piece;
mod xml;

use super::vtk::{CellList, Scalar};
use crate::mesh::raw::{Location, ParseError, RawMesh};
use std::borrow::Cow;
use xml::parse_xml;

/// Parse a `.vtu` file.
pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    let file = parse_xml(data)?;
    let mut mesh = RawMesh::default();
    let mut cells = CellList::default();
    cells.offsets.push(0);
    // VTK reads Lagrange hexahedra of files before version 2.1 in the VTK 8 numbering.
    cells.vtk8_hexes = file.version < (2, 1);
    let mut tags: Vec<i32> = Vec::new();
    let mut any_tags = false;
    for piece in &file.pieces {
        let base = mesh.points.len();
        let n_before = cells.len();
        let piece_tags = file.piece(piece, data, base, &mut mesh, &mut cells)?;
        if let Some(t) = piece_tags {
            if !any_tags {
                tags.resize(n_before, 0);
                any_tags = true;
            }
            tags.extend_from_slice(&t);
        } else if any_tags {
            tags.resize(cells.len(), 0);
        }
    }
    cells.push_to(&mut mesh, &tags)?;
    Ok(mesh)
}

/// 1-based line of byte `pos`.
fn line_at(data: &[u8], pos: usize) -> usize {
    1 + data[..pos.min(data.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Format {
    Ascii,
    Binary,
    Appended(usize),
}

/// A `DataArray` element.
struct Array<'a> {
    name: String,
    ty: Scalar,
    comps: usize,
    format: Format,
    /// Element content (for ascii and binary formats).
    text: Cow<'a, str>,
    /// Byte offset of the content in the file.
    text_pos: usize,
    /// Byte offset of the start tag.
    tag_pos: usize,
}

#[derive(Default)]
struct Piece<'a> {
    n_points: usize,
    n_cells: usize,
    pos: usize,
    points: Option<Array<'a>>,
    connectivity: Option<Array<'a>>,
    offsets: Option<Array<'a>>,
    types: Option<Array<'a>>,
    /// The preferred tag array of the piece's `CellData`, if any.
    tags: Option<(usize, Array<'a>)>,
}

#[derive(Clone, Copy, PartialEq)]
enum Compressor {
    None,
    Zlib,
}

struct Appended<'a> {
    raw: bool,
    /// Everything after the `_` marker.
    data: &'a [u8],
    /// File offset of `data[0]`.
    pos: usize,
    /// For base64: the end of the encoded text, and the sorted offsets of all arrays (an
    /// array's text runs to the next offset).
    end: usize,
    offsets: Vec<usize>,
}

struct File<'a> {
    /// The `version` attribute (major, minor); (0, 0) when missing.
    version: (u32, u32),
    big: bool,
    header64: bool,
    compressor: Compressor,
    /// The `compressor` attribute when it names one this reader does not know.
    unknown_compressor: Option<String>,
    pieces: Vec<Piece<'a>>,
    appended: Option<Appended<'a>>,
}

/// Where the values of a decoded array were found.
enum Locs {
    Lines(Vec<u32>),
    Bytes { start: usize, stride: usize },
    Fixed(Location),
}

impl Locs {
    fn at(&self, i: usize) -> Location {
        match self {
            Locs::Lines(l) => l
                .get(i)
                .map_or(Location::File, |&l| Location::Line(l as usize)),
            Locs::Bytes { start, stride } => Location::Byte(start + i * stride),
            Locs::Fixed(l) => *l,
        }
    }
}

#[cfg(test)]
mod tests;
