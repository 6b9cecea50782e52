//! Exodus II meshes stored as netCDF-3 (classic `CDF\x01` and 64-bit offset `CDF\x02`).
//!
//! The netCDF-3 container is parsed here directly from the bytes, with every count and offset
//! checked against the input size, so errors name byte offsets and a corrupt header cannot
//! cause a huge allocation. netCDF-4 (HDF5) and CDF-5 files are rejected with a message.
//!
//! Read:
//! * coordinates from `coordx`/`coordy`/`coordz`, or from `coord` (shape `[num_dim,
//!   num_nodes]`), as doubles or floats; `num_dim` becomes [`RawMesh::declared_dim`];
//! * element blocks `connect1..connectN` (1-based node indices; attribute `elem_type`):
//!   HEX/HEX8 → hexahedron, QUAD/QUAD4/SHELL/SHELL4 → quad (a SHELL block in a 3D file is a
//!   surface and is reported as quads all the same), TETRA/TET4 → tetrahedron, WEDGE →
//!   wedge, PYRAMID → pyramid, TRI/TRI3/TRISHELL → triangle, BAR/BEAM/TRUSS → line; any other
//!   type or node count (HEX20, HEX27, QUAD8, QUAD9, ...) → [`CellKind::Other`]. Exodus linear
//!   node orders equal VTK's. Each cell's location is the byte offset of its connectivity;
//! * element tags: the block id (`eb_prop1`, else the block number), named by `eb_names`;
//! * side sets `elem_ss<i>`/`side_ss<i>` (ids `ss_prop1`, names `ss_names`) → tagged facets
//!   built with the Exodus side numbering (hex: side 1 = nodes 1,2,6,5; 2 = 2,3,7,6;
//!   3 = 3,4,8,7; 4 = 1,5,8,4; 5 = 1,4,3,2; 6 = 5,6,7,8; 2D quad: side i = edge i→i+1; shell:
//!   sides 1/2 = the two faces, 3.. = edges; tetrahedron, wedge, pyramid as in the Exodus
//!   manual). Elements in side sets use the global element numbering (blocks in file order).
//!
//! When a block id and a side-set id are equal and both are named, the side-set name is kept
//! in [`RawMesh::tag_names`]. Node sets, maps (`node_num_map`, `elem_num_map`: connectivity
//! and side sets use internal numbering), attributes and results are ignored.

use super::raw::{CellKind, Location, ParseError, RawBlock, RawMesh};
use std::collections::BTreeMap;

const NC_DIMENSION: u32 = 10;
const NC_VARIABLE: u32 = 11;
const NC_ATTRIBUTE: u32 = 12;

/// netCDF external types (CDF-1/2 subset).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum NcType {
    Byte,
    Char,
    Short,
    Int,
    Float,
    Double,
}

impl NcType {
    fn from_code(code: u32) -> Option<NcType> {
        Some(match code {
            1 => NcType::Byte,
            2 => NcType::Char,
            3 => NcType::Short,
            4 => NcType::Int,
            5 => NcType::Float,
            6 => NcType::Double,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            NcType::Byte | NcType::Char => 1,
            NcType::Short => 2,
            NcType::Int | NcType::Float => 4,
            NcType::Double => 8,
        }
    }
}

struct Dim {
    name: String,
    /// 0 for the record dimension.
    len: usize,
}

struct Attr {
    name: String,
    ty: NcType,
    value: Vec<u8>,
}

struct Var {
    name: String,
    dims: Vec<usize>,
    attrs: Vec<Attr>,
    ty: NcType,
    begin: usize,
    /// Where the variable's header entry starts (for errors about it).
    header_at: usize,
}

/// The parsed header of a netCDF-3 file plus the bytes it describes.
struct NetCdf<'a> {
    data: &'a [u8],
    dims: Vec<Dim>,
    vars: Vec<Var>,
}

/// Big-endian reader over the header with byte-offset errors.
struct Cursor<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], ParseError> {
        match self.pos.checked_add(n) {
            Some(end) if end <= self.data.len() => {
                let s = &self.data[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            _ => Err(ParseError::at_byte(
                self.pos,
                format!(
                    "netCDF header truncated: expected {n} bytes of {what}, the file has {} left",
                    self.data.len().saturating_sub(self.pos)
                ),
            )),
        }
    }

    fn u32(&mut self, what: &str) -> Result<u32, ParseError> {
        let b = self.take(4, what)?;
        Ok(u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// A non-negative 32-bit count, bounded by the bytes left (each item takes at least
    /// `min_item_bytes`).
    fn count(&mut self, what: &str, min_item_bytes: usize) -> Result<usize, ParseError> {
        let at = self.pos;
        let v = self.u32(what)?;
        let left = self.data.len().saturating_sub(self.pos);
        if v > i32::MAX as u32 || (v as usize).saturating_mul(min_item_bytes) > left {
            return Err(ParseError::at_byte(
                at,
                format!(
                    "netCDF header: {what} {v} does not fit in the {left} bytes left (truncated or corrupt header)"
                ),
            ));
        }
        Ok(v as usize)
    }

    fn padded(&mut self, n: usize, what: &str) -> Result<&'a [u8], ParseError> {
        let s = self.take(n, what)?;
        let pad = (4 - n % 4) % 4;
        self.take(pad, "padding")?;
        Ok(s)
    }

    fn name(&mut self, what: &str) -> Result<String, ParseError> {
        let n = self.count(&format!("length of a {what} name"), 1)?;
        let s = self.padded(n, &format!("{what} name"))?;
        Ok(String::from_utf8_lossy(s).into_owned())
    }

    /// A list header: `ABSENT` (0, 0) or `tag, count`.
    fn list(&mut self, tag: u32, what: &str, min_item_bytes: usize) -> Result<usize, ParseError> {
        let at = self.pos;
        let t = self.u32(what)?;
        if t == 0 {
            let n = self.u32(what)?;
            if n != 0 {
                return Err(ParseError::at_byte(
                    at,
                    format!("netCDF header: expected an empty {what} (0, 0), found 0, {n}"),
                ));
            }
            return Ok(0);
        }
        if t != tag {
            return Err(ParseError::at_byte(
                at,
                format!("netCDF header: expected the {what} tag {tag} or 0, found {t}"),
            ));
        }
        self.count(&format!("number of {what} entries"), min_item_bytes)
    }

    fn attrs(&mut self) -> Result<Vec<Attr>, ParseError> {
        let n = self.list(NC_ATTRIBUTE, "attribute list", 12)?;
        let mut attrs = Vec::new();
        for _ in 0..n {
            let name = self.name("attribute")?;
            let at = self.pos;
            let code = self.u32("attribute type")?;
            let ty = NcType::from_code(code).ok_or_else(|| {
                ParseError::at_byte(
                    at,
                    format!("netCDF header: attribute {name} has unknown type {code}"),
                )
            })?;
            let len = self.count(&format!("length of attribute {name}"), ty.size())?;
            let value = self.padded(len * ty.size(), &format!("attribute {name}"))?;
            attrs.push(Attr {
                name,
                ty,
                value: value.to_vec(),
            });
        }
        Ok(attrs)
    }
}

impl<'a> NetCdf<'a> {
    fn parse(data: &'a [u8]) -> Result<NetCdf<'a>, ParseError> {
        if data.starts_with(b"\x89HDF") {
            return Err(ParseError::at_byte(
                0,
                "this is a netCDF-4 (HDF5) file; only netCDF-3 Exodus files are read (convert with `nccopy -k classic in.exo out.exo`)",
            ));
        }
        if data.len() < 4 || &data[..3] != b"CDF" {
            return Err(ParseError::at_byte(
                0,
                "not a netCDF file: expected the magic bytes \"CDF\\x01\" or \"CDF\\x02\"",
            ));
        }
        let offset_bytes = match data[3] {
            1 => 4,
            2 => 8,
            5 => {
                return Err(ParseError::at_byte(
                    3,
                    "netCDF CDF-5 (64-bit data) files are not supported; convert with `nccopy -k classic in.exo out.exo`",
                ));
            }
            v => {
                return Err(ParseError::at_byte(
                    3,
                    format!("unknown netCDF version byte {v} (expected 1 or 2)"),
                ));
            }
        };
        let mut c = Cursor { data, pos: 4 };
        let _numrecs = c.u32("number of records")?;
        let n_dims = c.list(NC_DIMENSION, "dimension list", 8)?;
        let mut dims = Vec::new();
        for _ in 0..n_dims {
            let name = c.name("dimension")?;
            let len = c.u32(&format!("length of dimension {name}"))? as usize;
            dims.push(Dim { name, len });
        }
        let _global = c.attrs()?;
        let n_vars = c.list(NC_VARIABLE, "variable list", 24)?;
        let mut vars = Vec::new();
        for _ in 0..n_vars {
            let header_at = c.pos;
            let name = c.name("variable")?;
            let rank = c.count(&format!("rank of variable {name}"), 4)?;
            let mut vdims = Vec::new();
            for _ in 0..rank {
                let at = c.pos;
                let d = c.u32("dimension id")? as usize;
                if d >= dims.len() {
                    return Err(ParseError::at_byte(
                        at,
                        format!(
                            "netCDF header: variable {name} uses dimension id {d}, but there are {} dimensions",
                            dims.len()
                        ),
                    ));
                }
                vdims.push(d);
            }
            let attrs = c.attrs()?;
            let at = c.pos;
            let code = c.u32("variable type")?;
            let ty = NcType::from_code(code).ok_or_else(|| {
                ParseError::at_byte(
                    at,
                    format!("netCDF header: variable {name} has unknown type {code}"),
                )
            })?;
            let _vsize = c.u32("variable size")?;
            let b = c.take(offset_bytes, "variable offset")?;
            let begin = if offset_bytes == 4 {
                u32::from_be_bytes([b[0], b[1], b[2], b[3]]) as u64
            } else {
                u64::from_be_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]])
            };
            vars.push(Var {
                name,
                dims: vdims,
                attrs,
                ty,
                begin: usize::try_from(begin).unwrap_or(usize::MAX),
                header_at,
            });
        }
        Ok(NetCdf { data, dims, vars })
    }

    fn dim(&self, name: &str) -> Option<usize> {
        self.dims.iter().find(|d| d.name == name).map(|d| d.len)
    }

    fn var(&self, name: &str) -> Option<&Var> {
        self.vars.iter().find(|v| v.name == name)
    }

    /// Variables named `{prefix}{k}` with 1 <= k <= `max`, sorted by k. Found by scanning the
    /// variables rather than by trying every k, since a corrupt count can be 2^31.
    fn numbered(&self, prefix: &str, max: usize) -> Vec<(usize, &Var)> {
        let mut found: Vec<(usize, &Var)> = self
            .vars
            .iter()
            .filter_map(|v| {
                let k: usize = v.name.strip_prefix(prefix)?.parse().ok()?;
                (k >= 1 && k <= max && !v.name[prefix.len()..].starts_with('0')).then_some((k, v))
            })
            .collect();
        found.sort_by_key(|&(k, _)| k);
        found.dedup_by_key(|&mut (k, _)| k);
        found
    }

    fn shape(&self, v: &Var) -> Vec<usize> {
        v.dims.iter().map(|&d| self.dims[d].len).collect()
    }

    /// The bytes of a fixed-size variable, checked against the file size.
    fn bytes(&self, v: &Var) -> Result<&'a [u8], ParseError> {
        let mut n: usize = 1;
        for &d in &v.dims {
            let dim = &self.dims[d];
            if dim.len == 0 {
                return Err(ParseError::at_byte(
                    v.header_at,
                    format!(
                        "variable {} is a record variable (dimension {}); expected fixed-size mesh data",
                        v.name, dim.name
                    ),
                ));
            }
            n = n.saturating_mul(dim.len);
        }
        let size = n.saturating_mul(v.ty.size());
        match v.begin.checked_add(size) {
            Some(end) if end <= self.data.len() => Ok(&self.data[v.begin..end]),
            _ => Err(ParseError::at_byte(
                v.begin.min(self.data.len()),
                format!(
                    "variable {} needs {size} bytes from byte {}, but the file has {} bytes (truncated?)",
                    v.name,
                    v.begin,
                    self.data.len()
                ),
            )),
        }
    }

    /// Integer variable values with the byte offset of the first one.
    fn ints(&self, v: &Var) -> Result<(Vec<i64>, usize), ParseError> {
        let b = self.bytes(v)?;
        let out = match v.ty {
            NcType::Int => b
                .chunks_exact(4)
                .map(|c| i32::from_be_bytes([c[0], c[1], c[2], c[3]]) as i64)
                .collect(),
            NcType::Short => b
                .chunks_exact(2)
                .map(|c| i16::from_be_bytes([c[0], c[1]]) as i64)
                .collect(),
            NcType::Byte => b.iter().map(|&x| x as i8 as i64).collect(),
            _ => {
                return Err(ParseError::at_byte(
                    v.header_at,
                    format!("variable {} has type {:?}, expected integers", v.name, v.ty),
                ));
            }
        };
        Ok((out, v.begin))
    }

    fn floats(&self, v: &Var) -> Result<Vec<f64>, ParseError> {
        let b = self.bytes(v)?;
        Ok(match v.ty {
            NcType::Double => b
                .chunks_exact(8)
                .map(|c| f64::from_be_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect(),
            NcType::Float => b
                .chunks_exact(4)
                .map(|c| f32::from_be_bytes([c[0], c[1], c[2], c[3]]) as f64)
                .collect(),
            _ => {
                return Err(ParseError::at_byte(
                    v.header_at,
                    format!(
                        "variable {} has type {:?}, expected floating-point values",
                        v.name, v.ty
                    ),
                ));
            }
        })
    }

    /// Rows of a `[n, len_name]` character variable, as trimmed strings.
    fn names(&self, name: &str) -> Vec<String> {
        let Some(v) = self.var(name) else {
            return Vec::new();
        };
        let shape = self.shape(v);
        let (Ok(b), &[_, len]) = (self.bytes(v), &shape[..]) else {
            return Vec::new();
        };
        if v.ty != NcType::Char || len == 0 {
            return Vec::new();
        }
        b.chunks(len)
            .map(|row| {
                let end = row.iter().position(|&c| c == 0).unwrap_or(row.len());
                String::from_utf8_lossy(&row[..end]).trim().to_string()
            })
            .collect()
    }

    /// Integer ids of a `*_prop1` variable (empty if absent or unreadable).
    fn ids(&self, name: &str) -> Vec<i64> {
        self.var(name)
            .and_then(|v| self.ints(v).ok())
            .map(|(v, _)| v)
            .unwrap_or_default()
    }
}

/// Element families with their side tables.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Family {
    Hex,
    Tet,
    Wedge,
    Pyramid,
    /// A quad in a 2D file (sides are edges).
    Quad,
    /// A quad in a 3D file (sides 1, 2 are faces; 3.. are edges).
    Shell,
    Tri,
    TriShell,
    Line,
    Point,
    Unknown,
}

impl Family {
    fn of(elem_type: &str, dim: usize) -> Family {
        let t = elem_type.trim().to_ascii_uppercase();
        let fam = t.trim_end_matches(|c: char| c.is_ascii_digit());
        let digits = &t[fam.len()..];
        match fam {
            "HEX" | "HEXAHEDRON" => Family::Hex,
            "TET" | "TETRA" | "TETRAHEDRON" => Family::Tet,
            "WEDGE" => Family::Wedge,
            "PYRAMID" | "PYRA" => Family::Pyramid,
            "SHELL" if digits == "3" => Family::TriShell,
            "SHELL" => Family::Shell,
            "QUAD" | "QUADRILATERAL" if dim == 3 => Family::Shell,
            "QUAD" | "QUADRILATERAL" => Family::Quad,
            "TRISHELL" => Family::TriShell,
            "TRI" | "TRIANGLE" if dim == 3 => Family::TriShell,
            "TRI" | "TRIANGLE" => Family::Tri,
            "BAR" | "BEAM" | "TRUSS" | "EDGE" | "ROD" => Family::Line,
            "SPHERE" | "CIRCLE" | "POINT" => Family::Point,
            _ => Family::Unknown,
        }
    }

    /// The linear cell kind when the node count is that of the linear cell.
    fn kind(self, npe: usize, elem_type: &str) -> CellKind {
        let linear = match self {
            Family::Hex => Some((CellKind::Hexahedron, 8)),
            Family::Tet => Some((CellKind::Tetra, 4)),
            Family::Wedge => Some((CellKind::Wedge, 6)),
            Family::Pyramid => Some((CellKind::Pyramid, 5)),
            Family::Quad | Family::Shell => Some((CellKind::Quad, 4)),
            Family::Tri | Family::TriShell => Some((CellKind::Triangle, 3)),
            Family::Line => Some((CellKind::Line, 2)),
            Family::Point => Some((CellKind::Vertex, 1)),
            Family::Unknown => None,
        };
        match linear {
            Some((k, n)) if n == npe => k,
            _ => CellKind::Other(format!("{npe}-node {} (Exodus)", elem_type.trim())),
        }
    }

    /// Corner positions (0-based) of side `side` (1-based) and the facet kind.
    fn side(self, side: i64) -> Option<(CellKind, &'static [usize])> {
        const HEX: [[usize; 4]; 6] = [
            [0, 1, 5, 4],
            [1, 2, 6, 5],
            [2, 3, 7, 6],
            [0, 4, 7, 3],
            [0, 3, 2, 1],
            [4, 5, 6, 7],
        ];
        const TET: [[usize; 3]; 4] = [[0, 1, 3], [1, 2, 3], [0, 3, 2], [0, 2, 1]];
        const WEDGE_QUAD: [[usize; 4]; 3] = [[0, 1, 4, 3], [1, 2, 5, 4], [0, 3, 5, 2]];
        const WEDGE_TRI: [[usize; 3]; 2] = [[0, 2, 1], [3, 4, 5]];
        const PYR_TRI: [[usize; 3]; 4] = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [0, 4, 3]];
        const PYR_BASE: [usize; 4] = [0, 3, 2, 1];
        const QUAD_EDGES: [[usize; 2]; 4] = [[0, 1], [1, 2], [2, 3], [3, 0]];
        const SHELL_FACES: [[usize; 4]; 2] = [[0, 1, 2, 3], [0, 3, 2, 1]];
        const TRI_EDGES: [[usize; 2]; 3] = [[0, 1], [1, 2], [2, 0]];
        const TRI_FACES: [[usize; 3]; 2] = [[0, 1, 2], [0, 2, 1]];
        let i = usize::try_from(side).ok()?.checked_sub(1)?;
        let quad = |f: &'static [usize]| (CellKind::Quad, f);
        let tri = |f: &'static [usize]| (CellKind::Triangle, f);
        let line = |f: &'static [usize]| (CellKind::Line, f);
        match self {
            Family::Hex => HEX.get(i).map(|f| quad(f)),
            Family::Tet => TET.get(i).map(|f| tri(f)),
            Family::Wedge if i < 3 => Some(quad(&WEDGE_QUAD[i])),
            Family::Wedge => WEDGE_TRI.get(i - 3).map(|f| tri(f)),
            Family::Pyramid if i < 4 => Some(tri(&PYR_TRI[i])),
            Family::Pyramid => (i == 4).then_some(quad(&PYR_BASE)),
            Family::Quad => QUAD_EDGES.get(i).map(|f| line(f)),
            Family::Shell if i < 2 => Some(quad(&SHELL_FACES[i])),
            Family::Shell => QUAD_EDGES.get(i - 2).map(|f| line(f)),
            Family::Tri => TRI_EDGES.get(i).map(|f| line(f)),
            Family::TriShell if i < 2 => Some(tri(&TRI_FACES[i])),
            Family::TriShell => TRI_EDGES.get(i - 2).map(|f| line(f)),
            Family::Line | Family::Point | Family::Unknown => None,
        }
    }
}

/// An element block as read (for side-set lookups).
struct Block {
    family: Family,
    elem_type: String,
    npe: usize,
    /// Global 0-based index of the block's first element.
    first: usize,
    /// Index into the mesh's blocks.
    raw: usize,
}

/// Read an Exodus II file held in memory.
pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    let nc = NetCdf::parse(data)?;
    let dim = nc.dim("num_dim").ok_or_else(|| {
        ParseError::new(
            Location::File,
            "netCDF file without the dimension num_dim: not an Exodus II mesh",
        )
    })?;
    if !(1..=3).contains(&dim) {
        return Err(ParseError::new(
            Location::File,
            format!("num_dim is {dim}; expected 1, 2 or 3"),
        ));
    }
    let num_nodes = nc.dim("num_nodes").unwrap_or(0);

    // Coordinates.
    let mut points = vec![[0.0f64; 3]; 0];
    if num_nodes > 0 {
        let mut axes: Vec<Vec<f64>> = Vec::new();
        if nc.var("coordx").is_some() {
            for name in ["coordx", "coordy", "coordz"].iter().take(dim) {
                let v = nc.var(name).ok_or_else(|| {
                    ParseError::new(
                        Location::File,
                        format!("num_dim is {dim} but the variable {name} is missing"),
                    )
                })?;
                axes.push(nc.floats(v)?);
            }
        } else if let Some(v) = nc.var("coord") {
            let all = nc.floats(v)?;
            if all.len() < dim * num_nodes {
                return Err(ParseError::at_byte(
                    v.header_at,
                    format!(
                        "variable coord holds {} values, expected num_dim × num_nodes = {}",
                        all.len(),
                        dim * num_nodes
                    ),
                ));
            }
            axes = all
                .chunks(num_nodes)
                .take(dim)
                .map(|c| c.to_vec())
                .collect();
        } else {
            return Err(ParseError::new(
                Location::File,
                "no coordinates: expected the variables coordx/coordy/coordz or coord",
            ));
        }
        for (k, a) in axes.iter().enumerate() {
            if a.len() != num_nodes {
                return Err(ParseError::new(
                    Location::File,
                    format!(
                        "coordinate variable {} holds {} values, expected num_nodes = {num_nodes}",
                        ["coordx", "coordy", "coordz"][k],
                        a.len()
                    ),
                ));
            }
        }
        points = (0..num_nodes)
            .map(|i| {
                let mut p = [0.0; 3];
                for (k, a) in axes.iter().enumerate() {
                    p[k] = a[i];
                }
                p
            })
            .collect();
    }
    let mut mesh = RawMesh {
        points,
        declared_dim: (dim >= 2).then_some(dim),
        ..Default::default()
    };
    let mut tag_names = BTreeMap::new();

    // Element blocks.
    let n_blocks = nc.dim("num_el_blk").unwrap_or(0);
    let block_ids = nc.ids("eb_prop1");
    let block_names = nc.names("eb_names");
    let mut blocks: Vec<Block> = Vec::new();
    let mut n_elems = 0usize;
    // Exodus leaves out the connectivity of empty blocks.
    for (k, v) in nc.numbered("connect", n_blocks) {
        let (b, name) = (k - 1, &v.name);
        let shape = nc.shape(v);
        let (&[n_cells, npe], true) = (&shape[..], shape.get(1).is_some_and(|&n| n > 0)) else {
            return Err(ParseError::at_byte(
                v.header_at,
                format!(
                    "variable {name} has shape {shape:?}, expected [elements, nodes per element]"
                ),
            ));
        };
        let elem_type = v
            .attrs
            .iter()
            .find(|a| a.name.eq_ignore_ascii_case("elem_type") && a.ty == NcType::Char)
            .map(|a| {
                let end = a
                    .value
                    .iter()
                    .position(|&c| c == 0)
                    .unwrap_or(a.value.len());
                String::from_utf8_lossy(&a.value[..end]).trim().to_string()
            })
            .ok_or_else(|| {
                ParseError::at_byte(
                    v.header_at,
                    format!("variable {name} has no elem_type attribute"),
                )
            })?;
        let family = Family::of(&elem_type, dim);
        let (conn, start) = nc.ints(v)?;
        let id = block_ids.get(b).copied().unwrap_or(b as i64 + 1);
        let tag = i32::try_from(id).map_err(|_| {
            ParseError::new(
                Location::File,
                format!("element block id {id} does not fit a 32-bit tag"),
            )
        })?;
        if let Some(n) = block_names.get(b).filter(|n| !n.is_empty()) {
            tag_names.insert(tag, n.clone());
        }
        let mut rb = RawBlock::new(family.kind(npe, &elem_type), npe);
        rb.nodes.reserve(conn.len());
        for (k, &c) in conn.iter().enumerate() {
            if c < 1 || c as usize > num_nodes {
                return Err(ParseError::at_byte(
                    start + k * v.ty.size(),
                    format!(
                        "block {id} ({elem_type}), element {}: node index {c} is out of range 1..={num_nodes}",
                        k / npe.max(1) + 1
                    ),
                ));
            }
            rb.nodes.push(c - 1);
        }
        rb.tags = vec![tag; n_cells];
        rb.locations = (0..n_cells)
            .map(|c| Location::Byte(start + c * npe * v.ty.size()))
            .collect();
        blocks.push(Block {
            family,
            elem_type,
            npe,
            first: n_elems,
            raw: mesh.blocks.len(),
        });
        n_elems += n_cells;
        // Kept unmerged so that side sets can find their element's block.
        mesh.blocks.push(rb);
    }

    // Side sets.
    let n_sets = nc.dim("num_side_sets").unwrap_or(0);
    let set_ids = nc.ids("ss_prop1");
    let set_names = nc.names("ss_names");
    let mut facets: Vec<RawBlock> = Vec::new();
    for (k, ev) in nc.numbered("elem_ss", n_sets) {
        let s = k - 1;
        let Some(sv) = nc.var(&format!("side_ss{k}")) else {
            continue;
        };
        let id = set_ids.get(s).copied().unwrap_or(s as i64 + 1);
        let tag = i32::try_from(id).map_err(|_| {
            ParseError::new(
                Location::File,
                format!("side set id {id} does not fit a 32-bit tag"),
            )
        })?;
        if let Some(n) = set_names.get(s).filter(|n| !n.is_empty()) {
            tag_names.insert(tag, n.clone());
        }
        let (elems, estart) = nc.ints(ev)?;
        let (sides, sstart) = nc.ints(sv)?;
        if elems.len() != sides.len() {
            return Err(ParseError::at_byte(
                sv.header_at,
                format!(
                    "side set {id}: {} elements but {} sides",
                    elems.len(),
                    sides.len()
                ),
            ));
        }
        for (k, (&e, &side)) in elems.iter().zip(&sides).enumerate() {
            let eloc = estart + k * ev.ty.size();
            if e < 1 || e as usize > n_elems {
                return Err(ParseError::at_byte(
                    eloc,
                    format!("side set {id}: element {e} is out of range 1..={n_elems}"),
                ));
            }
            let g = e as usize - 1;
            let bi = blocks.partition_point(|b| b.first <= g) - 1;
            let b = &blocks[bi];
            let face = b
                .family
                .side(side)
                .filter(|(_, f)| f.iter().all(|&i| i < b.npe));
            let Some((fkind, local)) = face else {
                return Err(ParseError::at_byte(
                    sstart + k * sv.ty.size(),
                    format!(
                        "side set {id}: element {e} ({}) has no side {side}",
                        b.elem_type
                    ),
                ));
            };
            let cell = g - b.first;
            let nodes = &mesh.blocks[b.raw].nodes[cell * b.npe..(cell + 1) * b.npe];
            let fb = match facets.iter().position(|f| f.kind() == &fkind) {
                Some(i) => &mut facets[i],
                None => {
                    facets.push(RawBlock::new(fkind.clone(), local.len()));
                    facets.last_mut().expect("just pushed")
                }
            };
            fb.nodes.extend(local.iter().map(|&i| nodes[i]));
            fb.tags.push(tag);
            fb.locations.push(Location::Byte(eloc));
        }
    }
    let element_blocks = std::mem::take(&mut mesh.blocks);
    for b in element_blocks.into_iter().chain(facets) {
        mesh.push_block(b);
    }
    mesh.tag_names = tag_names;
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    const REAL: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/meshes/real/libmesh/systems_of_equations_ex9.exo"
    );

    fn fixture(name: &str) -> Vec<u8> {
        let path = format!("{}/tests/data/exodus/{name}", env!("CARGO_MANIFEST_DIR"));
        std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
    }

    fn of_kind<'a>(m: &'a RawMesh, kind: &CellKind) -> Vec<&'a RawBlock> {
        m.blocks.iter().filter(|b| b.kind() == kind).collect()
    }

    /// Begin offset of a variable, from this module's header parser.
    fn begin_of(data: &[u8], var: &str) -> usize {
        let nc = NetCdf::parse(data).unwrap();
        nc.var(var).unwrap().begin
    }

    #[test]
    fn real_libmesh_hexes_match_an_independent_netcdf_reader() {
        let data = std::fs::read(REAL).unwrap();
        let m = read(&data).unwrap();
        assert_eq!(m.points.len(), 1608);
        assert_eq!(m.declared_dim, Some(3));
        let hexes = of_kind(&m, &CellKind::Hexahedron);
        assert_eq!(hexes.iter().map(|b| b.len()).sum::<usize>(), 1110);
        let quads = of_kind(&m, &CellKind::Quad);
        assert_eq!(quads.len(), 1);
        assert_eq!(quads[0].len(), 50 + 50 + 10 + 50 + 70 + 10 + 50 + 70);

        // The netcdf3 crate reads the same file independently.
        let mut r = netcdf3::FileReader::open(REAL).unwrap();
        let x = r.read_var_f64("coordx").unwrap();
        let z = r.read_var_f64("coordz").unwrap();
        for i in [0, 1, 777, 1607] {
            assert_eq!(m.points[i][0], x[i]);
            assert_eq!(m.points[i][2], z[i]);
        }
        let c1 = r.read_var_i32("connect1").unwrap();
        let c2 = r.read_var_i32("connect2").unwrap();
        let all: Vec<i64> = c1.iter().chain(&c2).map(|&v| v as i64 - 1).collect();
        let ours: Vec<i64> = hexes.iter().flat_map(|b| b.nodes.iter().copied()).collect();
        assert_eq!(ours, all);
        // Block ids 1 and 101 become element tags; the names are empty in this file.
        let tags: Vec<i32> = hexes.iter().flat_map(|b| b.tags.iter().copied()).collect();
        assert!(tags[..555].iter().all(|&t| t == 1));
        assert!(tags[555..].iter().all(|&t| t == 101));
        assert!(m.tag_names.is_empty());
        // First side of side set 1 (id 402): element 585, side 1 = nodes 1, 2, 6, 5.
        let e = r.read_var_i32("elem_ss1").unwrap();
        let s = r.read_var_i32("side_ss1").unwrap();
        assert_eq!((e[0], s[0]), (585, 1));
        let h = &all[(585 - 1) * 8..585 * 8];
        assert_eq!(&quads[0].nodes[..4], &[h[0], h[1], h[5], h[4]]);
        assert_eq!(quads[0].tags[0], 402);
        // Element 556 side 4 (fourth entry) = nodes 1, 5, 8, 4.
        assert_eq!((e[3], s[3]), (556, 4));
        let h = &all[(556 - 1) * 8..556 * 8];
        assert_eq!(&quads[0].nodes[12..16], &[h[0], h[4], h[7], h[3]]);
        // Locations are byte offsets of the connectivity.
        let b1 = begin_of(&data, "connect1");
        assert_eq!(hexes[0].locations[2], Location::Byte(b1 + 2 * 32));
    }

    #[test]
    fn real_libmesh_builds_a_linear_mesh() {
        use crate::mesh::{LinearMesh, MeshOptions};
        let raw = read(&std::fs::read(REAL).unwrap()).unwrap();
        let m = LinearMesh::from_raw(raw, &MeshOptions::default()).unwrap();
        assert_eq!(m.dim, 3);
        assert_eq!(m.elements.len(), 8 * 1110);
        assert_eq!(m.coords.len(), 1608);
        assert_eq!(m.facet_tags.len(), 360);
        assert_eq!(m.reoriented, 0);
    }

    #[test]
    fn classic_hexes_blocks_and_named_side_sets() {
        let m = read(&fixture("two_hex_classic.exo")).unwrap();
        assert_eq!(m.points.len(), 12);
        assert_eq!(m.points[2], [1.25, 0.0, 0.0]);
        assert_eq!(m.points[10], [0.5, 1.0, 1.0]);
        let hexes = of_kind(&m, &CellKind::Hexahedron);
        assert_eq!(hexes.len(), 1);
        assert_eq!(
            hexes[0].nodes,
            vec![0, 1, 4, 3, 6, 7, 10, 9, 1, 2, 5, 4, 7, 8, 11, 10]
        );
        assert_eq!(hexes[0].tags, vec![10, 20]);
        let q = of_kind(&m, &CellKind::Quad);
        assert_eq!(q[0].nodes, vec![0, 6, 9, 3, 6, 7, 10, 9, 7, 8, 11, 10]);
        assert_eq!(q[0].tags, vec![5, 7, 7]);
        let names: Vec<(i32, &str)> = m.tag_names.iter().map(|(k, v)| (*k, v.as_str())).collect();
        assert_eq!(
            names,
            vec![(5, "xmin"), (7, "top"), (10, "left"), (20, "right")]
        );
    }

    #[test]
    fn offset64_quads_triangles_and_float_coord() {
        let m = read(&fixture("quads_64bit.exo")).unwrap();
        assert_eq!(m.declared_dim, Some(2));
        assert_eq!(m.points.len(), 7);
        assert_eq!(m.points[6], [3.0, 0.5, 0.0]);
        let q = of_kind(&m, &CellKind::Quad);
        assert_eq!(q[0].nodes, vec![0, 1, 4, 3, 1, 2, 5, 4]);
        assert_eq!(q[0].tags, vec![1, 1]);
        let t = of_kind(&m, &CellKind::Triangle);
        assert_eq!(t[0].nodes, vec![2, 6, 5, 0, 4, 3]);
        assert_eq!(t[0].tags, vec![2, 2]);
        let l = of_kind(&m, &CellKind::Line);
        assert_eq!(l[0].nodes, vec![0, 1, 2, 5, 6, 5]);
        assert_eq!(l[0].tags, vec![3, 3, 3]);
        assert!(m.tag_names.is_empty());
    }

    #[test]
    fn element_type_names() {
        assert_eq!(Family::of("HEX8", 3).kind(8, "HEX8"), CellKind::Hexahedron);
        assert_eq!(Family::of("hex", 3).kind(8, "hex"), CellKind::Hexahedron);
        assert_eq!(Family::of("SHELL4", 3).kind(4, "SHELL4"), CellKind::Quad);
        assert_eq!(Family::of("QUAD", 3), Family::Shell);
        assert_eq!(Family::of("QUAD4", 2), Family::Quad);
        assert_eq!(Family::of("TETRA", 3).kind(4, "TETRA"), CellKind::Tetra);
        assert_eq!(Family::of("WEDGE6", 3).kind(6, "WEDGE6"), CellKind::Wedge);
        assert_eq!(
            Family::of("PYRAMID", 3).kind(5, "PYRAMID"),
            CellKind::Pyramid
        );
        assert_eq!(Family::of("TRI3", 2).kind(3, "TRI3"), CellKind::Triangle);
        assert_eq!(Family::of("BAR2", 2).kind(2, "BAR2"), CellKind::Line);
        for (t, n) in [("HEX20", 20), ("HEX27", 27), ("QUAD8", 8), ("QUAD9", 9)] {
            assert_eq!(
                Family::of(t, 3).kind(n, t),
                CellKind::Other(format!("{n}-node {t} (Exodus)"))
            );
        }
        assert_eq!(Family::Shell.side(1).unwrap().0, CellKind::Quad);
        assert_eq!(
            Family::Shell.side(3).unwrap(),
            (CellKind::Line, &[0, 1][..])
        );
        assert!(Family::Hex.side(7).is_none());
        assert!(Family::Hex.side(0).is_none());
        assert!(Family::Hex.side(-1).is_none());
    }

    #[test]
    fn not_netcdf_or_unsupported_containers() {
        let e = read(b"hello world, not a mesh").unwrap_err();
        assert_eq!(e.location, Location::Byte(0));
        assert!(e.message.contains("not a netCDF file"), "{}", e.message);
        let e = read(b"\x89HDF\r\n\x1a\n\0\0\0\0").unwrap_err();
        assert_eq!(e.location, Location::Byte(0));
        assert!(e.message.contains("netCDF-4"), "{}", e.message);
        let e = read(b"CDF\x05\0\0\0\0").unwrap_err();
        assert_eq!(e.location, Location::Byte(3));
        assert!(read(b"").is_err());
        assert!(read(b"CDF").is_err());
        // A netCDF file without Exodus dimensions.
        let e = read(&[b"CDF\x01".as_slice(), &[0; 28]].concat()).unwrap_err();
        assert_eq!(e.location, Location::File);
        assert!(e.message.contains("num_dim"), "{}", e.message);
    }

    #[test]
    fn huge_header_counts_are_errors_not_allocations() {
        // 2^31 - 1 dimensions claimed in a 16-byte file.
        let e = read(b"CDF\x01\0\0\0\0\0\0\0\x0a\x7f\xff\xff\xff").unwrap_err();
        assert_eq!(e.location, Location::Byte(12));
        assert!(e.message.contains("does not fit"), "{}", e.message);
        // A dimension claiming 2^32 - 1 entries: the variable using it does not fit the file.
        let mut data = fixture("two_hex_classic.exo");
        let nc = NetCdf::parse(&data).unwrap();
        let d = nc.dims.iter().position(|d| d.name == "num_nodes").unwrap();
        drop(nc);
        // Find the dimension's length field: after its padded name.
        let name = b"num_nodes\0\0\0";
        let at = data.windows(name.len()).position(|w| w == name).unwrap() + name.len();
        data[at..at + 4].copy_from_slice(&[0xff, 0xff, 0xff, 0xff]);
        let e = read(&data).unwrap_err();
        assert!(matches!(e.location, Location::Byte(_)), "{e}");
        assert!(e.message.contains("coordx"), "{} (dim {d})", e.message);
    }

    #[test]
    fn truncated_and_corrupted_copies_of_the_real_file() {
        let data = std::fs::read(REAL).unwrap();
        // Truncation inside the header.
        let e = read(&data[..300]).unwrap_err();
        assert!(matches!(e.location, Location::Byte(b) if b <= 300), "{e}");
        assert!(e.message.contains("truncated"), "{}", e.message);
        // Truncation inside the connectivity.
        let b2 = begin_of(&data, "connect2");
        let e = read(&data[..b2 + 100]).unwrap_err();
        assert_eq!(e.location, Location::Byte(b2));
        assert!(e.message.contains("connect2"), "{}", e.message);
        // An out-of-range node index names its byte.
        let b1 = begin_of(&data, "connect1");
        let mut bad = data.clone();
        bad[b1 + 16..b1 + 20].copy_from_slice(&99_999i32.to_be_bytes());
        let e = read(&bad).unwrap_err();
        assert_eq!(e.location, Location::Byte(b1 + 16));
        assert!(e.message.contains("99999"), "{}", e.message);
        // A side number out of range names its byte.
        let s1 = begin_of(&data, "side_ss1");
        let mut bad = data.clone();
        bad[s1 + 4..s1 + 8].copy_from_slice(&9i32.to_be_bytes());
        let e = read(&bad).unwrap_err();
        assert_eq!(e.location, Location::Byte(s1 + 4));
        assert!(e.message.contains("no side 9"), "{}", e.message);
        // An element number out of range in a side set.
        let e1 = begin_of(&data, "elem_ss1");
        let mut bad = data.clone();
        bad[e1..e1 + 4].copy_from_slice(&0i32.to_be_bytes());
        let e = read(&bad).unwrap_err();
        assert_eq!(e.location, Location::Byte(e1));
    }

    #[test]
    fn truncation_and_byte_flips_never_panic() {
        let data = std::fs::read(REAL).unwrap();
        let header_end = begin_of(&data, "eb_status");
        for cut in (0..header_end + 64).chain((header_end..data.len()).step_by(509)) {
            assert!(read(&data[..cut]).is_err(), "cut at {cut}");
        }
        for name in ["two_hex_classic.exo", "quads_64bit.exo"] {
            let clean = fixture(name);
            let mut x: u32 = 987_654_321;
            for _ in 0..4000 {
                let mut noisy = clean.clone();
                for _ in 0..3 {
                    x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
                    let i = (x as usize >> 3) % noisy.len();
                    noisy[i] = (x >> 19) as u8;
                }
                let _ = read(&noisy);
            }
        }
    }
}
