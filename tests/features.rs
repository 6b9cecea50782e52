//! Sharp features end to end: Gmsh-meshed solids with sharp rims (made by
//! `tests/external/feature_meshes.py` with Gmsh's Python API), curved with and without
//! feature handling, measured against their analytic surfaces, and checked by Gmsh's
//! Jacobians (`tests/external/gmsh_probe.py`).

mod common;

use polyspline::mesh::features::{FeatureOptions, FeatureParams};
use polyspline::pipeline::{CurveOptions, Geometry, curve, curve_in_memory};
use std::path::{Path, PathBuf};
use std::process::Command;

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("features");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn have_gmsh() -> bool {
    common::have_gmsh("the Gmsh-meshed solids were not made")
}

/// Make a Gmsh mesh of `kind` with `n` elements per block side.
fn gmsh_mesh(kind: &str, n: usize) -> PathBuf {
    let out = scratch(&format!("{kind}_{n}.msh"));
    let status = common::python()
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/external/feature_meshes.py"
        ))
        .args([kind, out.to_str().unwrap(), &n.to_string()])
        .status()
        .unwrap();
    assert!(status.success(), "feature_meshes.py {kind} failed");
    out
}

/// The analytic surfaces of a solid; `classify` names the surface a set of input boundary
/// vertices lies on (None for none), `distance` the distance of a point from surface `s`.
struct Solid {
    names: &'static [&'static str],
    classify: fn(&[[f64; 3]]) -> Option<usize>,
    distance: fn(usize, [f64; 3]) -> f64,
}

const TOL: f64 = 1e-9;

fn all(xs: &[[f64; 3]], f: impl Fn([f64; 3]) -> bool) -> bool {
    xs.iter().all(|&x| f(x))
}

fn radius(x: [f64; 3]) -> f64 {
    x[0].hypot(x[1])
}

/// Cylinder of radius 1, z ∈ [0, 2].
const CYLINDER: Solid = Solid {
    names: &["planes", "side"],
    classify: |xs| {
        if all(xs, |x| x[2].abs() < TOL) || all(xs, |x| (x[2] - 2.0).abs() < TOL) {
            Some(0)
        } else if all(xs, |x| (radius(x) - 1.0).abs() < TOL) {
            Some(1)
        } else {
            None
        }
    },
    distance: |s, x| {
        if s == 0 {
            x[2].abs().min((x[2] - 2.0).abs())
        } else {
            (radius(x) - 1.0).abs()
        }
    },
};

/// Box [-1, 1]² × [0, 1] with a hole of radius 0.5 along z.
const BOX_HOLE: Solid = Solid {
    names: &["side planes", "top/bottom", "hole"],
    classify: |xs| {
        if all(xs, |x| (x[0].abs() - 1.0).abs() < TOL)
            || all(xs, |x| (x[1].abs() - 1.0).abs() < TOL)
        {
            Some(0)
        } else if all(xs, |x| x[2].abs() < TOL) || all(xs, |x| (x[2] - 1.0).abs() < TOL) {
            Some(1)
        } else if all(xs, |x| (radius(x) - 0.5).abs() < TOL) {
            Some(2)
        } else {
            None
        }
    },
    distance: |s, x| match s {
        0 => (x[0].abs() - 1.0).abs().min((x[1].abs() - 1.0).abs()),
        1 => x[2].abs().min((x[2] - 1.0).abs()),
        _ => (radius(x) - 0.5).abs(),
    },
};

/// What a curved solid measures: per surface the largest distance of an output boundary node
/// from its analytic surface; the largest of a feature vertex's node from the surfaces of all
/// facets around it; the certified det J bound and the min scaled Jacobian.
#[derive(Debug)]
struct Measured {
    surface: Vec<f64>,
    rim: f64,
    min_det_bound: f64,
    min_scaled_jacobian: f64,
    q2_elements: usize,
}

fn measure(input: &Path, solid: &Solid, options: &CurveOptions) -> Measured {
    let c = curve_in_memory(input, options).unwrap();
    let (mesh, topo, ho) = (&c.mesh, &c.topo, &c.ho);
    let npf = ho.nodes_per_facet();
    let mut surface = vec![0.0f64; solid.names.len()];
    let mut at_vertex: Vec<Vec<usize>> = vec![Vec::new(); mesh.n_vertices()];
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        let xs: Vec<[f64; 3]> = topo
            .facet_vertices(f as usize)
            .iter()
            .map(|&v| mesh.coords[v as usize])
            .collect();
        let s = (solid.classify)(&xs).unwrap_or_else(|| panic!("facet {f} on no surface"));
        for &k in &ho.boundary[i * npf..(i + 1) * npf] {
            surface[s] = surface[s].max((solid.distance)(s, ho.nodes[k as usize]));
        }
        for &v in topo.facet_vertices(f as usize) {
            at_vertex[v as usize].push(s);
        }
    }
    // Vertices where two surfaces meet (the rims and edges): their node on every surface.
    let mut rim = 0.0f64;
    for (v, ss) in at_vertex.iter_mut().enumerate() {
        ss.sort_unstable();
        ss.dedup();
        if ss.len() > 1 {
            for &s in ss.iter() {
                rim = rim.max((solid.distance)(s, ho.nodes[v]));
            }
        }
    }
    Measured {
        surface,
        rim,
        min_det_bound: c.report.min_det_jacobian_bound.unwrap(),
        min_scaled_jacobian: c.report.min_scaled_jacobian,
        q2_elements: c.report.q2_elements,
    }
}

fn with_features(on: bool) -> CurveOptions {
    CurveOptions {
        geometry: Geometry::SplineFitted,
        features: FeatureOptions {
            params: if on {
                FeatureParams::default()
            } else {
                FeatureParams::off()
            },
            ..Default::default()
        },
        ..Default::default()
    }
}

/// Gmsh's Jacobians of a written file are positive: (min, max) det J over a Gauss rule (the
/// callers checked that Gmsh is there).
fn assert_gmsh_valid(file: &Path) {
    let jobs = scratch(&format!(
        "{}_jobs.json",
        file.file_stem().unwrap().to_string_lossy()
    ));
    let (lo, hi, _) = common::gmsh_det_range(file, &jobs).expect("gmsh checked by the caller");
    assert!(
        lo > 0.0 && hi > 0.0,
        "Gmsh finds det J in [{lo}, {hi}] on {}",
        file.display()
    );
}

/// Box with a hole: with features the side planes and top/bottom stay planar to rounding (the
/// side planes bulge without) and the rims stay on both surfaces, far below the feature-off
/// result; the hole is as accurate;
/// the result is certified valid by us and by Gmsh.
#[test]
fn box_with_hole_keeps_its_planes_and_rims() {
    if !have_gmsh() {
        return;
    }
    let input = gmsh_mesh("box_hole", 4);
    let on = measure(&input, &BOX_HOLE, &with_features(true));
    let off = measure(&input, &BOX_HOLE, &with_features(false));
    eprintln!("features on: {on:?}\nfeatures off: {off:?}");
    for s in 0..2 {
        assert!(
            on.surface[s] < 1e-12,
            "{}: {} with features, {} without",
            BOX_HOLE.names[s],
            on.surface[s],
            off.surface[s]
        );
    }
    // Without features the side planes bulge (z stays affine, so top and bottom do not).
    assert!(on.surface[0] < 1e-3 * off.surface[0], "{on:?} vs {off:?}");
    assert!(on.rim < 0.1 * off.rim, "rims: {} vs {}", on.rim, off.rim);
    assert!(
        on.surface[2] < 1.5 * off.surface[2],
        "hole: {} with features, {} without",
        on.surface[2],
        off.surface[2]
    );
    assert!(on.min_det_bound > 0.0 && on.min_scaled_jacobian > 0.3);
    assert!(on.q2_elements > off.q2_elements, "crease elements are Q2");
    let out = scratch("box_hole_features.msh");
    curve(&input, &out, &with_features(true)).unwrap();
    assert_gmsh_valid(&out);
}

/// The degeneration energy (`--fit energy`) moves control points after the least-squares fit;
/// planar faces must still come out planar, and the worst element no worse than without it.
#[test]
fn energy_fit_keeps_the_planes_of_the_box_with_a_hole() {
    if !have_gmsh() {
        return;
    }
    let input = gmsh_mesh("box_hole", 4);
    // The energy's start: no energy iterations after the certified control-point search.
    let start = CurveOptions {
        energy: Some(polyspline::energy::EnergyParams {
            max_iterations: 0,
            ..Default::default()
        }),
        ..with_features(true)
    };
    let ls = measure(&input, &BOX_HOLE, &start);
    let energy = CurveOptions {
        energy: Some(polyspline::energy::EnergyParams::default()),
        ..with_features(true)
    };
    let on = measure(&input, &BOX_HOLE, &energy);
    eprintln!("least squares: {ls:?}\nenergy: {on:?}");
    for s in 0..2 {
        assert!(
            on.surface[s] < 1e-12,
            "{}: {}",
            BOX_HOLE.names[s],
            on.surface[s]
        );
    }
    // The energy trades some boundary accuracy (rims 2.2× here) for element quality.
    assert!(on.min_scaled_jacobian >= ls.min_scaled_jacobian);
    assert!(on.min_det_bound > 0.0);
}

/// Gmsh cylinder: its rims are single hexes' edges, so the map is C⁰ there with or without
/// features; with features the end planes stay exactly planar, the side is as accurate as
/// without, the rims are at least as close, and the result is valid by us and by Gmsh.
#[test]
fn gmsh_cylinder_keeps_its_rims_and_end_planes() {
    if !have_gmsh() {
        return;
    }
    let input = gmsh_mesh("cylinder", 4);
    let on = measure(&input, &CYLINDER, &with_features(true));
    let off = measure(&input, &CYLINDER, &with_features(false));
    eprintln!("features on: {on:?}\nfeatures off: {off:?}");
    assert!(on.surface[0] < 1e-12, "end planes: {}", on.surface[0]);
    assert!(
        on.surface[1] < 1.5 * off.surface[1] && on.surface[1] < 1e-2,
        "side: {} with features, {} without",
        on.surface[1],
        off.surface[1]
    );
    assert!(
        on.rim <= 1.5 * off.rim + 1e-12,
        "rims: {} vs {}",
        on.rim,
        off.rim
    );
    assert!(on.min_det_bound > 0.0);
    let out = scratch("cylinder_features.msh");
    curve(&input, &out, &with_features(true)).unwrap();
    assert_gmsh_valid(&out);
}

/// `--snap-boundary` puts the feature vertices back onto the input exactly; the report's
/// feature numbers agree with the independent measurement above (planes exact).
#[test]
fn snap_boundary_puts_feature_vertices_back() {
    if !have_gmsh() {
        return;
    }
    let input = gmsh_mesh("box_hole", 3);
    let plain = curve_in_memory(&input, &with_features(true))
        .unwrap()
        .report;
    let f = plain.features.unwrap();
    let n = &f.found;
    assert_eq!((n.feature_edges, n.feature_corners, n.patches), (60, 8, 7));
    assert_eq!(n.planar_patches, 6);
    assert!(f.planarity_max < 1e-14, "{f:?}");
    assert!(f.feature_vertex_deviation_max > 1e-6, "{f:?}");
    let snapped = curve_in_memory(
        &input,
        &CurveOptions {
            snap_boundary: true,
            ..with_features(true)
        },
    )
    .unwrap()
    .report;
    let g = snapped.features.unwrap();
    assert_eq!(g.feature_vertex_deviation_max, 0.0, "{g:?}");
    assert!(g.planarity_max < 1e-14, "{g:?}");
}

fn polyspline() -> Command {
    Command::new(env!("CARGO_BIN_EXE_polyspline"))
}

/// An L-shaped domain of three unit quads (Gmsh 2.2 ASCII): six polygon corners, five of them
/// convex, one re-entrant; the re-entrant corner (node 5, 0-based 4) lies between two quads.
fn l_shape() -> PathBuf {
    let path = scratch("l_shape.msh");
    let nodes = [
        (0.0, 0.0),
        (1.0, 0.0),
        (2.0, 0.0),
        (0.0, 1.0),
        (1.0, 1.0),
        (2.0, 1.0),
        (0.0, 2.0),
        (1.0, 2.0),
    ];
    let mut s = String::from("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n8\n");
    for (i, (x, y)) in nodes.iter().enumerate() {
        s += &format!("{} {x} {y} 0\n", i + 1);
    }
    s += "$EndNodes\n$Elements\n3\n1 3 2 1 1 1 2 5 4\n2 3 2 1 1 2 3 6 5\n3 3 2 1 1 4 5 8 7\n$EndElements\n";
    std::fs::write(&path, s).unwrap();
    path
}

/// `info --json` reports the corners of the L (six, found by angle alone), none at 180°,
/// and the re-entrant corner's crease between two quads.
#[test]
fn info_reports_the_features_found() {
    let input = l_shape();
    let run = |args: &[&str]| -> serde_json::Value {
        let out = common::run_ok(
            polyspline()
                .arg("info")
                .arg(&input)
                .arg("--json")
                .args(args),
        );
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()["features"].clone()
    };
    let f = run(&[]);
    assert_eq!(f["feature_corners"], 6, "{f}");
    assert_eq!(f["patches"], 6, "{f}");
    // Corner (1, 1) of the L lies between quads 2 and 3; the convex ones are own corners.
    assert_eq!(f["crease_elements"], 2, "{f}");
    let none = run(&["--feature-angle", "180"]);
    assert_eq!(none["feature_corners"], 0, "{none}");
    let table = polyspline().arg("info").arg(&input).output().unwrap();
    assert!(String::from_utf8_lossy(&table.stdout).contains("sharp features        6 corners"));
}

/// `plot --show-features` draws one marker per corner; a bad edits file is refused with the
/// file and line named, and nothing is written.
#[test]
fn plot_shows_corners_and_bad_edits_are_refused() {
    let input = l_shape();
    let svg = scratch("l_shape.svg");
    let _ = std::fs::remove_file(&svg);
    common::run_ok(
        polyspline()
            .args(["plot", input.to_str().unwrap(), "-o", svg.to_str().unwrap()])
            .arg("--show-features"),
    );
    let text = std::fs::read_to_string(&svg).unwrap();
    let group = text
        .split("<title>feature corners</title>")
        .nth(1)
        .expect("a feature corner layer");
    let group = group.split("</g>").next().unwrap();
    assert_eq!(group.matches("<circle").count(), 6);

    let edits = scratch("bad_edits.txt");
    std::fs::write(&edits, "add 4\nadd 1 2\n").unwrap();
    let svg2 = scratch("l_shape_bad.svg");
    let _ = std::fs::remove_file(&svg2);
    let out = polyspline()
        .args([
            "plot",
            input.to_str().unwrap(),
            "-o",
            svg2.to_str().unwrap(),
        ])
        .args([
            "--show-features",
            "--feature-edits",
            edits.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!("{}:2:", edits.display())) && err.contains("one vertex id"),
        "{err}"
    );
    assert!(!svg2.exists());
    let out = polyspline()
        .args(["curve", input.to_str().unwrap(), "-o"])
        .arg(scratch("l_shape_bad.msh"))
        .args(["--feature-edits", "/nonexistent/edits.txt"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/edits.txt"));
}
