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
//! `$PartitionedEntities` (physical tags per entity), `$Nodes`, `$Elements`, `$Periodic` (into
//! [`RawMesh::periodic`], entity pairs turned into physical tags). Every other section
//! (`$NodeData`, `$ElementData`, `$Comments`, ...) is skipped up to its `$End` line.
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
//!
//! Modes: [`read`] makes the serial reader's [`RawMesh`]; [`header_tags`] parses the sections
//! before `$Nodes` only; `read_keeping_tags` (MSH 4, for Gmsh's partitioned files) keeps the
//! file's numbering, the node tags, each cell's element and entity tag and the ghost entities;
//! `stream` indexes a binary MSH 4.1 file without holding it and reads its blocks by
//! offset, for the ranks that each read a share of one file. All of them parse with the same
//! section, block-header, entity, element-type and binary-decoding code, so a file means the
//! same in every reader, and their errors name the place (line, byte) and the problem.
//!
//! Parts: this module reads `$MeshFormat` and `$PhysicalNames` and runs the section loop;
//! `entities`, `nodes` and `elements` read their sections in every version and encoding;
//! `periodic` reads `$Periodic`; `binary` decodes binary data with bounds checks;
//! `element_types` maps type numbers to cell kinds; `stream` is the offset-indexed reader.
//!
//! [`CellKind`]: crate::mesh::raw::CellKind
//! [`CellKind::Other`]: crate::mesh::raw::CellKind::Other

mod binary;
mod element_types;
mod elements;
mod entities;
mod nodes;
mod periodic;
pub(crate) mod stream;

use super::text::{TextCursor, parse_f64};
use crate::mesh::raw::{Location, ParseError, RawMesh};
use binary::Bin;
use element_types::Blocks;
pub use entities::EntityTags;
use nodes::NodeMap;
use std::collections::{BTreeMap, HashMap};

/// Parse a Gmsh `.msh` file held in memory.
pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    Reader::new(data).run()
}

/// The physical names and the entities' physical tags of a MSH file's header.
#[derive(Debug, Default)]
pub struct HeaderTags {
    /// As [`RawMesh::tag_names`].
    pub tag_names: BTreeMap<i32, String>,
    pub entities: EntityTags,
    /// What `$MeshFormat` said (None for MSH 1, which has no such section).
    pub(crate) format: Option<Format>,
}

impl HeaderTags {
    /// Whether the file is binary MSH 4.1 (what [`stream`] reads).
    pub(crate) fn is_binary_41(&self) -> bool {
        self.format
            .is_some_and(|f| f.binary && f.version == Version::V41)
    }

    /// Whether the file is MSH 4.0 or 4.1 (what [`read_keeping_tags`] reads).
    pub(crate) fn is_msh4(&self) -> bool {
        self.format
            .is_some_and(|f| matches!(f.version, Version::V40 | Version::V41))
    }

    /// The file's variant, for messages: "ASCII MSH 4.1", "binary MSH 2", ...
    pub(crate) fn describe_format(&self) -> String {
        match self.format {
            None => "MSH 1".into(),
            Some(f) => format!(
                "{} MSH {}",
                if f.binary { "binary" } else { "ASCII" },
                match f.version {
                    Version::V1 => "1",
                    Version::V2 => "2",
                    Version::V40 => "4.0",
                    Version::V41 => "4.1",
                }
            ),
        }
    }
}

/// Parse the sections of a MSH file that come before `$Nodes` (`$MeshFormat`,
/// `$PhysicalNames`, `$Entities`, `$PartitionedEntities`, and any other, skipped), given as the
/// file's first bytes: the readers that do not hold the whole file use it for the physical
/// names and tags, so that they name and tag as [`read`] does. Error locations are those of the
/// file.
pub fn header_tags(head: &[u8]) -> Result<HeaderTags, ParseError> {
    let mut r = Reader::new(head);
    r.sections()?;
    Ok(HeaderTags {
        tag_names: r.mesh.tag_names,
        entities: r.entities,
        format: r.format,
    })
}

/// One Gmsh element type's cells of a file read by [`read_keeping_tags`], in file order.
#[derive(Debug)]
pub(crate) struct TaggedBlock {
    pub(crate) gmsh_type: i64,
    /// The file's tag of each cell.
    pub(crate) element_tags: Vec<u64>,
    /// The tag of each cell's entity (see [`EntityTags::is_ghost`]).
    pub(crate) entities: Vec<i32>,
    /// The physical tag of each cell, as [`read`] tags it.
    pub(crate) physical: Vec<i32>,
    /// The node tags of each cell (as many per cell as the type has nodes), as in the file.
    pub(crate) nodes: Vec<u64>,
}

/// A MSH 4 file in its own numbering ([`read_keeping_tags`]).
#[derive(Debug)]
pub(crate) struct TaggedMesh {
    pub(crate) header: HeaderTags,
    /// The tag of each node of `points`, in file order.
    pub(crate) node_tags: Vec<u64>,
    pub(crate) points: Vec<[f64; 3]>,
    /// One per Gmsh element type, in order of first appearance.
    pub(crate) blocks: Vec<TaggedBlock>,
    /// The links of `$Periodic`, their sides as physical tags (a part of a partitioned mesh
    /// repeats the whole mesh's links; node pairs naming nodes it does not hold are kept unread).
    pub(crate) periodic: Vec<crate::mesh::raw::DeclaredPeriodic>,
}

/// Parse a MSH 4 file held in memory keeping the file's numbering: node tags, element tags,
/// entity tags, and elements' node tags as written (a node tag `$Nodes` does not define is
/// not an error here: a part of a partitioned mesh may name nodes it does not hold). Names,
/// physical tags and errors are those of [`read`]; MSH 1/2 files are an error.
pub(crate) fn read_keeping_tags(data: &[u8]) -> Result<TaggedMesh, ParseError> {
    let mut r = Reader::new(data);
    r.keep = Some(Kept::default());
    r.sections()?;
    if !matches!(r.format().version, Version::V40 | Version::V41) {
        return Err(ParseError::new(
            Location::File,
            "element tags are kept only from MSH 4 files",
        ));
    }
    let periodic = r.declared_periodic();
    let mut kept = r.keep.take().unwrap_or_default();
    kept.cells
        .resize_with(r.blocks.list.len(), Default::default);
    let blocks = r
        .blocks
        .list
        .into_iter()
        .zip(kept.cells)
        .map(|((gmsh_type, block), cells)| TaggedBlock {
            gmsh_type,
            element_tags: cells.element_tags,
            entities: cells.entities,
            physical: block.tags,
            // Non-negative: `NodeMap::Identity` keeps only tags that fit an i64.
            nodes: block.nodes.into_iter().map(|t| t as u64).collect(),
        })
        .collect();
    Ok(TaggedMesh {
        header: HeaderTags {
            tag_names: r.mesh.tag_names,
            entities: r.entities,
            format: r.format,
        },
        node_tags: kept.node_tags,
        points: r.mesh.points,
        blocks,
        periodic,
    })
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Version {
    V1,
    V2,
    V40,
    V41,
}

/// What `$MeshFormat` said.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Format {
    pub(crate) version: Version,
    pub(crate) binary: bool,
    pub(crate) big_endian: bool,
    /// Width of `size_t` in MSH 4 binary files.
    pub(crate) size_t: usize,
}

/// What the tag-keeping mode records besides the mesh.
#[derive(Default)]
struct Kept {
    node_tags: Vec<u64>,
    /// Per entry of `Reader::blocks`.
    cells: Vec<KeptCells>,
}

/// The element tag and entity tag of each cell of one block.
#[derive(Default)]
struct KeptCells {
    element_tags: Vec<u64>,
    entities: Vec<i32>,
}

impl KeptCells {
    fn push(&mut self, element_tag: u64, entity: i32) {
        self.element_tags.push(element_tag);
        self.entities.push(entity);
    }
}

impl Kept {
    /// The record of block `bi` of `Reader::blocks`.
    fn cells(&mut self, bi: usize) -> &mut KeptCells {
        if self.cells.len() <= bi {
            self.cells.resize_with(bi + 1, Default::default);
        }
        &mut self.cells[bi]
    }
}

struct Reader<'a> {
    c: TextCursor<'a>,
    format: Option<Format>,
    mesh: RawMesh,
    nodes: Option<NodeMap>,
    blocks: Blocks,
    /// The physical tag of each entity.
    entities: EntityTags,
    /// MSH 1/2: the physical tag of the first element of each (dimension, elementary entity).
    v2_entities: HashMap<(i32, i32), i32>,
    /// The links of `$Periodic`.
    periodic: Vec<periodic::Link>,
    /// The node tags of `$Periodic`'s node pairs with their places, kept to be checked by a
    /// reader that does not hold `$Nodes` (`stream`); `None`: checked as they are read.
    unchecked_nodes: Option<Vec<(u64, Location)>>,
    /// The file's numbering, in the tag-keeping mode.
    keep: Option<Kept>,
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
            entities: EntityTags::default(),
            v2_entities: HashMap::new(),
            periodic: Vec::new(),
            unchecked_nodes: None,
            keep: None,
        }
    }

    fn run(mut self) -> Result<RawMesh, ParseError> {
        self.sections()?;
        self.mesh.periodic = self.declared_periodic();
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

    /// Read every section of the input.
    fn sections(&mut self) -> Result<(), ParseError> {
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
                "Periodic" => self.periodic_section(line)?,
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
        Ok(())
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
            base: 0,
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
        let file_type = self
            .c
            .parse_or::<i64>(|| "file type (0 = ASCII, 1 = binary)".into())?;
        let binary = match file_type {
            0 => false,
            1 => true,
            _ => {
                return Err(self.c.error(format!(
                    "file type {file_type} is not 0 (ASCII) or 1 (binary)"
                )));
            }
        };
        let data_size = self.c.parse_or::<i64>(|| "data size".into())?;
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
        let n = self
            .c
            .parse_or::<u64>(|| "number of physical names".into())?;
        for i in 0..n {
            let what = || format!("physical name {} of {n}", i + 1);
            let dim = self
                .c
                .parse_or::<i64>(|| format!("dimension of {}", what()))?;
            let tag = self.c.parse_or::<i64>(|| format!("tag of {}", what()))?;
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
}

#[cfg(test)]
mod tests;
