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
//! into quad/hex order; other types become [`CellKind::Other`](super::raw::CellKind::Other).
//!
//! Traps: raw appended data is not UTF-8 (or XML), so only the part before `<AppendedData` is
//! parsed as XML; base64 writers encode the header and the data either as one stream (meshio,
//! uncompressed) or as two separately padded streams (VTK; meshio when compressing): both are
//! accepted. In appended base64 data an array's `offset` counts base64 characters.
//!
//! Locations: values of `ascii` arrays are located by line; raw appended data by byte offset in
//! the file; inline base64 data by the line of its `DataArray`; appended base64 data by the byte
//! offset where its encoded block starts.

use super::raw::{Location, ParseError, RawMesh};
use super::vtk::{CellList, Scalar, tag_priority};
use base64::Engine;
use base64::engine::general_purpose::STANDARD_PAD_INDIFFERENT;
use quick_xml::Reader;
use quick_xml::events::{BytesStart, Event};
use std::borrow::Cow;
use std::io::Read;

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

fn xml_error(data: &[u8], pos: u64, e: impl std::fmt::Display) -> ParseError {
    ParseError::at_line(line_at(data, pos as usize), format!("invalid XML: {e}"))
}

/// The value of attribute `key`, if present.
fn attr<'b>(
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

fn parse_count(v: Option<Cow<str>>, what: &str, line: usize) -> Result<usize, ParseError> {
    let v = v.ok_or_else(|| ParseError::at_line(line, format!("missing attribute {what}")))?;
    v.trim().parse().map_err(|_| {
        ParseError::at_line(line, format!("expected a count for {what}, found \"{v}\""))
    })
}

/// Parse the XML part of the file and locate the appended data.
fn parse_xml(data: &[u8]) -> Result<File<'_>, ParseError> {
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
                let ty = attr(e, "type", data, pos)?.unwrap_or_default();
                if ty != "UnstructuredGrid" {
                    return Err(ParseError::at_line(
                        line(),
                        format!(
                            "VTK XML file of type \"{ty}\": only UnstructuredGrid (.vtu) is supported"
                        ),
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
                "Piece" => {
                    let l = line();
                    file.pieces.push(Piece {
                        n_points: parse_count(
                            attr(e, "NumberOfPoints", data, pos)?,
                            "NumberOfPoints",
                            l,
                        )?,
                        n_cells: parse_count(
                            attr(e, "NumberOfCells", data, pos)?,
                            "NumberOfCells",
                            l,
                        )?,
                        pos,
                        ..Default::default()
                    });
                }
                "Points" | "Cells" | "CellData" if !empty => context = name_static(name),
                "PointData" | "FieldData" if !empty => context = "",
                "DataArray" => {
                    let l = line();
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
                        Some("appended") => Format::Appended(parse_count(
                            attr(e, "offset", data, pos)?,
                            "offset",
                            l,
                        )?),
                        other => {
                            return Err(ParseError::at_line(
                                l,
                                format!(
                                    "DataArray format must be ascii, binary or appended, found {other:?}"
                                ),
                            ));
                        }
                    };
                    let arr = Array {
                        name: attr(e, "Name", data, pos)?.unwrap_or_default().into_owned(),
                        ty,
                        comps,
                        format,
                        text: Cow::Borrowed(""),
                        text_pos: reader.buffer_position() as usize,
                        tag_pos: pos,
                    };
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

fn name_static(name: &str) -> &'static str {
    match name {
        "Points" => "Points",
        "Cells" => "Cells",
        "CellData" => "CellData",
        _ => "",
    }
}

fn append<'a>(text: &mut Cow<'a, str>, more: Cow<'a, str>) {
    if text.is_empty() {
        *text = more;
    } else {
        text.to_mut().push_str(&more);
    }
}

/// Whether the CellData array `a` could hold tags.
fn tag_like(a: &Array) -> Option<usize> {
    tag_priority(&a.name).filter(|_| a.comps == 1 && a.ty.is_int() && a.ty != Scalar::Bit)
}

impl<'a> File<'a> {
    /// Offsets of appended arrays collect here until the appended block is located.
    fn appended_offsets(&mut self) -> &mut Vec<usize> {
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

    fn store(&mut self, context: &str, arr: Array<'a>) {
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
    fn locate_appended(
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

    fn header_size(&self) -> usize {
        if self.header64 { 8 } else { 4 }
    }

    fn header_word(&self, b: &[u8]) -> u64 {
        let ty = if self.header64 {
            Scalar::U64
        } else {
            Scalar::U32
        };
        ty.int_at(b, self.big) as u64
    }

    /// The decoded bytes of a binary or appended array and where they were found.
    fn bytes(&self, arr: &Array<'a>, data: &'a [u8]) -> Result<(Cow<'a, [u8]>, Locs), ParseError> {
        let tag_line = Location::Line(line_at(data, arr.tag_pos));
        if let Some(c) = &self.unknown_compressor {
            return Err(ParseError::new(
                tag_line,
                format!("compressor {c} is not supported (only vtkZLibDataCompressor)"),
            ));
        }
        match arr.format {
            Format::Ascii => Ok((Cow::Borrowed(&[][..]), Locs::Fixed(tag_line))),
            Format::Binary => {
                let text = arr.text.trim_ascii().as_bytes();
                // Writers put the base64 text on one line; strip inner whitespace only if any.
                let text: Cow<[u8]> = if text.iter().any(u8::is_ascii_whitespace) {
                    Cow::Owned(
                        text.iter()
                            .copied()
                            .filter(|b| !b.is_ascii_whitespace())
                            .collect(),
                    )
                } else {
                    Cow::Borrowed(text)
                };
                let bytes = self.decode_base64(&text, tag_line, &arr.name)?;
                Ok((Cow::Owned(bytes), Locs::Fixed(tag_line)))
            }
            Format::Appended(off) => {
                let app = self
                    .appended
                    .as_ref()
                    .filter(|a| a.pos > 0)
                    .ok_or_else(|| {
                        ParseError::new(
                            tag_line,
                            format!(
                                "DataArray {} is appended but the file has no <AppendedData>",
                                arr.name
                            ),
                        )
                    })?;
                if app.raw {
                    self.raw_appended(app, off, &arr.name)
                } else {
                    let loc = Location::Byte(app.pos.saturating_add(off));
                    let next = app
                        .offsets
                        .iter()
                        .copied()
                        .find(|&o| o > off)
                        .unwrap_or(app.end);
                    let text = app.data.get(off..next.min(app.end)).ok_or_else(|| {
                        ParseError::new(
                            tag_line,
                            format!(
                                "DataArray {}: offset {off} is past the end of the appended data",
                                arr.name
                            ),
                        )
                    })?;
                    let bytes = self.decode_base64(text, loc, &arr.name)?;
                    Ok((Cow::Owned(bytes), Locs::Fixed(loc)))
                }
            }
        }
    }

    /// One array in raw appended data at `off`: header, then plain or compressed bytes.
    fn raw_appended(
        &self,
        app: &Appended<'a>,
        off: usize,
        name: &str,
    ) -> Result<(Cow<'a, [u8]>, Locs), ParseError> {
        let h = self.header_size();
        let at = |i: usize| app.pos.saturating_add(off).saturating_add(i);
        let short = |what: &str, need: usize| {
            ParseError::at_byte(
                at(0),
                format!(
                    "DataArray {name}: appended data ends inside the {what} (needs {need} more bytes)"
                ),
            )
        };
        let word = |i: usize| -> Result<u64, ParseError> {
            let s = off
                .checked_add(i * h)
                .and_then(|s| app.data.get(s..s.checked_add(h)?));
            s.map(|b| self.header_word(b))
                .ok_or_else(|| short("header", h))
        };
        if self.compressor == Compressor::None {
            let n = word(0)?;
            let start = off.saturating_add(h);
            let body = usize::try_from(n)
                .ok()
                .and_then(|n| app.data.get(start..start.checked_add(n)?))
                .ok_or_else(|| short("data", n as usize))?;
            return Ok((
                Cow::Borrowed(body),
                Locs::Bytes {
                    start: app.pos + start,
                    stride: 0,
                },
            ));
        }
        let nb = word(0)?;
        if nb > (app.data.len() / h) as u64 {
            return Err(ParseError::at_byte(
                at(0),
                format!("DataArray {name}: compression header claims {nb} blocks"),
            ));
        }
        let nb = nb as usize;
        let words: Vec<u64> = (0..3 + nb).map(word).collect::<Result<_, _>>()?;
        let start = off.saturating_add((3 + nb) * h);
        let body = app.data.get(start..).unwrap_or(&[]);
        let out = inflate(&words, body, Location::Byte(at((3 + nb) * h)), name)?;
        Ok((Cow::Owned(out), Locs::Fixed(Location::Byte(at(0)))))
    }

    /// Decode base64 `text` (no whitespace) holding a header and data, encoded either as one
    /// stream or as two separately padded streams.
    fn decode_base64(&self, text: &[u8], loc: Location, name: &str) -> Result<Vec<u8>, ParseError> {
        let h = self.header_size();
        let chars = |bytes: usize| bytes.div_ceil(3) * 4;
        let b64 = |t: &[u8]| {
            STANDARD_PAD_INDIFFERENT.decode(t).map_err(|e| {
                ParseError::new(loc, format!("DataArray {name}: invalid base64 data: {e}"))
            })
        };
        let short = || {
            ParseError::new(
                loc,
                format!("DataArray {name}: base64 data too short for its header"),
            )
        };
        let compressed = self.compressor == Compressor::Zlib;
        // Header length in bytes: one word, or three plus one per compressed block.
        let hbytes = if compressed {
            let pre = b64(text.get(..4 * h).ok_or_else(short)?)?;
            let nb = self.header_word(&pre);
            if nb > (text.len() / h) as u64 {
                return Err(ParseError::new(
                    loc,
                    format!("DataArray {name}: compression header claims {nb} blocks"),
                ));
            }
            (3 + nb as usize) * h
        } else {
            h
        };
        let hc = chars(hbytes);
        let head_text = text.get(..hc).ok_or_else(short)?;
        let separate = hbytes % 3 == 0 || head_text.last() == Some(&b'=');
        let (header, body) = if separate {
            (b64(head_text)?, b64(&text[hc..])?)
        } else {
            let mut all = b64(text)?;
            let body = all.split_off(hbytes.min(all.len()));
            (all, body)
        };
        if header.len() < hbytes {
            return Err(short());
        }
        let words: Vec<u64> = header[..hbytes]
            .chunks_exact(h)
            .map(|b| self.header_word(b))
            .collect();
        if compressed {
            inflate(&words, &body, loc, name)
        } else {
            let n = words[0];
            if n > body.len() as u64 {
                return Err(ParseError::new(
                    loc,
                    format!(
                        "DataArray {name}: header says {n} bytes, but the data holds {}",
                        body.len()
                    ),
                ));
            }
            let mut body = body;
            body.truncate(n as usize);
            Ok(body)
        }
    }

    /// Decode the array as integers.
    fn ints(
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
    fn floats(
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
        self.values(arr, data, lines, super::text::parse_f64, |b| {
            arr.ty.float_at(b, self.big)
        })
    }

    fn values<T>(
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
    fn piece(
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
        super::vtk::tags_to_i32(&values, &arr.name, |i| locs.at(i)).map(Some)
    }
}

/// Values of an ascii `DataArray`, with the line of each value if `lines`.
fn ascii_values<T>(
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

/// Decompress zlib blocks given the header words `[count, block size, last size, sizes...]`.
fn inflate(words: &[u64], body: &[u8], loc: Location, name: &str) -> Result<Vec<u8>, ParseError> {
    let err = |m: String| ParseError::new(loc, format!("DataArray {name}: {m}"));
    let (nb, bs, last) = match words {
        [nb, bs, last, ..] => (*nb as usize, *bs, *last),
        _ => return Err(err("compression header too short".into())),
    };
    let sizes = words
        .get(3..3usize.saturating_add(nb))
        .ok_or_else(|| err("compression header too short".into()))?;
    let mut out = Vec::new();
    let mut pos = 0usize;
    for (k, &size) in sizes.iter().enumerate() {
        let want = if k + 1 == nb && last != 0 { last } else { bs };
        let block = usize::try_from(size)
            .ok()
            .and_then(|s| body.get(pos..pos.checked_add(s)?))
            .ok_or_else(|| {
                err(format!(
                    "compressed block {k} of {size} bytes runs past the data"
                ))
            })?;
        pos += block.len();
        let before = out.len();
        // Room for the block as the header sizes it, but never more than deflate's largest
        // expansion (1032:1) of the compressed bytes: a header cannot make the reader allocate
        // beyond what the data can hold, and the exact reservation avoids doubling growth.
        let room = want.min(1032 * block.len() as u64 + 64);
        out.try_reserve_exact(usize::try_from(room).unwrap_or(usize::MAX))
            .map_err(|_| {
                err(format!(
                    "compressed block {k}: cannot allocate {room} bytes"
                ))
            })?;
        flate2::read::ZlibDecoder::new(block)
            .take(want)
            .read_to_end(&mut out)
            .map_err(|e| err(format!("compressed block {k}: {e}")))?;
        if (out.len() - before) as u64 != want {
            return Err(err(format!(
                "compressed block {k} holds {} bytes, the header says {want}",
                out.len() - before
            )));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::raw::CellKind;
    use std::path::Path;

    fn data(name: &str) -> Vec<u8> {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/vtu")
            .join(name);
        std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    }

    fn block_points() -> Vec<[f64; 3]> {
        let mut pts = Vec::new();
        for k in 0..3 {
            for j in 0..3 {
                for i in 0..3 {
                    let (i, j, k) = (i as f64, j as f64, k as f64);
                    pts.push([i + 0.125 * i * k, 1.5 * j, 0.25 * k + 0.125 * i]);
                }
            }
        }
        pts
    }

    /// The mesh of tests/data/vtu/make_fixtures.py, as the legacy reader's ASCII twin holds it.
    fn check_block(m: &RawMesh) {
        let twin = std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/data/vtk/block_v51_ascii.vtk"
        ))
        .unwrap();
        let twin = super::super::vtk::read(&twin).unwrap();
        assert_eq!(m.points, block_points());
        assert_eq!(m.points, twin.points);
        assert_eq!(m.point_locations.len(), 27);
        assert_eq!(m.blocks.len(), 3);
        for (a, b) in m.blocks.iter().zip(&twin.blocks) {
            assert_eq!(a.kind, b.kind);
            assert_eq!(a.nodes, b.nodes);
            assert_eq!(a.tags, b.tags);
            assert_eq!(a.locations.len(), a.len());
        }
        assert_eq!(m.blocks[0].kind(), &CellKind::Hexahedron);
        assert_eq!(&m.blocks[0].nodes[..8], &[0, 1, 4, 3, 9, 10, 13, 12]);
        assert_eq!(m.blocks[0].tags, [1, 1, 1, 1, 2, 2, 2, 2]);
        assert_eq!(m.blocks[1].tags, [10, 10, 11, 11]);
        assert_eq!(m.blocks[2].nodes, [26]);
    }

    #[test]
    fn ascii() {
        let m = read(&data("block_ascii.vtu")).unwrap();
        check_block(&m);
        // One value per line in meshio's ascii output.
        let text = String::from_utf8(data("block_ascii.vtu")).unwrap();
        let first = text
            .lines()
            .position(|l| l.contains("Name=\"Points\""))
            .unwrap()
            + 2;
        assert_eq!(m.point_locations[0], Location::Line(first));
        assert_eq!(m.point_locations[1], Location::Line(first + 3));
    }

    #[test]
    fn binary_joint_base64() {
        check_block(&read(&data("block_binary.vtu")).unwrap());
    }

    #[test]
    fn binary_zlib_separate_base64() {
        check_block(&read(&data("block_zlib.vtu")).unwrap());
    }

    #[test]
    fn appended_raw_uint64() {
        let d = data("block_appended_raw.vtu");
        let m = read(&d).unwrap();
        check_block(&m);
        // Points are at offset 344 of the appended data, after an 8-byte header.
        let app = d.windows(13).position(|w| w == b"<AppendedData").unwrap();
        let us = d[app..].iter().position(|&b| b == b'_').unwrap() + app + 1;
        assert_eq!(m.point_locations[1], Location::Byte(us + 344 + 8 + 24));
    }

    #[test]
    fn appended_base64_big_endian_zlib_blocks() {
        check_block(&read(&data("block_appended_base64_be_zlib.vtu")).unwrap());
    }

    #[test]
    fn binary_big_endian_uint64() {
        check_block(&read(&data("block_binary_be_uint64.vtu")).unwrap());
    }

    #[test]
    fn written_by_vtk() {
        // VTK 9.7's own writer, with <InformationKey> elements inside the Points DataArray.
        for name in [
            "block_vtk97_appended_raw_zlib.vtu",
            "block_vtk97_appended_base64.vtu",
            "block_vtk97_binary_zlib.vtu",
            "block_vtk97_ascii.vtu",
        ] {
            let m = read(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
            check_block(&m);
        }
    }

    #[test]
    fn lagrange_cells_match_vtk() {
        // Node ids as VTK 9.7's reader returns them; in the file relabelled as version 1.0
        // the order-3 hexahedron is renumbered from the VTK 8 layout.
        let expected: serde_json::Value =
            serde_json::from_slice(&data("lagrange_expected.json")).unwrap();
        for name in ["lagrange_vtk97.vtu", "lagrange_v10.vtu"] {
            let m = read(&data(name)).unwrap();
            assert_eq!(
                m.blocks[0].kind(),
                &CellKind::Lagrange {
                    dim: 3,
                    order: 3,
                    convention: crate::io::raw::NodeConvention::Vtk
                }
            );
            let got: Vec<i64> = m.blocks.iter().flat_map(|b| b.nodes.clone()).collect();
            let want: Vec<i64> = expected[name]
                .as_array()
                .unwrap()
                .iter()
                .flat_map(|c| c.as_array().unwrap().iter().map(|v| v.as_i64().unwrap()))
                .collect();
            assert_eq!(got, want, "{name}");
        }
    }

    #[test]
    fn two_pieces() {
        let m = read(&data("two_pieces_appended_raw_zlib.vtu")).unwrap();
        assert_eq!(m.points.len(), 37);
        let pts = block_points();
        assert_eq!(&m.points[..27], &pts[..]);
        assert_eq!(m.blocks.len(), 3);
        assert_eq!(m.blocks[0].tags, [1, 1, 1, 1, 2, 2, 2, 2]);
        // Second piece's quads, mapped back through the point coordinates.
        let q = &m.blocks[1];
        assert_eq!(q.kind(), &CellKind::Quad);
        assert_eq!(q.tags, [10, 10, 11, 11]);
        let want = [0usize, 3, 4, 1];
        for (k, &n) in q.nodes[..4].iter().enumerate() {
            assert!(n >= 27);
            assert_eq!(m.points[n as usize], pts[want[k]]);
        }
        assert_eq!(m.points[m.blocks[2].nodes[0] as usize], pts[26]);
    }

    #[test]
    fn errors() {
        let text = String::from_utf8(data("block_ascii.vtu")).unwrap();
        // A bad number names its line.
        let line = text
            .lines()
            .position(|l| l.contains("Name=\"connectivity\""))
            .unwrap()
            + 4;
        let bad = text.replacen("\n1\n4\n", "\n1\nfour\n", 1);
        let e = read(bad.as_bytes()).unwrap_err();
        assert_eq!(e.location, Location::Line(line), "{e}");
        assert!(e.message.contains("\"four\""), "{e}");
        // Wrong NumberOfPoints.
        let bad = text.replace("NumberOfPoints=\"27\"", "NumberOfPoints=\"28\"");
        let e = read(bad.as_bytes()).unwrap_err();
        assert!(e.message.contains("expected 84"), "{e}");
        // Huge NumberOfCells fails without allocating.
        let bad = text.replace("NumberOfCells=\"13\"", "NumberOfCells=\"999999999999999\"");
        assert!(read(bad.as_bytes()).is_err());
        // Other dataset types.
        let e = read(b"<VTKFile type=\"PolyData\"><PolyData/></VTKFile>").unwrap_err();
        assert!(e.message.contains("PolyData"), "{e}");
        // Broken XML.
        let e = read(b"<VTKFile type=\"UnstructuredGrid\"><Piece NumberOfPoints=\"1\" </VTKFile>")
            .unwrap_err();
        assert_eq!(e.location, Location::Line(1));
        // Truncated raw appended data names a byte offset.
        let d = data("block_appended_raw.vtu");
        let e = read(&d[..d.len() - 700]).unwrap_err();
        assert!(matches!(e.location, Location::Byte(_)), "{e}");
        // Corrupt base64.
        let b = String::from_utf8(data("block_binary.vtu")).unwrap();
        let bad = b.replacen("iAIAAAAAAAAAAAAA", "iAIAAAAAAAA*AAAA", 1);
        let e = read(bad.as_bytes()).unwrap_err();
        assert!(e.message.contains("base64"), "{e}");
        // Corrupt compressed block.
        let z = String::from_utf8(data("block_zlib.vtu")).unwrap();
        let i = z.find("format=\"binary\">").unwrap() + 40;
        let mut bad = z.into_bytes();
        bad[i] = if bad[i] == b'A' { b'B' } else { b'A' };
        assert!(read(&bad).is_err());
        // Offsets that decrease.
        let bad = text.replacen(
            "<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n8\n16\n",
            "<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n16\n8\n",
            1,
        );
        assert_ne!(bad, text);
        let e = read(bad.as_bytes()).unwrap_err();
        assert!(e.message.contains("offset 1"), "{e}");
    }

    #[test]
    fn garbage_never_panics() {
        let mut inputs: Vec<Vec<u8>> =
            vec![Vec::new(), b"\xff\xfe<".to_vec(), b"<AppendedData".to_vec()];
        for name in [
            "block_ascii.vtu",
            "block_binary.vtu",
            "block_zlib.vtu",
            "block_vtk97_appended_raw_zlib.vtu",
            "block_appended_raw.vtu",
            "block_appended_base64_be_zlib.vtu",
            "two_pieces_appended_raw_zlib.vtu",
        ] {
            let d = data(name);
            for cut in (0..d.len()).step_by(11) {
                inputs.push(d[..cut].to_vec());
            }
            for i in (0..d.len()).step_by(5) {
                let mut x = d.clone();
                x[i] = x[i].wrapping_add(0x31);
                inputs.push(x);
            }
        }
        for d in inputs {
            let _ = read(&d);
        }
    }
}
