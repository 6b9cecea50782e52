//! Unit tests of the MSH reader: files written by Gmsh and meshio, real files, hand-written
//! variants; malformed input in [`bad_input`].

use super::element_types::{ELEMENT_TYPES, element_type};
use super::*;
use crate::mesh::raw::{CellKind, NodeConvention, RawBlock};
use crate::mesh::{LinearMesh, MeshOptions};
use std::collections::BTreeMap;

fn fixture(name: &str) -> Vec<u8> {
    let path = format!("{}/tests/data/gmsh/{name}", env!("CARGO_MANIFEST_DIR"));
    std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

fn real(name: &str) -> Vec<u8> {
    let path = format!("{}/meshes/real/{name}", env!("CARGO_MANIFEST_DIR"));
    std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

fn parse(data: &[u8]) -> RawMesh {
    read(data).unwrap_or_else(|e| panic!("{e}"))
}

fn parse_str(s: &str) -> Result<RawMesh, ParseError> {
    read(s.as_bytes())
}

fn count(m: &RawMesh, kind: &CellKind) -> usize {
    m.count(kind)
}

fn block<'m>(m: &'m RawMesh, kind: &CellKind) -> &'m RawBlock {
    m.block(kind).unwrap_or_else(|| panic!("no {kind:?} block"))
}

type Cell = (i32, Vec<[i64; 3]>);

/// Coordinates quantised to 1e-10: ASCII files hold 16 significant digits, binary ones the
/// exact doubles.
fn q(p: &[f64; 3]) -> [i64; 3] {
    p.map(|x| (x * 1e10).round() as i64)
}

/// Cells by kind as (tag, node coordinates), sorted: independent of node numbering and of
/// cell order, so files written in different versions can be compared.
fn canonical(m: &RawMesh) -> BTreeMap<String, Vec<Cell>> {
    let mut out: BTreeMap<String, Vec<Cell>> = BTreeMap::new();
    for b in &m.blocks {
        let cells = out.entry(format!("{:?}", b.kind())).or_default();
        for c in 0..b.len() {
            let nodes = b.nodes[c * b.nodes_per_cell..(c + 1) * b.nodes_per_cell]
                .iter()
                .map(|&v| q(&m.points[v as usize]))
                .collect();
            cells.push((b.tags.get(c).copied().unwrap_or(0), nodes));
        }
    }
    for cells in out.values_mut() {
        cells.sort();
    }
    out
}

fn sorted_points(m: &RawMesh) -> Vec<[i64; 3]> {
    let mut p: Vec<_> = m.points.iter().map(q).collect();
    p.sort();
    p
}

fn linear(m: RawMesh) -> Result<LinearMesh, ParseError> {
    LinearMesh::from_raw(m, &MeshOptions::default())
}

// ---- fixtures written by gmsh / meshio ----

#[test]
fn box_variants_agree() {
    let reference = parse(&fixture("box_22_ascii.msh"));
    assert_eq!(reference.points.len(), 64);
    assert_eq!(count(&reference, &CellKind::Hexahedron), 27);
    assert_eq!(count(&reference, &CellKind::Quad), 18);
    assert_eq!(reference.blocks.len(), 2);
    let names: Vec<_> = reference
        .tag_names
        .iter()
        .map(|(k, v)| (*k, v.as_str()))
        .collect();
    assert_eq!(names, [(1, "block"), (10, "bottom"), (11, "top face")]);
    // Physical groups: every hex in 1; quads at z = 0 in 10, at z = 1.5 in 11.
    let hex = block(&reference, &CellKind::Hexahedron);
    assert!(hex.tags.iter().all(|&t| t == 1));
    let quads = block(&reference, &CellKind::Quad);
    for c in 0..quads.len() {
        let z: Vec<f64> = quads.nodes[4 * c..4 * c + 4]
            .iter()
            .map(|&v| reference.points[v as usize][2])
            .collect();
        let want = if z.iter().all(|&z| z == 0.0) {
            10
        } else {
            assert!(z.iter().all(|&z| z == 1.5), "{z:?}");
            11
        };
        assert_eq!(quads.tags[c], want);
    }
    // First hex of the 2.2 file: "99 5 2 1 1 1 33 10 ... " -> check its first corner.
    assert_eq!(hex.locations[0], Location::Line(97));
    let canon = canonical(&reference);
    let points = sorted_points(&reference);
    assert!(points.contains(&q(&[1.0, 1.0, 1.5])));

    for name in [
        "box_22_bin.msh",
        "box_1_ascii.msh",
        "box_40_ascii.msh",
        "box_41_ascii.msh",
        "box_41_bin.msh",
        "partitioned_41.msh",
    ] {
        let m = parse(&fixture(name));
        assert_eq!(m.points.len(), 64, "{name}");
        assert_eq!(m.point_locations.len(), 64, "{name}");
        assert_eq!(sorted_points(&m), points, "{name}");
        assert_eq!(canonical(&m), canon, "{name}");
        if name != "box_1_ascii.msh" {
            assert_eq!(m.tag_names, reference.tag_names, "{name}");
        }
        for b in &m.blocks {
            assert_eq!(b.locations.len(), b.len(), "{name}");
        }
    }

    // Same writer, same order: ASCII and binary twins agree exactly.
    for (a, b) in [
        ("box_22_ascii.msh", "box_22_bin.msh"),
        ("box_41_ascii.msh", "box_41_bin.msh"),
    ] {
        let (a, b) = (parse(&fixture(a)), parse(&fixture(b)));
        let qa: Vec<_> = a.points.iter().map(q).collect();
        let qb: Vec<_> = b.points.iter().map(q).collect();
        assert_eq!(qa, qb);
        for (x, y) in a.blocks.iter().zip(&b.blocks) {
            assert_eq!(x.kind, y.kind);
            assert_eq!(x.nodes, y.nodes);
            assert_eq!(x.tags, y.tags);
        }
        assert!(matches!(a.point_locations[0], Location::Line(_)));
        assert!(matches!(b.point_locations[0], Location::Byte(_)));
    }

    let lin = linear(reference).unwrap();
    assert_eq!(lin.dim, 3);
    assert_eq!(lin.n_elements(), 27);
    assert_eq!(lin.n_vertices(), 64);
    assert_eq!(lin.facet_tags.len(), 18);
}

#[test]
fn binary_locations_point_at_records() {
    // In the 2.2 binary box the first node record starts right after "$Nodes\n64\n".
    let data = fixture("box_22_bin.msh");
    let m = parse(&data);
    let Location::Byte(at) = m.point_locations[0] else {
        panic!()
    };
    let head = b"$Nodes\n64\n";
    let start = data.windows(head.len()).position(|w| w == head).unwrap() + head.len();
    assert_eq!(at, start);
    assert_eq!(i32::from_le_bytes(data[at..at + 4].try_into().unwrap()), 1);
    let x = f64::from_le_bytes(data[at + 4..at + 12].try_into().unwrap());
    assert_eq!(x, m.points[0][0]);
}

#[test]
fn ball_rewritten_in_binary_matches_the_ascii_original() {
    let original = parse(&real("dealii/unstructured_refined_ball.msh"));
    let canon = canonical(&original);
    for name in ["ball_22_bin.msh", "ball_41_bin.msh"] {
        let m = parse(&fixture(name));
        assert_eq!(m.points.len(), 581, "{name}");
        assert_eq!(sorted_points(&m), sorted_points(&original), "{name}");
        assert_eq!(canonical(&m), canon, "{name}");
        let lin = linear(m).unwrap();
        assert_eq!((lin.dim, lin.n_elements(), lin.n_vertices()), (2, 542, 581));
    }
}

#[test]
fn meshio_binary_41_matches_the_mfem_original() {
    // The MFEM file's vertices and elements, read directly.
    let text = String::from_utf8(real("mfem/cylinder-hex.mesh")).unwrap();
    let lines: Vec<&str> = text.lines().map(str::trim).collect();
    let e = lines.iter().position(|l| *l == "elements").unwrap();
    let n: usize = lines[e + 1].parse().unwrap();
    let elements: Vec<Vec<i64>> = (0..n)
        .map(|k| {
            lines[e + 2 + k]
                .split_whitespace()
                .skip(2)
                .map(|t| t.parse().unwrap())
                .collect()
        })
        .collect();
    let v = lines.iter().position(|l| *l == "vertices").unwrap();
    let nv: usize = lines[v + 1].parse().unwrap();
    let vertices: Vec<[f64; 3]> = (0..nv)
        .map(|k| {
            let x: Vec<f64> = lines[v + 3 + k]
                .split_whitespace()
                .map(|t| t.parse().unwrap())
                .collect();
            [x[0], x[1], x[2]]
        })
        .collect();

    let m = parse(&fixture("cylinder_meshio_41_bin.msh"));
    assert_eq!(m.points, vertices);
    assert_eq!(m.blocks.len(), 1);
    let hex = block(&m, &CellKind::Hexahedron);
    assert_eq!(hex.len(), 252);
    assert_eq!(hex.nodes, elements.concat());
    // meshio writes no $Entities, so there are no physical groups.
    assert!(hex.tags.is_empty());
}

#[test]
fn tetrahedra_are_reported() {
    let m = parse(&fixture("tets_41.msh"));
    assert_eq!(count(&m, &CellKind::Tetra), 1140);
    assert_eq!(count(&m, &CellKind::Triangle), 540);
    assert_eq!(m.points.len(), 341);
    let e = linear(m).unwrap_err();
    assert!(e.message.contains("1140 tetrahedra"), "{}", e.message);
}

#[test]
fn high_order_cells_are_named() {
    let m = parse(&fixture("quad9_22.msh"));
    let q9 = CellKind::Lagrange {
        dim: 2,
        order: 2,
        convention: NodeConvention::Gmsh,
    };
    let l3 = CellKind::Lagrange {
        dim: 1,
        order: 2,
        convention: NodeConvention::Gmsh,
    };
    assert_eq!(count(&m, &q9), 4);
    assert_eq!(count(&m, &l3), 8);
    assert_eq!(count(&m, &CellKind::Vertex), 4);
    assert_eq!(block(&m, &q9).nodes_per_cell, 9);
    // Centre node (index 8) of the first quad9 is the mean of its corners.
    let b = block(&m, &q9);
    let p = |i: usize| m.points[b.nodes[i] as usize];
    for d in 0..2 {
        let mean = (0..4).map(|i| p(i)[d]).sum::<f64>() / 4.0;
        assert!((p(8)[d] - mean).abs() < 1e-12);
    }
    let e = linear(m).unwrap_err();
    assert!(
        e.message.contains("order-2 9-node quadrilaterals"),
        "{}",
        e.message
    );
}

#[test]
fn element_type_table() {
    assert_eq!(element_type(5).unwrap(), (CellKind::Hexahedron, 8));
    assert_eq!(element_type(15).unwrap(), (CellKind::Vertex, 1));
    assert_eq!(element_type(6).unwrap(), (CellKind::Wedge, 6));
    for (t, name, n) in [
        (17, "20-node hexahedron (Gmsh type 17)", 20),
        (16, "8-node quadrilateral (Gmsh type 16)", 8),
        (11, "10-node tetrahedron (Gmsh type 11)", 10),
    ] {
        assert_eq!(element_type(t).unwrap(), (CellKind::Other(name.into()), n));
    }
    for (t, dim, order, n) in [
        (12, 3, 2, 27),
        (36, 2, 3, 16),
        (92, 3, 3, 64),
        (98, 3, 9, 1000),
        (8, 1, 2, 3),
    ] {
        let kind = CellKind::Lagrange {
            dim,
            order,
            convention: NodeConvention::Gmsh,
        };
        assert_eq!(element_type(t).unwrap(), (kind, n));
    }
    assert!(
        element_type(76)
            .unwrap_err()
            .contains("unknown Gmsh element type 76")
    );
    assert!(element_type(34).unwrap_err().contains("polygon"));
    assert!(element_type(-1).is_err());
    assert!(element_type(i64::MAX).is_err());
    assert!(ELEMENT_TYPES.windows(2).all(|w| w[0].0 < w[1].0));
}

// ---- real files (counts from meshes/real/SOURCES.md) ----

#[test]
fn real_hole8170_v20() {
    let m = parse(&real("dealii/hole8170.msh"));
    assert_eq!(m.points.len(), 8449);
    assert_eq!(count(&m, &CellKind::Quad), 8170);
    assert_eq!(m.blocks.len(), 1);
    assert!(m.tag_names.is_empty());
    let lin = linear(m).unwrap();
    assert_eq!(
        (lin.dim, lin.n_elements(), lin.n_vertices()),
        (2, 8170, 8449)
    );
}

#[test]
fn real_example_v41() {
    let m = parse(&real("dealii/example.msh"));
    assert_eq!(m.points.len(), 835);
    assert_eq!(count(&m, &CellKind::Quad), 744);
    assert_eq!(count(&m, &CellKind::Line), 184);
    let lin = linear(m).unwrap();
    assert_eq!((lin.dim, lin.n_elements(), lin.n_vertices()), (2, 744, 835));
}

#[test]
fn real_unstructured_refined_ball_v22() {
    let m = parse(&real("dealii/unstructured_refined_ball.msh"));
    assert_eq!(m.points.len(), 581);
    assert_eq!(count(&m, &CellKind::Quad), 542);
    assert_eq!(count(&m, &CellKind::Line), 76);
    assert_eq!(count(&m, &CellKind::Vertex), 1);
    // "1 -5.253322182645479 2.898678140929567 0" is the first node, on line 6.
    assert_eq!(m.points[0], [-5.253322182645479, 2.898678140929567, 0.0]);
    assert_eq!(m.point_locations[0], Location::Line(6));
    let lin = linear(m).unwrap();
    assert_eq!((lin.dim, lin.n_elements(), lin.n_vertices()), (2, 542, 581));
}

#[test]
fn real_sphere_r6_v22() {
    let m = parse(&real("dealii/sphere_r6.msh"));
    assert_eq!(m.points.len(), 4776);
    assert_eq!(count(&m, &CellKind::Hexahedron), 4625);
    assert_eq!(count(&m, &CellKind::Quad), 150);
    let lin = linear(m).unwrap();
    assert_eq!(
        (lin.dim, lin.n_elements(), lin.n_vertices()),
        (3, 4625, 4776)
    );
    assert_eq!(lin.facet_tags.len(), 150);
}

#[test]
fn real_70deg_cone_v41_partial_physicals() {
    let m = parse(&real("hopr/70degCone_3D.msh"));
    assert_eq!(m.points.len(), 24189);
    assert_eq!(count(&m, &CellKind::Hexahedron), 19952);
    let boundary =
        count(&m, &CellKind::Quad) + count(&m, &CellKind::Line) + count(&m, &CellKind::Vertex);
    assert_eq!(count(&m, &CellKind::Quad), 4926);
    assert!(boundary > 4926);
    // Only the boundary surfaces carry physical groups; the volume has none.
    assert!(block(&m, &CellKind::Hexahedron).tags.is_empty());
    let quads = block(&m, &CellKind::Quad);
    let mut tags = quads.tags.clone();
    tags.sort();
    tags.dedup();
    assert_eq!(tags, [29, 30, 31, 32]);
    assert_eq!(m.tag_names[&32], "WALL");
    let lin = linear(m).unwrap();
    assert_eq!(
        (lin.dim, lin.n_elements(), lin.n_vertices()),
        (3, 19952, 24189)
    );
    assert_eq!(lin.facet_tags.len(), 4926);
}

#[test]
fn real_naca4412_v22() {
    let m = parse(&real("trixi-juliacon2024-naca4412/NACA4412_2.msh"));
    assert_eq!(m.points.len(), 29250);
    assert_eq!(count(&m, &CellKind::Hexahedron), 14336);
    assert_eq!(count(&m, &CellKind::Quad), 29200);
    assert_eq!(m.tag_names.len(), 9);
    assert_eq!(m.tag_names[&6], "b6-viscous_solid");
    assert!(
        block(&m, &CellKind::Hexahedron)
            .tags
            .iter()
            .all(|&t| t == 1)
    );
    let lin = linear(m).unwrap();
    assert_eq!(
        (lin.dim, lin.n_elements(), lin.n_vertices()),
        (3, 14336, 29250)
    );
}

// ---- hand-written variants ----

const V41_PARTIAL: &str = "$MeshFormat\n4.1 0 8\n$EndMeshFormat
$Entities
0 0 2 0
1 0 0 0 1 1 0 2 5 6 0
2 1 0 0 2 1 0 0 0
$EndEntities
$Nodes
2 6 3 900
2 1 0 4
3
10
900
11
0 0 0
1 0 0
1 1 0
0 1 0
2 2 1 2
20
21
2 0 0 0.5 0
2 1 0 0.5 1
$EndNodes
$Elements
2 2 1 2
2 1 3 1
1 3 10 900 11
2 2 3 1
2 10 20 21 900
$EndElements
";

#[test]
fn v41_first_physical_per_entity_and_sparse_tags() {
    let m = parse_str(V41_PARTIAL).unwrap();
    assert_eq!(m.points.len(), 6);
    assert_eq!(m.points[2], [1.0, 1.0, 0.0]);
    assert_eq!(m.points[5], [2.0, 1.0, 0.0]);
    // Second block is parametric on a surface: (u, v) after x y z are skipped.
    assert_eq!(m.point_locations[4], Location::Line(23));
    let q = block(&m, &CellKind::Quad);
    assert_eq!(q.nodes, [0, 1, 2, 3, 1, 4, 5, 2]);
    assert_eq!(q.tags, [5, 0]);
    assert_eq!(q.locations, [Location::Line(29), Location::Line(31)]);
}

#[test]
fn v22_sparse_and_huge_node_tags() {
    let s = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n7 0 0 0\n3 1 0 0\n\
             4000000000 1 1 0\n12 0 1 0\n$EndNodes\n$Elements\n1\n1 3 2 4 1 7 3 4000000000 12\n$EndElements\n";
    let m = parse_str(s).unwrap();
    let q = block(&m, &CellKind::Quad);
    assert_eq!(q.nodes, [0, 1, 2, 3]);
    assert_eq!(q.tags, [4]);
}

#[test]
fn v22_without_physical_tags_and_with_comments() {
    let s = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Comments\nanything $Nodes here\n$EndComments\n\
             $Nodes\n4\n1 0 0 0\n2 1 0 0\n3 1 1 0\n4 0 1 0\n$EndNodes\n\
             $Elements\n2\n1 3 0 1 2 3 4\n2 1 2 0 3 1 2\n$EndElements\n\
             $NodeData\n1\n\"x\"\n$EndNodeData\n";
    let m = parse_str(s).unwrap();
    assert!(block(&m, &CellKind::Quad).tags.is_empty());
    assert!(block(&m, &CellKind::Line).tags.is_empty());
    assert_eq!(block(&m, &CellKind::Line).locations, [Location::Line(17)]);
}

#[test]
fn physical_names_with_spaces_and_clashing_dimensions() {
    let s = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n3\n2 1 \"wall with spaces\"\n\
             3 1 \"fluid\"\n3 2 \"solid\"\n$EndPhysicalNames\n";
    let m = parse_str(s).unwrap();
    assert_eq!(m.tag_names[&1], "wall with spaces / fluid");
    assert_eq!(m.tag_names[&2], "solid");
}

/// A one-quad MSH 2.2 binary file in either byte order.
fn v22_binary(big_endian: bool) -> Vec<u8> {
    let i = |v: i32| {
        if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let f = |v: f64| {
        if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let mut d = b"$MeshFormat\n2.2 1 8\n".to_vec();
    d.extend(i(1));
    d.extend(b"\n$EndMeshFormat\n$Nodes\n4\n");
    for (t, x, y) in [(1, 0.0, 0.0), (2, 1.0, 0.0), (3, 1.0, 1.0), (4, 0.0, 1.0)] {
        d.extend(i(t));
        for c in [x, y, 0.5] {
            d.extend(f(c));
        }
    }
    d.extend(b"\n$EndNodes\n$Elements\n1\n");
    for v in [3, 1, 2, 1, 9, 8, 4, 3, 2, 1] {
        d.extend(i(v));
    }
    d.extend(b"\n$EndElements\n");
    d
}

#[test]
fn v22_binary_either_byte_order() {
    for be in [false, true] {
        let m = parse(&v22_binary(be));
        assert_eq!(m.points[2], [1.0, 1.0, 0.5]);
        let q = block(&m, &CellKind::Quad);
        assert_eq!(q.nodes, [3, 2, 1, 0]);
        assert_eq!(q.tags, [9]);
    }
}

mod bad_input;
mod modes;
