use super::*;
use crate::mesh::raw::{CellKind, NodeConvention};
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
