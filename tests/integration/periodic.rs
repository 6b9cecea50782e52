//! Periodic meshes (`curve --periodic A:B`): the written nodes of the image side are the
//! transform of the master side's, and solvers' readers see the pairs. Oracles: Gmsh's reader
//! (`getPeriodicNodes` with high-order nodes, node coordinates, the affine transform and the
//! facet angles across the seam from its Jacobians, `tests/external/periodic_probe.py`), the
//! analytic transform of the generated sectors (a rotation about z, a translation along z),
//! and PyFR's importer (`periodic/…` datasets of the `.pyfrm`).

use crate::common::{self, polyspline, python, python_has, run_ok, scratch_in};
use polyspline::io::read_raw;
use polyspline::mesh::{HighOrderMesh, LinearMesh};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
const TURBINE: &str = "meshes/real/su2-testcases/mesh_vki_turbine_prepbc.su2";
/// Written images agree to rounding: relative to the bounding-box diagonal.
const IMAGE_TOL: f64 = 1e-12;

/// A sector of the annulus 1 ≤ r ≤ 2, 0 ≤ θ ≤ `deg`, (3D: 0 ≤ z ≤ 0.5) in `nr` × `nt` (× 2)
/// cells, its sides tagged `theta_lo`, `theta_hi`, `hub`, `shroud` (3D: `bottom`, `top`).
fn sector(dim: usize, deg: f64, nr: usize, nt: usize) -> LinearMesh {
    let nz = if dim == 3 { 2 } else { 0 };
    let point = |i: usize, j: usize, k: usize| {
        let r = 1.0 + i as f64 / nr as f64;
        let t = (deg * j as f64 / nt as f64).to_radians();
        [r * t.cos(), r * t.sin(), 0.25 * k as f64]
    };
    let names = ["hub", "shroud", "theta_lo", "theta_hi", "bottom", "top"];
    grid(dim, [nr, nt, nz], point, names)
}

/// The structured grid of `n[0]` × `n[1]` (3D: × `n[2]`) cells whose vertex (i, j, k) is at
/// `point(i, j, k)`, its sides tagged 1, 2 at i = 0, n[0]; 3, 4 at j = 0, n[1]; (3D) 5, 6 at
/// k = 0, n[2], named `names`.
fn grid(
    dim: usize,
    [nx, ny, nz]: [usize; 3],
    point: impl Fn(usize, usize, usize) -> [f64; 3],
    names: [&str; 6],
) -> LinearMesh {
    let id = |i: usize, j: usize, k: usize| ((k * (ny + 1) + j) * (nx + 1) + i) as u32;
    let mut coords = Vec::new();
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                coords.push(point(i, j, k));
            }
        }
    }
    let (mut elements, mut facets, mut tags) = (Vec::new(), Vec::new(), Vec::new());
    let quad = |i: usize, j: usize, k: usize| {
        [
            id(i, j, k),
            id(i + 1, j, k),
            id(i + 1, j + 1, k),
            id(i, j + 1, k),
        ]
    };
    for k in 0..nz.max(1) {
        for j in 0..ny {
            for i in 0..nx {
                elements.extend(quad(i, j, k));
                if dim == 3 {
                    elements.extend(quad(i, j, k + 1));
                }
            }
        }
    }
    let mut face = |vs: Vec<u32>, tag: i32| {
        facets.extend(vs);
        tags.push(tag);
    };
    for k in 0..nz.max(1) {
        let side = |a: u32, b: u32, c: u32, d: u32| match dim {
            2 => vec![a, b],
            _ => vec![a, b, c, d],
        };
        for j in 0..ny {
            for (i, tag) in [(0, 1), (nx, 2)] {
                face(
                    side(
                        id(i, j, k),
                        id(i, j + 1, k),
                        id(i, j + 1, k + 1),
                        id(i, j, k + 1),
                    ),
                    tag,
                );
            }
        }
        for i in 0..nx {
            for (j, tag) in [(0, 3), (ny, 4)] {
                face(
                    side(
                        id(i, j, k),
                        id(i + 1, j, k),
                        id(i + 1, j, k + 1),
                        id(i, j, k + 1),
                    ),
                    tag,
                );
            }
        }
    }
    if dim == 3 {
        for j in 0..ny {
            for i in 0..nx {
                for (k, tag) in [(0, 5), (nz, 6)] {
                    face(quad(i, j, k).to_vec(), tag);
                }
            }
        }
    }
    let mut raw = LinearMesh {
        dim,
        coords,
        elements,
        tagged_facets: facets,
        facet_tags: tags,
        tag_names: (1..=6)
            .zip(names)
            .map(|(t, n)| (t, n.to_string()))
            .collect(),
        ..Default::default()
    };
    raw.tag_names.retain(|t, _| dim == 3 || *t <= 4);
    raw
}

/// The sector written as a linear MSH file in the scratch folder.
fn sector_file(dim: usize, deg: f64) -> PathBuf {
    let path = scratch_in("periodic", &format!("sector{dim}d.msh"));
    common::write_linear(&sector(dim, deg, 3, 6), &path);
    path
}

/// `curve INPUT -o OUT ARGS --report`: the report.
fn curve(input: &Path, out: &Path, args: &[&str]) -> Value {
    let report = out.with_extension("json");
    run_ok(
        polyspline()
            .arg("curve")
            .arg(input)
            .arg("-o")
            .arg(out)
            .arg("-q")
            .arg("--report")
            .arg(&report)
            .args(args),
    );
    serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap()
}

/// `cmd` fails with one error line that contains every one of `says`.
fn assert_refused(cmd: &mut std::process::Command, says: &[&str]) {
    let run = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "accepted: {err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(says.iter().all(|s| err.contains(s)), "{says:?}: {err}");
}

/// `pyfr import MSH`, then the sizes of the `.pyfrm`'s `periodic/…` datasets (connected face
/// pairs), sorted, as Python prints the list.
fn pyfr_periodic_sizes(msh: &Path) -> String {
    let pyfrm = msh.with_extension("pyfrm");
    let _ = std::fs::remove_file(&pyfrm);
    run_ok(python().args(["-m", "pyfr", "import"]).arg(msh).arg(&pyfrm));
    let sizes = run_ok(python().arg("-c").arg(
        "import h5py, sys\nf = h5py.File(sys.argv[1])\nprint(sorted(len(f['periodic'][k]) for k in f['periodic']))",
    ).arg(&pyfrm));
    String::from_utf8_lossy(&sizes.stdout).trim().to_string()
}

/// Every node of each image entity is paired in Gmsh, and its coordinates are the affine
/// image of its master's to `IMAGE_TOL` of the diagonal. Returns the links by image name.
fn assert_exact_images(file: &Path, expect: usize) -> BTreeMap<String, Value> {
    let p = common::periodic_probe(file);
    let diag = p["diagonal"].as_f64().unwrap();
    let links = p["links"].as_array().unwrap();
    assert_eq!(links.len(), expect, "{}: links {links:?}", file.display());
    let mut out = BTreeMap::new();
    for l in links {
        let (pairs, nodes) = (
            l["pairs"].as_u64().unwrap(),
            l["entity_nodes"].as_u64().unwrap(),
        );
        assert!(pairs > 0 && pairs == nodes, "{}: {l}", file.display());
        assert_eq!(l["unpaired"], 0, "{}: {l}", file.display());
        let miss = l["max_mismatch"].as_f64().unwrap() / diag;
        assert!(
            miss <= IMAGE_TOL,
            "{}: images miss by {miss:e} of the diagonal: {l}",
            file.display()
        );
        out.insert(l["name"].as_str().unwrap().to_string(), l.clone());
    }
    out
}

/// The first three rows of a Gmsh link's affine map (`link["affine"]`, by rows) are `want` to
/// `tol`.
fn assert_affine(link: &Value, want: &[f64; 12], tol: f64, what: &str) {
    let a: Vec<f64> = link["affine"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    for k in 0..12 {
        assert!((a[k] - want[k]).abs() < tol, "{what}: affine {a:?}");
    }
}

/// The rotation by `deg` degrees about z, as the first three rows of an affine map.
fn rotation_z(deg: f64) -> [f64; 12] {
    let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
    [c, -s, 0.0, 0.0, s, c, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]
}

#[test]
fn turbine_images_are_exact_and_gmsh_pairs_every_node() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    let input = Path::new(ROOT).join(TURBINE);
    for (name, args) in [
        ("o1", vec!["--order", "1"]),
        ("o2", vec!["--order", "2"]),
        ("o4_v22", vec!["--order", "4", "--msh-version", "2.2"]),
        ("sub3", vec!["--order", "1", "--subdivide", "3"]),
        ("o3_bin", vec!["--order", "3", "--binary"]),
    ] {
        let out = scratch_in("periodic", &format!("turbine_{name}.msh"));
        let mut args = args;
        args.extend(["--periodic", "periodic_1:periodic_2"]);
        let report = curve(&input, &out, &args);
        let per = &report["periodic"];
        assert!(
            per["written_mismatch"].as_f64().unwrap() <= IMAGE_TOL,
            "{name}: {per}"
        );
        assert_eq!(per["pairs"][0]["kind"], "translation", "{name}");
        let links = assert_exact_images(&out, 1);
        let l = &links["periodic_2"];
        assert_eq!(l["master_name"], "periodic_1", "{name}");
        // The cascade's pitch: a translation by (0, -0.0575) (the file's markers to 3e-11).
        let expect = [
            1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -0.0575, 0.0, 0.0, 1.0, 0.0,
        ];
        assert_affine(l, &expect, 1e-6, name);
    }
}

#[test]
fn sectors_rotation_and_translation_are_exact_at_every_order() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    let rotation = rotation_z(30.0);
    let lift = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.5];
    for dim in [2, 3] {
        let input = sector_file(dim, 30.0);
        let max_order = if dim == 2 { 10 } else { 9 };
        let mut runs: Vec<Vec<String>> = (1..=max_order)
            .filter(|p| dim == 2 || [1, 2, 3, 5, 9].contains(p))
            .map(|p| vec!["--order".into(), p.to_string()])
            .collect();
        runs.push(vec![
            "--order".into(),
            "1".into(),
            "--subdivide".into(),
            "4".into(),
        ]);
        for run in runs {
            let mut args: Vec<&str> = run.iter().map(String::as_str).collect();
            args.extend(["--periodic", "theta_lo:theta_hi"]);
            if dim == 3 {
                args.extend(["--periodic", "bottom:top"]);
            }
            let out = scratch_in("periodic", &format!("sector{dim}d_{}.msh", run.join("_")));
            let report = curve(&input, &out, &args);
            let pairs = &report["periodic"]["pairs"];
            assert_eq!(pairs[0]["kind"], "rotation", "{dim}D {run:?}");
            let deg = pairs[0]["angle_degrees"].as_f64().unwrap();
            assert!((deg - 30.0).abs() < 1e-9, "{dim}D {run:?}: {deg}");
            let links = assert_exact_images(&out, dim - 1);
            let what = format!("{dim}D {run:?}");
            assert_affine(&links["theta_hi"], &rotation, 1e-9, &what);
            if dim == 3 {
                assert_eq!(pairs[1]["kind"], "translation");
                assert_affine(&links["top"], &lift, 1e-9, &what);
            }
        }
    }
}

/// A channel periodic in x, 0 ≤ x ≤ 2, between a wavy floor y = 0.1 sin(πx) and the roof
/// y = 1, in `nx` × `ny` cells graded towards the floor (3D: extruded over 0 ≤ z ≤ 0.6 in
/// three layers). Its sides are tagged `left`, `right` (the periodic pair, a translation by
/// (2, 0, 0)), `floor`, `roof` (3D: `front`, `back`).
fn channel(dim: usize, nx: usize, ny: usize) -> LinearMesh {
    let nz = if dim == 3 { 3 } else { 0 };
    let point = |i: usize, j: usize, k: usize| {
        let x = 2.0 * i as f64 / nx as f64;
        let floor = 0.1 * (std::f64::consts::PI * x).sin();
        let s = (j as f64 / ny as f64).powf(1.2);
        [x, floor + s * (1.0 - floor), 0.2 * k as f64]
    };
    let names = ["left", "right", "floor", "roof", "front", "back"];
    grid(dim, [nx, ny, nz], point, names)
}

#[test]
fn seam_facet_angle_is_no_worse_than_the_interior() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    // Translation pairs are identified in the spline space: the derivative across the seam,
    // seen from both sides through the translation, turns no more than across the interior
    // facets, and the exact-image step after sampling moves the seam nodes by rounding only.
    for dim in [2, 3] {
        let input = scratch_in("periodic", &format!("channel{dim}d.msh"));
        let (nx, ny) = if dim == 2 { (24, 6) } else { (16, 4) };
        common::write_linear(&channel(dim, nx, ny), &input);
        let orders: &[&[&str]] = match dim {
            2 => &[
                &["--order", "3"],
                &["--order", "1"],
                &["--order", "2"],
                &["--order", "6"],
                &["--order", "10"],
                &["--order", "1", "--subdivide", "3"],
            ],
            _ => &[
                &["--order", "3"],
                &["--order", "1"],
                &["--order", "5"],
                &["--order", "1", "--subdivide", "2"],
            ],
        };
        for (i, run) in orders.iter().enumerate() {
            let out = scratch_in("periodic", &format!("channel{dim}d_{}.msh", run.join("_")));
            let mut args = run.to_vec();
            args.extend(["--periodic", "left:right"]);
            let report = curve(&input, &out, &args);
            let per = &report["periodic"];
            if i == 0 {
                // C¹ spline facets meet at rounding-level angles, the interior's large ones are
                // where the blend held the fit back (C⁰ there).
                common::assert_seams_no_rougher(&out, &format!("{dim}D"));
            }
            assert_eq!(per["seam"], "c1", "{dim}D {run:?}: {per}");
            assert_eq!(per["pairs"][0]["kind"], "translation", "{dim}D {run:?}");
            // Both sides come from one spline: sampling them agrees to rounding already.
            let shift = per["max_seam_shift"].as_f64().unwrap();
            assert!(
                shift <= IMAGE_TOL,
                "{dim}D {run:?}: seam nodes moved {shift:e}"
            );
            assert_exact_images(&out, 1);
        }
    }
}

#[test]
fn turbine_seam_is_fitted_as_the_interior() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    // The cascade's two sides were meshed apart: across the seam its grid turns by 5.4° on
    // average against 1.4° inside, and by up to 81° where blocks meet. Where the grid is
    // regular across the facet (the straight mesh's angle below 10°), the glued seam must be
    // smoothed at least as well as the interior's facets of that kind, and far more than the
    // input's own turn there: once the seam facets are interior for the smooth targets,
    // features and fit weights, the angle left is 0.16 of the input's (0.30 while they kept
    // the unglued input's boundary treatment, pulled onto each side's boundary curve).
    // The default knots are graded on this boundary-layer grid, and the glued seam keeps them
    // (its knot surfaces run across the seam): the smallest scaled Jacobian (from Gmsh's
    // Jacobians) stays within 0.95 of the input's, as without pairs (graded: 1.00 of it;
    // the uniform knots glued seams were once limited to: 0.91), and the images stay exact.
    let input = Path::new(ROOT).join(TURBINE);
    let out = scratch_in("periodic", "turbine_seam_c1.msh");
    let straight = scratch_in("periodic", "turbine_seam_straight.msh");
    let pair = ["--periodic", "periodic_1:periodic_2"];
    let report = curve(&input, &out, &[&["--order", "2"][..], &pair[..]].concat());
    assert_eq!(report["periodic"]["seam"], "c1", "{}", report["periodic"]);
    assert_eq!(report["knot_intervals"], "graded", "{report}");
    assert_exact_images(&out, 1);
    curve(
        &input,
        &straight,
        &[&["--order", "2", "--straight"][..], &pair[..]].concat(),
    );
    let p = serde_json::from_slice::<Value>(
        &run_ok(
            python()
                .arg(Path::new(ROOT).join("tests/external/periodic_probe.py"))
                .arg(&out)
                .arg(&straight),
        )
        .stdout,
    )
    .unwrap();
    let get = |k: &str| p[k].as_f64().unwrap_or_else(|| panic!("{k}: {p}"));
    assert!(p["regular_seam_facets"].as_u64().unwrap() >= 100, "{p}");
    let (seam, inside, input_seam) = (
        get("regular_seam_angle_mean"),
        get("regular_interior_angle_mean"),
        get("regular_seam_input_angle_mean"),
    );
    assert!(seam <= inside, "seam {seam}° > interior {inside}° ({p})");
    assert!(
        seam <= 0.25 * input_seam,
        "seam {seam}° keeps more than a quarter of the input's {input_seam}° ({p})"
    );
    let (sj, input_sj) = (
        get("min_scaled_jacobian"),
        get("straight_min_scaled_jacobian"),
    );
    assert!(
        sj >= 0.95 * input_sj,
        "min scaled Jacobian {sj} < 0.95 × the input's {input_sj} ({p})"
    );
}

#[test]
fn rotation_seams_are_glued_c1_on_generated_sectors() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    // Rotation pairs are identified in the spline space: an element sees the control points
    // across the seam through the rotation, and the fit couples their coordinates. Generated
    // annulus sectors of 30° and 90°, boundary-layer graded. With graded knots every element
    // stays a C¹ spline element: the derivative across the seam, carried over by the
    // rotation (Gmsh's Jacobians), turns by rounding only, as across the interior facets
    // (kept C⁰, 0.26° to 0.83° on average and up to 1.2°, when the sides were curved apart).
    // In 2D that needs the wall's smooth targets at the seam fitted over both sides: built
    // from one side, a C¹ spline cannot follow both sides' targets and the misfit rounds made
    // the wall rows Q2 (C⁰ between them; 1.5° and 4.0° across the seam). Uniform knots hold
    // every element back, so the angle is not asserted there. Everywhere: the report says
    // c1, the written images are exact, the smallest scaled Jacobian is within 0.999 of the
    // input's (curved apart: 0.9964 against 0.9995 on the uniform 30° sector), and where the
    // spline is kept whole, sampling the two sides from it already gives images to rounding.
    for (dim, deg) in [(3, 30), (3, 90), (2, 30), (2, 90)] {
        let name = format!("rsector{dim}d_{deg}");
        let linear = generated_sector("periodic_rotation", &name, dim, deg);
        for knots in ["graded", "uniform"] {
            for order in ["2", "3"] {
                let what = format!("{name} {knots} order {order}");
                let out = scratch_in("periodic_rotation", &format!("{name}_{knots}_{order}.msh"));
                let report = curve(
                    &linear,
                    &out,
                    &["--order", order, "--knot-intervals", knots],
                );
                let per = &report["periodic"];
                assert_eq!(per["pairs"][0]["kind"], "rotation", "{what}");
                assert_eq!(per["seam"], "c1", "{what}: {per}");
                // Where the blend holds elements back towards the target map, whose smooth
                // corrections are reconstructed on each side of the seam apart, the sides
                // differ before the exact-image step (uniform knots: all, by 1e-7).
                let held = report["reduced_elements"].as_u64().unwrap();
                let shift = per["max_seam_shift"].as_f64().unwrap();
                let diag = report["bounding_box_diagonal"].as_f64().unwrap();
                assert!(
                    held > 0 || shift <= IMAGE_TOL * diag,
                    "{what}: seam nodes moved {shift:e}"
                );
                let sj = report["min_scaled_jacobian"].as_f64().unwrap();
                let input_sj = report["input_min_scaled_jacobian"].as_f64().unwrap();
                // Held back whole (uniform knots), the map is near the input's.
                assert!(
                    sj >= 0.999 * input_sj,
                    "{what}: min scaled Jacobian {sj} < {input_sj}"
                );
                assert_exact_images(&out, 1);
                if knots == "graded" {
                    assert_eq!(held, 0, "{what}");
                    if dim == 2 {
                        assert_eq!(report["q2_elements"], 0, "{what}");
                    }
                    // Every facet of the 6 × (2 layers in 3D) seam.
                    common::assert_seams_c1(&out, if dim == 3 { 12 } else { 6 }, &what);
                }
            }
        }
    }
}

#[test]
fn rotation_seams_are_c1_with_the_energy_fit() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    // `--fit energy` identifies rotation pairs in the spline space as the least-squares fit
    // does: the energy's nets see the points across the seam rotated, its least-squares term
    // couples their coordinates, and both minimisers move them through the rotation. On the
    // generated 30° sectors with graded knots every element is a C¹ spline element, so the
    // derivative across the seam, carried over by the rotation (Gmsh's Jacobians), turns by
    // rounding only, as inside; with the rotation pairs kept apart under the energy (C⁰,
    // each side fitted on its own) it turned by up to 7.9° (3D) and 9.1° (2D) against 0° in
    // the interior. The written images are exact, every element valid by Gmsh's Jacobians,
    // and the smallest scaled Jacobian within 0.999 of the input's (apart: 0.996).
    for (dim, solver) in [(3, "lbfgs"), (3, "colored"), (2, "lbfgs")] {
        let name = format!("esector{dim}d");
        let linear = generated_sector("periodic_energy", &name, dim, 30);
        let what = format!("{name} {solver}");
        let out = scratch_in("periodic_energy", &format!("{name}_{solver}.msh"));
        let report = curve(
            &linear,
            &out,
            &[
                "--order",
                "3",
                "--fit",
                "energy",
                "--energy-solver",
                solver,
                "--knot-intervals",
                "graded",
            ],
        );
        let per = &report["periodic"];
        assert_eq!(per["pairs"][0]["kind"], "rotation", "{what}");
        assert_eq!(per["seam"], "c1", "{what}: {per}");
        assert!(report["energy"].is_object(), "{what}: the energy ran");
        assert_eq!(report["q2_elements"], 0, "{what}");
        let sj = report["min_scaled_jacobian"].as_f64().unwrap();
        let input_sj = report["input_min_scaled_jacobian"].as_f64().unwrap();
        assert!(
            sj >= 0.999 * input_sj,
            "{what}: min scaled Jacobian {sj} < {input_sj}"
        );
        assert_exact_images(&out, 1);
        common::assert_seams_c1(&out, if dim == 3 { 12 } else { 6 }, &what);
        let jobs = out.with_extension("jobs.json");
        let (lo, _, _) = common::gmsh_det_range(&out, &jobs).expect("gmsh is available");
        assert!(lo > 0.0, "{what}: Gmsh's smallest det J {lo}");
    }
}

#[test]
fn auto_knots_under_the_energy_keep_the_seams_c1() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    // `--knot-intervals auto` under `--fit energy`: the energy counts the elements invalid at
    // its full step as held back, so auto may keep graded knots, which are measured on the
    // glued seams (one ratio on both sides). Whatever it chooses, the report says c1, the
    // written images are exact (Gmsh's pairs), and the facet angle across the seam is no
    // larger than across the interior facets (Gmsh's Jacobians); where it keeps graded knots
    // and holds nothing back, every facet is C¹ to rounding. Rotation (generated 30°
    // sectors, 2D and 3D) and translation (the bump channel, 2D and 3D).
    for (dim, kind) in [
        (2, "rotation"),
        (3, "rotation"),
        (2, "translation"),
        (3, "translation"),
    ] {
        let name = format!("auto_{kind}{dim}d");
        let (linear, pair): (PathBuf, &[&str]) = if kind == "rotation" {
            (generated_sector("periodic_auto", &name, dim, 30), &[])
        } else {
            let input = scratch_in("periodic_auto", &format!("{name}.msh"));
            let (nx, ny) = if dim == 2 { (24, 6) } else { (16, 4) };
            common::write_linear(&channel(dim, nx, ny), &input);
            (input, &["--periodic", "left:right"])
        };
        let out = scratch_in("periodic_auto", &format!("{name}_out.msh"));
        let mut args = vec![
            "--order",
            "3",
            "--fit",
            "energy",
            "--knot-intervals",
            "auto",
        ];
        args.extend(pair);
        let report = curve(&linear, &out, &args);
        let per = &report["periodic"];
        assert_eq!(per["pairs"][0]["kind"], kind, "{name}");
        assert_eq!(per["seam"], "c1", "{name}: {per}");
        assert!(report["energy"].is_object(), "{name}: the energy ran");
        assert_exact_images(&out, 1);
        common::assert_seams_no_rougher(&out, &name);
        let held = report["reduced_elements"].as_u64().unwrap();
        if report["knot_intervals"] == "graded" && held == 0 && report["q2_elements"] == 0 {
            let facets = match (kind, dim) {
                ("rotation", 3) => 12,
                ("rotation", _) => 6,
                (_, 3) => 12,
                _ => 6,
            };
            common::assert_seams_c1(&out, facets, &name);
        }
        let jobs = out.with_extension("jobs.json");
        let (lo, _, _) = common::gmsh_det_range(&out, &jobs).expect("gmsh is available");
        assert!(lo > 0.0, "{name}: Gmsh's smallest det J {lo}");
    }
}

/// The annulus 1 ≤ r ≤ 2 with its grid lines at the angles `angles` (degrees), 8 cells across,
/// (3D: `layers` layers over 0 ≤ z ≤ 0.5); `closed`: a whole ring, the last angle the first's
/// plus 360°. Sides `hub`, `shroud`, open: `lo`, `hi`, 3D: `bottom`, `top`. Elements column by
/// column (θ outermost), so a sector's elements are the first ones of a ring of its copies.
fn annulus(angles: &[f64], closed: bool, layers: usize) -> LinearMesh {
    let (nr, cells) = (8, angles.len() - 1);
    let columns = if closed { cells } else { cells + 1 };
    let nz = layers.max(1);
    let dim = if layers > 0 { 3 } else { 2 };
    let id = |i: usize, j: usize, k: usize| ((k * columns + j % columns) * (nr + 1) + i) as u32;
    let mut coords = Vec::new();
    for k in 0..=layers {
        for &a in &angles[..columns] {
            let t = a.to_radians();
            for i in 0..=nr {
                let r = 1.0 + i as f64 / nr as f64;
                coords.push([r * t.cos(), r * t.sin(), 0.5 * k as f64 / nz as f64]);
            }
        }
    }
    let quad = |i: usize, j: usize, k: usize| {
        [
            id(i, j, k),
            id(i + 1, j, k),
            id(i + 1, j + 1, k),
            id(i, j + 1, k),
        ]
    };
    let (mut elements, mut facets, mut tags) = (Vec::new(), Vec::new(), Vec::new());
    for j in 0..cells {
        for k in 0..nz {
            for i in 0..nr {
                elements.extend(quad(i, j, k));
                if dim == 3 {
                    elements.extend(quad(i, j, k + 1));
                }
            }
        }
    }
    // The side through the grid points (i, j, k) and (i2, j2, k) (3D: and their layer above).
    let mut side = |a: (usize, usize), b: (usize, usize), k: usize, tag: i32| {
        facets.extend([id(a.0, a.1, k), id(b.0, b.1, k)]);
        if dim == 3 {
            facets.extend([id(b.0, b.1, k + 1), id(a.0, a.1, k + 1)]);
        }
        tags.push(tag);
    };
    for k in 0..nz {
        for j in 0..cells {
            side((0, j), (0, j + 1), k, 1);
            side((nr, j), (nr, j + 1), k, 2);
        }
        for i in 0..nr.min(if closed { 0 } else { nr }) {
            side((i, 0), (i + 1, 0), k, 3);
            side((i, cells), (i + 1, cells), k, 4);
        }
    }
    if dim == 3 {
        for j in 0..cells {
            for i in 0..nr {
                for (k, tag) in [(0, 5), (layers, 6)] {
                    facets.extend(quad(i, j, k));
                    tags.push(tag);
                }
            }
        }
    }
    let names = ["hub", "shroud", "lo", "hi", "bottom", "top"];
    LinearMesh {
        dim,
        coords,
        elements,
        tagged_facets: facets,
        facet_tags: tags,
        tag_names: (1..=6)
            .zip(names)
            .filter(|&(t, _)| (dim == 3 || t <= 4) && (!closed || !(3..=4).contains(&t)))
            .map(|(t, n)| (t, n.to_string()))
            .collect(),
        ..Default::default()
    }
}

#[test]
fn a_glued_sector_curves_as_the_whole_ring() {
    // A 30° sector whose hub and shroud cells are 1°, 24°, 4° and 1° wide, and the ring of 12
    // such sectors, curved at order 3: the ring is rotationally periodic by construction, so
    // its nodes on the sector's elements are the glued sector's (the sector's seam at 0° and
    // 30° lies inside the ring). The seam's interior vertices next to the walls are too far
    // from their own wall vertex (1° cells) and from the next one on their side to inherit
    // its model: on the ring their nearest wall vertex is the one 1° past the seam, across
    // it in the sector. Inheriting along their own side only, the sector's nodes were up to
    // 1.3e-5 (2D) and 2.1e-5 (3D, two layers) from the ring's.
    let pattern = [0.0, 1.0, 25.0, 29.0];
    let ring_angles: Vec<f64> = (0..12)
        .flat_map(|k| pattern.map(|a| a + 30.0 * k as f64))
        .chain([360.0])
        .collect();
    for layers in [0, 2] {
        let what = if layers == 0 { "2D" } else { "3D" };
        let dir = "periodic_ring";
        let (sector, ring) = (
            scratch_in(dir, &format!("sector{layers}.msh")),
            scratch_in(dir, &format!("ring{layers}.msh")),
        );
        common::write_linear(
            &annulus(&[0.0, 1.0, 25.0, 29.0, 30.0], false, layers),
            &sector,
        );
        common::write_linear(&annulus(&ring_angles, true, layers), &ring);
        let (s_out, r_out) = (
            scratch_in(dir, &format!("sector{layers}_out.msh")),
            scratch_in(dir, &format!("ring{layers}_out.msh")),
        );
        let solver = ["--order", "3", "--fit-solver", "cholesky"];
        let report = curve(
            &sector,
            &s_out,
            &[&solver[..], &["--periodic", "lo:hi"]].concat(),
        );
        assert_eq!(report["periodic"]["seam"], "c1", "{what}");
        curve(&ring, &r_out, &solver);
        let read = |p: &Path| HighOrderMesh::from_raw(read_raw(p).unwrap()).unwrap();
        let (s, r) = (read(&s_out), read(&r_out));
        let mut gap = 0.0f64;
        for e in 0..s.n_elements() {
            for (&a, &b) in s.element(e).iter().zip(r.element(e)) {
                gap = gap.max(common::dist(s.nodes[a as usize], r.nodes[b as usize]));
            }
        }
        assert!(
            gap < 1e-9,
            "{what}: the sector's nodes {gap:e} from the ring's"
        );
    }
}

#[test]
fn pyfr_import_connects_the_periodic_faces() {
    let test = common::current_test();
    if !python_has("pyfr", &test) || !python_has("h5py", &test) {
        return;
    }
    let input = Path::new(ROOT).join(TURBINE);
    let out = scratch_in("periodic", "turbine_pyfr.msh");
    curve(
        &input,
        &out,
        &[
            "--periodic",
            "periodic_1:periodic_2",
            "--periodic-pyfr-names",
        ],
    );
    // 144 facets on each side: 144 connected face pairs.
    assert_eq!(pyfr_periodic_sizes(&out), "[144]");
}

/// Gmsh's own periodic meshes (`gmsh_periodic_input.py`: `setPeriodic` on a curved-sided
/// channel, an annular sector and a box, MSH 4.1 ASCII and binary and 2.2) in `dir`.
fn gmsh_periodic_inputs() -> PathBuf {
    let dir = scratch_in("periodic_input", "x")
        .parent()
        .unwrap()
        .to_owned();
    run_ok(
        python()
            .arg(Path::new(ROOT).join("tests/external/gmsh_periodic_input.py"))
            .arg(&dir),
    );
    dir
}

#[test]
fn gmsh_periodic_sections_are_used_without_the_option() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    let dir = gmsh_periodic_inputs();
    for (file, master, image, kind) in [
        ("channel2d_41.msh", "left", "right", "translation"),
        ("channel2d_41b.msh", "left", "right", "translation"),
        ("channel2d_22.msh", "left", "right", "translation"),
        ("sector2d_41.msh", "theta_lo", "theta_hi", "rotation"),
        ("box3d_41.msh", "xmin", "xmax", "translation"),
    ] {
        let input = dir.join(file);
        // `info` reports the file's pair.
        let info = run_ok(polyspline().arg("info").arg(&input).arg("--json"));
        let info: Value = serde_json::from_slice(&info.stdout).unwrap();
        let pairs = info["periodic"].as_array().unwrap();
        assert_eq!(pairs.len(), 1, "{file}: {info}");
        assert_eq!(
            (
                &pairs[0]["master"],
                &pairs[0]["slave"],
                &pairs[0]["from_file"]
            ),
            (
                &Value::from(master),
                &Value::from(image),
                &Value::Bool(true)
            ),
            "{file}"
        );
        // `curve` without --periodic pairs the sides and Gmsh sees exact images.
        for order in ["2", "4"] {
            let out = scratch_in("periodic_input", &format!("o{order}_{file}"));
            let report = curve(&input, &out, &["--order", order]);
            let per = &report["periodic"];
            assert_eq!(per["pairs"][0]["kind"], kind, "{file}: {per}");
            assert_eq!(per["pairs"][0]["from_file"], true, "{file}: {per}");
            assert!(
                per["written_mismatch"].as_f64().unwrap() <= IMAGE_TOL,
                "{file}: {per}"
            );
            let links = assert_exact_images(&out, 1);
            assert_eq!(links[image]["master_name"], master, "{file}");
        }
    }
    // A pair given on the command line wins for its groups.
    let input = dir.join("channel2d_41.msh");
    let out = scratch_in("periodic_input", "reversed.msh");
    let report = curve(&input, &out, &["--periodic", "right:left"]);
    let pairs = report["periodic"]["pairs"].as_array().unwrap();
    assert_eq!(pairs.len(), 1, "{pairs:?}");
    assert_eq!(
        (&pairs[0]["master"], &pairs[0]["from_file"]),
        (&Value::from("right"), &Value::Bool(false))
    );
    // A file whose affine map is not the transform of its nodes: one line naming the file
    // and the pair, nothing written.
    let good = std::fs::read_to_string(dir.join("channel2d_22.msh")).unwrap();
    let bad = good.replace("Affine 1 0 0 1 ", "Affine 1 0 0 1.01 ");
    assert_ne!(bad, good, "the 2.2 file's affine line changed");
    let input = scratch_in("periodic_input", "bad_affine.msh");
    std::fs::write(&input, bad).unwrap();
    let out = scratch_in("periodic_input", "bad_affine_out.msh");
    let _ = std::fs::remove_file(&out);
    assert_refused(
        polyspline().arg("curve").arg(&input).arg("-o").arg(&out),
        &["bad_affine.msh", "$Periodic pair left:right", "disagrees"],
    );
    assert!(!out.exists());
}

/// Largest distance of the nodes of `group` of `file` from the analytic `wall`
/// (`wall_error.py`, Gmsh's reading).
fn wall_error(file: &Path, group: &str, wall: &str) -> f64 {
    let v = wall_error_report(file, group, wall);
    assert!(v["nodes"].as_u64().unwrap() > 0, "{group}: {v}");
    v["max_error"].as_f64().unwrap()
}

/// `wall_error.py`'s report on the nodes of `group` of `file` against the analytic `wall`.
fn wall_error_report(file: &Path, group: &str, wall: &str) -> Value {
    let out = run_ok(
        python()
            .arg(Path::new(ROOT).join("tests/external/wall_error.py"))
            .arg(file)
            .args([group, wall]),
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn generated_channel_and_sector_are_periodic_and_curve_onto_their_walls() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    let rotation = rotation_z(40.0);
    let shift = [1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let channel = "--around 12 --across 8 --first-height 0.02 --bump 0.15";
    let sector = "--around 6 --across 8 --first-height 0.02 --sector 40";
    for (name, args, pair, expect, walls) in [
        (
            "channel2d",
            channel.to_string(),
            ["periodic_left", "periodic_right"],
            shift,
            vec![("wall", "bump=0.15")],
        ),
        (
            "channel3d",
            format!("{channel} --layers 2 --span 0.3"),
            ["periodic_left", "periodic_right"],
            shift,
            vec![("wall", "bump=0.15")],
        ),
        (
            "sector2d",
            sector.to_string(),
            ["periodic_lo", "periodic_hi"],
            rotation,
            vec![("hub", "r=1"), ("shroud", "r=2")],
        ),
        (
            "sector3d",
            format!("{sector} --layers 2 --span 0.5"),
            ["periodic_lo", "periodic_hi"],
            rotation,
            vec![("hub", "r=1"), ("shroud", "r=2")],
        ),
    ] {
        let kind = &name[..name.len() - 2];
        let linear = scratch_in("periodic_generate", &format!("{name}.msh"));
        run_ok(
            polyspline()
                .args(["generate", kind, "-o"])
                .arg(&linear)
                .args(args.split(' ')),
        );
        // The generated file carries the pair: Gmsh reads it, images exact.
        let links = assert_exact_images(&linear, 1);
        assert_eq!(links[pair[1]]["master_name"], pair[0], "{name}");
        assert_affine(&links[pair[1]], &expect, 1e-12, name);
        // Curved without --periodic: the pair from the file, exact images at order 3, and the
        // walls closer to the analytic curves than the straight order-3 mesh's nodes (by a fifth
        // at least; the 3D channel's wall meets the periodic sides and the end planes in
        // feature edges, where it gains least).
        let curved = scratch_in("periodic_generate", &format!("{name}_o3.msh"));
        let report = curve(&linear, &curved, &["--order", "3"]);
        assert_eq!(report["periodic"]["pairs"][0]["from_file"], true, "{name}");
        let links = assert_exact_images(&curved, 1);
        assert_eq!(links[pair[1]]["master_name"], pair[0], "{name}");
        let straight = scratch_in("periodic_generate", &format!("{name}_straight.msh"));
        curve(&linear, &straight, &["--order", "3", "--straight"]);
        for (group, wall) in walls {
            let (before, after) = (
                wall_error(&straight, group, wall),
                wall_error(&curved, group, wall),
            );
            assert!(
                after < 0.8 * before,
                "{name} {group}: curved nodes {after:e} from the wall, straight {before:e}"
            );
        }
    }
}

/// The largest distance from the analytic `wall` of the nodes of `group`'s facets of each kind
/// (`wall_error.py`: `seam` with a node on a periodic side, `inner` without, `_rim` with one on
/// another boundary group too).
fn wall_error_by_kind(file: &Path, group: &str, wall: &str) -> BTreeMap<String, f64> {
    serde_json::from_value(wall_error_report(file, group, wall)["by_kind"].clone()).unwrap()
}

/// A 40° sector of the annulus (hub r = 1, shroud r = 2), 6 columns and 8 layers graded to
/// both walls, 0.5 long, written to `linear`.
fn sector_40(linear: PathBuf) -> PathBuf {
    run_ok(
        polyspline()
            .args(["generate", "sector", "-o"])
            .arg(&linear)
            .args(
                "--sector 40 --around 6 --across 8 --first-height 0.02 --layers 4 --span 0.5"
                    .split(' '),
            ),
    );
    linear
}

#[test]
fn walls_at_3d_seams_are_fitted_from_both_sides() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    // A 40° annular sector of 6 columns and 4 layers: its hub (r = 1) and shroud (r = 2) meet
    // the rotation seam, and the two end planes in rims. Glued, every column is the same as
    // the next one, so walls fitted from both sides at the seam are as close to the cylinders
    // there as between (found: equal to 1e-6 of the distance), kind by kind (facets with a
    // rim node or without), and the largest facet angle across the seam is the interior's
    // (0.51°, between the rims' Q2 cells; the mean is not compared: the seam's facets are all
    // across the columns, where the rims' C⁰ facets are, the interior's mostly C¹ ones). With
    // the smooth targets (and the rims' curve and patch models) at the seam built from one
    // side only, the walls' seam facets were 13–15 % farther than the interior's (hub 3.5e-6
    // against 3.1e-6, 3× farther than both sides now), 1.8× at the hub's rim corners once
    // the other vertices were two-sided, and the seam facet angle reached 3.6° against 2.0°.
    let linear = sector_40(scratch_in("periodic_walls", "sector3d.msh"));
    let out = scratch_in("periodic_walls", "sector3d_o3.msh");
    let report = curve(&linear, &out, &["--order", "3"]);
    assert_eq!(report["periodic"]["seam"], "c1", "{}", report["periodic"]);
    assert_exact_images(&out, 1);
    let p = common::periodic_probe(&out);
    assert!(p["seam_facets"].as_u64().unwrap() >= 24, "{p}");
    let (seam, inside) = (
        p["seam_angle_max"].as_f64().unwrap(),
        p["interior_angle_max"].as_f64().unwrap(),
    );
    assert!(
        seam <= inside.max(1e-3),
        "seam {seam}° > interior {inside}° ({p})"
    );
    for (group, wall) in [("hub", "r=1"), ("shroud", "r=2")] {
        let e = wall_error_by_kind(&out, group, wall);
        for kind in ["", "_rim"] {
            let (seam, inner) = (e[&format!("seam{kind}")], e[&format!("inner{kind}")]);
            assert!(
                seam <= 1.001 * inner,
                "{group}{kind}: seam facets {seam:e} from the wall, interior {inner:e} ({e:?})"
            );
        }
    }
}

#[test]
fn coarse_walls_take_their_arcs_across_rotation_seams() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    // Annular sectors of 3, 4 and 5 cells turning 32° each (coarse: past the arcs' 30°, short
    // of the features' 35°), 4 across and 4 layers: the hub (r = 1) and shroud (r = 2) take
    // circular arcs on normals from their grid lines' conics. Glued, a seam column is one of
    // the ring's columns, so the walls' facets at the seam must be about as close to the
    // cylinders as the interior's (facets off the end planes' rims, whose Q2 cells are another
    // matter). With the seam vertices' grid lines and coarse flag, and the lines of their
    // neighbours, stopping at the seam, the hub's seam facets were 19× farther than the
    // interior's (1.39e-3 against 7.4e-5), the shroud's 2.6–3×; with the grid lines going on across the seam, the shroud's
    // within 0.3 % of the interior and the hub's seam column exact, its cell next to the seam
    // on one side 1.33× farther on the odd rings (9.8e-5; equal on the 4-cell ring).
    for (deg, around) in [(96, 3), (128, 4), (160, 5)] {
        let name = format!("sector{deg}");
        let linear = scratch_in("periodic_coarse", &format!("{name}.msh"));
        let args = format!(
            "--sector {deg} --around {around} --across 4 --first-height 0.2 --growth 1.1 \
             --layers 4 --span 2"
        );
        run_ok(
            polyspline()
                .args(["generate", "sector", "-o"])
                .arg(&linear)
                .args(args.split_whitespace()),
        );
        let out = scratch_in("periodic_coarse", &format!("{name}_o3.msh"));
        let report = curve(&linear, &out, &["--order", "3"]);
        assert_eq!(report["periodic"]["seam"], "c1", "{}", report["periodic"]);
        assert_exact_images(&out, 1);
        for (group, wall) in [("hub", "r=1"), ("shroud", "r=2")] {
            let e = wall_error_by_kind(&out, group, wall);
            let (seam, inner) = (e["seam"], e["inner"]);
            assert!(
                seam <= 1.4 * inner,
                "{name} {group}: seam facets {seam:e} from the wall, interior {inner:e} ({e:?})"
            );
        }
    }
}

/// `curve INPUT -o OUT --backend gpu ARGS --report`: the report, or `None` (a visible skip
/// naming `what`; a failure under `CI=true`) where no GPU adapter exists.
fn curve_on_gpu(input: &Path, out: &Path, args: &[&str], what: &str) -> Option<Value> {
    let report = out.with_extension("json");
    let run = polyspline()
        .arg("curve")
        .arg(input)
        .arg("-o")
        .arg(out)
        .args(["-q", "--backend", "gpu"])
        .args(args)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    if !run.status.success() && err.contains("GPU adapter") {
        common::skip(
            &common::current_test(),
            &format!("{what} was not checked: {}", err.trim()),
        );
        return None;
    }
    assert!(run.status.success(), "{what}: {err}");
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["backend"], "gpu", "{what}");
    Some(r)
}

/// Across rotation seams the fit's coupled solve (K ⊗ I₃ + C, `fit::rotated`) runs where the
/// backend runs the fit, and the report says so: `coupled_fit_device` is `cpu` on the 30°
/// sectors (2D and 3D, seams `c1`) on the CPU; under `--backend gpu` it is `gpu`, and the
/// device's own count of the fit's dispatches (`gpu_traffic.fit`) covers the solve's
/// iterations (at least the 8 kernels of a coupled iteration each); with `--fit-solver
/// cholesky` K's factor preconditions it on the CPU (`cpu`, no dispatch in the fit). A fit not
/// coupled (the sector with its pair not declared, the generated channel's translation
/// seams) has no such field. `coupled_fit_preconditioner` names what preconditioned the
/// coupled CG: K's block-Jacobi pair on the CPU, also when `--cg-preconditioner` asks for
/// another (which the summary line says), K's diagonal on the device, K's factor with
/// `--fit-solver cholesky`.
#[test]
fn the_report_says_where_the_coupled_fit_ran() {
    let sector_in = |dim: usize| {
        let path = scratch_in("periodic_coupled", &format!("sector{dim}d_in.msh"));
        common::write_linear(&sector(dim, 30.0, 3, 6), &path);
        path
    };
    for dim in [2, 3] {
        let input = sector_in(dim);
        let out = scratch_in("periodic_coupled", &format!("sector{dim}d.msh"));
        let r = curve(&input, &out, &["--periodic", "theta_lo:theta_hi"]);
        assert_eq!(r["periodic"]["seam"], "c1", "{}", r["periodic"]);
        assert_eq!(r["coupled_fit_device"], "cpu", "{dim}D");
        // The sectors are small enough to factor: `auto` runs the coupled CG on K's factor.
        assert_eq!(r["coupled_fit_preconditioner"], "cholesky", "{dim}D");
        let plain = curve(&input, &out, &[]);
        assert!(plain.get("coupled_fit_device").is_none(), "{dim}D: {plain}");
        assert!(plain.get("coupled_fit_preconditioner").is_none(), "{dim}D");
        // With CG asked for, K's pair, whatever `--cg-preconditioner` says, and the summary
        // line on stderr says so.
        for asked in ["block-jacobi-pair", "block-jacobi-lines", "jacobi"] {
            let mut cmd = polyspline();
            cmd.arg("curve")
                .arg(&input)
                .arg("-o")
                .arg(&out)
                .args(["--periodic", "theta_lo:theta_hi", "--fit-solver", "cg"])
                .args(["--cg-preconditioner", asked]);
            let report = scratch_in("periodic_coupled", &format!("sector{dim}d_{asked}.json"));
            let run = run_ok(cmd.arg("--report").arg(&report));
            let r: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
            assert_eq!(r["coupled_fit_device"], "cpu", "{dim}D {asked}");
            assert_eq!(
                r["coupled_fit_preconditioner"], "block-jacobi-pair",
                "{dim}D {asked}"
            );
            let stderr = String::from_utf8_lossy(&run.stderr);
            assert!(
                stderr.contains("coupled across rotation seams, CG on cpu preconditioned by K's block-jacobi-pair"),
                "{dim}D {asked}: {stderr}"
            );
        }
    }
    let channel = scratch_in("periodic_coupled", "channel.msh");
    run_ok(
        polyspline()
            .args([
                "generate", "channel", "--around", "12", "--across", "4", "-o",
            ])
            .arg(&channel),
    );
    let out = scratch_in("periodic_coupled", "channel_o2.msh");
    let r = curve(&channel, &out, &[]);
    assert_eq!(r["periodic"]["seam"], "c1", "{}", r["periodic"]);
    assert!(r.get("coupled_fit_device").is_none(), "{r}");
    // Under `--backend gpu` (where an adapter exists).
    let input = sector_in(3);
    for (solver, device) in [("auto", "gpu"), ("cholesky", "cpu")] {
        let out = scratch_in("periodic_coupled", &format!("sector3d_gpu_{solver}.msh"));
        let args = ["--periodic", "theta_lo:theta_hi", "--fit-solver", solver];
        let what = format!("the GPU run ({solver})");
        let Some(r) = curve_on_gpu(&input, &out, &args, &what) else {
            return;
        };
        assert_eq!(r["periodic"]["seam"], "c1", "{what}: {}", r["periodic"]);
        assert_eq!(r["coupled_fit_device"], device, "{what}: {r}");
        let pre = if device == "gpu" {
            "jacobi"
        } else {
            "cholesky"
        };
        assert_eq!(r["coupled_fit_preconditioner"], pre, "{what}: {r}");
        let dispatches = r["gpu_traffic"]["fit"]["dispatches"].as_u64().unwrap();
        let iterations = r["cg_iterations"].as_u64().unwrap();
        assert!(iterations > 0, "{what}: {r}");
        if device == "gpu" {
            assert!(
                dispatches >= 8 * iterations,
                "{what}: {dispatches} dispatches for {iterations} iterations"
            );
        } else {
            assert_eq!(dispatches, 0, "{what}: {}", r["gpu_traffic"]);
        }
    }
}

/// The generated 40° sector, periodic in θ (its own `$Periodic` rotation) and along z
/// (`--periodic zmin:zmax`), curved with its coupled fit on the device (`--backend gpu`, f64
/// and f32 kernels): both seams `c1`, Gmsh pairs every image node with its master under the
/// written affine maps to 1e-12 of the diagonal, and every node is within 1e-6 of the
/// diagonal of the CPU run's (found: 3.5e-11 in f64, 1.4e-8 in f32).
#[test]
fn the_sector_curves_on_the_device_as_on_the_cpu() {
    let dir = "periodic_device";
    let linear = sector_40(scratch_in(dir, "sector40.msh"));
    let args = ["--periodic", "zmin:zmax"];
    let cpu_out = scratch_in(dir, "sector40_cpu.msh");
    let cpu = curve(&linear, &cpu_out, &args);
    assert_eq!(cpu["coupled_fit_device"], "cpu", "{cpu}");
    let read = |p: &Path| HighOrderMesh::from_raw(read_raw(p).unwrap()).unwrap();
    let want = read(&cpu_out);
    let (lo, hi) = want.nodes.iter().fold(
        ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
        |(lo, hi), p| {
            (
                std::array::from_fn(|k| lo[k].min(p[k])),
                std::array::from_fn(|k| hi[k].max(p[k])),
            )
        },
    );
    let diag = common::dist(lo, hi);
    for precision in ["f64", "f32"] {
        let out = scratch_in(dir, &format!("sector40_gpu_{precision}.msh"));
        let what = format!("the {precision} GPU run");
        let gpu_args = [&args[..], &["--precision", precision]].concat();
        let Some(r) = curve_on_gpu(&linear, &out, &gpu_args, &what) else {
            return;
        };
        assert_eq!(r["coupled_fit_device"], "gpu", "{what}: {r}");
        assert_eq!(r["periodic"]["seam"], "c1", "{what}: {}", r["periodic"]);
        assert_eq!(
            r["periodic"]["pairs"].as_array().unwrap().len(),
            2,
            "{what}"
        );
        let got = read(&out);
        assert_eq!(got.n_elements(), want.n_elements(), "{what}");
        assert_eq!(got.nodes.len(), want.nodes.len(), "{what}");
        let mut gap = 0.0f64;
        for e in 0..want.n_elements() {
            for (&a, &b) in want.element(e).iter().zip(got.element(e)) {
                gap = gap.max(common::dist(want.nodes[a as usize], got.nodes[b as usize]));
            }
        }
        assert!(
            gap <= 1e-6 * diag,
            "{what}: nodes {:e} of the diagonal from the CPU run's",
            gap / diag
        );
        if common::have_gmsh(&common::current_test()) {
            assert_exact_images(&out, 2);
        }
    }
}

#[test]
fn a_wrong_periodic_pair_is_refused_in_one_line() {
    let turbine = Path::new(ROOT).join(TURBINE);
    let sector = sector_file(2, 30.0);
    for (input, pair, says) in [
        (&turbine, "periodic_1:airfoil", "cannot be images"),
        (
            &turbine,
            "periodic_1:nosuch",
            "no boundary group named or tagged \"nosuch\"",
        ),
        (&turbine, "periodic_1:4", "both sides"),
        // Same vertex counts, but the shroud is the hub scaled by 2: no rigid map.
        (
            &sector,
            "hub:shroud",
            "no translation or rotation maps hub onto shroud: vertex",
        ),
    ] {
        let out = scratch_in("periodic", "refused.msh");
        let _ = std::fs::remove_file(&out);
        let run = polyspline()
            .arg("curve")
            .arg(input)
            .arg("-o")
            .arg(&out)
            .args(["--periodic", pair])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{pair}: accepted");
        assert_eq!(err.trim().lines().count(), 1, "{pair}: {err}");
        assert!(err.contains(says), "{pair}: {err}");
        assert!(!out.exists(), "{pair}: wrote output");
    }
    // A PyFR naming option without pairs cannot apply.
    assert_refused(
        polyspline()
            .arg("curve")
            .arg(&turbine)
            .arg("-o")
            .arg(scratch_in("periodic", "refused.msh"))
            .arg("--periodic-pyfr-names"),
        &["--periodic-pyfr-names", "no periodic pair"],
    );
}

/// `cgns_periodic.py FILE`: the periodic grid connectivity of a CGNS file as h5py reads it.
fn cgns_probe(file: &Path) -> Value {
    let out = run_ok(
        python()
            .arg(Path::new(ROOT).join("tests/external/cgns_periodic.py"))
            .arg(file),
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `info` reports the sharp features `curve` works with: on the cascade with its translation
/// seams glued, the boundary is the blade, the inlet and the outlet (3 patches), and the
/// inlet's and outlet's ends, on the seams, are no corners; without `--periodic` the four
/// corners of each periodic side are there.
#[test]
fn info_reports_the_features_of_the_glued_cascade() {
    let turbine = Path::new(ROOT).join(TURBINE);
    let features = |extra: &[&str]| -> Value {
        let out = run_ok(
            polyspline()
                .arg("info")
                .arg(&turbine)
                .arg("--json")
                .args(extra),
        );
        serde_json::from_slice::<Value>(&out.stdout).unwrap()["features"].clone()
    };
    let glued = features(&["--periodic", "periodic_1:periodic_2"]);
    assert_eq!(
        (&glued["patches"], &glued["feature_corners"]),
        (&Value::from(3), &Value::from(0)),
        "{glued}"
    );
    let apart = features(&[]);
    assert_eq!(apart["feature_corners"], 8, "{apart}");
}

/// `info --knot-intervals graded --periodic` measures the knot surfaces as `curve` does, on the
/// cascade with its seams glued: its surfaces continue across the seams, so there are fewer
/// of them than on the sides apart, and the figures are the curve report's.
#[test]
fn info_measures_the_knots_across_the_glued_seams() {
    let turbine = Path::new(ROOT).join(TURBINE);
    let knots = |extra: &[&str]| -> Value {
        let out = run_ok(
            polyspline()
                .arg("info")
                .arg(&turbine)
                .args(["--json", "--knot-intervals", "graded"])
                .args(extra),
        );
        serde_json::from_slice::<Value>(&out.stdout).unwrap()["knot_surfaces"].clone()
    };
    let pair = ["--periodic", "periodic_1:periodic_2"];
    let glued = knots(&pair);
    let out = scratch_in("periodic", "turbine_info_knots.msh");
    let report = curve(
        &turbine,
        &out,
        &[pair[0], pair[1], "--knot-intervals", "graded"],
    );
    assert_eq!(glued, report["knot_surfaces"], "info and curve");
    let apart = knots(&[]);
    let surfaces = |v: &Value| v["surfaces"].as_u64().unwrap();
    assert!(
        surfaces(&glued) < surfaces(&apart),
        "{glued} against {apart}"
    );
}

/// A CGNS file's periodic grid connectivity makes the mesh periodic without any option: the
/// cascade's translation and the 3D sector's rotation and lift, written as CGNS by `curve
/// --order 1` (the writer is checked with h5py and cgnscheck below), are reported by `info`
/// as the pairs they were written from, and `curve` of that file pairs the same sides, its MSH
/// sides exact images as Gmsh reads them. A map that carries no group onto another is refused
/// in one line naming the connection node.
#[test]
fn cgns_periodic_connectivity_is_read_as_its_pairs() {
    let test = common::current_test();
    let turbine = Path::new(ROOT).join(TURBINE);
    let s3 = sector_file(3, 30.0);
    let cases: [(&str, &Path, &[&str]); 2] = [
        (
            "turbine",
            &turbine,
            &["--periodic", "periodic_1:periodic_2"],
        ),
        (
            "sector3d",
            &s3,
            &[
                "--periodic",
                "theta_lo:theta_hi",
                "--periodic",
                "bottom:top",
            ],
        ),
    ];
    let sides = |pairs: &Value| -> Vec<(String, String, String)> {
        let mut v: Vec<_> = pairs
            .as_array()
            .unwrap()
            .iter()
            .map(|p| {
                let mut s = [p["master"].as_str().unwrap(), p["slave"].as_str().unwrap()];
                s.sort_unstable();
                (s[0].to_string(), s[1].to_string(), p["kind"].to_string())
            })
            .collect();
        v.sort();
        v
    };
    for (name, input, given) in cases {
        let cgns = scratch_in("periodic_cgns", &format!("{name}.cgns"));
        let mut args = vec!["--order", "1"];
        args.extend(given);
        let written = curve(input, &cgns, &args);
        let want = sides(&written["periodic"]["pairs"]);
        assert_eq!(want.len(), given.len() / 2, "{name}: {written}");
        let info = run_ok(polyspline().arg("info").arg(&cgns).arg("--json"));
        let info: Value = serde_json::from_slice(&info.stdout).unwrap();
        assert_eq!(sides(&info["periodic"]), want, "{name}: {info}");
        assert!(
            info["periodic"]
                .as_array()
                .unwrap()
                .iter()
                .all(|p| p["from_file"] == true),
            "{name}: {info}"
        );
        let out = scratch_in("periodic_cgns", &format!("{name}_o3.msh"));
        let report = curve(&cgns, &out, &["--order", "3"]);
        assert_eq!(
            sides(&report["periodic"]["pairs"]),
            want,
            "{name}: {report}"
        );
        if common::have_gmsh(&test) {
            assert_exact_images(&out, want.len());
        }
    }
    // The cascade's map moved by a tenth of the pitch: no side lands on another. The stored
    // translation's y (single precision) is found as h5py reads it.
    let cgns = scratch_in("periodic_cgns", "turbine.cgns");
    let bytes = std::fs::read(&cgns).unwrap();
    let moved = scratch_in("periodic_cgns", "moved_map.cgns");
    let stored = cgns_probe(&cgns)["connections"][0]["translation"][1]
        .as_f64()
        .unwrap() as f32;
    let (from, to) = (stored.to_le_bytes(), (1.1 * stored).to_le_bytes());
    let at = bytes
        .windows(4)
        .position(|w| w == from)
        .expect("the cascade's translation is stored as f32");
    let mut bad = bytes.clone();
    bad[at..at + 4].copy_from_slice(&to);
    std::fs::write(&moved, bad).unwrap();
    let out = scratch_in("periodic_cgns", "moved_map.msh");
    let _ = std::fs::remove_file(&out);
    assert_refused(
        polyspline().arg("curve").arg(&moved).arg("-o").arg(&out),
        &[
            "moved_map.cgns",
            "periodic connection",
            "carries no boundary group",
        ],
    );
    assert!(!out.exists());
}

/// CGNS output carries every periodic pair as standard grid connectivity. The CGNS library's
/// `cgnscheck` accepts the file; read with h5py (`cgns_periodic.py`), each pair A → B has two
/// `GridConnectivity_t`, `A_to_B` and `B_to_A` (`Abutting1to1`, `Vertex`, donor the zone
/// itself), whose `PointList` is exactly the node set of the current side's boundary section
/// and `PointListDonor` the other side's, one entry per node pair of the MSH `$Periodic`;
/// the pairs are rigid images to rounding, and the stored `Periodic_t` (centre, angles about
/// x, y, z, translation), rebuilt into a map by the probe, carries each node onto its donor to
/// single precision: the cascade's translation (0, −0.0575), the sectors' 30° about z (forward
/// +30°, backward −30°; the 2D sector is written with 3 physical dimensions for its angle about
/// z), the 3D sector's lift by 0.5 along z.
#[test]
fn cgns_output_carries_the_periodic_pairs() {
    let test = common::current_test();
    if !python_has("h5py", &test) {
        return;
    }
    let turbine = Path::new(ROOT).join(TURBINE);
    let (s2, s3) = (sector_file(2, 30.0), sector_file(3, 30.0));
    let lift = ["--periodic", "bottom:top"];
    for (name, input, order, extra, phys) in [
        (
            "turbine",
            &turbine,
            "2",
            &["--periodic", "periodic_1:periodic_2"],
            2,
        ),
        (
            "sector2d",
            &s2,
            "4",
            &["--periodic", "theta_lo:theta_hi"],
            3,
        ),
        (
            "sector3d",
            &s3,
            "3",
            &["--periodic", "theta_lo:theta_hi"],
            3,
        ),
    ] {
        let out = scratch_in("periodic", &format!("{name}.cgns"));
        let mut args = vec!["--order", order];
        args.extend(extra);
        if name == "sector3d" {
            args.extend(lift);
        }
        let report = curve(input, &out, &args);
        // A planar mesh written with a z coordinate: cgnscheck notes its zero range.
        let allowed: &[&str] = if name == "sector2d" {
            &["coordinate range is 0"]
        } else {
            &[]
        };
        if !crate::formats::cgnscheck_allowing(&out, allowed) {
            return;
        }
        let v = cgns_probe(&out);
        let ctx = format!("{name}: {v}");
        assert_eq!(v["phys_dim"], phys, "{ctx}");
        let diag = v["diagonal"].as_f64().unwrap();
        let pairs = report["periodic"]["pairs"].as_array().unwrap();
        let conns = v["connections"].as_array().unwrap();
        assert_eq!(conns.len(), 2 * pairs.len(), "{ctx}");
        let mut entries = 0;
        for p in pairs {
            let (a, b) = (p["master"].as_str().unwrap(), p["slave"].as_str().unwrap());
            for (from, to, sign) in [(a, b, 1.0), (b, a, -1.0)] {
                let c = conns
                    .iter()
                    .find(|c| c["name"] == format!("{from}_to_{to}"))
                    .unwrap_or_else(|| panic!("{ctx}: no {from}_to_{to}"));
                assert_eq!(
                    (&c["type"], &c["location"], &c["donor"]),
                    (
                        &Value::from("Abutting1to1"),
                        &Value::from("Vertex"),
                        &Value::from("Zone")
                    ),
                    "{ctx}"
                );
                assert_eq!(
                    (&c["current_side"], &c["donor_side"]),
                    (&Value::from(from), &Value::from(to)),
                    "{ctx}"
                );
                let n = c["n"].as_u64().unwrap();
                assert!(n > 0 && c["donor_n"] == n && c["distinct"] == n, "{ctx}");
                if sign > 0.0 {
                    entries += n;
                }
                let miss = c["max_mismatch"].as_f64().unwrap() / diag;
                assert!(miss < 1e-6, "{ctx}: {from}_to_{to} misses by {miss:e}");
                let rigid = c["max_residual"].as_f64().unwrap() / diag;
                assert!(rigid < 1e-12, "{ctx}: {from}_to_{to} residual {rigid:e}");
                let f = |k: &str, i: usize| c[k][i].as_f64().unwrap();
                if p["kind"] == "rotation" {
                    let gamma = f("angles", 2).to_degrees();
                    assert!((gamma - sign * 30.0).abs() < 1e-4, "{ctx}: {gamma}");
                    assert!(f("angles", 0).abs() < 1e-6 && f("angles", 1).abs() < 1e-6);
                } else {
                    for i in 0..phys {
                        let t = sign * p["translation"][i].as_f64().unwrap();
                        assert!((f("translation", i) - t).abs() < 1e-6, "{ctx}");
                    }
                }
            }
        }
        assert_eq!(entries, report["periodic"]["node_pairs"], "{ctx}");
        // Gmsh's CGNS reader takes the 2D pairs (it classifies each node on one boundary
        // section, so a side's two end nodes sit on the neighbouring sides and stay unpaired;
        // in 3D it mixes up the sections sharing nodes, so only 2D is asked of it).
        if name != "sector3d" && common::have_gmsh(&test) {
            let g = common::periodic_probe(&out);
            let links = g["links"].as_array().unwrap();
            let p = &pairs[0];
            assert_eq!(links.len(), 1, "{name}: {g}");
            let l = &links[0];
            let sides = [l["name"].clone(), l["master_name"].clone()];
            assert!(
                sides == [p["master"].clone(), p["slave"].clone()]
                    || sides == [p["slave"].clone(), p["master"].clone()],
                "{name}: {l}"
            );
            let (n, own) = (
                l["pairs"].as_u64().unwrap(),
                l["entity_nodes"].as_u64().unwrap(),
            );
            assert!(n + 2 >= own && n > 0, "{name}: {l}");
            let miss = l["max_mismatch"].as_f64().unwrap() / g["diagonal"].as_f64().unwrap();
            assert!(miss < 1e-6, "{name}: {l}");
        }
    }
}

/// VTU output names the tags and records the pairs in its field data (`tag_ids`/`tag_names`,
/// `periodic_tags`, `periodic_affine`): VTK's own reader reads them (and meshio, which reads
/// only version-1.0 files: the 2D sector's), the names decode to the report's sides and the
/// affine rows are the report's transform, in every encoding.
#[test]
fn vtu_field_data_records_names_and_pairs() {
    let test = common::current_test();
    if !python_has("vtkmodules", &test) || !python_has("meshio", &test) {
        return;
    }
    let (s2, s3) = (sector_file(2, 30.0), sector_file(3, 30.0));
    let cases = [
        (
            &s3,
            "3",
            &[
                "--periodic",
                "theta_lo:theta_hi",
                "--periodic",
                "bottom:top",
            ][..],
        ),
        (&s2, "2", &["--periodic", "theta_lo:theta_hi"][..]),
    ];
    for ((input, dim, pairs), enc) in cases
        .iter()
        .flat_map(|c| ["ascii", "base64", "appended"].map(|e| (c, e)))
    {
        let out = scratch_in("periodic", &format!("sector{dim}d_{enc}.vtu"));
        let mut args = vec!["--order", "2", "--vtu-encoding", enc];
        args.extend(*pairs);
        let report = curve(input, &out, &args);
        let script = r#"
import json, sys
import meshio
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader
from vtkmodules.util.numpy_support import vtk_to_numpy
r = vtkXMLUnstructuredGridReader(); r.SetFileName(sys.argv[1]); r.Update()
fd = r.GetOutput().GetFieldData()
a = {fd.GetArrayName(i): vtk_to_numpy(fd.GetArray(i)).tolist() for i in range(fd.GetNumberOfArrays())}
names = bytes(a["tag_names"]).split(b"\0")[:-1]
m = sorted(meshio.read(sys.argv[1]).field_data) if sys.argv[2] == "2" else None
print(json.dumps({"names": dict(zip(a["tag_ids"], [n.decode() for n in names])),
                  "pairs": a["periodic_tags"], "affine": a["periodic_affine"],
                  "meshio": m, "cells": r.GetOutput().GetNumberOfCells()}))
"#;
        let o = run_ok(python().arg("-c").arg(script).arg(&out).arg(dim));
        let v: Value = serde_json::from_slice(&o.stdout).unwrap();
        let ctx = format!("{enc}: {v}");
        assert!(v["cells"].as_u64().unwrap() > 0, "{ctx}");
        if *dim == "2" {
            assert_eq!(
                v["meshio"],
                serde_json::json!(["periodic_affine", "periodic_tags", "tag_ids", "tag_names"]),
                "{ctx}"
            );
        }
        let pairs = report["periodic"]["pairs"].as_array().unwrap();
        assert_eq!(v["pairs"].as_array().unwrap().len(), pairs.len(), "{ctx}");
        for (i, p) in pairs.iter().enumerate() {
            let tags = &v["pairs"][i];
            let name = |t: &Value| v["names"][t.as_i64().unwrap().to_string()].clone();
            assert_eq!(name(&tags[0]), p["master"], "{ctx}");
            assert_eq!(name(&tags[1]), p["slave"], "{ctx}");
            let a = &v["affine"][i];
            let t = |k: usize| a[k].as_f64().unwrap();
            for (k, want) in [(3, 0), (7, 1), (11, 2)] {
                let tw = p["translation"][want].as_f64().unwrap();
                assert!((t(k) - tw).abs() < 1e-12, "{ctx}");
            }
            if p["kind"] == "rotation" {
                let deg = t(4).atan2(t(0)).to_degrees();
                assert!((deg - 30.0).abs() < 1e-9, "{ctx}: {deg}");
            } else {
                assert!((t(0) - 1.0).abs() < 1e-15 && t(1).abs() < 1e-15, "{ctx}");
            }
        }
    }
}

/// `--periodic-pyfr-names` names the pairs of a Gmsh input's own `$Periodic` section (no
/// `--periodic`): `pyfr import` connects the channel's periodic faces (8 facets a side).
#[test]
fn pyfr_names_apply_to_the_files_own_pairs() {
    let test = common::current_test();
    if !python_has("pyfr", &test) || !python_has("h5py", &test) || !common::have_gmsh(&test) {
        return;
    }
    let dir = gmsh_periodic_inputs();
    let out = scratch_in("periodic_input", "channel_pyfr.msh");
    let report = curve(
        &dir.join("channel2d_41.msh"),
        &out,
        &["--periodic-pyfr-names"],
    );
    assert_eq!(report["periodic"]["pyfr_names"], true, "{report}");
    assert_eq!(report["periodic"]["pairs"][0]["from_file"], true);
    assert_eq!(pyfr_periodic_sizes(&out), "[8]");
}

/// A `$Periodic` link whose entities are no two separate boundary groups (here the image
/// curve's elements lose their physical group) is refused in one line naming the file, the
/// link's entities and the fix, for `curve` and `info`; nothing is written.
#[test]
fn a_periodic_link_without_physical_groups_is_refused() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    let dir = gmsh_periodic_inputs();
    let good = std::fs::read_to_string(dir.join("channel2d_22.msh")).unwrap();
    // MSH 2.2: `$PhysicalNames` gives the tag of "right"; its line elements get physical 0.
    let right = good
        .lines()
        .find(|l| l.ends_with("\"right\""))
        .and_then(|l| l.split(' ').nth(1))
        .unwrap()
        .to_string();
    let mut in_elements = false;
    let mut changed = 0;
    let bad: Vec<String> = good
        .lines()
        .map(|l| {
            in_elements = match l {
                "$Elements" => true,
                "$EndElements" => false,
                _ => in_elements,
            };
            let f: Vec<&str> = l.split(' ').collect();
            if in_elements && f.len() > 4 && f[1] == "1" && f[3] == right {
                changed += 1;
                let mut f = f.clone();
                f[3] = "0";
                return f.join(" ");
            }
            l.to_string()
        })
        .collect();
    assert!(changed > 0, "no line element of group {right}");
    let input = scratch_in("periodic_input", "unnamed_side.msh");
    std::fs::write(&input, bad.join("\n") + "\n").unwrap();
    let out = scratch_in("periodic_input", "unnamed_side_out.msh");
    let _ = std::fs::remove_file(&out);
    for cmd in [vec!["curve", "-o", out.to_str().unwrap()], vec!["info"]] {
        assert_refused(
            polyspline().arg(cmd[0]).arg(&input).args(&cmd[1..]),
            &[
                "unnamed_side.msh",
                "$Periodic link of entities",
                "no physical group",
            ],
        );
    }
    assert!(!out.exists());
}

/// `generate sector` of `deg` degrees, 12 cells around and 6 across, first height 0.02 (in 3D
/// two layers over a span of 0.5), written as `name.msh` in the scratch folder `dir`.
fn generated_sector(dir: &str, name: &str, dim: usize, deg: u32) -> PathBuf {
    let linear = scratch_in(dir, &format!("{name}.msh"));
    let layers = if dim == 3 {
        " --layers 2 --span 0.5"
    } else {
        ""
    };
    let args = format!("--sector {deg} --around 12 --across 6 --first-height 0.02{layers}");
    run_ok(
        polyspline()
            .args(["generate", "sector", "-o"])
            .arg(&linear)
            .args(args.split(' ')),
    );
    linear
}

#[test]
fn hub_cells_on_two_seams_fit_the_cylinder_as_the_interior() {
    if !common::have_gmsh(&common::current_test()) {
        return;
    }
    // A 40° sector of the annulus, 0.5 long, periodic in θ (a rotation) and in z (a
    // translation): glued, every hub cell is the same as every other. The hub's corner cells,
    // on both seams, have wall vertices glued to three others; their fans and two-rings are
    // completed by all three (the models must see the whole glued wall), so those cells sit as
    // close to the cylinder r = 1 as the interior's (found: 4.45e-8 and 4.41e-8 against
    // 4.18e-8). With one partner kept per wall vertex (the last seam's), the corners were
    // 1.84e-6 from the cylinder and the θ seam's column 1.46e-7.
    let linear = sector_40(scratch_in("periodic_corner", "sector.msh"));
    let out = scratch_in("periodic_corner", "sector_o3.msh");
    let pairs = [
        "--periodic",
        "periodic_lo:periodic_hi",
        "--periodic",
        "zmin:zmax",
    ];
    let args = [&pairs[..], &["--order", "3", "--knot-intervals", "uniform"]];
    let report = curve(&linear, &out, &args.concat());
    assert_eq!(report["periodic"]["seam"], "c1", "{}", report["periodic"]);
    let run = run_ok(
        python()
            .arg(Path::new(ROOT).join("tests/external/cylinder_cells.py"))
            .arg(&out)
            .args(["hub", "1"]),
    );
    let e: BTreeMap<String, f64> = serde_json::from_slice(&run.stdout).unwrap();
    for kind in ["corner", "theta", "z"] {
        assert!(
            e[kind] <= 1.1 * e["interior"],
            "hub {kind} cells {:e} from the cylinder, interior {:e} ({e:?})",
            e[kind],
            e["interior"]
        );
    }
}
