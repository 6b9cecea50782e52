//! The tag-keeping mode ([`read_keeping_tags`]) and the offset-indexed reader ([`stream`])
//! against the serial reader's [`read`] of the same file, and against hand-written files
//! whose tags are known.

use super::super::stream::Head;
use super::*;
use crate::mesh::raw::{CellKind, Location, RawMesh};
use std::collections::{HashMap, HashSet};
use std::path::PathBuf;

/// A binary MSH 4.1 file in either byte order and `size_t` width: two stacked hexes (entity 1,
/// physical 9) and their bottom quad (entity 1 of dimension 2, physical 7), sparse node tags
/// 101 … 112, element tags 1 (quad), 2 and 3 (hexes).
fn tiny_binary(big_endian: bool, size_t: usize) -> Vec<u8> {
    let mut o: Vec<u8> = Vec::new();
    let int = |o: &mut Vec<u8>, v: i32| {
        o.extend(if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        })
    };
    let size = |o: &mut Vec<u8>, v: u64| match (size_t, big_endian) {
        (4, true) => o.extend((v as u32).to_be_bytes()),
        (4, false) => o.extend((v as u32).to_le_bytes()),
        (_, true) => o.extend(v.to_be_bytes()),
        (_, false) => o.extend(v.to_le_bytes()),
    };
    let real = |o: &mut Vec<u8>, v: f64| {
        o.extend(if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        })
    };
    o.extend(format!("$MeshFormat\n4.1 1 {size_t}\n").as_bytes());
    int(&mut o, 1);
    o.extend(b"\n$EndMeshFormat\n$PhysicalNames\n2\n2 7 \"bottom\"\n3 9 \"solid\"\n$EndPhysicalNames\n$Entities\n");
    for n in [0, 0, 1, 1] {
        size(&mut o, n);
    }
    for phys in [7, 9] {
        int(&mut o, 1);
        for _ in 0..6 {
            real(&mut o, 0.0);
        }
        size(&mut o, 1);
        int(&mut o, phys);
        size(&mut o, 0);
    }
    o.extend(b"\n$EndEntities\n$Nodes\n");
    for n in [1, 12, 101, 112] {
        size(&mut o, n);
    }
    for v in [3, 1, 0] {
        int(&mut o, v);
    }
    size(&mut o, 12);
    for t in 101..=112 {
        size(&mut o, t);
    }
    for i in 0..12 {
        for x in [(i % 2) as f64, ((i / 2) % 2) as f64, (i / 4) as f64] {
            real(&mut o, x);
        }
    }
    o.extend(b"\n$EndNodes\n$Elements\n");
    for n in [2, 3, 1, 3] {
        size(&mut o, n);
    }
    for v in [2, 1, 3] {
        int(&mut o, v);
    }
    size(&mut o, 1);
    for t in [1, 101, 102, 104, 103] {
        size(&mut o, t);
    }
    for v in [3, 1, 5] {
        int(&mut o, v);
    }
    size(&mut o, 2);
    for (tag, base) in [(2, 101), (3, 105)] {
        size(&mut o, tag);
        for k in [0, 1, 3, 2, 4, 5, 7, 6] {
            size(&mut o, base + k);
        }
    }
    o.extend(b"\n$EndElements\n");
    o
}

fn scratch(name: &str, data: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("polyspline-gmsh-modes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, data).unwrap();
    path
}

/// Each cell of Gmsh type `ty` as the stream reads it: physical tag and corner coordinates.
fn streamed_cells(path: &std::path::Path, ty: i32) -> Vec<(i32, Vec<[f64; 3]>)> {
    let mut ix = Head::open(path).unwrap().index().unwrap();
    let mut cells = Vec::new();
    ix.for_each(ty, |_, p, v| cells.push((p, v.to_vec())))
        .unwrap();
    let have: HashSet<u64> = cells.iter().flat_map(|c| c.1.clone()).collect();
    let (tags, points) = ix.coordinates(&have).unwrap();
    let at: HashMap<u64, [f64; 3]> = tags.into_iter().zip(points).collect();
    cells
        .into_iter()
        .map(|(p, v)| (p, v.iter().map(|t| at[t]).collect()))
        .collect()
}

/// Each cell of `kind` as the serial reader reads it.
fn serial_cells(m: &RawMesh, kind: &CellKind) -> Vec<(i32, Vec<[f64; 3]>)> {
    let b = block(m, kind);
    (0..b.len())
        .map(|i| {
            let nodes = &b.nodes[i * b.nodes_per_cell..(i + 1) * b.nodes_per_cell];
            let tag = b.tags.get(i).copied().unwrap_or(0);
            (tag, nodes.iter().map(|&n| m.points[n as usize]).collect())
        })
        .collect()
}

#[test]
fn the_stream_reads_what_the_serial_reader_reads_in_every_byte_order_and_width() {
    let mut files = vec![("box_41_bin.msh".to_string(), fixture("box_41_bin.msh"))];
    files.push(("ball_41_bin.msh".into(), fixture("ball_41_bin.msh")));
    for (be, sz) in [(false, 8), (true, 8), (false, 4), (true, 4)] {
        files.push((format!("tiny_{be}_{sz}.msh"), tiny_binary(be, sz)));
    }
    for (name, data) in files {
        let serial = parse(&data);
        let path = scratch(&name, &data);
        for (ty, kind) in [
            (5, CellKind::Hexahedron),
            (3, CellKind::Quad),
            (1, CellKind::Line),
        ] {
            if serial.count(&kind) == 0 {
                continue;
            }
            assert_eq!(
                streamed_cells(&path, ty),
                serial_cells(&serial, &kind),
                "{name} type {ty}"
            );
        }
        let head = Head::open(&path).unwrap();
        assert_eq!(head.header.tag_names, serial.tag_names, "{name}");
        // A run of elements at its offsets is that run of the streamed pass.
        let mut ix = head.index().unwrap();
        let (mut all, mut run) = (Vec::new(), Vec::new());
        let ty = if serial.count(&CellKind::Hexahedron) > 0 {
            5
        } else {
            3
        };
        ix.for_each(ty, |g, p, v| all.push((g, p, v.to_vec())))
            .unwrap();
        ix.range(ty, 1, 2, |g, p, v| run.push((g, p, v.to_vec())))
            .unwrap();
        assert_eq!(run, all[1..2], "{name}");
    }
    // The tiny file's tags: the quad on physical 7, the hexes on 9.
    let tiny = scratch("tiny.msh", &tiny_binary(true, 4));
    assert_eq!(streamed_cells(&tiny, 3)[0].0, 7);
    assert_eq!(streamed_cells(&tiny, 5)[1].0, 9);
}

#[test]
fn the_stream_names_the_byte_where_a_file_ends_or_lacks_a_node() {
    let data = tiny_binary(false, 8);
    let end = data
        .windows(13)
        .position(|w| w == b"\n$EndElements")
        .unwrap();
    // Cut inside the hexes' records: found while indexing, at the block's first record.
    let cut = scratch("cut.msh", &data[..end - 8]);
    let e = Head::open(&cut).unwrap().index().err().unwrap();
    assert!(matches!(e.location, Location::Byte(_)), "{e}");
    assert!(e.to_string().contains("end of the file"), "{e}");
    // A node no block defines.
    let path = scratch("tiny_le.msh", &data);
    let mut ix = Head::open(&path).unwrap().index().unwrap();
    let e = ix.coordinates(&HashSet::from([101, 7])).err().unwrap();
    assert!(e.to_string().contains("not defined in $Nodes"), "{e}");
    // ASCII is refused by the index, naming the variant.
    let ascii = scratch("box_41_ascii.msh", &fixture("box_41_ascii.msh"));
    let e = Head::open(&ascii).unwrap().index().err().unwrap();
    assert!(e.to_string().contains("ASCII MSH 4.1"), "{e}");
}

/// One part of a two-part mesh in Gmsh's layout, with entity 5 (partition 2) a ghost entity:
/// hex 2 on volume 4 (partition 1, physical 9 through its parent), ghost hex 3 on volume 5
/// naming nodes this part does not hold, boundary quad 1 on surface 6 (physical 7).
const PART: &str = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n2\n2 7 \"wall\"\n3 9 \"fluid\"\n$EndPhysicalNames\n$Entities\n0 0 1 1\n1 0 0 0 1 1 0 1 7 0\n1 0 0 0 1 1 2 1 9 0\n$EndEntities\n$PartitionedEntities\n2\n1\n5 2\n0 0 1 2\n6 2 1 1 1 0 0 0 1 1 0 1 7 0\n4 3 1 1 1 0 0 0 1 1 1 0 0\n5 3 1 1 2 0 0 1 1 1 2 0 0\n$EndPartitionedEntities\n$Nodes\n1 8 11 18\n3 4 0 8\n11\n12\n13\n14\n15\n16\n17\n18\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n0 0 1\n1 0 1\n0 1 1\n1 1 1\n$EndNodes\n$Elements\n3 3 1 3\n2 6 3 1\n1 11 12 14 13\n3 4 5 1\n2 11 12 14 13 15 16 18 17\n3 5 5 1\n3 15 16 18 17 21 22 24 23\n$EndElements\n";

#[test]
fn keeping_tags_gives_the_files_numbering_entities_and_ghosts() {
    let m = read_keeping_tags(PART.as_bytes()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(m.header.entities.partitions(), Some(2));
    assert!(m.header.entities.is_ghost(5) && !m.header.entities.is_ghost(4));
    assert_eq!(m.node_tags, (11..=18).collect::<Vec<u64>>());
    assert_eq!(m.points[7], [1.0, 1.0, 1.0]);
    let types: Vec<i64> = m.blocks.iter().map(|b| b.gmsh_type).collect();
    assert_eq!(types, [3, 5]);
    let (quads, hexes) = (&m.blocks[0], &m.blocks[1]);
    assert_eq!(quads.element_tags, [1]);
    assert_eq!(
        (quads.entities.as_slice(), quads.physical.as_slice()),
        (&[6][..], &[7][..])
    );
    assert_eq!(quads.nodes, [11, 12, 14, 13]);
    assert_eq!(hexes.element_tags, [2, 3]);
    assert_eq!(hexes.entities, [4, 5]);
    // Physical tags as the serial reader gives them: the parent volume's.
    let serial_tags = {
        // The serial reader refuses the ghost hex's undefined nodes; drop that block.
        let cut = PART.replace("3 3 1 3\n", "2 2 1 2\n");
        let cut = cut.replace("3 5 5 1\n3 15 16 18 17 21 22 24 23\n", "");
        let s = parse(cut.as_bytes());
        serial_cells(&s, &CellKind::Hexahedron)[0].0
    };
    assert_eq!(hexes.physical, [serial_tags, serial_tags]);
    assert_eq!(serial_tags, 9);
    assert_eq!(hexes.nodes[8..], [15, 16, 18, 17, 21, 22, 24, 23]);
    // MSH 2 has no element tags to keep.
    let e = read_keeping_tags(&fixture("box_22_ascii.msh"))
        .err()
        .unwrap();
    assert!(e.message.contains("MSH 4"), "{e}");
}
