use super::*;
use crate::mesh::raw::CellKind;
use std::path::Path;

fn data(name: &str) -> Vec<u8> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/vtu")
        .join(name);
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn block_points() -> Vec<[f64; 3]> {
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

/// The mesh of tests/data/vtu/make_fixtures.py, as the legacy reader's ASCII twin holds it.
fn check_block(m: &RawMesh) {
    let twin = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/vtk/block_v51_ascii.vtk"
    ))
    .unwrap();
    let twin = super::super::vtk::read(&twin).unwrap();
    assert_eq!(m.points, block_points());
    assert_eq!(m.points, twin.points);
    assert_eq!(m.point_locations.len(), 27);
    assert_eq!(m.blocks.len(), 3);
    for (a, b) in m.blocks.iter().zip(&twin.blocks) {
        assert_eq!(a.kind, b.kind);
        assert_eq!(a.nodes, b.nodes);
        assert_eq!(a.tags, b.tags);
        assert_eq!(a.locations.len(), a.len());
    }
    assert_eq!(m.blocks[0].kind(), &CellKind::Hexahedron);
    assert_eq!(&m.blocks[0].nodes[..8], &[0, 1, 4, 3, 9, 10, 13, 12]);
    assert_eq!(m.blocks[0].tags, [1, 1, 1, 1, 2, 2, 2, 2]);
    assert_eq!(m.blocks[1].tags, [10, 10, 11, 11]);
    assert_eq!(m.blocks[2].nodes, [26]);
}

#[test]
fn ascii() {
    let m = read(&data("block_ascii.vtu")).unwrap();
    check_block(&m);
    // One value per line in meshio's ascii output.
    let text = String::from_utf8(data("block_ascii.vtu")).unwrap();
    let first = text
        .lines()
        .position(|l| l.contains("Name=\"Points\""))
        .unwrap()
        + 2;
    assert_eq!(m.point_locations[0], Location::Line(first));
    assert_eq!(m.point_locations[1], Location::Line(first + 3));
}

#[test]
fn binary_joint_base64() {
    check_block(&read(&data("block_binary.vtu")).unwrap());
}

#[test]
fn binary_zlib_separate_base64() {
    check_block(&read(&data("block_zlib.vtu")).unwrap());
}

#[test]
fn appended_raw_uint64() {
    let d = data("block_appended_raw.vtu");
    let m = read(&d).unwrap();
    check_block(&m);
    // Points are at offset 344 of the appended data, after an 8-byte header.
    let app = d.windows(13).position(|w| w == b"<AppendedData").unwrap();
    let us = d[app..].iter().position(|&b| b == b'_').unwrap() + app + 1;
    assert_eq!(m.point_locations[1], Location::Byte(us + 344 + 8 + 24));
}

#[test]
fn appended_base64_big_endian_zlib_blocks() {
    check_block(&read(&data("block_appended_base64_be_zlib.vtu")).unwrap());
}

#[test]
fn binary_big_endian_uint64() {
    check_block(&read(&data("block_binary_be_uint64.vtu")).unwrap());
}

#[test]
fn written_by_vtk() {
    // VTK 9.7's own writer, with <InformationKey> elements inside the Points DataArray.
    for name in [
        "block_vtk97_appended_raw_zlib.vtu",
        "block_vtk97_appended_base64.vtu",
        "block_vtk97_binary_zlib.vtu",
        "block_vtk97_ascii.vtu",
    ] {
        let m = read(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        check_block(&m);
    }
}

#[test]
fn lagrange_cells_match_vtk() {
    // Node ids as VTK 9.7's reader returns them; in the file relabelled as version 1.0
    // the order-3 hexahedron is renumbered from the VTK 8 layout.
    let expected: serde_json::Value =
        serde_json::from_slice(&data("lagrange_expected.json")).unwrap();
    for name in ["lagrange_vtk97.vtu", "lagrange_v10.vtu"] {
        let m = read(&data(name)).unwrap();
        assert_eq!(
            m.blocks[0].kind(),
            &CellKind::Lagrange {
                dim: 3,
                order: 3,
                convention: crate::mesh::raw::NodeConvention::Vtk
            }
        );
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
fn two_pieces() {
    let m = read(&data("two_pieces_appended_raw_zlib.vtu")).unwrap();
    assert_eq!(m.points.len(), 37);
    let pts = block_points();
    assert_eq!(&m.points[..27], &pts[..]);
    assert_eq!(m.blocks.len(), 3);
    assert_eq!(m.blocks[0].tags, [1, 1, 1, 1, 2, 2, 2, 2]);
    // Second piece's quads, mapped back through the point coordinates.
    let q = &m.blocks[1];
    assert_eq!(q.kind(), &CellKind::Quad);
    assert_eq!(q.tags, [10, 10, 11, 11]);
    let want = [0usize, 3, 4, 1];
    for (k, &n) in q.nodes[..4].iter().enumerate() {
        assert!(n >= 27);
        assert_eq!(m.points[n as usize], pts[want[k]]);
    }
    assert_eq!(m.points[m.blocks[2].nodes[0] as usize], pts[26]);
}

#[test]
fn errors() {
    let text = String::from_utf8(data("block_ascii.vtu")).unwrap();
    // A bad number names its line.
    let line = text
        .lines()
        .position(|l| l.contains("Name=\"connectivity\""))
        .unwrap()
        + 4;
    let bad = text.replacen("\n1\n4\n", "\n1\nfour\n", 1);
    let e = read(bad.as_bytes()).unwrap_err();
    assert_eq!(e.location, Location::Line(line), "{e}");
    assert!(e.message.contains("\"four\""), "{e}");
    // Wrong NumberOfPoints.
    let bad = text.replace("NumberOfPoints=\"27\"", "NumberOfPoints=\"28\"");
    let e = read(bad.as_bytes()).unwrap_err();
    assert!(e.message.contains("expected 84"), "{e}");
    // Huge NumberOfCells fails without allocating.
    let bad = text.replace("NumberOfCells=\"13\"", "NumberOfCells=\"999999999999999\"");
    assert!(read(bad.as_bytes()).is_err());
    // Other dataset types.
    let e = read(b"<VTKFile type=\"PolyData\"><PolyData/></VTKFile>").unwrap_err();
    assert!(e.message.contains("PolyData"), "{e}");
    // Broken XML.
    let e = read(b"<VTKFile type=\"UnstructuredGrid\"><Piece NumberOfPoints=\"1\" </VTKFile>")
        .unwrap_err();
    assert_eq!(e.location, Location::Line(1));
    // Truncated raw appended data names a byte offset.
    let d = data("block_appended_raw.vtu");
    let e = read(&d[..d.len() - 700]).unwrap_err();
    assert!(matches!(e.location, Location::Byte(_)), "{e}");
    // Corrupt base64.
    let b = String::from_utf8(data("block_binary.vtu")).unwrap();
    let bad = b.replacen("iAIAAAAAAAAAAAAA", "iAIAAAAAAAA*AAAA", 1);
    let e = read(bad.as_bytes()).unwrap_err();
    assert!(e.message.contains("base64"), "{e}");
    // Corrupt compressed block.
    let z = String::from_utf8(data("block_zlib.vtu")).unwrap();
    let i = z.find("format=\"binary\">").unwrap() + 40;
    let mut bad = z.into_bytes();
    bad[i] = if bad[i] == b'A' { b'B' } else { b'A' };
    assert!(read(&bad).is_err());
    // Offsets that decrease.
    let bad = text.replacen(
        "<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n8\n16\n",
        "<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n16\n8\n",
        1,
    );
    assert_ne!(bad, text);
    let e = read(bad.as_bytes()).unwrap_err();
    assert!(e.message.contains("offset 1"), "{e}");
}

#[test]
fn garbage_never_panics() {
    let mut inputs: Vec<Vec<u8>> =
        vec![Vec::new(), b"\xff\xfe<".to_vec(), b"<AppendedData".to_vec()];
    for name in [
        "block_ascii.vtu",
        "block_binary.vtu",
        "block_zlib.vtu",
        "block_vtk97_appended_raw_zlib.vtu",
        "block_appended_raw.vtu",
        "block_appended_base64_be_zlib.vtu",
        "two_pieces_appended_raw_zlib.vtu",
    ] {
        let d = data(name);
        for cut in (0..d.len()).step_by(11) {
            inputs.push(d[..cut].to_vec());
        }
        for i in (0..d.len()).step_by(5) {
            let mut x = d.clone();
            x[i] = x[i].wrapping_add(0x31);
            inputs.push(x);
        }
    }
    for d in inputs {
        let _ = read(&d);
    }
}
