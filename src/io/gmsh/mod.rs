//! Gmsh MSH reader.
//!
//! Variants read:
//! * MSH 4.1, ASCII and binary (binary `size_t` has the width given by the header's data-size,
//!   4 or 8 bytes);
//! * MSH 4.0, ASCII (Gmsh itself writes 4.0 only in ASCII; 4.0 binary is refused);
//! * MSH 2.0, 2.1 and 2.2, ASCII and binary;
//! * MSH 1 (`$NOD` / `$ELM`, ASCII).
//!
//! Binary files are read in either byte order: the integer `1` after the `$MeshFormat` line
//! says which.
//!
//! Sections: `$MeshFormat`, `$PhysicalNames` (into [`RawMesh::tag_names`]), `$Entities` and
//! `$PartitionedEntities` (physical tags per entity), `$Nodes`, `$Elements`. Every other section
//! (`$Periodic`, `$NodeData`, `$ElementData`, `$Comments`, ...) is skipped up to its `$End` line.
//!
//! Tags: each cell's tag is its physical group. In MSH 1/2 that is the first integer tag of the
//! element; in MSH 4 it is the first physical tag of the entity the element block belongs to
//! (a partitioned entity without physical tags uses its parent's), and 0 ("no tag") when the
//! entity has none. Physical names are keyed by (dimension, tag) in the file but by tag alone in
//! [`RawMesh::tag_names`]; when two dimensions use the same tag number with different names,
//! the names are joined with " / ".
//!
//! Element types: 15 (point), 1, 2, 3, 4, 5, 6, 7 (linear line, triangle, quadrilateral,
//! tetrahedron, hexahedron, prism, pyramid) become the matching [`CellKind`]; every other type
//! Gmsh defines (high-order, serendipity, incomplete) becomes [`CellKind::Other`] named like
//! "9-node quadrilateral (Gmsh type 10)" with its node count, so it is read and reported rather
//! than silently dropped. Unknown type numbers and polygons/polyhedra (no fixed node count) are
//! errors.
//!
//! Node tags may be sparse and in any order (MSH 4 files written after renumbering or
//! partitioning have gaps); they are mapped to 0-based positions with a dense table when the
//! largest tag is at most about ten times the node count, with a hash map otherwise. A node tag
//! defined twice, or an element naming a tag `$Nodes` does not define, is an error at that line
//! (byte offset in binary sections).
//!
//! Traps handled: physical tags on only some entities (hopr's `70degCone_3D.msh`); MSH 2.0
//! headers (`2.0 0 8`); parametric coordinates after the node coordinates in MSH 4 (skipped);
//! MSH 2 binary element blocks (type, count, tag count) followed by records; counts in headers
//! are never trusted for allocation beyond what the remaining input can hold.

use super::raw::{CellKind, Location, NodeConvention, ParseError, RawBlock, RawMesh};
use super::text::{TextCursor, parse_f64};
use crate::sample::ordering::gmsh_type_info;
use std::collections::HashMap;

/// Parse a Gmsh `.msh` file held in memory.
pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    Reader::new(data).run()
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Version {
    V1,
    V2,
    V40,
    V41,
}

/// What `$MeshFormat` said.
#[derive(Clone, Copy, Debug)]
struct Format {
    version: Version,
    binary: bool,
    big_endian: bool,
    /// Width of `size_t` in MSH 4 binary files.
    size_t: usize,
}

// Element families, used to name the cell kinds polyspline does not handle itself.
const POINT: &str = "point";
const LINE: &str = "line";
const TRIANGLE: &str = "triangle";
const QUADRILATERAL: &str = "quadrilateral";
const TETRAHEDRON: &str = "tetrahedron";
const HEXAHEDRON: &str = "hexahedron";
const PRISM: &str = "prism";
const PYRAMID: &str = "pyramid";

/// Every element type Gmsh defines with a fixed node count: (type number, family, nodes).
/// Node counts as reported by the Gmsh API (`getElementProperties`); the high-order prisms Gmsh
/// defines but that API does not describe take their counts from their names in GmshDefines.h.
#[rustfmt::skip]
const ELEMENT_TYPES: &[(u16, &str, u16)] = &[
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
fn element_type(t: i64) -> Result<(CellKind, usize), String> {
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

/// Node tag -> 0-based position.
enum NodeMap {
    Dense(Vec<u32>),
    Sparse(HashMap<u64, u32>),
}

impl NodeMap {
    /// Build the map; a tag defined twice is an error at its second definition.
    fn build(tags: &[u64], locations: &[Location]) -> Result<NodeMap, ParseError> {
        if tags.len() >= u32::MAX as usize {
            return Err(ParseError::new(
                Location::File,
                format!("too many nodes ({})", tags.len()),
            ));
        }
        let duplicate = |i: usize, first: u32| {
            let loc = locations.get(i).copied().unwrap_or_default();
            let first_loc = locations.get(first as usize).copied().unwrap_or_default();
            ParseError::new(
                loc,
                format!(
                    "node tag {} is defined twice (first at {first_loc})",
                    tags[i]
                ),
            )
        };
        let max = tags.iter().copied().max().unwrap_or(0);
        // A dense table costs 4 bytes per possible tag; use it while that stays within a small
        // multiple of the node count.
        if max <= 10 * tags.len() as u64 + 1024 {
            let mut table = vec![u32::MAX; max as usize + 1];
            for (i, &t) in tags.iter().enumerate() {
                let slot = &mut table[t as usize];
                if *slot != u32::MAX {
                    return Err(duplicate(i, *slot));
                }
                *slot = i as u32;
            }
            Ok(NodeMap::Dense(table))
        } else {
            let mut map = HashMap::with_capacity(tags.len());
            for (i, &t) in tags.iter().enumerate() {
                if let Some(&first) = map.get(&t) {
                    return Err(duplicate(i, first));
                }
                map.insert(t, i as u32);
            }
            Ok(NodeMap::Sparse(map))
        }
    }

    #[inline]
    fn get(&self, tag: u64) -> Option<u32> {
        match self {
            NodeMap::Dense(v) => usize::try_from(tag)
                .ok()
                .and_then(|t| v.get(t))
                .copied()
                .filter(|&i| i != u32::MAX),
            NodeMap::Sparse(m) => m.get(&tag).copied(),
        }
    }
}

/// One output block per Gmsh element type, in order of first appearance.
#[derive(Default)]
struct Blocks {
    list: Vec<(i64, RawBlock)>,
}

impl Blocks {
    /// Index of the block for Gmsh type `t`, created on first use.
    fn index(&mut self, t: i64, location: Location) -> Result<usize, ParseError> {
        if let Some(i) = self.list.iter().position(|(ty, _)| *ty == t) {
            return Ok(i);
        }
        let (kind, n) = element_type(t).map_err(|m| ParseError::new(location, m))?;
        self.list.push((t, RawBlock::new(kind, n)));
        Ok(self.list.len() - 1)
    }
}

/// Little reader over the binary parts of a file. Every read is bounds-checked and fails with
/// the byte offset where the data ran out.
struct Bin<'a> {
    data: &'a [u8],
    pos: usize,
    big_endian: bool,
    size_t: usize,
}

impl<'a> Bin<'a> {
    fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    fn take(&mut self, n: usize, what: &dyn Fn() -> String) -> Result<&'a [u8], ParseError> {
        match self
            .pos
            .checked_add(n)
            .and_then(|end| self.data.get(self.pos..end))
        {
            Some(s) => {
                self.pos += n;
                Ok(s)
            }
            None => Err(ParseError::at_byte(
                self.pos,
                format!(
                    "expected {} ({n} bytes), but the file ends after {} more bytes",
                    what(),
                    self.remaining()
                ),
            )),
        }
    }

    /// Check that `count` records of `record` bytes fit in the rest of the input, so that no
    /// allocation follows an absurd count; returns the total size.
    fn room(&self, count: u64, record: usize, what: &str) -> Result<usize, ParseError> {
        let total = usize::try_from(count)
            .ok()
            .and_then(|c| c.checked_mul(record));
        match total {
            Some(t) if t <= self.remaining() => Ok(t),
            _ => Err(ParseError::at_byte(
                self.pos,
                format!(
                    "{count} {what} of {record} bytes each do not fit in the {} bytes left in the file",
                    self.remaining()
                ),
            )),
        }
    }

    #[inline]
    fn dec_i32(&self, b: &[u8]) -> i32 {
        let a = [b[0], b[1], b[2], b[3]];
        if self.big_endian {
            i32::from_be_bytes(a)
        } else {
            i32::from_le_bytes(a)
        }
    }

    #[inline]
    fn dec_f64(&self, b: &[u8]) -> f64 {
        let a = [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
        if self.big_endian {
            f64::from_be_bytes(a)
        } else {
            f64::from_le_bytes(a)
        }
    }

    #[inline]
    fn dec_size(&self, b: &[u8]) -> u64 {
        if self.size_t == 4 {
            self.dec_i32(b) as u32 as u64
        } else {
            let a = [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
            if self.big_endian {
                u64::from_be_bytes(a)
            } else {
                u64::from_le_bytes(a)
            }
        }
    }

    fn i32(&mut self, what: &dyn Fn() -> String) -> Result<i32, ParseError> {
        let b = self.take(4, what)?;
        Ok(self.dec_i32(b))
    }

    fn size(&mut self, what: &dyn Fn() -> String) -> Result<u64, ParseError> {
        let b = self.take(self.size_t, what)?;
        Ok(self.dec_size(b))
    }

    /// Skip `count` values of `width` bytes.
    fn skip(&mut self, count: u64, width: usize, what: &str) -> Result<(), ParseError> {
        let n = self.room(count, width, what)?;
        self.pos += n;
        Ok(())
    }
}

struct Reader<'a> {
    c: TextCursor<'a>,
    format: Option<Format>,
    mesh: RawMesh,
    nodes: Option<NodeMap>,
    blocks: Blocks,
    /// First physical tag (0 if none) of each (dimension, entity tag).
    entity_physical: HashMap<(i32, i32), i32>,
    /// Parent (dimension, tag) of each partitioned entity that has no physical tag itself.
    partition_parent: HashMap<(i32, i32), (i32, i32)>,
}

/// Parse a token as `T`, with a lazily built description for the error message.
fn parse_tok<T: std::str::FromStr>(
    c: &mut TextCursor,
    what: &dyn Fn() -> String,
) -> Result<T, ParseError> {
    match c.next_token() {
        Some(t) => t.parse::<T>().map_err(|_| c.expected(&what(), t)),
        None => Err(c.error(format!("unexpected end of file while reading {}", what()))),
    }
}

fn f64_tok(c: &mut TextCursor, what: &dyn Fn() -> String) -> Result<f64, ParseError> {
    match c.next_token() {
        Some(t) => parse_f64(t).ok_or_else(|| c.expected(&what(), t)),
        None => Err(c.error(format!("unexpected end of file while reading {}", what()))),
    }
}

/// Reserve for `count` items, but never more than the input could possibly hold (every item
/// takes at least `min_bytes` bytes).
fn capped(count: u64, remaining: usize, min_bytes: usize) -> usize {
    usize::try_from(count)
        .unwrap_or(usize::MAX)
        .min(remaining / min_bytes.max(1))
}

fn to_i32(v: i64, c: &TextCursor, what: &str) -> Result<i32, ParseError> {
    i32::try_from(v).map_err(|_| c.error(format!("{what} {v} is out of range")))
}

impl<'a> Reader<'a> {
    fn new(data: &'a [u8]) -> Self {
        Reader {
            c: TextCursor::new(data),
            format: None,
            mesh: RawMesh::default(),
            nodes: None,
            blocks: Blocks::default(),
            entity_physical: HashMap::new(),
            partition_parent: HashMap::new(),
        }
    }

    fn run(mut self) -> Result<RawMesh, ParseError> {
        let mut any_section = false;
        while let Some(tok) = self.c.next_token() {
            let Some(name) = tok.strip_prefix('$') else {
                return Err(self.c.expected(
                    if any_section {
                        "a section header such as $Nodes"
                    } else {
                        "$MeshFormat at the start of a Gmsh file"
                    },
                    tok,
                ));
            };
            let line = self.c.line();
            if !any_section && name != "MeshFormat" && name != "NOD" && name != "NOE" {
                return Err(self
                    .c
                    .expected("$MeshFormat at the start of a Gmsh file", tok));
            }
            any_section = true;
            match name {
                "MeshFormat" => self.mesh_format()?,
                "NOD" | "NOE" => {
                    if self.format.is_none() {
                        self.format = Some(Format {
                            version: Version::V1,
                            binary: false,
                            big_endian: false,
                            size_t: 8,
                        });
                    }
                    self.nodes_section(name)?
                }
                "ELM" => self.elements_section(name, line)?,
                "PhysicalNames" => self.physical_names()?,
                "Entities" => self.entities(false)?,
                "PartitionedEntities" => self.entities(true)?,
                "Nodes" => self.nodes_section(name)?,
                "Elements" => self.elements_section(name, line)?,
                _ if name.len() >= 3 && name.as_bytes()[..3].eq_ignore_ascii_case(b"End") => {
                    return Err(self.c.error(format!(
                        "unexpected {tok} without a matching ${}",
                        name.get(3..).unwrap_or("")
                    )));
                }
                _ => self.skip_section(name, line)?,
            }
        }
        if !any_section {
            return Err(ParseError::new(
                Location::File,
                "empty file: expected a Gmsh mesh starting with $MeshFormat",
            ));
        }
        let mut mesh = self.mesh;
        for (_, mut block) in self.blocks.list {
            // Tag 0 means "no tag"; a block without any tag has none.
            if block.tags.iter().all(|&t| t == 0) {
                block.tags.clear();
            }
            mesh.push_block(block);
        }
        Ok(mesh)
    }

    fn format(&self) -> Format {
        self.format.unwrap_or(Format {
            version: Version::V2,
            binary: false,
            big_endian: false,
            size_t: 8,
        })
    }

    /// Consume `$End<name>` (MSH 1 spells it `$ENDNOD`).
    fn expect_end(&mut self, name: &str) -> Result<(), ParseError> {
        let want = format!("$End{name}");
        match self.c.next_token() {
            Some(t) if t.eq_ignore_ascii_case(&want) => Ok(()),
            Some(t) => Err(self
                .c
                .expected(&format!("{want} (or fewer entries than declared)"), t)),
            None => Err(self
                .c
                .error(format!("unexpected end of file: missing {want}"))),
        }
    }

    /// A reader for binary data starting at the cursor.
    fn bin(&self) -> Bin<'a> {
        let f = self.format();
        Bin {
            data: self.c.data(),
            pos: self.c.pos(),
            big_endian: f.big_endian,
            size_t: f.size_t,
        }
    }

    fn skip_section(&mut self, name: &str, line: usize) -> Result<(), ParseError> {
        let data = self.c.data();
        let start = self.c.pos();
        let needle_len = 4 + name.len();
        let mut i = start;
        // Look for `$End<name>` at the start of a line.
        while let Some(off) = data[i..].iter().position(|&b| b == b'\n') {
            let s = i + off + 1;
            let rest = &data[s..];
            if rest.len() >= needle_len
                && &rest[..4] == b"$End"
                && &rest[4..needle_len] == name.as_bytes()
            {
                self.c.seek_forward(s + needle_len);
                return Ok(());
            }
            i = s;
        }
        Err(ParseError::at_line(
            line,
            format!("section ${name} has no matching $End{name} line"),
        ))
    }

    fn mesh_format(&mut self) -> Result<(), ParseError> {
        if self.format.is_some() {
            return Err(self.c.error("second $MeshFormat section"));
        }
        let vt = self.c.expect_token("MSH version number")?;
        let v = parse_f64(vt).ok_or_else(|| self.c.expected("MSH version number", vt))?;
        let version = if (2.0..3.0).contains(&v) {
            Version::V2
        } else if (4.0..4.05).contains(&v) {
            Version::V40
        } else if (4.05..5.0).contains(&v) {
            Version::V41
        } else {
            return Err(self.c.error(format!(
                "MSH version {vt} is not supported (supported: 1, 2.0-2.2, 4.0, 4.1)"
            )));
        };
        let file_type =
            parse_tok::<i64>(&mut self.c, &|| "file type (0 = ASCII, 1 = binary)".into())?;
        let binary = match file_type {
            0 => false,
            1 => true,
            _ => {
                return Err(self.c.error(format!(
                    "file type {file_type} is not 0 (ASCII) or 1 (binary)"
                )));
            }
        };
        let data_size = parse_tok::<i64>(&mut self.c, &|| "data size".into())?;
        let mut format = Format {
            version,
            binary,
            big_endian: false,
            size_t: 8,
        };
        if binary {
            match version {
                Version::V40 => {
                    return Err(self.c.error(
                        "MSH 4.0 binary files are not supported; write MSH 4.1 or 2.2 instead",
                    ));
                }
                Version::V41 if data_size == 4 || data_size == 8 => {
                    format.size_t = data_size as usize
                }
                Version::V2 if data_size == 8 => {}
                _ => {
                    return Err(self.c.error(format!(
                        "binary data size {data_size} is not supported (expected 8{})",
                        if version == Version::V41 { " or 4" } else { "" }
                    )));
                }
            }
            // The binary integer 1 on the next line tells the byte order.
            self.c.skip_line();
            let mut bin = self.bin();
            let at = bin.pos;
            let b = bin.take(4, &|| {
                "the binary integer 1 that gives the byte order".into()
            })?;
            format.big_endian = match b {
                [1, 0, 0, 0] => false,
                [0, 0, 0, 1] => true,
                _ => {
                    return Err(ParseError::at_byte(
                        at,
                        format!(
                            "expected the binary integer 1 after the binary MSH header, found bytes {b:02x?}"
                        ),
                    ));
                }
            };
            self.c.seek_forward(bin.pos);
        }
        self.format = Some(format);
        self.expect_end("MeshFormat")
    }

    fn physical_names(&mut self) -> Result<(), ParseError> {
        let n = parse_tok::<u64>(&mut self.c, &|| "number of physical names".into())?;
        for i in 0..n {
            let what = || format!("physical name {} of {n}", i + 1);
            let dim = parse_tok::<i64>(&mut self.c, &|| format!("dimension of {}", what()))?;
            let tag = parse_tok::<i64>(&mut self.c, &|| format!("tag of {}", what()))?;
            let tag = to_i32(tag, &self.c, "physical tag")?;
            let _ = dim;
            let rest = self.c.next_line().unwrap_or("").trim();
            let name = rest
                .strip_prefix('"')
                .and_then(|r| r.strip_suffix('"'))
                .unwrap_or(rest);
            let entry = self.mesh.tag_names.entry(tag).or_default();
            if entry.is_empty() {
                *entry = name.to_string();
            } else if entry.split(" / ").all(|e| e != name) {
                entry.push_str(" / ");
                entry.push_str(name);
            }
        }
        self.expect_end("PhysicalNames")
    }

    /// `$Entities` or `$PartitionedEntities`: remember the first physical tag of each entity.
    fn entities(&mut self, partitioned: bool) -> Result<(), ParseError> {
        let f = self.format();
        if f.version != Version::V40 && f.version != Version::V41 {
            let name = if partitioned {
                "PartitionedEntities"
            } else {
                "Entities"
            };
            return self.skip_section(name, self.c.line());
        }
        if f.binary {
            self.c.skip_line();
            let mut b = self.bin();
            self.entities_binary(&mut b, partitioned)?;
            self.c.seek_forward(b.pos);
        } else {
            self.entities_ascii(partitioned, f.version)?;
        }
        self.expect_end(if partitioned {
            "PartitionedEntities"
        } else {
            "Entities"
        })
    }

    fn record_entity(&mut self, dim: i32, tag: i32, first_phys: i32, parent: Option<(i32, i32)>) {
        self.entity_physical.insert((dim, tag), first_phys);
        // A partition entity inherits its parent's physical group only from a parent of the
        // same dimension (partition interfaces have the volume or surface as parent).
        if let Some(p) = parent
            && first_phys == 0
            && p.0 == dim
        {
            self.partition_parent.insert((dim, tag), p);
        }
    }

    fn entities_ascii(&mut self, partitioned: bool, version: Version) -> Result<(), ParseError> {
        let c = &mut self.c;
        if partitioned {
            let _parts = parse_tok::<u64>(c, &|| "number of partitions".into())?;
            let ghosts = parse_tok::<u64>(c, &|| "number of ghost entities".into())?;
            for _ in 0..ghosts {
                parse_tok::<i64>(c, &|| "ghost entity tag".into())?;
                parse_tok::<i64>(c, &|| "ghost entity partition".into())?;
            }
        }
        let mut counts = [0u64; 4];
        for (d, n) in counts.iter_mut().enumerate() {
            *n = parse_tok::<u64>(&mut self.c, &|| {
                format!(
                    "number of {} entities",
                    ["point", "curve", "surface", "volume"][d]
                )
            })?;
        }
        for (dim, &count) in counts.iter().enumerate() {
            let dim = dim as i32;
            for k in 0..count {
                let c = &mut self.c;
                let what =
                    |s: &'static str| move || format!("{s} of entity {} of dimension {dim}", k + 1);
                let tag = parse_tok::<i64>(c, &what("tag"))?;
                let tag = to_i32(tag, c, "entity tag")?;
                let mut parent = None;
                if partitioned {
                    let pdim = parse_tok::<i64>(c, &what("parent dimension"))?;
                    let ptag = parse_tok::<i64>(c, &what("parent tag"))?;
                    parent = Some((
                        to_i32(pdim, c, "dimension")?,
                        to_i32(ptag, c, "entity tag")?,
                    ));
                    let np = parse_tok::<u64>(c, &what("number of partitions"))?;
                    for _ in 0..np {
                        parse_tok::<i64>(c, &what("partition"))?;
                    }
                }
                let nbox = if version == Version::V41 && dim == 0 {
                    3
                } else {
                    6
                };
                for _ in 0..nbox {
                    f64_tok(c, &what("bounding box coordinate"))?;
                }
                let nphys = parse_tok::<u64>(c, &what("number of physical tags"))?;
                let mut first = 0;
                for j in 0..nphys {
                    let p = parse_tok::<i64>(c, &what("physical tag"))?;
                    if j == 0 {
                        first = to_i32(p, c, "physical tag")?;
                    }
                }
                if dim > 0 {
                    let nb = parse_tok::<u64>(c, &what("number of bounding entities"))?;
                    for _ in 0..nb {
                        parse_tok::<i64>(c, &what("bounding entity tag"))?;
                    }
                }
                self.record_entity(dim, tag, first, parent);
            }
        }
        Ok(())
    }

    fn entities_binary(&mut self, b: &mut Bin, partitioned: bool) -> Result<(), ParseError> {
        let sz = b.size_t;
        if partitioned {
            b.size(&|| "number of partitions".into())?;
            let ghosts = b.size(&|| "number of ghost entities".into())?;
            b.skip(ghosts, 8, "ghost entities")?;
        }
        let mut counts = [0u64; 4];
        for n in counts.iter_mut() {
            *n = b.size(&|| "number of entities".into())?;
        }
        for (dim, &count) in counts.iter().enumerate() {
            let dim = dim as i32;
            // Every entity takes at least an int, a box and a count.
            b.room(count, 4 + 24 + sz, "entities")?;
            for k in 0..count {
                let what = || format!("entity {} of dimension {dim}", k + 1);
                let tag = b.i32(&what)?;
                let mut parent = None;
                if partitioned {
                    let pdim = b.i32(&what)?;
                    let ptag = b.i32(&what)?;
                    parent = Some((pdim, ptag));
                    let np = b.size(&what)?;
                    b.skip(np, 4, "partition tags")?;
                }
                b.take(if dim == 0 { 24 } else { 48 }, &what)?;
                let nphys = b.size(&what)?;
                b.room(nphys, 4, "physical tags")?;
                let mut first = 0;
                if nphys > 0 {
                    first = b.i32(&what)?;
                    b.skip(nphys - 1, 4, "physical tags")?;
                }
                if dim > 0 {
                    let nb = b.size(&what)?;
                    b.skip(nb, 4, "bounding entity tags")?;
                }
                self.record_entity(dim, tag, first, parent);
            }
        }
        Ok(())
    }

    /// Physical tag of the elements of entity (dim, tag).
    fn physical_of(&self, dim: i32, tag: i32) -> i32 {
        match self.entity_physical.get(&(dim, tag)) {
            Some(&p) if p != 0 => p,
            _ => self
                .partition_parent
                .get(&(dim, tag))
                .and_then(|parent| self.entity_physical.get(parent))
                .copied()
                .unwrap_or(0),
        }
    }

    fn nodes_section(&mut self, name: &str) -> Result<(), ParseError> {
        if self.nodes.is_some() {
            return Err(self.c.error(format!("second ${name} section")));
        }
        let f = self.format();
        let mut tags: Vec<u64> = Vec::new();
        match (f.version, f.binary) {
            (Version::V1 | Version::V2, false) => self.nodes_v2_ascii(&mut tags)?,
            (Version::V2, true) => self.nodes_v2_binary(&mut tags)?,
            (Version::V40 | Version::V41, false) => self.nodes_v4_ascii(&mut tags, f.version)?,
            (_, true) => self.nodes_v41_binary(&mut tags)?,
        }
        self.nodes = Some(NodeMap::build(&tags, &self.mesh.point_locations)?);
        self.expect_end(name)
    }

    fn push_point(&mut self, p: [f64; 3], loc: Location) {
        self.mesh.points.push(p);
        self.mesh.point_locations.push(loc);
    }

    fn reserve_points(&mut self, n: usize) {
        self.mesh.points.reserve(n);
        self.mesh.point_locations.reserve(n);
    }

    fn nodes_v2_ascii(&mut self, tags: &mut Vec<u64>) -> Result<(), ParseError> {
        let n = parse_tok::<u64>(&mut self.c, &|| "number of nodes".into())?;
        let remaining = self.c.data().len() - self.c.pos();
        let cap = capped(n, remaining, 8);
        tags.reserve(cap);
        self.reserve_points(cap);
        for i in 0..n {
            let c = &mut self.c;
            let tag = parse_tok::<u64>(c, &|| format!("tag of node {} of {n}", i + 1))?;
            let loc = c.location();
            let mut p = [0.0; 3];
            for (k, x) in p.iter_mut().enumerate() {
                *x = f64_tok(c, &|| {
                    format!("{} coordinate of node {tag}", ["x", "y", "z"][k])
                })?;
            }
            tags.push(tag);
            self.push_point(p, loc);
        }
        Ok(())
    }

    fn nodes_v2_binary(&mut self, tags: &mut Vec<u64>) -> Result<(), ParseError> {
        let n = parse_tok::<u64>(&mut self.c, &|| "number of nodes".into())?;
        self.c.skip_line();
        let mut b = self.bin();
        let start = b.pos;
        let len = b.room(n, 28, "nodes")?;
        let data = b.take(len, &|| "node records".into())?;
        tags.reserve(n as usize);
        self.reserve_points(n as usize);
        for (i, r) in data.chunks_exact(28).enumerate() {
            let at = start + 28 * i;
            let tag = b.dec_i32(r);
            if tag < 0 {
                return Err(ParseError::at_byte(at, format!("negative node tag {tag}")));
            }
            tags.push(tag as u64);
            let p = [b.dec_f64(&r[4..]), b.dec_f64(&r[12..]), b.dec_f64(&r[20..])];
            self.push_point(p, Location::Byte(at));
        }
        self.c.seek_forward(b.pos);
        Ok(())
    }

    fn nodes_v4_ascii(&mut self, tags: &mut Vec<u64>, version: Version) -> Result<(), ParseError> {
        let c = &mut self.c;
        let blocks = parse_tok::<u64>(c, &|| "number of node entity blocks".into())?;
        let total = parse_tok::<u64>(c, &|| "number of nodes".into())?;
        if version == Version::V41 {
            parse_tok::<u64>(c, &|| "minimum node tag".into())?;
            parse_tok::<u64>(c, &|| "maximum node tag".into())?;
        }
        let remaining = c.data().len() - c.pos();
        let cap = capped(total, remaining, 8);
        tags.reserve(cap);
        self.reserve_points(cap);
        for blk in 0..blocks {
            let c = &mut self.c;
            let what = |s: &'static str| move || format!("{s} of node block {}", blk + 1);
            let (dim, parametric, count);
            if version == Version::V41 {
                dim = parse_tok::<i64>(c, &what("entity dimension"))?;
                parse_tok::<i64>(c, &what("entity tag"))?;
            } else {
                parse_tok::<i64>(c, &what("entity tag"))?;
                dim = parse_tok::<i64>(c, &what("entity dimension"))?;
            }
            parametric = parse_tok::<i64>(c, &what("parametric flag"))?;
            count = parse_tok::<u64>(c, &what("number of nodes"))?;
            if !(0..=3).contains(&dim) {
                return Err(c.error(format!("entity dimension {dim} is not 0, 1, 2 or 3")));
            }
            let nparam = if parametric != 0 { dim as usize } else { 0 };
            let first = tags.len();
            if version == Version::V41 {
                for i in 0..count {
                    let t = parse_tok::<u64>(c, &|| {
                        format!("node tag {} of {count} in node block {}", i + 1, blk + 1)
                    })?;
                    tags.push(t);
                }
            }
            for i in 0..count {
                let c = &mut self.c;
                let tag = if version == Version::V41 {
                    tags[first + i as usize]
                } else {
                    let t = parse_tok::<u64>(c, &|| {
                        format!("node tag {} of {count} in node block {}", i + 1, blk + 1)
                    })?;
                    tags.push(t);
                    t
                };
                let mut p = [0.0; 3];
                let mut loc = Location::File;
                for (k, x) in p.iter_mut().enumerate() {
                    *x = f64_tok(c, &|| {
                        format!("{} coordinate of node {tag}", ["x", "y", "z"][k])
                    })?;
                    if k == 0 {
                        loc = c.location();
                    }
                }
                for _ in 0..nparam {
                    f64_tok(c, &|| format!("parametric coordinate of node {tag}"))?;
                }
                self.push_point(p, loc);
            }
        }
        if tags.len() as u64 != total {
            return Err(self.c.error(format!(
                "$Nodes declares {total} nodes but its blocks hold {}",
                tags.len()
            )));
        }
        Ok(())
    }

    fn nodes_v41_binary(&mut self, tags: &mut Vec<u64>) -> Result<(), ParseError> {
        self.c.skip_line();
        let mut b = self.bin();
        let sz = b.size_t;
        let blocks = b.size(&|| "number of node entity blocks".into())?;
        let total = b.size(&|| "number of nodes".into())?;
        b.size(&|| "minimum node tag".into())?;
        b.size(&|| "maximum node tag".into())?;
        let cap = capped(total, b.remaining(), sz + 24);
        tags.reserve(cap);
        self.reserve_points(cap);
        for blk in 0..blocks {
            let what = || format!("header of node block {}", blk + 1);
            let header_at = b.pos;
            let dim = b.i32(&what)?;
            b.i32(&what)?;
            let parametric = b.i32(&what)?;
            let count = b.size(&what)?;
            if !(0..=3).contains(&dim) {
                return Err(ParseError::at_byte(
                    header_at,
                    format!(
                        "entity dimension {dim} of node block {} is not 0, 1, 2 or 3",
                        blk + 1
                    ),
                ));
            }
            let nval = 3 + if parametric != 0 { dim as usize } else { 0 };
            // Tags of the whole block first, then its coordinates.
            let tag_len = b.room(count, sz, "node tags")?;
            let tag_data = b.take(tag_len, &|| "node tags".into())?;
            tags.extend(tag_data.chunks_exact(sz).map(|t| b.dec_size(t)));
            let rec = 8 * nval;
            let coord_at = b.pos;
            let len = b.room(count, rec, "node coordinate records")?;
            let data = b.take(len, &|| "node coordinates".into())?;
            for (i, r) in data.chunks_exact(rec).enumerate() {
                let p = [b.dec_f64(r), b.dec_f64(&r[8..]), b.dec_f64(&r[16..])];
                self.push_point(p, Location::Byte(coord_at + i * rec));
            }
        }
        if tags.len() as u64 != total {
            return Err(ParseError::at_byte(
                b.pos,
                format!(
                    "$Nodes declares {total} nodes but its blocks hold {}",
                    tags.len()
                ),
            ));
        }
        self.c.seek_forward(b.pos);
        Ok(())
    }

    fn elements_section(&mut self, name: &str, line: usize) -> Result<(), ParseError> {
        let Some(nodes) = self.nodes.take() else {
            return Err(ParseError::at_line(
                line,
                format!("${name} section before the $Nodes section"),
            ));
        };
        let f = self.format();
        let r = match (f.version, f.binary) {
            (Version::V1 | Version::V2, false) => self.elements_v2_ascii(&nodes, f.version),
            (Version::V2, true) => self.elements_v2_binary(&nodes),
            (Version::V40 | Version::V41, false) => self.elements_v4_ascii(&nodes, f.version),
            (_, true) => self.elements_v41_binary(&nodes),
        };
        self.nodes = Some(nodes);
        r?;
        self.expect_end(name)
    }

    fn elements_v2_ascii(&mut self, nodes: &NodeMap, version: Version) -> Result<(), ParseError> {
        let n = parse_tok::<u64>(&mut self.c, &|| "number of elements".into())?;
        for i in 0..n {
            let c = &mut self.c;
            let id = parse_tok::<u64>(c, &|| format!("number of element {} of {n}", i + 1))?;
            let loc = c.location();
            let ty = parse_tok::<i64>(c, &|| format!("type of element {id}"))?;
            let bi = self.blocks.index(ty, loc)?;
            let npe = self.blocks.list[bi].1.nodes_per_cell;
            let physical;
            if version == Version::V1 {
                let p = parse_tok::<i64>(c, &|| format!("physical region of element {id}"))?;
                physical = to_i32(p, c, "physical tag")?;
                parse_tok::<i64>(c, &|| format!("elementary region of element {id}"))?;
                let nn = parse_tok::<u64>(c, &|| format!("node count of element {id}"))?;
                if nn != npe as u64 {
                    return Err(c.error(format!(
                        "element {id} of Gmsh type {ty} has {npe} nodes, but the file says {nn}"
                    )));
                }
            } else {
                let ntags = parse_tok::<u64>(c, &|| format!("number of tags of element {id}"))?;
                let mut first = 0;
                for j in 0..ntags {
                    let t = parse_tok::<i64>(c, &|| format!("tag {} of element {id}", j + 1))?;
                    if j == 0 {
                        first = to_i32(t, c, "physical tag")?;
                    }
                }
                physical = first;
            }
            let block = &mut self.blocks.list[bi].1;
            for k in 0..npe {
                let t =
                    parse_tok::<u64>(c, &|| format!("node {} of {npe} of element {id}", k + 1))?;
                let Some(v) = nodes.get(t) else {
                    return Err(c.error(format!(
                        "element {id} refers to node {t}, which $Nodes does not define"
                    )));
                };
                block.nodes.push(i64::from(v));
            }
            block.tags.push(physical);
            block.locations.push(loc);
        }
        Ok(())
    }

    fn elements_v2_binary(&mut self, nodes: &NodeMap) -> Result<(), ParseError> {
        let n = parse_tok::<u64>(&mut self.c, &|| "number of elements".into())?;
        self.c.skip_line();
        let mut b = self.bin();
        let mut read = 0u64;
        while read < n {
            let header_at = b.pos;
            let what = || format!("element block header after {read} of {n} elements");
            let ty = b.i32(&what)?;
            let count = b.i32(&what)?;
            let ntags = b.i32(&what)?;
            if count < 0 || ntags < 0 {
                return Err(ParseError::at_byte(
                    header_at,
                    format!(
                        "element block header has a negative count ({count} elements, {ntags} tags)"
                    ),
                ));
            }
            if count as u64 > n - read {
                return Err(ParseError::at_byte(
                    header_at,
                    format!(
                        "element block of {count} elements exceeds the {} elements left of the {n} declared",
                        n - read
                    ),
                ));
            }
            let bi = self
                .blocks
                .index(i64::from(ty), Location::Byte(header_at))?;
            let block = &mut self.blocks.list[bi].1;
            let npe = block.nodes_per_cell;
            let ntags = ntags as usize;
            let rec = 4 * (1 + ntags + npe);
            let start = b.pos;
            let len = b.room(count as u64, rec, "element records")?;
            let data = b.take(len, &|| "element records".into())?;
            block.nodes.reserve(count as usize * npe);
            for (e, r) in data.chunks_exact(rec).enumerate() {
                let at = start + e * rec;
                let physical = if ntags > 0 { b.dec_i32(&r[4..]) } else { 0 };
                for node in r[4 * (1 + ntags)..].chunks_exact(4) {
                    let t = b.dec_i32(node);
                    let Some(v) = u64::try_from(t).ok().and_then(|t| nodes.get(t)) else {
                        return Err(ParseError::at_byte(
                            at,
                            format!(
                                "element {} refers to node {t}, which $Nodes does not define",
                                b.dec_i32(r)
                            ),
                        ));
                    };
                    block.nodes.push(i64::from(v));
                }
                block.tags.push(physical);
                block.locations.push(Location::Byte(at));
            }
            read += count as u64;
        }
        self.c.seek_forward(b.pos);
        Ok(())
    }

    fn elements_v4_ascii(&mut self, nodes: &NodeMap, version: Version) -> Result<(), ParseError> {
        let c = &mut self.c;
        let blocks = parse_tok::<u64>(c, &|| "number of element entity blocks".into())?;
        let total = parse_tok::<u64>(c, &|| "number of elements".into())?;
        if version == Version::V41 {
            parse_tok::<u64>(c, &|| "minimum element tag".into())?;
            parse_tok::<u64>(c, &|| "maximum element tag".into())?;
        }
        let mut read = 0u64;
        for blk in 0..blocks {
            let c = &mut self.c;
            let what = |s: &'static str| move || format!("{s} of element block {}", blk + 1);
            let (dim, etag);
            if version == Version::V41 {
                dim = parse_tok::<i64>(c, &what("entity dimension"))?;
                etag = parse_tok::<i64>(c, &what("entity tag"))?;
            } else {
                etag = parse_tok::<i64>(c, &what("entity tag"))?;
                dim = parse_tok::<i64>(c, &what("entity dimension"))?;
            }
            let ty = parse_tok::<i64>(c, &what("element type"))?;
            let type_loc = c.location();
            let count = parse_tok::<u64>(c, &what("number of elements"))?;
            let physical = match (i32::try_from(dim), i32::try_from(etag)) {
                (Ok(d), Ok(t)) => self.physical_of(d, t),
                _ => 0,
            };
            let bi = self.blocks.index(ty, type_loc)?;
            let block = &mut self.blocks.list[bi].1;
            let npe = block.nodes_per_cell;
            let c = &mut self.c;
            let remaining = c.data().len() - c.pos();
            block
                .nodes
                .reserve(capped(count, remaining, 2 * (npe + 1)).saturating_mul(npe));
            for i in 0..count {
                let id = parse_tok::<u64>(c, &|| {
                    format!(
                        "tag of element {} of {count} in element block {}",
                        i + 1,
                        blk + 1
                    )
                })?;
                let loc = c.location();
                for k in 0..npe {
                    let t = parse_tok::<u64>(c, &|| {
                        format!("node {} of {npe} of element {id}", k + 1)
                    })?;
                    let Some(v) = nodes.get(t) else {
                        return Err(c.error(format!(
                            "element {id} refers to node {t}, which $Nodes does not define"
                        )));
                    };
                    block.nodes.push(i64::from(v));
                }
                block.tags.push(physical);
                block.locations.push(loc);
            }
            read += count;
        }
        if read != total {
            return Err(self.c.error(format!(
                "$Elements declares {total} elements but its blocks hold {read}"
            )));
        }
        Ok(())
    }

    fn elements_v41_binary(&mut self, nodes: &NodeMap) -> Result<(), ParseError> {
        self.c.skip_line();
        let mut b = self.bin();
        let sz = b.size_t;
        let blocks = b.size(&|| "number of element entity blocks".into())?;
        let total = b.size(&|| "number of elements".into())?;
        b.size(&|| "minimum element tag".into())?;
        b.size(&|| "maximum element tag".into())?;
        let mut read = 0u64;
        for blk in 0..blocks {
            let what = || format!("header of element block {}", blk + 1);
            let header_at = b.pos;
            let dim = b.i32(&what)?;
            let etag = b.i32(&what)?;
            let ty = b.i32(&what)?;
            let count = b.size(&what)?;
            let physical = self.physical_of(dim, etag);
            let bi = self
                .blocks
                .index(i64::from(ty), Location::Byte(header_at))?;
            let block = &mut self.blocks.list[bi].1;
            let npe = block.nodes_per_cell;
            let rec = sz * (1 + npe);
            let start = b.pos;
            let len = b.room(count, rec, "element records")?;
            let data = b.take(len, &|| "element records".into())?;
            block.nodes.reserve(count as usize * npe);
            for (e, r) in data.chunks_exact(rec).enumerate() {
                let at = start + e * rec;
                for node in r[sz..].chunks_exact(sz) {
                    let t = b.dec_size(node);
                    let Some(v) = nodes.get(t) else {
                        return Err(ParseError::at_byte(
                            at,
                            format!(
                                "element {} refers to node {t}, which $Nodes does not define",
                                b.dec_size(r)
                            ),
                        ));
                    };
                    block.nodes.push(i64::from(v));
                }
                block.tags.push(physical);
                block.locations.push(Location::Byte(at));
            }
            read += count;
        }
        if read != total {
            return Err(ParseError::at_byte(
                b.pos,
                format!("$Elements declares {total} elements but its blocks hold {read}"),
            ));
        }
        self.c.seek_forward(b.pos);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{LinearMesh, MeshOptions};
    use std::collections::BTreeMap;

    fn fixture(name: &str) -> Vec<u8> {
        let path = format!("{}/tests/data/gmsh/{name}", env!("CARGO_MANIFEST_DIR"));
        std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
    }

    fn real(name: &str) -> Vec<u8> {
        let path = format!("{}/meshes/real/{name}", env!("CARGO_MANIFEST_DIR"));
        std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
    }

    fn parse(data: &[u8]) -> RawMesh {
        read(data).unwrap_or_else(|e| panic!("{e}"))
    }

    fn parse_str(s: &str) -> Result<RawMesh, ParseError> {
        read(s.as_bytes())
    }

    fn count(m: &RawMesh, kind: &CellKind) -> usize {
        m.count(kind)
    }

    fn block<'m>(m: &'m RawMesh, kind: &CellKind) -> &'m RawBlock {
        m.block(kind).unwrap_or_else(|| panic!("no {kind:?} block"))
    }

    type Cell = (i32, Vec<[i64; 3]>);

    /// Coordinates quantised to 1e-10: ASCII files hold 16 significant digits, binary ones the
    /// exact doubles.
    fn q(p: &[f64; 3]) -> [i64; 3] {
        p.map(|x| (x * 1e10).round() as i64)
    }

    /// Cells by kind as (tag, node coordinates), sorted: independent of node numbering and of
    /// cell order, so files written in different versions can be compared.
    fn canonical(m: &RawMesh) -> BTreeMap<String, Vec<Cell>> {
        let mut out: BTreeMap<String, Vec<Cell>> = BTreeMap::new();
        for b in &m.blocks {
            let cells = out.entry(format!("{:?}", b.kind())).or_default();
            for c in 0..b.len() {
                let nodes = b.nodes[c * b.nodes_per_cell..(c + 1) * b.nodes_per_cell]
                    .iter()
                    .map(|&v| q(&m.points[v as usize]))
                    .collect();
                cells.push((b.tags.get(c).copied().unwrap_or(0), nodes));
            }
        }
        for cells in out.values_mut() {
            cells.sort();
        }
        out
    }

    fn sorted_points(m: &RawMesh) -> Vec<[i64; 3]> {
        let mut p: Vec<_> = m.points.iter().map(q).collect();
        p.sort();
        p
    }

    fn linear(m: RawMesh) -> Result<LinearMesh, ParseError> {
        LinearMesh::from_raw(m, &MeshOptions::default())
    }

    // ---- fixtures written by gmsh / meshio ----

    #[test]
    fn box_variants_agree() {
        let reference = parse(&fixture("box_22_ascii.msh"));
        assert_eq!(reference.points.len(), 64);
        assert_eq!(count(&reference, &CellKind::Hexahedron), 27);
        assert_eq!(count(&reference, &CellKind::Quad), 18);
        assert_eq!(reference.blocks.len(), 2);
        let names: Vec<_> = reference
            .tag_names
            .iter()
            .map(|(k, v)| (*k, v.as_str()))
            .collect();
        assert_eq!(names, [(1, "block"), (10, "bottom"), (11, "top face")]);
        // Physical groups: every hex in 1; quads at z = 0 in 10, at z = 1.5 in 11.
        let hex = block(&reference, &CellKind::Hexahedron);
        assert!(hex.tags.iter().all(|&t| t == 1));
        let quads = block(&reference, &CellKind::Quad);
        for c in 0..quads.len() {
            let z: Vec<f64> = quads.nodes[4 * c..4 * c + 4]
                .iter()
                .map(|&v| reference.points[v as usize][2])
                .collect();
            let want = if z.iter().all(|&z| z == 0.0) {
                10
            } else {
                assert!(z.iter().all(|&z| z == 1.5), "{z:?}");
                11
            };
            assert_eq!(quads.tags[c], want);
        }
        // First hex of the 2.2 file: "99 5 2 1 1 1 33 10 ... " -> check its first corner.
        assert_eq!(hex.locations[0], Location::Line(97));
        let canon = canonical(&reference);
        let points = sorted_points(&reference);
        assert!(points.contains(&q(&[1.0, 1.0, 1.5])));

        for name in [
            "box_22_bin.msh",
            "box_1_ascii.msh",
            "box_40_ascii.msh",
            "box_41_ascii.msh",
            "box_41_bin.msh",
            "partitioned_41.msh",
        ] {
            let m = parse(&fixture(name));
            assert_eq!(m.points.len(), 64, "{name}");
            assert_eq!(m.point_locations.len(), 64, "{name}");
            assert_eq!(sorted_points(&m), points, "{name}");
            assert_eq!(canonical(&m), canon, "{name}");
            if name != "box_1_ascii.msh" {
                assert_eq!(m.tag_names, reference.tag_names, "{name}");
            }
            for b in &m.blocks {
                assert_eq!(b.locations.len(), b.len(), "{name}");
            }
        }

        // Same writer, same order: ASCII and binary twins agree exactly.
        for (a, b) in [
            ("box_22_ascii.msh", "box_22_bin.msh"),
            ("box_41_ascii.msh", "box_41_bin.msh"),
        ] {
            let (a, b) = (parse(&fixture(a)), parse(&fixture(b)));
            let qa: Vec<_> = a.points.iter().map(q).collect();
            let qb: Vec<_> = b.points.iter().map(q).collect();
            assert_eq!(qa, qb);
            for (x, y) in a.blocks.iter().zip(&b.blocks) {
                assert_eq!(x.kind, y.kind);
                assert_eq!(x.nodes, y.nodes);
                assert_eq!(x.tags, y.tags);
            }
            assert!(matches!(a.point_locations[0], Location::Line(_)));
            assert!(matches!(b.point_locations[0], Location::Byte(_)));
        }

        let lin = linear(reference).unwrap();
        assert_eq!(lin.dim, 3);
        assert_eq!(lin.n_elements(), 27);
        assert_eq!(lin.n_vertices(), 64);
        assert_eq!(lin.facet_tags.len(), 18);
    }

    #[test]
    fn binary_locations_point_at_records() {
        // In the 2.2 binary box the first node record starts right after "$Nodes\n64\n".
        let data = fixture("box_22_bin.msh");
        let m = parse(&data);
        let Location::Byte(at) = m.point_locations[0] else {
            panic!()
        };
        let head = b"$Nodes\n64\n";
        let start = data.windows(head.len()).position(|w| w == head).unwrap() + head.len();
        assert_eq!(at, start);
        assert_eq!(i32::from_le_bytes(data[at..at + 4].try_into().unwrap()), 1);
        let x = f64::from_le_bytes(data[at + 4..at + 12].try_into().unwrap());
        assert_eq!(x, m.points[0][0]);
    }

    #[test]
    fn ball_rewritten_in_binary_matches_the_ascii_original() {
        let original = parse(&real("dealii/unstructured_refined_ball.msh"));
        let canon = canonical(&original);
        for name in ["ball_22_bin.msh", "ball_41_bin.msh"] {
            let m = parse(&fixture(name));
            assert_eq!(m.points.len(), 581, "{name}");
            assert_eq!(sorted_points(&m), sorted_points(&original), "{name}");
            assert_eq!(canonical(&m), canon, "{name}");
            let lin = linear(m).unwrap();
            assert_eq!((lin.dim, lin.n_elements(), lin.n_vertices()), (2, 542, 581));
        }
    }

    #[test]
    fn meshio_binary_41_matches_the_mfem_original() {
        // The MFEM file's vertices and elements, read directly.
        let text = String::from_utf8(real("mfem/cylinder-hex.mesh")).unwrap();
        let lines: Vec<&str> = text.lines().map(str::trim).collect();
        let e = lines.iter().position(|l| *l == "elements").unwrap();
        let n: usize = lines[e + 1].parse().unwrap();
        let elements: Vec<Vec<i64>> = (0..n)
            .map(|k| {
                lines[e + 2 + k]
                    .split_whitespace()
                    .skip(2)
                    .map(|t| t.parse().unwrap())
                    .collect()
            })
            .collect();
        let v = lines.iter().position(|l| *l == "vertices").unwrap();
        let nv: usize = lines[v + 1].parse().unwrap();
        let vertices: Vec<[f64; 3]> = (0..nv)
            .map(|k| {
                let x: Vec<f64> = lines[v + 3 + k]
                    .split_whitespace()
                    .map(|t| t.parse().unwrap())
                    .collect();
                [x[0], x[1], x[2]]
            })
            .collect();

        let m = parse(&fixture("cylinder_meshio_41_bin.msh"));
        assert_eq!(m.points, vertices);
        assert_eq!(m.blocks.len(), 1);
        let hex = block(&m, &CellKind::Hexahedron);
        assert_eq!(hex.len(), 252);
        assert_eq!(hex.nodes, elements.concat());
        // meshio writes no $Entities, so there are no physical groups.
        assert!(hex.tags.is_empty());
    }

    #[test]
    fn tetrahedra_are_reported() {
        let m = parse(&fixture("tets_41.msh"));
        assert_eq!(count(&m, &CellKind::Tetra), 1140);
        assert_eq!(count(&m, &CellKind::Triangle), 540);
        assert_eq!(m.points.len(), 341);
        let e = linear(m).unwrap_err();
        assert!(e.message.contains("1140 tetrahedra"), "{}", e.message);
    }

    #[test]
    fn high_order_cells_are_named() {
        let m = parse(&fixture("quad9_22.msh"));
        let q9 = CellKind::Lagrange {
            dim: 2,
            order: 2,
            convention: NodeConvention::Gmsh,
        };
        let l3 = CellKind::Lagrange {
            dim: 1,
            order: 2,
            convention: NodeConvention::Gmsh,
        };
        assert_eq!(count(&m, &q9), 4);
        assert_eq!(count(&m, &l3), 8);
        assert_eq!(count(&m, &CellKind::Vertex), 4);
        assert_eq!(block(&m, &q9).nodes_per_cell, 9);
        // Centre node (index 8) of the first quad9 is the mean of its corners.
        let b = block(&m, &q9);
        let p = |i: usize| m.points[b.nodes[i] as usize];
        for d in 0..2 {
            let mean = (0..4).map(|i| p(i)[d]).sum::<f64>() / 4.0;
            assert!((p(8)[d] - mean).abs() < 1e-12);
        }
        let e = linear(m).unwrap_err();
        assert!(
            e.message.contains("order-2 9-node quadrilaterals"),
            "{}",
            e.message
        );
    }

    #[test]
    fn element_type_table() {
        assert_eq!(element_type(5).unwrap(), (CellKind::Hexahedron, 8));
        assert_eq!(element_type(15).unwrap(), (CellKind::Vertex, 1));
        assert_eq!(element_type(6).unwrap(), (CellKind::Wedge, 6));
        for (t, name, n) in [
            (17, "20-node hexahedron (Gmsh type 17)", 20),
            (16, "8-node quadrilateral (Gmsh type 16)", 8),
            (11, "10-node tetrahedron (Gmsh type 11)", 10),
        ] {
            assert_eq!(element_type(t).unwrap(), (CellKind::Other(name.into()), n));
        }
        for (t, dim, order, n) in [
            (12, 3, 2, 27),
            (36, 2, 3, 16),
            (92, 3, 3, 64),
            (98, 3, 9, 1000),
            (8, 1, 2, 3),
        ] {
            let kind = CellKind::Lagrange {
                dim,
                order,
                convention: NodeConvention::Gmsh,
            };
            assert_eq!(element_type(t).unwrap(), (kind, n));
        }
        assert!(
            element_type(76)
                .unwrap_err()
                .contains("unknown Gmsh element type 76")
        );
        assert!(element_type(34).unwrap_err().contains("polygon"));
        assert!(element_type(-1).is_err());
        assert!(element_type(i64::MAX).is_err());
        assert!(ELEMENT_TYPES.windows(2).all(|w| w[0].0 < w[1].0));
    }

    // ---- real files (counts from meshes/real/SOURCES.md) ----

    #[test]
    fn real_hole8170_v20() {
        let m = parse(&real("dealii/hole8170.msh"));
        assert_eq!(m.points.len(), 8449);
        assert_eq!(count(&m, &CellKind::Quad), 8170);
        assert_eq!(m.blocks.len(), 1);
        assert!(m.tag_names.is_empty());
        let lin = linear(m).unwrap();
        assert_eq!(
            (lin.dim, lin.n_elements(), lin.n_vertices()),
            (2, 8170, 8449)
        );
    }

    #[test]
    fn real_example_v41() {
        let m = parse(&real("dealii/example.msh"));
        assert_eq!(m.points.len(), 835);
        assert_eq!(count(&m, &CellKind::Quad), 744);
        assert_eq!(count(&m, &CellKind::Line), 184);
        let lin = linear(m).unwrap();
        assert_eq!((lin.dim, lin.n_elements(), lin.n_vertices()), (2, 744, 835));
    }

    #[test]
    fn real_unstructured_refined_ball_v22() {
        let m = parse(&real("dealii/unstructured_refined_ball.msh"));
        assert_eq!(m.points.len(), 581);
        assert_eq!(count(&m, &CellKind::Quad), 542);
        assert_eq!(count(&m, &CellKind::Line), 76);
        assert_eq!(count(&m, &CellKind::Vertex), 1);
        // "1 -5.253322182645479 2.898678140929567 0" is the first node, on line 6.
        assert_eq!(m.points[0], [-5.253322182645479, 2.898678140929567, 0.0]);
        assert_eq!(m.point_locations[0], Location::Line(6));
        let lin = linear(m).unwrap();
        assert_eq!((lin.dim, lin.n_elements(), lin.n_vertices()), (2, 542, 581));
    }

    #[test]
    fn real_sphere_r6_v22() {
        let m = parse(&real("dealii/sphere_r6.msh"));
        assert_eq!(m.points.len(), 4776);
        assert_eq!(count(&m, &CellKind::Hexahedron), 4625);
        assert_eq!(count(&m, &CellKind::Quad), 150);
        let lin = linear(m).unwrap();
        assert_eq!(
            (lin.dim, lin.n_elements(), lin.n_vertices()),
            (3, 4625, 4776)
        );
        assert_eq!(lin.facet_tags.len(), 150);
    }

    #[test]
    fn real_70deg_cone_v41_partial_physicals() {
        let m = parse(&real("hopr/70degCone_3D.msh"));
        assert_eq!(m.points.len(), 24189);
        assert_eq!(count(&m, &CellKind::Hexahedron), 19952);
        let boundary =
            count(&m, &CellKind::Quad) + count(&m, &CellKind::Line) + count(&m, &CellKind::Vertex);
        assert_eq!(count(&m, &CellKind::Quad), 4926);
        assert!(boundary > 4926);
        // Only the boundary surfaces carry physical groups; the volume has none.
        assert!(block(&m, &CellKind::Hexahedron).tags.is_empty());
        let quads = block(&m, &CellKind::Quad);
        let mut tags = quads.tags.clone();
        tags.sort();
        tags.dedup();
        assert_eq!(tags, [29, 30, 31, 32]);
        assert_eq!(m.tag_names[&32], "WALL");
        let lin = linear(m).unwrap();
        assert_eq!(
            (lin.dim, lin.n_elements(), lin.n_vertices()),
            (3, 19952, 24189)
        );
        assert_eq!(lin.facet_tags.len(), 4926);
    }

    #[test]
    fn real_naca4412_v22() {
        let m = parse(&real("trixi-juliacon2024-naca4412/NACA4412_2.msh"));
        assert_eq!(m.points.len(), 29250);
        assert_eq!(count(&m, &CellKind::Hexahedron), 14336);
        assert_eq!(count(&m, &CellKind::Quad), 29200);
        assert_eq!(m.tag_names.len(), 9);
        assert_eq!(m.tag_names[&6], "b6-viscous_solid");
        assert!(
            block(&m, &CellKind::Hexahedron)
                .tags
                .iter()
                .all(|&t| t == 1)
        );
        let lin = linear(m).unwrap();
        assert_eq!(
            (lin.dim, lin.n_elements(), lin.n_vertices()),
            (3, 14336, 29250)
        );
    }

    // ---- hand-written variants ----

    const V41_PARTIAL: &str = "$MeshFormat\n4.1 0 8\n$EndMeshFormat
$Entities
0 0 2 0
1 0 0 0 1 1 0 2 5 6 0
2 1 0 0 2 1 0 0 0
$EndEntities
$Nodes
2 6 3 900
2 1 0 4
3
10
900
11
0 0 0
1 0 0
1 1 0
0 1 0
2 2 1 2
20
21
2 0 0 0.5 0
2 1 0 0.5 1
$EndNodes
$Elements
2 2 1 2
2 1 3 1
1 3 10 900 11
2 2 3 1
2 10 20 21 900
$EndElements
";

    #[test]
    fn v41_first_physical_per_entity_and_sparse_tags() {
        let m = parse_str(V41_PARTIAL).unwrap();
        assert_eq!(m.points.len(), 6);
        assert_eq!(m.points[2], [1.0, 1.0, 0.0]);
        assert_eq!(m.points[5], [2.0, 1.0, 0.0]);
        // Second block is parametric on a surface: (u, v) after x y z are skipped.
        assert_eq!(m.point_locations[4], Location::Line(23));
        let q = block(&m, &CellKind::Quad);
        assert_eq!(q.nodes, [0, 1, 2, 3, 1, 4, 5, 2]);
        assert_eq!(q.tags, [5, 0]);
        assert_eq!(q.locations, [Location::Line(29), Location::Line(31)]);
    }

    #[test]
    fn v22_sparse_and_huge_node_tags() {
        let s = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n7 0 0 0\n3 1 0 0\n\
                 4000000000 1 1 0\n12 0 1 0\n$EndNodes\n$Elements\n1\n1 3 2 4 1 7 3 4000000000 12\n$EndElements\n";
        let m = parse_str(s).unwrap();
        let q = block(&m, &CellKind::Quad);
        assert_eq!(q.nodes, [0, 1, 2, 3]);
        assert_eq!(q.tags, [4]);
    }

    #[test]
    fn v22_without_physical_tags_and_with_comments() {
        let s = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Comments\nanything $Nodes here\n$EndComments\n\
                 $Nodes\n4\n1 0 0 0\n2 1 0 0\n3 1 1 0\n4 0 1 0\n$EndNodes\n\
                 $Elements\n2\n1 3 0 1 2 3 4\n2 1 2 0 3 1 2\n$EndElements\n\
                 $NodeData\n1\n\"x\"\n$EndNodeData\n";
        let m = parse_str(s).unwrap();
        assert!(block(&m, &CellKind::Quad).tags.is_empty());
        assert!(block(&m, &CellKind::Line).tags.is_empty());
        assert_eq!(block(&m, &CellKind::Line).locations, [Location::Line(17)]);
    }

    #[test]
    fn physical_names_with_spaces_and_clashing_dimensions() {
        let s = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n3\n2 1 \"wall with spaces\"\n\
                 3 1 \"fluid\"\n3 2 \"solid\"\n$EndPhysicalNames\n";
        let m = parse_str(s).unwrap();
        assert_eq!(m.tag_names[&1], "wall with spaces / fluid");
        assert_eq!(m.tag_names[&2], "solid");
    }

    /// A one-quad MSH 2.2 binary file in either byte order.
    fn v22_binary(big_endian: bool) -> Vec<u8> {
        let i = |v: i32| {
            if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let f = |v: f64| {
            if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let mut d = b"$MeshFormat\n2.2 1 8\n".to_vec();
        d.extend(i(1));
        d.extend(b"\n$EndMeshFormat\n$Nodes\n4\n");
        for (t, x, y) in [(1, 0.0, 0.0), (2, 1.0, 0.0), (3, 1.0, 1.0), (4, 0.0, 1.0)] {
            d.extend(i(t));
            for c in [x, y, 0.5] {
                d.extend(f(c));
            }
        }
        d.extend(b"\n$EndNodes\n$Elements\n1\n");
        for v in [3, 1, 2, 1, 9, 8, 4, 3, 2, 1] {
            d.extend(i(v));
        }
        d.extend(b"\n$EndElements\n");
        d
    }

    #[test]
    fn v22_binary_either_byte_order() {
        for be in [false, true] {
            let m = parse(&v22_binary(be));
            assert_eq!(m.points[2], [1.0, 1.0, 0.5]);
            let q = block(&m, &CellKind::Quad);
            assert_eq!(q.nodes, [3, 2, 1, 0]);
            assert_eq!(q.tags, [9]);
        }
    }

    // ---- bad input ----

    fn err(data: &[u8]) -> ParseError {
        match read(data) {
            Ok(_) => panic!("expected an error"),
            Err(e) => e,
        }
    }

    fn err_str(s: &str) -> ParseError {
        err(s.as_bytes())
    }

    const HEAD: &str = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n";
    const NODES: &str = "$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 1 1 0\n4 0 1 0\n$EndNodes\n";

    #[test]
    fn garbage_and_empty() {
        assert_eq!(err(b"").location, Location::File);
        assert_eq!(err(b"  \n\n").location, Location::File);
        let e = err(b"\xff\xfe\x00garbage\n");
        assert_eq!(e.location, Location::Line(1));
        assert!(e.message.contains("$MeshFormat"), "{}", e.message);
        let e = err_str("$Nodes\n1\n1 0 0 0\n$EndNodes\n");
        assert_eq!(e.location, Location::Line(1));
        let e = err_str("$MeshFormat\n3.0 0 8\n$EndMeshFormat\n");
        assert!(e.message.contains("3.0"), "{}", e.message);
        let e = err_str("$MeshFormat\n2.2 2 8\n$EndMeshFormat\n");
        assert_eq!(e.location, Location::Line(2));
        let e = err_str(&format!("{HEAD}{NODES}junk\n"));
        assert_eq!(e.location, Location::Line(11));
        let e = err_str(&format!("{HEAD}$EndNodes\n"));
        assert_eq!(e.location, Location::Line(4));
    }

    #[test]
    fn truncated_ascii() {
        let full = format!("{HEAD}{NODES}$Elements\n1\n1 3 2 0 1 1 2 3 4\n$EndElements\n");
        assert!(read(full.as_bytes()).is_ok());
        let e = err_str(&full[..full.len() - 20]);
        assert_eq!(e.location, Location::Line(13));
        assert!(e.message.contains("end of file"), "{}", e.message);
        let e = err_str(&format!("{HEAD}$Nodes\n4\n1 0 0 0\n2 1 0"));
        assert_eq!(e.location, Location::Line(7));
        assert!(
            e.message.contains("z coordinate of node 2"),
            "{}",
            e.message
        );
        // Every prefix either parses or fails cleanly.
        for n in 0..full.len() {
            let _ = read(&full.as_bytes()[..n]);
        }
    }

    #[test]
    fn wrong_counts() {
        // Fewer nodes than declared: the $EndNodes token is met where a node tag is expected.
        let e = err_str(&format!("{HEAD}$Nodes\n5\n1 0 0 0\n2 1 0 0\n$EndNodes\n"));
        assert_eq!(e.location, Location::Line(8));
        assert!(e.message.contains("tag of node 3 of 5"), "{}", e.message);
        // More nodes than declared.
        let e = err_str(&format!("{HEAD}$Nodes\n1\n1 0 0 0\n2 1 0 0\n$EndNodes\n"));
        assert_eq!(e.location, Location::Line(7));
        assert!(e.message.contains("$EndNodes"), "{}", e.message);
        // MSH 4.1 block counts that disagree with the header.
        let e = err_str(
            "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 3 1 2\n0 1 0 2\n1\n2\n0 0 0\n1 0 0\n$EndNodes\n",
        );
        assert_eq!(e.location, Location::Line(10));
        assert!(e.message.contains("declares 3 nodes"), "{}", e.message);
        // Huge counts do not allocate.
        let e = err_str(&format!("{HEAD}$Nodes\n18446744073709551615\n1 0 0 0\n"));
        assert!(matches!(e.location, Location::Line(_)));
        let e = err_str(&format!("{HEAD}$Nodes\n99999999999999999999999\n"));
        assert!(e.message.contains("number of nodes"), "{}", e.message);
    }

    #[test]
    fn bad_tokens_and_indices() {
        let el = |line: &str| format!("{HEAD}{NODES}$Elements\n1\n{line}\n$EndElements\n");
        let e = err_str(&el("1 3 2 0 1 1 2 x 4"));
        assert_eq!(e.location, Location::Line(13));
        assert!(
            e.message.contains("node 3 of 4 of element 1"),
            "{}",
            e.message
        );
        let e = err_str(&el("1 3 2 0 1 1 2 -3 4"));
        assert_eq!(e.location, Location::Line(13));
        let e = err_str(&el("1 3 2 0 1 1 2 5 4"));
        assert_eq!(e.location, Location::Line(13));
        assert!(e.message.contains("node 5"), "{}", e.message);
        assert!(e.message.contains("does not define"), "{}", e.message);
        let e = err_str(&el("1 77 2 0 1 1 2 3 4"));
        assert_eq!(e.location, Location::Line(13), "{e}");
        assert!(
            e.message.contains("unknown Gmsh element type 77"),
            "{}",
            e.message
        );
        let e = err_str(&el("1 3 2 99999999999 1 1 2 3 4"));
        assert!(e.message.contains("out of range"), "{}", e.message);
        let e = err_str(&format!("{HEAD}$Nodes\n2\n1 0 0 0\n1 1 0 0\n$EndNodes\n"));
        assert_eq!(e.location, Location::Line(7));
        assert!(
            e.message.contains("defined twice (first at line 6)"),
            "{}",
            e.message
        );
        let e = err_str(&format!("{HEAD}$Nodes\n1\n1 0 zero 0\n$EndNodes\n"));
        assert_eq!(e.location, Location::Line(6));
        assert!(
            e.message.contains("y coordinate of node 1"),
            "{}",
            e.message
        );
        let e = err_str(&format!("{HEAD}$Elements\n0\n$EndElements\n"));
        assert!(e.message.contains("before the $Nodes"), "{}", e.message);
        let e = err_str(&format!("{HEAD}$Periodic\n1\n"));
        assert_eq!(e.location, Location::Line(4));
        assert!(e.message.contains("$EndPeriodic"), "{}", e.message);
    }

    #[test]
    fn v41_bad_input() {
        let bad_node = V41_PARTIAL.replace("2 10 20 21 900", "2 10 20 22 900");
        let e = err_str(&bad_node);
        assert_eq!(e.location, Location::Line(31));
        assert!(e.message.contains("node 22"), "{}", e.message);
        let bad_type = V41_PARTIAL.replace("2 2 3 1\n", "2 2 77 1\n");
        let e = err_str(&bad_type);
        assert_eq!(e.location, Location::Line(30));
        let bad_dim = V41_PARTIAL.replace("2 1 0 4\n", "7 1 0 4\n");
        assert_eq!(err_str(&bad_dim).location, Location::Line(11));
        for n in 0..V41_PARTIAL.len() {
            let _ = read(&V41_PARTIAL.as_bytes()[..n]);
        }
    }

    #[test]
    fn binary_truncated_or_corrupt() {
        for name in ["box_22_bin.msh", "box_41_bin.msh", "ball_41_bin.msh"] {
            let data = fixture(name);
            // Cut inside the element records: a byte offset in the element data.
            let el = data.windows(10).position(|w| w == b"$Elements\n").unwrap();
            let end = data
                .windows(13)
                .position(|w| w == b"$EndElements\n")
                .unwrap();
            let e = err(&data[..(el + end) / 2]);
            let Location::Byte(b) = e.location else {
                panic!("{name}: {e}")
            };
            assert!(b > el && b < end, "{name}: {e}");
            assert!(
                e.message.contains("file ends") || e.message.contains("do not fit"),
                "{name}: {}",
                e.message
            );
            // No prefix panics.
            for n in (0..data.len()).step_by(7) {
                let _ = read(&data[..n]);
            }
            // Nor does flipping bytes.
            let mut rng = 0x1234_5678_u64;
            for _ in 0..300 {
                let mut d = data.clone();
                for _ in 0..4 {
                    rng = rng
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    let i = (rng >> 33) as usize % d.len();
                    d[i] = (rng >> 17) as u8;
                }
                let _ = read(&d);
            }
        }
        // Byte order marker that is not 1.
        let mut d = v22_binary(false);
        let at = d.windows(8).position(|w| w == b"2.2 1 8\n").unwrap() + 8;
        d[at] = 2;
        assert_eq!(err(&d).location, Location::Byte(at));
        // A huge node count in a 4.1 binary header is refused before any allocation.
        let data = fixture("box_41_bin.msh");
        let nodes = data.windows(7).position(|w| w == b"$Nodes\n").unwrap() + 7;
        let mut d = data.clone();
        d[nodes + 16..nodes + 24].copy_from_slice(&u64::MAX.to_le_bytes());
        let mut d2 = data.clone();
        // First block's node count.
        d2[nodes + 32 + 12..nodes + 32 + 20].copy_from_slice(&(1u64 << 60).to_le_bytes());
        let e = err(&d2);
        assert!(e.message.contains("do not fit"), "{}", e.message);
        let _ = read(&d);
        // An undefined node in a binary element record.
        let mut d = v22_binary(false);
        let n = d.len();
        d[n - 14 - 16..n - 14 - 12].copy_from_slice(&77i32.to_le_bytes());
        let e = err(&d);
        assert!(e.message.contains("node 77"), "{}", e.message);
        assert!(matches!(e.location, Location::Byte(_)));
    }

    #[test]
    fn random_fragments_never_panic() {
        let fragments = [
            "$MeshFormat\n",
            "2.2 0 8\n",
            "4.1 0 8\n",
            "4.0 0 8\n",
            "2.2 1 8\n",
            "4.1 1 4\n",
            "$EndMeshFormat\n",
            "$Nodes\n",
            "$EndNodes\n",
            "$Elements\n",
            "$EndElements\n",
            "$Entities\n",
            "$EndEntities\n",
            "$PhysicalNames\n",
            "\"a b\"\n",
            "$NOD\n",
            "$ELM\n",
            "$PartitionedEntities\n",
            "1 ",
            "0 ",
            "3 ",
            "5 ",
            "-1 ",
            "99999999999 ",
            "1e300 ",
            "nan ",
            "\n",
            "\u{e9}",
            "$\u{e9}\u{e9}",
            "$End",
            "\x01\x00\x00\x00",
            "\r\n",
            "$Endx",
            "18446744073709551615 ",
        ];
        let mut rng = 0x9e37_79b9_7f4a_7c15_u64;
        for _ in 0..20000 {
            let mut s = String::new();
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let n = (rng >> 58) as usize;
            for _ in 0..n {
                rng = rng
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                s.push_str(fragments[(rng >> 33) as usize % fragments.len()]);
            }
            let _ = read(s.as_bytes());
        }
        let _ = read("$\u{e9}\u{e9}".as_bytes());
    }
}
