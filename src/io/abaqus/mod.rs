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
//!   T2D2/T3D2/B21/B31/... → line. The quadratic Lagrange types M3D9/M3D9R/S9R5 (9-node
//!   quadrilaterals) and C3D27 (27-node hexahedra, the types our `.inp` output writes) become
//!   [`CellKind::Lagrange`] of order 2 in [`NodeConvention::Abaqus`](crate::mesh::raw::NodeConvention::Abaqus)
//!   order, read by `HighOrderMesh::from_raw` (and refused by the linear reader). Other types
//!   (C3D20, CPS8, springs, ...) are reported as [`CellKind::Other`] with the Abaqus type name.
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
//!
//! Parts: [`read`] runs the keyword loop (parts, assembly, modes); `lines` splits lines,
//! fields and keyword parameters; `records` reads the data lines of each kept keyword;
//! `element_types` knows the element types and their faces; `finish` maps ids and builds
//! the mesh.

mod element_types;
mod finish;
mod lines;
mod records;

use crate::mesh::raw::{CellKind, ParseError, RawMesh};
use element_types::element_kind;
use lines::{Keyword, Lines};
use std::collections::HashMap;

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
mod tests;
