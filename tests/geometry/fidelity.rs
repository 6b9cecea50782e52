//! Boundary fidelity against Gmsh with the exact CAD: analytic shapes made by Gmsh's Python API
//! (`scripts/fidelity_shapes.py`: an O-grid disk, a plate with a hole meshed by frontal quads and
//! recombined, a ball of tetrahedra subdivided into hexahedra), curved by the `polyspline` binary
//! at orders 2 and 3, and measured by the same script: RMS and max distance of the boundary (a
//! dense lattice of parameter points on every boundary side) from the exact surface, against
//! Gmsh's own order-2 mesh of the same linear mesh with its nodes on the CAD.
//!
//! * on the whole boundary ours is within 5× Gmsh-with-CAD at both orders: RMS and max on the
//!   O-grid disk, torus and cylinder and the unstructured plate (three levels) and ball (every
//!   element Q2 on the ball);
//! * `--fit energy` never leaves the boundary more than 1.5× further from the surface than the
//!   least-squares fit it starts from (RMS and max), and its output is valid by Gmsh's
//!   Jacobians;
//! * the default demotion redo is not kept where it moves the boundary off the first fit (the
//!   level-2 O-grid torus and cylinder): no further from the exact surface than with
//!   `--demote-uncertified`.
//!
//! Skipped visibly without Gmsh's Python module (a failure under `CI=true`).

use crate::common;

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

pub(super) fn dir() -> PathBuf {
    // The running test's own directory: tests run in parallel and share file names.
    common::test_dir()
}

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/fidelity_shapes.py");

/// The linear mesh and Gmsh's CAD order-2 mesh of `shape` at `level`.
pub(super) fn make(shape: &str, level: usize) -> (PathBuf, PathBuf) {
    let (linear, cad) = (
        dir().join(format!("{shape}_{level}.msh")),
        dir().join(format!("{shape}_{level}_cad.msh")),
    );
    common::run_ok(
        common::python()
            .arg(SCRIPT)
            .args(["make", shape, &level.to_string()])
            .arg(&linear)
            .arg(&cad),
    );
    (linear, cad)
}

/// (RMS, max) boundary distance of each file from the exact `shape`, over the points selected
/// by `--only` (`curved`: the curved part of the boundary; `all`).
pub(super) fn measure(shape: &str, files: &[&Path], only: &str) -> Vec<(f64, f64)> {
    let out = common::run_ok(
        common::python()
            .arg(SCRIPT)
            .args(["measure", shape, "--only", only])
            .args(files),
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Value = serde_json::from_str(l).unwrap();
            (v["rms"].as_f64().unwrap(), v["max"].as_f64().unwrap())
        })
        .collect()
}

pub(super) fn curve(input: &Path, output: &Path, args: &[&str]) {
    common::run_ok(
        Command::new(env!("CARGO_BIN_EXE_polyspline"))
            .arg("curve")
            .arg(input)
            .arg("-o")
            .arg(output)
            .args(["--msh-version", "2.2"])
            .args(args),
    );
}

/// Ours within 5× Gmsh-with-CAD on the whole boundary, orders 2 and 3: RMS and max on the
/// O-grid disk (levels 1 and 2), the plate at levels 1–3 (992 quads at level 3; the runs of
/// spline sides between Q2 elements that the fit leaves off the hole are made Q2 after the
/// fit, which puts the plate within 1.2× Gmsh-with-CAD at every level), the ball at level 1,
/// the O-grid torus at levels 1 and 2 (level 1: 45° per cell around the tube, the coarse
/// surface's arcs; level 2: its second-ring height functions need facets turning by more than
/// the feature angle from the vertex's normal) and the O-grid cylinder at levels 1 and 2 (sharp
/// rims between the exact caps and the side: one-sided height functions next to the rims and
/// Q2 cells along them; the max at level 2 was 8.6× before both).
#[test]
fn boundary_within_five_times_gmsh_with_cad() {
    if !common::have_gmsh("boundary_within_five_times_gmsh_with_cad") {
        return;
    }
    for (shape, level) in [
        ("disk", 1),
        ("disk", 2),
        ("plate", 1),
        ("plate", 2),
        ("plate", 3),
        ("ball", 1),
        ("torus", 1),
        ("torus", 2),
        ("cylinder", 1),
        ("cylinder", 2),
    ] {
        let (linear, cad) = make(shape, level);
        let mut files = vec![cad.clone()];
        for order in ["2", "3"] {
            let out = dir().join(format!("{shape}_{level}_o{order}.msh"));
            curve(&linear, &out, &["--order", order]);
            files.push(out);
        }
        let refs: Vec<&Path> = files.iter().map(|p| p.as_path()).collect();
        let m = measure(shape, &refs, "all");
        let (gmsh, ours) = (m[0], &m[1..]);
        for (order, (rms, max)) in [2, 3].iter().zip(ours) {
            println!(
                "{shape} level {level} order {order}: RMS {rms:.3e} ({:.2}× Gmsh-with-CAD {:.3e}), max {max:.3e} ({:.2}× {:.3e})",
                rms / gmsh.0,
                gmsh.0,
                max / gmsh.1,
                gmsh.1
            );
            assert!(
                *rms <= 5.0 * gmsh.0,
                "{shape} level {level} order {order}: RMS {rms:.3e} vs Gmsh {:.3e}",
                gmsh.0
            );
            assert!(
                *max <= 5.0 * gmsh.1,
                "{shape} level {level} order {order}: max {max:.3e} vs Gmsh {:.3e}",
                gmsh.1
            );
        }
    }
}

/// `--fit energy` keeps the least-squares fit's boundary: within 1.5× (RMS and max) on the
/// O-grid disk, the unstructured plate (levels 1 and 2: the energy starts from the fit with
/// the misfit runs made Q2) and the ball; Gmsh finds its det J positive.
#[test]
fn energy_fit_keeps_the_boundary() {
    if !common::have_gmsh("energy_fit_keeps_the_boundary") {
        return;
    }
    for (shape, level) in [("disk", 1), ("plate", 1), ("plate", 2), ("ball", 1)] {
        let (linear, _) = make(shape, level);
        let (ls, en) = (
            dir().join(format!("{shape}_{level}_ls.msh")),
            dir().join(format!("{shape}_{level}_energy.msh")),
        );
        curve(&linear, &ls, &[]);
        curve(&linear, &en, &["--fit", "energy"]);
        let m = measure(shape, &[&ls, &en], "all");
        let ((rms0, max0), (rms1, max1)) = (m[0], m[1]);
        println!(
            "{shape} level {level}: least squares RMS {rms0:.3e} max {max0:.3e}; energy RMS {rms1:.3e} max {max1:.3e}"
        );
        assert!(
            rms1 <= 1.5 * rms0,
            "{shape} level {level}: energy RMS {rms1:.3e} vs {rms0:.3e}"
        );
        assert!(
            max1 <= 1.5 * max0,
            "{shape} level {level}: energy max {max1:.3e} vs {max0:.3e}"
        );
        // Valid by Gmsh's Jacobians, signed in 2D (a mirrored quad fails).
        let jobs = dir().join(format!("{shape}_{level}_energy_jobs.json"));
        let (lo, hi, _) = common::gmsh_det_range(&en, &jobs).expect("Gmsh checked above");
        assert!(
            lo > 0.0,
            "{shape} level {level}: Gmsh finds the energy fit's det J in [{lo:e}, {hi:e}]"
        );
    }
}

/// `auto`'s knots on the level-2 O-grid disk with the extraordinary midpoint weight on (the
/// default, given here explicitly): the four valence-3 vertices of its central block make the
/// weight raise the interior midpoints around them. Fitted with it, uniform knots' blend held
/// back as few elements as graded knots' (44 of 192; 124 without it), so `auto` kept the
/// uniform spline, whose max boundary error is 5.45× Gmsh-with-CAD's. The knots are chosen
/// without the weight: graded knots, within 1.1× Gmsh-with-CAD (RMS and max) against the
/// exact circle.
#[test]
fn auto_keeps_graded_knots_on_the_disk_with_the_extraordinary_weight() {
    if !common::have_gmsh("auto_keeps_graded_knots_on_the_disk_with_the_extraordinary_weight") {
        return;
    }
    let (linear, cad) = make("disk", 2);
    let out = dir().join("disk_2_ev.msh");
    let report = dir().join("disk_2_ev.json");
    curve(
        &linear,
        &out,
        &[
            "--w-extraordinary-midpoint",
            "3",
            "--report",
            report.to_str().unwrap(),
        ],
    );
    let r: Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let m = measure("disk", &[&cad, &out], "all");
    let (gmsh, (rms, max)) = (m[0], m[1]);
    println!(
        "disk level 2 ({} knots, {} of {} held back): RMS {:.2}×, max {:.2}× Gmsh-with-CAD",
        r["knot_intervals"],
        r["reduced_elements"],
        r["elements"],
        rms / gmsh.0,
        max / gmsh.1
    );
    assert_eq!(r["knot_intervals"], "graded");
    assert!(
        rms <= 1.1 * gmsh.0 && max <= 1.1 * gmsh.1,
        "disk level 2: RMS {rms:.3e}, max {max:.3e} vs Gmsh {:.3e}, {:.3e}",
        gmsh.0,
        gmsh.1
    );
}

/// `--knot-intervals auto` on the level-2 O-grid torus and cylinder: uniform knots hold back
/// more than a tenth of the elements there, so `auto` tries graded knots; on the torus their
/// blend holds back as many or more, and on the cylinder fewer (352 of 1,536 against 800) but
/// with a fitted boundary further from the smooth one (1.33× uniform knots'); it keeps the
/// uniform spline, whose boundary is within 5× Gmsh-with-CAD (RMS and max) against the exact
/// surface. (Graded knots' max is 7.1× on the torus and 26× on the cylinder: the knot ratios
/// of the surfaces crossing the wall come from the cells inside, not from the wall's uniform
/// spacing. With the held-back count alone `auto` took them on the cylinder: RMS 16.9×, max
/// 25.9×.)
#[test]
fn auto_knots_keep_the_o_grid_boundary() {
    if !common::have_gmsh("auto_knots_keep_the_o_grid_boundary") {
        return;
    }
    for shape in ["torus", "cylinder"] {
        let (linear, cad) = make(shape, 2);
        let out = dir().join(format!("{shape}_2_auto.msh"));
        let report = dir().join(format!("{shape}_2_auto.json"));
        curve(
            &linear,
            &out,
            &[
                "--knot-intervals",
                "auto",
                "--report",
                report.to_str().unwrap(),
            ],
        );
        let r: Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
        let m = measure(shape, &[&cad, &out], "all");
        let (gmsh, (rms, max)) = (m[0], m[1]);
        println!(
            "{shape} level 2 auto ({} knots, {} passes, share {}, {} of {} held back): RMS {:.2}×, max {:.2}× Gmsh-with-CAD",
            r["knot_intervals"],
            r["knot_passes"],
            r["knot_surfaces"]["graded_share"],
            r["reduced_elements"],
            r["elements"],
            rms / gmsh.0,
            max / gmsh.1
        );
        assert!(
            r["reduced_elements"].as_f64().unwrap() > 0.1 * r["elements"].as_f64().unwrap(),
            "{shape}: auto must have tried graded knots for this test to mean anything"
        );
        assert!(
            rms <= 5.0 * gmsh.0 && max <= 5.0 * gmsh.1,
            "{shape} level 2 auto: RMS {rms:.3e}, max {max:.3e} vs Gmsh {:.3e}, {:.3e}",
            gmsh.0,
            gmsh.1
        );
    }
}

/// The default demotion redo (where the pass kept holds back more than a tenth of the
/// elements, on meshes of at most 5,000) is kept only where its output boundary stays on the
/// first fit's: on the level-2 O-grid torus and cylinder, `--demote-uncertified` (the redo kept
/// on the held-back count alone) demotes elements and holds back fewer (torus: 0 against
/// 1,024 of 1,536), but its boundary is further from the exact surface (torus RMS 11.6×
/// Gmsh-with-CAD's, max 16.0×; cylinder max 5.6×); the default output is not demoted, no
/// further from the exact surface than the option's (RMS and max) and within 5× Gmsh-with-CAD.
#[test]
fn the_default_demotion_redo_keeps_the_boundary() {
    if !common::have_gmsh("the_default_demotion_redo_keeps_the_boundary") {
        return;
    }
    for shape in ["torus", "cylinder"] {
        let (linear, cad) = make(shape, 2);
        let run = |name: &str, args: &[&str]| {
            let out = dir().join(format!("{shape}_2_{name}.msh"));
            let report = dir().join(format!("{shape}_2_{name}.json"));
            let mut all = vec!["--report", report.to_str().unwrap()];
            all.extend_from_slice(args);
            curve(&linear, &out, &all);
            let r: Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
            (out, r)
        };
        let (default, r) = run("default", &[]);
        let (option, o) = run("demoted", &["--demote-uncertified"]);
        let m = measure(shape, &[&cad, &default, &option], "all");
        let (gmsh, (rms, max), (rms_o, max_o)) = (m[0], m[1], m[2]);
        let count = |r: &Value, key: &str| r[key].as_u64().unwrap();
        println!(
            "{shape} level 2: default {} held back, {} demoted, RMS {:.2}× max {:.2}× Gmsh-with-CAD; \
             --demote-uncertified {} held back, {} demoted, RMS {:.2}× max {:.2}×",
            count(&r, "reduced_elements"),
            count(&r, "demoted_elements"),
            rms / gmsh.0,
            max / gmsh.1,
            count(&o, "reduced_elements"),
            count(&o, "demoted_elements"),
            rms_o / gmsh.0,
            max_o / gmsh.1
        );
        assert_eq!(
            count(&r, "demoted_elements"),
            0,
            "{shape}: the redo was kept"
        );
        // The redo ran and would have been kept on the count: the default had it to refuse.
        assert!(
            count(&r, "reduced_elements") as f64 > 0.1 * count(&r, "elements") as f64,
            "{shape}: the default redo must run for this test to mean anything"
        );
        assert!(
            count(&o, "demoted_elements") > 0
                && count(&o, "reduced_elements") < count(&r, "reduced_elements"),
            "{shape}: the redo must hold back fewer for this test to mean anything"
        );
        assert!(
            rms <= rms_o && max <= max_o,
            "{shape}: default RMS {rms:.3e} max {max:.3e}, demoted RMS {rms_o:.3e} max {max_o:.3e}"
        );
        assert!(
            rms <= 5.0 * gmsh.0 && max <= 5.0 * gmsh.1,
            "{shape} level 2: RMS {rms:.3e}, max {max:.3e} vs Gmsh {:.3e}, {:.3e}",
            gmsh.0,
            gmsh.1
        );
    }
}
