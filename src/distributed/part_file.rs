//! One part of a Gmsh partitioned MSH 4 mesh (`NAME_<k>.msh`, as Gmsh writes them with
//! `Mesh.PartitionSplitMeshFiles=1`), ASCII or binary, parsed whole.
//!
//! Input: a part's path. Outputs: whether a file is such a part ([`is_partitioned`]); the
//! names of all the parts and the physical names, from one part's header ([`part_names`]);
//! and a part's hexahedra, quadrilaterals and lines (Gmsh tag, physical tag as the serial
//! reader assigns it, whether the element's entity is one of Gmsh's ghost entities, node
//! tags) and its nodes (tags, coordinates) (`read_part`). [`super::read_parts`] distributes
//! the parts over the ranks.
//!
//! Parsing is the MSH parser family's ([`crate::io::gmsh::header_tags`] for the header,
//! `io::gmsh::read_keeping_tags` for the part, in the file's numbering, with the ghost
//! entities of `$PartitionedEntities`); this module adds what is distributed: which files make
//! the set, which element types a partitioned input may hold, and the ghost mark per cell.
//! Invariant: a part's cells carry the physical tags [`crate::io::gmsh::read`] gives them.

use crate::io::gmsh::{HeaderTags, header_tags, read_keeping_tags};
use crate::mesh::raw::{Location, ParseError};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn err(what: impl Into<String>) -> ParseError {
    ParseError::new(Location::File, what)
}

/// Whether the MSH file at `path` is a Gmsh partition (`$PartitionedEntities` before
/// `$Nodes`); false for any other file and for an unreadable one (its reader reports that).
pub fn is_partitioned(path: &Path) -> bool {
    use std::io::BufRead;
    let Ok(f) = std::fs::File::open(path) else {
        return false;
    };
    let mut r = std::io::BufReader::new(f);
    let mut buf = Vec::new();
    for _ in 0..100_000 {
        buf.clear();
        match r.read_until(b'\n', &mut buf) {
            Ok(0) | Err(_) => return false,
            Ok(_) => {}
        }
        match buf.trim_ascii() {
            b"$PartitionedEntities" => return true,
            b"$Nodes" | b"$Elements" => return false,
            _ => {}
        }
    }
    false
}

/// Elements of one Gmsh type read from a part: Gmsh tag, physical tag, whether its entity
/// is a ghost entity, and node tags.
#[derive(Default)]
pub(super) struct Records {
    pub items: Vec<(u64, i32, bool)>,
    pub nodes: Vec<u64>,
}

/// What a rank reads of one part: its hexahedra, quadrilaterals and lines, and its nodes.
#[derive(Default)]
pub(super) struct PartData {
    /// The number of partitions its header declares.
    pub partitions: u64,
    pub hexes: Records,
    pub quads: Records,
    pub lines: Records,
    pub node_tags: Vec<u64>,
    pub node_coords: Vec<[f64; 3]>,
    /// The part's `$Periodic` links (Gmsh writes the whole mesh's into every part).
    pub periodic: Vec<crate::mesh::raw::DeclaredPeriodic>,
}

/// Check that a part's header is that of a Gmsh partition: MSH 4 with
/// `$PartitionedEntities`; returns its number of partitions.
fn partitions_of(head: &HeaderTags) -> Result<u64, ParseError> {
    if !head.is_msh4() {
        return Err(err(format!(
            "partitioned input must be MSH 4.1; this part is {}",
            head.describe_format()
        )));
    }
    head.entities.partitions().ok_or_else(|| {
        err(
            "not a Gmsh partition (no $PartitionedEntities): give one part of a partitioned mesh (NAME_1.msh … NAME_K.msh), or a single binary MSH 4.1 file",
        )
    })
}

/// Parse one part (see [`PartData`]).
pub(super) fn read_part(path: &Path) -> Result<PartData, ParseError> {
    let partitions = partitions_of(&header_tags(&head_of(path)?)?)?;
    let bytes = std::fs::read(path).map_err(|e| err(format!("read failed: {e}")))?;
    let m = read_keeping_tags(&bytes)?;
    drop(bytes);
    let mut d = PartData {
        partitions,
        node_tags: m.node_tags,
        node_coords: m.points,
        periodic: m.periodic,
        ..PartData::default()
    };
    let entities = &m.header.entities;
    for b in m.blocks {
        let into = match b.gmsh_type {
            1 => &mut d.lines,
            3 => &mut d.quads,
            5 => &mut d.hexes,
            15 => continue,
            kind => {
                return Err(err(format!(
                    "element type {kind} in a partitioned input: polyspline curves linear quad (2D) and hex (3D) meshes"
                )));
            }
        };
        into.items.extend(
            (b.element_tags.iter().zip(&b.physical).zip(&b.entities))
                .map(|((&t, &p), &e)| (t, p, entities.is_ghost(e))),
        );
        into.nodes.extend(b.nodes);
    }
    Ok(d)
}

/// The sections before `$Nodes` of the file at `path` (read line by line, not the whole file).
fn head_of(path: &Path) -> Result<Vec<u8>, ParseError> {
    use std::io::BufRead;
    let f = std::fs::File::open(path).map_err(|e| err(format!("read failed: {e}")))?;
    let mut r = std::io::BufReader::new(f);
    let mut head = Vec::new();
    let mut buf = Vec::new();
    loop {
        buf.clear();
        if r.read_until(b'\n', &mut buf)
            .map_err(|e| err(format!("read failed: {e}")))?
            == 0
        {
            return Err(err("no $Nodes section"));
        }
        if buf.trim_ascii() == b"$Nodes" {
            return Ok(head);
        }
        head.extend_from_slice(&buf);
    }
}

/// The names `NAME_1.EXT … NAME_K.EXT` of the parts of the mesh that `path` (`NAME_<k>.EXT`)
/// is a part of, K from its `$PartitionedEntities`, and the names of its physical groups
/// (every rank reads them from this part, whether it reads any part or not).
pub fn part_names(path: &Path) -> Result<(Vec<PathBuf>, BTreeMap<i32, String>), ParseError> {
    let head = header_tags(&head_of(path)?)?;
    let k = partitions_of(&head)?;
    let tag_names = head.tag_names;
    let stem = path.file_stem().unwrap_or_default().to_string_lossy();
    let base = stem
        .rsplit_once('_')
        .filter(|(_, n)| !n.is_empty() && n.bytes().all(|c| c.is_ascii_digit()))
        .map(|(b, _)| b.to_string())
        .ok_or_else(|| {
            err("a partitioned input is named as Gmsh names its parts, NAME_<k>.msh (k = 1 … the number of partitions)")
        })?;
    if k == 0 || k > 1 << 20 {
        return Err(err(format!("{k} partitions")));
    }
    let base = path.with_file_name(base);
    let parts = super::write_parts::part_paths(
        &base.with_extension(path.extension().unwrap_or_default()),
        k as usize,
    );
    if !parts.iter().any(|p| p.file_name() == path.file_name()) {
        return Err(err(format!(
            "this part's number is not among the {k} partitions its header declares"
        )));
    }
    if let Some(missing) = parts.iter().find(|p| !p.is_file()) {
        return Err(err(format!(
            "part {} of the {k} partitions is missing",
            missing.display()
        )));
    }
    Ok((parts, tag_names))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A two-part ASCII set in Gmsh's layout: one hexahedron per part (tags 2 and 3, tag 1 a
    /// boundary quad of part 1), the shared face's nodes in both parts.
    fn part(k: usize) -> String {
        let (tag, nodes, quad) = if k == 1 {
            (2, [1, 2, 3, 4, 5, 6, 7, 8], "2 6 3 1\n1 1 2 3 4\n")
        } else {
            (3, [5, 6, 7, 8, 9, 10, 11, 12], "")
        };
        let mut s = String::from(
            "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n2\n2 7 \"wall\"\n3 9 \"fluid\"\n$EndPhysicalNames\n$Entities\n0 0 1 1\n1 0 0 0 1 1 0 1 7 0\n1 0 0 0 1 1 2 1 9 0\n$EndEntities\n$PartitionedEntities\n2\n0\n0 0 1 2\n6 2 1 1 1 0 0 0 1 1 0 1 7 0\n4 3 1 1 1 0 0 0 1 1 1 1 9 0\n5 3 1 1 2 0 0 1 1 1 2 1 9 0\n$EndPartitionedEntities\n",
        );
        let z0 = if k == 1 { 0.0 } else { 1.0 };
        s += &format!("$Nodes\n1 8 {} {}\n3 {} 0 8\n", nodes[0], nodes[7], 3 + k);
        for n in nodes {
            s += &format!("{n}\n");
        }
        for i in 0..8 {
            let (x, y, z) = ((i % 2) as f64, ((i / 2) % 2) as f64, z0 + (i / 4) as f64);
            s += &format!("{x} {y} {z}\n");
        }
        let blocks = if quad.is_empty() { 1 } else { 2 };
        s += &format!("$EndNodes\n$Elements\n{blocks} {blocks} 1 3\n{quad}");
        s += &format!("3 {} 5 1\n{tag}", 3 + k);
        for n in nodes {
            s += &format!(" {n}");
        }
        s += "\n$EndElements\n";
        s
    }

    #[test]
    fn a_part_is_read_with_its_tags_names_and_physical_groups() {
        let dir = std::env::temp_dir().join(format!("polyspline-parts-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for k in 1..=2 {
            std::fs::write(dir.join(format!("m_{k}.msh")), part(k)).unwrap();
        }
        let first = dir.join("m_2.msh");
        assert!(is_partitioned(&first));
        let (names, tags) = part_names(&first).unwrap();
        assert_eq!(names, vec![dir.join("m_1.msh"), dir.join("m_2.msh")]);
        assert_eq!(tags.get(&9).map(String::as_str), Some("fluid"));
        let p = read_part(&names[0]).unwrap();
        assert_eq!(p.partitions, 2);
        assert_eq!(p.hexes.items, vec![(2, 9, false)]);
        assert_eq!(p.hexes.nodes, (1..=8).collect::<Vec<u64>>());
        assert_eq!(p.quads.items, vec![(1, 7, false)]);
        assert_eq!(p.node_tags.len(), 8);
        assert_eq!(p.node_coords[7], [1.0, 1.0, 1.0]);
        // A missing part, and a name without the part number.
        std::fs::remove_file(&names[0]).unwrap();
        let e = part_names(&first).err().unwrap().to_string();
        assert!(e.contains("missing") && !e.contains('\n'), "{e}");
        std::fs::write(dir.join("plain.msh"), part(2)).unwrap();
        let e = part_names(&dir.join("plain.msh"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("NAME_<k>"), "{e}");
    }
}
