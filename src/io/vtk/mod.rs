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

use super::raw::{CellKind, Location, NodeConvention, ParseError, RawBlock, RawMesh};
use super::text::{TextCursor, parse_f64};
use std::borrow::Cow;

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

/// Numeric types of VTK data arrays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    Bit,
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
    Str,
}

impl Scalar {
    /// A legacy type name (`float`, `unsigned_int`, `vtktypeint64`, ...), case-insensitive.
    fn legacy(name: &str) -> Option<Scalar> {
        use Scalar::*;
        Some(match name.to_ascii_lowercase().as_str() {
            "bit" => Bit,
            "char" | "signed_char" | "vtktypeint8" => I8,
            "unsigned_char" | "vtktypeuint8" => U8,
            "short" | "vtktypeint16" => I16,
            "unsigned_short" | "vtktypeuint16" => U16,
            "int" | "vtktypeint32" => I32,
            "unsigned_int" | "vtktypeuint32" => U32,
            "long" | "vtktypeint64" | "vtkidtype" | "long_long" | "__int64" => I64,
            "unsigned_long" | "vtktypeuint64" | "unsigned_long_long" | "unsigned___int64" => U64,
            "float" | "vtktypefloat32" => F32,
            "double" | "vtktypefloat64" => F64,
            "string" | "utf8_string" => Str,
            _ => return None,
        })
    }

    /// An XML `type` attribute (`Float32`, `Int64`, ...).
    pub(crate) fn xml(name: &str) -> Option<Scalar> {
        use Scalar::*;
        Some(match name {
            "Int8" | "Char" => I8,
            "UInt8" => U8,
            "Int16" => I16,
            "UInt16" => U16,
            "Int32" => I32,
            "UInt32" => U32,
            "Int64" | "IdType" => I64,
            "UInt64" => U64,
            "Float32" => F32,
            "Float64" => F64,
            "String" => Str,
            "Bit" => Bit,
            _ => return None,
        })
    }

    /// Bytes per value in binary data (0 for bits and strings, which are not fixed-size).
    pub(crate) fn size(self) -> usize {
        use Scalar::*;
        match self {
            Bit | Str => 0,
            I8 | U8 => 1,
            I16 | U16 => 2,
            I32 | U32 | F32 => 4,
            I64 | U64 | F64 => 8,
        }
    }

    pub(crate) fn is_int(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64 | Scalar::Str)
    }

    /// Decode one integer value; `b` holds at least [`Scalar::size`] bytes. Unsigned values
    /// beyond `i64::MAX` saturate (they are out of range as node indices or tags anyway).
    pub(crate) fn int_at(self, b: &[u8], big: bool) -> i64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            }};
        }
        use Scalar::*;
        match self {
            I8 => get!(i8, 1) as i64,
            U8 | Bit => get!(u8, 1) as i64,
            I16 => get!(i16, 2) as i64,
            U16 => get!(u16, 2) as i64,
            I32 => get!(i32, 4) as i64,
            U32 => get!(u32, 4) as i64,
            I64 => get!(i64, 8),
            U64 => i64::try_from(get!(u64, 8)).unwrap_or(i64::MAX),
            F32 => get!(f32, 4) as i64,
            F64 => get!(f64, 8) as i64,
            Str => 0,
        }
    }

    /// Decode one value as a float; `b` holds at least [`Scalar::size`] bytes.
    pub(crate) fn float_at(self, b: &[u8], big: bool) -> f64 {
        match self {
            Scalar::F32 => {
                let mut a = [0u8; 4];
                a.copy_from_slice(&b[..4]);
                (if big {
                    f32::from_be_bytes(a)
                } else {
                    f32::from_le_bytes(a)
                }) as f64
            }
            Scalar::F64 => {
                let mut a = [0u8; 8];
                a.copy_from_slice(&b[..8]);
                if big {
                    f64::from_be_bytes(a)
                } else {
                    f64::from_le_bytes(a)
                }
            }
            _ => self.int_at(b, big) as f64,
        }
    }
}

const PIXEL_TO_QUAD: [usize; 4] = [0, 1, 3, 2];
const VOXEL_TO_HEX: [usize; 8] = [0, 1, 3, 2, 4, 5, 7, 6];

/// Human-readable names of the VTK cell types polyspline does not read as linear cells.
fn vtk_type_name(t: i64) -> &'static str {
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
fn lattice_order(n: usize, dim: u32) -> Option<usize> {
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
fn lagrange(dim: usize, order: usize) -> CellKind {
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
fn vtk_cell(t: i64, n: usize) -> (CellKind, Option<&'static [usize]>) {
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
fn vtk8_hex_to_vtk9(p: usize) -> Vec<usize> {
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

fn singular(kind: &CellKind) -> String {
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
    fn len_declared(&self) -> usize {
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

    /// `# vtk DataFile Version x.y`, a title line and `ASCII` or `BINARY`.
    fn header(&mut self) -> Result<(), ParseError> {
        let first = self.cur.next_line().unwrap_or("");
        let ok =
            first.len() >= 14 && first.as_bytes()[..14].eq_ignore_ascii_case(b"# vtk DataFile");
        if !ok {
            let shown: String = first.chars().take(40).collect();
            return Err(ParseError::at_line(
                1,
                format!("expected \"# vtk DataFile Version ...\", found \"{shown}\""),
            ));
        }
        let number = first.get(14..).unwrap_or("").trim_start();
        let number = number
            .strip_prefix("Version")
            .or_else(|| number.strip_prefix("version"))
            .unwrap_or(number)
            .trim();
        if let Some((major, minor)) = number.split_once('.') {
            self.version = (major.parse().unwrap_or(0), minor.parse().unwrap_or(0));
        }
        if self.cur.next_line().is_none() {
            return Err(ParseError::at_line(
                2,
                "unexpected end of file while reading the title line",
            ));
        }
        let mode = self.cur.expect_token("ASCII or BINARY")?;
        if mode.eq_ignore_ascii_case("BINARY") {
            self.binary = true;
        } else if !mode.eq_ignore_ascii_case("ASCII") {
            return Err(self.cur.expected("ASCII or BINARY", mode));
        }
        Ok(())
    }

    fn scalar_type(&mut self, what: &str) -> Result<Scalar, ParseError> {
        let t = self.cur.expect_token(what)?;
        Scalar::legacy(t).ok_or_else(|| self.cur.expected(what, t))
    }

    fn count(&mut self, what: &str) -> Result<usize, ParseError> {
        self.cur.usize(what)
    }

    /// Start of a binary block of `len` bytes after the current header line; advances past it.
    fn binary_block(
        &mut self,
        count: usize,
        ty: Scalar,
        what: &str,
    ) -> Result<(usize, &'a [u8]), ParseError> {
        let header_line = self.cur.line();
        self.cur.skip_line();
        let start = self.cur.pos();
        let data = self.cur.data();
        let len = match ty {
            Scalar::Bit => Some(count.div_ceil(8)),
            Scalar::Str => {
                return Err(ParseError::at_line(
                    header_line,
                    format!("{what}: binary string arrays are not supported"),
                ));
            }
            _ => count.checked_mul(ty.size()),
        };
        let left = data.len() - start.min(data.len());
        match len {
            Some(len) if len <= left => {
                let block = &data[start..start + len];
                self.cur.seek_forward(start + len);
                Ok((start, block))
            }
            _ => Err(ParseError::at_byte(
                start,
                format!(
                    "{what}: expected {count} binary values of {} bytes, but only {left} bytes are left",
                    ty.size().max(1)
                ),
            )),
        }
    }

    /// Read `count` integers of type `ty`, calling `f(index, value, location)` for each.
    fn ints(
        &mut self,
        count: usize,
        ty: Scalar,
        what: &str,
        mut f: impl FnMut(usize, i64, Location) -> Result<(), ParseError>,
    ) -> Result<(), ParseError> {
        if !ty.is_int() {
            return Err(self
                .cur
                .error(format!("{what} must have an integer type, found {ty:?}")));
        }
        if self.binary {
            if ty == Scalar::Bit {
                return Err(self
                    .cur
                    .error(format!("{what}: bit arrays are not supported here")));
            }
            let (start, block) = self.binary_block(count, ty, what)?;
            let size = ty.size();
            for (i, b) in block.chunks_exact(size).enumerate() {
                f(i, ty.int_at(b, true), Location::Byte(start + i * size))?;
            }
        } else {
            for i in 0..count {
                let Some(t) = self.cur.next_token() else {
                    return Err(self.eof(what, i, count));
                };
                let v: i64 = t
                    .parse()
                    .map_err(|_| self.cur.expected(&format!("integer in {what}"), t))?;
                f(i, v, self.cur.location())?;
            }
        }
        Ok(())
    }

    /// Read `count` numbers of type `ty` as floats, calling `f(index, value, location)`.
    fn floats(
        &mut self,
        count: usize,
        ty: Scalar,
        what: &str,
        mut f: impl FnMut(usize, f64, Location),
    ) -> Result<(), ParseError> {
        if matches!(ty, Scalar::Str | Scalar::Bit) {
            return Err(self
                .cur
                .error(format!("{what} must have a numeric type, found {ty:?}")));
        }
        if self.binary {
            let (start, block) = self.binary_block(count, ty, what)?;
            let size = ty.size();
            for (i, b) in block.chunks_exact(size).enumerate() {
                f(i, ty.float_at(b, true), Location::Byte(start + i * size));
            }
        } else {
            for i in 0..count {
                let Some(t) = self.cur.next_token() else {
                    return Err(self.eof(what, i, count));
                };
                let v = parse_f64(t)
                    .ok_or_else(|| self.cur.expected(&format!("number in {what}"), t))?;
                f(i, v, self.cur.location());
            }
        }
        Ok(())
    }

    /// Skip `count` values of type `ty`.
    fn skip(&mut self, count: usize, ty: Scalar, what: &str) -> Result<(), ParseError> {
        if self.binary {
            self.binary_block(count, ty, what)?;
        } else {
            for i in 0..count {
                if self.cur.next_token().is_none() {
                    return Err(self.eof(what, i, count));
                }
            }
        }
        Ok(())
    }

    fn eof(&self, what: &str, i: usize, count: usize) -> ParseError {
        ParseError::at_line(
            self.cur.line(),
            format!("unexpected end of file in {what}: found {i} of {count} values"),
        )
    }

    /// A vector capacity for `count` items that the rest of the input can hold.
    fn capacity(&self, count: usize, min_bytes: usize) -> usize {
        count.min(
            (self.cur.data().len() - self.cur.pos().min(self.cur.data().len())) / min_bytes.max(1)
                + 1,
        )
    }

    fn points(&mut self, mesh: &mut RawMesh) -> Result<(), ParseError> {
        let n = self.count("number of points")?;
        let ty = self.scalar_type("POINTS data type")?;
        let values = n
            .checked_mul(3)
            .ok_or_else(|| self.cur.error(format!("POINTS count {n} is too large")))?;
        let cap = self.capacity(n, if self.binary { 3 * ty.size() } else { 6 });
        mesh.points = Vec::with_capacity(cap);
        mesh.point_locations = Vec::with_capacity(cap);
        let mut p = [0.0; 3];
        self.floats(values, ty, "POINTS", |i, v, loc| {
            let k = i % 3;
            if k == 0 {
                mesh.point_locations.push(loc);
            }
            p[k] = v;
            if k == 2 {
                mesh.points.push(p);
            }
        })
    }

    fn cells(&mut self) -> Result<CellList, ParseError> {
        let line = self.cur.line();
        let a = self.count("number of cells")?;
        let b = self.count("size of the cell list")?;
        let next = if self.binary {
            None
        } else {
            self.cur.peek_token()
        };
        let new_layout = match next {
            Some(t) => t.eq_ignore_ascii_case("OFFSETS"),
            // In binary files the data follows; look at the next line without tokenising it.
            None => {
                let data = self.cur.data();
                let rest = &data[self.cur.pos().min(data.len())..];
                let rest = match rest.iter().position(|&c| c == b'\n') {
                    Some(nl) => &rest[nl + 1..],
                    None => &[],
                };
                rest.len() >= 7 && rest[..7].eq_ignore_ascii_case(b"OFFSETS")
            }
        };
        if new_layout {
            self.cells_offsets(a, b)
        } else {
            self.cells_counted(a, b, line)
        }
    }

    /// Versions up to 4.x: `CELLS n size`, then per cell `count i0 i1 ...`.
    fn cells_counted(
        &mut self,
        n: usize,
        size: usize,
        line: usize,
    ) -> Result<CellList, ParseError> {
        let mut list = CellList {
            types: Vec::new(),
            offsets: Vec::with_capacity(self.capacity(n, 2) + 1),
            conn: Vec::with_capacity(self.capacity(size, if self.binary { 4 } else { 2 })),
            locations: Vec::with_capacity(self.capacity(n, 2)),
            vtk8_hexes: false,
        };
        list.offsets.push(0);
        // Nodes still to read for the current cell.
        let mut left = 0usize;
        let ty = if self.binary {
            Scalar::I32
        } else {
            Scalar::I64
        };
        self.ints(size, ty, "CELLS", |i, v, loc| {
            if left > 0 {
                list.conn.push(v);
                left -= 1;
                if left == 0 {
                    list.offsets.push(list.conn.len());
                }
                return Ok(());
            }
            let c = list.locations.len();
            if c == n {
                return Err(ParseError::new(
                    loc,
                    format!("CELLS declares {n} cells but its list of {size} values holds more"),
                ));
            }
            if v < 0 || v as u64 > (size - i - 1) as u64 {
                return Err(ParseError::new(
                    loc,
                    format!(
                        "cell {c} lists {v} nodes, but the CELLS list has {} values left",
                        size - i - 1
                    ),
                ));
            }
            list.locations.push(loc);
            left = v as usize;
            if left == 0 {
                list.offsets.push(list.conn.len());
            }
            Ok(())
        })?;
        if list.locations.len() != n {
            return Err(ParseError::at_line(
                line,
                format!(
                    "CELLS declares {n} cells but its list of {size} values holds {}",
                    list.locations.len()
                ),
            ));
        }
        Ok(list)
    }

    /// Version 5.x: `CELLS n_offsets n_conn`, `OFFSETS type` + values, `CONNECTIVITY type` + values.
    fn cells_offsets(&mut self, n_offsets: usize, n_conn: usize) -> Result<CellList, ParseError> {
        self.cur.expect_keyword("OFFSETS")?;
        let ty = self.scalar_type("OFFSETS data type")?;
        let n = n_offsets.saturating_sub(1);
        let mut list = CellList {
            types: Vec::new(),
            offsets: Vec::with_capacity(self.capacity(n_offsets, 2)),
            conn: Vec::new(),
            locations: Vec::new(),
            vtk8_hexes: false,
        };
        self.ints(n_offsets, ty, "OFFSETS", |i, v, loc| {
            let prev = list.offsets.last().copied();
            let ok = match prev {
                None => v == 0,
                Some(p) => v >= p as i64 && v as u64 <= n_conn as u64,
            };
            if !ok {
                let why = match prev {
                    None => "the first offset must be 0".to_string(),
                    Some(p) if v < p as i64 => {
                        format!("it is smaller than the previous offset {p}")
                    }
                    _ => format!("it exceeds the connectivity size {n_conn}"),
                };
                return Err(ParseError::new(loc, format!("offset {i} is {v}: {why}")));
            }
            list.offsets.push(v as usize);
            Ok(())
        })?;
        let last = list.offsets.last().copied().unwrap_or(0);
        if last != n_conn {
            return Err(self.cur.error(format!(
                "the last offset is {last}, but CELLS declares {n_conn} connectivity entries"
            )));
        }
        if list.offsets.is_empty() {
            list.offsets.push(0);
        }
        self.cur.expect_keyword("CONNECTIVITY")?;
        let ty = self.scalar_type("CONNECTIVITY data type")?;
        list.conn =
            Vec::with_capacity(self.capacity(n_conn, if self.binary { ty.size() } else { 2 }));
        list.locations = Vec::with_capacity(self.capacity(n, 2));
        let offsets = &list.offsets;
        let (conn, locations) = (&mut list.conn, &mut list.locations);
        self.ints(n_conn, ty, "CONNECTIVITY", |i, v, loc| {
            // Cells start where their offset says; empty cells start at the same entry.
            while locations.len() < n && offsets[locations.len()] == i {
                locations.push(loc);
            }
            conn.push(v);
            Ok(())
        })?;
        let loc = self.cur.location();
        while list.locations.len() < n {
            list.locations.push(loc);
        }
        Ok(list)
    }

    fn cell_types(&mut self, list: &mut CellList) -> Result<(), ParseError> {
        let n = self.count("number of cell types")?;
        if n != list.len_declared() {
            return Err(self.cur.error(format!(
                "CELL_TYPES declares {n} cells but CELLS has {}",
                list.len_declared()
            )));
        }
        let mut types = Vec::with_capacity(n);
        let ty = if self.binary {
            Scalar::I32
        } else {
            Scalar::I64
        };
        self.ints(n, ty, "CELL_TYPES", |_, v, _| {
            types.push(v);
            Ok(())
        })?;
        list.types = types;
        Ok(())
    }

    /// `FIELD name n` and its arrays (`name components tuples type`, then the values).
    fn field(&mut self, section: Section, tags: &mut TagCandidate) -> Result<(), ParseError> {
        self.cur.expect_token("FIELD name")?;
        let arrays = self.count("number of FIELD arrays")?;
        for _ in 0..arrays {
            let mut name = self.cur.expect_token("FIELD array name")?;
            while name.eq_ignore_ascii_case("METADATA") {
                self.metadata();
                name = self.cur.expect_token("FIELD array name")?;
            }
            if name == "NULL_ARRAY" {
                continue;
            }
            let comps = self.count("number of components")?;
            let tuples = self.count("number of tuples")?;
            let ty = self.scalar_type("FIELD array data type")?;
            let is_cell = matches!(section, Section::Cell(n) if n == tuples);
            self.array(name, comps, tuples, ty, is_cell, tags)?;
        }
        Ok(())
    }

    /// Read an array as tags if it is a better tag array than the one so far, else skip it.
    fn array(
        &mut self,
        name: &str,
        comps: usize,
        tuples: usize,
        ty: Scalar,
        is_cell: bool,
        tags: &mut TagCandidate,
    ) -> Result<(), ParseError> {
        let count = comps
            .checked_mul(tuples)
            .ok_or_else(|| self.cur.error(format!("array {name} is too large")))?;
        let prio = tag_priority(name).filter(|_| {
            is_cell && comps == 1 && ty.is_int() && !(self.binary && ty == Scalar::Bit)
        });
        match prio {
            Some(p) if tags.as_ref().is_none_or(|(q, _)| p < *q) => {
                let mut values = Vec::with_capacity(self.capacity(tuples, 2));
                let what = format!("cell data array {name}");
                self.ints(count, ty, &what, |i, v, loc| {
                    let t = i32::try_from(v).map_err(|_| {
                        ParseError::new(
                            loc,
                            format!("{what}: value {v} of cell {i} does not fit a 32-bit integer"),
                        )
                    })?;
                    values.push(t);
                    Ok(())
                })?;
                *tags = Some((p, values));
                Ok(())
            }
            _ => self.skip(count, ty, &format!("array {name}")),
        }
    }

    /// One attribute of a `POINT_DATA` / `CELL_DATA` section with `n` tuples.
    fn attribute(
        &mut self,
        kw: &str,
        n: usize,
        is_cell: bool,
        tags: &mut TagCandidate,
    ) -> Result<(), ParseError> {
        let kw = kw.to_ascii_uppercase();
        match kw.as_str() {
            "SCALARS" => {
                let name = self.cur.expect_token("SCALARS name")?;
                let ty = self.scalar_type("SCALARS data type")?;
                let mut comps = 1;
                let next = self.cur.peek_token();
                if next.is_some_and(|t| !t.eq_ignore_ascii_case("LOOKUP_TABLE")) {
                    comps = self.count("number of components or LOOKUP_TABLE")?;
                }
                if self
                    .cur
                    .peek_token()
                    .is_some_and(|t| t.eq_ignore_ascii_case("LOOKUP_TABLE"))
                {
                    self.cur.next_token();
                    self.cur.expect_token("lookup table name")?;
                }
                self.array(name, comps, n, ty, is_cell, tags)
            }
            "COLOR_SCALARS" => {
                let name = self.cur.expect_token("COLOR_SCALARS name")?;
                let comps = self.count("number of color components")?;
                let ty = if self.binary { Scalar::U8 } else { Scalar::F32 };
                self.array(name, comps, n, ty, false, tags)
            }
            "LOOKUP_TABLE" => {
                self.cur.expect_token("lookup table name")?;
                let size = self.count("lookup table size")?;
                let ty = if self.binary { Scalar::U8 } else { Scalar::F32 };
                self.array("LOOKUP_TABLE", 4, size, ty, false, tags)
            }
            "VECTORS" | "NORMALS" | "TENSORS" | "TENSORS6" => {
                let name = self.cur.expect_token("array name")?;
                let ty = self.scalar_type("data type")?;
                let comps = match kw.as_str() {
                    "TENSORS" => 9,
                    "TENSORS6" => 6,
                    _ => 3,
                };
                self.array(name, comps, n, ty, false, tags)
            }
            "TEXTURE_COORDINATES" => {
                let name = self.cur.expect_token("array name")?;
                let dim = self.count("texture dimension")?;
                let ty = self.scalar_type("data type")?;
                self.array(name, dim, n, ty, false, tags)
            }
            "GLOBAL_IDS" | "PEDIGREE_IDS" | "EDGE_FLAGS" => {
                let name = self.cur.expect_token("array name")?;
                let ty = self.scalar_type("data type")?;
                self.array(name, 1, n, ty, false, tags)
            }
            _ => Err(self.cur.expected(
                "a data attribute (SCALARS, VECTORS, FIELD, ...) or POINTS, CELLS, CELL_TYPES",
                &kw,
            )),
        }
    }

    /// `METADATA` blocks run to the next empty line.
    fn metadata(&mut self) {
        self.cur.skip_line();
        while let Some(line) = self.cur.next_line() {
            if line.trim().is_empty() {
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn data(name: &str) -> Vec<u8> {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/vtk")
            .join(name);
        std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    }

    /// The fixture mesh of tests/data/vtk/make_fixtures.py.
    pub(crate) fn block_points() -> Vec<[f64; 3]> {
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

    pub(crate) fn block_hexes() -> Vec<i64> {
        let p = |i: i64, j: i64, k: i64| i + 3 * j + 9 * k;
        let mut h = Vec::new();
        for k in 0..2 {
            for j in 0..2 {
                for i in 0..2 {
                    h.extend([
                        p(i, j, k),
                        p(i + 1, j, k),
                        p(i + 1, j + 1, k),
                        p(i, j + 1, k),
                        p(i, j, k + 1),
                        p(i + 1, j, k + 1),
                        p(i + 1, j + 1, k + 1),
                        p(i, j + 1, k + 1),
                    ]);
                }
            }
        }
        h
    }

    pub(crate) fn block_quads() -> Vec<i64> {
        let p = |i: i64, j: i64| i + 3 * j;
        let mut q = Vec::new();
        for j in 0..2 {
            for i in 0..2 {
                q.extend([p(i, j), p(i, j + 1), p(i + 1, j + 1), p(i + 1, j)]);
            }
        }
        q
    }

    /// Check a mesh read from any fixture of the block against the writer's input.
    pub(crate) fn check_block(m: &RawMesh) {
        let want = block_points();
        assert_eq!(m.points.len(), 27);
        for (a, b) in m.points.iter().zip(&want) {
            assert_eq!(a, b);
        }
        assert_eq!(m.point_locations.len(), 27);
        assert_eq!(m.blocks.len(), 3, "{:?}", m.blocks);
        let (h, q, v) = (&m.blocks[0], &m.blocks[1], &m.blocks[2]);
        assert_eq!(h.kind(), &CellKind::Hexahedron);
        assert_eq!(h.nodes, block_hexes());
        assert_eq!(h.tags, [1, 1, 1, 1, 2, 2, 2, 2]);
        assert_eq!(h.locations.len(), 8);
        assert_eq!(q.kind(), &CellKind::Quad);
        assert_eq!(q.nodes, block_quads());
        assert_eq!(q.tags, [10, 10, 11, 11]);
        assert_eq!(v.kind(), &CellKind::Vertex);
        assert_eq!(v.nodes, [26]);
        assert_eq!(v.tags, [5]);
    }

    #[test]
    fn v51_ascii() {
        let m = read(&data("block_v51_ascii.vtk")).unwrap();
        check_block(&m);
        // Points on line 6; hexes' connectivity starts on the line after CONNECTIVITY.
        assert_eq!(m.point_locations[0], Location::Line(6));
        let text = String::from_utf8(data("block_v51_ascii.vtk")).unwrap();
        let conn = text
            .lines()
            .position(|l| l.starts_with("CONNECTIVITY"))
            .unwrap()
            + 1;
        assert_eq!(m.blocks[0].locations[0], Location::Line(conn + 1));
        assert_eq!(m.blocks[0].locations[1], Location::Line(conn + 9));
    }

    #[test]
    fn v51_binary() {
        let m = read(&data("block_v51_binary.vtk")).unwrap();
        check_block(&m);
        // The point data starts right after the "POINTS 27 double\n" line.
        let d = data("block_v51_binary.vtk");
        let start = d.windows(7).position(|w| w == b"double\n").unwrap() + 7;
        assert_eq!(m.point_locations[1], Location::Byte(start + 24));
    }

    #[test]
    fn v42_ascii_and_binary_float32() {
        check_block(&read(&data("block_v42_ascii.vtk")).unwrap());
        check_block(&read(&data("block_v42_binary_f32.vtk")).unwrap());
    }

    #[test]
    fn v30_voxels_pixels_scalars() {
        // Hand-written 3.0: voxels/pixels, tags as SCALARS after a lower-priority array,
        // skipped POINT_DATA, LOOKUP_TABLE, FIELD with a string array, METADATA.
        let m = read(&data("block_v30_voxels.vtk")).unwrap();
        check_block(&m);
        assert_eq!(m.point_locations[0], Location::Line(11));
        assert_eq!(m.blocks[0].locations[0], Location::Line(40));
        assert_eq!(m.blocks[1].locations[0], Location::Line(48));
    }

    #[test]
    fn v20_binary_voxels_field_tags() {
        // Big-endian float points, int32 counted cells, binary LOOKUP_TABLE bytes that
        // include newlines, CellEntityIds as a vtktypeint64 FIELD array.
        let m = read(&data("block_v20_binary_voxels.vtk")).unwrap();
        check_block(&m);
    }

    #[test]
    fn written_by_vtk() {
        // VTK 9.7's own writer: 5.1 binary and 4.2 ASCII, each with a METADATA block after
        // the points and the tags as a FIELD array.
        check_block(&read(&data("block_vtk97_binary.vtk")).unwrap());
        check_block(&read(&data("block_vtk97_ascii_v42.vtk")).unwrap());
    }

    #[test]
    fn quad2d_binary_medit_ref() {
        let m = read(&data("quad2d_v51_binary.vtk")).unwrap();
        assert_eq!(m.points.len(), 12);
        assert_eq!(m.points[7], [3.0, 0.5, 0.0]);
        assert_eq!(m.blocks.len(), 2);
        assert_eq!(m.blocks[0].kind(), &CellKind::Quad);
        assert_eq!(&m.blocks[0].nodes[..8], &[0, 1, 5, 4, 1, 2, 6, 5]);
        assert_eq!(m.blocks[0].tags, [7, 7, 7, 8, 8, 8]);
        assert_eq!(m.blocks[1].kind(), &CellKind::Line);
        assert_eq!(m.blocks[1].nodes, [0, 1, 1, 2]);
        assert_eq!(m.blocks[1].tags, [3, 4]);
    }

    #[test]
    fn real_hsphere8() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/meshes/real/sfepy/hsphere8.vtk"
        );
        let m = read(&std::fs::read(path).unwrap()).unwrap();
        assert_eq!(m.points.len(), 889);
        assert_eq!(m.blocks.len(), 1);
        let b = &m.blocks[0];
        assert_eq!(b.kind(), &CellKind::Hexahedron);
        assert_eq!(b.len(), 648);
        // Tags come from the FIELD array mat_id (all 1).
        assert_eq!(b.tags.len(), 648);
        assert!(b.tags.iter().all(|&t| t == 1));
        assert_eq!(m.points[1], [0.025, 0.0, 0.0]);
        assert_eq!(&b.nodes[..4], &[1, 74, 464, 103]);
        assert_eq!(b.locations[0], Location::Line(659));
        let mesh = crate::mesh::LinearMesh::from_raw(m, &Default::default()).unwrap();
        assert_eq!(mesh.element_tags.len(), 648);
    }

    #[test]
    fn block_builds_linear_mesh() {
        // Voxels/pixels in, a checked hex mesh with region tags and tagged boundary quads out.
        let m = read(&data("block_v30_voxels.vtk")).unwrap();
        let lin = crate::mesh::LinearMesh::from_raw(m, &Default::default()).unwrap();
        assert_eq!(lin.dim, 3);
        assert_eq!(lin.elements.len(), 64);
        assert_eq!(lin.reoriented, 0);
        assert_eq!(lin.element_tags, [1, 1, 1, 1, 2, 2, 2, 2]);
        assert_eq!(lin.facet_tags, [10, 10, 11, 11]);
    }

    #[test]
    fn metadata_blocks_are_skipped() {
        let text = "# vtk DataFile Version 4.1\nmeta\nASCII\nDATASET UNSTRUCTURED_GRID\n\
            POINTS 4 float\n0 0 0 1 0 0 1 1 0 0 1 0\n\nMETADATA\nCOMPONENT_NAMES\nX\nY\nZ\n\
            INFORMATION 1\nNAME L2_NORM_RANGE LOCATION vtkDataArray\nDATA 2 0 1.41\n\n\
            CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n9\nCELL_DATA 1\nFIELD FieldData 2\n\
            vtkGhostType 1 1 unsigned_char\n0\nMETADATA\nINFORMATION 1\n\
            NAME UNITS_LABEL LOCATION vtkDataArray\nDATA none\n\n\
            MaterialIds 1 1 int\n4\nMETADATA\nCOMPONENT_NAMES\nid\n\n";
        let m = read(text.as_bytes()).unwrap();
        assert_eq!(m.points.len(), 4);
        assert_eq!(m.blocks[0].nodes, [0, 1, 2, 3]);
        assert_eq!(m.blocks[0].tags, [4]);
    }

    fn err(text: &str) -> ParseError {
        read(text.as_bytes()).unwrap_err()
    }

    const HEAD: &str = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n";

    #[test]
    fn ascii_errors_name_lines() {
        let e = err("hello\n");
        assert_eq!(e.location, Location::Line(1));
        let e = err("# vtk DataFile Version 3.0\nt\nTEXT\n");
        assert_eq!(e.location, Location::Line(3));
        let e = err(&format!("{HEAD}POINTS 2 float\n0 0 0\n1 1\n"));
        assert_eq!(e.location, Location::Line(7));
        assert!(e.message.contains("end of file"), "{}", e.message);
        let e = err(&format!("{HEAD}POINTS 1 float\n0 x 0\n"));
        assert_eq!(e.location, Location::Line(6));
        assert!(e.message.contains("\"x\""), "{}", e.message);
        let e = err(&format!(
            "{HEAD}POINTS 1 float\n0 0 0\nCELLS 1 5\n4 0 0 0 zero\n"
        ));
        assert_eq!(e.location, Location::Line(8));
        let e = err(&format!("{HEAD}POINTS 1 float\n0 0 0\nCELLS 1 3\n4 0 0\n"));
        assert!(e.message.contains("4 nodes"), "{}", e.message);
        assert_eq!(e.location, Location::Line(8));
        let e = err(&format!(
            "{HEAD}POINTS 1 float\n0 0 0\nCELLS 2 3\n2 0 0\nCELL_TYPES 2\n3 3\n"
        ));
        assert!(e.message.contains("holds 1"), "{}", e.message);
        let e = err(&format!(
            "{HEAD}POINTS 1 float\n0 0 0\nCELLS 1 3\n2 0 0\nCELL_TYPES 1\n12\n"
        ));
        assert!(e.message.contains("2 nodes, expected 8"), "{}", e.message);
        assert_eq!(e.location, Location::Line(8));
        let e = err(&format!(
            "{HEAD}POINTS 1 float\n0 0 0\nCELLS 1 3\n2 0 0\nCELL_TYPES 2\n3 3\n"
        ));
        assert_eq!(e.location, Location::Line(9));
        let e = err("# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\n");
        assert!(e.message.contains("POLYDATA"), "{}", e.message);
        assert_eq!(e.location, Location::Line(4));
        let e = err(&format!("{HEAD}POINTS 1000000000000000 double\n0 0 0\n"));
        assert!(e.message.contains("end of file"), "{}", e.message);
        let e = err(&format!("{HEAD}POINTS 1 float\n0 0 0\nFOO 3\n"));
        assert_eq!(e.location, Location::Line(7));
        let e = err(&format!("{HEAD}POINTS -1 float\n"));
        assert!(e.message.contains("\"-1\""), "{}", e.message);
    }

    #[test]
    fn v51_offsets_errors() {
        let pts = "POINTS 1 float\n0 0 0\n";
        let e = err(&format!(
            "# vtk DataFile Version 5.1\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n{pts}CELLS 3 4\nOFFSETS vtktypeint64\n0 3 2\n"
        ));
        assert_eq!(e.location, Location::Line(9));
        assert!(e.message.contains("smaller"), "{}", e.message);
        let e = err(&format!(
            "# vtk DataFile Version 5.1\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n{pts}CELLS 2 1\nOFFSETS vtktypeint64\n0 1\nCONNECTIVITY vtktypeint64\n"
        ));
        assert!(e.message.contains("end of file"), "{}", e.message);
        // Offsets that promise a huge connectivity must not allocate it up front.
        let e = err(&format!(
            "# vtk DataFile Version 5.1\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n{pts}CELLS 2 1000000000000000\nOFFSETS vtktypeint64\n0 1000000000000000\nCONNECTIVITY vtktypeint64\n0\n"
        ));
        assert!(e.message.contains("end of file"), "{}", e.message);
        let e = err(&format!(
            "# vtk DataFile Version 5.1\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n{pts}CELLS 2 1\nOFFSETS float\n0 1\n"
        ));
        assert!(e.message.contains("integer type"), "{}", e.message);
    }

    #[test]
    fn binary_errors_name_bytes() {
        let d = data("block_v51_binary.vtk");
        let start = d.windows(7).position(|w| w == b"double\n").unwrap() + 7;
        // Truncated inside the points.
        let e = read(&d[..start + 100]).unwrap_err();
        assert_eq!(e.location, Location::Byte(start));
        // Truncated inside the connectivity.
        let conn = d.windows(13).position(|w| w == b"CONNECTIVITY ").unwrap();
        let e = read(&d[..conn + 40]).unwrap_err();
        assert!(matches!(e.location, Location::Byte(_)), "{e}");
        // A huge count must fail cleanly.
        let mut big = d.clone();
        let at = big.windows(9).position(|w| w == b"POINTS 27").unwrap();
        big.splice(at..at + 9, b"POINTS 999999999999999".iter().copied());
        let e = read(&big).unwrap_err();
        assert!(e.message.contains("bytes are left"), "{}", e.message);
        // Text errors after binary blocks name the line an editor shows.
        let d = data("block_v42_binary_f32.vtk");
        let at = d.windows(10).position(|w| w == b"CELL_TYPES").unwrap();
        let mut bad = d[..at].to_vec();
        bad.extend_from_slice(b"CELL_TYPOS 13\n");
        let line = 1 + d[..at].iter().filter(|&&b| b == b'\n').count();
        let e = read(&bad).unwrap_err();
        assert_eq!(e.location, Location::Line(line), "{e}");
    }

    #[test]
    fn other_cells_are_named() {
        let text = format!(
            "{HEAD}POINTS 12 float\n{}CELLS 5 47\n8 0 1 2 3 4 5 6 7\n5 0 1 2 3 4\n\
             12 0 1 2 3 4 5 6 7 8 9 10 11\n8 0 1 2 3 4 5 6 7\n9 0 1 2 3 4 5 6 7 8\n\
             CELL_TYPES 5\n23\n7\n70\n72\n28\n",
            "0 0 0\n".repeat(12)
        );
        let m = read(text.as_bytes()).unwrap();
        let kinds: Vec<_> = m.blocks.iter().map(|b| b.kind().clone()).collect();
        assert_eq!(
            kinds,
            [
                CellKind::Other("8-node quadratic quadrilateral (VTK type 23)".into()),
                CellKind::Other("5-node polygon (VTK type 7)".into()),
                CellKind::Other("12-node Lagrange quadrilateral (VTK type 70)".into()),
                // An order-1 Lagrange hexahedron is a linear one.
                CellKind::Hexahedron,
                CellKind::Lagrange {
                    dim: 2,
                    order: 2,
                    convention: NodeConvention::Vtk
                },
            ]
        );
        assert_eq!(m.blocks[0].nodes_per_cell, 8);
        // A biquadratic quad needs 9 nodes.
        let bad = text
            .replace("CELLS 5 47", "CELLS 5 42")
            .replace("9 0 1 2 3 4 5 6 7 8\n", "4 0 1 2 3\n");
        let e = read(bad.as_bytes()).unwrap_err();
        assert!(
            e.message
                .contains("order-2 Lagrange quadrilateral) and 4 nodes, expected 9"),
            "{e}"
        );
        assert_eq!(e.location, Location::Line(23));
    }

    #[test]
    fn lagrange_cells_match_vtk() {
        // Node ids as VTK 9.7's reader returns them; the 4.2 file's order-3 hexahedron is
        // renumbered from the VTK 8 layout.
        let expected: serde_json::Value =
            serde_json::from_slice(&data("lagrange_expected.json")).unwrap();
        for name in ["lagrange_vtk97.vtk", "lagrange_vtk97_v42.vtk"] {
            let m = read(&data(name)).unwrap();
            let lagrange = |dim, order| CellKind::Lagrange {
                dim,
                order,
                convention: NodeConvention::Vtk,
            };
            let kinds: Vec<_> = m.blocks.iter().map(|b| b.kind().clone()).collect();
            assert_eq!(
                kinds,
                [
                    lagrange(3, 3),
                    lagrange(2, 2),
                    lagrange(1, 3),
                    lagrange(3, 2)
                ]
            );
            assert_eq!(m.blocks[1].len(), 2);
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
    fn garbage_never_panics() {
        let mut inputs: Vec<Vec<u8>> = vec![Vec::new(), b"\xff\xfe\x00".to_vec()];
        for name in [
            "block_v51_ascii.vtk",
            "block_v51_binary.vtk",
            "block_v42_binary_f32.vtk",
            "block_v30_voxels.vtk",
            "block_v20_binary_voxels.vtk",
        ] {
            let d = data(name);
            for cut in (0..d.len()).step_by(7) {
                inputs.push(d[..cut].to_vec());
            }
            for i in (0..d.len()).step_by(13) {
                let mut x = d.clone();
                x[i] = x[i].wrapping_add(0x5b);
                inputs.push(x);
            }
        }
        for d in inputs {
            let _ = read(&d);
        }
    }
}
