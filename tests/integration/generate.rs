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

// ---------------------------------------------------------------------------------------------
// Boundary-layer O-grids and C-grids (`generate ogrid|cgrid`).

use crate::common::{self, dist, polyspline};

use polyspline::mesh::LinearMesh;
use polyspline::mesh::generate::boundary_layer::{
    BoundaryLayer, Wall, cgrid, max_aspect_ratio, ogrid, wall_normal_spacing,
};

/// Vertices of the facets tagged `tag`.
fn tagged_vertices(m: &LinearMesh, tag: i32) -> Vec<u32> {
    let npf = m.nodes_per_facet();
    let mut v: Vec<u32> = m
        .tagged_facets
        .chunks(npf)
        .zip(&m.facet_tags)
        .filter(|(_, t)| **t == tag)
        .flat_map(|(f, _)| f.iter().copied())
        .collect();
    v.sort_unstable();
    v.dedup();
    v
}

/// Check one 2D boundary-layer mesh against its options: validity, counts, wall and far-field
/// vertices on their analytic curves, first height and growth along every wall-normal line.
fn check_layer_mesh(p: &BoundaryLayer, c_grid: bool) {
    let made = if c_grid { cgrid(p) } else { ogrid(p) }.unwrap_or_else(|e| panic!("{p:?}: {e}"));
    let (m, s) = (&made.mesh, &made.spacing);
    let what = format!("{} {p:?}", if c_grid { "cgrid" } else { "ogrid" });
    let around = if c_grid {
        p.around + 2 * p.wake
    } else {
        p.around
    };
    assert_eq!(m.n_elements(), around * p.across, "{what}");
    assert_eq!(m.reoriented, 0, "{what}");
    let (msj, worst) = m.min_scaled_jacobian().unwrap();
    assert!(msj > 0.0, "{what}: element {worst} scaled Jacobian {msj}");
    let t = Topology::build(m);
    assert_eq!(t.n_components, 1);
    assert!(t.boundary_facet_tags.iter().all(|&x| x > 0), "{what}");
    // Wall vertices on the analytic wall.
    let wall = tagged_vertices(m, 1);
    assert_eq!(wall.len(), p.around, "{what}");
    for &v in &wall {
        let q = m.coords[v as usize];
        let d = p.wall.distance([q[0], q[1]]);
        assert!(
            d < 1e-12,
            "{what}: wall vertex {v} {q:?} is {d:e} off the wall"
        );
    }
    // Far field.
    let r = p.farfield * p.wall.chord();
    for v in tagged_vertices(m, 2) {
        let q = m.coords[v as usize];
        let off = if c_grid {
            if q[0] <= 1.0 {
                ((q[0] - 1.0).hypot(q[1]) - r).abs()
            } else {
                (q[1].abs() - r).abs()
            }
        } else {
            let c = p.wall.centre();
            ((q[0] - c[0]).hypot(q[1] - c[1]) - r).abs()
        };
        assert!(
            off < 1e-12 * r,
            "{what}: far-field vertex {q:?} off by {off:e}"
        );
    }
    // Walk each wall-normal line: from a wall vertex to its off-wall neighbour (not along the
    // wake cut), then on to the neighbour that continues straightest.
    let mut adj = vec![Vec::new(); m.n_vertices()];
    for e in &t.edges {
        adj[e[0] as usize].push(e[1]);
        adj[e[1] as usize].push(e[0]);
    }
    let on_wall: std::collections::HashSet<u32> = wall.iter().copied().collect();
    let check_cells = s.geometric_cells.min(12);
    assert!(s.geometric_cells >= 1);
    let mut lines = 0;
    for &v in &wall {
        let x0 = m.coords[v as usize];
        for &w in &adj[v as usize] {
            let x1 = m.coords[w as usize];
            if on_wall.contains(&w) || (c_grid && x1[1] == 0.0 && x1[0] > 1.0) {
                continue;
            }
            lines += 1;
            let h0 = dist(x0, x1);
            assert!(
                (h0 / p.first_height - 1.0).abs() < 1e-9,
                "{what}: first height {h0:e} at {x0:?}"
            );
            let (mut a, mut b) = (v, w);
            let mut h = h0;
            for k in 1..check_cells {
                let (pa, pb) = (m.coords[a as usize], m.coords[b as usize]);
                let dir = [pb[0] - pa[0], pb[1] - pa[1]];
                let next = *adj[b as usize]
                    .iter()
                    .max_by(|&&x, &&y| {
                        let score = |u: u32| {
                            let pu = m.coords[u as usize];
                            let d = [pu[0] - pb[0], pu[1] - pb[1]];
                            (d[0] * dir[0] + d[1] * dir[1]) / d[0].hypot(d[1])
                        };
                        score(x).total_cmp(&score(y))
                    })
                    .unwrap();
                let hn = dist(m.coords[b as usize], m.coords[next as usize]);
                assert!(
                    (hn / h / p.growth - 1.0).abs() < 1e-9,
                    "{what}: cell {k} off the wall at {x0:?}: ratio {}",
                    hn / h
                );
                (a, b, h) = (b, next, hn);
            }
        }
    }
    // One line per wall vertex, two at the C-grid's trailing edge.
    assert_eq!(lines, wall.len() + usize::from(c_grid), "{what}");
}

#[test]
fn boundary_layer_meshes_are_valid_with_exact_wall_spacing() {
    let walls = [
        Wall::Ellipse { thickness: 0.2 },
        Wall::Ellipse { thickness: 0.3 },
        Wall::Circle,
        Wall::Naca { thickness: 0.12 },
    ];
    for first_height in [1e-6, 1e-5, 1e-4, 1e-3, 1e-2] {
        for growth in [1.05, 1.15, 1.25, 1.32, 1.4] {
            for (around, across) in [(48, 40), (96, 24)] {
                let base = BoundaryLayer {
                    around,
                    across,
                    first_height,
                    growth,
                    wake: 12,
                    ..Default::default()
                };
                for wall in walls {
                    check_layer_mesh(&BoundaryLayer { wall, ..base }, false);
                }
                check_layer_mesh(
                    &BoundaryLayer {
                        wall: walls[3],
                        ..base
                    },
                    true,
                );
            }
        }
    }
}

#[test]
fn wall_normal_spacing_handles_short_and_long_series() {
    // Undershoot: 48 cells growing by 1.28 from 1e-5 reach only ~5 of 19: growth holds until a
    // cell reaches the cap, then the rest stretch faster to end exactly at the far field.
    // Overshoot: 48 cells by 1.4 from 1e-2 would pass 19 long before: they stop growing.
    for (first, growth, cap) in [(1e-5, 1.28, 0.033), (1e-2, 1.4, 1.0), (1e-6, 1.05, 0.05)] {
        let s = wall_normal_spacing(first, growth, 48, 19.0, cap).unwrap();
        let d = &s.distances;
        assert_eq!(d.len(), 49);
        assert_eq!(d[0], 0.0);
        assert_eq!(d[48], 19.0);
        assert!(d.windows(2).all(|w| w[1] > w[0]));
        assert!((d[1] / first - 1.0).abs() < 1e-12);
        let k = s.geometric_cells;
        assert!(k >= 1 && s.outer_growth >= 1.0, "{s:?}");
        for i in 1..k {
            let ratio = (d[i + 1] - d[i]) / (d[i] - d[i - 1]);
            assert!(
                (ratio / growth - 1.0).abs() < 1e-9,
                "{first} {growth}: {ratio}"
            );
        }
        // The geometric region stops at the cap (or earlier, when the far field is near).
        assert!(d[k] - d[k - 1] <= cap.max(first));
        for i in k + 1..48 {
            let ratio = (d[i + 1] - d[i]) / (d[i] - d[i - 1]);
            assert!((ratio / s.outer_growth - 1.0).abs() < 1e-6, "{ratio}");
        }
    }
    // Heights that cannot fit are refused, not shrunk.
    assert!(wall_normal_spacing(1.0, 1.2, 48, 19.0, 1.0).is_err());
    assert!(wall_normal_spacing(1e-5, 0.9, 48, 19.0, 1.0).is_err());
    assert!(wall_normal_spacing(1e-5, 1.2, 1, 19.0, 1.0).is_err());
}

#[test]
fn analytic_wall_distance_matches_offsets() {
    // Points offset along the outward normal by δ are δ from a convex wall.
    let t: f64 = 0.2;
    let ellipse = Wall::Ellipse { thickness: t };
    for k in 0..50 {
        let a = 0.123 + k as f64 * 0.1257;
        let p = [a.cos(), t * a.sin()];
        let n = [t * a.cos(), a.sin()];
        let l = n[0].hypot(n[1]);
        for delta in [0.0, 1e-9, 1e-3, 0.5, 3.0] {
            let q = [p[0] + delta * n[0] / l, p[1] + delta * n[1] / l];
            let (c, d) = ellipse.closest_point(q);
            assert!((d - delta).abs() < 1e-12, "{a} {delta}: {d}");
            assert!(dist([c[0], c[1], 0.0], [p[0], p[1], 0.0]) < 1e-7);
        }
    }
    assert!((Wall::Circle.distance([3.0, 4.0]) - 4.0).abs() < 1e-14);
    // NACA 0012: the half thickness at x is y_t(x); the closed trailing edge is at (1, 0);
    // 0.12 thick at 30% chord (the 4-digit maximum, to the formula's rounding).
    let naca = Wall::Naca { thickness: 0.12 };
    let yt = |x: f64| {
        0.6 * (0.2969 * x.sqrt() - 0.126 * x - 0.3516 * x * x + 0.2843 * x.powi(3)
            - 0.1036 * x.powi(4))
    };
    for x in [0.0, 1e-6, 0.01, 0.3, 0.77, 1.0] {
        assert!(naca.distance([x, yt(x)]) < 1e-12, "{x}");
        assert!(naca.distance([x, -yt(x)]) < 1e-12, "{x}");
    }
    assert!((2.0 * yt(0.3) - 0.12).abs() < 2e-4);
    assert!(yt(1.0).abs() < 1e-15);
    assert!((naca.distance([2.0, 0.0]) - 1.0).abs() < 1e-12);
    assert!((naca.distance([-0.5, 0.0]) - 0.5).abs() < 1e-12);
}

#[test]
fn generate_ogrid_and_cgrid_commands_write_named_valid_meshes() {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let cases: [(&str, &[&str], usize, &[&str]); 4] = [
        (
            "bl_ogrid2d.msh",
            &["ogrid", "--thickness", "0.2"],
            64 * 32,
            &["wall", "farfield"],
        ),
        (
            "bl_ogrid3.msh",
            &["ogrid", "--wall", "naca", "--layers", "3", "--span", "0.5"],
            3 * 64 * 32,
            &["wall", "farfield", "zmin", "zmax"],
        ),
        (
            "bl_cgrid.msh",
            &["cgrid", "--wake", "16"],
            (64 + 32) * 32,
            &["wall", "farfield", "outflow"],
        ),
        (
            "bl_cgrid1.msh",
            &["cgrid", "--wake", "16", "--layers", "1"],
            (64 + 32) * 32,
            &["wall", "farfield", "outflow", "zmin", "zmax"],
        ),
    ];
    let mut jobs = Vec::new();
    for (file, args, elements, _) in &cases {
        let out = dir.join(file);
        common::run_ok(
            polyspline()
                .arg("generate")
                .args(*args)
                .args(["--around", "64", "--across", "32", "--first-height", "1e-5"])
                .args(["--growth", "1.28", "-o"])
                .arg(&out),
        );
        let info = common::run_ok(polyspline().args(["info", "--json"]).arg(&out));
        let v: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
        assert_eq!(v["elements"].as_u64(), Some(*elements as u64), "{file}");
        assert_eq!(v["reoriented"].as_u64(), Some(0), "{file}");
        let msj = v["min_scaled_jacobian"].as_f64().unwrap();
        assert!(msj > 0.0, "{file}: {msj}");
        jobs.push(serde_json::json!({ "file": out, "probes": [] }));
    }
    // Gmsh reads the files, finds positive Jacobians and the named physical groups.
    let Some(results) = common::gmsh_probe(&jobs, &dir.join("bl_jobs.json")) else {
        return;
    };
    for ((file, _, elements, names), r) in cases.iter().zip(&results) {
        assert_eq!(r["elements"].as_u64(), Some(*elements as u64), "{file}");
        assert!(r["min_det_jac"].as_f64().unwrap() > 0.0, "{file}: {r}");
        let groups: Vec<&str> = r["physical_groups"]
            .as_object()
            .unwrap()
            .values()
            .map(|v| v.as_str().unwrap())
            .collect();
        for name in *names {
            assert!(groups.contains(name), "{file}: {name} not in {groups:?}");
        }
    }
}

#[test]
fn extruded_boundary_layers_have_layers_times_quads() {
    for layers in [1, 3] {
        let p = BoundaryLayer {
            around: 32,
            across: 16,
            layers,
            span: 0.25,
            ..Default::default()
        };
        let m = ogrid(&p).unwrap().mesh;
        assert_eq!(m.dim, 3);
        assert_eq!(m.n_elements(), layers * 32 * 16);
        assert_eq!(m.reoriented, 0);
        assert!(m.min_scaled_jacobian().unwrap().0 > 0.0);
        assert!(max_aspect_ratio(&m) > 1e3);
        let names: Vec<&str> = m.tag_names.values().map(|s| s.as_str()).collect();
        assert_eq!(names, ["wall", "farfield", "zmin", "zmax"]);
        let c = cgrid(&BoundaryLayer {
            wall: Wall::Naca { thickness: 0.12 },
            wake: 8,
            ..p
        })
        .unwrap()
        .mesh;
        assert_eq!(c.n_elements(), layers * (32 + 16) * 16);
        assert!(c.min_scaled_jacobian().unwrap().0 > 0.0);
    }
}

#[test]
fn generate_rejects_bad_boundary_layer_options_in_one_line() {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    for (i, args) in [
        &["cgrid", "--wall", "ellipse"][..],
        &["ogrid", "--across", "1"],
        &["ogrid", "--first-height", "1"],
        &["ogrid", "--growth", "0.9"],
        &["ogrid", "--wall", "naca", "--around", "33"],
        &["ogrid", "--thickness", "0"],
        &["ogrid", "--farfield", "0.5"],
        &["ogrid", "--layers", "2", "--span", "0"],
        &["cgrid", "--wake", "0"],
        &["ogrid", "--elements", "100"],
        // Options of another kind are refused, not ignored.
        &["disc", "--elements", "100", "--bump", "0.2"],
        &["ogrid", "--sector", "20"],
        &["ogrid", "--wake", "8"],
        &["channel", "--farfield", "5"],
        &["sector", "--bump", "0.1"],
        &["cylinder", "--elements", "100", "--layers", "2"],
    ]
    .iter()
    .enumerate()
    {
        let out = dir.join(format!("bl_bad_{i}.msh"));
        let _ = std::fs::remove_file(&out);
        let r = polyspline()
            .arg("generate")
            .args(*args)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        assert_eq!(r.status.code(), Some(1), "{args:?}");
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains("--"), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?}");
    }
}
