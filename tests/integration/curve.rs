//! The `curve` job end to end on real and generated meshes: every written mesh is read back and
//! checked, the sampled output represents the spline geometry exactly, and bad output paths
//! lose nothing.

use crate::common;

use polyspline::io::read_raw;
use polyspline::mesh::HighOrderMesh;
use polyspline::mesh::generate::{grid_2d, grid_3d, uniform};
use polyspline::mesh::high_order::lattice_point;
use polyspline::mesh::{LinearMesh, MeshOptions, Topology};
use polyspline::pipeline::{CurveError, CurveOptions, Geometry, LineSearchMode, curve};
use polyspline::quality::{CheckReport, lagrange_1d};
use polyspline::sample::{multilinear, sample};
use polyspline::spline::SplineSpace;
use std::path::{Path, PathBuf};
use std::process::Command;

fn scratch(name: &str) -> PathBuf {
    common::scratch_in("curve", name)
}

fn real_meshes() -> Vec<PathBuf> {
    let out = common::real_meshes();
    assert_eq!(out.len(), 17, "the bundled real meshes");
    out
}

fn options(order: usize, geometry: Geometry) -> CurveOptions {
    CurveOptions {
        order,
        geometry,
        fit: Default::default(),
        line_search_mode: LineSearchMode::Local,
        ..Default::default()
    }
}

fn read_back(path: &Path) -> HighOrderMesh {
    HighOrderMesh::from_raw(read_raw(path).unwrap()).unwrap()
}

/// Straight-sided output and the unfitted spline map at orders 2 and 3 on every real mesh: the
/// written files read back with the right size and no invalid element. Where the unfitted
/// map is not certified valid, `curve` refuses and writes nothing.
#[test]
fn straight_and_unfitted_on_every_real_mesh() {
    for mesh in real_meshes() {
        for order in [2, 3] {
            for geometry in [Geometry::Straight, Geometry::SplineInitial] {
                let name = format!(
                    "{}_{order}_{geometry:?}.msh",
                    mesh.file_stem().unwrap().to_string_lossy()
                );
                let out = scratch(&name);
                let _ = std::fs::remove_file(&out);
                match curve(&mesh, &out, &options(order, geometry)) {
                    Ok(r) => {
                        let back = read_back(&out);
                        assert_eq!(
                            (back.n_elements(), back.order),
                            (r.elements, order),
                            "{name}"
                        );
                        let check = CheckReport::new(&back);
                        assert_eq!(check.invalid, 0, "{name}");
                        assert_eq!(r.invalid_elements, 0);
                    }
                    Err(CurveError::Invalid { what, count, .. }) => {
                        assert_eq!(
                            geometry,
                            Geometry::SplineInitial,
                            "{name}: straight output must not fail"
                        );
                        assert!(what.contains("initial spline map") && count > 0);
                        assert!(!out.exists(), "{name}: nothing may be written");
                    }
                    Err(e) => panic!("{name}: {e}"),
                }
            }
        }
    }
}

/// The default fit on every real mesh at orders 2 and 3: certified valid output, checked again by sampling our
/// file and by Gmsh's own Jacobians; the fit moves the boundary closer to the input vertices
/// than the unfitted map.
#[test]
fn fitted_on_every_real_mesh() {
    let mut jobs = Vec::new();
    for mesh in real_meshes() {
        let name = format!("{}_fit.msh", mesh.file_stem().unwrap().to_string_lossy());
        let out = scratch(&name);
        let r = curve(&mesh, &out, &options(2, Geometry::SplineFitted))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(r.invalid_elements, 0);
        assert!(r.min_det_jacobian_bound.unwrap() > 0.0, "{name}");
        let back = read_back(&out);
        assert_eq!(CheckReport::new(&back).invalid, 0, "{name}");
        // Boundary vertices of the unfitted spline map, for comparison.
        let m = polyspline::io::read_mesh(&mesh, &MeshOptions::default()).unwrap();
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        let (unfitted, _) =
            polyspline::pipeline::boundary_deviation(&m, &t, &sample(&s, &m, &t, 1));
        assert!(
            r.boundary_vertex_deviation_max < 0.5 * unfitted
                || r.boundary_vertex_deviation_max < 1e-12,
            "{name}: boundary deviation {} fitted, {unfitted} unfitted",
            r.boundary_vertex_deviation_max
        );
        jobs.push(serde_json::json!({ "file": out, "probes": [] }));
    }
    assert_gmsh_finds_valid(&jobs, "fit");
}

/// Gmsh's Jacobians of every file in `jobs` are positive (signed in 2D too, by the probe: a
/// mirrored quad counts as inverted).
fn assert_gmsh_finds_valid(jobs: &[serde_json::Value], tag: &str) {
    let Some(results) = common::gmsh_probe(jobs, &scratch(&format!("{tag}_jobs.json"))) else {
        return;
    };
    for (v, job) in results.iter().zip(jobs) {
        let (lo, hi) = (
            v["min_det_jac"].as_f64().unwrap(),
            v["max_det_jac"].as_f64().unwrap(),
        );
        assert!(
            lo > 0.0 && hi >= lo,
            "{}: Gmsh finds det J in [{lo}, {hi}]",
            job["file"]
        );
    }
}

/// Uniform grids (and affine images) keep the identity map at orders 2–5 with the spline
/// geometry, unfitted and fitted.
#[test]
fn uniform_grids_reproduce_the_linear_map() {
    let affine = |p: [f64; 3]| {
        [
            2.0 * p[0] + 0.5 * p[1] + 1.0,
            -0.3 * p[0] + 1.5 * p[1] + 0.2 * p[2],
            0.1 * p[0] + p[2] * 0.8,
        ]
    };
    let mut g2 = grid_2d(&uniform(4, 1.0), &uniform(3, 1.0));
    let mut g3 = grid_3d(&uniform(3, 1.0), &uniform(3, 1.0), &uniform(2, 1.0));
    for p in g2.coords.iter_mut() {
        let q = affine(*p);
        *p = [q[0], q[1], 0.0];
    }
    for p in g3.coords.iter_mut() {
        *p = affine(*p);
    }
    for m in [g2, g3] {
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        for p in 2..=5 {
            let ho = sample(&s, &m, &t, p);
            for e in 0..m.n_elements() {
                let x = m.element_coords(e);
                for (n, &id) in ho.element(e).iter().enumerate() {
                    let l = lattice_point(p, m.dim, n);
                    let want = multilinear(m.dim, &x, l.map(|c| c as f64 / p as f64));
                    let got = ho.nodes[id as usize];
                    assert!(
                        (0..3).all(|k| (got[k] - want[k]).abs() < 1e-11),
                        "p={p} e={e}"
                    );
                }
            }
        }
        // The fit keeps an exactly reproduced map.
        let (c, _) = polyspline::fit::fit(&s, &m, &t, &Default::default(), |_, _| {}).unwrap();
        let s2 = SplineSpace {
            control_points: c,
            ..s.clone()
        };
        for e in 0..m.n_elements() {
            let want = multilinear(m.dim, &m.element_coords(e), [0.3, 0.6, 0.2]);
            let got = s2.eval(e, [0.3, 0.6, 0.2]);
            assert!(
                (0..3).all(|k| (got[k] - want[k]).abs() < 1e-6),
                "fitted e={e}"
            );
        }
    }
}

/// An order-p ≥ 2 output element is the spline element itself: its Lagrange interpolant,
/// evaluated anywhere, equals the spline map.
#[test]
fn sampled_elements_represent_the_spline_exactly() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/real/mfem/cylinder-hex.mesh");
    let m: LinearMesh = polyspline::io::read_mesh(&path, &MeshOptions::default()).unwrap();
    let t = Topology::build(&m);
    let s = SplineSpace::build(&m, &t);
    for p in [2, 3, 4] {
        let ho = sample(&s, &m, &t, p);
        let mut v = [vec![0.0; p + 1], vec![0.0; p + 1], vec![0.0; p + 1]];
        let mut d = vec![0.0; p + 1];
        for e in (0..m.n_elements()).step_by(7) {
            let u = [0.13, 0.71, 0.42];
            for k in 0..3 {
                lagrange_1d(p, u[k], &mut v[k], &mut d);
            }
            let mut x = [0.0; 3];
            for (n, &id) in ho.element(e).iter().enumerate() {
                let l = lattice_point(p, 3, n);
                let w = v[0][l[0]] * v[1][l[1]] * v[2][l[2]];
                for (xk, nk) in x.iter_mut().zip(ho.nodes[id as usize]) {
                    *xk += w * nk;
                }
            }
            let want = s.eval(e, u);
            assert!(
                (0..3).all(|k| (x[k] - want[k]).abs() < 1e-10),
                "p={p} e={e}: {x:?} vs {want:?}"
            );
        }
    }
}

/// Output problems: an unwritable place or the input itself; nothing is left behind.
#[test]
fn bad_outputs_lose_nothing() {
    // A folder of its own: other tests write (and briefly hold .tmp files) in `scratch("")`.
    let dir = scratch("lose_nothing");
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("input_copy.msh");
    std::fs::copy(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/generated/block_hex8_8.msh"),
        &input,
    )
    .unwrap();
    let before = std::fs::read(&input).unwrap();
    let e = curve(&input, &input, &options(2, Geometry::SplineFitted)).unwrap_err();
    assert!(
        e.to_string().contains("refusing to overwrite the input"),
        "{e}"
    );
    assert_eq!(std::fs::read(&input).unwrap(), before);
    let missing_dir = dir.join("no/such/dir/out.msh");
    let e = curve(&input, &missing_dir, &options(2, Geometry::SplineFitted)).unwrap_err();
    assert!(e.to_string().contains("cannot write"), "{e}");
    let e = curve(
        &input,
        &dir.join("out.xyz"),
        &options(2, Geometry::SplineFitted),
    )
    .unwrap_err();
    assert!(e.to_string().contains("unknown output format"), "{e}");
    // No temporary files are left next to the outputs.
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .filter(|f| f.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // The CLI says so in one line with exit status 1.
    let out = Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .arg("curve")
        .arg(&input)
        .arg("-o")
        .arg(&input)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("refusing to overwrite"));
}

/// The turbine cascade has thin boundary-layer cells that the full least-squares step inverts
/// or distorts: the global search (one factor, paper §2.3) holds every point back, the local one
/// only some, and both written meshes are certified valid, by us and by Gmsh.
#[test]
fn line_search_keeps_a_mesh_the_full_fit_would_invert_valid() {
    let mesh = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("meshes/real/su2-testcases/mesh_vki_turbine_prepbc.su2");
    for (mode, order) in [(LineSearchMode::Global, 2), (LineSearchMode::Local, 3)] {
        let out = scratch(&format!("turbine_{mode:?}.msh"));
        let mut o = options(order, Geometry::SplineFitted);
        o.line_search_mode = mode;
        let r = curve(&mesh, &out, &o).unwrap();
        let blend = r.blend.as_ref().unwrap();
        assert!(
            blend.invalid_at_full_step + blend.poor_at_full_step > 0,
            "the full step must invert or distort something here"
        );
        let alpha = r.line_search_alpha.unwrap();
        assert!(alpha < 1.0, "{mode:?}: alpha {alpha}");
        match mode {
            LineSearchMode::Global => assert_eq!(r.reduced_elements, r.elements),
            LineSearchMode::Local => {
                assert!(r.reduced_elements > 0 && r.reduced_elements < r.elements)
            }
        }
        assert!(r.min_det_jacobian_bound.unwrap() > 0.0);
        assert_eq!(CheckReport::new(&read_back(&out)).invalid, 0);
        let jobs = scratch(&format!("turbine_{mode:?}_jobs.json"));
        if let Some((lo, hi, _)) = common::gmsh_det_range(&out, &jobs) {
            assert!(lo > 0.0, "{mode:?}: Gmsh finds det J in [{lo}, {hi}]");
        }
    }
}

/// `--snap-boundary` puts boundary vertex nodes on the input vertices where that stays
/// certified valid, and leaves the others.
#[test]
fn snapping_the_boundary_keeps_the_certificate() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/real");
    for (rel, all) in [
        ("dealii/unstructured_refined_ball.msh", true),
        ("mfem/cylinder-hex.mesh", true),
        ("su2-testcases/n0012_113-33.su2", false),
    ] {
        let mesh = root.join(rel);
        let out = scratch(&format!(
            "snap_{}.msh",
            mesh.file_stem().unwrap().to_string_lossy()
        ));
        let mut o = options(3, Geometry::SplineFitted);
        let unsnapped = polyspline::pipeline::curve_in_memory(&mesh, &o).unwrap();
        o.snap_boundary = true;
        let r = curve(&mesh, &out, &o).unwrap();
        let m = polyspline::io::read_mesh(&mesh, &MeshOptions::default()).unwrap();
        let t = Topology::build(&m);
        let boundary = t.vertex_on_boundary.iter().filter(|&&b| b).count();
        // Only the vertices that really move count as snapped.
        let off = (0..m.n_vertices())
            .filter(|&v| t.vertex_on_boundary[v] && unsnapped.ho.nodes[v] != m.coords[v])
            .count();
        let snapped = r.snapped_boundary_vertices.unwrap();
        assert!(
            snapped <= off,
            "{rel}: {snapped} snapped, {off} off the input"
        );
        // Snapping moves vertex nodes only: the curved wall still stands off the linear one
        // at the edge nodes, and the report says so.
        assert!(
            r.boundary_node_distance_max > 0.0
                && r.boundary_node_distance_max
                    >= 0.5 * unsnapped.report.boundary_node_distance_max,
            "{rel}: node distance {} snapped, {} unsnapped",
            r.boundary_node_distance_max,
            unsnapped.report.boundary_node_distance_max
        );
        if all {
            assert_eq!(snapped, off, "{rel}");
            assert_eq!(r.boundary_vertex_deviation_max, 0.0, "{rel}");
        } else {
            // Thin trailing-edge cells: snaps that would invert them would be kept back.
            assert!(
                snapped > boundary / 2 && snapped <= boundary,
                "{rel}: {snapped} of {boundary}"
            );
        }
        let back = read_back(&out);
        assert_eq!(CheckReport::new(&back).invalid, 0, "{rel}");
        for v in 0..m.n_vertices() {
            if t.vertex_on_boundary[v] && back.nodes[v] == m.coords[v] {
                continue;
            }
            if all && t.vertex_on_boundary[v] {
                panic!("{rel}: boundary vertex {v} not on the input");
            }
        }
    }
}

/// `plot` draws each element edge once, as a curve through the edge's nodes.
#[test]
fn plot_draws_every_edge_through_its_nodes() {
    let mesh = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("meshes/real/dealii/unstructured_refined_ball.msh");
    let out = scratch("ball_p3.msh");
    curve(&mesh, &out, &options(3, Geometry::SplineFitted)).unwrap();
    let ho = read_back(&out);
    let lines = polyspline::plot::edge_polylines(&ho);
    let m = polyspline::io::read_mesh(&mesh, &MeshOptions::default()).unwrap();
    assert_eq!(lines.len(), Topology::build(&m).edges.len());
    // Each polyline starts and ends at element corners and passes through the edge's nodes
    // (the samples at 0, 1/3, 2/3, 1 of 16 segments are not all nodes; check the ends and
    // that the middle of the curve is off the chord somewhere, i.e. edges are drawn curved).
    let mut curved = 0;
    for l in &lines {
        let (a, b) = (l[0], l[l.len() - 1]);
        let mid = l[l.len() / 2];
        let chord = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
        if ((mid[0] - chord[0]).powi(2) + (mid[1] - chord[1]).powi(2)).sqrt() > 1e-6 {
            curved += 1;
        }
        assert!(
            ho.nodes
                .iter()
                .any(|n| (n[0] - a[0]).abs() < 1e-12 && (n[1] - a[1]).abs() < 1e-12)
        );
    }
    assert!(
        curved > lines.len() / 10,
        "{curved} of {} edges curved",
        lines.len()
    );
    let svg = polyspline::plot::render_svg(
        &[polyspline::plot::Layer::Mesh {
            mesh: &ho,
            colour: "black",
            width: 1.0,
            label: "m",
        }],
        800.0,
    );
    assert_eq!(svg.matches("<polyline").count(), lines.len());
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
}

/// The smooth-boundary fit (the default, with Q2 elements at kinks of the boundary grid lines)
/// on every real mesh at orders 2 and 3: written, certified valid (our certificate, the sampled
/// check of the file read back, and Gmsh's own Jacobians); prints how far from the input
/// vertices it stays, how many steps the line search shortened and how many elements it made
/// Q2, next to the paper's `position` fit.
#[test]
fn smooth_fit_on_every_real_mesh() {
    let mut jobs = Vec::new();
    for mesh in real_meshes() {
        let stem = mesh.file_stem().unwrap().to_string_lossy().to_string();
        let mut line = format!("{stem:40}");
        for (mode, fit, order) in [
            ("position", polyspline::fit::FitParams::default(), 2),
            ("smooth", polyspline::fit::FitParams::smooth(), 2),
            ("smooth", polyspline::fit::FitParams::smooth(), 3),
        ] {
            let out = scratch(&format!("{stem}_{mode}_{order}.msh"));
            let mut o = options(order, Geometry::SplineFitted);
            o.fit = fit;
            let r = curve(&mesh, &out, &o)
                .unwrap_or_else(|e| panic!("{stem} {mode} order {order}: {e}"));
            assert_eq!(r.invalid_elements, 0);
            assert!(r.min_det_jacobian_bound.unwrap() > 0.0, "{stem} {mode}");
            let back = read_back(&out);
            assert_eq!(back.order, order);
            assert_eq!(CheckReport::new(&back).invalid, 0, "{stem} {mode}");
            if mode == "position" {
                assert_eq!(r.kink_elements, 0, "{stem}: kinks only with the smooth fit");
            } else {
                jobs.push(serde_json::json!({ "file": out, "probes": [] }));
            }
            if order == 2 {
                line += &format!(
                    " | {mode}: dev {:.2e} msj {:.3} invalid_full {} damped {} demoted {} kinks {}",
                    r.boundary_vertex_deviation_max,
                    r.min_scaled_jacobian,
                    r.invalid_at_full_step,
                    r.damped_control_points,
                    r.demoted_elements,
                    r.kink_elements
                );
            }
        }
        println!("{line}");
    }
    assert_gmsh_finds_valid(&jobs, "smooth");
}

/// `plot --control-points` draws one disc per control point of the spline space.
#[test]
fn plot_shows_the_control_points() {
    let mesh =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/generated/star5_quad4_20.msh");
    let svg = scratch("star_cp.svg");
    common::run_ok(
        Command::new(env!("CARGO_BIN_EXE_polyspline"))
            .args(["plot", "--control-points", "-o"])
            .arg(&svg)
            .arg(&mesh),
    );
    let text = std::fs::read_to_string(&svg).unwrap();
    let m = polyspline::io::read_mesh(&mesh, &MeshOptions::default()).unwrap();
    let s = SplineSpace::build(&m, &Topology::build(&m));
    assert_eq!(text.matches("<circle").count(), s.n_control_points());
    // 3D meshes are refused with a message.
    let hex = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/generated/block_hex8_8.msh");
    let out = Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .args(["plot", "-o"])
        .arg(scratch("b.svg"))
        .arg(&hex)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("2D"));
}

/// `plot` of a linear mesh draws each edge of the mesh once, as a straight polyline from one of
/// its vertices to the other. The picture's scale and offset are read off the picture itself
/// (its extreme points against the mesh's bounding box), so a polyline through the wrong
/// nodes, a missing or doubled edge or a distorted picture fails.
#[test]
fn plot_draws_every_edge_through_its_vertices() {
    let mesh =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/generated/star5_quad4_20.msh");
    let svg = scratch("star_edges.svg");
    common::run_ok(
        Command::new(env!("CARGO_BIN_EXE_polyspline"))
            .args(["plot", "-o"])
            .arg(&svg)
            .arg(&mesh),
    );
    let text = std::fs::read_to_string(&svg).unwrap();
    let lines: Vec<Vec<[f64; 2]>> = text
        .lines()
        .filter_map(|l| l.strip_prefix("<polyline points=\""))
        .map(|l| {
            l.trim_end_matches("\"/>")
                .split(' ')
                .map(|xy| {
                    let (a, b) = xy.split_once(',').unwrap();
                    [a.parse().unwrap(), b.parse().unwrap()]
                })
                .collect()
        })
        .collect();
    let m = polyspline::io::read_mesh(&mesh, &MeshOptions::default()).unwrap();
    // The mesh's edges (quads counter-clockwise), as vertex pairs.
    let mut edges = std::collections::BTreeSet::new();
    for q in m.elements.chunks(4) {
        for k in 0..4 {
            let (a, b) = (q[k], q[(k + 1) % 4]);
            edges.insert((a.min(b), a.max(b)));
        }
    }
    // Picture coordinates: (x − x0) s + a0 across, (y1 − y) s + b0 down.
    let (lo, hi) = m.bounding_box();
    let ext = |k: usize, f: fn(f64, f64) -> f64, init: f64| {
        lines.iter().flatten().map(|p| p[k]).fold(init, f)
    };
    let (a0, a1) = (ext(0, f64::min, f64::MAX), ext(0, f64::max, f64::MIN));
    let (b0, b1) = (ext(1, f64::min, f64::MAX), ext(1, f64::max, f64::MIN));
    let s = (a1 - a0) / (hi[0] - lo[0]);
    assert!(
        ((b1 - b0) / (hi[1] - lo[1]) - s).abs() < 1e-3 * s,
        "unequal scales"
    );
    let to_mesh = |p: [f64; 2]| [lo[0] + (p[0] - a0) / s, hi[1] - (p[1] - b0) / s];
    // Coordinates are printed to 0.01 pixel.
    let tol = 0.02 / s;
    let vertex_at = |x: [f64; 2]| {
        (0..m.coords.len())
            .find(|&v| common::dist([x[0], x[1], 0.0], m.coords[v]) <= tol)
            .unwrap_or_else(|| panic!("{x:?} is no vertex of the mesh"))
    };
    let mut drawn = std::collections::BTreeSet::new();
    for l in &lines {
        let (u, v) = (
            vertex_at(to_mesh(l[0])) as u32,
            vertex_at(to_mesh(*l.last().unwrap())) as u32,
        );
        assert!(
            edges.contains(&(u.min(v), u.max(v))),
            "({u}, {v}) is no edge"
        );
        assert!(drawn.insert((u.min(v), u.max(v))), "({u}, {v}) drawn twice");
        let (p, q) = (m.coords[u as usize], m.coords[v as usize]);
        let len = common::dist(p, q);
        for &x in l {
            let x = to_mesh(x);
            // Distance from the straight edge.
            let off = ((q[0] - p[0]) * (x[1] - p[1]) - (q[1] - p[1]) * (x[0] - p[0])).abs() / len;
            assert!(off <= tol, "({u}, {v}): {x:?} is {off:e} off the edge");
        }
    }
    assert_eq!(drawn, edges, "edges drawn");
}

/// `--order 1 --subdivide K` writes a valid refined linear mesh on the curved geometry.
#[test]
fn subdivided_output_is_valid() {
    let mesh = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("meshes/real/dealii/unstructured_refined_ball.msh");
    for (k, file) in [(3, "ball_sub3.msh"), (2, "ball_sub2.vtu")] {
        let out = scratch(file);
        let mut o = options(1, Geometry::SplineFitted);
        o.subdivide = Some(k);
        let r = curve(&mesh, &out, &o).unwrap();
        assert_eq!(r.output_elements, r.elements * k * k);
        let back = read_back(&out);
        assert_eq!((back.order, back.n_elements()), (1, r.elements * k * k));
        assert_eq!(CheckReport::new(&back).invalid, 0);
    }
}

/// Progress goes through the callback: every stage of the report's timings is announced in
/// order, the fit's CG iterations are counted, and the command line prints no spinner when
/// stderr is not a terminal (here a pipe), with or without `--quiet`.
#[test]
fn progress_reports_stages_and_stays_off_stderr_pipes() {
    use polyspline::progress::{Progress, Stage};
    use std::sync::Mutex;
    #[derive(Default)]
    struct Log(Mutex<(Vec<String>, usize)>);
    impl Progress for Log {
        fn finished(&self, stage: Stage) {
            self.0.lock().unwrap().0.push(stage.key().to_string());
        }
        fn cg(&self, iteration: usize, _: f64) {
            self.0.lock().unwrap().1 = iteration;
        }
    }
    let input =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/real/mfem/cylinder-hex.mesh");
    let out = scratch("progress.msh");
    let log = Log::default();
    let r = polyspline::pipeline::curve_with_progress(
        &input,
        &out,
        &options(2, Geometry::SplineFitted),
        &log,
    )
    .unwrap();
    let (stages, cg) = log.0.into_inner().unwrap();
    for s in [
        "read", "topology", "spline", "fit", "validity", "sample", "quality",
    ] {
        assert!(stages.iter().any(|x| x == s), "{s} missing from {stages:?}");
        assert!(r.timings.contains_key(s));
    }
    assert_eq!(stages[0], "read");
    assert!(
        cg > 0 && Some(cg) <= r.cg_iterations,
        "{cg} vs {:?}",
        r.cg_iterations
    );
    for quiet in [false, true] {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_polyspline"));
        cmd.args([
            "curve",
            input.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]);
        if quiet {
            cmd.arg("-q");
        }
        let o = cmd.output().unwrap();
        assert!(o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        // The spinner's line (not the summary's "N CG iterations, relative residual …").
        assert!(
            !err.contains("fit: CG iteration ") && !err.contains('\r'),
            "{err}"
        );
    }
}

/// `curve` on hsphere8 with `args`, writing `name`.msh: the process's output and the report
/// (`Null` where the run failed, having written nothing).
fn curve_hsphere8(name: &str, args: &[&str]) -> (std::process::Output, serde_json::Value) {
    let mesh = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/real/sfepy/hsphere8.vtk");
    let out = scratch(&format!("{name}.msh"));
    let (o, report) = common::curve_with_report(&mesh, &out, args);
    let r = match report {
        Some(report) => serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap(),
        None => {
            assert!(!out.exists(), "{name}: nothing may be written");
            serde_json::Value::Null
        }
    };
    (o, r)
}

/// `--kink-angle` on the command line: the smooth fit (the default) makes the elements at
/// kinks of a cubed sphere's boundary grid lines Q2 and says how many, in the report and on the
/// terminal; 180 turns it off, the paper's presets never use it, and a non-positive angle is
/// refused before anything is written.
#[test]
fn kink_angle_on_the_command_line() {
    let (o, on) = curve_hsphere8("kinks_default", &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let kinks = on["kink_elements"].as_u64().unwrap();
    assert!(kinks > 0, "the cubed sphere's block arcs kink");
    assert!(String::from_utf8_lossy(&o.stderr).contains(&format!("({kinks} at boundary kinks)")));
    let (_, off) = curve_hsphere8("kinks_off", &["--kink-angle", "180"]);
    assert_eq!(off["kink_elements"], 0);
    assert!(on["q2_elements"].as_u64().unwrap() > off["q2_elements"].as_u64().unwrap());
    for preset in ["position", "frame"] {
        let (_, r) = curve_hsphere8(&format!("kinks_{preset}"), &["--fit", preset]);
        assert_eq!(r["kink_elements"], 0, "{preset}");
    }
    for bad in ["0", "-5", "nan"] {
        let (o, _) = curve_hsphere8("kinks_bad", &[&format!("--kink-angle={bad}")]);
        assert_eq!(o.status.code(), Some(1), "--kink-angle {bad}");
        assert!(String::from_utf8_lossy(&o.stderr).contains("--kink-angle"));
    }
}

/// `--interior-kink-angle` on the command line: on hsphere8 (its interior grid lines turn by
/// 47.8° and 36.7° next to the valence-3 line) 35° redoes the pass, which holds back 72 of 648
/// elements by default (the option off, 180), with the elements at those turns Q2: at most a
/// tenth held back and more Q2 elements; 40° takes only the 47.8° turns, whose redo is not
/// kept; the report records the angle; the paper's presets refuse it; a non-positive angle is
/// refused before anything is written.
#[test]
fn interior_kink_angle_on_the_command_line() {
    let count = |r: &serde_json::Value, key: &str| r[key].as_u64().unwrap();
    let (o, on) = curve_hsphere8("interior_35", &["--interior-kink-angle", "35"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (_, off) = curve_hsphere8("interior_default", &[]);
    let (_, wide) = curve_hsphere8("interior_40", &["--interior-kink-angle", "40"]);
    let elements = count(&on, "elements");
    eprintln!(
        "held back: 35° {}, default (off) {}, 40° {}; Q2: {}, {}, {}",
        count(&on, "reduced_elements"),
        count(&off, "reduced_elements"),
        count(&wide, "reduced_elements"),
        count(&on, "q2_elements"),
        count(&off, "q2_elements"),
        count(&wide, "q2_elements")
    );
    assert!(10 * count(&on, "reduced_elements") <= elements);
    assert!(10 * count(&off, "reduced_elements") > elements);
    assert!(count(&on, "q2_elements") > count(&off, "q2_elements"));
    assert!(count(&wide, "q2_elements") < count(&on, "q2_elements"));
    for (r, deg) in [(&on, 35.0), (&off, 180.0), (&wide, 40.0)] {
        assert_eq!(
            r["fit_targets"]["smooth"]["interior_kink_angle_deg"].as_f64(),
            Some(deg)
        );
    }
    let (o, _) = curve_hsphere8(
        "interior_position",
        &["--fit", "position", "--interior-kink-angle", "20"],
    );
    assert_eq!(o.status.code(), Some(1), "--fit position");
    assert!(String::from_utf8_lossy(&o.stderr).contains("--interior-kink-angle"));
    for bad in ["0", "-5", "nan"] {
        let (o, _) = curve_hsphere8("interior_bad", &[&format!("--interior-kink-angle={bad}")]);
        assert_eq!(o.status.code(), Some(1), "--interior-kink-angle {bad}");
        assert!(String::from_utf8_lossy(&o.stderr).contains("--interior-kink-angle"));
    }
}

/// The same input and options give the same bytes on any number of threads: every float
/// reduction that decides the output (CG dot products, right-hand side, block-Jacobi
/// aggregates, the sparse Cholesky of small fits) has a fixed order. The cylinder is large
/// enough for several parallel blocks (CG); the disc is a 2D fit small enough to be factored.
#[test]
fn output_does_not_depend_on_the_thread_count() {
    for (shape, elements) in [("cylinder", "12000"), ("disc", "3000")] {
        let input = scratch(&format!("threads_{shape}_in.msh"));
        common::run_ok(
            common::polyspline()
                .args(["generate", shape, "--elements", elements, "-o"])
                .arg(&input),
        );
        let files: Vec<Vec<u8>> = ["1", "3"]
            .into_iter()
            .map(|threads| {
                let out = scratch(&format!("threads_{shape}_{threads}.msh"));
                common::run_ok(
                    common::polyspline()
                        .env("RAYON_NUM_THREADS", threads)
                        .arg("curve")
                        .arg(&input)
                        .arg("-o")
                        .arg(&out),
                );
                std::fs::read(&out).unwrap()
            })
            .collect();
        assert!(
            files[0] == files[1],
            "{shape}: outputs on 1 and 3 threads differ"
        );
    }
}

/// The fit's two solvers solve the same system. On a small unstructured 2D mesh (the ball:
/// post-fit Q2 rounds, 1.4k control points) the automatic choice factors it, to a residual
/// at rounding, and its output nodes are those of the CG fit to within what CG's relative
/// residual of 1e-6 leaves (the same Q2 elements chosen, the same validity); a 3D mesh over
/// the 3D limit stays with CG.
#[test]
fn cholesky_and_cg_fits_agree() {
    use polyspline::fit::{FitParams, FitSolver};
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/real");
    let input = root.join("dealii/unstructured_refined_ball.msh");
    let mut runs = Vec::new();
    for solver in [FitSolver::Auto, FitSolver::Cg] {
        let out = scratch(&format!("solver_{solver:?}.msh"));
        let o = CurveOptions {
            fit: FitParams {
                solver,
                ..FitParams::smooth()
            },
            ..Default::default()
        };
        let r = curve(&input, &out, &o).unwrap();
        assert_eq!(r.invalid_elements, 0);
        runs.push((r, read_back(&out)));
    }
    let ((auto, a), (cg, c)) = (&runs[0], &runs[1]);
    assert_eq!(auto.fit_solver, Some(FitSolver::Cholesky));
    assert!(
        auto.cg_rel_residual.unwrap() < 1e-12,
        "{:?}",
        auto.cg_rel_residual
    );
    assert_eq!(cg.fit_solver, Some(FitSolver::Cg));
    assert!(cg.cg_iterations.unwrap() > 0);
    assert_eq!(auto.q2_elements, cg.q2_elements);
    assert_eq!(a.nodes.len(), c.nodes.len());
    let diag = auto.bounding_box_diagonal;
    let gap = common::max_coordinate_gap(&a.nodes, &c.nodes);
    assert!(
        gap < 1e-5 * diag,
        "nodes {:.2e} of the diagonal apart",
        gap / diag
    );
    let hex = root.join("mfem/cylinder-hex.mesh");
    let r = curve(&hex, &scratch("solver_hex.msh"), &Default::default()).unwrap();
    assert_eq!(
        r.fit_solver,
        Some(FitSolver::Cg),
        "1.7k control points in 3D"
    );
}
