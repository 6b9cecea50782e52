//! The XML part of a `.vtu` file: the `<VTKFile>` attributes, the pieces and their
//! `DataArray`s, and where the appended data starts.
//!
//! Input: the file bytes. Output: a [`File`] whose arrays still hold their undecoded text (ascii
//! and inline base64) or their offset into the appended block. Invariants: XML is parsed only
//! up to `<AppendedData>` (raw appended data is arbitrary bytes); of each piece's `CellData`
//! only the preferred tag array is kept; errors name the line of the element at fault.

use super::{Appended, Array, Compressor, File, Format, Piece, line_at};
use crate::io::vtk::{Scalar, tag_priority};
use crate::mesh::raw::{Location, ParseError};
use quick_xml::Reader;
use quick_xml::events::{BytesStart, Event};
use std::borrow::Cow;

pub(super) fn xml_error(data: &[u8], pos: u64, e: impl std::fmt::Display) -> ParseError {
    ParseError::at_line(line_at(data, pos as usize), format!("invalid XML: {e}"))
}

/// The value of attribute `key`, if present.
pub(super) fn attr<'b>(
    e: &'b BytesStart,
    key: &str,
    data: &[u8],
    pos: usize,
) -> Result<Option<Cow<'b, str>>, ParseError> {
    match e.try_get_attribute(key) {
        Ok(a) => Ok(a.map(|a| a.value)),
        Err(err) => Err(xml_error(data, pos as u64, err)),
    }
}

pub(super) fn parse_count(
    v: Option<Cow<str>>,
    what: &str,
    line: usize,
) -> Result<usize, ParseError> {
    let v = v.ok_or_else(|| ParseError::at_line(line, format!("missing attribute {what}")))?;
    v.trim().parse().map_err(|_| {
        ParseError::at_line(line, format!("expected a count for {what}, found \"{v}\""))
    })
}

/// Parse the XML part of the file and locate the appended data.
pub(super) fn parse_xml(data: &[u8]) -> Result<File<'_>, ParseError> {
    let mut reader = Reader::from_reader(data);
    let mut file = File {
        version: (0, 0),
        big: false,
        header64: false,
        compressor: Compressor::None,
        unknown_compressor: None,
        pieces: Vec::new(),
        appended: None,
    };
    let mut seen_root = false;
    // Which of Points / Cells / CellData the parser is inside.
    let mut context = "";
    // Raw appended data is arbitrary bytes, not XML: parsing stops at its start tag.
    let mut appended: Option<(usize, usize, String)> = None;
    let mut current: Option<Array> = None;
    // Depth of elements nested in the current DataArray (VTK writes <InformationKey> there);
    // their text is not array data.
    let mut nested = 0usize;
    loop {
        let pos = reader.buffer_position() as usize;
        let ev = reader
            .read_event()
            .map_err(|e| xml_error(data, reader.error_position(), e))?;
        let (start, empty) = match &ev {
            Event::Start(e) => (Some(e), false),
            Event::Empty(e) => (Some(e), true),
            _ => (None, false),
        };
        if let Some(e) = start {
            if current.is_some() {
                if !empty {
                    nested += 1;
                }
                continue;
            }
            let name = e.name();
            let name = name.as_ref();
            let line = || line_at(data, pos);
            if !seen_root {
                if name != "VTKFile" {
                    return Err(ParseError::at_line(
                        line(),
                        format!("expected a <VTKFile> element, found <{name}>"),
                    ));
                }
                seen_root = true;
                root_attributes(&mut file, e, data, pos)?;
                continue;
            }
            match name {
                "AppendedData" => {
                    let encoding = attr(e, "encoding", data, pos)?.unwrap_or(Cow::Borrowed("raw"));
                    appended = Some((
                        pos,
                        reader.buffer_position() as usize,
                        encoding.into_owned(),
                    ));
                    break;
                }
                "Piece" => file.pieces.push(piece_start(e, data, pos)?),
                "Points" | "Cells" | "CellData" if !empty => context = name_static(name),
                "PointData" | "FieldData" if !empty => context = "",
                "DataArray" => {
                    let arr = data_array(e, data, pos, context, reader.buffer_position() as usize)?;
                    let format = arr.format;
                    if let Format::Appended(off) = format {
                        // Every appended array delimits the base64 text of the one before.
                        file.appended_offsets().push(off);
                    }
                    if empty {
                        file.store(context, arr);
                    } else {
                        current = Some(arr);
                    }
                }
                _ => {}
            }
            continue;
        }
        match ev {
            Event::Text(t) if nested == 0 => {
                if let Some(arr) = current.as_mut() {
                    append(&mut arr.text, t.into_inner());
                }
            }
            Event::CData(t) if nested == 0 => {
                if let Some(arr) = current.as_mut() {
                    append(&mut arr.text, t.into_inner());
                }
            }
            Event::End(_) if nested > 0 => nested -= 1,
            Event::End(e) => match e.name().as_ref() {
                "DataArray" => {
                    if let Some(arr) = current.take() {
                        file.store(context, arr);
                    }
                }
                "Points" | "Cells" | "CellData" | "PointData" | "FieldData" => context = "",
                _ => {}
            },
            Event::Eof => break,
            _ => {}
        }
    }
    if !seen_root {
        return Err(ParseError::new(
            Location::File,
            "no <VTKFile> element: not a VTK XML file",
        ));
    }
    if let Some((at, after, encoding)) = appended {
        file.locate_appended(data, at, after, &encoding)?;
    }
    Ok(file)
}

/// The `<VTKFile>` attributes: type (must be `UnstructuredGrid`), version, byte order,
/// header type and compressor.
fn root_attributes(
    file: &mut File,
    e: &BytesStart,
    data: &[u8],
    pos: usize,
) -> Result<(), ParseError> {
    let line = || line_at(data, pos);
    let ty = attr(e, "type", data, pos)?.unwrap_or_default();
    if ty != "UnstructuredGrid" {
        return Err(ParseError::at_line(
            line(),
            format!("VTK XML file of type \"{ty}\": only UnstructuredGrid (.vtu) is supported"),
        ));
    }
    if let Some(v) = attr(e, "version", data, pos)?
        && let Some((major, minor)) = v.trim().split_once('.')
    {
        file.version = (major.parse().unwrap_or(0), minor.parse().unwrap_or(0));
    }
    match attr(e, "byte_order", data, pos)?.as_deref() {
        None | Some("LittleEndian") => {}
        Some("BigEndian") => file.big = true,
        Some(o) => {
            return Err(ParseError::at_line(
                line(),
                format!("unknown byte_order \"{o}\""),
            ));
        }
    }
    match attr(e, "header_type", data, pos)?.as_deref() {
        None | Some("UInt32") => {}
        Some("UInt64") => file.header64 = true,
        Some(h) => {
            return Err(ParseError::at_line(
                line(),
                format!("unknown header_type \"{h}\" (expected UInt32 or UInt64)"),
            ));
        }
    }
    match attr(e, "compressor", data, pos)?.as_deref() {
        None | Some("") => {}
        Some("vtkZLibDataCompressor") => file.compressor = Compressor::Zlib,
        Some(c) => file.unknown_compressor = Some(c.to_string()),
    }
    Ok(())
}

/// A `<Piece>` start tag: its point and cell counts.
fn piece_start<'a>(e: &BytesStart, data: &[u8], pos: usize) -> Result<Piece<'a>, ParseError> {
    let l = line_at(data, pos);
    Ok(Piece {
        n_points: parse_count(attr(e, "NumberOfPoints", data, pos)?, "NumberOfPoints", l)?,
        n_cells: parse_count(attr(e, "NumberOfCells", data, pos)?, "NumberOfCells", l)?,
        pos,
        ..Default::default()
    })
}

/// A `DataArray` start tag in `context` (`Points`, `Cells`, `CellData` or none); its text
/// starts at `text_pos`.
fn data_array<'a>(
    e: &BytesStart,
    data: &[u8],
    pos: usize,
    context: &str,
    text_pos: usize,
) -> Result<Array<'a>, ParseError> {
    let l = line_at(data, pos);
    let ty_name = attr(e, "type", data, pos)?.unwrap_or_default();
    // Arrays of unknown types matter only where the mesh is read from.
    let ty = match Scalar::xml(&ty_name) {
        Some(t) => t,
        None if matches!(context, "Points" | "Cells") => {
            return Err(ParseError::at_line(
                l,
                format!("unknown DataArray type \"{ty_name}\""),
            ));
        }
        None => Scalar::Str,
    };
    let comps = match attr(e, "NumberOfComponents", data, pos)? {
        Some(c) => parse_count(Some(c), "NumberOfComponents", l)?,
        None => 1,
    };
    let format = match attr(e, "format", data, pos)?.as_deref() {
        Some("ascii") => Format::Ascii,
        Some("binary") => Format::Binary,
        Some("appended") => {
            Format::Appended(parse_count(attr(e, "offset", data, pos)?, "offset", l)?)
        }
        other => {
            return Err(ParseError::at_line(
                l,
                format!("DataArray format must be ascii, binary or appended, found {other:?}"),
            ));
        }
    };
    Ok(Array {
        name: attr(e, "Name", data, pos)?.unwrap_or_default().into_owned(),
        ty,
        comps,
        format,
        text: Cow::Borrowed(""),
        text_pos,
        tag_pos: pos,
    })
}

pub(super) fn name_static(name: &str) -> &'static str {
    match name {
        "Points" => "Points",
        "Cells" => "Cells",
        "CellData" => "CellData",
        _ => "",
    }
}

pub(super) fn append<'a>(text: &mut Cow<'a, str>, more: Cow<'a, str>) {
    if text.is_empty() {
        *text = more;
    } else {
        text.to_mut().push_str(&more);
    }
}

/// Whether the CellData array `a` could hold tags.
pub(super) fn tag_like(a: &Array) -> Option<usize> {
    tag_priority(&a.name).filter(|_| a.comps == 1 && a.ty.is_int() && a.ty != Scalar::Bit)
}

impl<'a> File<'a> {
    /// Offsets of appended arrays collect here until the appended block is located.
    pub(super) fn appended_offsets(&mut self) -> &mut Vec<usize> {
        &mut self
            .appended
            .get_or_insert(Appended {
                raw: true,
                data: &[],
                pos: 0,
                end: 0,
                offsets: Vec::new(),
            })
            .offsets
    }

    pub(super) fn store(&mut self, context: &str, arr: Array<'a>) {
        let Some(piece) = self.pieces.last_mut() else {
            return;
        };
        match context {
            "Points" if piece.points.is_none() => piece.points = Some(arr),
            "Cells" => match arr.name.as_str() {
                "connectivity" => piece.connectivity = Some(arr),
                "offsets" => piece.offsets = Some(arr),
                "types" => piece.types = Some(arr),
                _ => {}
            },
            "CellData" => {
                if let Some(p) = tag_like(&arr)
                    && piece.tags.as_ref().is_none_or(|(q, _)| p < *q)
                {
                    piece.tags = Some((p, arr));
                }
            }
            _ => {}
        }
    }

    /// Find the `_` that starts the appended data after the `<AppendedData>` tag at `at`
    /// (which ends before `after`).
    pub(super) fn locate_appended(
        &mut self,
        data: &'a [u8],
        at: usize,
        after: usize,
        encoding: &str,
    ) -> Result<(), ParseError> {
        let raw = match encoding {
            "raw" => true,
            "base64" => false,
            other => {
                return Err(ParseError::at_line(
                    line_at(data, at),
                    format!("unknown AppendedData encoding \"{other}\" (expected raw or base64)"),
                ));
            }
        };
        let mut u = after;
        while u < data.len() && data[u].is_ascii_whitespace() {
            u += 1;
        }
        if data.get(u) != Some(&b'_') {
            return Err(ParseError::at_byte(
                u,
                "expected '_' at the start of the appended data",
            ));
        }
        let start = u + 1;
        let rest = &data[start..];
        let end = if raw {
            rest.len()
        } else {
            // Base64 text ends at the first byte outside its alphabet (whitespace, '<').
            rest.iter()
                .position(|&b| !(b.is_ascii_alphanumeric() || b == b'+' || b == b'/' || b == b'='))
                .unwrap_or(rest.len())
        };
        let mut offsets = self.appended.take().map(|a| a.offsets).unwrap_or_default();
        offsets.sort_unstable();
        offsets.dedup();
        self.appended = Some(Appended {
            raw,
            data: rest,
            pos: start,
            end,
            offsets,
        });
        Ok(())
    }
}
