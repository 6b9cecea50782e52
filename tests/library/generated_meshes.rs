//! The small meshes in `meshes/generated/` (written by its Python script, independently of the
//! library) read with the counts their construction gives.

use polyspline::io::read_mesh;
use polyspline::mesh::{MeshOptions, Topology};
use std::collections::BTreeMap;
use std::path::PathBuf;

fn load(name: &str) -> (polyspline::mesh::LinearMesh, Topology) {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("meshes/generated")
        .join(name);
    let m = read_mesh(&p, &MeshOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let t = Topology::build(&m);
    (m, t)
}

fn tag_counts(m: &polyspline::mesh::LinearMesh, t: &Topology) -> BTreeMap<String, usize> {
    let mut out = BTreeMap::new();
    for &tag in &t.boundary_facet_tags {
        let name = m
            .tag_names
            .get(&tag)
            .cloned()
            .unwrap_or_else(|| format!("untagged {tag}"));
        *out.entry(name).or_insert(0) += 1;
    }
    out
}

#[test]
fn grid_3x3() {
    let (m, t) = load("grid_quad4_9.msh");
    assert_eq!(
        (
            m.dim,
            m.n_elements(),
            m.n_vertices(),
            t.boundary_facets.len()
        ),
        (2, 9, 16, 12)
    );
    let want: BTreeMap<String, usize> = [("bottom", 3), ("left", 3), ("right", 3), ("top", 3)]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
    assert_eq!(tag_counts(&m, &t), want);
    assert_eq!(t.irregular_count(), 0);
}

#[test]
fn l_shape() {
    let (m, t) = load("lshape_quad4_12.msh");
    assert_eq!(
        (m.n_elements(), m.n_vertices(), t.boundary_facets.len()),
        (12, 21, 16)
    );
    let corner = m
        .coords
        .iter()
        .position(|p| p[0] == 2.0 && p[1] == 2.0)
        .unwrap();
    assert_eq!(t.vertex_valence(corner), 3);
    assert!(t.vertex_on_boundary[corner]);
    assert_eq!(tag_counts(&m, &t).get("wall"), Some(&16));
}

#[test]
fn stars() {
    for k in [3usize, 5] {
        let (m, t) = load(&format!("star{k}_quad4_{}.msh", 4 * k));
        assert_eq!((m.n_elements(), m.n_vertices()), (4 * k, 1 + 6 * k));
        let centre = m
            .coords
            .iter()
            .position(|p| p[0] == 0.0 && p[1] == 0.0)
            .unwrap();
        assert_eq!(t.vertex_valence(centre), k);
        assert_eq!(t.irregular_count(), 1);
        assert_eq!(tag_counts(&m, &t).get("outer"), Some(&(4 * k)));
        assert!(m.min_scaled_jacobian().unwrap().0 > 0.2);
    }
}

#[test]
fn hex_block_2x2x2() {
    let (m, t) = load("block_hex8_8.msh");
    assert_eq!(
        (
            m.dim,
            m.n_elements(),
            m.n_vertices(),
            t.boundary_facets.len()
        ),
        (3, 8, 27, 24)
    );
    let counts = tag_counts(&m, &t);
    for side in ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax"] {
        assert_eq!(counts.get(side), Some(&4), "{side}: {counts:?}");
    }
    assert_eq!(m.element_tags, vec![7; 8]);
    assert_eq!(m.tag_names.get(&7).map(String::as_str), Some("domain"));
}
