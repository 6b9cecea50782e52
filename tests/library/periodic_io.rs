//! Gmsh's `$Periodic` section through the writer and the reader: the pairs written are the
//! pairs read, and the reader's pairs are used (and checked) without any `--periodic`.

use polyspline::mesh::LinearMesh;

/// A 3D grid whose sides x = 0 / x = 2 (tags 1 / 2) and y = 0 / y = 1 (tags 3 / 4) are
/// periodic, sampled at order 1 with its node pairs, written in every MSH variant with a
/// `$Periodic` section, and read back: the declared pairs name the written tags with the written
/// affine maps, and [`polyspline::mesh::periodic::resolve`] without any `--periodic` finds both pairs
/// from them, with the same transforms.
#[test]
fn periodic_section_round_trips_in_every_variant() {
    use polyspline::io::gmsh_write::{MshVersion, write_msh};
    use polyspline::mesh::periodic::{PeriodicSpec, node_pairs, resolve};
    use polyspline::mesh::{MeshOptions, Topology, generate::grid_3d};
    let mesh = grid_3d(&[0.0, 0.7, 2.0], &[0.0, 0.4, 1.0], &[0.0, 0.3, 0.5]);
    let topo = Topology::build(&mesh);
    let specs: Vec<PeriodicSpec> = ["1:2", "3:4"].iter().map(|s| s.parse().unwrap()).collect();
    let pairs = resolve(&mesh, &topo, &specs).unwrap();
    let mut ho = polyspline::sample::sample(&mesh, &mesh, &topo, 1);
    ho.periodic = node_pairs(&ho, &pairs).unwrap();
    for (version, binary) in [
        (MshVersion::V41, false),
        (MshVersion::V41, true),
        (MshVersion::V22, false),
        (MshVersion::V22, true),
    ] {
        let what = format!("{version:?} binary {binary}");
        let mut data = Vec::new();
        write_msh(&ho, version, binary, &mut data).unwrap();
        let raw = polyspline::io::gmsh::read(&data).unwrap();
        let facets: Vec<_> = raw.periodic.iter().filter(|p| p.dim == 2).collect();
        assert_eq!(facets.len(), 2, "{what}: {:?}", raw.periodic);
        for (d, l) in facets.iter().zip(&ho.periodic) {
            assert_eq!(d.sides, Some([l.master_tag, l.slave_tag]), "{what}");
            assert_eq!(d.affine, Some(l.transform.affine()), "{what}");
        }
        let back = LinearMesh::from_raw(raw, &MeshOptions::default()).unwrap();
        let topo = Topology::build(&back);
        let found = resolve(&back, &topo, &[]).unwrap();
        assert_eq!(found.len(), 2, "{what}");
        for (f, p) in found.iter().zip(&pairs) {
            assert!(f.spec.from_file, "{what}");
            assert_eq!((f.master_tag, f.slave_tag), (p.master_tag, p.slave_tag));
            for k in 0..3 {
                assert!((f.transform.translation[k] - p.transform.translation[k]).abs() < 1e-12);
            }
        }
        // A pair given on the command line wins for its groups: 2:1 replaces the file's 1:2.
        let reverse: PeriodicSpec = "2:1".parse().unwrap();
        let found = resolve(&back, &topo, &[reverse]).unwrap();
        assert_eq!(found.len(), 2, "{what}");
        assert_eq!((found[0].master_tag, found[0].spec.from_file), (2, false));
        assert_eq!((found[1].master_tag, found[1].spec.from_file), (3, true));
    }
}

/// The file's affine map must agree with the transform found from the positions.
#[test]
fn periodic_section_with_a_wrong_affine_map_is_refused() {
    use polyspline::io::gmsh_write::{MshVersion, write_msh};
    use polyspline::mesh::periodic::{PeriodicSpec, node_pairs, resolve};
    use polyspline::mesh::{MeshOptions, Topology, generate::grid_2d};
    let mesh = grid_2d(&[0.0, 0.7, 2.0], &[0.0, 0.4, 1.0]);
    let topo = Topology::build(&mesh);
    let spec: PeriodicSpec = "1:2".parse().unwrap();
    let pairs = resolve(&mesh, &topo, &[spec]).unwrap();
    let mut ho = polyspline::sample::sample(&mesh, &mesh, &topo, 1);
    ho.periodic = node_pairs(&ho, &pairs).unwrap();
    ho.periodic[0].transform.translation[0] = 2.001;
    let mut data = Vec::new();
    write_msh(&ho, MshVersion::V41, false, &mut data).unwrap();
    let back = LinearMesh::from_raw(
        polyspline::io::gmsh::read(&data).unwrap(),
        &MeshOptions::default(),
    )
    .unwrap();
    let topo = Topology::build(&back);
    let e = resolve(&back, &topo, &[]).unwrap_err().to_string();
    assert!(
        e.starts_with(
            "$Periodic pair boundary_1:boundary_2: the file's map ($Periodic link of entities"
        ) && e.contains("disagrees with the transform found")
            && !e.contains('\n'),
        "{e}"
    );
}
