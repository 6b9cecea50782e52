use super::*;
use crate::mesh::raw::{Location, RawBlock};

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
    let quadratic = |dim| CellKind::Lagrange {
        dim,
        order: 2,
        convention: crate::mesh::raw::NodeConvention::Abaqus,
    };
    for (ty, dim, n) in [
        ("M3D9", 2, 9),
        ("s9r5", 2, 9),
        ("M3D9R", 2, 9),
        ("C3D27", 3, 27),
    ] {
        assert_eq!(element_kind(ty), (quadratic(dim), Some(n)), "{ty}");
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

    let e = err("*NODE\n1,0,0\n*ELEMENT, TYPE=CPS4\n1,1,1,1,1\n*SURFACE, NAME=s\nnowhere, S1\n");
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
