//! Abaqus input files (`.inp`).
//!
//! Read:
//! * `*NODE` lines `id, x[, y[, z]]` (blank or missing coordinates are 0; extra fields such as
//!   normal direction cosines are ignored). Node ids are arbitrary distinct integers; they are
//!   mapped to 0-based positions in file order.
//! * `*ELEMENT, TYPE=...[, ELSET=name]` lines `id, n1, n2, ...`. A line ending with a comma
//!   continues on the next line. Linear types become their [`CellKind`] (node order equals
//!   VTK's): CPS4/CPE4/CAX4/S4/S4R/M3D4/R3D4/SFM3D4/... → quad, C3D8/C3D8R/C3D8I/C3D8H/SC8R →
//!   hexahedron, CPS3/S3/STRI3/... → triangle, C3D4 → tetrahedron, C3D6 → wedge, C3D5 → pyramid,
//!   T2D2/T3D2/B21/B31/... → line. Other types (C3D20, C3D27, CPS8, springs, ...) are reported
//!   as [`CellKind::Other`] with the Abaqus type name.
//! * `*ELSET, ELSET=name[, GENERATE]`: element ids, `first, last[, step]` ranges, or names of
//!   earlier element sets. Repeated definitions of one name add to the set.
//! * `*SURFACE, TYPE=ELEMENT, NAME=name` lines `element_id_or_elset, Sn`: the faces become
//!   boundary facets (lines for 2D elements, quads or triangles for 3D ones) with the Abaqus
//!   face numbering (C3D8: S1 = 1-2-3-4, S2 = 5-8-7-6, S3 = 1-5-6-2, S4 = 2-6-7-3,
//!   S5 = 3-7-8-4, S6 = 4-8-5-1; quad and triangle: Sk = edge from node k to node k+1).
//!   Lines without a face label (the free faces of a set) and labels such as `SPOS`/`SNEG` or
//!   edge labels are skipped.
//! * `*PART`/`*END PART`, `*ASSEMBLY`, `*INSTANCE`: the mesh of the first part is read (instance
//!   positioning is ignored, and a part instanced twice is read once). Element sets and
//!   surfaces in the assembly that refer to an instance of that part (`INSTANCE=` or
//!   `instance.set` names) are used; everything else in the assembly is skipped.
//!
//! Tags: every element set that is not marked `INTERNAL` gets the tag 1, 2, ... in order of
//! first appearance (the set named on `*ELEMENT, ELSET=` included); an element carries the tag
//! of the first such set that contains it (0 if none). Surfaces get the tags after the element
//! sets. All tags are named in [`RawMesh::tag_names`].
//!
//! Ignored: `*NSET` (real files list node ids that `*NODE` never defines; see the NACA 4412
//! mesh), materials, steps and every other keyword with its data lines. Keywords that would
//! generate or move nodes or elements (`*NGEN`, `*NFILL`, `*NCOPY`, `*ELGEN`, `*ELCOPY`,
//! `*NMAP`, `*SYSTEM`) are errors, since skipping them would give a wrong mesh. `*INCLUDE` is
//! not followed; if the file then holds no elements, the error says so.
//!
//! Traps: keywords and set names are case-insensitive; `**` starts a comment line; keyword
//! lines may also continue after a trailing comma; set members may name undefined elements
//! (ignored, as for node sets).

use super::raw::{CellKind, Location, ParseError, RawBlock, RawMesh};
use super::text::parse_f64;
use std::collections::HashMap;

/// Iterator over the lines of the input with 1-based line numbers (`\r\n` aware).
struct Lines<'a> {
    data: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> Lines<'a> {
    fn next_line(&mut self) -> Option<(usize, &'a [u8])> {
        if self.pos >= self.data.len() {
            return None;
        }
        let rest = &self.data[self.pos..];
        let len = rest.iter().position(|&b| b == b'\n');
        let (line, advance) = match len {
            Some(l) => (&rest[..l], l + 1),
            None => (rest, rest.len()),
        };
        self.pos += advance;
        self.line += 1;
        Some((self.line, line.strip_suffix(b"\r").unwrap_or(line)))
    }

    /// The next line that is neither blank nor a comment, without consuming it.
    fn peek_content(&mut self) -> Option<(usize, &'a [u8])> {
        let (pos, line) = (self.pos, self.line);
        let mut found = None;
        while let Some((n, l)) = self.next_line() {
            let t = l.trim_ascii();
            if t.is_empty() || t.starts_with(b"**") {
                continue;
            }
            found = Some((n, l));
            break;
        }
        self.pos = pos;
        self.line = line;
        found
    }
}

fn show(field: &[u8]) -> String {
    String::from_utf8_lossy(field).chars().take(40).collect()
}

/// Parse a (possibly signed) decimal integer field without allocating.
fn parse_int(field: &[u8]) -> Option<i64> {
    let (neg, digits) = match field.first() {
        Some(b'-') => (true, &field[1..]),
        Some(b'+') => (false, &field[1..]),
        _ => (false, field),
    };
    if digits.is_empty() || digits.len() > 18 {
        return None;
    }
    let mut v: i64 = 0;
    for &b in digits {
        if !b.is_ascii_digit() {
            return None;
        }
        v = v * 10 + (b - b'0') as i64;
    }
    Some(if neg { -v } else { v })
}

fn parse_float(field: &[u8]) -> Option<f64> {
    std::str::from_utf8(field).ok().and_then(parse_f64)
}

/// A keyword line: upper-case keyword with spaces removed, and its parameters (upper-case key,
/// value as written, quotes removed).
struct Keyword {
    name: String,
    params: Vec<(String, String)>,
}

impl Keyword {
    fn parse(text: &str) -> Keyword {
        let mut parts = text.trim_start_matches('*').split(',');
        let name: String = parts
            .next()
            .unwrap_or("")
            .chars()
            .filter(|c| !c.is_whitespace())
            .collect::<String>()
            .to_ascii_uppercase();
        let params = parts
            .filter_map(|p| {
                let p = p.trim();
                if p.is_empty() {
                    return None;
                }
                let (k, v) = p.split_once('=').unwrap_or((p, ""));
                let key: String = k
                    .chars()
                    .filter(|c| !c.is_whitespace())
                    .collect::<String>()
                    .to_ascii_uppercase();
                Some((key, v.trim().trim_matches('"').to_string()))
            })
            .collect();
        Keyword { name, params }
    }

    fn param(&self, key: &str) -> Option<&str> {
        self.params
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    fn has(&self, key: &str) -> bool {
        self.params.iter().any(|(k, _)| k == key)
    }
}

/// What an Abaqus element type is: its kind and, where the type fixes it, its node count.
fn element_kind(ty: &str) -> (CellKind, Option<usize>) {
    let t = ty.to_ascii_uppercase();
    // Leading decimal digits after `prefix`, if `t` starts with it.
    let count_after = |prefix: &str| -> Option<usize> {
        let rest = t.strip_prefix(prefix)?;
        let digits: String = rest.chars().take_while(|c| c.is_ascii_digit()).collect();
        digits.parse().ok()
    };
    let other = |n: Option<usize>, shape: &str| -> (CellKind, Option<usize>) {
        let name = match n {
            Some(n) if !shape.is_empty() => format!("{n}-node {shape} (Abaqus {ty})"),
            _ => format!("Abaqus {ty}"),
        };
        (CellKind::Other(name), n)
    };
    const SOLID: [&str; 5] = ["DCC3D", "DC3D", "AC3D", "C3D", "SC"];
    const PLANAR: [&str; 16] = [
        "CPEG", "CPE", "CPS", "CGAX", "CAX", "DCC2D", "DCCAX", "DC2D", "DCAX", "AC2D", "ACAX",
        "SFM3D", "M3D", "R3D", "STRI", "DS",
    ];
    const LINE: [&str; 7] = ["DCC1D", "DC1D", "T2D", "T3D", "RB2D", "RB3D", "R2D"];
    for p in SOLID {
        if let Some(n) = count_after(p) {
            return match n {
                4 => (CellKind::Tetra, Some(4)),
                5 => (CellKind::Pyramid, Some(5)),
                6 => (CellKind::Wedge, Some(6)),
                8 => (CellKind::Hexahedron, Some(8)),
                10 => other(Some(10), "tetrahedron"),
                15 => other(Some(15), "wedge"),
                20 | 27 => other(Some(n), "hexahedron"),
                _ => other(None, ""),
            };
        }
    }
    // Shells S3, S4, S4R, S8R, ... (checked after "SC" and "SFM3D" above and below).
    let planar = PLANAR
        .iter()
        .find_map(|p| count_after(p))
        .or_else(|| count_after("S"));
    if let Some(n) = planar {
        return match n {
            3 => (CellKind::Triangle, Some(3)),
            4 => (CellKind::Quad, Some(4)),
            6 => other(Some(6), "triangle"),
            8 | 9 => other(Some(n), "quadrilateral"),
            _ => other(None, ""),
        };
    }
    if let Some(n) = LINE.iter().find_map(|p| count_after(p)) {
        return match n {
            2 => (CellKind::Line, Some(2)),
            3 => other(Some(3), "line"),
            _ => other(None, ""),
        };
    }
    // Beams and pipes: B21, B31, B23 (cubic, 2 nodes), B22/B32 (3 nodes), PIPE21, ...
    for p in ["B2", "B3", "PIPE2", "PIPE3"] {
        if let Some(n) = count_after(p) {
            return match n {
                1 | 3 => (CellKind::Line, Some(2)),
                2 => other(Some(3), "line"),
                _ => other(None, ""),
            };
        }
    }
    other(None, "")
}

/// Face (or edge) `face` (1-based) of an element as 0-based local node positions, with the
/// facet kind; `None` when the element has no such face.
fn element_face(kind: &CellKind, face: usize) -> Option<(CellKind, &'static [usize])> {
    const HEX: [[usize; 4]; 6] = [
        [0, 1, 2, 3],
        [4, 7, 6, 5],
        [0, 4, 5, 1],
        [1, 5, 6, 2],
        [2, 6, 7, 3],
        [3, 7, 4, 0],
    ];
    const TET: [[usize; 3]; 4] = [[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]];
    const WEDGE_TRI: [[usize; 3]; 2] = [[0, 1, 2], [3, 5, 4]];
    const WEDGE_QUAD: [[usize; 4]; 3] = [[0, 3, 4, 1], [1, 4, 5, 2], [2, 5, 3, 0]];
    const PYR_TRI: [[usize; 3]; 4] = [[0, 4, 1], [1, 4, 2], [2, 4, 3], [3, 4, 0]];
    const QUAD: [[usize; 2]; 4] = [[0, 1], [1, 2], [2, 3], [3, 0]];
    const TRI: [[usize; 2]; 3] = [[0, 1], [1, 2], [2, 0]];
    let i = face.checked_sub(1)?;
    match kind {
        CellKind::Hexahedron => HEX.get(i).map(|f| (CellKind::Quad, &f[..])),
        CellKind::Tetra => TET.get(i).map(|f| (CellKind::Triangle, &f[..])),
        CellKind::Wedge => match i {
            0 | 1 => Some((CellKind::Triangle, &WEDGE_TRI[i][..])),
            _ => WEDGE_QUAD.get(i - 2).map(|f| (CellKind::Quad, &f[..])),
        },
        CellKind::Pyramid => match i {
            0 => Some((CellKind::Quad, &HEX[0][..])),
            _ => PYR_TRI.get(i - 1).map(|f| (CellKind::Triangle, &f[..])),
        },
        CellKind::Quad => QUAD.get(i).map(|f| (CellKind::Line, &f[..])),
        CellKind::Triangle => TRI.get(i).map(|f| (CellKind::Line, &f[..])),
        _ => None,
    }
}

/// Map from file ids to 0-based positions: a dense table when ids are compact, else a hash map.
enum IdMap {
    Dense(Vec<u32>),
    Sparse(HashMap<i64, u32>),
}

impl IdMap {
    /// Build the map; on a repeated id returns the position of its second occurrence.
    fn build(ids: &[i64]) -> Result<IdMap, usize> {
        let max = ids.iter().copied().max().unwrap_or(0);
        let min = ids.iter().copied().min().unwrap_or(0);
        if min >= 0 && (max as u64) <= 2 * ids.len() as u64 + 1024 {
            let mut table = vec![u32::MAX; max as usize + 1];
            for (i, &id) in ids.iter().enumerate() {
                let slot = &mut table[id as usize];
                if *slot != u32::MAX {
                    return Err(i);
                }
                *slot = i as u32;
            }
            Ok(IdMap::Dense(table))
        } else {
            let mut map = HashMap::with_capacity(ids.len());
            for (i, &id) in ids.iter().enumerate() {
                if map.insert(id, i as u32).is_some() {
                    return Err(i);
                }
            }
            Ok(IdMap::Sparse(map))
        }
    }

    fn get(&self, id: i64) -> Option<usize> {
        match self {
            IdMap::Dense(t) => {
                let v = *t.get(usize::try_from(id).ok()?)?;
                (v != u32::MAX).then_some(v as usize)
            }
            IdMap::Sparse(m) => m.get(&id).map(|&v| v as usize),
        }
    }
}

/// One `*ELEMENT` section.
struct ElementBlock {
    kind: CellKind,
    type_name: String,
    /// Nodes per element, fixed by the type or by the first element of the section.
    npc: Option<usize>,
    /// Node ids as written (translated to positions at the end).
    nodes: Vec<i64>,
    ids: Vec<i64>,
    lines: Vec<usize>,
    /// The set named by `ELSET=` on the keyword line.
    elset: Option<usize>,
}

struct ElementSet {
    name: String,
    internal: bool,
    members: Vec<i64>,
}

struct Surface {
    name: String,
    /// (line, element set index or element id, face number).
    faces: Vec<(usize, SurfaceTarget, usize)>,
}

enum SurfaceTarget {
    Set(usize),
    Element(i64),
}

enum Mode {
    Skip,
    Node,
    Element(usize),
    Elset { set: usize, generate: bool },
    Surface(usize),
}

#[derive(Default)]
struct Reader {
    node_ids: Vec<i64>,
    points: Vec<[f64; 3]>,
    point_lines: Vec<usize>,
    blocks: Vec<ElementBlock>,
    sets: Vec<ElementSet>,
    /// Lower-case set name → index into `sets`.
    set_index: HashMap<String, usize>,
    surfaces: Vec<Surface>,
    includes: Vec<(usize, String)>,
}

impl Reader {
    fn set_named(&mut self, name: &str, internal: bool) -> usize {
        let key = name.to_ascii_lowercase();
        if let Some(&i) = self.set_index.get(&key) {
            return i;
        }
        self.sets.push(ElementSet {
            name: name.to_string(),
            internal,
            members: Vec::new(),
        });
        self.set_index.insert(key, self.sets.len() - 1);
        self.sets.len() - 1
    }

    fn node_line(&mut self, ln: usize, line: &[u8]) -> Result<(), ParseError> {
        let mut fields = line.split(|&b| b == b',').map(|f| f.trim_ascii());
        let id_field = fields.next().unwrap_or_default();
        let id = parse_int(id_field).ok_or_else(|| {
            ParseError::at_line(
                ln,
                format!("expected node id, found \"{}\"", show(id_field)),
            )
        })?;
        let mut p = [0.0; 3];
        for (k, c) in p.iter_mut().enumerate() {
            match fields.next() {
                None => break,
                Some([]) => {}
                Some(f) => {
                    *c = parse_float(f).ok_or_else(|| {
                        ParseError::at_line(
                            ln,
                            format!(
                                "expected {} coordinate of node {id}, found \"{}\"",
                                ["x", "y", "z"][k],
                                show(f)
                            ),
                        )
                    })?;
                }
            }
        }
        self.node_ids.push(id);
        self.points.push(p);
        self.point_lines.push(ln);
        Ok(())
    }

    fn element_record(
        &mut self,
        b: usize,
        ln: usize,
        line: &[u8],
        lines: &mut Lines,
    ) -> Result<(), ParseError> {
        let block = &mut self.blocks[b];
        let start = block.nodes.len();
        let mut id: Option<i64> = None;
        let mut line = line;
        let mut cur_line = ln;
        loop {
            let trimmed = line.trim_ascii();
            let continues = trimmed.ends_with(b",");
            for f in trimmed.split(|&c| c == b',').map(|f| f.trim_ascii()) {
                if f.is_empty() {
                    continue;
                }
                let v = parse_int(f).ok_or_else(|| {
                    let what = if id.is_none() {
                        "element id".to_string()
                    } else {
                        format!("node id of element {}", id.unwrap_or(0))
                    };
                    ParseError::at_line(cur_line, format!("expected {what}, found \"{}\"", show(f)))
                })?;
                if id.is_none() {
                    id = Some(v);
                    continue;
                }
                if block.npc == Some(block.nodes.len() - start) {
                    return Err(ParseError::at_line(
                        cur_line,
                        format!(
                            "element {} of type {} has more than {} node ids",
                            id.unwrap_or(0),
                            block.type_name,
                            block.nodes.len() - start
                        ),
                    ));
                }
                block.nodes.push(v);
            }
            let have = block.nodes.len() - start;
            let complete = match block.npc {
                Some(n) => have == n,
                None => !continues,
            };
            if complete && id.is_some() {
                break;
            }
            // The record goes on in the next line, which must be a data line.
            match lines.peek_content() {
                Some((_, next)) if !next.trim_ascii().starts_with(b"*") => {
                    while let Some((n, l)) = lines.next_line() {
                        let t = l.trim_ascii();
                        if t.is_empty() || t.starts_with(b"**") {
                            continue;
                        }
                        cur_line = n;
                        line = l;
                        break;
                    }
                }
                _ => {
                    return Err(ParseError::at_line(
                        cur_line,
                        match (id, block.npc) {
                            (Some(id), Some(n)) => format!(
                                "element {id} of type {} needs {n} node ids, found {have} before the end of the section",
                                block.type_name
                            ),
                            (Some(id), None) => format!(
                                "element {id}: the line ends with a comma but no data line follows"
                            ),
                            (None, _) => "expected an element id".to_string(),
                        },
                    ));
                }
            }
        }
        let have = block.nodes.len() - start;
        match block.npc {
            None if have == 0 => {
                return Err(ParseError::at_line(
                    cur_line,
                    format!("element {} has no node ids", id.unwrap_or(0)),
                ));
            }
            None => block.npc = Some(have),
            Some(_) => {}
        }
        if block.npc != Some(have) {
            return Err(ParseError::at_line(
                cur_line,
                format!(
                    "element {} of type {} has {have} node ids, the first element of this section has {}",
                    id.unwrap_or(0),
                    block.type_name,
                    block.npc.unwrap_or(0)
                ),
            ));
        }
        let id = id.unwrap_or(0);
        block.ids.push(id);
        block.lines.push(ln);
        if let Some(s) = block.elset {
            self.sets[s].members.push(id);
        }
        Ok(())
    }

    fn elset_line(
        &mut self,
        set: usize,
        generate: bool,
        ln: usize,
        line: &[u8],
    ) -> Result<(), ParseError> {
        let fields: Vec<&[u8]> = line
            .split(|&b| b == b',')
            .map(|f| f.trim_ascii())
            .filter(|f| !f.is_empty())
            .collect();
        if generate {
            let nums: Vec<i64> = fields
                .iter()
                .map(|f| {
                    parse_int(f).ok_or_else(|| {
                        ParseError::at_line(
                            ln,
                            format!(
                                "expected an element id of a GENERATE range, found \"{}\"",
                                show(f)
                            ),
                        )
                    })
                })
                .collect::<Result<_, _>>()?;
            let (first, last, step) = match nums[..] {
                [a, b] => (a, b, 1),
                [a, b, s] => (a, b, s),
                _ => {
                    return Err(ParseError::at_line(
                        ln,
                        format!(
                            "expected \"first, last[, increment]\", found {} values",
                            nums.len()
                        ),
                    ));
                }
            };
            if step <= 0 || last < first {
                return Err(ParseError::at_line(
                    ln,
                    format!("invalid GENERATE range {first}, {last}, {step}"),
                ));
            }
            // Members of a range that names no element are dropped later, so bound the range
            // by what the file can hold.
            let count = (last - first) / step + 1;
            if count > 8 * (self.blocks.iter().map(|b| b.ids.len()).sum::<usize>() as i64) + 1024 {
                return Err(ParseError::at_line(
                    ln,
                    format!(
                        "GENERATE range {first}..{last} is far larger than the number of elements"
                    ),
                ));
            }
            let members = &mut self.sets[set].members;
            let mut v = first;
            while v <= last {
                members.push(v);
                v += step;
            }
            return Ok(());
        }
        for f in fields {
            if let Some(v) = parse_int(f) {
                self.sets[set].members.push(v);
                continue;
            }
            let name = String::from_utf8_lossy(f).to_ascii_lowercase();
            match self.set_index.get(&name) {
                Some(&other) if other != set => {
                    let m = self.sets[other].members.clone();
                    self.sets[set].members.extend(m);
                }
                _ => {
                    return Err(ParseError::at_line(
                        ln,
                        format!(
                            "expected an element id or the name of an element set, found \"{}\"",
                            show(f)
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    fn surface_line(
        &mut self,
        surface: usize,
        instances: &[String],
        ln: usize,
        line: &[u8],
    ) -> Result<(), ParseError> {
        let mut fields = line.split(|&b| b == b',').map(|f| f.trim_ascii());
        let target = fields.next().unwrap_or_default();
        let label = fields.next().unwrap_or_default();
        let face = match label {
            [b'S' | b's', rest @ ..] => match parse_int(rest) {
                Some(n) if n > 0 => n as usize,
                // SPOS / SNEG (shell sides) and the like.
                _ => return Ok(()),
            },
            // No label (free faces of a set) or edge labels: not read.
            _ => return Ok(()),
        };
        let target = if let Some(id) = parse_int(target) {
            SurfaceTarget::Element(id)
        } else {
            let mut name = String::from_utf8_lossy(target)
                .trim_matches('"')
                .to_ascii_lowercase();
            if let Some((inst, rest)) = name.split_once('.')
                && instances.iter().any(|i| i == inst)
            {
                name = rest.to_string();
            }
            match self.set_index.get(&name) {
                Some(&s) => SurfaceTarget::Set(s),
                None => {
                    return Err(ParseError::at_line(
                        ln,
                        format!(
                            "surface {} refers to element set \"{}\", which is not defined before it",
                            self.surfaces[surface].name,
                            show(target)
                        ),
                    ));
                }
            }
        };
        self.surfaces[surface].faces.push((ln, target, face));
        Ok(())
    }

    fn finish(self) -> Result<RawMesh, ParseError> {
        let Reader {
            node_ids,
            points,
            point_lines,
            blocks,
            sets,
            surfaces,
            includes,
            ..
        } = self;
        if blocks.iter().all(|b| b.ids.is_empty())
            && let Some((line, file)) = includes.first()
        {
            return Err(ParseError::at_line(
                *line,
                format!(
                    "the file defines no elements and includes \"{file}\", which is not read; merge the included file into this one"
                ),
            ));
        }
        let node_map = IdMap::build(&node_ids).map_err(|i| {
            ParseError::at_line(
                point_lines[i],
                format!("node id {} is defined twice", node_ids[i]),
            )
        })?;
        // Element ids → global element position (in block order).
        let elem_ids: Vec<i64> = blocks.iter().flat_map(|b| b.ids.iter().copied()).collect();
        let elem_map = IdMap::build(&elem_ids).map_err(|i| {
            let mut k = i;
            let mut line = 0;
            for b in &blocks {
                if k < b.ids.len() {
                    line = b.lines[k];
                    break;
                }
                k -= b.ids.len();
            }
            ParseError::at_line(line, format!("element id {} is defined twice", elem_ids[i]))
        })?;
        // Element set tags.
        let mut tag_names = std::collections::BTreeMap::new();
        let mut elem_tags = vec![0i32; if sets.is_empty() { 0 } else { elem_ids.len() }];
        let mut next_tag = 1i32;
        for set in &sets {
            if set.internal {
                continue;
            }
            tag_names.insert(next_tag, set.name.clone());
            for &id in &set.members {
                if let Some(e) = elem_map.get(id)
                    && elem_tags[e] == 0
                {
                    elem_tags[e] = next_tag;
                }
            }
            next_tag += 1;
        }
        // Per-element (block, cell) lookup for surfaces.
        let mut owner: Vec<(u32, u32)> = Vec::with_capacity(elem_ids.len());
        for (bi, b) in blocks.iter().enumerate() {
            owner.extend((0..b.ids.len()).map(|c| (bi as u32, c as u32)));
        }
        let translate = |id: i64, ln: usize, elem: i64| -> Result<i64, ParseError> {
            node_map.get(id).map(|v| v as i64).ok_or_else(|| {
                ParseError::at_line(
                    ln,
                    format!("element {elem} refers to node {id}, which no *NODE line defines"),
                )
            })
        };

        let mut mesh = RawMesh {
            points,
            point_locations: point_lines.into_iter().map(Location::Line).collect(),
            ..Default::default()
        };
        // Surface facets, grouped by facet kind.
        let mut facet_blocks: Vec<RawBlock> = Vec::new();
        for surface in &surfaces {
            let tag = next_tag;
            next_tag += 1;
            tag_names.insert(tag, surface.name.clone());
            for (ln, target, face) in &surface.faces {
                let members: &[i64] = match target {
                    SurfaceTarget::Set(s) => &sets[*s].members,
                    SurfaceTarget::Element(id) => std::slice::from_ref(id),
                };
                for &id in members {
                    let Some(e) = elem_map.get(id) else {
                        if matches!(target, SurfaceTarget::Element(_)) {
                            return Err(ParseError::at_line(
                                *ln,
                                format!(
                                    "surface {} refers to element {id}, which is not defined",
                                    surface.name
                                ),
                            ));
                        }
                        continue;
                    };
                    let (bi, c) = owner[e];
                    let b = &blocks[bi as usize];
                    let npc = b.npc.unwrap_or(0);
                    let Some((fkind, local)) = element_face(&b.kind, *face) else {
                        return Err(ParseError::at_line(
                            *ln,
                            format!(
                                "surface {}: element {id} of type {} has no face S{face}",
                                surface.name, b.type_name
                            ),
                        ));
                    };
                    let cell = &b.nodes[c as usize * npc..(c as usize + 1) * npc];
                    let fb = match facet_blocks.iter_mut().position(|fb| fb.kind() == &fkind) {
                        Some(i) => &mut facet_blocks[i],
                        None => {
                            facet_blocks.push(RawBlock::new(fkind.clone(), local.len()));
                            facet_blocks.last_mut().expect("just pushed")
                        }
                    };
                    for &l in local {
                        fb.nodes.push(translate(cell[l], b.lines[c as usize], id)?);
                    }
                    fb.tags.push(tag);
                    fb.locations.push(Location::Line(*ln));
                }
            }
        }

        let mut first = 0;
        for b in blocks {
            let n = b.ids.len();
            let npc = b.npc.unwrap_or(0);
            let mut rb = RawBlock::new(b.kind.clone(), npc);
            rb.nodes.reserve(b.nodes.len());
            for (c, cell) in b.nodes.chunks(npc.max(1)).enumerate() {
                for &id in cell {
                    rb.nodes.push(translate(id, b.lines[c], b.ids[c])?);
                }
            }
            if !elem_tags.is_empty() {
                rb.tags = elem_tags[first..first + n].to_vec();
            }
            rb.locations = b.lines.into_iter().map(Location::Line).collect();
            first += n;
            mesh.push_block(rb);
        }
        for fb in facet_blocks {
            mesh.push_block(fb);
        }
        mesh.tag_names = tag_names;
        Ok(mesh)
    }
}

/// Read an Abaqus input file.
pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    let mut lines = Lines {
        data,
        pos: 0,
        line: 0,
    };
    let mut r = Reader::default();
    let mut mode = Mode::Skip;
    // Part handling: how many `*PART`s were opened, whether we are inside a skipped one, and
    // the names (lower case) of the first part and of its instances.
    let mut parts = 0usize;
    let mut skipping_part = false;
    let mut in_assembly = false;
    let mut first_part: Option<String> = None;
    let mut instances: Vec<String> = Vec::new();

    while let Some((ln, raw_line)) = lines.next_line() {
        let t = raw_line.trim_ascii();
        if t.is_empty() || t.starts_with(b"**") {
            continue;
        }
        if t[0] != b'*' {
            match mode {
                Mode::Skip => {}
                Mode::Node => r.node_line(ln, t)?,
                Mode::Element(b) => r.element_record(b, ln, t, &mut lines)?,
                Mode::Elset { set, generate } => r.elset_line(set, generate, ln, t)?,
                Mode::Surface(s) => r.surface_line(s, &instances, ln, t)?,
            }
            continue;
        }
        // Keyword line, possibly continued after a trailing comma.
        let mut text = String::from_utf8_lossy(t).into_owned();
        while text.trim_end().ends_with(',') {
            match lines.peek_content() {
                Some((_, next)) if !next.trim_ascii().starts_with(b"*") => {
                    let (_, l) = lines.next_line().unwrap_or_default();
                    text.push_str(&String::from_utf8_lossy(l.trim_ascii()));
                }
                _ => break,
            }
        }
        let kw = Keyword::parse(&text);
        mode = Mode::Skip;
        match kw.name.as_str() {
            "PART" => {
                parts += 1;
                if parts == 1 {
                    first_part = kw.param("NAME").map(|s| s.to_ascii_lowercase());
                } else {
                    skipping_part = true;
                }
            }
            "ENDPART" => skipping_part = false,
            "ASSEMBLY" => in_assembly = true,
            "ENDASSEMBLY" => in_assembly = false,
            "INSTANCE" => {
                let part = kw.param("PART").map(|s| s.to_ascii_lowercase());
                if part.is_some()
                    && part == first_part
                    && let Some(name) = kw.param("NAME")
                {
                    instances.push(name.to_ascii_lowercase());
                }
            }
            _ if skipping_part => {}
            "NGEN" | "NFILL" | "NCOPY" | "ELGEN" | "ELCOPY" | "NMAP" | "SYSTEM" => {
                return Err(ParseError::at_line(
                    ln,
                    format!(
                        "*{} (generating or transforming nodes or elements) is not supported; write the mesh out with explicit *NODE and *ELEMENT lines",
                        kw.name
                    ),
                ));
            }
            "INCLUDE" => r
                .includes
                .push((ln, kw.param("INPUT").unwrap_or("").to_string())),
            "NODE" if !in_assembly => mode = Mode::Node,
            "ELEMENT" if !in_assembly => {
                let Some(ty) = kw.param("TYPE").filter(|t| !t.is_empty()) else {
                    return Err(ParseError::at_line(ln, "*ELEMENT without TYPE="));
                };
                let (kind, npc) = element_kind(ty);
                let elset = kw
                    .param("ELSET")
                    .filter(|s| !s.is_empty())
                    .map(|s| r.set_named(s, false));
                r.blocks.push(ElementBlock {
                    kind,
                    type_name: ty.to_ascii_uppercase(),
                    npc,
                    nodes: Vec::new(),
                    ids: Vec::new(),
                    lines: Vec::new(),
                    elset,
                });
                mode = Mode::Element(r.blocks.len() - 1);
            }
            "ELSET" => {
                let ok = !in_assembly
                    || kw
                        .param("INSTANCE")
                        .is_some_and(|i| instances.contains(&i.to_ascii_lowercase()));
                if let (true, Some(name)) = (ok, kw.param("ELSET").filter(|s| !s.is_empty())) {
                    let set = r.set_named(name, kw.has("INTERNAL"));
                    mode = Mode::Elset {
                        set,
                        generate: kw.has("GENERATE"),
                    };
                }
            }
            "SURFACE" => {
                let ty = kw.param("TYPE").unwrap_or("ELEMENT").to_ascii_uppercase();
                if ty == "ELEMENT" {
                    let name = kw.param("NAME").unwrap_or("").to_string();
                    r.surfaces.push(Surface {
                        name,
                        faces: Vec::new(),
                    });
                    mode = Mode::Surface(r.surfaces.len() - 1);
                }
            }
            _ => {}
        }
    }
    r.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixture(name: &str) -> Vec<u8> {
        let path = format!("{}/tests/data/abaqus/{name}", env!("CARGO_MANIFEST_DIR"));
        std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
    }

    fn cells<'a>(m: &'a RawMesh, kind: &CellKind) -> Vec<&'a RawBlock> {
        m.blocks.iter().filter(|b| b.kind() == kind).collect()
    }

    fn err(text: &str) -> ParseError {
        read(text.as_bytes()).expect_err("input must be rejected")
    }

    #[test]
    fn real_naca4412_quads_with_dangling_node_sets() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/meshes/real/trixi-juliacon2024-naca4412/NACA4412_2_2D_unique.inp"
        );
        let m = read(&std::fs::read(path).unwrap()).unwrap();
        assert_eq!(m.points.len(), 14_625);
        assert_eq!(m.blocks.len(), 1);
        let b = &m.blocks[0];
        assert_eq!(b.kind(), &CellKind::Quad);
        assert_eq!(b.len(), 14_336);
        // Element 1 is "1, 1, 66, 67, 2" on line 14631.
        assert_eq!(&b.nodes[..4], &[0, 65, 66, 1]);
        assert_eq!(b.locations[0], Location::Line(14631));
        assert_eq!(m.points[1], [100.0, -0.0160337673701, 0.0]);
        assert_eq!(m.point_locations[1], Location::Line(5));
        assert!(b.tags.iter().all(|&t| t == 1));
        assert_eq!(m.tag_names[&1], "Volume1");
    }

    #[test]
    fn real_naca4412_builds_a_linear_mesh() {
        use crate::mesh::{LinearMesh, MeshOptions};
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/meshes/real/trixi-juliacon2024-naca4412/NACA4412_2_2D_unique.inp"
        );
        let raw = read(&std::fs::read(path).unwrap()).unwrap();
        let m = LinearMesh::from_raw(raw, &MeshOptions::default()).unwrap();
        assert_eq!(m.dim, 2);
        assert_eq!(m.elements.len(), 4 * 14_336);
        assert_eq!(m.coords.len(), 14_625);
        assert_eq!(m.element_tags.len(), 14_336);
        assert_eq!(m.reoriented, 0);
    }

    #[test]
    fn meshio_hexes_and_element_sets() {
        let m = read(&fixture("hsphere8.inp")).unwrap();
        assert_eq!(m.points.len(), 889);
        assert_eq!(
            m.points[100],
            [0.021650635103014272, 0.01249999998544506, 0.0]
        );
        let hexes = cells(&m, &CellKind::Hexahedron);
        assert_eq!(hexes.len(), 1);
        let b = hexes[0];
        assert_eq!(b.len(), 648);
        assert_eq!(
            &b.nodes[37 * 8..38 * 8],
            &[288, 287, 539, 514, 283, 282, 540, 515]
        );
        assert_eq!(m.tag_names[&1], "first100");
        assert_eq!(m.tag_names[&2], "all");
        assert!(b.tags[..100].iter().all(|&t| t == 1));
        assert!(b.tags[100..].iter().all(|&t| t == 2));
    }

    #[test]
    fn meshio_quads_and_beams() {
        let m = read(&fixture("ball2d.inp")).unwrap();
        assert_eq!(m.points.len(), 581);
        assert_eq!(m.points[7], [-5.983340411560994, -0.4466142415594451, 0.0]);
        let quads = cells(&m, &CellKind::Quad);
        let lines = cells(&m, &CellKind::Line);
        assert_eq!(quads[0].len(), 542);
        assert_eq!(lines[0].len(), 76);
        assert_eq!(&quads[0].nodes[20..24], &[416, 78, 530, 418]);
        assert_eq!(&lines[0].nodes[6..8], &[3, 4]);
        assert!(quads[0].tags.is_empty());
    }

    #[test]
    fn parts_assembly_surfaces_and_continuations() {
        let m = read(&fixture("features.inp")).unwrap();
        // Only the first part is read: 12 nodes with ids 11, 13, ..., 33.
        assert_eq!(m.points.len(), 12);
        assert_eq!(m.points[1], [0.5, 0.0, 0.0]);
        let idx = |ids: &[i64]| -> Vec<i64> { ids.iter().map(|id| (id - 11) / 2).collect() };
        let hexes = cells(&m, &CellKind::Hexahedron);
        assert_eq!(hexes.len(), 1);
        let h = hexes[0];
        assert_eq!(h.len(), 2);
        // Element 101 continues onto a second line.
        assert_eq!(&h.nodes[..8], &idx(&[11, 13, 19, 17, 23, 25, 31, 29])[..]);
        assert_eq!(&h.nodes[8..], &idx(&[13, 15, 21, 19, 25, 27, 33, 31])[..]);
        assert_eq!(h.locations, vec![Location::Line(19), Location::Line(22)]);
        // Sets: Solid (both), RIGHT (103); the internal set gets no tag.
        assert_eq!(h.tags, vec![1, 1]);
        assert_eq!(m.tag_names[&1], "Solid");
        assert_eq!(m.tag_names[&2], "RIGHT");
        assert_eq!(m.tag_names[&3], "Bottom");
        assert_eq!(m.tag_names[&4], "OuterX");
        assert_eq!(m.tag_names.len(), 4);
        let quads = cells(&m, &CellKind::Quad);
        assert_eq!(quads.len(), 1);
        let q = quads[0];
        let expected: Vec<i64> = [
            [11, 13, 19, 17],
            [13, 15, 21, 19],
            [15, 27, 33, 21],
            [11, 23, 25, 13],
            [13, 25, 27, 15],
        ]
        .iter()
        .flat_map(|f| idx(f))
        .collect();
        assert_eq!(q.nodes, expected);
        assert_eq!(q.tags, vec![3, 3, 4, 4, 4]);
        assert_eq!(q.locations[2], Location::Line(45));
        // No tetrahedron from the second part.
        assert!(cells(&m, &CellKind::Tetra).is_empty());
    }

    #[test]
    fn element_kinds() {
        for (ty, kind, n) in [
            ("CPS4R", CellKind::Quad, Some(4)),
            ("S4R", CellKind::Quad, Some(4)),
            ("M3D4", CellKind::Quad, Some(4)),
            ("C3D8I", CellKind::Hexahedron, Some(8)),
            ("c3d8h", CellKind::Hexahedron, Some(8)),
            ("CPE3", CellKind::Triangle, Some(3)),
            ("S3", CellKind::Triangle, Some(3)),
            ("C3D4", CellKind::Tetra, Some(4)),
            ("C3D6", CellKind::Wedge, Some(6)),
            ("C3D5", CellKind::Pyramid, Some(5)),
            ("T2D2", CellKind::Line, Some(2)),
            ("B31", CellKind::Line, Some(2)),
        ] {
            assert_eq!(element_kind(ty), (kind, n), "{ty}");
        }
        let (k, n) = element_kind("C3D20R");
        assert_eq!(n, Some(20));
        assert!(
            matches!(k, CellKind::Other(s) if s.contains("20-node hexahedron") && s.contains("C3D20R"))
        );
        assert!(
            matches!(element_kind("CPS8").0, CellKind::Other(s) if s.contains("8-node quadrilateral"))
        );
        assert!(matches!(
            element_kind("SPRINGA"),
            (CellKind::Other(_), None)
        ));
    }

    #[test]
    fn high_order_and_unknown_types_are_reported() {
        let mut text = String::from("*NODE\n");
        for i in 1..=20 {
            text.push_str(&format!("{i}, {i}, 0, 0\n"));
        }
        text.push_str("*ELEMENT, TYPE=C3D20\n1, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15,\n16, 17, 18, 19, 20\n");
        text.push_str("*ELEMENT, TYPE=SPRINGA\n2, 1, 2\n3, 3, 4\n");
        let m = read(text.as_bytes()).unwrap();
        assert_eq!(m.blocks.len(), 2);
        assert_eq!(m.blocks[0].nodes_per_cell, 20);
        assert_eq!(m.blocks[0].nodes[19], 19);
        assert_eq!(m.blocks[1].nodes_per_cell, 2);
        assert_eq!(m.blocks[1].len(), 2);
    }

    #[test]
    fn quad_surface_edges() {
        let text = "*NODE\n1,0,0\n2,1,0\n3,1,1\n4,0,1\n*ELEMENT,TYPE=CPS4\n7,1,2,3,4\n*SURFACE,NAME=top\n7,S3\n7,S4\n";
        let m = read(text.as_bytes()).unwrap();
        let lines = cells(&m, &CellKind::Line);
        assert_eq!(lines[0].nodes, vec![2, 3, 3, 0]);
        assert_eq!(lines[0].tags, vec![1, 1]);
        assert_eq!(m.tag_names[&1], "top");
        assert!(m.blocks[0].tags.is_empty());
    }

    #[test]
    fn bad_inputs_name_the_line() {
        let e = err("*NODE\n1, 0, 0\n2, x, 0\n");
        assert_eq!(e.location, Location::Line(3));
        assert!(
            e.message.contains("x coordinate of node 2"),
            "{}",
            e.message
        );

        // Too few nodes before the next keyword.
        let e = err("*NODE\n1,0,0\n*ELEMENT, TYPE=CPS4\n1, 1, 1, 1\n*NSET, NSET=a\n1\n");
        assert_eq!(e.location, Location::Line(4));
        assert!(
            e.message.contains("needs 4 node ids, found 3"),
            "{}",
            e.message
        );

        // Truncated file in the middle of an element.
        let e = err("*NODE\n1,0,0\n*ELEMENT, TYPE=C3D8\n1, 1, 1, 1, 1,");
        assert_eq!(e.location, Location::Line(4));

        let e = err("*NODE\n1,0,0\n*ELEMENT, TYPE=CPS4\n1, 1, 1, 1, 1, 1\n");
        assert_eq!(e.location, Location::Line(4));
        assert!(e.message.contains("more than 4"), "{}", e.message);

        let e = err("*NODE\n1,0,0\n*ELEMENT, TYPE=CPS4\n1, 1, 1, 1e0, 1\n");
        assert_eq!(e.location, Location::Line(4));
        assert!(e.message.contains("node id of element 1"), "{}", e.message);

        let e = err("*NODE\n1,0,0\n2,0,0\n*ELEMENT, TYPE=T2D2\n1, 1, 3\n");
        assert_eq!(e.location, Location::Line(5));
        assert!(e.message.contains("node 3"), "{}", e.message);

        let e = err("*NODE\n1,0,0\n1,0,0\n");
        assert_eq!(e.location, Location::Line(3));
        assert!(e.message.contains("defined twice"), "{}", e.message);

        let e = err("*NODE\n1,0,0\n*ELEMENT\n1, 1\n");
        assert_eq!(e.location, Location::Line(3));

        let e = err("*NODE\n1,0,0\n*ELEMENT, TYPE=CPS4\n1,1,1,1,1\n*SURFACE, NAME=s\n1, S5\n");
        assert_eq!(e.location, Location::Line(6));
        assert!(e.message.contains("no face S5"), "{}", e.message);

        let e =
            err("*NODE\n1,0,0\n*ELEMENT, TYPE=CPS4\n1,1,1,1,1\n*SURFACE, NAME=s\nnowhere, S1\n");
        assert_eq!(e.location, Location::Line(6));

        let e = err("*NODE\n1,0,0\n*ELSET, ELSET=e, GENERATE\n1, 1000000000000, 1\n");
        assert_eq!(e.location, Location::Line(4));

        let e = err("*NGEN, NSET=x\n1, 10\n");
        assert_eq!(e.location, Location::Line(1));

        let e = err("*HEADING\n*INCLUDE, INPUT=mesh.inp\n");
        assert_eq!(e.location, Location::Line(2));
        assert!(e.message.contains("mesh.inp"), "{}", e.message);
    }

    #[test]
    fn garbage_and_truncation_never_panic() {
        let data = fixture("features.inp");
        for cut in 0..data.len() {
            let _ = read(&data[..cut]);
        }
        let mut noise = data.clone();
        let mut x: u32 = 12345;
        for _ in 0..2000 {
            x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
            let i = (x as usize >> 4) % noise.len();
            noise[i] = (x >> 20) as u8;
            let _ = read(&noise);
        }
        let _ = read(&[0xff, 0xfe, b'*', b'\n', 0x80]);
        let _ = read(b"*NODE\n-9223372036854775808, 1, 2\n99999999999999999999,1\n");
        // Garbage with no keyword gives an empty mesh; judging it is `from_raw`'s job.
        assert!(read(b"not an abaqus file").unwrap().blocks.is_empty());
    }
}
