//! The elastic-analogy baseline (paper §2.5) and the `compare` job.
//!
//! Oracles: rigid motions and linear displacement fields are exact solutions of linear
//! elasticity without body forces, and isoparametric Lagrange elements on straight-sided
//! (multilinear) geometry contain them, so the discrete solution must reproduce them (patch
//! test); the facet angle jump of a hand-made mesh is computed by hand.

use polyspline::compare::facet_angle_jumps;
use polyspline::elastic::{
    ElasticParams, ElasticPreconditioner, ElasticSolver, elastic_analogy, solve_displacement,
    solve_displacement_with_progress,
};
use polyspline::mesh::HighOrderMesh;
use polyspline::mesh::generate::{grid_2d, grid_3d};
use polyspline::mesh::{LinearMesh, Topology};
use polyspline::pipeline::{CurveOptions, Geometry, Method, curve_in_memory};
use polyspline::sample::sample;
use polyspline::solve::CgParams;
use std::ffi::OsString;
use std::path::Path;
use std::process::{Command, Output};

fn tight() -> ElasticParams {
    ElasticParams {
        cg: CgParams {
            rel_tol: 1e-13,
            abs_tol: 1e-14,
            max_iters: 20_000,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// A graded grid with its interior vertices moved off the grid lines (straight-sided, but no
/// two elements alike).
fn distorted(dim: usize) -> (LinearMesh, Topology) {
    let xs = [0.0, 0.3, 0.7, 1.2, 1.5];
    let ys = [0.0, 0.4, 0.9, 1.1];
    let mut mesh = if dim == 2 {
        grid_2d(&xs, &ys)
    } else {
        grid_3d(&xs[..4], &ys, &[0.0, 0.5, 0.8, 1.3])
    };
    let topo = Topology::build(&mesh);
    for (v, x) in mesh.coords.iter_mut().enumerate() {
        if !topo.vertex_on_boundary[v] {
            let s = v as f64;
            x[0] += 0.05 * (1.3 * s).sin();
            x[1] += 0.05 * (0.7 * s).cos();
            if dim == 3 {
                x[2] += 0.04 * (2.1 * s).sin();
            }
        }
    }
    let topo = Topology::build(&mesh);
    (mesh, topo)
}

fn straight(dim: usize, p: usize) -> HighOrderMesh {
    let (mesh, topo) = distorted(dim);
    sample(&mesh, &mesh, &topo, p)
}

/// Boundary nodes displaced by `field`; everything else free.
fn prescribe(ho: &HighOrderMesh, field: impl Fn([f64; 3]) -> [f64; 3]) -> Vec<Option<[f64; 3]>> {
    let mut out = vec![None; ho.nodes.len()];
    for &n in &ho.boundary {
        out[n as usize] = Some(field(ho.nodes[n as usize]));
    }
    out
}

#[test]
fn zero_boundary_displacement_leaves_the_mesh_unchanged() {
    for dim in [2, 3] {
        for p in [1, 2, 3] {
            let ho = straight(dim, p);
            let (moved, info) = elastic_analogy(&ho, &ho, &ElasticParams::default()).unwrap();
            assert_eq!(moved.nodes, ho.nodes, "{dim}D order {p}");
            assert_eq!(moved.elements, ho.elements);
            assert!(info.unknowns > 0);
        }
    }
}

/// The elastic analogy's CG reports every iteration to its monitor, which may stop it (a
/// job's progress receiver, Ctrl-C in the Python package): run to its end the monitor sees
/// iterations 1 to the count the solve reports; asked to stop once it has seen iteration 5 the
/// solve ends there with `CgError::Cancelled`.
#[test]
fn the_elastic_cg_reports_to_its_monitor_and_stops_when_asked() {
    let ho = straight(3, 2);
    let params = ElasticParams {
        solver: ElasticSolver::Cg,
        ..tight()
    };
    let shear = |x: [f64; 3]| [0.05 * x[1], -0.03 * x[2], 0.02 * x[0] * x[1]];
    let prescribed = prescribe(&ho, shear);
    let mut seen = Vec::new();
    let (_, info) =
        solve_displacement_with_progress(&ho, &prescribed, &params, &mut |i: usize, _: f64| {
            seen.push(i)
        })
        .unwrap();
    assert!(info.cg.iterations > 5, "{} iterations", info.cg.iterations);
    assert_eq!(seen, (1..=info.cg.iterations).collect::<Vec<_>>());
    let last = std::cell::Cell::new(0usize);
    let mut stop = polyspline::solve::Cancellable {
        progress: |i: usize, _: f64| last.set(i),
        cancelled: || last.get() >= 5,
    };
    let e = solve_displacement_with_progress(&ho, &prescribed, &params, &mut stop).unwrap_err();
    assert!(
        matches!(
            e,
            polyspline::elastic::ElasticError::Solve(polyspline::solve::CgError::Cancelled {
                iterations: 5
            })
        ),
        "{e}"
    );
}

#[test]
fn rigid_translation_of_the_boundary_translates_every_node() {
    let c = [0.3, -0.2, 0.15];
    for dim in [2, 3] {
        for p in [1, 2, 3] {
            let ho = straight(dim, p);
            let t = [c[0], c[1], if dim == 3 { c[2] } else { 0.0 }];
            for solver in [ElasticSolver::Cg, ElasticSolver::Cholesky] {
                let params = ElasticParams { solver, ..tight() };
                let (u, info) = solve_displacement(&ho, &prescribe(&ho, |_| t), &params).unwrap();
                assert_eq!(info.solver, solver);
                assert_eq!(info.cg.iterations > 0, solver == ElasticSolver::Cg);
                for (n, u) in u.iter().enumerate() {
                    for k in 0..3 {
                        assert!((u[k] - t[k]).abs() < 1e-9, "{dim}D p{p} node {n}: {u:?}");
                    }
                }
            }
        }
    }
}

#[test]
fn linear_boundary_displacement_gives_the_linear_field_inside() {
    // u(x) = A x + c, with a symmetric and a rotational part.
    let a = [
        [0.10, -0.05, 0.02],
        [0.07, -0.08, 0.03],
        [-0.04, 0.06, 0.05],
    ];
    let c = [0.01, 0.02, -0.03];
    for dim in [2, 3] {
        let field = |x: [f64; 3]| -> [f64; 3] {
            std::array::from_fn(|i| {
                if i < dim {
                    c[i] + (0..dim).map(|j| a[i][j] * x[j]).sum::<f64>()
                } else {
                    0.0
                }
            })
        };
        for p in [1, 2, 3] {
            let ho = straight(dim, p);
            for (solver, pre) in [
                (ElasticSolver::Cg, ElasticPreconditioner::BlockJacobi),
                (ElasticSolver::Cg, ElasticPreconditioner::Jacobi),
                (ElasticSolver::Cg, ElasticPreconditioner::BlockSgs),
                (ElasticSolver::Cholesky, ElasticPreconditioner::BlockJacobi),
            ] {
                let params = ElasticParams {
                    preconditioner: pre,
                    solver,
                    ..tight()
                };
                let (u, info) = solve_displacement(&ho, &prescribe(&ho, field), &params).unwrap();
                let free = ho.nodes.len() - info.prescribed_nodes;
                assert!(free > 0 && info.unknowns == free * dim);
                let mut worst = 0.0f64;
                for (n, x) in ho.nodes.iter().enumerate() {
                    let want = field(*x);
                    for k in 0..3 {
                        worst = worst.max((u[n][k] - want[k]).abs());
                    }
                }
                assert!(
                    worst < 1e-9,
                    "{dim}D p{p} {solver:?} {pre:?}: error {worst:e}"
                );
                assert_eq!(info.solver, solver);
                assert!(info.cg.rel_residual < 1e-12, "{:e}", info.cg.rel_residual);
                eprintln!(
                    "patch test {dim}D p{p} {solver:?} {pre:?}: {} CG iterations, max error {worst:.1e}",
                    info.cg.iterations
                );
            }
        }
    }
}

/// With Jacobian stiffening the material is no longer homogeneous, so a general linear field
/// is not an equilibrium any more; a rigid motion (a translation plus an infinitesimal
/// rotation, u = c + W x with W skew-symmetric) has no strain and stays exact for every
/// stiffening exponent, through both solvers.
#[test]
fn stiffened_material_still_moves_rigidly() {
    let w = [[0.0, -0.07, 0.03], [0.07, 0.0, -0.05], [-0.03, 0.05, 0.0]];
    let c = [0.02, -0.01, 0.04];
    for dim in [2, 3] {
        let field = |x: [f64; 3]| -> [f64; 3] {
            std::array::from_fn(|i| {
                if i < dim {
                    c[i] + (0..dim).map(|j| w[i][j] * x[j]).sum::<f64>()
                } else {
                    0.0
                }
            })
        };
        let ho = straight(dim, 2);
        for stiffening in [1.0, 2.0] {
            for solver in [ElasticSolver::Cg, ElasticSolver::Cholesky] {
                let params = ElasticParams {
                    stiffening,
                    solver,
                    ..tight()
                };
                let (u, _) = solve_displacement(&ho, &prescribe(&ho, field), &params).unwrap();
                let worst = ho
                    .nodes
                    .iter()
                    .zip(&u)
                    .flat_map(|(x, u)| {
                        let want = field(*x);
                        (0..3).map(move |k| (u[k] - want[k]).abs())
                    })
                    .fold(0.0, f64::max);
                assert!(
                    worst < 1e-9,
                    "{dim}D chi {stiffening} {solver:?}: {worst:e}"
                );
            }
        }
        // The stiffening changes a non-rigid solution: it is not ignored.
        let shear = |x: [f64; 3]| -> [f64; 3] { [0.1 * x[1] * x[1], 0.0, 0.0] };
        let solve = |stiffening| {
            let params = ElasticParams {
                stiffening,
                ..tight()
            };
            solve_displacement(&ho, &prescribe(&ho, shear), &params)
                .unwrap()
                .0
        };
        let (a, b) = (solve(0.0), solve(1.0));
        let gap = a
            .iter()
            .zip(&b)
            .map(|(a, b)| (a[0] - b[0]).abs())
            .fold(0.0, f64::max);
        assert!(gap > 1e-6, "{dim}D: stiffening changed nothing ({gap:e})");
    }
}

/// A tangled elastic result is moved back towards the straight mesh until every element is
/// certified: the elements away from the tangle keep their nodes, and every node that moved
/// lies on the segment from its straight position to its elastic one.
#[test]
fn hold_back_makes_a_tangled_mesh_valid_and_touches_only_its_neighbourhood() {
    use polyspline::elastic::hold_back_invalid;
    use polyspline::validity::lagrange_element_bounds;
    for dim in [2, 3] {
        let ho = straight(dim, 2);
        let mut moved = ho.clone();
        // A smooth small displacement everywhere, and one interior vertex node thrown far
        // through its neighbours.
        for x in moved.nodes.iter_mut() {
            x[0] += 0.01 * (3.0 * x[1]).sin();
        }
        let interior = (0..ho.nodes.len())
            .find(|&n| {
                !ho.boundary.contains(&(n as u32))
                    && ho.elements.iter().filter(|&&m| m as usize == n).count() == 1 << dim
            })
            .expect("an interior vertex node");
        moved.nodes[interior][0] += 0.45;
        let certify =
            |m: &HighOrderMesh, e: usize| lagrange_element_bounds(m, e, 6).certified_positive();
        let bad_before = (0..moved.n_elements())
            .filter(|&e| !certify(&moved, e))
            .count();
        assert!(bad_before > 0, "{dim}D: the tangle is not tangled");
        let elastic = moved.clone();
        let (left, held) = hold_back_invalid(&ho, &mut moved, certify);
        assert!(left.is_empty(), "{dim}D: {left:?}");
        assert!((0..moved.n_elements()).all(|e| certify(&moved, e)));
        assert!(held.nodes > 0 && held.min_fraction < 1.0);
        assert_eq!(
            held.boundary_nodes, 0,
            "{dim}D: the boundary was not involved"
        );
        let mut changed = 0;
        for n in 0..ho.nodes.len() {
            let (s, e, m) = (ho.nodes[n], elastic.nodes[n], moved.nodes[n]);
            if m != e {
                changed += 1;
                // m = s + f (e − s) for one f in [0, 1).
                let k = (0..dim)
                    .max_by(|&a, &b| (e[a] - s[a]).abs().total_cmp(&(e[b] - s[b]).abs()))
                    .unwrap();
                let f = (m[k] - s[k]) / (e[k] - s[k]);
                assert!((0.0..1.0).contains(&f), "{f}");
                for c in 0..dim {
                    assert!((m[c] - (s[c] + f * (e[c] - s[c]))).abs() < 1e-12);
                }
            }
        }
        assert_eq!(changed, held.nodes);
        assert!(
            changed < ho.nodes.len() / 2,
            "{dim}D: {changed} of {} nodes moved",
            ho.nodes.len()
        );
    }
}

/// The elastic analogy on the boundary-layer C-grid around NACA 0012 (aspect ratios near
/// 10⁴, where block-Jacobi CG stalls): the system is solved to rounding, the mesh is
/// certified by us and valid by Gmsh's Jacobians, and `compare` keeps every method.
#[test]
fn elastic_analogy_runs_on_the_naca0012_boundary_layer_grid() {
    let out = polyspline_ok([
        OsString::from("compare"),
        "--json".into(),
        root("meshes/real/su2-testcases/n0012_113-33.su2").into(),
    ]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    crate::common::compare_rows_all_valid(&v);
    let el = curved(
        "meshes/real/su2-testcases/n0012_113-33.su2",
        Method::Elastic(ElasticParams::default()),
    );
    let info = el.report.elastic.unwrap();
    assert_eq!(info.solver, ElasticSolver::Cholesky);
    assert!(info.cg.rel_residual < 1e-8, "{:e}", info.cg.rel_residual);
    assert!(el.report.min_det_jacobian_bound.unwrap() > 0.0);
    // Valid by Gmsh's Jacobians too, signed (a mirrored quad fails).
    let out = crate::common::test_dir().join("n0012_elastic.msh");
    polyspline::pipeline::write_high_order(&el.ho, &out, &Default::default(), &[]).unwrap();
    let jobs = out.with_extension("json");
    if let Some((lo, hi, _)) = crate::common::gmsh_det_range(&out, &jobs) {
        assert!(lo > 0.0, "Gmsh finds det J in [{lo:e}, {hi:e}]");
    }
}

#[test]
fn bad_material_is_an_error() {
    let ho = straight(2, 2);
    for (young, poisson) in [(1.5, 0.5), (0.0, 0.3), (1.0, -1.0), (f64::NAN, 0.3)] {
        let params = ElasticParams {
            young,
            poisson,
            ..Default::default()
        };
        let e = elastic_analogy(&ho, &ho, &params).unwrap_err();
        assert!(e.to_string().contains("elastic material"), "{e}");
    }
}

#[test]
fn angle_jump_of_a_kinked_mesh_line() {
    // Two unit squares side by side; the right one's far top corner is raised by h. Across the
    // shared edge the left element's transversal derivative is (1, 0); the right element's,
    // at the edge midpoint, is the mean of its bottom (1, 0) and top (1, h) edge vectors.
    let h = 0.6;
    let mut mesh = grid_2d(&[0.0, 1.0, 2.0], &[0.0, 1.0]);
    mesh.coords[5][1] += h;
    let topo = Topology::build(&mesh);
    let ho = sample(&mesh, &mesh, &topo, 2);
    let s = facet_angle_jumps(&mesh, &topo, &ho);
    let want = (h / 2.0f64).atan().to_degrees();
    assert_eq!(s.interior.facets, 0);
    assert_eq!(s.near_boundary.facets, 1);
    assert_eq!(s.near_boundary.points, 1);
    assert!((s.near_boundary.mean_deg - want).abs() < 1e-9, "{s:?}");
    // A uniform grid has straight mesh lines: no jump anywhere, near or away from the boundary.
    let grid = grid_3d(
        &[0.0, 1.0, 2.0, 3.0, 4.0],
        &[0.0, 0.5, 1.0, 1.5],
        &[0.0, 1.0, 2.0, 3.0],
    );
    let topo = Topology::build(&grid);
    let s = facet_angle_jumps(&grid, &topo, &sample(&grid, &grid, &topo, 3));
    assert!(s.interior.facets > 0 && s.interior.points == 4 * s.interior.facets);
    assert!(
        s.interior.max_deg < 1e-6 && s.near_boundary.max_deg < 1e-6,
        "{s:?}"
    );
}

fn root(rel: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// Run the binary with `args`.
fn polyspline<S: AsRef<std::ffi::OsStr>>(args: impl IntoIterator<Item = S>) -> Output {
    Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .args(args)
        .output()
        .unwrap()
}

/// Run the binary with `args`; it must succeed.
fn polyspline_ok<S: AsRef<std::ffi::OsStr>>(args: impl IntoIterator<Item = S>) -> Output {
    let out = polyspline(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Curve `rel` with the smooth fit and method `method` at order 2.
fn curved(rel: &str, method: Method) -> polyspline::pipeline::Curved {
    curve_in_memory(&root(rel), &smooth_options(method)).unwrap()
}

fn smooth_options(method: Method) -> CurveOptions {
    CurveOptions {
        order: 2,
        geometry: Geometry::SplineFitted,
        method,
        fit: polyspline::fit::FitParams::smooth(),
        line_search_mode: polyspline::pipeline::LineSearchMode::Local,
        backend: polyspline::exec::gpu::Backend::Cpu,
        ..Default::default()
    }
}

/// `--order 1 --subdivide K` with the elastic analogy: the elasticity runs at order K, then the
/// elements are split; the result is the subdivided order-K elastic mesh.
#[test]
fn elastic_with_subdivision_splits_the_order_k_result() {
    let rel = "meshes/real/dealii/unstructured_refined_ball.msh";
    let method = Method::Elastic(ElasticParams::default());
    let whole = curved(rel, method);
    let mut o = smooth_options(method);
    o.order = 1;
    o.subdivide = Some(2);
    let split = curve_in_memory(&root(rel), &o).unwrap();
    assert_eq!(split.ho.order, 1);
    assert_eq!(split.ho.n_elements(), 4 * whole.ho.n_elements());
    assert_eq!(split.ho.nodes.len(), whole.ho.nodes.len());
    let (lo, hi) = whole.mesh.bounding_box();
    let tol = 1e-6 * (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    for (a, b) in split.ho.nodes.iter().zip(&whole.ho.nodes) {
        assert!((0..3).all(|k| (a[k] - b[k]).abs() < tol), "{a:?} {b:?}");
    }
}

/// The paper's claim (Figs. 2f, 5): inside the domain the IGA mesh is smoother than the elastic
/// one, which shares its boundary. Both are certified valid and share the boundary nodes.
fn iga_is_smoother_inside(rel: &str) {
    let iga = curved(rel, Method::Iga);
    let el = curved(rel, Method::Elastic(ElasticParams::default()));
    assert_eq!(el.report.invalid_elements, 0);
    assert!(el.report.min_det_jacobian_bound.unwrap() > 0.0);
    // Two fits of the same problem differ by the parallel CG's round-off only.
    let (lo, hi) = iga.mesh.bounding_box();
    let tol = 1e-8 * (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    for &n in &iga.ho.boundary {
        let (a, b) = (iga.ho.nodes[n as usize], el.ho.nodes[n as usize]);
        assert!((0..3).all(|k| (a[k] - b[k]).abs() < tol), "{a:?} {b:?}");
    }
    let si = facet_angle_jumps(&iga.mesh, &iga.topo, &iga.ho);
    let se = facet_angle_jumps(&el.mesh, &el.topo, &el.ho);
    let straight = sample(&el.mesh, &el.mesh, &el.topo, 2);
    let ss = facet_angle_jumps(&el.mesh, &el.topo, &straight);
    eprintln!(
        "{rel}: interior facet angle jump mean/max (deg): iga {:.3}/{:.2}, elastic {:.3}/{:.2}, straight {:.3}/{:.2}; near boundary: iga {:.3}, elastic {:.3}, straight {:.3}; elastic CG iterations {}",
        si.interior.mean_deg,
        si.interior.max_deg,
        se.interior.mean_deg,
        se.interior.max_deg,
        ss.interior.mean_deg,
        ss.interior.max_deg,
        si.near_boundary.mean_deg,
        se.near_boundary.mean_deg,
        ss.near_boundary.mean_deg,
        el.report.elastic.unwrap().cg.iterations,
    );
    assert!(si.interior.facets > 100);
    assert!(
        si.interior.mean_deg < 0.75 * se.interior.mean_deg,
        "iga {si:?} elastic {se:?}"
    );
}

#[test]
fn iga_is_smoother_than_elastic_inside_the_plate_with_a_hole() {
    iga_is_smoother_inside("meshes/real/dealii/hole8170.msh");
}

#[test]
fn iga_is_smoother_than_elastic_inside_a_3d_mesh() {
    iga_is_smoother_inside("meshes/real/libmesh/systems_of_equations_ex9.exo");
}

#[test]
fn compare_json_has_every_method_and_key() {
    let out = polyspline_ok([
        OsString::from("compare"),
        "--json".into(),
        root("meshes/real/dealii/unstructured_refined_ball.msh").into(),
    ]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "input",
        "dimension",
        "elements",
        "order",
        "rows",
        "elastic_over_iga_time",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    let rows = v["rows"].as_array().unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r["method"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "straight",
            "iga-position",
            "iga-frame",
            "iga-smooth",
            "elastic"
        ]
    );
    for r in rows {
        for key in [
            "error",
            "timings",
            "method_seconds",
            "total_seconds",
            "invalid_elements",
            "min_scaled_jacobian",
            "boundary_vertex_deviation_max",
            "boundary_vertex_deviation_rms",
            "boundary_node_distance_max",
            "cg_iterations",
            "smoothness",
        ] {
            assert!(r.get(key).is_some(), "{}: missing {key}", r["method"]);
        }
        if r["error"].is_null() {
            for part in ["near_boundary", "interior"] {
                for key in ["facets", "points", "mean_deg", "max_deg"] {
                    assert!(r["smoothness"][part][key].is_number(), "{part}.{key}");
                }
            }
        } else {
            assert!(r["smoothness"].is_null());
        }
    }
    assert!(rows[4]["timings"]["elastic_cg"].is_number());
}

/// `compare` takes the sharp-feature options of `curve`: an edits file naming a vertex that
/// does not exist is refused with the file and line, before any table is printed.
#[test]
fn compare_takes_the_feature_options() {
    let dir = std::env::temp_dir().join(format!("polyspline-cmp-feat-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let edits = dir.join("edits.txt");
    std::fs::write(&edits, "add 0 999999999\n").unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .arg("compare")
        .arg(root("meshes/real/dealii/unstructured_refined_ball.msh"))
        .arg("--feature-edits")
        .arg(&edits)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("edits.txt:1"), "{err}");
    assert!(o.stdout.is_empty());
}

#[test]
fn curve_method_elastic_writes_a_valid_mesh_with_the_iga_boundary() {
    let dir = std::env::temp_dir().join(format!("polyspline-elastic-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = root("meshes/real/dealii/unstructured_refined_ball.msh");
    let run = |method: &str| {
        let out = dir.join(format!("{method}.msh"));
        let report = dir.join(format!("{method}.json"));
        polyspline_ok([
            OsString::from("curve"),
            input.clone().into(),
            "-o".into(),
            out.clone().into(),
            "--order".into(),
            "3".into(),
            "--method".into(),
            method.into(),
            "--report".into(),
            report.clone().into(),
        ]);
        (out, report)
    };
    let (out_e, rep_e) = run("elastic");
    let (_, rep_i) = run("iga");
    let ri: serde_json::Value = serde_json::from_slice(&std::fs::read(&rep_i).unwrap()).unwrap();
    let re: serde_json::Value = serde_json::from_slice(&std::fs::read(&rep_e).unwrap()).unwrap();
    // Same report keys as the IGA path (plus the elastic solve's own).
    for key in ri.as_object().unwrap().keys() {
        assert!(re.get(key).is_some(), "elastic report lacks {key}");
    }
    assert_eq!(re["method"], "elastic");
    assert_eq!(re["invalid_elements"], 0);
    assert!(re["min_det_jacobian_bound"].as_f64().unwrap() > 0.0);
    let (dev_e, dev_i) = (
        re["boundary_vertex_deviation_max"].as_f64().unwrap(),
        ri["boundary_vertex_deviation_max"].as_f64().unwrap(),
    );
    assert!((dev_e - dev_i).abs() <= 1e-6 * dev_i, "{dev_e} vs {dev_i}");
    assert_eq!(re["elastic"]["solver"], "cholesky");
    assert!(re["elastic"]["cg"]["rel_residual"].as_f64().unwrap() < 1e-10);
    // The written file reads back as a valid order-3 mesh: Gmsh's Jacobians, and our `check`.
    if let Some((lo, hi, _)) = crate::common::gmsh_det_range(&out_e, &dir.join("jobs.json")) {
        assert!(
            lo > 0.0,
            "Gmsh finds det J in [{lo:e}, {hi:e}] (signed in 2D)"
        );
    }
    let chk = polyspline_ok([OsString::from("check"), "--json".into(), out_e.into()]);
    let c: serde_json::Value = serde_json::from_slice(&chk.stdout).unwrap();
    assert_eq!(c["invalid"], 0);
    assert_eq!(c["order"], 3);
    // A material the solve cannot use: error, exit non-zero, nothing written.
    let bad = dir.join("bad.msh");
    let st = polyspline([
        OsString::from("curve"),
        input.into(),
        "-o".into(),
        bad.clone().into(),
        "--method".into(),
        "elastic".into(),
        "--poisson".into(),
        "0.5".into(),
    ]);
    assert!(!st.status.success());
    assert!(String::from_utf8_lossy(&st.stderr).contains("Poisson"));
    assert!(!bad.exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// `plot --overlay` draws two results (IGA vs elastic, paper Fig. 2f) with a legend, their
/// nodes with `--nodes`, and only the part inside `--window`.
#[test]
fn plot_overlays_iga_and_elastic() {
    let dir = std::env::temp_dir().join(format!("polyspline-plot-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = root("meshes/real/dealii/unstructured_refined_ball.msh");
    for method in ["iga", "elastic"] {
        polyspline_ok([
            OsString::from("curve"),
            input.clone().into(),
            "-o".into(),
            dir.join(format!("{method}.msh")).into(),
            "--method".into(),
            method.into(),
        ]);
    }
    let plot = |extra: &[&str]| -> String {
        let svg = dir.join("p.svg");
        let mut args = vec![
            OsString::from("plot"),
            dir.join("iga.msh").into(),
            "--overlay".into(),
            dir.join("elastic.msh").into(),
            "--label".into(),
            "IGA".into(),
            "--label".into(),
            "elastic".into(),
            "-o".into(),
            svg.clone().into(),
        ];
        args.extend(extra.iter().map(OsString::from));
        polyspline_ok(args);
        std::fs::read_to_string(&svg).unwrap()
    };
    let full = plot(&["--nodes"]);
    let ho = |m: &str| {
        let raw = polyspline::io::read_raw(&dir.join(m)).unwrap();
        HighOrderMesh::from_raw(raw).unwrap()
    };
    let (a, b) = (ho("iga.msh"), ho("elastic.msh"));
    assert_eq!(
        full.matches("<circle").count(),
        a.nodes.len() + b.nodes.len()
    );
    assert!(full.contains(">IGA</text>") && full.contains(">elastic</text>"));
    let polylines = full.matches("<polyline").count();
    // The ball has radius 6 about the origin: a window of one quadrant's corner shows less.
    let zoom = plot(&["--window", "0,0,3,3"]);
    let shown = zoom.matches("<polyline").count();
    assert!(shown > 0 && shown < polylines / 2, "{shown} of {polylines}");
    assert!(zoom.contains("clip-path"));
    std::fs::remove_dir_all(&dir).ok();
}
