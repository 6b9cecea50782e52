//! Every bundled real mesh loads with the counts of `meshes/real/SOURCES.md`, which were
//! obtained with independent per-format parsers and cross-checked with meshio.

use polyspline::info::MeshInfo;
use polyspline::io::read_mesh;
use polyspline::mesh::{MeshOptions, Topology};
use std::path::PathBuf;

struct Expect {
    path: &'static str,
    dim: usize,
    elements: usize,
    vertices: usize,
    /// SOURCES.md "Irregular": 2D interior vertices of valence != 4; 3D interior edges
    /// (not both end points on the boundary) with valence != 4.
    irregular: usize,
    components: usize,
    reoriented: usize,
}

const MESHES: &[Expect] = &[
    Expect {
        path: "su2-testcases/n0012_113-33.su2",
        dim: 2,
        elements: 3584,
        vertices: 3704,
        irregular: 0,
        components: 1,
        reoriented: 0,
    },
    Expect {
        path: "su2-testcases/mesh_vki_turbine_prepbc.su2",
        dim: 2,
        elements: 15568,
        vertices: 15860,
        irregular: 1,
        components: 1,
        reoriented: 384,
    },
    Expect {
        path: "dealii/hole8170.msh",
        dim: 2,
        elements: 8170,
        vertices: 8449,
        irregular: 232,
        components: 1,
        reoriented: 0,
    },
    Expect {
        path: "dealii/example.msh",
        dim: 2,
        elements: 744,
        vertices: 835,
        irregular: 55,
        components: 1,
        reoriented: 0,
    },
    Expect {
        path: "dealii/unstructured_refined_ball.msh",
        dim: 2,
        elements: 542,
        vertices: 581,
        irregular: 72,
        components: 1,
        reoriented: 0,
    },
    Expect {
        path: "trixi-juliacon2024-naca4412/NACA4412_2_2D_unique.inp",
        dim: 2,
        elements: 14336,
        vertices: 14625,
        irregular: 0,
        components: 1,
        reoriented: 0,
    },
    Expect {
        path: "trixi-juliacon2024-naca4412/NACA4412_2.msh",
        dim: 3,
        elements: 14336,
        vertices: 29250,
        irregular: 0,
        components: 1,
        reoriented: 14336,
    },
    Expect {
        path: "hopr/70degCone_3D.msh",
        dim: 3,
        elements: 19952,
        vertices: 24189,
        irregular: 27024,
        components: 1,
        reoriented: 0,
    },
    Expect {
        path: "mfem/cylinder-hex.mesh",
        dim: 3,
        elements: 252,
        vertices: 364,
        irregular: 63,
        components: 1,
        reoriented: 0,
    },
    // SOURCES.md speaks of two bodies; topologically there are three (attributes 1, 2, 3 with
    // 1518, 266 and 85 hexes) that touch only through coincident, distinct vertices.
    Expect {
        path: "mfem/beam-sphere.mesh",
        dim: 3,
        elements: 1869,
        vertices: 2634,
        irregular: 25,
        components: 3,
        reoriented: 0,
    },
    Expect {
        path: "su2-testcases/cylinder.su2",
        dim: 3,
        elements: 315,
        vertices: 512,
        irregular: 0,
        components: 1,
        reoriented: 0,
    },
    Expect {
        path: "dealii/sphere_r6.msh",
        dim: 3,
        elements: 4625,
        vertices: 4776,
        irregular: 300,
        components: 1,
        reoriented: 0,
    },
    Expect {
        path: "sfepy/acoustics_mesh3d.mesh",
        dim: 3,
        elements: 4380,
        vertices: 5272,
        irregular: 418,
        components: 1,
        reoriented: 0,
    },
    Expect {
        path: "sfepy/hsphere8.vtk",
        dim: 3,
        elements: 648,
        vertices: 889,
        irregular: 6,
        components: 1,
        reoriented: 0,
    },
    // Two element blocks of 555 hexes with disjoint node sets (66 coincident positions on
    // their interface): two topological components.
    Expect {
        path: "libmesh/systems_of_equations_ex9.exo",
        dim: 3,
        elements: 1110,
        vertices: 1608,
        irregular: 40,
        components: 2,
        reoriented: 0,
    },
];

fn path(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("meshes/real")
        .join(rel)
}

#[test]
fn every_real_mesh_has_the_documented_counts() {
    let mut failures = Vec::new();
    for m in MESHES {
        let mesh = match read_mesh(&path(m.path), &MeshOptions::default()) {
            Ok(mesh) => mesh,
            Err(e) => {
                failures.push(format!("{}: {e}", m.path));
                continue;
            }
        };
        let topo = Topology::build(&mesh);
        let info = MeshInfo::new(&mesh, &topo);
        let got = (
            info.dimension,
            info.elements,
            info.vertices,
            info.irregular,
            info.components,
            info.reoriented,
        );
        let want = (
            m.dim,
            m.elements,
            m.vertices,
            m.irregular,
            m.components,
            m.reoriented,
        );
        if got != want {
            failures.push(format!(
                "{}: (dim, elements, vertices, irregular, components, reoriented) = {got:?}, expected {want:?}",
                m.path
            ));
        }
        // After normalisation no element is inverted, and the topology is a manifold.
        if info.min_scaled_jacobian.is_nan() || info.min_scaled_jacobian <= 0.0 {
            failures.push(format!(
                "{}: min scaled Jacobian {}",
                m.path, info.min_scaled_jacobian
            ));
        }
        if !topo.non_manifold.is_empty() {
            failures.push(format!("{}: non-manifold {:?}", m.path, topo.non_manifold));
        }
        // Closed boundary: every boundary vertex lies on a boundary facet, so
        // 2D: #boundary edges = #boundary vertices (a union of cycles).
        if m.dim == 2 && info.boundary_facets != info.boundary_vertices {
            failures.push(format!(
                "{}: {} boundary edges, {} boundary vertices",
                m.path, info.boundary_facets, info.boundary_vertices
            ));
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

/// Boundary tags named in SOURCES.md survive reading and attach to boundary facets.
#[test]
fn named_boundary_markers_are_attached() {
    let cases: &[(&str, &[&str])] = &[
        ("su2-testcases/n0012_113-33.su2", &["airfoil", "farfield"]),
        (
            "su2-testcases/cylinder.su2",
            &["inner", "outer", "per_1", "per_2", "x_plus", "x_minus"],
        ),
        (
            "su2-testcases/mesh_vki_turbine_prepbc.su2",
            &["periodic_1", "periodic_2"],
        ),
    ];
    for (rel, names) in cases {
        let mesh = read_mesh(&path(rel), &MeshOptions::default()).unwrap();
        let topo = Topology::build(&mesh);
        for name in *names {
            let tag = mesh
                .tag_names
                .iter()
                .find(|(_, n)| n.as_str() == *name)
                .map(|(t, _)| *t)
                .unwrap_or_else(|| panic!("{rel}: no tag named {name}: {:?}", mesh.tag_names));
            let n = topo
                .boundary_facet_tags
                .iter()
                .filter(|&&t| t == tag)
                .count();
            assert!(n > 0, "{rel}: marker {name} is on no boundary facet");
        }
    }
    // SU2 markers cover the whole boundary of the structured meshes.
    for rel in [
        "su2-testcases/n0012_113-33.su2",
        "su2-testcases/cylinder.su2",
    ] {
        let mesh = read_mesh(&path(rel), &MeshOptions::default()).unwrap();
        let topo = Topology::build(&mesh);
        assert_eq!(
            topo.boundary_facet_tags.iter().filter(|&&t| t == 0).count(),
            0,
            "{rel}"
        );
    }
}

/// `polyspline info --json` prints one JSON object with the documented keys.
#[test]
fn info_json_on_every_real_mesh() {
    for m in MESHES {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_polyspline"))
            .args(["info", "--json"])
            .arg(path(m.path))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}: {}",
            m.path,
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        for key in [
            "dimension",
            "elements",
            "vertices",
            "boundary_facets",
            "components",
            "reoriented",
            "min_scaled_jacobian",
            "spline_elements",
            "q2_elements",
            "control_points",
        ] {
            assert!(v.get(key).is_some(), "{}: key {key} missing", m.path);
        }
        let spline = v["spline_elements"].as_u64().unwrap();
        let q2 = v["q2_elements"].as_u64().unwrap();
        assert_eq!(spline + q2, m.elements as u64, "{}", m.path);
        assert_eq!(
            v["elements"].as_u64(),
            Some(m.elements as u64),
            "{}",
            m.path
        );
        assert_eq!(v["dimension"].as_u64(), Some(m.dim as u64), "{}", m.path);
        let (s, q) = (
            v["spline_elements"].as_u64().unwrap(),
            v["q2_elements"].as_u64().unwrap(),
        );
        assert_eq!(s + q, m.elements as u64, "{}", m.path);
    }
}
