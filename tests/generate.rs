//! Synthetic benchmark meshes: sizes near the request, valid, with boundaries on the analytic
//! surfaces they discretise, and the documented irregular vertices/edges.

use polyspline::mesh::Topology;
use polyspline::mesh::generate::{Kind, generate};
use std::process::Command;

#[test]
fn generated_meshes_have_their_shape() {
    for (kind, n) in [
        (Kind::Disc, 3000),
        (Kind::Cylinder, 5000),
        (Kind::Torus, 5000),
    ] {
        let m = generate(kind, n);
        let t = Topology::build(&m);
        let ne = m.n_elements() as f64;
        assert!(
            (ne / n as f64 - 1.0).abs() < 0.25,
            "{kind:?}: {ne} elements for {n}"
        );
        assert!(m.min_scaled_jacobian().unwrap().0 > 0.5, "{kind:?}");
        assert_eq!(t.n_components, 1);
        assert!(t.non_manifold.is_empty());
        assert_eq!(m.reoriented, 0, "{kind:?}: generated already oriented");
        for (v, p) in m.coords.iter().enumerate() {
            if !t.vertex_on_boundary[v] {
                continue;
            }
            let r = (p[0] * p[0] + p[1] * p[1]).sqrt();
            match kind {
                Kind::Disc => assert!((r - 1.0).abs() < 1e-12),
                // On the curved wall or on a flat end.
                Kind::Cylinder => assert!(
                    (r - 1.0).abs() < 1e-12 || p[2].abs() < 1e-12 || (p[2] - 2.0).abs() < 1e-12
                ),
                Kind::Torus => {
                    assert!((((r - 3.0).powi(2) + p[2] * p[2]).sqrt() - 1.0).abs() < 1e-12)
                }
            }
        }
        // Valence-3 vertices (2D) or edges (3D): 4 per disc section.
        let irregular = t.irregular_count();
        match kind {
            Kind::Disc => assert_eq!(irregular, 4),
            _ => assert!(
                irregular > 0 && irregular.is_multiple_of(4),
                "{kind:?}: {irregular}"
            ),
        }
        // Every boundary facet is tagged.
        assert!(t.boundary_facet_tags.iter().all(|&x| x > 0), "{kind:?}");
    }
}

#[test]
fn generate_command_writes_a_mesh_info_reads_back() {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let out = dir.join("gen_torus.msh");
    let status = Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .args(["generate", "torus", "--elements", "3000", "-o"])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let info = Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .args(["info", "--json"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(info.status.success());
    let v: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    let m = generate(Kind::Torus, 3000);
    assert_eq!(v["elements"].as_u64(), Some(m.n_elements() as u64));
    assert_eq!(v["vertices"].as_u64(), Some(m.n_vertices() as u64));
    assert_eq!(v["reoriented"].as_u64(), Some(0));
}
