use super::*;
use crate::mesh::raw::CellKind;

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
