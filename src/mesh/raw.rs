//! The format-neutral result of parsing a mesh file.
//!
//! Every reader turns its file into a [`RawMesh`]: points, blocks of cells of any kind the file
//! holds (volume cells, boundary cells, points), and tag names. Readers only parse; they do not
//! judge whether the mesh is one polyspline can curve. [`crate::mesh::LinearMesh::from_raw`]
//! does that in one place: it picks the volume cells, checks indices and coordinates, normalises
//! orientation, and turns lower-dimensional cells into boundary tags.
//!
//! Invariants a reader must keep:
//! * node indices in [`RawBlock::nodes`] are 0-based positions in [`RawMesh::points`]; a file id
//!   that names no node is reported by the reader (it knows the line) or left out of range, in
//!   which case `from_raw` reports it with the block's [`RawBlock::locations`];
//! * cell node order is VTK/Gmsh order for linear cells (quad: counter-clockwise 0..3; hex:
//!   bottom face 0..3 then top face 4..7 above them);
//! * `locations` is empty or has one entry per cell, so errors can name the line or byte offset.

use std::collections::BTreeMap;
use std::fmt;

/// Where in a file something was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Location {
    /// 1-based line number in a text file.
    Line(usize),
    /// 0-based byte offset in a binary file or section.
    Byte(usize),
    /// Nowhere in particular (for example, a problem with the whole file).
    #[default]
    File,
    /// A node of a tree-structured file (CGNS), whose path the message starts with.
    Tree,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(l) => write!(f, "line {l}"),
            Location::Byte(b) => write!(f, "byte {b}"),
            Location::File => write!(f, "file"),
            Location::Tree => write!(f, "node"),
        }
    }
}

/// A parse problem at a place in the file; the reader's caller adds the path.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub struct ParseError {
    pub location: Location,
    pub message: String,
}

impl fmt::Display for ParseError {
    /// `place: problem`; a [`Location::Tree`] message already starts with its node's path.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.location {
            Location::Tree => f.write_str(&self.message),
            l => write!(f, "{l}: {}", self.message),
        }
    }
}

/// Longest message a [`ParseError`] keeps (characters); the rest is cut with a note.
pub const MAX_MESSAGE_CHARS: usize = 400;

/// `text` as one bounded line: control characters (a newline copied from the input, an
/// escape sequence) shown escaped (`\n`, `\x1b`), and cut after `max` characters with a
/// note of how much was left out, so a message quoting hostile input stays one short line.
pub fn one_line(text: &str, max: usize) -> String {
    let mut out = String::with_capacity(text.len().min(max + 32));
    // Characters of `out` so far (escapes count as what they show).
    let mut shown = 0;
    for (i, ch) in text.char_indices() {
        let escaped = match ch {
            '\n' => "\\n".to_string(),
            '\r' => "\\r".to_string(),
            '\t' => "\\t".to_string(),
            c if c.is_control() => format!("\\x{:02x}", c as u32),
            c => c.to_string(),
        };
        let n = escaped.chars().count();
        if shown + n > max {
            out.push_str(&format!("… ({} more bytes)", text.len() - i));
            return out;
        }
        out.push_str(&escaped);
        shown += n;
    }
    out
}

impl ParseError {
    /// The message is made one bounded line by [`one_line`].
    pub fn new(location: Location, message: impl Into<String>) -> Self {
        let message = message.into();
        let message =
            if message.len() <= MAX_MESSAGE_CHARS && !message.chars().any(|c| c.is_control()) {
                message
            } else {
                one_line(&message, MAX_MESSAGE_CHARS)
            };
        ParseError { location, message }
    }
    pub fn at_line(line: usize, message: impl Into<String>) -> Self {
        Self::new(Location::Line(line), message)
    }
    pub fn at_byte(byte: usize, message: impl Into<String>) -> Self {
        Self::new(Location::Byte(byte), message)
    }
}

/// Linear cell kinds (and a catch-all for the rest, named as the file names them).
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CellKind {
    Vertex,
    Line,
    Triangle,
    Quad,
    Tetra,
    Hexahedron,
    Wedge,
    Pyramid,
    /// A Lagrange line (dim 1), quadrilateral (2) or hexahedron (3) of order ≥ 2 on the
    /// equispaced lattice, its nodes in the file's node-order convention.
    Lagrange {
        dim: usize,
        order: usize,
        convention: NodeConvention,
    },
    /// Anything else (high-order or polygonal cells), with a human-readable name such as
    /// "9-node quadrilateral (Gmsh type 10)".
    Other(String),
}

/// Whose node order a Lagrange cell follows (the orderings are the readers' and writers',
/// `io/ordering.rs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum NodeConvention {
    Gmsh,
    Vtk,
    /// CGNS (`QUAD_9/16/25`, `HEXA_27/64/125`, in the order of the CGNS standard; the tables are
    /// the CGNS reader's).
    Cgns,
    /// Abaqus (`M3D9`/`S9R5` 9-node quadrilaterals in Gmsh's order; `C3D27` as
    /// the Abaqus writer's `c3d27` order).
    Abaqus,
}

impl CellKind {
    /// Topological dimension, where known.
    pub fn dim(&self) -> Option<usize> {
        match self {
            CellKind::Vertex => Some(0),
            CellKind::Line => Some(1),
            CellKind::Triangle | CellKind::Quad => Some(2),
            CellKind::Tetra | CellKind::Hexahedron | CellKind::Wedge | CellKind::Pyramid => Some(3),
            CellKind::Lagrange { dim, .. } => Some(*dim),
            CellKind::Other(_) => None,
        }
    }

    /// Number of nodes of the linear cell, where fixed.
    pub fn nodes(&self) -> Option<usize> {
        match self {
            CellKind::Vertex => Some(1),
            CellKind::Line => Some(2),
            CellKind::Triangle => Some(3),
            CellKind::Quad => Some(4),
            CellKind::Tetra => Some(4),
            CellKind::Hexahedron => Some(8),
            CellKind::Wedge => Some(6),
            CellKind::Pyramid => Some(5),
            CellKind::Lagrange { dim, order, .. } => Some((order + 1).pow(*dim as u32)),
            CellKind::Other(_) => None,
        }
    }

    /// Plural noun for messages ("120 tetrahedra").
    pub fn plural(&self) -> String {
        match self {
            CellKind::Vertex => "point cells".into(),
            CellKind::Line => "line segments".into(),
            CellKind::Triangle => "triangles".into(),
            CellKind::Quad => "quadrilaterals".into(),
            CellKind::Tetra => "tetrahedra".into(),
            CellKind::Hexahedron => "hexahedra".into(),
            CellKind::Wedge => "wedges (prisms)".into(),
            CellKind::Pyramid => "pyramids".into(),
            CellKind::Lagrange { dim, order, .. } => {
                let n = (order + 1).pow(*dim as u32);
                let what = ["points", "lines", "quadrilaterals", "hexahedra"][*dim];
                format!("order-{order} {n}-node {what}")
            }
            CellKind::Other(name) => format!("cells of type {name}"),
        }
    }
}

/// One block of cells of a single kind.
#[derive(Clone, Debug, Default)]
pub struct RawBlock {
    pub kind: Option<CellKind>,
    /// Nodes per cell (the stride of `nodes`).
    pub nodes_per_cell: usize,
    /// Flattened 0-based node indices; `i64` so a reader can pass a negative or huge index
    /// through for `from_raw` to report.
    pub nodes: Vec<i64>,
    /// One tag per cell (Gmsh physical group, SU2 marker index, Medit reference, MFEM attribute,
    /// Abaqus set index, Exodus block or side-set id), or empty when the file has none. Tag 0
    /// means "no tag" for this cell.
    pub tags: Vec<i32>,
    /// Where each cell was read (empty, or one per cell).
    pub locations: Vec<Location>,
}

impl RawBlock {
    pub fn new(kind: CellKind, nodes_per_cell: usize) -> Self {
        RawBlock {
            kind: Some(kind),
            nodes_per_cell,
            ..Default::default()
        }
    }
    pub fn len(&self) -> usize {
        self.nodes
            .len()
            .checked_div(self.nodes_per_cell)
            .unwrap_or(0)
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn kind(&self) -> &CellKind {
        self.kind
            .as_ref()
            .expect("RawBlock kind is set by the reader")
    }
    pub fn location(&self, cell: usize) -> Location {
        self.locations.get(cell).copied().unwrap_or_default()
    }
}

/// Everything a reader found in a file.
#[derive(Clone, Debug, Default)]
pub struct RawMesh {
    /// Coordinates; z = 0 where the file stores 2 components.
    pub points: Vec<[f64; 3]>,
    /// Where each point was read (empty, or one per point).
    pub point_locations: Vec<Location>,
    /// The number of coordinates the file declares per point (2 or 3), if it says.
    pub declared_dim: Option<usize>,
    pub blocks: Vec<RawBlock>,
    /// Names of tags (Gmsh physical names, SU2 marker names, Abaqus set names).
    pub tag_names: BTreeMap<i32, String>,
    /// Periodic pairs the file declares (Gmsh's `$Periodic`), in every dimension.
    pub periodic: Vec<DeclaredPeriodic>,
}

/// A periodic pair a file declares: the boundary cells of one side are the image of the
/// other's under a rigid map. Gmsh's `$Periodic` names the sides by their entities' tags
/// ([`RawBlock::tags`], 0 when the entity has none); CGNS's periodic grid connectivity gives
/// the map only, and the sides are the boundary groups it carries onto each other. The pair
/// is a claim, verified from the positions before use.
#[derive(Clone, Debug, PartialEq)]
pub struct DeclaredPeriodic {
    /// Dimension of the paired cells (the boundary's: 1 in 2D, 2 in 3D).
    pub dim: usize,
    /// Tags of the master side and the image side, where the file names them.
    pub sides: Option<[i32; 2]>,
    /// The claim as the file states it, for messages (`$Periodic link of entities 3 -> 5`,
    /// `CGNS periodic connection /Base/Zone/ZoneGridConnectivity/A_to_B`).
    pub source: String,
    /// The file's 4×4 affine map master → image, by rows, when it gives one.
    pub affine: Option<[f64; 16]>,
    /// Relative precision of `affine` as stored (single-precision CGNS data: `f32::EPSILON`;
    /// 0 for text written to full precision).
    pub precision: f64,
    /// Where the pair was read.
    pub location: Location,
}

impl RawMesh {
    /// Number of cells of `kind` over all blocks.
    pub fn count(&self, kind: &CellKind) -> usize {
        self.blocks
            .iter()
            .filter(|b| b.kind() == kind)
            .map(|b| b.len())
            .sum()
    }

    /// The first block of cells of `kind`.
    pub fn block(&self, kind: &CellKind) -> Option<&RawBlock> {
        self.blocks.iter().find(|b| b.kind() == kind)
    }

    /// Append a block, merging it into the last block when kind and stride agree (readers of
    /// per-element formats call this once per cell group).
    pub fn push_block(&mut self, block: RawBlock) {
        if block.is_empty() {
            return;
        }
        if let Some(last) = self.blocks.last_mut()
            && last.kind == block.kind
            && last.nodes_per_cell == block.nodes_per_cell
            && last.tags.is_empty() == block.tags.is_empty()
            && last.locations.is_empty() == block.locations.is_empty()
        {
            last.nodes.extend_from_slice(&block.nodes);
            last.tags.extend_from_slice(&block.tags);
            last.locations.extend_from_slice(&block.locations);
            return;
        }
        self.blocks.push(block);
    }
}
