//! Values of data arrays and the assembly of one `<Piece>` into the mesh.
//!
//! Input: a located [`Piece`]. Output: its points appended to the [`RawMesh`], its cells to the
//! [`CellList`] (point indices offset by the earlier pieces' point counts), and its tags if it
//! has a tag array. Invariants: every array has the length the piece's counts declare; offsets
//! are nondecreasing and within the connectivity; a point index outside the piece is an error at
//! the value that names it.

use super::{Array, File, Format, Locs, Piece, line_at};
use crate::io::text::parse_f64;
use crate::io::vtk::{CellList, Scalar};
use crate::mesh::raw::{Location, ParseError, RawMesh};

/// Values of an ascii `DataArray`, with the line of each value if `lines`.
pub(super) fn ascii_values<T>(
    arr: &Array,
    data: &[u8],
    lines: bool,
    parse: impl Fn(&str) -> Option<T>,
) -> Result<(Vec<T>, Locs), ParseError> {
    let text = arr.text.as_ref();
    let bytes = text.as_bytes();
    let mut line = line_at(data, arr.text_pos);
    let mut values = Vec::new();
    let mut value_lines = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        if b.is_ascii_whitespace() {
            if b == b'\n' {
                line += 1;
            }
            i += 1;
            continue;
        }
        let start = i;
        while i < bytes.len() && !bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        let token = &text[start..i];
        let v = parse(token).ok_or_else(|| {
            let shown: String = token.chars().take(40).collect();
            ParseError::at_line(
                line,
                format!(
                    "DataArray {}: expected a number, found \"{shown}\"",
                    arr.name
                ),
            )
        })?;
        values.push(v);
        if lines {
            value_lines.push(u32::try_from(line).unwrap_or(u32::MAX));
        }
    }
    let locs = if lines {
        Locs::Lines(value_lines)
    } else {
        Locs::Fixed(Location::Line(line_at(data, arr.tag_pos)))
    };
    Ok((values, locs))
}

impl<'a> File<'a> {
    /// Decode the array as integers.
    pub(super) fn ints(
        &self,
        arr: &Array<'a>,
        data: &'a [u8],
        lines: bool,
    ) -> Result<(Vec<i64>, Locs), ParseError> {
        if !arr.ty.is_int() || arr.ty == Scalar::Bit {
            return Err(ParseError::at_line(
                line_at(data, arr.tag_pos),
                format!(
                    "DataArray {} must have an integer type, found {:?}",
                    arr.name, arr.ty
                ),
            ));
        }
        self.values(
            arr,
            data,
            lines,
            |t| t.parse().ok(),
            |b| arr.ty.int_at(b, self.big),
        )
    }

    /// Decode the array as floats.
    pub(super) fn floats(
        &self,
        arr: &Array<'a>,
        data: &'a [u8],
        lines: bool,
    ) -> Result<(Vec<f64>, Locs), ParseError> {
        if matches!(arr.ty, Scalar::Bit | Scalar::Str) {
            return Err(ParseError::at_line(
                line_at(data, arr.tag_pos),
                format!(
                    "DataArray {} must have a numeric type, found {:?}",
                    arr.name, arr.ty
                ),
            ));
        }
        self.values(arr, data, lines, parse_f64, |b| {
            arr.ty.float_at(b, self.big)
        })
    }

    pub(super) fn values<T>(
        &self,
        arr: &Array<'a>,
        data: &'a [u8],
        lines: bool,
        parse: impl Fn(&str) -> Option<T>,
        decode: impl Fn(&[u8]) -> T,
    ) -> Result<(Vec<T>, Locs), ParseError> {
        if arr.format == Format::Ascii {
            return ascii_values(arr, data, lines, parse);
        }
        let (bytes, mut locs) = self.bytes(arr, data)?;
        let size = arr.ty.size();
        if bytes.len() % size != 0 {
            return Err(ParseError::new(
                locs.at(0),
                format!(
                    "DataArray {}: {} bytes is not a whole number of {size}-byte values",
                    arr.name,
                    bytes.len()
                ),
            ));
        }
        if let Locs::Bytes { stride, .. } = &mut locs {
            *stride = size;
        }
        Ok((bytes.chunks_exact(size).map(decode).collect(), locs))
    }

    /// Read one piece into `mesh` and `cells`; returns its tags, if it has a tag array.
    pub(super) fn piece(
        &self,
        piece: &Piece<'a>,
        data: &'a [u8],
        base: usize,
        mesh: &mut RawMesh,
        cells: &mut CellList,
    ) -> Result<Option<Vec<i32>>, ParseError> {
        let line = Location::Line(line_at(data, piece.pos));
        let missing = |what: &str| ParseError::new(line, format!("<Piece> has no {what} array"));
        let count_error = |arr: &Array, found: usize, want: usize| {
            ParseError::at_line(
                line_at(data, arr.tag_pos),
                format!(
                    "DataArray {} holds {found} values, expected {want}",
                    arr.name
                ),
            )
        };

        // Points.
        if piece.n_points > 0 {
            let arr = piece.points.as_ref().ok_or_else(|| missing("Points"))?;
            if !(2..=3).contains(&arr.comps) {
                return Err(ParseError::at_line(
                    line_at(data, arr.tag_pos),
                    format!("Points have {} components, expected 3", arr.comps),
                ));
            }
            let (xyz, locs) = self.floats(arr, data, true)?;
            let want = piece.n_points.saturating_mul(arr.comps);
            if xyz.len() != want {
                return Err(count_error(arr, xyz.len(), want));
            }
            for (i, p) in xyz.chunks_exact(arr.comps).enumerate() {
                mesh.points
                    .push([p[0], p[1], p.get(2).copied().unwrap_or(0.0)]);
                mesh.point_locations.push(locs.at(i * arr.comps));
            }
        }
        if piece.n_cells == 0 {
            return Ok(None);
        }

        // Cells: offsets are cell ends (a leading 0 is tolerated).
        let off_arr = piece.offsets.as_ref().ok_or_else(|| missing("offsets"))?;
        let (mut offsets, off_locs) = self.ints(off_arr, data, false)?;
        if Some(offsets.len()) == piece.n_cells.checked_add(1) && offsets.first() == Some(&0) {
            offsets.remove(0);
        }
        if offsets.len() != piece.n_cells {
            return Err(count_error(off_arr, offsets.len(), piece.n_cells));
        }
        let conn_arr = piece
            .connectivity
            .as_ref()
            .ok_or_else(|| missing("connectivity"))?;
        let (conn, conn_locs) = self.ints(conn_arr, data, true)?;
        let types_arr = piece.types.as_ref().ok_or_else(|| missing("types"))?;
        let (types, _) = self.ints(types_arr, data, false)?;
        if types.len() != piece.n_cells {
            return Err(count_error(types_arr, types.len(), piece.n_cells));
        }
        let base_conn = cells.conn.len();
        let mut prev = 0i64;
        for (c, &end) in offsets.iter().enumerate() {
            if end < prev || end as u64 > conn.len() as u64 {
                return Err(ParseError::new(
                    off_locs.at(c),
                    format!(
                        "offset {c} is {end}: offsets must not decrease or exceed the connectivity size {}",
                        conn.len()
                    ),
                ));
            }
            let start = prev as usize;
            cells.locations.push(if start < conn.len() {
                conn_locs.at(start)
            } else {
                Location::Line(line_at(data, conn_arr.tag_pos))
            });
            cells.offsets.push(base_conn + end as usize);
            prev = end;
        }
        if prev as usize != conn.len() {
            return Err(ParseError::new(
                off_locs.at(piece.n_cells - 1),
                format!(
                    "the last offset is {prev}, but the connectivity holds {} entries",
                    conn.len()
                ),
            ));
        }
        let shift = base as i64;
        cells
            .conn
            .extend(conn.iter().map(|&v| v.saturating_add(shift)));
        cells.types.extend_from_slice(&types);

        // Tags.
        let Some((_, arr)) = &piece.tags else {
            return Ok(None);
        };
        let (values, locs) = self.ints(arr, data, true)?;
        if values.len() != piece.n_cells {
            return Err(count_error(arr, values.len(), piece.n_cells));
        }
        crate::io::vtk::tags_to_i32(&values, &arr.name, |i| locs.at(i)).map(Some)
    }
}
