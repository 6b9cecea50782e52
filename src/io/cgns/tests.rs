//! CGNS reader and writer tests on files written by Gmsh and the CGNS library
//! (`tests/data/cgns/make_fixtures.py`).

use super::*;
use crate::io::test_util::{block, count, real};
use crate::mesh::raw::CellKind;
use crate::mesh::{LinearMesh, MeshOptions};

fn names(m: &RawMesh, b: &RawBlock) -> Vec<(String, usize)> {
    let mut by: BTreeMap<String, usize> = BTreeMap::new();
    for t in &b.tags {
        let name = m
            .tag_names
            .get(t)
            .cloned()
            .unwrap_or_else(|| format!("#{t}"));
        *by.entry(name).or_default() += 1;
    }
    by.into_iter().collect()
}

#[test]
fn gmsh_unstructured_hexes_with_families() {
    let m = read(&real("tests/data/cgns/hex_box_gmsh.cgns")).unwrap();
    assert_eq!(m.points.len(), 27);
    assert_eq!(count(&m, &CellKind::Hexahedron), 8);
    let q = block(&m, &CellKind::Quad);
    assert_eq!(names(&m, q), vec![("far".into(), 16), ("wall".into(), 8)]);
    // The volume family names the region.
    let h = block(&m, &CellKind::Hexahedron);
    assert_eq!(names(&m, h), vec![("fluid".into(), 8)]);
    let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
    assert_eq!(lm.n_elements(), 8);
    assert_eq!(lm.facet_tags.len(), 24);
}

#[test]
fn gmsh_unstructured_quads() {
    let m = read(&real("tests/data/cgns/quads_gmsh.cgns")).unwrap();
    assert_eq!(count(&m, &CellKind::Quad), 9);
    let l = block(&m, &CellKind::Line);
    assert_eq!(names(&m, l), vec![("bottom".into(), 3), ("rest".into(), 9)]);
    let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
    assert_eq!((lm.dim, lm.n_elements()), (2, 9));
}

/// Two structured zones joined by their 1-to-1 connectivity: the shared face's 9 vertices
/// are one, the inlet face's 4 quads are named.
#[test]
fn structured_zones_joined_by_connectivity() {
    let m = read(&real("tests/data/cgns/two_blocks_structured_gmsh.cgns")).unwrap();
    assert_eq!(m.points.len(), 2 * 27 - 9);
    assert_eq!(count(&m, &CellKind::Hexahedron), 16);
    let q = block(&m, &CellKind::Quad);
    assert!(
        names(&m, q).contains(&("inlet".into(), 4)),
        "{:?}",
        names(&m, q)
    );
    let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
    let topo = crate::mesh::Topology::build(&lm);
    // A closed box of 2x1 by 2x2 faces of quads: 2(8 + 8 + 4) boundary faces.
    assert_eq!(topo.boundary_facets.len(), 40);
}

/// Zones without connectivity (the CGNS library's plot3d_to_cgns) are glued where their
/// vertices coincide.
#[test]
fn structured_zones_glued_at_coincident_vertices() {
    let m = read(&real("tests/data/cgns/two_blocks_plot3d.cgns")).unwrap();
    assert_eq!(m.points.len(), 45);
    let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
    let topo = crate::mesh::Topology::build(&lm);
    assert_eq!(topo.boundary_facets.len(), 40);
}

/// The CGNS library's ADF copy of a file (`cgnsconvert -a`) reads as the HDF5 original:
/// every coordinate bit for bit, every cell, tag and name.
#[test]
fn adf_reads_as_its_hdf5_original() {
    let adf = read(&real("tests/data/cgns/hex_box.adf")).unwrap();
    let hdf5 = read(&real("tests/data/cgns/hex_box_gmsh.cgns")).unwrap();
    assert_eq!(adf.points.len(), 27);
    assert_eq!(format!("{adf:?}"), format!("{hdf5:?}"));
}

#[test]
fn non_cgns_is_refused_in_one_line() {
    let e = read(b"not a cgns file").unwrap_err();
    assert!(
        e.message.contains("HDF5") && e.message.contains("ADF"),
        "{e}"
    );
    let e = read(b"\0\0\0\0ADF Database Version").unwrap_err();
    assert!(e.message.contains("ADF"), "{e}");
}

/// A damaged ADF file (truncated anywhere, or any byte overwritten) gives a result or a
/// one-line error, never a panic or an allocation beyond the file's size.
#[test]
fn damaged_adf_files_give_one_line_errors() {
    let good = real("tests/data/cgns/hex_box.adf");
    let check = |data: &[u8], what: &str| {
        if let Err(e) = read(data) {
            let e = e.to_string();
            assert!(!e.contains('\n') && e.len() < 400, "{what}: {e}");
        }
    };
    let mut failed = 0;
    for cut in (0..good.len()).step_by(61) {
        check(&good[..cut], &format!("cut at {cut}"));
        failed += usize::from(read(&good[..cut]).is_err());
    }
    // Every truncation before the last node's data breaks the file.
    assert!(failed > good.len() / 61 / 2, "{failed}");
    let mut state = 0x2545_f491_4f6c_dd1du64;
    for _ in 0..3000 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let mut bad = good.clone();
        let at = (state % good.len() as u64) as usize;
        bad[at] = (state >> 32) as u8;
        check(&bad, &format!("byte {at} = {}", bad[at]));
    }
}

/// A forged zone size is refused with the node's path, before anything is allocated for it.
#[test]
fn errors_name_the_node_path() {
    let mut data = real("tests/data/cgns/quads_gmsh.cgns");
    // Truncate: the HDF5 structure is broken, and the error says so in one line.
    data.truncate(data.len() / 2);
    let e = read(&data).unwrap_err().to_string();
    assert!(!e.contains('\n'), "{e}");
}

/// Gmsh's CGNS export of a 30° sector of an annulus (r in [1, 2], z in [0, 1]) whose side
/// faces Gmsh was told are periodic: Gmsh writes one periodic connection per mesh entity (its
/// points, curves and the face, each with its inverse), all one rotation about z. They make
/// one claim, and on the mesh it pairs the two side groups, 9 vertices each, as the rotation
/// by 30° about the z axis (either way round).
#[test]
fn gmsh_periodic_connections_pair_the_side_groups() {
    let m = read(&real("tests/data/cgns/periodic_sector_gmsh.cgns")).unwrap();
    assert_eq!(m.periodic.len(), 1, "{:?}", m.periodic);
    assert!(m.periodic[0].sides.is_none() && m.periodic[0].dim == 2);
    let lm = LinearMesh::from_raw(m, &MeshOptions::default()).unwrap();
    let topo = crate::mesh::Topology::build(&lm);
    let pairs = crate::mesh::periodic::resolve(&lm, &topo, &[]).unwrap();
    assert_eq!(pairs.len(), 1);
    let p = &pairs[0];
    let mut names = [
        lm.tag_names[&p.master_tag].clone(),
        lm.tag_names[&p.slave_tag].clone(),
    ];
    names.sort();
    assert_eq!(names, ["side0".to_string(), "side1".to_string()]);
    assert_eq!(p.vertex_map.len(), 9);
    let (axis, point, angle) = p.transform.axis_angle().expect("a rotation");
    assert!((angle - 30.0).abs() < 1e-9, "{angle}");
    assert!((axis[2].abs() - 1.0).abs() < 1e-12, "{axis:?}");
    assert!(
        point[0].abs() < 1e-12 && point[1].abs() < 1e-12,
        "{point:?}"
    );
}
